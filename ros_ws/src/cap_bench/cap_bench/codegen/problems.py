"""The 37 problems of robot code generation, in the paper's four categories: NumPy, controls, Shapely, robot API.

A problem is a function signature without docstring (`i, j = get_closest_pair_idxs(points)`); the model writes the
`def` from the name and argument names alone. Hidden from it: a reference solution (a module-level function here,
whose source text is also a valid answer), seeded test inputs, and the rule that decides whether two outputs are
equivalent (compare.py).

References are written as a model's answer would be: no type hints or comments, only names the sandbox offers (the
harness and the oracle serve their source text as it is).
"""
from __future__ import annotations

import copy
import inspect
import textwrap
import types
from dataclasses import dataclass
from typing import Any, Callable, Mapping, TypeVar

import numpy as np
from shapely.affinity import rotate, scale
from shapely.geometry import LineString, MultiPoint, Point, Polygon, box
from shapely.ops import unary_union

from cap_bench.codegen.world import CodegenWorld, footprint_area, random_scene
from cap_tabletop.workspace import SPAWN_X_RANGE, SPAWN_Y_RANGE

CATEGORIES: dict[str, int] = {'numpy': 16, 'controls': 4, 'shapely': 10, 'robot_api': 7}


@dataclass(frozen=True)
class Case:
    """One test input: positional arguments, and for robot API problems the world's state (world.py)."""

    args: tuple
    scene: Mapping | None = None


@dataclass(frozen=True)
class Problem:
    name: str  # the function's name
    category: str  # a key of CATEGORIES
    signature: str  # what the model is asked to define, e.g. 'i, j = get_closest_pair_idxs(points)'
    reference: Callable  # module-level function of this module named `name`
    make_cases: Callable[[np.random.Generator], list[Case]]  # 5-8 small cases
    compare: str  # 'allclose' | 'equal' | 'geometry' (compare.py)


def _world_only(*args: Any, **kwargs: Any) -> Any:
    raise RuntimeError('the robot API exists only in a CodegenWorld; run references through reference_output()')


# The robot API the robot_api references call: reference_output() binds these names to a CodegenWorld's functions.
get_obj_names = get_obj_pos = get_bbox = is_obj_visible = put_first_on_second = say = _world_only
ROBOT_API_NAMES = ('get_obj_names', 'get_obj_pos', 'get_bbox', 'is_obj_visible', 'put_first_on_second', 'say')


# ==================================================================================================== references
# -- NumPy ----------------------------------------------------------------------------------------------------
def get_k_nearest_idxs(points, point, k):
    dists = np.linalg.norm(np.asarray(points, dtype=float) - np.asarray(point, dtype=float), axis=1)
    return [int(i) for i in np.argsort(dists)[:k]]


def get_closest_pair_idxs(points):
    points = np.asarray(points, dtype=float)
    best = None
    for i in range(len(points)):
        for j in range(i + 1, len(points)):
            dist = np.linalg.norm(points[i] - points[j])
            if best is None or dist < best[0]:
                best = (dist, i, j)
    return best[1], best[2]


def normalize_vectors(vectors):
    vectors = np.asarray(vectors, dtype=float)
    return vectors / np.linalg.norm(vectors, axis=1, keepdims=True)


def get_bbox_center(points):
    points = np.asarray(points, dtype=float)
    return (points.min(axis=0) + points.max(axis=0)) / 2


def rotate_pts_about(points, center, angle_rad):
    c, s = np.cos(angle_rad), np.sin(angle_rad)
    rotation = np.array([[c, -s], [s, c]])
    center = np.asarray(center, dtype=float)
    return (np.asarray(points, dtype=float) - center) @ rotation.T + center


def get_path_length(points):
    return float(np.sum(np.linalg.norm(np.diff(np.asarray(points, dtype=float), axis=0), axis=1)))


def resample_path(points, n):
    points = np.asarray(points, dtype=float)
    along = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(points, axis=0), axis=1))])
    targets = np.linspace(0.0, along[-1], n)
    return np.column_stack([np.interp(targets, along, points[:, axis]) for axis in range(points.shape[1])])


def get_in_box_mask(points, lower, upper):
    points = np.asarray(points, dtype=float)
    return np.all((points >= np.asarray(lower)) & (points <= np.asarray(upper)), axis=1)


def make_2d_transform(angle_rad, translation):
    c, s = np.cos(angle_rad), np.sin(angle_rad)
    return np.array([[c, -s, translation[0]], [s, c, translation[1]], [0.0, 0.0, 1.0]])


def apply_2d_transform(transform, points):
    points = np.asarray(points, dtype=float)
    homogeneous = np.column_stack([points, np.ones(len(points))])
    return (homogeneous @ np.asarray(transform, dtype=float).T)[:, :2]


def wrap_angles(angles):
    return np.mod(np.asarray(angles, dtype=float) + np.pi, 2 * np.pi) - np.pi


def get_pt_to_segment_dist(point, start, end):
    point, start, end = np.asarray(point, dtype=float), np.asarray(start, dtype=float), np.asarray(end, dtype=float)
    direction = end - start
    t = np.clip(np.dot(point - start, direction) / np.dot(direction, direction), 0.0, 1.0)
    return float(np.linalg.norm(point - (start + t * direction)))


def get_pairwise_dists(points):
    points = np.asarray(points, dtype=float)
    return np.linalg.norm(points[:, np.newaxis, :] - points[np.newaxis, :, :], axis=2)


def project_vec_onto(vec, axis):
    vec, axis = np.asarray(vec, dtype=float), np.asarray(axis, dtype=float)
    return np.dot(vec, axis) / np.dot(axis, axis) * axis


def get_angle_between(vec_a, vec_b):
    vec_a, vec_b = np.asarray(vec_a, dtype=float), np.asarray(vec_b, dtype=float)
    cos = np.dot(vec_a, vec_b) / (np.linalg.norm(vec_a) * np.linalg.norm(vec_b))
    return float(np.arccos(np.clip(cos, -1.0, 1.0)))


def get_polygon_area(vertices):
    x, y = np.asarray(vertices, dtype=float).T
    return float(abs(np.dot(x, np.roll(y, -1)) - np.dot(y, np.roll(x, -1))) / 2)


# -- controls -------------------------------------------------------------------------------------------------
def pd_control(error, prev_error, dt, kp, kd):
    return kp * error + kd * (error - prev_error) / dt


def pid_step(error, prev_error, integral, dt, kp, ki, kd):
    integral = integral + error * dt
    u = kp * error + ki * integral + kd * (error - prev_error) / dt
    return u, integral


def get_clamped_velocity(pos, target, kp, max_speed):
    vel = kp * (np.asarray(target, dtype=float) - np.asarray(pos, dtype=float))
    speed = np.linalg.norm(vel)
    if speed > max_speed:
        vel = vel * (max_speed / speed)
    return vel


def interpolate_trajectory(waypoints, times, t):
    waypoints = np.asarray(waypoints, dtype=float)
    return np.array([np.interp(t, times, waypoints[:, axis]) for axis in range(waypoints.shape[1])])


# -- Shapely --------------------------------------------------------------------------------------------------
def get_square_polygon(center, side_length):
    half = side_length / 2
    return box(center[0] - half, center[1] - half, center[0] + half, center[1] + half)


def get_closest_pt_on_line(line, point):
    return line.interpolate(line.project(point))


def get_overlap_area(poly_a, poly_b):
    return poly_a.intersection(poly_b).area


def is_pt_in_polygon(point, vertices):
    return bool(Polygon(vertices).contains(Point(point)))


def get_convex_hull(points):
    return MultiPoint(points).convex_hull


def scale_polygon_about_centroid(polygon, factor):
    return scale(polygon, xfact=factor, yfact=factor, origin='centroid')


def get_evenly_spaced_pts_on_line(line, n):
    return np.array([line.interpolate(dist).coords[0] for dist in np.linspace(0.0, line.length, n)])


def get_rotated_rectangle(center, width, height, angle_rad):
    rectangle = box(center[0] - width / 2, center[1] - height / 2, center[0] + width / 2, center[1] + height / 2)
    return rotate(rectangle, angle_rad, origin=(center[0], center[1]), use_radians=True)


def merge_polygons(polygons):
    return unary_union(polygons)


def clip_line_to_box(line, lower, upper):
    return line.intersection(box(lower[0], lower[1], upper[0], upper[1]))


# -- robot API ------------------------------------------------------------------------------------------------
def filter_visible_objs(obj_names):
    return [name for name in obj_names if is_obj_visible(name)]


def get_nearest_obj_to(obj_name):
    pos = get_obj_pos(obj_name)
    others = [name for name in get_obj_names() if name != obj_name]
    return min(others, key=lambda name: np.linalg.norm(get_obj_pos(name) - pos))


def get_obj_names_in_box(lower, upper):
    names = []
    for name in get_obj_names():
        x, y = get_obj_pos(name)
        if lower[0] <= x <= upper[0] and lower[1] <= y <= upper[1]:
            names.append(name)
    return names


def get_largest_obj_name():
    def footprint(name):
        x_min, y_min, x_max, y_max = get_bbox(name)
        return (x_max - x_min) * (y_max - y_min)
    return max(get_obj_names(), key=footprint)


def put_blocks_in_bowl(bowl_name):
    for name in get_obj_names():
        if 'block' in name:
            put_first_on_second(name, bowl_name)


def move_obj_by(obj_name, offset):
    put_first_on_second(obj_name, get_obj_pos(obj_name) + np.asarray(offset, dtype=float))


def line_up_objs(obj_names, start, end):
    start, end = np.asarray(start, dtype=float), np.asarray(end, dtype=float)
    for i, name in enumerate(obj_names):
        put_first_on_second(name, start + (end - start) * i / (len(obj_names) - 1))


# ==================================================================================================== test inputs
# Coordinates are drawn on a millimetre grid (short literals, exact round trips). Inputs where the natural
# readings of a signature would disagree (ties for a nearest or largest, points on a box's edge) are redrawn.
T = TypeVar('T')


def _until(draw: Callable[[], T], accept: Callable[[T], bool]) -> T:
    for _ in range(1000):
        value = draw()
        if accept(value):
            return value
    raise RuntimeError('no acceptable test input in 1000 draws')


def _round(values: Any, decimals: int = 3) -> np.ndarray:
    return np.round(np.asarray(values, dtype=float), decimals) + 0.0  # (+ 0.0: no -0.0 in literals)


def _num(rng: np.random.Generator, low: float, high: float, decimals: int = 3) -> float:
    return float(_round(rng.uniform(low, high), decimals))


def _pts(rng: np.random.Generator, n: int, dim: int = 2, low: float = -1.0, high: float = 1.0) -> np.ndarray:
    return _round(rng.uniform(low, high, (n, dim)))


def _vec(rng: np.random.Generator, dim: int = 2, min_norm: float = 0.2) -> np.ndarray:
    return _until(lambda: _pts(rng, 1, dim)[0], lambda v: np.linalg.norm(v) >= min_norm)


def _distinct(values: Any, gap: float = 1e-6) -> bool:
    """No two values within `gap`: the order of `values` is unambiguous."""
    ordered = np.sort(np.ravel(values))
    return bool(np.all(np.diff(ordered) > gap))


def _margin(values: Any, gap: float = 1e-6) -> bool:
    """The largest of `values` is unique (by more than `gap`)."""
    ordered = np.sort(np.ravel(values))
    return len(ordered) < 2 or bool(ordered[-1] - ordered[-2] > gap)


def _pair_dists(points: np.ndarray) -> np.ndarray:
    i, j = np.triu_indices(len(points), 1)
    return np.linalg.norm(points[i] - points[j], axis=1)


def _star_vertices(rng: np.random.Generator, n: int, center: Any, radius: float) -> np.ndarray:
    """Vertices of a simple polygon with `center` inside: sorted angles around it, each at its own distance (the
    polygon is star-shaped about `center`)."""
    def draw() -> np.ndarray:
        angles = np.sort(rng.uniform(0.0, 2 * np.pi, n))
        radii = radius * rng.uniform(0.4, 1.0, n)
        return _round(np.asarray(center) + radii[:, None] * np.column_stack([np.cos(angles), np.sin(angles)]))

    def accept(vertices: np.ndarray) -> bool:
        angles = np.sort(np.arctan2(*(vertices - np.asarray(center)).T[::-1]))
        gaps = np.diff(np.concatenate([angles, [angles[0] + 2 * np.pi]]))
        polygon = Polygon(vertices)
        return bool(np.all(gaps > 0.25) and np.all(gaps < 0.8 * np.pi) and polygon.is_valid and polygon.area > 0.01
                    and polygon.exterior.distance(Point(center)) > 0.05 and polygon.contains(Point(center)))

    return _until(draw, accept)


def _bounds(rng: np.random.Generator, x_range: tuple[float, float], y_range: tuple[float, float],
            ) -> tuple[np.ndarray, np.ndarray]:
    """A box's lower and upper corner, half a millimetre off the grid: no millimetre point lies on its edge."""
    xs = np.sort([_num(rng, *x_range), _num(rng, *x_range)])
    ys = np.sort([_num(rng, *y_range), _num(rng, *y_range)])
    return np.array([xs[0], ys[0]]) + 0.0005, np.array([xs[1], ys[1]]) + 0.0005


# -- NumPy ----------------------------------------------------------------------------------------------------
def _cases_get_k_nearest_idxs(rng: np.random.Generator) -> list[Case]:
    cases = []
    for index in range(6):
        n = int(rng.integers(5, 10))
        points, point = _until(lambda: (_pts(rng, n), _pts(rng, 1)[0]),
                               lambda pair: _distinct(np.linalg.norm(pair[0] - pair[1], axis=1)))
        k = 1 if index == 0 else n if index == 1 else int(rng.integers(2, n))
        cases.append(Case((points, point, k)))
    return cases


def _cases_get_closest_pair_idxs(rng: np.random.Generator) -> list[Case]:
    return [Case((_until(lambda: _pts(rng, n), lambda points: _distinct(_pair_dists(points))),))
            for n in (2, 3, 5, 6, 8, 9)]


def _cases_normalize_vectors(rng: np.random.Generator) -> list[Case]:
    return [Case((_until(lambda: _pts(rng, n, dim), lambda v: bool(np.all(np.linalg.norm(v, axis=1) > 0.2))),))
            for n, dim in ((1, 2), (3, 2), (5, 2), (2, 3), (4, 3), (6, 2))]


def _cases_get_bbox_center(rng: np.random.Generator) -> list[Case]:
    return [Case((_pts(rng, n, dim),)) for n, dim in ((1, 2), (2, 2), (4, 2), (6, 2), (8, 2), (5, 3))]


def _cases_rotate_pts_about(rng: np.random.Generator) -> list[Case]:
    angles = (0.0, np.pi / 2, _num(rng, -np.pi, np.pi), _num(rng, -np.pi, np.pi), _num(rng, -6.0, 6.0),
              _num(rng, -np.pi, np.pi))
    return [Case((_pts(rng, n), _pts(rng, 1)[0], angle)) for n, angle in zip((4, 3, 1, 5, 6, 8), angles)]


def _cases_get_path_length(rng: np.random.Generator) -> list[Case]:
    return [Case((_pts(rng, n, dim),)) for n, dim in ((1, 2), (2, 2), (3, 2), (5, 2), (7, 2), (4, 3))]


def _cases_resample_path(rng: np.random.Generator) -> list[Case]:
    def path(m: int) -> np.ndarray:
        return _until(lambda: _pts(rng, m), lambda p: bool(np.all(np.linalg.norm(np.diff(p, axis=0), axis=1) > 0.1)))

    return [Case((path(m), n)) for m, n in ((2, 2), (2, 5), (3, 4), (4, 7), (5, 10), (6, 3))]


def _cases_get_in_box_mask(rng: np.random.Generator) -> list[Case]:
    cases = [Case((_pts(rng, 5), np.array([-2.0, -2.0]), np.array([2.0, 2.0])))]  # every point inside
    for n in (4, 6, 8, 10, 7):
        lower, upper = _bounds(rng, (-0.9, 0.9), (-0.9, 0.9))
        cases.append(Case((_pts(rng, n), lower, upper)))
    return cases


def _cases_make_2d_transform(rng: np.random.Generator) -> list[Case]:
    angles = (0.0, np.pi / 2, _num(rng, -np.pi, np.pi), _num(rng, -np.pi, np.pi), _num(rng, -np.pi, np.pi))
    translations = (np.zeros(2), _pts(rng, 1)[0], np.zeros(2), _pts(rng, 1)[0], _pts(rng, 1)[0])
    return [Case((angle, translation)) for angle, translation in zip(angles, translations)]


def _cases_apply_2d_transform(rng: np.random.Generator) -> list[Case]:
    transforms = [np.eye(3), make_2d_transform(np.pi / 2, np.array([0.5, 0.0]))]
    transforms += [make_2d_transform(_num(rng, -np.pi, np.pi), _pts(rng, 1)[0]) for _ in range(3)]
    transforms.append(np.vstack([_pts(rng, 2, 3, -2.0, 2.0), [0.0, 0.0, 1.0]]))  # an affine map (shear, scale)
    return [Case((transform, _pts(rng, n))) for transform, n in zip(transforms, (3, 1, 4, 5, 6, 2))]


def _cases_wrap_angles(rng: np.random.Generator) -> list[Case]:
    return [Case((np.array([0.0]),)), Case((_round(rng.uniform(-3.1, 3.1, 4)),))] + [
        Case((_round(rng.uniform(-12.0, 12.0, n)),)) for n in (1, 3, 6, 8)]


def _cases_get_pt_to_segment_dist(rng: np.random.Generator) -> list[Case]:
    cases = []
    for along in (-0.6, 0.0, 0.3, 0.5, 1.0, 1.5):  # before, at and after the ends, and between them
        start = _pts(rng, 1)[0]
        end = _until(lambda: _pts(rng, 1)[0], lambda e: np.linalg.norm(e - start) > 0.3)
        direction = end - start
        normal = np.array([-direction[1], direction[0]])
        offset = 0.0 if along == 0.5 else rng.uniform(-1.0, 1.0)
        cases.append(Case((_round(start + along * direction + offset * normal), start, end)))
    return cases


def _cases_get_pairwise_dists(rng: np.random.Generator) -> list[Case]:
    return [Case((_pts(rng, n, dim),)) for n, dim in ((1, 2), (2, 2), (3, 2), (4, 2), (6, 2), (4, 3))]


def _cases_project_vec_onto(rng: np.random.Generator) -> list[Case]:
    axis_2d, axis_3d = _vec(rng), _vec(rng, 3)
    cases = [Case((np.array([-axis_2d[1], axis_2d[0]]), axis_2d)),  # perpendicular: the zero vector
             Case((axis_3d * 2.0, axis_3d))]  # parallel: the vector itself
    cases += [Case((_vec(rng, dim), _vec(rng, dim))) for dim in (2, 2, 3, 3)]
    return cases


def _cases_get_angle_between(rng: np.random.Generator) -> list[Case]:
    vec_2d, vec_3d = _vec(rng), _vec(rng, 3)
    cases = [Case((vec_2d, vec_2d * 2.0)),  # parallel: 0
             Case((vec_3d, vec_3d * -0.5))]  # opposite: pi
    cases += [Case((_vec(rng, dim), _vec(rng, dim))) for dim in (2, 2, 3, 3)]
    return cases


def _cases_get_polygon_area(rng: np.random.Generator) -> list[Case]:
    cases = []
    for index, n in enumerate((3, 4, 5, 6, 7, 8)):
        vertices = _star_vertices(rng, n, _pts(rng, 1)[0], _num(rng, 0.3, 1.0))
        cases.append(Case((vertices[::-1].copy() if index % 2 else vertices,)))  # clockwise and counterclockwise
    return cases


# -- controls -------------------------------------------------------------------------------------------------
_TIME_STEPS = (0.01, 0.02, 0.05, 0.1)


def _cases_pd_control(rng: np.random.Generator) -> list[Case]:
    cases = []
    for dim in (0, 0, 0, 0, 2, 3):  # scalar errors, and error vectors
        shape = () if dim == 0 else (dim,)
        error, prev_error = _round(rng.uniform(-1.0, 1.0, shape)), _round(rng.uniform(-1.0, 1.0, shape))
        if dim == 0:
            error, prev_error = float(error), float(prev_error)
        cases.append(Case((error, prev_error, float(rng.choice(_TIME_STEPS)), _num(rng, 0.5, 5.0, 2),
                           _num(rng, 0.01, 0.5))))
    return cases


def _cases_pid_step(rng: np.random.Generator) -> list[Case]:
    cases = [Case((0.25, 0.25, 0.0, 0.05, 2.0, 0.5, 0.1))]  # first step, constant error
    for _ in range(5):
        cases.append(Case((_num(rng, -1.0, 1.0), _num(rng, -1.0, 1.0), _num(rng, -0.5, 0.5),
                           float(rng.choice(_TIME_STEPS)), _num(rng, 0.5, 5.0, 2), _num(rng, 0.0, 2.0, 2),
                           _num(rng, 0.01, 0.5))))
    return cases


def _cases_get_clamped_velocity(rng: np.random.Generator) -> list[Case]:
    here = _pts(rng, 1)[0]
    cases = [Case((here, here.copy(), 2.0, 0.2))]  # at the target: no motion
    for index, dim in enumerate((2, 2, 3, 2, 3)):
        pos, target = _until(lambda: (_pts(rng, 1, dim)[0], _pts(rng, 1, dim)[0]),
                             lambda pair: np.linalg.norm(pair[1] - pair[0]) > 0.2)
        kp = _num(rng, 0.5, 5.0, 2)
        speed = kp * np.linalg.norm(target - pos)
        fraction = (0.3, 0.6) if index % 2 else (1.5, 3.0)  # the limit binds in some cases only
        cases.append(Case((pos, target, kp, float(_round(speed * rng.uniform(*fraction))))))
    return cases


def _cases_interpolate_trajectory(rng: np.random.Generator) -> list[Case]:
    cases = []
    for index, (n, dim) in enumerate(((2, 2), (3, 2), (4, 3), (5, 2), (3, 3), (4, 2))):
        waypoints = _pts(rng, n, dim)
        times = _round(_num(rng, 0.0, 2.0, 1) + np.cumsum(rng.uniform(0.5, 2.0, n)), 2)
        t = (times[0], times[-1], times[1])[index] if index < 3 else _num(rng, times[0], times[-1])
        cases.append(Case((waypoints, times, float(t))))
    return cases


# -- Shapely --------------------------------------------------------------------------------------------------
def _cases_get_square_polygon(rng: np.random.Generator) -> list[Case]:
    return [Case((_pts(rng, 1)[0], _num(rng, 0.05, 0.5))) for _ in range(6)]


def _cases_get_closest_pt_on_line(rng: np.random.Generator) -> list[Case]:
    cases = []
    for n in (2, 2, 3, 4, 5, 3):
        line = LineString(_until(lambda: _pts(rng, n), lambda p: LineString(p).is_simple))
        cases.append(Case((line, Point(_pts(rng, 1)[0]))))
    end = np.asarray(cases[0].args[0].coords[-1])
    beyond = end + (end - np.asarray(cases[0].args[0].coords[0]))  # past the end of the first line
    cases.append(Case((cases[0].args[0], Point(_round(beyond)))))
    return cases


def _cases_get_overlap_area(rng: np.random.Generator) -> list[Case]:
    def square(center: Any, side: float) -> Polygon:
        return box(center[0] - side / 2, center[1] - side / 2, center[0] + side / 2, center[1] + side / 2)

    a = _pts(rng, 1)[0]
    cases = [Case((square(a, 0.4), square(a + np.array([0.2, 0.1]), 0.4))),  # overlapping squares
             Case((square(a, 0.2), square(a + np.array([0.5, 0.0]), 0.2))),  # apart: 0
             Case((square(a, 0.6), square(a, 0.2))),  # one inside the other
             Case((Polygon(_star_vertices(rng, 6, a, 0.5)), Polygon(_star_vertices(rng, 5, a + 0.2, 0.5))))]
    b = _pts(rng, 1)[0]
    cases.append(Case((Polygon(_star_vertices(rng, 7, b, 0.6)), square(b, 0.5))))
    cases.append(Case((Polygon(_star_vertices(rng, 4, b, 0.4)), Polygon(_star_vertices(rng, 8, b + 0.1, 0.4)))))
    return cases


def _cases_is_pt_in_polygon(rng: np.random.Generator) -> list[Case]:
    cases = []
    for index, n in enumerate((3, 4, 5, 6, 7, 8)):
        center = _pts(rng, 1)[0]
        vertices = _star_vertices(rng, n, center, 0.6)
        polygon = Polygon(vertices)
        if index % 2 == 0:  # inside: on the way from the centre to a vertex (the polygon is star-shaped about it)
            draw = lambda: _round(center + rng.uniform(0.1, 0.8) * (vertices[rng.integers(n)] - center))
        else:
            draw = lambda: _round(center + rng.uniform(-0.9, 0.9, 2))
        point = _until(draw, lambda p: polygon.contains(Point(p)) == (index % 2 == 0)
                       and polygon.exterior.distance(Point(p)) > 0.005)
        cases.append(Case((point, vertices)))
    return cases


def _cases_get_convex_hull(rng: np.random.Generator) -> list[Case]:
    return [Case((_until(lambda: _pts(rng, n), lambda p: MultiPoint(p).convex_hull.area > 0.05),))
            for n in (3, 4, 6, 8, 10, 12)]


def _cases_scale_polygon_about_centroid(rng: np.random.Generator) -> list[Case]:
    return [Case((Polygon(_star_vertices(rng, n, _pts(rng, 1)[0], 0.5)), factor))
            for n, factor in ((3, 2.0), (4, 0.5), (5, 1.0), (6, 1.5), (7, 0.25), (8, 3.0))]


def _cases_get_evenly_spaced_pts_on_line(rng: np.random.Generator) -> list[Case]:
    return [Case((LineString(_pts(rng, m)), n)) for m, n in ((2, 2), (2, 3), (3, 5), (4, 8), (5, 4), (3, 6))]


def _cases_get_rotated_rectangle(rng: np.random.Generator) -> list[Case]:
    angles = (0.0, np.pi / 2, _num(rng, -np.pi, np.pi), _num(rng, -np.pi, np.pi), _num(rng, 0.0, 1.0),
              _num(rng, -1.0, 0.0))
    return [Case((_pts(rng, 1)[0], _num(rng, 0.1, 0.6), _num(rng, 0.05, 0.3), angle)) for angle in angles]


def _cases_merge_polygons(rng: np.random.Generator) -> list[Case]:
    def rect(corner: Any, size: Any) -> Polygon:
        return box(corner[0], corner[1], corner[0] + size[0], corner[1] + size[1])

    a, b = _pts(rng, 1)[0], _pts(rng, 1)[0]
    return [Case(([rect(a, (0.3, 0.2))],)),
            Case(([rect(a, (0.4, 0.4)), rect(a + 0.2, (0.4, 0.4))],)),  # overlapping: one polygon
            Case(([rect(a, (0.2, 0.2)), rect(a + 0.5, (0.2, 0.2))],)),  # apart: a multipolygon
            Case(([rect(a, (0.6, 0.6)), rect(a + 0.1, (0.2, 0.2))],)),  # one inside the other
            Case(([rect(b, (0.3, 0.3)), rect(b + np.array([0.2, 0.1]), (0.3, 0.3)), rect(b + 0.8, (0.2, 0.1))],)),
            Case(([Polygon(_star_vertices(rng, 6, b, 0.4)), rect(b, (0.5, 0.2))],))]


def _cases_clip_line_to_box(rng: np.random.Generator) -> list[Case]:
    def accept(args: tuple) -> bool:
        clipped = clip_line_to_box(*args)
        parts = getattr(clipped, 'geoms', [clipped])
        return clipped.geom_type in ('LineString', 'MultiLineString') and all(p.length > 0.01 for p in parts)

    cases = []
    for n in (2, 2, 3, 4, 5, 6):
        lower, upper = _until(lambda: _bounds(rng, (-0.8, 0.8), (-0.8, 0.8)),
                              lambda b: bool(np.all(b[1] - b[0] > 0.3)))
        inside = _round(rng.uniform(lower, upper))  # one vertex in the box: the clip is not empty
        cases.append(Case(_until(lambda: (LineString(np.vstack([inside, _pts(rng, n - 1)])), lower, upper),
                                 accept)))
    return cases


# -- robot API ------------------------------------------------------------------------------------------------
def _names(scene: Mapping) -> list[str]:
    return [entry['name'] for entry in scene['objects']]


def _positions(scene: Mapping) -> np.ndarray:
    return np.array([entry['pos'] for entry in scene['objects']])


def _cases_filter_visible_objs(rng: np.random.Generator) -> list[Case]:
    cases = []
    for counts, hidden in (({'block': 2, 'bowl': 1}, 0), ({'block': 3, 'bowl': 2}, 2), ({'block': 4, 'bowl': 1}, 1),
                           ({'block': 2, 'bowl': 2}, 3), ({'block': 1, 'bowl': 1}, 1)):
        scene = random_scene(rng, counts, hidden)
        absent = [f'{colour} {kind}' for colour in ('white', 'black') for kind in ('block', 'bowl')]
        candidates = list(rng.permutation(_names(scene) + list(rng.choice(absent, size=2, replace=False))))
        cases.append(Case(([str(name) for name in candidates],), scene))
    cases.append(Case(([],), random_scene(rng, {'block': 2, 'bowl': 1}, 1)))  # no names to look for
    return cases


def _cases_get_nearest_obj_to(rng: np.random.Generator) -> list[Case]:
    def nearest_is_unique(case: Case) -> bool:
        positions = _positions(case.scene)
        index = _names(case.scene).index(case.args[0])
        return _distinct(np.delete(np.linalg.norm(positions - positions[index], axis=1), index))

    def draw(counts: Mapping[str, int]) -> Case:
        scene = random_scene(rng, counts)
        return Case((str(rng.choice(_names(scene))),), scene)

    return [_until(lambda: draw(counts), nearest_is_unique)
            for counts in ({'block': 1, 'bowl': 1}, {'block': 2, 'bowl': 1}, {'block': 3, 'bowl': 1},
                           {'block': 3, 'bowl': 2}, {'block': 4, 'bowl': 2}, {'block': 2, 'bowl': 2})]


def _cases_get_obj_names_in_box(rng: np.random.Generator) -> list[Case]:
    scene = random_scene(rng, {'block': 3, 'bowl': 2})
    cases = [Case((np.array([-0.3, -0.8]), np.array([0.3, -0.2])), scene)]  # the whole table
    for counts in ({'block': 2, 'bowl': 1}, {'block': 3, 'bowl': 1}, {'block': 4, 'bowl': 2}, {'block': 3, 'bowl': 3},
                   {'block': 5, 'bowl': 1}):
        lower, upper = _bounds(rng, SPAWN_X_RANGE, SPAWN_Y_RANGE)
        cases.append(Case((lower, upper), random_scene(rng, counts)))
    return cases


def _cases_get_largest_obj_name(rng: np.random.Generator) -> list[Case]:
    cases = []
    for counts in ({'block': 2}, {'block': 3, 'bowl': 1}, {'block': 2, 'bowl': 2}, {'block': 4, 'bowl': 3},
                   {'block': 1, 'bowl': 2}, {'block': 5}):
        scene = _until(lambda: random_scene(rng, counts),
                       lambda s: _margin([footprint_area(entry) for entry in s['objects']]))
        cases.append(Case((), scene))
    return cases


def _cases_put_blocks_in_bowl(rng: np.random.Generator) -> list[Case]:
    cases = []
    for counts in ({'block': 2, 'bowl': 1}, {'block': 3, 'bowl': 2}, {'block': 0, 'bowl': 1}, {'block': 1, 'bowl': 1},
                   {'block': 4, 'bowl': 2}, {'block': 2, 'bowl': 3}):
        scene = random_scene(rng, counts)
        bowls = [name for name in _names(scene) if name.endswith('bowl')]
        cases.append(Case((str(rng.choice(bowls)),), scene))
    return cases


def _cases_move_obj_by(rng: np.random.Generator) -> list[Case]:
    cases = []
    for counts in ({'block': 1}, {'block': 2, 'bowl': 1}, {'block': 3, 'bowl': 1}, {'block': 1, 'bowl': 2},
                   {'block': 2, 'bowl': 2}):
        scene = random_scene(rng, counts)
        cases.append(Case((str(rng.choice(_names(scene))), _round(rng.uniform(-0.08, 0.08, 2))), scene))
    return cases


def _cases_line_up_objs(rng: np.random.Generator) -> list[Case]:
    cases = []
    for counts, n in (({'block': 2}, 2), ({'block': 2, 'bowl': 1}, 3), ({'block': 3, 'bowl': 1}, 2),
                      ({'block': 3, 'bowl': 2}, 4), ({'block': 2, 'bowl': 2}, 3)):
        scene = random_scene(rng, counts)
        names = [str(name) for name in rng.choice(_names(scene), size=n, replace=False)]
        start, end = (_round([rng.uniform(-0.25, 0.25), rng.uniform(-0.75, -0.25)]) for _ in range(2))
        cases.append(Case((names, start, end), scene))
    return cases


# ==================================================================================================== problems
def _problem(category: str, signature: str, reference: Callable, compare: str) -> Problem:
    return Problem(name=reference.__name__, category=category, signature=signature, reference=reference,
                   make_cases=globals()[f'_cases_{reference.__name__}'], compare=compare)


PROBLEMS: tuple[Problem, ...] = (
    _problem('numpy', 'idxs = get_k_nearest_idxs(points, point, k)', get_k_nearest_idxs, 'equal'),
    _problem('numpy', 'i, j = get_closest_pair_idxs(points)', get_closest_pair_idxs, 'equal'),
    _problem('numpy', 'units = normalize_vectors(vectors)', normalize_vectors, 'allclose'),
    _problem('numpy', 'center = get_bbox_center(points)', get_bbox_center, 'allclose'),
    _problem('numpy', 'pts = rotate_pts_about(points, center, angle_rad)', rotate_pts_about, 'allclose'),
    _problem('numpy', 'length = get_path_length(points)', get_path_length, 'allclose'),
    _problem('numpy', 'pts = resample_path(points, n)', resample_path, 'allclose'),
    _problem('numpy', 'mask = get_in_box_mask(points, lower, upper)', get_in_box_mask, 'equal'),
    _problem('numpy', 'transform = make_2d_transform(angle_rad, translation)', make_2d_transform, 'allclose'),
    _problem('numpy', 'pts = apply_2d_transform(transform, points)', apply_2d_transform, 'allclose'),
    _problem('numpy', 'angles = wrap_angles(angles)', wrap_angles, 'allclose'),
    _problem('numpy', 'dist = get_pt_to_segment_dist(point, start, end)', get_pt_to_segment_dist, 'allclose'),
    _problem('numpy', 'dists = get_pairwise_dists(points)', get_pairwise_dists, 'allclose'),
    _problem('numpy', 'proj = project_vec_onto(vec, axis)', project_vec_onto, 'allclose'),
    _problem('numpy', 'angle = get_angle_between(vec_a, vec_b)', get_angle_between, 'allclose'),
    _problem('numpy', 'area = get_polygon_area(vertices)', get_polygon_area, 'allclose'),
    _problem('controls', 'u = pd_control(error, prev_error, dt, kp, kd)', pd_control, 'allclose'),
    _problem('controls', 'u, integral = pid_step(error, prev_error, integral, dt, kp, ki, kd)', pid_step, 'allclose'),
    _problem('controls', 'vel = get_clamped_velocity(pos, target, kp, max_speed)', get_clamped_velocity, 'allclose'),
    _problem('controls', 'pos = interpolate_trajectory(waypoints, times, t)', interpolate_trajectory, 'allclose'),
    _problem('shapely', 'square = get_square_polygon(center, side_length)', get_square_polygon, 'geometry'),
    _problem('shapely', 'pt = get_closest_pt_on_line(line, point)', get_closest_pt_on_line, 'geometry'),
    _problem('shapely', 'area = get_overlap_area(poly_a, poly_b)', get_overlap_area, 'allclose'),
    _problem('shapely', 'inside = is_pt_in_polygon(point, vertices)', is_pt_in_polygon, 'equal'),
    _problem('shapely', 'hull = get_convex_hull(points)', get_convex_hull, 'geometry'),
    _problem('shapely', 'poly = scale_polygon_about_centroid(polygon, factor)', scale_polygon_about_centroid,
             'geometry'),
    _problem('shapely', 'pts = get_evenly_spaced_pts_on_line(line, n)', get_evenly_spaced_pts_on_line, 'allclose'),
    _problem('shapely', 'rect = get_rotated_rectangle(center, width, height, angle_rad)', get_rotated_rectangle,
             'geometry'),
    _problem('shapely', 'shape = merge_polygons(polygons)', merge_polygons, 'geometry'),
    _problem('shapely', 'clipped = clip_line_to_box(line, lower, upper)', clip_line_to_box, 'geometry'),
    _problem('robot_api', 'names = filter_visible_objs(obj_names)', filter_visible_objs, 'equal'),
    _problem('robot_api', 'name = get_nearest_obj_to(obj_name)', get_nearest_obj_to, 'equal'),
    _problem('robot_api', 'names = get_obj_names_in_box(lower, upper)', get_obj_names_in_box, 'equal'),
    _problem('robot_api', 'name = get_largest_obj_name()', get_largest_obj_name, 'equal'),
    _problem('robot_api', 'put_blocks_in_bowl(bowl_name)', put_blocks_in_bowl, 'equal'),
    _problem('robot_api', 'move_obj_by(obj_name, offset)', move_obj_by, 'equal'),
    _problem('robot_api', 'line_up_objs(obj_names, start, end)', line_up_objs, 'equal'),
)
_BY_NAME = {item.name: item for item in PROBLEMS}


def problem(name: str) -> Problem:
    """The problem whose function is called `name`."""
    if name not in _BY_NAME:
        raise KeyError(f'no codegen problem named {name!r}')
    return _BY_NAME[name]


def reference_source(problem: Problem) -> str:
    """The reference's source text: a valid answer to the problem."""
    return textwrap.dedent(inspect.getsource(problem.reference))


def cases(problem: Problem, seed: int) -> list[Case]:
    """The problem's test inputs for `seed` (the same for the same seed)."""
    return problem.make_cases(np.random.default_rng(seed))


def reference_output(problem: Problem, case: Case, world: CodegenWorld) -> Any:
    """The reference's output on `case`, run on the host; for robot API problems {'return': ..., 'actions': [...]},
    the actions the reference asked `world` for."""
    world.begin_case(case.scene)
    args = copy.deepcopy(case.args)  # a reference never changes its inputs; the case stays as it is anyway
    if problem.category != 'robot_api':
        return problem.reference(*args)
    reference = problem.reference
    function = types.FunctionType(reference.__code__, {**reference.__globals__, **world.api()}, reference.__name__,
                                  reference.__defaults__, reference.__closure__)
    value = function(*args)
    return {'return': value, 'actions': list(world.actions)}


# One deliberately wrong answer per category: it runs in the sandbox and fails on the seeded cases (a check that
# the comparison can tell).
WRONG_SOURCES: dict[str, tuple[str, str]] = {
    'numpy': ('get_path_length', 'def get_path_length(points):\n'
                                 '    points = np.asarray(points, dtype=float)\n'
                                 '    return float(np.linalg.norm(points[-1] - points[0]))\n'),
    'controls': ('pd_control', 'def pd_control(error, prev_error, dt, kp, kd):\n'
                               '    return kp * error + kd * (error - prev_error)\n'),
    'shapely': ('get_overlap_area', 'def get_overlap_area(poly_a, poly_b):\n'
                                    '    return poly_a.union(poly_b).area\n'),
    'robot_api': ('put_blocks_in_bowl', 'def put_blocks_in_bowl(bowl_name):\n'
                                        '    for name in reversed(get_obj_names()):\n'
                                        "        if 'block' in name:\n"
                                        '            put_first_on_second(name, bowl_name)\n'),
}
