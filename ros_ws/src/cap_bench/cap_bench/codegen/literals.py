"""Python values as source text that rebuilds them exactly in a sandbox scope (test inputs are written into the
program the sandbox runs; `np` and the Shapely constructors are in that scope)."""
from __future__ import annotations

import math
from typing import Any, Sequence

import numpy as np
from shapely.geometry import LineString, MultiLineString, MultiPoint, MultiPolygon, Point, Polygon
from shapely.geometry.base import BaseGeometry

# dtypes an array literal infers from its elements (no dtype argument needed), and the others it may name: every
# one of them is numeric, so the sandbox accepts it.
_INFERRED_DTYPES = frozenset({np.dtype('float64'), np.dtype('int64'), np.dtype('bool')})
_NAMED_DTYPE_KINDS = 'fiu'
_SCALAR_TYPES = frozenset({'float64', 'float32', 'int64', 'int32'})  # numpy scalar types the sandbox's np offers


def _float(value: float) -> str:
    if math.isnan(value):
        return "float('nan')"
    if math.isinf(value):
        return "float('inf')" if value > 0 else "-float('inf')"
    return repr(value)


def _plain(value: Any) -> str:
    """Elements of ndarray.tolist(): bool, int, float, or nested lists of them."""
    if isinstance(value, list):
        return '[' + ', '.join(_plain(item) for item in value) + ']'
    if isinstance(value, float):
        return _float(value)
    return repr(value)


def _array(array: np.ndarray) -> str:
    dtype = array.dtype
    if dtype not in _INFERRED_DTYPES and dtype.kind not in _NAMED_DTYPE_KINDS:
        raise TypeError(f'no source text for arrays of dtype {dtype}')
    dtype_argument = '' if dtype == np.dtype('float64') else f', dtype={dtype.name!r}'
    if array.size == 0:  # a nested list cannot carry the shape of an empty array
        return f'np.zeros({tuple(array.shape)!r}{dtype_argument})'
    if dtype in _INFERRED_DTYPES:
        dtype_argument = ''
    return f'np.array({_plain(array.tolist())}{dtype_argument})'


def _coords(coords: Sequence[Sequence[float]]) -> str:
    return '[' + ', '.join('(' + ', '.join(_float(float(c)) for c in xy) + ')' for xy in coords) + ']'


def _geometry(geometry: BaseGeometry) -> str:
    kind = type(geometry).__name__
    if geometry.is_empty and isinstance(geometry, (Point, LineString, Polygon, MultiPoint, MultiLineString,
                                                   MultiPolygon)):
        return f'{kind}()'
    if isinstance(geometry, Point):
        return 'Point(' + ', '.join(_float(float(c)) for c in geometry.coords[0]) + ')'
    if isinstance(geometry, LineString):  # (a LinearRing is a LineString; it is written as one)
        return f'LineString({_coords(geometry.coords)})'
    if isinstance(geometry, Polygon):
        holes = [_coords(ring.coords) for ring in geometry.interiors]
        return (f'Polygon({_coords(geometry.exterior.coords)}' + (f', [{", ".join(holes)}]' if holes else '') + ')')
    if isinstance(geometry, MultiPoint):
        return f'MultiPoint({_coords([point.coords[0] for point in geometry.geoms])})'
    if isinstance(geometry, MultiLineString):
        return f'MultiLineString([{", ".join(_coords(line.coords) for line in geometry.geoms)}])'
    if isinstance(geometry, MultiPolygon):
        return f'MultiPolygon([{", ".join(_geometry(polygon) for polygon in geometry.geoms)}])'
    raise TypeError(f'no source text for a {geometry.geom_type}')


def to_source(value: Any) -> str:
    """Exact Python source that rebuilds `value`: floats via repr, ndarrays as np.array (dtype kept), tuples,
    lists, dicts, str, bool, None, NumPy scalars, and Shapely points, lines, polygons (holes too) and their multi
    kinds as constructor calls."""
    if value is None or isinstance(value, (bool, int, str)):
        return repr(value)
    if isinstance(value, float):
        return _float(value)
    if isinstance(value, np.bool_):
        return repr(bool(value))
    if isinstance(value, (np.integer, np.floating)):
        if value.dtype.name not in _SCALAR_TYPES:
            raise TypeError(f'no source text for a NumPy {value.dtype.name} scalar')
        return f'np.{value.dtype.name}({to_source(value.item())})'
    if isinstance(value, np.ndarray):
        return _array(value)
    if isinstance(value, BaseGeometry):
        return _geometry(value)
    if isinstance(value, tuple):
        items = [to_source(item) for item in value]
        return '(' + ', '.join(items) + (',' if len(items) == 1 else '') + ')'
    if isinstance(value, list):
        return '[' + ', '.join(to_source(item) for item in value) + ']'
    if isinstance(value, dict):
        return '{' + ', '.join(f'{to_source(key)}: {to_source(item)}' for key, item in value.items()) + '}'
    raise TypeError(f'no source text for a {type(value).__name__}')


def call_source(name: str, args: Sequence[Any]) -> str:
    """`name(<arg>, ...)` with every argument as source text."""
    return f'{name}({", ".join(to_source(arg) for arg in args)})'
