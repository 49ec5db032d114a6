"""The GLSL path of recompositing (Zubiaga et al. 2016, §4, eqs. 3–5): the shader's declared
interface and sources (``shaders/rokeby_recomposite_{vert,frag}.glsl``), one frame's inputs packed
for it (``RecompositeFrame``), the checks both GPU backends share, and the moderngl backend
(``GLRecompositor``). Blender's ``gpu`` backend is ``compositing/blender_gpu.py``; both are reached
through ``rokeby.compositing`` (``recomposite(..., backend=...)``, ``RecompositeSession``).
"""

from __future__ import annotations

import math
import weakref
from dataclasses import dataclass

import numpy as np

from .errors import CompositingError


# --- the GLSL path: shaders/rokeby_recomposite_{vert,frag}.glsl ---------------------------------

# The recompositing shader's interface in GPUShaderCreateInfo's terms, declared once: Blender compiles
# the files in shaders/ (bodies only) with it through ``glsl.create_shader`` (rokeby.compositing.blender_gpu),
# and ``glsl.standalone_from`` makes their #version header for plain OpenGL (moderngl) from it.
# Every texture is float (ids too: exact below 2^24); RGB data may sit in RGB or RGBA textures.
RECOMPOSITE_FILES = {"vertex": "rokeby_recomposite_vert.glsl", "fragment": "rokeby_recomposite_frag.glsl"}
RECOMPOSITE_INTERFACE = {
    "vertex_in": [],  # a fullscreen triangle from gl_VertexID
    "vertex_out": [],
    # (k_D, k_R, γ, 2 sin(ε/2)), 1/ε, (view per pixel, c_D given, c_R given), the one view vector.
    "push_constant": [("VEC4", "rk_params"), ("FLOAT", "rk_inv_eps"), ("IVEC3", "rk_flags"), ("VEC3", "rk_view_const"),
                      ("INT", "rk_npatches")],
    "sampler": [(0, "FLOAT_2D", "rk_ids"), (1, "FLOAT_2D", "rk_normals"), (2, "FLOAT_2D", "rk_edited"),
                (3, "FLOAT_2D", "rk_view"), (4, "FLOAT_2D", "rk_diffuse"), (5, "FLOAT_2D", "rk_reflection"),
                (6, "FLOAT_2D", "rk_image"), (7, "FLOAT_2D", "rk_alphas"), (8, "FLOAT_2D", "rk_dcolor"),
                (9, "FLOAT_2D", "rk_rcolor"), (10, "FLOAT_2D", "rk_sh"), (11, "FLOAT_2D_ARRAY", "rk_env")],
    "uniform_buf": [],
    "fragment_out": [(0, "VEC4", "rk_out")],
}
RECOMPOSITE_INTERFACE_NAME = "rokeby_recomposite_iface"


def recomposite_files() -> dict:
    """The recompositing shader's sources as ``glsl.create_shader`` / ``glsl.standalone_from`` take
    them (no types block, no library: the fragment file holds its helpers)."""
    from ..core import shaders as glsl

    d = glsl.shader_dir()
    return {"types": "", "lib": "", "vertex": (d / RECOMPOSITE_FILES["vertex"]).read_text(),
            "fragment": (d / RECOMPOSITE_FILES["fragment"]).read_text()}


def recomposite_sources(version: str = "330 core") -> tuple[str, str]:
    """(vertex, fragment) GLSL of the recompositing pass for a plain OpenGL context."""
    from ..core import shaders as glsl

    return glsl.standalone_from(RECOMPOSITE_INTERFACE, recomposite_files(), version)


def _gpu_image(a, name: str, h: int | None, w: int | None, channels: int) -> np.ndarray:
    try:
        a = np.asarray(a, np.float32)
    except (TypeError, ValueError) as exc:
        raise CompositingError(f"{name}: expected a numeric array ({exc})") from None
    want = (h, w, 3) if channels == 3 else (h, w)
    if h is None:
        if a.ndim != 3 or a.shape[2] != 3 or 0 in a.shape:
            raise CompositingError(f"{name}: expected shape (H, W, 3), got {a.shape}")
    elif a.shape != want:
        raise CompositingError(f"{name}: expected shape {want} like normals, got {a.shape}")
    return np.ascontiguousarray(a)


def _gpu_patches(patches) -> tuple[np.ndarray, np.ndarray]:
    """The SH table (P, 10, 3) and the reflection maps (2P, S, S, 3) of `patches`."""
    if not isinstance(patches, list):
        raise CompositingError("patches: must be a list of dicts {'sh': (3, 9) or None, 'env': (2, S, S, 3) or None}")
    table = np.zeros((max(len(patches), 1), 10, 3), np.float32)
    maps: dict[int, np.ndarray] = {}
    for k, item in enumerate(patches):
        name = f"patches[{k}]"
        if item is None:
            continue
        if not isinstance(item, dict):
            raise CompositingError(f"{name}: must be a dict or None")
        sh, env = item.get("sh"), item.get("env")
        if sh is not None:
            sh = np.asarray(sh, np.float64)
            if sh.shape != (3, 9) or not np.isfinite(sh).all():
                raise CompositingError(f"{name}.sh: expected finite coefficients of shape (3, 9), got {sh.shape}")
            table[k, :9] = sh.T
            table[k, 9, 0] = 1.0
        if env is not None:
            env = np.asarray(env, np.float32)
            if env.ndim != 4 or env.shape[0] != 2 or env.shape[1] != env.shape[2] or env.shape[1] < 1:
                raise CompositingError(f"{name}.env: expected a dual-paraboloid map of shape (2, S, S, 3), got {env.shape}")
            if env.shape[3] != 3:
                raise CompositingError(f"{name}.env: expected 3 channels, got {env.shape[3]}")
            maps[k] = env
            table[k, 9, 1] = 1.0
    sizes = {m.shape[1] for m in maps.values()}
    if len(sizes) > 1:
        raise CompositingError(f"patches: the GLSL path needs one reflection-map size for all patches, got {sorted(sizes)}")
    s = sizes.pop() if sizes else 1
    layers = np.zeros((2 * max(len(patches), 1), s, s, 3), np.float32)
    for k, m in maps.items():
        layers[2 * k:2 * k + 2] = m
    return table, layers


@dataclass
class RecompositeFrame:
    """One frame's inputs for the recompositing shader, validated: the contents of every sampler of
    ``RECOMPOSITE_INTERFACE`` by name (float32; (H, W) for rk_ids, (H, W, 3) for images, (P, 10, 3)
    for rk_sh, (2P, S, S, 3) for rk_env) and the push-constant values."""

    height: int
    width: int
    textures: dict
    uniforms: dict
    n_patches: int

    def set_edit(self, edited_normals, k_d: float, k_r: float) -> None:
        """Replaces the edited normals and k_D, k_R (checked as ``recomposite_frame`` checks them):
        what changes from one frame of an interactive session to the next (``RecompositeSession``)."""
        e = _gpu_image(edited_normals, "edited_normals", self.height, self.width, 3)
        _check_k(k_d, k_r)
        self.textures["rk_edited"] = e
        _k_d, _k_r, gamma, chord = self.uniforms["rk_params"]
        self.uniforms["rk_params"] = (float(k_d), float(k_r), gamma, chord)

    def check_limits(self, max_size: int, max_layers: int, device: str) -> None:
        layers = self.textures["rk_env"].shape[0]
        if layers > max_layers:
            raise CompositingError(f"patches: {self.n_patches} patches need {layers} texture layers; {device} has {max_layers}")
        rows = self.textures["rk_sh"].shape[0]
        if max(self.height, self.width, rows, self.textures["rk_env"].shape[1]) > max_size:
            raise CompositingError(f"image: {self.width}×{self.height} (or {rows} patches, or the reflection maps) exceed "
                                   f"{device}'s texture size {max_size}")


# Largest |k_D|, |k_R| (intensity factors of eq. 5): far beyond any useful edit, small enough that
# no finite rendered value times it overflows float32 in practice (the output is checked as well).
MAX_K = 1e4


def _check_k(k_d, k_r) -> None:
    for name, x in (("k_d", k_d), ("k_r", k_r)):
        if isinstance(x, bool) or not isinstance(x, (int, float, np.integer, np.floating)):
            raise TypeError(f"{name}: expected a number, got {x!r}")
        if not (math.isfinite(x) and abs(x) <= MAX_K):
            raise CompositingError(f"{name}: must be finite and at most {MAX_K:g} in size, got {x}")


def _check_output(out, image) -> None:
    """Never inf/NaN out of finite input: a pixel that is finite in the rendered image must be
    finite in the recomposited one."""
    img = np.asarray(out[0] if isinstance(out, tuple) else out)[..., :3]
    if np.isfinite(img).all():  # the common case: one pass
        return
    bad = ~np.isfinite(img) & np.isfinite(np.asarray(image)[..., :3])
    if bad.any():
        raise CompositingError(f"the recomposited image has {int(bad.any(-1).sum())} non-finite pixels where the render is "
                               "finite (k_d, k_r or the edit too large for float32?); nothing was written")


def recomposite_frame(ids, normals, edited_normals, view, diffuse, reflection, image, patches, alpha_d=None,
                      alpha_r=None, alpha=None, diffuse_color=None, reflection_color=None, k_d=1.0, k_r=1.0, gamma=1.0,
                      epsilon=0.005 * math.pi) -> RecompositeFrame:
    """``rokeby_native.compositing.recomposite``'s arguments checked (a ``CompositingError`` names the wrong one)
    and packed as the shader's textures and push constants; shared by every GLSL backend."""
    n = _gpu_image(normals, "normals", None, None, 3)
    h, w = n.shape[:2]
    e = _gpu_image(edited_normals, "edited_normals", h, w, 3)
    ids_a = np.asarray(ids)
    if ids_a.shape != (h, w):
        raise CompositingError(f"ids: expected shape ({h}, {w}) like normals, got {ids_a.shape}")
    if ids_a.dtype.kind not in "iuf":
        raise CompositingError(f"ids: expected integer patch indices, got dtype {ids_a.dtype}")
    ids_f = ids_a.astype(np.float32)
    ids_f[~np.isfinite(ids_f)] = -1.0
    v = np.asarray(view, np.float32)
    if v.shape not in ((3,), (h, w, 3)):
        raise CompositingError(f"view: expected shape (3,) or ({h}, {w}, 3), got {v.shape}")
    d0 = _gpu_image(diffuse, "diffuse", h, w, 3)
    r0 = _gpu_image(reflection, "reflection", h, w, 3)
    img = _gpu_image(image, "image", h, w, 3)
    al = np.ones((h, w, 3), np.float32)
    for c, (a, name) in enumerate(((alpha_d, "alpha_d"), (alpha_r, "alpha_r"), (alpha, "alpha"))):
        if a is not None:
            al[..., c] = _gpu_image(a, name, h, w, 1)
    dc = None if diffuse_color is None else _gpu_image(diffuse_color, "diffuse_color", h, w, 3)
    rc = None if reflection_color is None else _gpu_image(reflection_color, "reflection_color", h, w, 3)
    _check_k(k_d, k_r)
    if not (gamma > 0 and math.isfinite(gamma)):
        raise CompositingError(f"gamma: must be positive and finite, got {gamma}")
    if not epsilon > 0:
        raise CompositingError(f"epsilon: must be positive, got {epsilon}")
    table, layers = _gpu_patches(patches)
    one = np.zeros((1, 1, 3), np.float32)
    textures = {"rk_ids": ids_f, "rk_normals": n, "rk_edited": e, "rk_view": v if v.ndim == 3 else one,
                "rk_diffuse": d0, "rk_reflection": r0, "rk_image": img, "rk_alphas": al,
                "rk_dcolor": dc if dc is not None else one, "rk_rcolor": rc if rc is not None else one,
                "rk_sh": table, "rk_env": layers}
    chord_eps = 4.0 if epsilon >= math.pi else 2.0 * math.sin(0.5 * epsilon)
    uniforms = {"rk_params": (float(k_d), float(k_r), float(gamma), chord_eps), "rk_inv_eps": 1.0 / epsilon,
                "rk_flags": (int(v.ndim == 3), int(dc is not None), int(rc is not None)),
                "rk_view_const": tuple(float(x) for x in (v if v.ndim == 1 else one[0, 0])),
                "rk_npatches": len(patches)}
    return RecompositeFrame(h, w, textures, uniforms, len(patches))


def frame_result(out: np.ndarray) -> tuple[np.ndarray, dict]:
    """The shader's (H, W, 4) output as (image (H, W, 3), {"edited", "masked"}): alpha holds each
    pixel's status (0 = I unchanged, 1 = recomposited, 2 = masked)."""
    status = out[..., 3]
    stats = {"edited": int((status == 1).sum()), "masked": int((status == 2).sum())}
    return np.ascontiguousarray(out[..., :3]), stats


_EGL_DRAW, _EGL_READ = 0x3059, 0x305A


def _gl_lib(name: str, functions: dict):
    import ctypes  # noqa: PLC0415

    try:
        lib = ctypes.CDLL(name)
    except OSError:
        return None
    for fn, (restype, argtypes) in functions.items():
        f = getattr(lib, fn, None)
        if f is None:
            return None
        f.restype, f.argtypes = restype, argtypes
    return lib


class _CurrentGL:
    """The thread's current OpenGL context (EGL or GLX), saved to be made current again.

    moderngl makes its own context current; Blender's ``gpu`` module assumes that Blender's is, so
    a moderngl call in a Blender process would send Blender's next draws (the UI, or
    ``rokeby.compositing.blender_gpu``) to the wrong context. ``GLRecompositor`` saves whatever is
    current before it touches moderngl and restores it after."""

    _libs = None

    @classmethod
    def _load(cls):
        if cls._libs is None:
            import ctypes  # noqa: PLC0415

            v, i = ctypes.c_void_p, ctypes.c_int
            egl = _gl_lib("libEGL.so.1", {"eglGetCurrentContext": (v, []), "eglGetCurrentDisplay": (v, []),
                                          "eglGetCurrentSurface": (v, [i]), "eglMakeCurrent": (i, [v, v, v, v])})
            glx = _gl_lib("libGL.so.1", {"glXGetCurrentContext": (v, []), "glXGetCurrentDisplay": (v, []),
                                         "glXGetCurrentDrawable": (ctypes.c_ulong, []),
                                         "glXGetCurrentReadDrawable": (ctypes.c_ulong, []),
                                         "glXMakeContextCurrent": (i, [v, ctypes.c_ulong, ctypes.c_ulong, v])})
            cls._libs = (egl, glx)
        return cls._libs

    def __init__(self):
        egl, glx = self._load()
        self.egl = self.glx = None
        if egl is not None and egl.eglGetCurrentContext():
            self.egl = (egl.eglGetCurrentDisplay(), egl.eglGetCurrentSurface(_EGL_DRAW),
                        egl.eglGetCurrentSurface(_EGL_READ), egl.eglGetCurrentContext())
        if glx is not None and glx.glXGetCurrentContext():
            self.glx = (glx.glXGetCurrentDisplay(), glx.glXGetCurrentDrawable(), glx.glXGetCurrentReadDrawable(),
                        glx.glXGetCurrentContext())

    def restore(self) -> None:
        egl, glx = self._load()
        if self.egl is not None:
            egl.eglMakeCurrent(*self.egl)
        if self.glx is not None:
            glx.glXMakeContextCurrent(*self.glx)


class GLRecompositor:
    """The recompositing shader on a moderngl context (EGL, headless; Mesa llvmpipe without a GPU).
    Textures and the framebuffer are kept between frames of the same size. Whatever OpenGL context
    was current before a call (Blender's, inside Blender) is current again after it."""

    def __init__(self, ctx=None):
        import moderngl

        caller = _CurrentGL()
        try:
            self.ctx = ctx or moderngl.create_context(standalone=True, backend="egl")
            self._own = _CurrentGL()  # moderngl's, to make current for each frame
            vs, fs = recomposite_sources()
            self.program = self.ctx.program(vertex_shader=vs, fragment_shader=fs)
            self.vao = self.ctx.vertex_array(self.program, [])
            self.max_layers = int(self.ctx.info.get("GL_MAX_ARRAY_TEXTURE_LAYERS", 256))
        finally:
            caller.restore()
        self._size = None
        self._tex: dict = {}
        self._fbo = None
        self._frame = None  # a weak reference to the frame the textures hold
        self.uploads = 0  # texture writes so far

    def _texture(self, name: str, data: np.ndarray):
        comps = 1 if data.ndim == 2 else data.shape[-1]
        h, w = data.shape[:2]
        t = self._tex.get(name)
        if t is None or t.size != (w, h) or t.components != comps:
            if t is not None:
                t.release()
            t = self.ctx.texture((w, h), comps, dtype="f4")
            self._tex[name] = t
        t.write(np.ascontiguousarray(data, np.float32).tobytes())
        self.uploads += 1
        return t

    def _array(self, name: str, layers: np.ndarray):
        s = layers.shape[1]
        t = self._tex.get(name)
        if t is None or t.size != (s, s, layers.shape[0]):
            if t is not None:
                t.release()
            t = self._tex[name] = self.ctx.texture_array((s, s, layers.shape[0]), 3, dtype="f4")
        t.write(layers.tobytes())
        self.uploads += 1
        return t

    def __call__(self, *args, **kw):
        return self.draw(recomposite_frame(*args, **kw))

    def draw(self, f: "RecompositeFrame", changed=None) -> tuple[np.ndarray, dict]:
        """Draws the packed frame ``f``. ``changed``: the names of the textures that differ from the
        last frame drawn, when that was ``f`` itself (``RecompositeSession``): only those are
        written again. None, or a different frame, writes all of them."""
        f.check_limits(int(self.ctx.info.get("GL_MAX_TEXTURE_SIZE", 16384)), self.max_layers, "this GL")
        caller = _CurrentGL()
        self._own.restore()
        try:
            return self._draw(f, changed)
        finally:
            caller.restore()

    def _draw(self, f: "RecompositeFrame", changed) -> tuple[np.ndarray, dict]:
        h, w = f.height, f.width
        same = self._frame is not None and self._frame() is f
        self._frame = None  # until every texture of f is written: a failure leaves no frame claimed
        for unit, t, name in RECOMPOSITE_INTERFACE["sampler"]:
            tex = self._tex.get(name)
            if tex is None or changed is None or not same or name in changed:
                data = f.textures[name]
                tex = self._array(name, data) if t == "FLOAT_2D_ARRAY" else self._texture(name, data)
            tex.use(unit)
            if name in self.program:
                self.program[name].value = unit
        for name, val in f.uniforms.items():
            if name in self.program:
                self.program[name].value = val
        if self._fbo is None or self._size != (w, h):
            if self._fbo is not None:
                self._fbo.release()
            self._fbo = self.ctx.framebuffer(color_attachments=[self.ctx.texture((w, h), 4, dtype="f4")])
            self._size = (w, h)
        self._fbo.use()
        self.ctx.viewport = (0, 0, w, h)
        self._frame = weakref.ref(f)
        self.vao.render(vertices=3)
        out = np.frombuffer(self._fbo.read(components=4, dtype="f4"), np.float32).reshape(h, w, 4)
        return frame_result(out)


_GL: GLRecompositor | None = None


def gl_recompositor() -> GLRecompositor:
    """The process's moderngl recompositor, made on first use."""
    global _GL
    if _GL is None:
        _GL = GLRecompositor()
    return _GL


def recomposite_gpu(ids, normals, edited_normals, view, diffuse, reflection, image, patches, **kw):
    """Eqs. 3–5 by the GLSL shader (shaders/rokeby_recomposite_frag.glsl): the arguments and the
    result (image (H, W, 3) float32, {"edited", "masked"}) of ``rokeby_native.compositing.recomposite``, in
    float32 on the GPU. Runs on a headless moderngl/EGL context made on first use; inside Blender,
    ``rokeby.compositing.blender_gpu.recomposite_blender`` draws the same shader through the ``gpu`` module."""
    return gl_recompositor()(ids, normals, edited_normals, view, diffuse, reflection, image, patches, **kw)
