"""Recompositing (Zubiaga et al. 2016, eqs. 3–5) drawn through Blender's own ``gpu`` module.

The same shader files as the moderngl path (``shaders/rokeby_recomposite_{vert,frag}.glsl``),
compiled by ``glsl.create_shader`` from the one declared interface
``gl.RECOMPOSITE_INTERFACE``; a fullscreen triangle into a ``GPUOffScreen`` with an
RGBA32F colour buffer, read back as float32. Arguments and result are those of
``rokeby_native.recomposite``: (image (H, W, 3) float32, {"edited", "masked"}).

Needs a GPU context: inside Blender's UI there always is one; in background mode (bpy as a
module, ``blender -b``) the ``gpu`` module has none until something has drawn — one EEVEE render
makes it (``ensure_context``). Nothing here touches ``gpu`` at import time.

Blender specifics (4.5):

* Its Python API has no way to write into an existing ``GPUTexture``, so a frame makes new
  textures — all of them for a new frame, only the edited normals for the next frame of an
  interactive session (``compositing.RecompositeSession``); the shader, the batch, the offscreen buffer, the read-back buffer and the RGBA staging
  arrays are kept between frames of one size.
* There is no RGB32F texture format: RGB buffers are padded into RGBA32F staging arrays (the
  shader reads ``.rgb``); ids are R32F (integer textures need an INT buffer, which
  ``GPUTexture`` does not take) — exact below 2^24, as in the moderngl path.
* The reflection maps are one 2D array texture (``layers=``), layer 2p + face.
* ``gpu.types.Buffer`` wraps a contiguous numpy array without a copy; ``read_color`` fills a
  flat Buffer (a multi-dimensional Buffer's buffer protocol reports Fortran strides, so
  ``np.asarray`` of ``texture.read()`` would transpose it).
"""

from __future__ import annotations

import time
import weakref

import numpy as np

from .errors import CompositingError
from .gl import RECOMPOSITE_INTERFACE, RECOMPOSITE_INTERFACE_NAME, frame_result, recomposite_files, recomposite_frame


class NoGPUContext(RuntimeError):
    """Blender's ``gpu`` module cannot draw in this process (background mode before any render)."""


def _gpu():
    import gpu  # noqa: PLC0415

    try:
        gpu.capabilities.max_texture_size_get()
    except SystemError as exc:
        raise NoGPUContext(
            f"Blender's gpu module has no context here ({exc}): in background mode render one frame with "
            "EEVEE first (rokeby.recomposite_gpu.ensure_context()), or use the CPU path (backend='cpu')") from None
    return gpu


def has_context() -> bool:
    """Whether Blender's ``gpu`` module can draw in this process now."""
    try:
        _gpu()
    except (NoGPUContext, ImportError):
        return False
    return True


def ensure_context() -> None:
    """Makes Blender's GPU context in background mode if there is none: one 8×8 EEVEE render of a
    temporary scene (with its own camera), which is removed again. Tens of seconds on a software
    renderer (EEVEE compiles its shaders); nothing when a context exists (always, in Blender with a
    window). Side effect in background mode: the "Render Result" image then holds that 8×8 render
    (render the frame you want after this, or read its passes from an EXR first)."""
    if has_context():
        return
    import bpy  # noqa: PLC0415

    from ..blender import compat  # noqa: PLC0415

    scene = bpy.data.scenes.new("rokeby_gpu_context")
    cam_data = bpy.data.cameras.new("rokeby_gpu_context")
    cam = bpy.data.objects.new("rokeby_gpu_context", cam_data)
    try:
        scene.collection.objects.link(cam)
        scene.camera = cam
        scene.render.engine = compat.eevee_engine()
        scene.render.resolution_x = scene.render.resolution_y = 8
        scene.render.resolution_percentage = 100
        window = bpy.context.window
        if window is not None:
            with bpy.context.temp_override(window=window, scene=scene):
                bpy.ops.render.render(scene=scene.name)
        else:
            bpy.ops.render.render(scene=scene.name)
    finally:
        bpy.data.objects.remove(cam)
        bpy.data.cameras.remove(cam_data)
        bpy.data.scenes.remove(scene)
    _gpu()  # still none: say so


class BlenderRecompositor:
    """The recompositing shader drawn by Blender's ``gpu`` module into an RGBA32F offscreen buffer.
    Call it with ``rokeby_native.recomposite``'s arguments. Make it (and call it) only where a GPU
    context exists (see ``ensure_context``)."""

    def __init__(self):
        gpu = _gpu()
        from ..blender import gpu as glsl  # noqa: PLC0415

        self.shader = glsl.create_shader(RECOMPOSITE_INTERFACE, RECOMPOSITE_INTERFACE_NAME, recomposite_files())
        fmt = gpu.types.GPUVertFormat()
        fmt.attr_add(id="rk_unused", comp_type="F32", len=1, fetch_mode="FLOAT")  # the vertex stage uses gl_VertexID
        vbo = gpu.types.GPUVertBuf(fmt, 3)
        vbo.attr_fill("rk_unused", [0.0, 0.0, 0.0])
        self.batch = gpu.types.GPUBatch(type="TRIS", buf=vbo)
        self.max_size = int(gpu.capabilities.max_texture_size_get())
        self.max_layers = int(gpu.capabilities.max_texture_layers_get())
        self.max_samplers = int(gpu.capabilities.max_textures_frag_get())
        if self.max_samplers < len(RECOMPOSITE_INTERFACE["sampler"]):
            raise NoGPUContext(f"this GPU offers {self.max_samplers} fragment textures; recompositing reads "
                               f"{len(RECOMPOSITE_INTERFACE['sampler'])}")
        self.renderer = gpu.platform.renderer_get()
        self._size = None
        self._offscreen = None
        self._read = None
        self._staging: dict = {}
        self.textures: dict = {}  # the last frame's, kept for the next one (see draw's ``changed``)
        self._frame = None  # a weak reference to the frame those textures hold
        self.uploads = 0  # textures made so far
        self.timings: dict = {}  # the last frame's stages, seconds

    def _rgba(self, name: str, data: np.ndarray) -> np.ndarray:
        """``data`` (..., 3) or (...,) as a contiguous float32 array Blender can take (RGBA or R)."""
        if data.ndim == 2:  # R32F
            return np.ascontiguousarray(data, np.float32)
        shape = data.shape[:-1] + (4,)
        st = self._staging.get(name)
        if st is None or st.shape != shape:
            st = self._staging[name] = np.zeros(shape, np.float32)
        st[..., :3] = data
        return st

    def _texture(self, gpu, name: str, data: np.ndarray, array: bool):
        a = self._rgba(name, data)
        self.uploads += 1
        buf = gpu.types.Buffer("FLOAT", a.size, a.reshape(-1))
        fmt = "R32F" if a.ndim == 2 else "RGBA32F"
        if array:  # (layers, S, S, 4)
            return gpu.types.GPUTexture((a.shape[2], a.shape[1]), layers=a.shape[0], format=fmt, data=buf)
        return gpu.types.GPUTexture((a.shape[1], a.shape[0]), format=fmt, data=buf)

    def __call__(self, *args, **kw):
        t0 = time.perf_counter()
        return self.draw(recomposite_frame(*args, **kw), t0=t0)

    def draw(self, f, changed=None, *, t0=None):
        """Draws the packed frame ``f`` (``compositing.recomposite_frame``). ``changed``: the names of
        the textures that differ from the last frame drawn, when that was ``f`` itself (an
        interactive session's, ``compositing.RecompositeSession``): only those are made again, the
        other textures stay on the GPU. None, or a different frame, makes all of them."""
        t0 = time.perf_counter() if t0 is None else t0
        f.check_limits(self.max_size, self.max_layers, f"this GPU ({self.renderer})")
        gpu = _gpu()
        h, w = f.height, f.width
        if self._offscreen is None or self._size != (w, h):
            if self._offscreen is not None:
                self._offscreen.free()
            self._offscreen = gpu.types.GPUOffScreen(w, h, format="RGBA32F")
            self._read = gpu.types.Buffer("FLOAT", w * h * 4)
            self._size = (w, h)
        t1 = time.perf_counter()
        same = self._frame is not None and self._frame() is f and set(self.textures) == set(f.textures)
        self._frame = None  # until every texture of f is made: a failure here leaves no frame claimed
        for _unit, t, name in RECOMPOSITE_INTERFACE["sampler"]:
            if changed is None or not same or name in changed:
                self.textures[name] = self._texture(gpu, name, f.textures[name], t == "FLOAT_2D_ARRAY")
        self._frame = weakref.ref(f)
        t2 = time.perf_counter()
        sh = self.shader
        with self._offscreen.bind():
            fb = gpu.state.active_framebuffer_get()
            gpu.state.depth_test_set("NONE")
            gpu.state.depth_mask_set(False)
            gpu.state.blend_set("NONE")
            gpu.state.viewport_set(0, 0, w, h)
            sh.bind()
            for name, tex in self.textures.items():
                sh.uniform_sampler(name, tex)
            for t, name in RECOMPOSITE_INTERFACE["push_constant"]:
                val = f.uniforms[name]
                if t in ("INT", "IVEC2", "IVEC3", "IVEC4"):
                    sh.uniform_int(name, val)
                else:
                    sh.uniform_float(name, val)
            self.batch.draw(sh)
            t3 = time.perf_counter()
            fb.read_color(0, 0, w, h, 4, 0, "FLOAT", data=self._read)  # waits for the draw
        t4 = time.perf_counter()
        result = frame_result(np.asarray(self._read, dtype=np.float32).reshape(h, w, 4))
        t5 = time.perf_counter()
        self.timings = {"prepare": t1 - t0, "textures": t2 - t1, "draw_submit": t3 - t2, "draw_read": t4 - t3,
                        "result": t5 - t4, "total": t5 - t0}
        return result

    def free(self) -> None:
        if self._offscreen is not None:
            self._offscreen.free()
        self._offscreen = self._read = None
        self._size = None
        self.textures = {}
        self._frame = None
        self._staging = {}


_BLENDER: BlenderRecompositor | None = None


def blender_recompositor() -> BlenderRecompositor:
    """The process's recompositor on Blender's GPU context, made on first use."""
    global _BLENDER
    if _BLENDER is None:
        _BLENDER = BlenderRecompositor()
    return _BLENDER


def recomposite_blender(ids, normals, edited_normals, view, diffuse, reflection, image, patches, **kw):
    """Eqs. 3–5 by the GLSL shader drawn through Blender's ``gpu`` module: the arguments and the result
    (image (H, W, 3) float32, {"edited", "masked"}) of ``rokeby_native.recomposite``. Bad inputs raise
    ``CompositingError`` naming the argument; no GPU context raises ``NoGPUContext``."""
    return blender_recompositor()(ids, normals, edited_normals, view, diffuse, reflection, image, patches, **kw)


__all__ = ["BlenderRecompositor", "CompositingError", "NoGPUContext", "blender_recompositor", "ensure_context",
           "has_context", "recomposite_blender"]
