"""Whether a generated function's output on a test input is equivalent to the reference's.

Outputs of generated code arrive as the sandbox reports them: JSON-like values (tuples as lists, numeric arrays),
geometries as WKT text. Expected outputs are the reference's return values on the host.
"""
from __future__ import annotations

import reprlib
from typing import Any, Mapping

import numpy as np
import shapely
from shapely.geometry.base import BaseGeometry

COMPARE_KINDS = ('allclose', 'equal', 'geometry')
ATOL = 1e-6  # absolute tolerance of 'allclose' and of geometry comparison
RTOL = 1e-6
_GRID = 1e-10  # relative to the coordinates' magnitude: the overlay grid of areal comparison
_AREAL = ('Polygon', 'MultiPolygon')
_SHORT = reprlib.Repr()
_SHORT.maxstring = _SHORT.maxother = 120
_SHORT.maxlist = _SHORT.maxtuple = _SHORT.maxdict = 8


def _short(value: Any) -> str:
    if isinstance(value, np.ndarray):
        value = value.tolist()
    if isinstance(value, BaseGeometry):
        value = value.wkt
    return _SHORT.repr(value)


# -- 'equal' --------------------------------------------------------------------------------------------------
def normalise(value: Any) -> Any:
    """Tuples and arrays as lists, NumPy scalars as Python values (the form values have after crossing over)."""
    if isinstance(value, np.ndarray):
        return normalise(value.tolist())
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, (list, tuple)):
        return [normalise(item) for item in value]
    if isinstance(value, Mapping):
        return {key: normalise(item) for key, item in value.items()}
    return value


def _same(a: Any, b: Any) -> bool:
    if isinstance(a, bool) or isinstance(b, bool):  # True is not 1 here
        return isinstance(a, bool) and isinstance(b, bool) and a == b
    if isinstance(a, (int, float)) and isinstance(b, (int, float)):
        return a == b  # 2 and 2.0 are the same value
    if isinstance(a, list) and isinstance(b, list):
        return len(a) == len(b) and all(_same(x, y) for x, y in zip(a, b))
    if isinstance(a, dict) and isinstance(b, dict):
        return a.keys() == b.keys() and all(_same(a[key], b[key]) for key in a)
    return type(a) is type(b) and a == b


def _equal(expected: Any, got: Any) -> tuple[bool, str]:
    if _same(normalise(expected), normalise(got)):
        return True, ''
    return False, f'expected {_short(expected)}, got {_short(got)}'


# -- 'allclose' -----------------------------------------------------------------------------------------------
def _numeric(value: Any) -> bool:
    """Numbers (bools count as 0/1), numeric arrays, and lists/tuples of them: nothing else is compared by value."""
    if isinstance(value, (bool, int, float, np.bool_, np.integer, np.floating)):
        return True
    if isinstance(value, np.ndarray):
        return value.dtype.kind in 'biuf'
    if isinstance(value, (list, tuple)):
        return all(_numeric(item) for item in value)
    return False


def _as_array(value: Any) -> np.ndarray | None:
    try:
        return np.asarray(value, dtype=float)
    except (TypeError, ValueError):  # ragged nesting
        return None


def _allclose(expected: Any, got: Any) -> tuple[bool, str]:
    if not _numeric(got):
        return False, f'expected numbers, got {_short(got)}'
    want, have = _as_array(expected), _as_array(got)
    if want is None:  # e.g. a tuple of arrays of different shapes: element by element
        if not isinstance(got, (list, tuple)) or len(got) != len(expected):
            return False, f'expected {len(expected)} values, got {_short(got)}'
        for index, (part, answer) in enumerate(zip(expected, got)):
            passed, reason = _allclose(part, answer)
            if not passed:
                return False, f'item {index}: {reason}'
        return True, ''
    if have is None:
        return False, f'expected shape {want.shape}, got a ragged {_short(got)}'
    if want.shape != have.shape:
        return False, f'expected shape {want.shape}, got shape {have.shape}: {_short(got)}'
    if not np.allclose(want, have, rtol=RTOL, atol=ATOL, equal_nan=True):
        return False, f'expected {_short(expected)}, got {_short(got)}'
    return True, ''


# -- 'geometry' -----------------------------------------------------------------------------------------------
def _geometry(expected: BaseGeometry, got: Any) -> tuple[bool, str]:
    if isinstance(got, str):
        try:
            got = shapely.from_wkt(got)
        except (shapely.errors.ShapelyError, ValueError, TypeError) as error:
            return False, f'the output is not valid WKT ({error}): {_short(got)}'
    if not isinstance(got, BaseGeometry):
        return False, f'expected a {expected.geom_type} (as WKT), got {_short(got)}'
    if got.geom_type != expected.geom_type:
        return False, f'expected a {expected.geom_type}, got a {got.geom_type}: {_short(got)}'
    if not np.isfinite(shapely.get_coordinates(got)).all():  # NaN vertices escape the distance checks below
        return False, f'the output has coordinates that are not finite numbers: {_short(got)}'
    if expected.is_empty or got.is_empty:
        return (expected.is_empty and got.is_empty), f'expected {_short(expected)}, got {_short(got)}'
    if expected.geom_type in _AREAL:
        # Overlay on a fine grid (snap rounding): the floating-point overlay of two polygons one ulp apart (WKT text
        # keeps 16 digits) can return both of them instead of a sliver.
        extent = max(1.0, *np.abs(expected.bounds), *np.abs(got.bounds))
        try:
            difference = shapely.symmetric_difference(expected, got, grid_size=_GRID * extent).area
        except shapely.errors.ShapelyError as error:  # e.g. a self-intersecting polygon
            return False, f'the output cannot be compared ({error}): {_short(got)}'
        if difference <= ATOL * max(1.0, expected.area):
            return True, ''
        return False, f'the shapes differ by an area of {difference:.3g}: got {_short(got)}'
    if shapely.normalize(expected).equals_exact(shapely.normalize(got), ATOL):
        return True, ''
    # the same line through other vertices (a collinear extra point) or points in another order
    if expected.hausdorff_distance(got) <= ATOL:
        return True, ''
    return False, f'expected {_short(expected)}, got {_short(got)}'


def _actions(expected: Any, got: Any) -> tuple[bool, str]:
    want, have = normalise(expected), normalise(got)
    if _same(want, have):
        return True, ''
    if isinstance(want, list) and isinstance(have, list):
        for index, (a, b) in enumerate(zip(want, have)):
            if not _same(a, b):
                return False, f'the robot actions differ at action {index}: expected {_short(a)}, got {_short(b)}'
        return False, (f'the robot actions differ: expected {len(want)} actions, got {len(have)} '
                       f'({_short(have[len(want):] or want[len(have):])} extra or missing)')
    return False, f'the robot actions differ: expected {_short(want)}, got {_short(have)}'


_BY_KIND = {'allclose': _allclose, 'equal': _equal}


def _compare(kind: str, expected: Any, got: Any) -> tuple[bool, str]:
    if kind == 'geometry':
        if isinstance(expected, BaseGeometry):
            return _geometry(expected, got)
        kind = 'allclose' if _numeric(expected) else 'equal'  # (a reference that returned no geometry)
    return _BY_KIND[kind](expected, got)


def equivalent(kind: str, expected: Any, got: Any) -> tuple[bool, str]:
    """(passed, reason when not). `kind` is 'allclose', 'equal' or 'geometry'. Robot API outputs are dicts with
    'return' and 'actions': the return value is compared by `kind`, the actions by 'equal'."""
    if kind not in COMPARE_KINDS:
        raise ValueError(f'unknown comparison {kind!r}; one of {COMPARE_KINDS}')
    if isinstance(expected, Mapping) and set(expected) == {'return', 'actions'}:
        if not isinstance(got, Mapping) or set(got) != {'return', 'actions'}:
            return False, f"expected a return value and actions, got {_short(got)}"
        passed, reason = _compare(kind, expected['return'], got['return'])
        if not passed:
            return False, f'the return value differs: {reason}'
        return _actions(expected['actions'], got['actions'])
    return _compare(kind, expected, got)
