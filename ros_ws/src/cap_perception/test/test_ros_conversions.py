"""Images and object states convert to and from ROS messages without loss."""
import numpy as np
import pytest
from sensor_msgs.msg import Image

from cap_perception.objects import PerceivedObject
from cap_perception.ros_conversions import from_msg, image_to_array, to_msg


def test_object_state_round_trip():
    obj = PerceivedObject.from_fields('cyan', 'bowl', (0.1, -0.45, 0.03), (0.13, 0.13, 0.04), visible=False)
    back = from_msg(to_msg(obj))
    assert back.name == 'cyan bowl' and back.category == 'bowl'
    assert back.position == pytest.approx(obj.position) and back.bbox_max == pytest.approx(obj.bbox_max)
    assert back.visible is False and back.color_rgba == pytest.approx(obj.color_rgba)


def _image(array, encoding, step=None):
    msg = Image(height=array.shape[0], width=array.shape[1], encoding=encoding)
    data = array.tobytes()
    msg.step = step or len(data) // array.shape[0]
    if step:  # rows padded to `step` bytes
        rows = [data[i * (len(data) // array.shape[0]):(i + 1) * (len(data) // array.shape[0])].ljust(step, b'\0')
                for i in range(array.shape[0])]
        data = b''.join(rows)
    msg.data = data
    return msg


def test_colour_images_decode_as_rgb():
    rgb = np.random.default_rng(0).integers(0, 255, (4, 5, 3), dtype=np.uint8)
    assert np.array_equal(image_to_array(_image(rgb, 'rgb8')), rgb)
    assert np.array_equal(image_to_array(_image(rgb[..., ::-1].copy(), 'bgr8')), rgb)
    assert np.array_equal(image_to_array(_image(rgb, 'rgb8', step=16)), rgb)


def test_depth_images_decode_to_metres():
    metres = np.array([[0.5, 1.25], [2.0, 0.0]], dtype=np.float32)
    assert np.array_equal(image_to_array(_image(metres, '32FC1')), metres)
    millimetres = np.array([[500, 1250], [2000, 0]], dtype=np.uint16)
    assert np.allclose(image_to_array(_image(millimetres, '16UC1')), metres)


def test_unsupported_encoding_is_named():
    with pytest.raises(ValueError, match="unsupported image encoding 'yuv422'"):
        image_to_array(_image(np.zeros((2, 2, 2), np.uint8), 'yuv422'))
