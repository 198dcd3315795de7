"""The drawing tool the UR5e carries: a spring-loaded marker along the flange's axis and an eraser on its side.

Frames: the flange is DH frame 6 of the UR5e (its +z axis points away from the wrist). A tool's frame has its
origin at the point that touches the board and its +z axis pointing from the tool into the board, so a tool pose
with z down (world -z) at a point of the board is the pose of touching it there.

- **Marker**: a pen along the flange's +z axis, its tip MARKER_TIP_OFFSET from the flange when the spring is at
  rest. The pen slides back into its holder against a preloaded spring (like a pen plotter's), so a tool held a few
  millimetres too low still draws with a gentle, nearly even force; the path follower presses it in by
  MARKER_PRESS and keeps the compression within MARKER_COMPRESSION_BAND. The gripper's fingers hold the pen's
  barrel (closed to GRIP_OPENING), so nothing but the pen reaches down near the objects on the board.
- **Eraser**: a felt pad on the side of the tool, facing the flange's +x axis, also on a preloaded spring. To erase,
  the wrist turns the tool a quarter turn so that the pad faces the board; the marker then points sideways, well
  above the board.

Ink is laid where the marker's tip touches the board, MARKER_TIP_WIDTH wide; the pad wipes what it covers.
"""
from __future__ import annotations

import numpy as np

TOOL_MARKER = 'marker'
TOOL_ERASER = 'eraser'
TOOLS = (TOOL_MARKER, TOOL_ERASER)
# The sprung slides of the tool, as the robot's joint states name them (position = minus the spring's compression).
MARKER_JOINT = 'marker_joint'
ERASER_JOINT = 'eraser_joint'

# Tip from the flange along its +z, spring at rest [m]: 8 cm beyond the fingertips, so that the fingers pass over the
# objects a shape is drawn around (an apple is 6 cm tall).
MARKER_TIP_OFFSET = 0.24
MARKER_TIP_WIDTH = 0.003  # width of the line the tip draws [m]
MARKER_RADIUS = 0.008  # the pen's barrel [m]
GRIP_OPENING = 2 * MARKER_RADIUS  # the fingers closed on the barrel [m]
MARKER_TRAVEL = 0.008  # how far the pen can slide back into its holder [m]
MARKER_STIFFNESS = 300.0  # spring [N/m]
MARKER_PRELOAD = 0.6  # spring force with the pen fully out [N]: a touch below it does not move the pen
MARKER_PRESS = 0.003  # how far the path follower presses the pen in while drawing [m]
MARKER_COMPRESSION_BAND: tuple[float, float] = (0.0005, 0.0065)  # compression kept while drawing [m]

# The pad's face from the flange's axis, along the flange's +x [m]: far enough that, with the pad on the board, the
# wrist passes 2 cm over the tallest object standing on it (an orange, 8 cm over the table).
ERASER_FACE_OFFSET = 0.14
ERASER_FACE_HEIGHT = 0.05  # the pad's centre along the flange's +z [m]
ERASER_PAD_SIZE: tuple[float, float] = (0.03, 0.06)  # the face: along the flange's z, along its y [m]
ERASER_THICKNESS = 0.02
ERASER_TRAVEL = 0.008
ERASER_STIFFNESS = 500.0
ERASER_PRELOAD = 1.0
ERASER_PRESS = 0.003
ERASER_COMPRESSION_BAND: tuple[float, float] = (0.0005, 0.0065)


def flange_to_tool(tool: str) -> np.ndarray:
    """4x4 flange_T_tool: the touching point and axes of `tool` ('marker' or 'eraser') in the flange frame."""
    transform = np.eye(4)
    if tool == TOOL_MARKER:
        transform[2, 3] = MARKER_TIP_OFFSET
    elif tool == TOOL_ERASER:
        # Tool z along the flange's +x (the pad's normal), tool y along the flange's y, tool x = -flange z.
        transform[:3, :3] = np.array([[0.0, 0.0, 1.0], [0.0, 1.0, 0.0], [-1.0, 0.0, 0.0]])
        transform[:3, 3] = [ERASER_FACE_OFFSET, 0.0, ERASER_FACE_HEIGHT]
    else:
        raise ValueError(f'unknown tool {tool!r}; tools: {", ".join(TOOLS)}')
    return transform


def tool_joint(tool: str) -> str:
    """The joint of `tool`'s sprung slide."""
    return MARKER_JOINT if tool == TOOL_MARKER else ERASER_JOINT


def press_depth(tool: str) -> float:
    """How far the path follower presses `tool` into the board while drawing or erasing [m]."""
    return MARKER_PRESS if tool == TOOL_MARKER else ERASER_PRESS


def compression_band(tool: str) -> tuple[float, float]:
    """(least, most) spring compression of `tool` allowed while in contact [m]."""
    return MARKER_COMPRESSION_BAND if tool == TOOL_MARKER else ERASER_COMPRESSION_BAND


__all__ = ['ERASER_COMPRESSION_BAND', 'ERASER_FACE_HEIGHT', 'ERASER_FACE_OFFSET', 'ERASER_JOINT', 'ERASER_PAD_SIZE',
           'ERASER_PRELOAD', 'ERASER_PRESS', 'ERASER_STIFFNESS', 'ERASER_THICKNESS', 'ERASER_TRAVEL', 'GRIP_OPENING',
           'MARKER_COMPRESSION_BAND', 'MARKER_JOINT', 'MARKER_PRELOAD', 'MARKER_PRESS', 'MARKER_RADIUS',
           'MARKER_STIFFNESS', 'MARKER_TIP_OFFSET', 'MARKER_TIP_WIDTH', 'MARKER_TRAVEL', 'TOOLS', 'TOOL_ERASER',
           'TOOL_MARKER', 'compression_band', 'flange_to_tool', 'press_depth', 'tool_joint']
