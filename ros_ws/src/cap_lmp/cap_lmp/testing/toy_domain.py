"""A toy robot domain for the engine's tests: its prompts, its LMPs and its engine builder.

The robot functions (toy_world.ToyWorld binds them in memory; a ROS binding may bind some of them): reading the
world, `get_obj_names()` and `get_obj_pos(name)`; acting on it, `put_first_on_second(obj_name, target)`,
`say(text)` and `ring_bell(times)`. Its LMPs are the paper's in small: `toy_ui` for commands (it keeps a session),
the nested `parse_obj_name`, `parse_position` and `transform_shape_pts` that generated code calls, and `fgen`, which
defines the functions generated code calls but nothing defines. The prompts are a few examples each: the tests
script the model's answers. No import beyond cap_lmp and NumPy: the sandbox process imports this module to build
its engine.
"""
from __future__ import annotations

from typing import Any, Callable, Mapping

from cap_lmp.engine import Engine, LMPConfig
from cap_lmp.llm import LLMClient
from cap_lmp.sandbox import SandboxLimits

# The robot functions that only read the world, and those that act on it (what a plan-only run records).
QUERY_FUNCTIONS = ('get_obj_names', 'get_obj_pos')
ACTING_FUNCTIONS = ('put_first_on_second', 'say', 'ring_bell')

TOY_PROMPT = '''# ring the bell once.
ring_bell(1)
# ring the bell three times.
ring_bell(3)
objects = ['red block', 'blue block', 'red bowl']
# put the red block in the red bowl.
put_first_on_second('red block', 'red bowl')
objects = ['red block', 'blue block', 'red bowl']
# put the blocks in the bowl.
for name in parse_obj_name('the blocks', f'objects = {get_obj_names()}'):
    put_first_on_second(name, 'red bowl')
say('done')
'''
PARSE_OBJ_NAME_PROMPT = '''objects = ['red block', 'blue block', 'red bowl']
# the blocks.
ret_val = [name for name in objects if 'block' in name]
objects = ['red block', 'blue block', 'red bowl']
# the block nearest the red bowl.
bowl_pos = get_obj_pos('red bowl')
ret_val = min(['red block', 'blue block'], key=lambda name: np.linalg.norm(get_obj_pos(name) - bowl_pos))
'''
PARSE_POSITION_PROMPT = '''# a point 10cm above the red block.
ret_val = get_obj_pos('red block') + np.array([0.0, 0.1])
'''
TRANSFORM_SHAPE_PTS_PROMPT = '''# move it 10cm to the right.
new_shape_pts = shape_pts + np.array([0.1, 0.0])
'''
FGEN_PROMPT = '''# define function: dist = get_distance(obj_pos, other_pos).
def get_distance(obj_pos, other_pos):
    return float(np.linalg.norm(np.array(obj_pos) - np.array(other_pos)))
'''


def toy_lmp_configs(context_api: str | None = 'get_obj_names') -> list[LMPConfig]:
    """The toy domain's LMPs; `toy_ui`'s runs start with `objects = <context_api()>` when it is given."""
    return [
        LMPConfig('toy_ui', TOY_PROMPT, maintain_session=True, context_var='objects', context_api=context_api),
        LMPConfig('parse_obj_name', PARSE_OBJ_NAME_PROMPT, has_return=True, callable_from_code=True),
        LMPConfig('parse_position', PARSE_POSITION_PROMPT, stop=('#',), has_return=True, callable_from_code=True),
        LMPConfig('transform_shape_pts', TRANSFORM_SHAPE_PTS_PROMPT, stop=('#',), has_return=True,
                  return_val_name='new_shape_pts', callable_from_code=True),
        # Parameter names, not the call's values, in the query: a small model copies values into its `def` line.
        LMPConfig('fgen', FGEN_PROMPT, stop=('# define', '# example'), signature_style='parameters'),
    ]


def build_engine(api: Mapping[str, Callable[..., Any]], client: LLMClient, limits: SandboxLimits | None = None,
                 **engine_options: Any) -> Engine:
    """An Engine with the toy LMPs over `api` (some or all of the toy robot functions). A module-level function:
    the sandbox process builds its engine with it. An API without get_obj_names (a bell alone) has no objects to
    name, so its commands run without the `objects = [...]` line."""
    context_api = 'get_obj_names' if 'get_obj_names' in api else None
    return Engine(toy_lmp_configs(context_api), client, dict(api), limits=limits, default_lmp='toy_ui',
                  **engine_options)


__all__ = ['ACTING_FUNCTIONS', 'QUERY_FUNCTIONS', 'TOY_PROMPT', 'build_engine', 'toy_lmp_configs']
