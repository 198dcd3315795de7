"""Camera frames for the console: a sensor_msgs/Image's pixels as JPEG, and the latest frame of a topic shared by
every browser watching it. Plain Python (NumPy, OpenCV), no rclpy.

The stream must not slow the simulator down: a topic is subscribed only while a browser watches it (the node asks
`FrameChannel.viewers`), a frame is encoded only when a viewer takes it (at most `max_fps` per viewer, so a fast
simulation's 50 frames a second cost what the page shows), and once per frame however many viewers there are.
"""
from __future__ import annotations

import threading
import time
from dataclasses import dataclass
from typing import Any

import cv2
import numpy as np

# Depth images are shown as grey levels over this range [m]: near is light, far is dark, nothing (0, inf) black.
DEPTH_RANGE_M = (0.2, 2.5)


class UnsupportedImage(ValueError):
    """An image whose encoding the console cannot show."""


@dataclass(frozen=True)
class RawImage:
    """The fields of a sensor_msgs/Image the console needs (so this module needs no message type)."""

    encoding: str
    width: int
    height: int
    step: int
    data: Any  # bytes-like
    stamp_s: float = 0.0  # header stamp [s] (simulated time in the simulator)
    received_s: float = 0.0  # time.time() when it arrived here


_CHANNELS = {'rgb8': 3, 'bgr8': 3, 'rgba8': 4, 'bgra8': 4, 'mono8': 1, '8UC1': 1, '8UC3': 3}


def image_array(image: RawImage) -> np.ndarray:
    """The pixels as an 8-bit BGR (or grey) array OpenCV can encode; UnsupportedImage for other encodings."""
    if image.width <= 0 or image.height <= 0 or image.width * image.height > 4096 * 4096:
        raise UnsupportedImage(f'an image of {image.width} x {image.height} pixels')
    buffer = np.frombuffer(image.data, dtype=np.uint8)
    if image.encoding in _CHANNELS:
        channels = _CHANNELS[image.encoding]
        rows = _rows(buffer, image, image.width * channels)
        pixels = rows.reshape(image.height, image.width, channels) if channels > 1 else rows
        if image.encoding == 'rgb8':
            return cv2.cvtColor(pixels, cv2.COLOR_RGB2BGR)
        if image.encoding == 'rgba8':
            return cv2.cvtColor(pixels, cv2.COLOR_RGBA2BGR)
        if image.encoding == 'bgra8':
            return cv2.cvtColor(pixels, cv2.COLOR_BGRA2BGR)
        return pixels
    if image.encoding in ('32FC1', '16UC1', 'mono16'):
        kind, width = (np.float32, 4) if image.encoding == '32FC1' else (np.uint16, 2)
        values = _rows(buffer, image, image.width * width).copy().view(kind).reshape(image.height, image.width)
        metres = values.astype(np.float32) / (1.0 if image.encoding == '32FC1' else 1000.0)
        near, far = DEPTH_RANGE_M
        grey = np.clip((far - metres) / (far - near), 0.0, 1.0) * 255.0
        grey[~np.isfinite(metres) | (metres <= 0)] = 0.0
        return grey.astype(np.uint8)
    raise UnsupportedImage(f'images encoded {image.encoding!r}')


def _rows(buffer: np.ndarray, image: RawImage, row_bytes: int) -> np.ndarray:
    """The image's rows without the padding `step` may add; UnsupportedImage when the data is too short."""
    step = image.step or row_bytes
    if step < row_bytes or buffer.size < step * (image.height - 1) + row_bytes:
        raise UnsupportedImage('an image with less data than its size says')
    if step == row_bytes:
        return buffer[:row_bytes * image.height]
    return np.lib.stride_tricks.as_strided(buffer, (image.height, row_bytes), (step, 1))


def encode_jpeg(image: RawImage, quality: int = 80) -> bytes:
    """The image as JPEG bytes."""
    ok, encoded = cv2.imencode('.jpg', image_array(image), [cv2.IMWRITE_JPEG_QUALITY, int(quality)])
    if not ok:
        raise UnsupportedImage('an image OpenCV could not encode')
    return encoded.tobytes()


@dataclass(frozen=True)
class Frame:
    """One encoded frame: its number on the channel, JPEG bytes and the source image's times."""

    number: int
    jpeg: bytes
    stamp_s: float
    received_s: float


class FrameChannel:
    """The latest image of one topic, encoded on demand, and who watches it. Thread-safe: `put` comes from a ROS
    callback, `frame` and the viewer count from the web server's threads."""

    def __init__(self, topic: str, quality: int = 80) -> None:
        self.topic = topic
        self.quality = quality
        self.viewers = 0
        self.error = ''  # why the latest image could not be shown ('' when it could)
        self._lock = threading.Lock()
        self._latest: RawImage | None = None
        self._number = 0
        self._encoded: Frame | None = None
        self._listeners: list[Any] = []  # callables told of each new image (no arguments)

    def put(self, image: RawImage) -> None:
        with self._lock:
            self._latest = image
            self._number += 1
            listeners = list(self._listeners)
        for listener in listeners:
            listener()

    @property
    def number(self) -> int:
        """How many images arrived so far."""
        with self._lock:
            return self._number

    def frame(self) -> Frame | None:
        """The latest image as JPEG (encoded once, whoever asks), or None when there is none (or it cannot be
        shown: then `error` says why)."""
        with self._lock:
            if self._encoded is not None and self._encoded.number == self._number:
                return self._encoded
            image, number = self._latest, self._number
        if image is None:
            return None
        try:
            jpeg = encode_jpeg(image, self.quality)  # outside the lock: OpenCV releases the interpreter meanwhile
        except UnsupportedImage as error:
            self.error = f'{self.topic}: cannot show {error}'
            return None
        self.error = ''
        encoded = Frame(number, jpeg, image.stamp_s, image.received_s)
        with self._lock:
            if self._encoded is None or self._encoded.number < number:
                self._encoded = encoded
        return encoded

    def add_listener(self, listener: Any) -> None:
        with self._lock:
            self._listeners.append(listener)

    def remove_listener(self, listener: Any) -> None:
        with self._lock:
            if listener in self._listeners:
                self._listeners.remove(listener)


def now_s() -> float:
    return time.time()


__all__ = ['DEPTH_RANGE_M', 'Frame', 'FrameChannel', 'RawImage', 'UnsupportedImage', 'encode_jpeg', 'image_array',
           'now_s']
