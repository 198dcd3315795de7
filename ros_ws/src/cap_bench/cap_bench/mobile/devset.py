"""The mobile kitchen's development set: everyday commands of this project, judged like the benchmark's episodes.

Prompts are tuned on these, never on the benchmark's episodes. Each command is worded its own way (no instruction
is one the benchmark's templates render, so the benchmark's reference parser reads none of them) and is judged by
the benchmark judge of its kind (goto, back_and_forth, rectangle, fetch, bin, count): where the base stopped, the
path it drove, where an object ended, the last number said. Scenes come from the kitchen's default objects, seeded
per command. `cap bench mobile --set dev` runs them (oracle: the references below; --policy llm: the model).
"""
from __future__ import annotations

from dataclasses import dataclass
from cap_mobile import objects

from cap_bench.mobile.episodes import Episode, kitchen_scene, surface_radius


@dataclass(frozen=True)
class DevCommand:
    key: str
    kind: str  # the benchmark judge that decides it
    instructions: tuple[str, ...]
    attributes: dict
    references: tuple[str, ...]  # one program per instruction
    must_have: tuple[str, ...] = ()  # objects the scene holds
    keep_free: str = ''  # a surface whose middle stays clear (a fetch's destination)


def _goto(key: str, words: str, place: str) -> DevCommand:
    return DevCommand(key, 'goto', (words,), {'place': place}, (f'goto_loc({place!r})',))


def _count(key: str, words: str, group: str, surface: str) -> DevCommand:
    members = sorted(name for name, g in objects.GROUPS.items() if g == group)
    reference = (f'names = [name for name in get_obj_names() if name in {members!r} and '
                 f'np.linalg.norm(get_obj_pos(name) - get_loc_pos({surface!r})) < {surface_radius(surface):.2f}]\n'
                 f'say(f"I count {{len(names)}} on the {surface}")')
    return DevCommand(key, 'count', (words,), {'group': group, 'surface': surface}, (reference,))


def _fetch(key: str, words: str, thing: str, destination: str) -> DevCommand:
    return DevCommand(key, 'fetch', (words,), {'object': thing, 'destination': destination},
                      (f'pick_obj({thing!r})\nplace_at_pos(get_loc_pos({destination!r}))',), (thing,), destination)


COMMANDS: tuple[DevCommand, ...] = (
    _goto('drive_to_desk', 'drive over to the desk', 'desk'),
    _goto('head_to_bin', 'please head to the grey bin', 'grey bin'),
    _goto('stand_by_stool', 'could you go stand next to the barstool', 'barstool'),
    _goto('go_to_counter', 'make your way to the countertop', 'countertop'),
    DevCommand('desk_and_chair_twice', 'back_and_forth', ('drive to the desk, then to the chair, and do that twice',),
               {'first': 'desk', 'second': 'chair', 'times': 2},
               ("for _ in range(2):\n    goto_loc('desk')\n    goto_loc('chair')",)),
    DevCommand('table_then_bin_three_times', 'back_and_forth',
               ('visit the table and then the blue bin, three rounds in total',),
               {'first': 'table', 'second': 'blue bin', 'times': 3},
               ("for _ in range(3):\n    goto_loc('table')\n    goto_loc('blue bin')",)),
    DevCommand('loop_round_chair', 'rectangle',
               ('drive a rectangular loop around the office chair, 2.5 m along x and 2 m along y',),
               {'around': 'office chair', 'width': 2.5, 'height': 2.0},
               ("center = get_loc_pos('office chair')\n"
                'follow_traj(center + np.array([[-1.25, -1.0], [1.25, -1.0], [1.25, 1.0], [-1.25, 1.0], '
                '[-1.25, -1.0]]))',)),
    _fetch('apple_to_desk', 'take the apple over to the desk', 'apple', 'desk'),
    _fetch('chips_to_counter', 'could you put the chips bag on the countertop', 'chips bag', 'countertop'),
    _fetch('water_to_table', 'I need the water bottle on the table', 'water bottle', 'table'),
    _fetch('bar_to_desk', 'move the granola bar onto the desk please', 'granola bar', 'desk'),
    DevCommand('banana_in_compost', 'bin',
               ('drive to the green bin', 'remember that this one is the compost bin',
                'throw the banana into the compost bin'),
               {'object': 'banana', 'bin': 'green bin', 'label': 'compost bin'},
               ("goto_loc('green bin')",
                'pos, angle = get_robot_pos_and_angle()\n'
                'ahead = pos + 0.6 * np.array([np.cos(angle), np.sin(angle)])\n'
                'compost_bin_pos = get_loc_pos(min(get_loc_names(), '
                'key=lambda name: np.linalg.norm(get_loc_pos(name) - ahead)))',
                "pick_obj('banana')\nplace_at_pos(compost_bin_pos)"), ('banana',)),
    _count('count_drinks_desk', 'count the drinks on the desk for me', 'drink', 'desk'),
    _count('fruit_on_counter', 'how much fruit is there on the countertop?', 'fruit', 'countertop'),
    _count('snacks_on_table', 'tell me the number of snacks lying on the table', 'snack', 'table'),
    _count('drinks_on_table', 'are there any drinks on the table? say how many', 'drink', 'table'),
)
BY_KEY = {command.key: command for command in COMMANDS}
KINDS = tuple(dict.fromkeys(command.kind for command in COMMANDS))  # the report's rows, in the set's order
REFERENCES: dict[str, str] = {instruction: reference for command in COMMANDS
                              for instruction, reference in zip(command.instructions, command.references)}


def reference_program(instruction: str) -> str:
    """The reference of a development instruction (KeyError for another)."""
    return REFERENCES[instruction]


def episodes(trials: int = 1) -> list[Episode]:
    """The development set as the runner's episodes, `trials` times over: command i of trial t has seed
    t * 100 + i (unique keys), its scene drawn from that seed."""
    out = []
    for trial in range(trials):
        for index, command in enumerate(COMMANDS):
            seed = trial * 100 + index
            scene = kitchen_scene(seed, command.must_have, command.keep_free)
            out.append(Episode(command.kind, seed, command.instructions, scene,
                               {**command.attributes, 'dev': command.key}))
    return out


__all__ = ['BY_KEY', 'COMMANDS', 'KINDS', 'DevCommand', 'episodes', 'reference_program']
