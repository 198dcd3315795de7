"""The simulated world: a UR5e with a parallel-jaw gripper in a registered scene (by default the table top with its
blocks and bowls; see cap_sim_bridge.scenes). No ROS here.

Typical use::

    world = World()
    objects = world.reset(seed=3)                       # list[ObjectState] after the objects settled
    world.follow_trajectory([1.0, 2.0], [q_mid, q_goal])  # times from now [s], arm joint positions [rad]
    world.run_for(2.5)                                  # advance simulated time
    world.command_gripper(opening=0.0, max_force=20.0)  # close with 20 N per finger
    rgb, depth = world.render('front', 640, 480)

Threading rule: every public method takes ``world.lock`` (a re-entrant lock) for as long as it touches the
simulation, so one thread may step the physics while others command and read the world. Hold ``world.lock``
yourself to make several calls atomic (e.g. read the state and command a trajectory at one instant).
Rendering owns an OpenGL context per calling thread; render from one thread (the physics thread in the node).

Simulated time (``world.time``) never goes backwards, not even on reset; trajectory times are relative to the
moment the trajectory is commanded. The same seed and object list always give the same initial state.
"""
from __future__ import annotations

import dataclasses
import math
import threading
from typing import Callable, Sequence

import mujoco
import numpy as np
from cap_tabletop.workspace import REST_JOINTS

from cap_sim_bridge import camera as camera_math
from cap_sim_bridge import objects as scene_objects, scenes
from cap_sim_bridge.ink import InkCanvas, InkSurface
from cap_sim_bridge.mobile_base import MobileBase
from cap_sim_bridge.rendering import RgbdRenderer
from cap_sim_bridge.objects import ObjectSpec
from cap_sim_bridge.trajectory import JointTrajectory

ARM_JOINT_NAMES = ('shoulder_pan_joint', 'shoulder_lift_joint', 'elbow_joint', 'wrist_1_joint', 'wrist_2_joint',
                   'wrist_3_joint')
GRIPPER_JOINT_NAMES = ('gripper_left_finger_joint', 'gripper_right_finger_joint')
GRIPPER_ACTUATOR = 'gripper'
GRIPPER_TENDON = 'gripper_opening'
TCP_SITE = 'tcp'
FLANGE_SITE = 'flange'
TCP_OFFSET = 0.15  # tcp distance along the flange's +z [m]

# Arm pose at reset in the table top (its REST_JOINTS); a scene may give its own (SceneSpec.home_joints).
HOME_JOINT_POSITIONS = np.array(REST_JOINTS)

GRIPPER_MAX_OPENING = scenes.GRIPPER_MAX_OPENING  # [m], pad to pad
GRIPPER_DEFAULT_FORCE = 20.0  # [N] per finger
GRIPPER_MAX_FORCE = 100.0
# [m/s] rate at which the commanded opening moves: the Robotiq 2F-85's highest finger speed (20-150 mm/s).
GRIPPER_SPEED = 0.15

# Objects of a perceived scene that reach this far into each other were seen twice (ghost_overlaps) [m]: more than
# the few millimetres perception is off, less than any real object's size.
OVERLAP_DEPTH = 0.008
DEFAULT_SETTLE_TIME = 0.5  # [s] of simulated time for objects to come to rest after reset


@dataclasses.dataclass(frozen=True)
class ObjectState:
    """Ground truth of one object [world frame, m]. position = centre of the axis-aligned bounding box."""

    name: str
    category: str
    color_name: str
    rgba: tuple[float, float, float, float]
    position: tuple[float, float, float]
    orientation_xyzw: tuple[float, float, float, float]
    bbox_min: tuple[float, float, float]
    bbox_max: tuple[float, float, float]
    # Seen by the scene's visibility camera (a ray test), or True in a scene without one.
    visible: bool = True


@dataclasses.dataclass(frozen=True)
class GripperState:
    """opening between the pads [m]; force: squeeze per finger [N] (positive when closing); speed [m/s]."""

    opening: float
    force: float
    speed: float
    target_opening: float
    max_force: float
    # True while the commanded opening still ramps toward the target at GRIPPER_SPEED.
    reference_moving: bool


@dataclasses.dataclass(frozen=True)
class _Push:
    force: np.ndarray  # [N] world frame, at the tcp
    end_time: float  # [s] simulated


class World:
    """The table-top simulation. See the module docstring for the threading rule."""

    def __init__(self, scene_name: str = scenes.DEFAULT_SCENE, seed: int = 0,
                 objects: Sequence[ObjectSpec | str] | None = None,
                 adjust_model: Callable[[mujoco.MjModel], None] | None = None) -> None:
        """scene_name: a registered scene (ValueError naming the known ones otherwise); it must contain the robot.
        adjust_model(model): changes every model compiled for a reset before it is used (a hardware stand-in's
        perturbations, cap_sim_bridge.standin)."""
        self.lock = threading.RLock()
        self._adjust_model = adjust_model
        self.scene_name = scene_name
        self.scene = scenes.get_scene(scene_name)
        self._models: dict[tuple, mujoco.MjModel] = {}
        self._renderers: dict[tuple[int, int, int, str], RgbdRenderer] = {}
        self.model: mujoco.MjModel | None = None
        self.data: mujoco.MjData | None = None
        self.objects: list[ObjectSpec] = []
        self.seed = seed
        self._arm_command_serial = 0
        # The scene's drawing surface, if it has one: the canvas outlives model changes, its surface does not.
        self.ink_canvas: InkCanvas | None = InkCanvas(self.scene.ink) if self.scene.ink is not None else None
        self._ink: InkSurface | None = None
        self._uploaded_ink: dict[tuple[int, int, int, str], int] = {}  # renderer -> ink version its texture shows
        self.reset(seed, objects)

    # ----------------------------------------------------------------------------------------------- reset
    def reset(self, seed: int, objects: Sequence[ObjectSpec | str] | None = None,
              settle_time: float = DEFAULT_SETTLE_TIME, arm_joints: Sequence[float] | None = None,
              base_pose: Sequence[float] | None = None, ghost_overlaps: bool = False) -> list[ObjectState]:
        """Place the objects (default: the scene's episode for this seed) and let them settle.

        objects: ObjectSpec or names like "red block" (an empty list: none); specs without a position get one
        sampled from the seed under the spawn rules. The arm goes to the scene's home joints (HOME_JOINT_POSITIONS
        in the table top), or to `arm_joints`, with the gripper open, a mobile base to the scene's start pose or to
        `base_pose` (x, y, yaw). With `ghost_overlaps` (a twin of a perceived scene), objects placed into each other
        are not thrown apart: one of each overlapping pair (the one in most overlaps, else the later in the list)
        becomes a ghost, which nothing touches (ObjectSpec.solid), until none overlap. Returns the settled object
        states. Raises ValueError for unknown colours or categories, duplicate names, impossible layouts, or joints
        outside their limits.
        """
        specs = [ObjectSpec.from_name(o) if isinstance(o, str) else o for o in objects] if objects is not None else \
            self.scene.default_objects(seed)
        for spec in specs:
            spec.validate()
        names = [spec.name for spec in specs]
        if len(set(names)) != len(names):
            raise ValueError(f'object names must be unique: {names}')
        positions = self.scene.spawn_positions(specs, seed)
        key = (self.scene_name, tuple((s.name, s.category, s.color_name, s.solid) for s in specs))
        with self.lock:
            previous_time = 0.0 if self.data is None else float(self.data.time)
            model = self._models.get(key)
            if model is None:
                model = self.scene.build(specs).compile()
                if self._adjust_model is not None:
                    self._adjust_model(model)
                # A few compiled models are kept: benchmarks and tests reset the same objects again and again.
                if len(self._models) >= 8:
                    self._models.pop(next(iter(self._models)))
                self._models[key] = model
            if model is not self.model:
                self.model = model
                self.data = mujoco.MjData(model)
                try:
                    self._index_model()
                except KeyError as error:
                    raise ValueError(f'scene {self.scene_name!r} lacks part of the UR5e and gripper the world drives '
                                     f'({error}); include {scenes.ROBOT_MJCF} in it') from None
            else:
                mujoco.mj_resetData(self.model, self.data)
            self.objects = specs
            self.seed = seed
            self._place_robot_at_home()
            if arm_joints is not None and len(arm_joints):
                self._place_arm(arm_joints)
            if self._ink is not None:
                self._ink.reset()
            for spec, position in zip(specs, positions):
                x, y = position[:2]
                surface = position[2] if len(position) > 2 else self.scene.surface_z
                adr = self._object_qpos_adr[spec.name]
                resting = surface + scene_objects.resting_height(spec.category)
                # A given height never puts an object below its surface (perception's centre is a few mm off).
                z = max(resting, spec.height if spec.height is not None else resting) + scene_objects.SPAWN_CLEARANCE
                half = spec.yaw / 2
                self.data.qpos[adr:adr + 7] = [x, y, z, math.cos(half), 0.0, 0.0, math.sin(half)]
            if ghost_overlaps:
                mujoco.mj_forward(self.model, self.data)
                overlapping = self._overlapping_object()
                if overlapping is not None:  # placed into another: a double detection, made a ghost
                    specs = [dataclasses.replace(spec, solid=False) if spec.name == overlapping else spec
                             for spec in specs]
                    self.data.time = previous_time  # the clock goes on from where it was, as in any reset
                    return self.reset(seed, specs, settle_time, arm_joints, base_pose, ghost_overlaps)
            if self.scene.initialize is not None:  # the scene's own seeded start (e.g. a cart-pole's lean)
                self.scene.initialize(self.model, self.data, seed)
            if self.base is not None:
                if base_pose is not None and len(base_pose):
                    if len(base_pose) != 3:
                        raise ValueError(f'a base pose is (x, y, yaw), not {len(base_pose)} numbers')
                    self.base.set_positions(self.data, [float(v) for v in base_pose])
                self.base.hold_here(self.data)
            self.data.time = previous_time
            mujoco.mj_forward(self.model, self.data)
            self.run_for(settle_time)
            return self.object_states()

    def _index_model(self) -> None:
        model = self.model
        self._arm_joint_ids = np.array([model.joint(n).id for n in ARM_JOINT_NAMES])
        self._arm_qpos_adr = model.jnt_qposadr[self._arm_joint_ids]
        self._arm_dof_adr = model.jnt_dofadr[self._arm_joint_ids]
        self._arm_actuator_ids = np.array([model.actuator(n.replace('_joint', '')).id for n in ARM_JOINT_NAMES])
        # Velocity feed-forward through the position servo: ctrl = q_ref + (kv / kp) * qdot_ref (and the inertia's
        # torques / kp: _inertia_feedforward).
        bias = model.actuator_biasprm[self._arm_actuator_ids]
        self._arm_feedforward = bias[:, 2] / bias[:, 1]
        # The servos' parameters, restored when torque control ends (set_arm_torque_mode).
        self._arm_servo_gain = model.actuator_gainprm[self._arm_actuator_ids].copy()
        self._feedforward_buffers = (np.zeros(model.nv), np.zeros(model.nv))  # reused each step (no allocation)
        self._arm_servo_bias = bias.copy()
        self.arm_torque_mode = False
        self._pushes: list[_Push] = []
        self._finger_qpos_adr = model.jnt_qposadr[[model.joint(n).id for n in GRIPPER_JOINT_NAMES]]
        self._finger_dof_adr = model.jnt_dofadr[[model.joint(n).id for n in GRIPPER_JOINT_NAMES]]
        self._gripper_actuator_id = model.actuator(GRIPPER_ACTUATOR).id
        self._gripper_tendon_id = model.tendon(GRIPPER_TENDON).id
        self._tcp_site_id = model.site(TCP_SITE).id
        self._flange_site_id = model.site(FLANGE_SITE).id
        self.arm_joint_limits = model.jnt_range[self._arm_joint_ids].copy()
        self._object_body_ids = {}
        self._object_qpos_adr = {}
        self._object_geom_ids = {}
        for name in self.objects_in_model():
            body = model.body(name)
            self._object_body_ids[name] = body.id
            self._object_qpos_adr[name] = int(model.jnt_qposadr[model.joint(name).id])
            self._object_geom_ids[name] = np.flatnonzero(model.geom_bodyid == body.id)
        self._object_geom_set = np.zeros(model.ngeom, dtype=bool)
        for ids in self._object_geom_ids.values():
            self._object_geom_set[ids] = True
        self._ink = InkSurface(model, self.scene.ink, self.ink_canvas) if self.ink_canvas is not None else None
        # A mobile base, in scenes that have one (the kitchen).
        previous = getattr(self, 'base', None)
        self.base: MobileBase | None = MobileBase(model, previous.command_serial + 1 if previous else 0) \
            if MobileBase.in_model(model) else None

    def objects_in_model(self) -> list[str]:
        """Names of the object bodies of the current model (each has a free joint of the same name)."""
        model = self.model
        return [model.body(b).name for b in range(model.nbody)
                if model.body_jntnum[b] == 1 and model.jnt_type[model.body_jntadr[b]] == mujoco.mjtJoint.mjJNT_FREE]

    def _place_robot_at_home(self) -> None:
        data = self.data
        self._set_servo_parameters(torque=False)
        self._pushes = []
        data.xfrc_applied[:] = 0.0
        data.ctrl[:] = 0.0  # the scene's other actuators (a cart's motor) start idle
        home = np.array(self.scene.home_joints, dtype=float)
        data.qpos[self._arm_qpos_adr] = home
        opening = self.scene.home_gripper_opening  # open, unless the scene's tool is held between the fingers
        data.qpos[self._finger_qpos_adr] = opening / 2
        self._trajectory: JointTrajectory | None = None
        self._arm_command_serial += 1
        self._hold_positions = home.copy()
        self._gripper_target = opening
        self._gripper_reference = opening
        self._set_gripper_force(GRIPPER_DEFAULT_FORCE)
        data.ctrl[self._arm_actuator_ids] = home
        data.ctrl[self._gripper_actuator_id] = opening

    def _place_arm(self, joints: Sequence[float]) -> None:
        """Put the arm at `joints` (held there): a twin starts where the real arm is."""
        positions = np.array([float(v) for v in joints])
        if positions.shape != (len(ARM_JOINT_NAMES),) or not np.all(np.isfinite(positions)):
            raise ValueError(f'the arm has {len(ARM_JOINT_NAMES)} joints; got {list(joints)[:10]}')
        low, high = self.arm_joint_limits[:, 0], self.arm_joint_limits[:, 1]
        if np.any(positions < low - 1e-6) or np.any(positions > high + 1e-6):
            raise ValueError(f'arm joints {np.round(positions, 3).tolist()} are outside their limits')
        self.data.qpos[self._arm_qpos_adr] = positions
        self._hold_positions = positions.copy()
        self.data.ctrl[self._arm_actuator_ids] = positions

    # -------------------------------------------------------------------------------------------- stepping
    @property
    def time(self) -> float:
        """Simulated time [s]."""
        return float(self.data.time)

    @property
    def timestep(self) -> float:
        return float(self.model.opt.timestep)

    def step(self, n: int = 1) -> None:
        """Advance the physics by n steps, updating the arm and gripper references every step."""
        with self.lock:
            model, data = self.model, self.data
            ink, base = self._ink, self.base
            base_moving = base is not None and base.moving
            if self._trajectory is None and self._gripper_reference == self._gripper_target and not self._pushes \
                    and not base_moving:
                # Nothing to interpolate: the references are constant, let MuJoCo run the steps in one call (the
                # arm holds still, so the tool touches the board, if at all, where it did at the last step).
                mujoco.mj_step(model, data, nstep=n)
                if ink is not None:
                    ink.update(data)
                return
            # The trajectories' references for every step of the chunk at once (the time after each step).
            times = data.time + model.opt.timestep * np.arange(1, n + 1)
            references = self._trajectory.sample_many(times) if self._trajectory is not None else None
            base_references = base.references_for(times) if base_moving else None
            for k in range(n):
                self._update_references(None if references is None else
                                        (references[0][k], references[1][k], references[2][k]))
                if base_references is not None and base.moving:
                    base.update(data, base_references[0][k], base_references[1][k])
                if self._pushes:
                    self._apply_pushes()
                mujoco.mj_step(model, data)
                if ink is not None:
                    ink.update(data)

    def run_for(self, duration: float) -> None:
        """Advance simulated time by duration [s] (rounded to whole steps)."""
        self.step(max(0, int(round(duration / self.timestep))))

    def _update_references(self, reference: tuple[np.ndarray, np.ndarray, np.ndarray] | None) -> None:
        """Set the servos' references for the next step; `reference`: the trajectory's position, velocity and
        acceleration then (None without a trajectory)."""
        data = self.data
        if self._trajectory is not None:
            q_ref, qd_ref, qdd_ref = reference
            data.ctrl[self._arm_actuator_ids] = q_ref + self._arm_feedforward * qd_ref + \
                self._inertia_feedforward(qdd_ref)
            if data.time >= self._trajectory.end_time:
                self._hold_positions = self._trajectory.final_positions
                self._trajectory = None
                data.ctrl[self._arm_actuator_ids] = self._hold_positions
        if self._gripper_reference != self._gripper_target:
            step = GRIPPER_SPEED * self.model.opt.timestep
            delta = self._gripper_target - self._gripper_reference
            self._gripper_reference = self._gripper_target if abs(delta) <= step else \
                self._gripper_reference + np.sign(delta) * step
            data.ctrl[self._gripper_actuator_id] = self._gripper_reference

    def _inertia_feedforward(self, accelerations: np.ndarray) -> np.ndarray:
        """The servos' ctrl offset that adds the torques M(q) qdd_ref of the reference's accelerations (as an arm
        controller's model-based feed-forward does), so the arm does not lag its reference while it accelerates:
        that lag would read as contact. The servos' force range still bounds the sum."""
        model, data = self.model, self.data
        wanted, torques = self._feedforward_buffers
        wanted[self._arm_dof_adr] = accelerations
        mujoco.mj_mulM(model, data, torques, wanted)
        return torques[self._arm_dof_adr] / self._arm_servo_gain[:, 0]

    # ------------------------------------------------------------------------------------------------- arm
    def joint_positions(self) -> np.ndarray:
        """Arm joint positions [rad] in ARM_JOINT_NAMES order."""
        with self.lock:
            return self.data.qpos[self._arm_qpos_adr].copy()

    def joint_velocities(self) -> np.ndarray:
        """Arm joint velocities [rad/s] in ARM_JOINT_NAMES order."""
        with self.lock:
            return self.data.qvel[self._arm_dof_adr].copy()

    def joint_efforts(self) -> np.ndarray:
        """Arm actuator torques [N m] in ARM_JOINT_NAMES order."""
        with self.lock:
            return self.data.actuator_force[self._arm_actuator_ids].copy()

    def finger_positions(self) -> np.ndarray:
        """Finger joint positions [m] in GRIPPER_JOINT_NAMES order (each = pad distance from the tcp)."""
        with self.lock:
            return self.data.qpos[self._finger_qpos_adr].copy()

    def finger_velocities(self) -> np.ndarray:
        """Finger joint velocities [m/s] in GRIPPER_JOINT_NAMES order."""
        with self.lock:
            return self.data.qvel[self._finger_dof_adr].copy()

    def follow_trajectory(self, times: Sequence[float], positions: Sequence[Sequence[float]],
                          velocities: Sequence[Sequence[float]] | None = None) -> float:
        """Make the arm track a timed trajectory; returns its end time on the simulation clock [s].

        times: seconds from now, strictly increasing, >= 0; positions: (N, 6) [rad] in ARM_JOINT_NAMES order;
        velocities: optional (N, 6) [rad/s]; without them they are estimated (see JointTrajectory). When
        times[0] > 0 the trajectory starts from the current reference, so replacing a running trajectory is
        continuous (and smooth when velocities are given). The arm holds the last
        point afterwards. Raises ValueError for a malformed trajectory or positions outside the joint limits.
        """
        times = np.asarray(times, dtype=float)
        positions = np.asarray(positions, dtype=float)
        if positions.ndim != 2 or positions.shape[1] != len(ARM_JOINT_NAMES):
            raise ValueError(f'positions must have shape (N, {len(ARM_JOINT_NAMES)})')
        if times.ndim != 1 or len(times) == 0 or times[0] < 0:
            raise ValueError('times must be a non-empty sequence of seconds from now, >= 0')
        with self.lock:
            if self.arm_torque_mode:
                raise ValueError('the arm is under torque control; a trajectory needs it back on its servos')
            limits = self.arm_joint_limits
            if np.any(positions < limits[:, 0]) or np.any(positions > limits[:, 1]):
                raise ValueError('trajectory positions outside the joint limits')
            velocities = None if velocities is None else np.asarray(velocities, dtype=float)
            now = self.time
            if times[0] > 0:
                q_now, qd_now = self.reference()
                times = np.concatenate([[0.0], times])
                positions = np.vstack([q_now, positions])
                if velocities is not None:
                    velocities = np.vstack([qd_now, velocities])
            self._trajectory = JointTrajectory(now + times, positions, velocities)
            self._arm_command_serial += 1
            return self._trajectory.end_time

    def reference(self) -> tuple[np.ndarray, np.ndarray]:
        """The arm's current reference (desired position [rad], velocity [rad/s])."""
        with self.lock:
            if self._trajectory is None:
                return self._hold_positions.copy(), np.zeros(len(ARM_JOINT_NAMES))
            return self._trajectory.sample(self.time)

    @property
    def arm_command_serial(self) -> int:
        """Counts arm commands (trajectories, holds, resets): a change tells a follower it was replaced."""
        with self.lock:
            return self._arm_command_serial

    @property
    def trajectory_end_time(self) -> float | None:
        """End time of the running trajectory on the simulation clock, or None when the arm is holding."""
        with self.lock:
            return None if self._trajectory is None else self._trajectory.end_time

    def hold(self) -> None:
        """Stop any trajectory; the arm holds where it is now."""
        with self.lock:
            if self.arm_torque_mode:  # a hold always means the servos: torques of joint positions would be nonsense
                self._set_servo_parameters(torque=False)
            self._trajectory = None
            self._arm_command_serial += 1
            self._hold_positions = self.joint_positions()
            self.data.ctrl[self._arm_actuator_ids] = self._hold_positions

    def tcp_pose(self) -> np.ndarray:
        """4x4 world_T_tcp: the grasp point between the pads; its z axis points from the flange to the fingertips."""
        return self._site_pose(self._tcp_site_id)

    def flange_pose(self) -> np.ndarray:
        """4x4 world_T_flange (DH frame 6)."""
        return self._site_pose(self._flange_site_id)

    def _site_pose(self, site_id: int) -> np.ndarray:
        with self.lock:
            pose = np.eye(4)
            pose[:3, :3] = self.data.site_xmat[site_id].reshape(3, 3)
            pose[:3, 3] = self.data.site_xpos[site_id]
            return pose

    # ------------------------------------------------------------------------------------------ mobile base
    def _require_base(self) -> MobileBase:
        if self.base is None:
            raise ValueError(f'scene {self.scene_name!r} has no mobile base')
        return self.base

    def base_pose(self) -> np.ndarray:
        """(x [m], y [m], yaw [rad, not wrapped]) of the mobile base; ValueError in a scene without one."""
        with self.lock:
            return self._require_base().positions(self.data)

    def base_velocity(self) -> np.ndarray:
        """(x', y' [m/s], yaw' [rad/s]) of the mobile base in the world frame."""
        with self.lock:
            return self._require_base().velocities(self.data)

    def base_reference(self) -> tuple[np.ndarray, np.ndarray]:
        """The base servos' reference now (position, velocity)."""
        with self.lock:
            return self._require_base().reference(self.time)

    def follow_base_trajectory(self, times: Sequence[float], positions: Sequence[Sequence[float]],
                               velocities: Sequence[Sequence[float]] | None = None) -> float:
        """Make the base track a timed (x, y, yaw) trajectory (as follow_trajectory does for the arm); returns its
        end time on the simulation clock [s]."""
        with self.lock:
            return self._require_base().follow(self.time, np.asarray(times, dtype=float),
                                               np.asarray(positions, dtype=float),
                                               None if velocities is None else np.asarray(velocities, dtype=float))

    def hold_base(self) -> None:
        """Stop the base's trajectory; the base holds the pose it has now (its servos brake it)."""
        with self.lock:
            self._require_base().hold_here(self.data)

    def visible_with_base_at(self, pose: Sequence[float], names: Sequence[str]) -> list[bool]:
        """Whether the scene's visibility camera would see each named object with the mobile base at `pose` (x, y,
        yaw), by the ray test of `object_states`. The base's joints are set for the test only (kinematics, no physics
        step, no time passes) and put back before this returns: nothing in the simulation moves. For deciding what a
        pose would show before driving there (whether a benchmark's episode can be solved)."""
        with self.lock:
            base = self._require_base()
            saved = self.data.qpos.copy()
            try:
                base.set_positions(self.data, pose)
                mujoco.mj_kinematics(self.model, self.data)
                mujoco.mj_camlight(self.model, self.data)
                return [self.object_state(name).visible for name in names]
            finally:
                self.data.qpos[:] = saved
                mujoco.mj_kinematics(self.model, self.data)
                mujoco.mj_camlight(self.model, self.data)

    # ------------------------------------------------------------------------------- torque control, joints, pushes
    def set_arm_torque_mode(self, enabled: bool) -> None:
        """Drive the arm's joints by torque (True: each actuator's ctrl is its joint torque [N m], within the
        actuator's force range) or by its position servos again (False: the arm holds where it is now).

        The links stay gravity-compensated in both modes, as a torque-controlled arm's own controller does.
        """
        with self.lock:
            if enabled == self.arm_torque_mode:
                return
            if enabled:
                self._trajectory = None
                self._arm_command_serial += 1
                self._set_servo_parameters(torque=True)
                self.data.ctrl[self._arm_actuator_ids] = 0.0
            else:
                self._set_servo_parameters(torque=False)
                self.hold()

    def _set_servo_parameters(self, torque: bool) -> None:
        ids = self._arm_actuator_ids
        if torque:  # force = ctrl
            self.model.actuator_gainprm[ids] = 0.0
            self.model.actuator_gainprm[ids, 0] = 1.0
            self.model.actuator_biasprm[ids] = 0.0
        else:
            self.model.actuator_gainprm[ids] = self._arm_servo_gain
            self.model.actuator_biasprm[ids] = self._arm_servo_bias
        self.arm_torque_mode = torque

    def set_controls(self, actuators: Sequence[str], values: Sequence[float]) -> None:
        """Set the named actuators' controls (a motor's force or torque); the arm's only in torque mode."""
        with self.lock:
            ids = [self.model.actuator(name).id for name in actuators]
            if not self.arm_torque_mode and set(ids) & set(int(i) for i in self._arm_actuator_ids):
                raise ValueError('the arm takes torques only in torque mode (set_arm_torque_mode(True))')
            self.data.ctrl[ids] = np.asarray(values, dtype=float)

    def controls(self, actuators: Sequence[str]) -> np.ndarray:
        """The named actuators' controls now (a motor's commanded force or torque; the physics clamps it to the
        actuator's range)."""
        with self.lock:
            ids = [self.model.actuator(name).id for name in actuators]
            return self.data.ctrl[ids].copy()

    def joint_state(self, joints: Sequence[str]) -> tuple[np.ndarray, np.ndarray]:
        """(positions, velocities) of the named one-degree-of-freedom joints (hinges and slides)."""
        with self.lock:
            ids = [self.model.joint(name).id for name in joints]
            return self.data.qpos[self.model.jnt_qposadr[ids]].copy(), self.data.qvel[self.model.jnt_dofadr[ids]].copy()

    def joint_actuator_forces(self, joints: Sequence[str]) -> np.ndarray:
        """What the actuators apply to each named joint now (generalized force: N for a slide, N m for a hinge)."""
        with self.lock:
            ids = [self.model.joint(name).id for name in joints]
            return self.data.qfrc_actuator[self.model.jnt_dofadr[ids]].copy()

    @property
    def arm_actuator_names(self) -> tuple[str, ...]:
        """The arm's actuators, in ARM_JOINT_NAMES order."""
        return tuple(self.model.actuator(int(i)).name for i in self._arm_actuator_ids)

    def scene_joint_names(self) -> list[str]:
        """The scene's own one-degree-of-freedom joints (a cart-pole's): neither the robot's nor an object's."""
        with self.lock:
            model = self.model
            robot = set(ARM_JOINT_NAMES) | set(GRIPPER_JOINT_NAMES)
            return [model.joint(j).name for j in range(model.njnt)
                    if int(model.jnt_type[j]) in (int(mujoco.mjtJoint.mjJNT_HINGE), int(mujoco.mjtJoint.mjJNT_SLIDE))
                    and model.joint(j).name not in robot]

    def release_holds(self) -> list[str]:
        """Let go of what the scene holds still until a controller takes it over: every equality constraint whose
        name ends in '_hold' is switched off (a reset switches them on again). Returns their names."""
        with self.lock:
            model = self.model
            released = []
            for index in range(model.neq):
                name = model.equality(index).name
                if name.endswith('_hold') and self.data.eq_active[index]:
                    self.data.eq_active[index] = 0
                    released.append(name)
            return released

    def restart_plant(self) -> None:
        """Put the scene's own joints (its plant) back at the start the last reset gave them: at rest and held, as
        the scene's restart_plant says; ValueError when the scene defines no such start."""
        with self.lock:
            if self.scene.restart_plant is None:
                raise ValueError(f'the scene {self.scene_name!r} cannot put its own joints back at a defined start')
            self.scene.restart_plant(self.model, self.data, self.seed)
            mujoco.mj_forward(self.model, self.data)

    def push_tool(self, force: Sequence[float], duration: float) -> None:
        """Push the tool centre point with `force` [N, world frame] for `duration` seconds of simulated time from
        now (an external force, as a hand pushing the tool; pushes add up)."""
        force = np.asarray(force, dtype=float)
        if force.shape != (3,) or not np.all(np.isfinite(force)) or not duration > 0:
            raise ValueError('a push needs a finite 3-vector force and a positive duration')
        with self.lock:
            self._pushes.append(_Push(force, self.time + float(duration)))

    def _apply_pushes(self) -> None:
        data = self.data
        now = data.time
        self._pushes = [push for push in self._pushes if push.end_time > now]
        body = self.model.site_bodyid[self._tcp_site_id]
        data.xfrc_applied[body] = 0.0
        if self._pushes:
            force = np.sum([push.force for push in self._pushes], axis=0)
            # Applied at the tcp, not at the body's centre of mass: the moment of the offset comes along.
            lever = data.site_xpos[self._tcp_site_id] - data.xipos[body]
            data.xfrc_applied[body, :3] = force
            data.xfrc_applied[body, 3:] = np.cross(lever, force)

    # --------------------------------------------------------------------------------------------- gripper
    def command_gripper(self, opening: float, max_force: float = 0.0) -> None:
        """Move the fingers to an opening [m] (0 = closed) squeezing with at most max_force [N] per finger.

        max_force <= 0 means GRIPPER_DEFAULT_FORCE. To grasp, command an opening smaller than the object: the
        fingers stop on it and squeeze with max_force.
        """
        with self.lock:
            self._gripper_target = float(np.clip(opening, 0.0, GRIPPER_MAX_OPENING))
            # The ramp starts where the fingers are, as a real gripper's does: after a grasp the reference has run
            # on to the closed end, and a release ramping back from there would stand still for a while.
            self._gripper_reference = float(self.data.ten_length[self._gripper_tendon_id])
            force = GRIPPER_DEFAULT_FORCE if max_force <= 0 else min(float(max_force), GRIPPER_MAX_FORCE)
            self._set_gripper_force(force)

    def _set_gripper_force(self, force: float) -> None:
        self.model.actuator_forcerange[self._gripper_actuator_id] = [-force, force]

    def gripper_state(self) -> GripperState:
        with self.lock:
            return GripperState(
                opening=float(self.data.ten_length[self._gripper_tendon_id]),
                force=float(-self.data.actuator_force[self._gripper_actuator_id]),
                speed=float(abs(self.data.ten_velocity[self._gripper_tendon_id])),
                target_opening=self._gripper_target,
                max_force=float(self.model.actuator_forcerange[self._gripper_actuator_id][1]),
                reference_moving=self._gripper_reference != self._gripper_target)

    # --------------------------------------------------------------------------------------------- objects
    def object_states(self) -> list[ObjectState]:
        """Ground truth of every object, in the order of the reset's object list (with `visible` from the scene's
        visibility camera, if it has one)."""
        with self.lock:
            return [self._seen(self._object_state(spec)) for spec in self.objects]

    def object_state(self, name: str) -> ObjectState:
        with self.lock:
            for spec in self.objects:
                if spec.name == name:
                    return self._seen(self._object_state(spec))
        raise KeyError(f'no object named {name!r}; objects: {", ".join(s.name for s in self.objects)}')

    def _seen(self, state: ObjectState) -> ObjectState:
        camera = self.scene.visibility_camera
        if camera is None:
            return state
        return dataclasses.replace(state, visible=self.is_visible_from(camera, state))

    def is_visible_from(self, camera: str, state: ObjectState, aspect: float = 4 / 3) -> bool:
        """Whether the camera sees the object: its centre or the middle of its top is inside the camera's field of
        view (images `aspect` wide for 1 high) and the first thing a ray from the camera to that point hits is the
        object. The camera's own body (its mount) is left out of the test."""
        model, data = self.model, self.data
        cam = data.camera(camera)
        origin, axes = cam.xpos.copy(), cam.xmat.reshape(3, 3)
        half_height = math.radians(float(model.camera(camera).fovy[0])) / 2
        half_width = math.atan(math.tan(half_height) * aspect)
        mount = int(model.cam_bodyid[model.camera(camera).id])
        body = self._object_body_ids[state.name]
        top = (state.position[0], state.position[1], state.bbox_max[2] - 0.005)
        hit = np.array([-1], dtype=np.int32)
        for point in (np.array(state.position), np.array(top)):
            ray = point - origin
            depth = -float(ray @ axes[:, 2])  # a MuJoCo camera looks along its -z
            if depth <= 0 or abs(math.atan2(float(ray @ axes[:, 0]), depth)) > half_width or \
                    abs(math.atan2(float(ray @ axes[:, 1]), depth)) > half_height:
                continue
            mujoco.mj_ray(model, data, origin, ray, None, 1, mount, hit)
            if hit[0] >= 0 and model.geom_bodyid[hit[0]] == body:
                return True
        return False

    def _object_state(self, spec: ObjectSpec) -> ObjectState:
        model, data = self.model, self.data
        lows, highs = [], []
        for geom in self._object_geom_ids[spec.name]:
            centre_local, half_local = model.geom_aabb[geom, :3], model.geom_aabb[geom, 3:]
            rotation = data.geom_xmat[geom].reshape(3, 3)
            centre = data.geom_xpos[geom] + rotation @ centre_local
            half = np.abs(rotation) @ half_local
            lows.append(centre - half)
            highs.append(centre + half)
        low, high = np.min(lows, axis=0), np.max(highs, axis=0)
        w, x, y, z = data.xquat[self._object_body_ids[spec.name]]
        return ObjectState(name=spec.name, category=spec.category, color_name=spec.color_name,
                           rgba=scene_objects.rgba(spec.color_name), position=tuple(float(v) for v in (low + high) / 2),
                           orientation_xyzw=(float(x), float(y), float(z), float(w)),
                           bbox_min=tuple(float(v) for v in low), bbox_max=tuple(float(v) for v in high))

    def object_speeds(self) -> dict[str, float]:
        """Linear speed of each object's body [m/s] (to tell whether the scene is at rest)."""
        with self.lock:
            speeds = {}
            for name, body in self._object_body_ids.items():
                adr = self.model.jnt_dofadr[self.model.body_jntadr[body]]
                speeds[name] = float(np.linalg.norm(self.data.qvel[adr:adr + 3]))
            return speeds

    def max_speed(self) -> float:
        """The largest joint speed of the whole model, arm, fingers and objects [m/s or rad/s] (is it still?)."""
        with self.lock:
            return float(np.max(np.abs(self.data.qvel))) if self.model.nv else 0.0

    def _overlapping_object(self, depth: float = OVERLAP_DEPTH) -> str | None:
        """Of the solid objects that reach more than `depth` into another solid object, the one in most such
        overlaps (ties: the later in the reset's list); None when none do."""
        model, data = self.model, self.data
        solid = [spec.name for spec in self.objects if spec.solid]
        counts = dict.fromkeys(solid, 0)
        for i, first in enumerate(solid):
            for second in solid[i + 1:]:
                if any(mujoco.mj_geomDistance(model, data, int(a), int(b), 0.01, None) < -depth
                       for a in self._object_geom_ids[first] for b in self._object_geom_ids[second]):
                    counts[first] += 1
                    counts[second] += 1
        worst = max(counts.items(), key=lambda item: (item[1], solid.index(item[0])), default=(None, 0))
        return worst[0] if worst[1] > 0 else None

    def deepest_object_penetration(self) -> tuple[float, str, str]:
        """(depth [m], geom, geom) of the deepest overlap of an object with the table or another object.

        Computed from the geometry, not from the contact list: objects at rest sleep, and the contacts of
        sleeping objects are not generated. Depth 0 when nothing overlaps.
        """
        with self.lock:
            model, data = self.model, self.data
            table = [model.geom('table').id] if mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_GEOM, 'table') >= 0 \
                else []
            others = table + [int(g) for ids in self._object_geom_ids.values() for g in ids]
            deepest = (0.0, '', '')
            for name, geoms in self._object_geom_ids.items():
                for geom in geoms:
                    for other in others:
                        if model.geom_bodyid[other] == model.geom_bodyid[geom] or other < geom and \
                                self._object_geom_set[other]:
                            continue  # same body, or a pair of object geoms already measured the other way round
                        distance = mujoco.mj_geomDistance(model, data, int(geom), other, 0.01, None)
                        if -distance > deepest[0]:
                            deepest = (float(-distance), model.geom(int(geom)).name, model.geom(other).name)
            return deepest

    # ----------------------------------------------------------------------------------------------- cameras
    @property
    def camera_names(self) -> tuple[str, ...]:
        """The cameras of the current model."""
        with self.lock:
            return tuple(self.model.camera(i).name for i in range(self.model.ncam))

    def camera_intrinsics(self, camera: str, width: int = 640, height: int = 480) -> camera_math.CameraIntrinsics:
        """Pinhole intrinsics of images rendered at width x height from the named camera."""
        with self.lock:
            return camera_math.intrinsics_from_fovy(float(self.model.camera(camera).fovy[0]), width, height)

    def camera_moves(self, camera: str) -> bool:
        """Whether the named camera is on a moving body (the mobile base's head camera) rather than fixed."""
        with self.lock:
            model = self.model
            return bool(model.body_weldid[model.cam_bodyid[model.camera(camera).id]] != 0)

    def camera_mount(self, camera: str) -> tuple[str, np.ndarray] | None:
        """(the body the named camera is fixed to, 'world' for the world body; 4x4 pose of its ROS optical frame in
        that body's frame), constant while the model stays: what a camera's static transform says. None for a
        camera that is not fixed to a body (one that tracks the robot from afar)."""
        with self.lock:
            model = self.model
            index = model.camera(camera).id
            if model.cam_mode[index] != mujoco.mjtCamLight.mjCAMLIGHT_FIXED:
                return None
            body = int(model.cam_bodyid[index])
            body_pose = np.eye(4)
            body_pose[:3, :3], body_pose[:3, 3] = self.data.xmat[body].reshape(3, 3), self.data.xpos[body]
            parent = 'world' if body == 0 else mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_BODY, body)
            return parent, np.linalg.inv(body_pose) @ self.camera_pose(camera)

    def camera_pose(self, camera: str) -> np.ndarray:
        """4x4 world_T_optical of the named camera (ROS optical frame: +z forward, +y down, +x right)."""
        with self.lock:
            cam = self.data.camera(camera)
            return camera_math.optical_pose(cam.xpos.copy(), cam.xmat.copy())

    def render(self, camera: str, width: int = 640, height: int = 480, with_depth: bool = True,
               quality: str = 'fast') -> tuple[np.ndarray, np.ndarray | None]:
        """(rgb uint8 HxWx3, depth float32 HxW [m along the optical axis] or None) from the named camera.

        quality "fast" (no shadows, no anti-aliasing) is what the bridge publishes; "pretty" is for pictures.
        """
        with self.lock:
            renderer = self._renderer(width, height, quality)
            self._show_ink(renderer, (threading.get_ident(), width, height, quality))
            renderer.update(self.data, camera)
        # The scene is a snapshot: drawing it needs no lock, so physics can go on meanwhile.
        return renderer.render(with_depth)

    def _show_ink(self, renderer: RgbdRenderer, key: tuple[int, int, int, str]) -> None:
        """Bring the board's ink texture in `renderer` up to date with the canvas (only when it changed)."""
        ink = self._ink
        if ink is None or ink.texture_id < 0 or self._uploaded_ink.get(key) == ink.canvas.version:
            return
        image, version = ink.canvas.snapshot()
        model = self.model
        address, size = model.tex_adr[ink.texture_id], image.size * 3
        model.tex_data[address:address + size] = ink.canvas.texture_rgb(image).reshape(-1)
        renderer.upload_texture(ink.texture_id)
        self._uploaded_ink[key] = version

    def _renderer(self, width: int, height: int, quality: str) -> RgbdRenderer:
        key = (threading.get_ident(), width, height, quality)
        renderer = self._renderers.get(key)
        if renderer is not None and renderer.model is not self.model:
            renderer.close()
            renderer = None
        if renderer is None:
            renderer = RgbdRenderer(self.model, width, height, quality)
            self._renderers[key] = renderer
            self._uploaded_ink.pop(key, None)
        return renderer

    def close(self) -> None:
        """Free the renderers created by the calling thread."""
        me = threading.get_ident()
        for key in [k for k in self._renderers if k[0] == me]:
            self._renderers.pop(key).close()

