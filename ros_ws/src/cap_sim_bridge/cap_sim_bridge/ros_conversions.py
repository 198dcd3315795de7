"""Conversions between the world's plain data and ROS messages (message types only, no rclpy)."""
from __future__ import annotations

import math

from typing import Sequence

import cv2  # opencv-python-headless, pinned: the PNG encoder the ink image uses too
import numpy as np
from geometry_msgs.msg import Point, PoseStamped, Quaternion
from scipy.spatial.transform import Rotation
from sensor_msgs.msg import CameraInfo, CompressedImage, Image, JointState
from std_msgs.msg import ColorRGBA, Header

from cap_interfaces.msg import ObjectSpec as ObjectSpecMsg
from cap_interfaces.msg import ObjectState as ObjectStateMsg
from cap_ros_common.time import time_msg
from cap_sim_bridge.camera import CameraIntrinsics
from cap_sim_bridge.objects import ObjectSpec
from cap_sim_bridge.world import ObjectState

WORLD_FRAME = 'world'
# REP-105's frames of a mobile base: the map, the odometry's origin (both the world in the simulator).
MAP_FRAME = 'map'
ODOM_FRAME = 'odom'


def optical_frame_id(camera: str) -> str:
    return f'{camera}_optical_frame'


def header(seconds: float, frame_id: str = WORLD_FRAME) -> Header:
    return Header(stamp=time_msg(seconds), frame_id=frame_id)


def object_state_msg(state: ObjectState) -> ObjectStateMsg:
    return ObjectStateMsg(
        name=state.name, category=state.category, color_name=state.color_name,
        color=ColorRGBA(r=state.rgba[0], g=state.rgba[1], b=state.rgba[2], a=state.rgba[3]),
        position=Point(x=state.position[0], y=state.position[1], z=state.position[2]),
        orientation=Quaternion(x=state.orientation_xyzw[0], y=state.orientation_xyzw[1],
                               z=state.orientation_xyzw[2], w=state.orientation_xyzw[3]),
        bbox_min=Point(x=state.bbox_min[0], y=state.bbox_min[1], z=state.bbox_min[2]),
        bbox_max=Point(x=state.bbox_max[0], y=state.bbox_max[1], z=state.bbox_max[2]),
        visible=state.visible)


def object_spec(msg: ObjectSpecMsg) -> ObjectSpec:
    """A reset request's object; a missing category or colour is read from the name ("red block"), a missing
    name is made of them."""
    name = msg.name.strip().lower() or f'{msg.color_name} {msg.category}'
    from_name = ObjectSpec.from_name(name)
    return ObjectSpec(name=name, category=msg.category or from_name.category,
                      color_name=msg.color_name or from_name.color_name,
                      position=(msg.position.x, msg.position.y) if msg.use_position else None,
                      height=msg.position.z if msg.use_position and msg.use_height else None,
                      yaw=msg.yaw if msg.use_position and math.isfinite(msg.yaw) else 0.0, solid=not msg.ghost)


def joint_state_msg(seconds: float, names: Sequence[str], positions: np.ndarray, velocities: np.ndarray,
                    efforts: np.ndarray) -> JointState:
    return JointState(header=header(seconds, ''), name=list(names), position=positions.tolist(),
                      velocity=velocities.tolist(), effort=efforts.tolist())


def color_image_msg(seconds: float, camera: str, rgb: np.ndarray) -> Image:
    height, width, _ = rgb.shape
    return Image(header=header(seconds, optical_frame_id(camera)), height=height, width=width, encoding='rgb8',
                 is_bigendian=0, step=width * 3, data=np.ascontiguousarray(rgb).tobytes())


def png_image_msg(seconds: float, camera: str, rgb: np.ndarray) -> CompressedImage:
    """An RGB picture as a PNG (the twin's view on /cap/status: small, lossless)."""
    ok, encoded = cv2.imencode('.png', np.ascontiguousarray(rgb[..., ::-1]))
    if not ok:
        raise RuntimeError('could not encode the picture as PNG')
    return CompressedImage(header=header(seconds, optical_frame_id(camera)), format='png', data=encoded.tobytes())


def depth_image_msg(seconds: float, camera: str, depth: np.ndarray) -> Image:
    """32FC1 depth in metres along the optical axis (REP 118)."""
    height, width = depth.shape
    depth = np.ascontiguousarray(depth, dtype='<f4')
    return Image(header=header(seconds, optical_frame_id(camera)), height=height, width=width, encoding='32FC1',
                 is_bigendian=0, step=width * 4, data=depth.tobytes())


def depth_mm_image_msg(seconds: float, camera: str, millimetres: np.ndarray) -> Image:
    """16UC1 depth in millimetres, 0 where nothing was measured: what a RealSense's driver sends."""
    height, width = millimetres.shape
    data = np.ascontiguousarray(millimetres, dtype='<u2')
    return Image(header=header(seconds, optical_frame_id(camera)), height=height, width=width, encoding='16UC1',
                 is_bigendian=0, step=width * 2, data=data.tobytes())


def ink_image_msg(seconds: float, ink: np.ndarray) -> Image:
    """A whiteboard's ink image: mono8, 255 = ink, row 0 = the board's top edge (GraphNames.SIM_INK_TOPIC)."""
    height, width = ink.shape
    return Image(header=header(seconds, 'whiteboard'), height=height, width=width, encoding='mono8',
                 is_bigendian=0, step=width, data=np.ascontiguousarray(ink, dtype=np.uint8).tobytes())


def camera_info_msg(seconds: float, camera: str, intrinsics: CameraIntrinsics) -> CameraInfo:
    k = intrinsics
    return CameraInfo(header=header(seconds, optical_frame_id(camera)), height=k.height, width=k.width,
                      distortion_model='plumb_bob', d=[0.0] * 5,
                      k=[k.fx, 0.0, k.cx, 0.0, k.fy, k.cy, 0.0, 0.0, 1.0],
                      r=[1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0],
                      p=[k.fx, 0.0, k.cx, 0.0, 0.0, k.fy, k.cy, 0.0, 0.0, 0.0, 1.0, 0.0])


def pose_stamped_msg(seconds: float, pose: np.ndarray) -> PoseStamped:
    """A 4x4 world_T_frame as a PoseStamped in the world frame."""
    x, y, z, w = Rotation.from_matrix(pose[:3, :3]).as_quat()
    msg = PoseStamped(header=header(seconds))
    msg.pose.position = Point(x=float(pose[0, 3]), y=float(pose[1, 3]), z=float(pose[2, 3]))
    msg.pose.orientation = Quaternion(x=float(x), y=float(y), z=float(z), w=float(w))
    return msg
