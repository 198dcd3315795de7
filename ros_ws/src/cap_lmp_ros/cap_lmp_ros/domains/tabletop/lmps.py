"""The table-top domain: named positions, the pure helper functions of the robot API, and the table-top LMPs.

The named positions come from cap_tabletop.workspace (re-exported here): table-top bounds x in [-0.3, 0.3],
y in [-0.8, -0.2]; normalised coordinates [0, 0] = (-0.25, -0.75) (bottom-left), [1, 1] = (0.25, -0.25)
(top-right); "top" is +y, "left" is -x. The functions that need the robot (get_obj_pos, put_first_on_second, ...)
are bound by the caller (the ROS node, or a table model in tests); the pure ones are here so every binding shares
them. No rclpy here: the sandbox process imports this module to build its engine.
"""
from __future__ import annotations

from pathlib import Path
from typing import Any, Callable, Mapping, Sequence

import numpy as np

from cap_lmp.engine import Engine, LMPConfig
from cap_lmp.llm import LLMClient
from cap_lmp.prompts import load_prompt
from cap_lmp.sandbox import SandboxLimits
from cap_lmp_ros.domains.object_names import object_name_candidate
from cap_lmp_ros.domains.tabletop.answer_check import invented_object
from cap_tabletop.workspace import CORNERS, MIDDLE, NORMALISED_ORIGIN, NORMALISED_SPAN, SIDES

PROMPTS_DIR = Path(__file__).resolve().parent / 'prompts'

# Names generated code may call, besides np, Shapely and the LMPs.


def denormalize_xy(pos: Sequence[float]) -> np.ndarray:
    """Normalised table coordinates (0..1 from the left and from the lower edge) to metres."""
    return NORMALISED_ORIGIN + NORMALISED_SPAN * np.asarray(pos, dtype=float)


def _closest(pos: Sequence[float], named: Mapping[str, tuple[float, float]]) -> str:
    xy = np.asarray(pos, dtype=float)[:2]
    return min(named, key=lambda name: float(np.linalg.norm(xy - np.array(named[name]))))


def get_corner_name(pos: Sequence[float]) -> str:
    """The name of the table corner closest to `pos`."""
    return _closest(pos, CORNERS)


def get_side_name(pos: Sequence[float]) -> str:
    """The name of the table side closest to `pos`."""
    return _closest(pos, SIDES)


def tabletop_lmp_configs() -> list[LMPConfig]:
    """The six LMPs of the table-top domain, prompts loaded from prompts/ beside this module."""
    parse_stop = ('#', 'objects = [')
    return [
        LMPConfig('tabletop_ui', load_prompt(PROMPTS_DIR, 'tabletop_ui'), stop=parse_stop, maintain_session=True,
                  context_var='objects', context_api='get_obj_names', check_answer=invented_object),
        LMPConfig('parse_obj_name', load_prompt(PROMPTS_DIR, 'parse_obj_name'), stop=parse_stop, has_return=True,
                  callable_from_code=True, check_answer=invented_object),
        LMPConfig('parse_position', load_prompt(PROMPTS_DIR, 'parse_position'), stop=('#',), has_return=True,
                  callable_from_code=True),
        LMPConfig('parse_question', load_prompt(PROMPTS_DIR, 'parse_question'), stop=parse_stop, has_return=True,
                  callable_from_code=True),
        LMPConfig('transform_shape_pts', load_prompt(PROMPTS_DIR, 'transform_shape_pts'), stop=('#',), has_return=True,
                  return_val_name='new_shape_pts', callable_from_code=True),
        # Parameter names, not the call's values, in the query: a small model copies values into its `def` line.
        LMPConfig('fgen', load_prompt(PROMPTS_DIR, 'fgen'), stop=('# define', '# example'), max_tokens=1024,
                  signature_style='parameters'),
    ]


def build_engine(api: Mapping[str, Callable[..., Any]], client: LLMClient, limits: SandboxLimits | None = None,
                 **engine_options: Any) -> Engine:
    """An Engine with the table-top LMPs over `api` (the robot functions); the pure helpers are added if absent."""
    names: dict[str, Any] = {'denormalize_xy': denormalize_xy, 'get_corner_name': get_corner_name,
                             'get_side_name': get_side_name}
    names.update(api)
    return Engine(tabletop_lmp_configs(), client, names, limits=limits, default_lmp='tabletop_ui', **engine_options)



__all__ = ['CORNERS', 'MIDDLE', 'NORMALISED_ORIGIN', 'NORMALISED_SPAN', 'PROMPTS_DIR', 'SIDES',
           'build_engine', 'denormalize_xy', 'get_corner_name', 'get_side_name', 'object_name_candidate',
           'tabletop_lmp_configs']
