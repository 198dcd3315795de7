"""What a twin watches for while a program is rehearsed on it (plain Python over a World, no ROS).

A simulator run as a twin (sim_bridge with `twin:=true`) is reset to the scene as the graph perceives it, and a
generated program then runs on it before the robot moves. TwinWatch looks at the physics after every stretch of
steps and keeps what a person would call harm, each said once in words:

- the robot (arm, mobile base) touching the fixed scene (table, furniture, board) or itself, beyond the contacts it
  had when the twin was built (a pedestal on the floor); the gripper pressing on it harder than GRIPPER_PRESS_N;
- an object the fingers never held that moved: pushed (more than PUSHED_M), knocked over (tilted past TIPPED_DEG),
  fallen (more than FALLEN_M below where it stood, or falling faster than FALL_SPEED_M_S), the worst kept;
  and at the end one left leaning past TILTED_DEG.

Where a held object goes is the program's: its controller checks the grasp, the lift and where it was put (a drop
into a bin is meant). The harm watched for here is what nobody asked for.

Which bodies are which comes from the model: the robot is every body of the tree that holds the arm's shoulder, its
gripper the subtree of `gripper_base` (a tool on it included), what holds an object its fingers; the fixed scene is
what is welded to the world; the objects are the world's. A scene's drawing tool on its board draws (ink.py).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import mujoco
import numpy as np

PUSHED_M = 0.02  # an object the gripper never held that moved this far [m] was pushed
TIPPED_DEG = 45.0  # ... and one that leans this far was knocked over
FALLEN_M = 0.10  # ... and one this far below where it stood fell
FALL_SPEED_M_S = 1.2  # ... and one falling faster than this (from about 7 cm) fell
GRIPPER_PRESS_N = 20.0  # the gripper pressing on the fixed scene harder than this hit it (a brush is not harm)
TILTED_DEG = 25.0  # an object left leaning this far at the end does not rest on its base
SHOULDER_BODY = 'shoulder_link'
GRIPPER_BODY = 'gripper_base'
FINGER_BODIES = ('left_finger', 'right_finger')  # what holds an object


@dataclass(frozen=True)
class _Start:
    position: np.ndarray
    up: np.ndarray  # the object's vertical axis at the start (world frame)


def _up_axis(quaternion_wxyz: np.ndarray) -> np.ndarray:
    matrix = np.zeros(9)
    mujoco.mju_quat2Mat(matrix, quaternion_wxyz)
    return matrix.reshape(3, 3)[:, 2].copy()


def _angle_deg(a: np.ndarray, b: np.ndarray) -> float:
    return math.degrees(math.acos(float(np.clip(a @ b, -1.0, 1.0))))


class TwinWatch:
    """Call start() right after the world was reset to the perceived scene, update() after each stretch of steps
    (with the world's lock held), findings() for what was seen so far."""

    def __init__(self, world) -> None:
        self.world = world
        self._findings: dict[tuple[str, str], str] = {}
        self._severity: dict[str, int] = {}  # of each object's 'moved' finding
        self._starts: dict[str, _Start] = {}
        self._held: set[str] = set()
        self._allowed_pairs: set[tuple[int, int]] = set()
        self.started_at = 0.0
        self.max_gripper_force = 0.0

    # ------------------------------------------------------------------------------------------------ model
    def _index(self) -> None:
        model = self.world.model
        self._model = model
        shoulder = model.body(SHOULDER_BODY).id
        root = int(model.body_rootid[shoulder])
        self._robot = np.array([int(model.body_rootid[b]) == root for b in range(model.nbody)])
        self._gripper = self._subtree(model.body(GRIPPER_BODY).id)
        self._fingers = self._subtree(*(model.body(name).id for name in FINGER_BODIES))
        self._static = np.array([int(model.body_weldid[b]) == 0 and not self._robot[b] for b in range(model.nbody)])
        self._object_of_body = {int(model.body(name).id): name for name in self.world.objects_in_model()}
        # A drawing tool on its board is drawing, not a collision (scenes with ink, cap_sim_bridge.ink).
        self._drawing: set[tuple[int, int]] = set()
        ink = self.world.scene.ink
        if ink is not None:
            surface = model.geom(ink.surface_geom).id
            for tool in (ink.marker_geom, ink.eraser_geom):
                self._drawing.add((int(model.geom_bodyid[model.geom(tool).id]), int(model.geom_bodyid[surface])))

    def _subtree(self, *roots: int) -> np.ndarray:
        """Which bodies are `roots` or below one of them."""
        model, inside = self.world.model, np.zeros(self.world.model.nbody, dtype=bool)
        for body in range(model.nbody):
            walk = body
            while walk > 0 and walk not in roots:
                walk = int(model.body_parentid[walk])
            inside[body] = walk in roots
        return inside

    def _body_name(self, body: int) -> str:
        name = mujoco.mj_id2name(self._model, mujoco.mjtObj.mjOBJ_BODY, body) or f'body {body}'
        return 'the world' if body == 0 else name.replace('_', ' ')

    def _geom_name(self, geom: int) -> str:
        name = mujoco.mj_id2name(self._model, mujoco.mjtObj.mjOBJ_GEOM, geom)
        return name.replace('_', ' ') if name else self._body_name(int(self._model.geom_bodyid[geom]))

    # ------------------------------------------------------------------------------------------------ watch
    def start(self) -> None:
        """The scene as built is the reference: nothing was seen yet, its contacts now are the robot's own."""
        world = self.world
        with world.lock:
            self._index()
            data = world.data
            self._findings.clear()
            self._severity: dict[str, int] = {}
            self._held.clear()
            self._starts = {}
            ghosts = {spec.name for spec in world.objects if not spec.solid}  # nothing touches them
            for state in world.object_states():
                if state.name in ghosts:
                    continue
                body = world._object_body_ids[state.name]
                self._starts[state.name] = _Start(np.array(state.position), _up_axis(data.xquat[body]))
            self._allowed_pairs = {pair for _, pair, _ in self._robot_contacts()}
            self.max_gripper_force = 0.0  # the hardest the gripper pressed on the fixed scene [N]
            self.started_at = float(data.time)

    def _robot_contacts(self) -> list[tuple[int, tuple[int, int], tuple[int, int]]]:
        """(index, (body, body), (geom, geom)) of each contact of a robot body now, the robot's body first."""
        model, data = self._model, self.world.data
        found = []
        for i in range(data.ncon):
            contact = data.contact[i]
            g1, g2 = int(contact.geom1), int(contact.geom2)
            b1, b2 = int(model.geom_bodyid[g1]), int(model.geom_bodyid[g2])
            if not self._robot[b1]:
                b1, b2, g1, g2 = b2, b1, g2, g1
            if self._robot[b1]:
                found.append((i, (b1, b2), (g1, g2)))
        return found

    def _normal_force(self, contact: int) -> float:
        wrench = np.zeros(6)
        mujoco.mj_contactForce(self._model, self.world.data, contact, wrench)
        return abs(float(wrench[0]))

    def _see(self, kind: str, subject: str, text: str) -> None:
        self._findings.setdefault((kind, subject), text)

    def update(self) -> None:
        """Look at the world now (call with world.lock held, after a stretch of steps)."""
        world = self.world
        if getattr(self, '_model', None) is not world.model:
            return  # a reset changed the model and start() has not run yet
        model, data = self._model, world.data
        for i, (b1, b2), (g1, g2) in self._robot_contacts():
            if (b1, b2) in self._allowed_pairs or (b1, b2) in self._drawing:
                continue
            if b2 in self._object_of_body:
                if self._fingers[b1]:
                    self._held.add(self._object_of_body[b2])
                continue  # an arm link or a tool on an object: judged by where the object goes
            if self._static[b2]:
                if self._gripper[b1]:  # fingertips brush a surface they grasp from: pressing into it is harm
                    force = self._normal_force(i)
                    self.max_gripper_force = max(self.max_gripper_force, force)
                    if force < GRIPPER_PRESS_N:
                        continue
                x, y, z = data.contact[i].pos
                self._see('collision', self._geom_name(g2), f'the {self._body_name(b1)} hit the '
                                                            f'{self._geom_name(g2)} at ({x:.2f}, {y:.2f}, {z:.2f})')
            elif self._robot[b2] and not (self._gripper[b1] and self._gripper[b2]):
                pair = ' and the '.join(sorted((self._body_name(b1), self._body_name(b2))))
                self._see('self', pair, f'the robot touched itself (the {pair})')
        for name, start in self._starts.items():
            if name in self._held:
                continue  # where a held object goes is the program's, and its controller checks that it got there
            body = world._object_body_ids[name]
            position = data.xipos[body]
            adr = model.jnt_dofadr[model.body_jntadr[body]]
            moved = float(np.linalg.norm(position[:2] - start.position[:2]))
            fallen = start.position[2] - float(position[2])
            if fallen > FALLEN_M or -float(data.qvel[adr + 2]) > FALL_SPEED_M_S:
                self._moved(name, 3, f'the {name} fell off where it stood')
            elif _angle_deg(_up_axis(data.xquat[body]), start.up) > TIPPED_DEG:
                self._moved(name, 2, f'the {name} was knocked over')
            elif moved > PUSHED_M:
                self._moved(name, 1, f'the {name} was pushed {100 * moved:.0f} cm')

    def _moved(self, name: str, severity: int, text: str) -> None:
        """An object nothing held moved: the worst seen of it is kept (pushed, then knocked over, then fallen)."""
        if severity > self._severity.get(name, 0):
            self._severity[name] = severity
            self._findings[('moved', name)] = f'{text} (the gripper never held it)'

    def finish(self) -> None:
        """At the end (the world at rest): objects nothing held left leaning."""
        world, data = self.world, self.world.data
        with world.lock:
            self.update()
            for name, start in self._starts.items():
                tilt = _angle_deg(_up_axis(data.xquat[world._object_body_ids[name]]), start.up)
                if name not in self._held and tilt > TILTED_DEG:
                    self._moved(name, 2, f'the {name} was left leaning {tilt:.0f} degrees')

    def findings(self) -> list[str]:
        """What was seen since start(), in the order it was first seen."""
        return list(self._findings.values())

    def held(self) -> list[str]:
        """The objects the gripper touched since start()."""
        return sorted(self._held)
