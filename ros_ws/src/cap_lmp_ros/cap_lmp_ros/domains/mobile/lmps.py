"""The mobile domain's LMPs (no rclpy: the sandbox process imports this).

The LMPs follow the structure of the paper's mobile LMPs, with prompts written for this project: a session UI
(`mobile_ui`, which keeps earlier commands, so "do that again but ..." can use the variables of the last one),
`parse_obj_name` (names out of a list: which locations are "the seats"), `parse_position` (a point on the floor from
a description), `transform_traj` (a trajectory moved, turned, scaled) and function generation. Positions are floor
metres in the room's frame, np.array([x, y]); angles are radians, counterclockwise from +x.
"""
from __future__ import annotations

from pathlib import Path
from typing import Any, Callable, Mapping

from cap_lmp.engine import Engine, LMPConfig
from cap_lmp.llm import LLMClient
from cap_lmp.prompts import load_prompt
from cap_lmp.sandbox import SandboxLimits

PROMPTS_DIR = Path(__file__).resolve().parent / 'prompts'
DEFAULT_LMP = 'mobile_ui'


def mobile_lmp_configs() -> list[LMPConfig]:
    """The five LMPs of the mobile domain, prompts loaded from prompts/ beside this module."""
    stop = ('#', 'locations = [')
    return [
        LMPConfig(DEFAULT_LMP, load_prompt(PROMPTS_DIR, DEFAULT_LMP), stop=stop, maintain_session=True,
                  context_var='locations', context_api='get_loc_names'),
        LMPConfig('parse_obj_name', load_prompt(PROMPTS_DIR, 'parse_obj_name'), stop=stop, has_return=True,
                  callable_from_code=True),
        LMPConfig('parse_position', load_prompt(PROMPTS_DIR, 'parse_position'), stop=('#',), has_return=True,
                  callable_from_code=True),
        LMPConfig('transform_traj', load_prompt(PROMPTS_DIR, 'transform_traj'), stop=('#',), has_return=True,
                  return_val_name='new_traj', callable_from_code=True),
        # Parameter names, not the call's values, in the query (as the whiteboard's): a small model copies values.
        LMPConfig('fgen', load_prompt(PROMPTS_DIR, 'fgen'), stop=('# define', '# example'), max_tokens=1024,
                  signature_style='parameters'),
    ]


def build_engine(api: Mapping[str, Callable[..., Any]], client: LLMClient, limits: SandboxLimits | None = None,
                 **engine_options: Any) -> Engine:
    """An Engine with the mobile LMPs over `api` (the robot functions)."""
    return Engine(mobile_lmp_configs(), client, dict(api), limits=limits, default_lmp=DEFAULT_LMP, **engine_options)


__all__ = ['DEFAULT_LMP', 'PROMPTS_DIR', 'build_engine', 'mobile_lmp_configs']
