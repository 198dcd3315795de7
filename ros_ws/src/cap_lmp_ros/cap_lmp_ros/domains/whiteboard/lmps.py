"""The whiteboard domain's LMPs and the pure helpers of its robot API (no rclpy: the sandbox process imports this).

The LMPs follow the structure of the paper's drawing LMPs, with prompts written for this project: a session UI
(`whiteboard_ui`, which keeps earlier commands, so a shape drawn stays nameable through the variable that holds its
points), `parse_obj_name`, `parse_shape_pts` (a shape's points from a description), `transform_shape_pts` (a shape
moved, scaled, turned) and function generation. Positions are board metres, np.array([x, y]); `denormalize_xy`
maps normalised board coordinates ([0, 0] bottom left, [1, 1] top right) to them.
"""
from __future__ import annotations

from pathlib import Path
from typing import Any, Callable, Mapping, Sequence

import numpy as np
from cap_whiteboard.board import NORMALISED_ORIGIN, NORMALISED_SPAN

from cap_lmp.engine import Engine, LMPConfig
from cap_lmp.llm import LLMClient
from cap_lmp.prompts import load_prompt
from cap_lmp.sandbox import SandboxLimits

PROMPTS_DIR = Path(__file__).resolve().parent / 'prompts'
DEFAULT_LMP = 'whiteboard_ui'


def denormalize_xy(pos: Sequence[float]) -> np.ndarray:
    """Normalised board coordinates (0..1 from the left and from the lower edge) to metres."""
    return NORMALISED_ORIGIN + NORMALISED_SPAN * np.asarray(pos, dtype=float)


def whiteboard_lmp_configs() -> list[LMPConfig]:
    """The five LMPs of the whiteboard domain, prompts loaded from prompts/ beside this module."""
    stop = ('#', 'objects = [')
    return [
        LMPConfig(DEFAULT_LMP, load_prompt(PROMPTS_DIR, DEFAULT_LMP), stop=stop, maintain_session=True,
                  context_var='objects', context_api='get_obj_names'),
        LMPConfig('parse_obj_name', load_prompt(PROMPTS_DIR, 'parse_obj_name'), stop=stop, has_return=True,
                  callable_from_code=True),
        LMPConfig('parse_shape_pts', load_prompt(PROMPTS_DIR, 'parse_shape_pts'), stop=('#',), has_return=True,
                  return_val_name='shape_pts', callable_from_code=True),
        LMPConfig('transform_shape_pts', load_prompt(PROMPTS_DIR, 'transform_shape_pts'), stop=('#',),
                  # the result in the variable it came in: a small model writes `shape_pts = shape_pts + ...`
                  has_return=True, return_val_name='shape_pts', callable_from_code=True),
        # Parameter names, not the call's values, in the query: a small model copies values into its `def` line.
        LMPConfig('fgen', load_prompt(PROMPTS_DIR, 'fgen'), stop=('# define', '# example'), max_tokens=1024,
                  signature_style='parameters'),
    ]


def build_engine(api: Mapping[str, Callable[..., Any]], client: LLMClient, limits: SandboxLimits | None = None,
                 **engine_options: Any) -> Engine:
    """An Engine with the whiteboard LMPs over `api` (the robot functions); denormalize_xy is added if absent."""
    names: dict[str, Any] = {'denormalize_xy': denormalize_xy}
    names.update(api)
    return Engine(whiteboard_lmp_configs(), client, names, limits=limits, default_lmp=DEFAULT_LMP, **engine_options)


__all__ = ['DEFAULT_LMP', 'PROMPTS_DIR', 'build_engine', 'denormalize_xy', 'whiteboard_lmp_configs']
