"""Offscreen RGB-D rendering of MuJoCo cameras: colour and metric depth from a single render pass.

mujoco.Renderer draws the scene twice for colour plus depth; here one pass fills both buffers and both are read
at once, which halves the cost on a software OpenGL (llvmpipe) machine. Two qualities: "fast" (no shadows, no
multisampling; what the bridge publishes) and "pretty" (shadows, 4x multisampling; pictures for people).
"""
from __future__ import annotations

import mujoco
import numpy as np

QUALITIES = ('fast', 'pretty')


class RgbdRenderer:
    """Renders one image size of one model. Owns an OpenGL context: use it from the thread that created it."""

    def __init__(self, model: mujoco.MjModel, width: int, height: int, quality: str = 'fast') -> None:
        if quality not in QUALITIES:
            raise ValueError(f'unknown render quality {quality!r}; choose one of {QUALITIES}')
        if width > model.vis.global_.offwidth or height > model.vis.global_.offheight:
            raise ValueError(f'{width}x{height} exceeds the model\'s offscreen buffer '
                             f'{model.vis.global_.offwidth}x{model.vis.global_.offheight}')
        self.model = model
        self.width, self.height = width, height
        self.quality = quality
        self._gl = mujoco.GLContext(width, height)
        self._gl.make_current()
        # Multisampling is a property of the offscreen buffer, fixed when the context is made.
        samples = model.vis.quality.offsamples
        model.vis.quality.offsamples = 4 if quality == 'pretty' else 0
        try:
            self._context = mujoco.MjrContext(model, mujoco.mjtFontScale.mjFONTSCALE_100.value)
        finally:
            model.vis.quality.offsamples = samples
        mujoco.mjr_setBuffer(mujoco.mjtFramebuffer.mjFB_OFFSCREEN.value, self._context)
        self._context.readDepthMap = mujoco.mjtDepthMap.mjDEPTH_ZEROFAR
        self._scene = mujoco.MjvScene(model, maxgeom=2000)
        self._scene.flags[mujoco.mjtRndFlag.mjRND_SHADOW] = quality == 'pretty'
        self._scene.flags[mujoco.mjtRndFlag.mjRND_REFLECTION] = quality == 'pretty'
        self._option = mujoco.MjvOption()
        self._camera = mujoco.MjvCamera()
        self._camera.type = mujoco.mjtCamera.mjCAMERA_FIXED
        self._rect = mujoco.MjrRect(0, 0, width, height)
        extent = model.stat.extent
        self._near = np.float32(model.vis.map.znear * extent)
        self._far = np.float32(model.vis.map.zfar * extent)

    def update(self, data: mujoco.MjData, camera: str) -> None:
        """Take a snapshot of the scene as seen by the named camera (reads data: hold the world's lock)."""
        camera_id = mujoco.mj_name2id(self.model, mujoco.mjtObj.mjOBJ_CAMERA, camera)
        if camera_id < 0:
            raise ValueError(f'no camera named {camera!r}')
        self._camera.fixedcamid = camera_id
        mujoco.mjv_updateScene(self.model, data, self._option, None, self._camera, mujoco.mjtCatBit.mjCAT_ALL,
                               self._scene)

    def upload_texture(self, texture_id: int) -> None:
        """Send the model's texture `texture_id` (changed in model.tex_data) to this renderer's OpenGL context."""
        self._gl.make_current()
        mujoco.mjr_uploadTexture(self.model, self._context, texture_id)

    def render(self, with_depth: bool = True) -> tuple[np.ndarray, np.ndarray | None]:
        """(rgb uint8 HxWx3, depth float32 HxW [m along the optical axis] or None) of the last snapshot."""
        self._gl.make_current()
        mujoco.mjr_render(self._rect, self._scene, self._context)
        rgb = np.empty((self.height, self.width, 3), dtype=np.uint8)
        raw_depth = np.empty((self.height, self.width), dtype=np.float32) if with_depth else None
        mujoco.mjr_readPixels(rgb, raw_depth, self._rect, self._context)
        # OpenGL's rows run bottom-up.
        rgb = np.ascontiguousarray(rgb[::-1])
        if raw_depth is None:
            return rgb, None
        return rgb, np.ascontiguousarray(self._metric_depth(raw_depth)[::-1])

    def _metric_depth(self, raw: np.ndarray) -> np.ndarray:
        """Undo the reversed-Z perspective projection: buffer value -> distance along the optical axis [m]."""
        near, far = self._near, self._far
        c = np.float32(-0.5) * (-(far + near) / (far - near)) - np.float32(0.5)
        d = np.float32(-0.5) * (-(np.float32(2) * far * near) / (far - near))
        return (d / (raw.astype(np.float64) + c)).astype(np.float32)

    def close(self) -> None:
        if self._context is not None:
            self._gl.make_current()
            self._context.free()
            self._context = None
            self._gl.free()
