"""Running a pick-and-place plan's stages on a MuJoCo world directly, the way the ROS node runs them (trajectories
tracked by the simulated servos, gripper commands, checks on what the world then shows), for the physics tests of
the table top and of the mobile manipulator. Imported by those tests from this folder (not a test module itself).
"""
import numpy as np

from cap_control.pick_place.plan import (
    GripperStep, ObjectInfo, Observation, PickPlaceErrorCode, PickPlacePlan, TrajectoryStep, yaw_of_quaternion,
)

SETTLE = 0.3  # [s] after a trajectory's end before the next stage


def object_info(world, name: str) -> ObjectInfo:
    state = world.object_state(name)
    return ObjectInfo.from_bounding_box(name, state.bbox_min, state.bbox_max, state.category,
                                        yaw_of_quaternion(*state.orientation_xyzw))


def run_gripper(world, step: GripperStep, observation: Observation) -> None:
    world.command_gripper(step.position, step.max_effort)
    # The commanded opening ramps at the finger speed; after the ramp, wait until the fingers stop (on the object
    # or at the commanded opening).
    while world.gripper_state().reference_moving:
        world.run_for(0.02)
    world.run_for(0.05)
    for _ in range(100):
        if world.gripper_state().speed < 1e-3:
            break
        world.run_for(0.02)
    state = world.gripper_state()
    observation.gripper_position = state.opening
    observation.gripper_stalled = state.opening > state.target_opening + 0.002


def run_trajectory(world, plan: PickPlacePlan, step: TrajectoryStep) -> bool:
    """Track the step; True if it stopped on contact."""
    trajectory = plan.trajectory_for(step, world.joint_positions())
    if len(trajectory) < 2:
        return False
    end = world.follow_trajectory(trajectory.times, trajectory.positions, trajectory.velocities)
    while world.time < end + SETTLE:
        world.step(5)
        if step.stop_on_contact:
            desired, _ = world.reference()
            if np.max(np.abs(desired - world.joint_positions())) > step.contact_tolerance:
                world.hold()
                world.run_for(SETTLE)
                return True
    return False


def execute(world, plan: PickPlacePlan) -> tuple[PickPlaceErrorCode, str, list[str]]:
    observation = Observation()
    stages_run = []
    for stage in plan.stages:
        stages_run.append(stage.name.value)
        for step in stage.steps:
            if isinstance(step, TrajectoryStep):
                run_trajectory(world, plan, step)
            else:
                run_gripper(world, step, observation)
        if stage.checks and not any(isinstance(step, GripperStep) for step in stage.steps):
            observation.gripper_position = world.gripper_state().opening  # the fingers now, as /joint_states has it
        if any(check.needs_object_position for check in stage.checks):
            observation.object_position = world.object_state(plan.object.name).position
        for check in stage.checks:
            failure = check.failure(observation)
            if failure:
                return stage.failure_code, failure, stages_run
    return PickPlaceErrorCode.NONE, '', stages_run


