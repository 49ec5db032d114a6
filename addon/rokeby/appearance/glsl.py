"""GLSL interface and numpy twin of the appearance preview under environment light.

The shader lives in ``shaders/rokeby_appearance_*.glsl`` (bodies only); this module declares its
interface once (:data:`INTERFACE`, in GPUShaderCreateInfo's terms), turns it into a ``#version
330`` header for plain OpenGL (:func:`standalone_sources`, the moderngl tests), packs the std140
block (:func:`pack_block`), builds the lat-long atlas of prefiltered levels (:func:`atlas`) and
the GGX directional-albedo table (:func:`brdf_lut`), and shades in numpy exactly as the shader
does (:func:`shade_reference`).

Preview models (``RokebyAppearance.options.y``), all driven by the painted Principled parameters:

* ``PRINCIPLED`` — Blender's BSDF as a split sum: GGX prefiltered radiance times the GGX
  directional albedo F0·A + B (Karis 2013; :func:`brdf_lut`), F0 = mix(0.08·specular, base,
  metallic); the dielectric diffuse base·(1 − metallic)·E(n)/π is weighted by 1 − (0.08·specular·A
  + B), the energy the specular layer does not reflect.
* ``PHONG`` — the seed's normalised Phong lobe about the reflected direction, exponent
  σ = (2/α² − 2)/4 with α = roughness² (the Blinn–Phong exponent of the same width, halved in
  angle), k_s = F0; no Fresnel.
* ``TORRANCE_SPARROW`` — Fraser's simplified Torrance–Sparrow lobe exp(−(θ_h/σ)²), σ = α, with
  Schlick's Fresnel at n·v.

The specular tint (Principled Specular Tint, the specular colour brush) multiplies the dielectric
F0 in every model (``rk_shade_tinted``; ``rk_shade`` is it with a white tint). Fraser's second
view, one point light (``options.w`` = RK_LIGHT_POINT, ``light`` in the block), evaluates each
model's BRDF directly (``rk_shade_point``, numpy twin :func:`shade_point_reference`). Renders
always use the Principled BSDF: :func:`render_difference` measures how far a Phong or
Torrance–Sparrow preview is from it.

The atlas stacks the levels top to bottom, each resampled to the same H×W lat-long grid (row 0 at
the top, Blender's convention); lookups are bilinear with texelFetch, wrapping in u and crossing
the poles at u + ½, exactly like rokeby_core::envmaps::envmap.
"""

from __future__ import annotations

import re
from functools import lru_cache

import numpy as np

from .. import envmaps
from ..core import shaders as glsl

FILES = {
    "types": "rokeby_appearance_types.glsl",
    "lib": "rokeby_appearance_lib.glsl",
    "vertex": "rokeby_appearance_vert.glsl",
    "fragment": "rokeby_appearance_frag.glsl",
}

MODELS = ("PRINCIPLED", "PHONG", "TORRANCE_SPARROW")
LOBE = {"PRINCIPLED": "ggx", "PHONG": "phong", "TORRANCE_SPARROW": "torrance_sparrow"}

INTERFACE = {
    # vid: the mesh vertex a drawn vertex belongs to (a float: exact below 2^24 vertices); uv: the
    # UV map a texture target reads (zeros without one). Seams split drawn vertices, not vid.
    "vertex_in": [(0, "VEC3", "pos"), (1, "VEC3", "nor"), (2, "VEC2", "uv"), (3, "FLOAT", "vid")],
    "vertex_out": [("smooth", "VEC3", "v_pos"), ("smooth", "VEC3", "v_nor"), ("smooth", "VEC2", "v_uv"), ("smooth", "VEC4", "v_base"),
                   ("smooth", "VEC3", "v_par"), ("smooth", "VEC3", "v_tint")],
    "push_constant": [("MAT4", "rk_model")],  # 64 bytes: within Vulkan's guaranteed 128
    "sampler": [(0, "FLOAT_2D", "rk_env_atlas"), (1, "FLOAT_2D", "rk_brdf_lut"), (2, "FLOAT_2D", "rk_points"),
                (3, "FLOAT_2D", "rk_tex_base"), (4, "FLOAT_2D", "rk_tex_specular"), (5, "FLOAT_2D", "rk_tex_roughness"),
                (6, "FLOAT_2D", "rk_tex_metallic"), (7, "FLOAT_2D", "rk_tex_specular_tint")],
    "uniform_buf": [(0, "RokebyAppearance", "rk_appearance")],
    "fragment_out": [(0, "VEC4", "frag")],
    "depth_write": "LESS",  # the fragment stage writes gl_FragDepth, only ever nearer
}
INTERFACE_NAME = "rk_appearance_iface"
BLOCK_BYTES = (16 + 4 + 4 + 9 * 4 + 4 + 4 + 16 + 4 + 4) * 4  # mat4, vec4 eye, ivec4 options, vec4 sh[9], vec4 tint, vec4 scale, mat4, vec4 spec_tint, vec4 light
# options.z bits (RK_TEX_* in the types file): parameters read from image textures at the UV.
TEXTURE_BITS = {"diffuse": 1, "specular": 2, "roughness": 4, "metallic": 8, "specular_tint": 16}
TEXTURE_SAMPLERS = {"diffuse": "rk_tex_base", "specular": "rk_tex_specular", "roughness": "rk_tex_roughness", "metallic": "rk_tex_metallic",
                    "specular_tint": "rk_tex_specular_tint"}
# options.w (RK_LIGHT_* in the types file): what lights the preview. Fraser's interface shows the
# painted sphere under the environment and, beside it, under a point light.
LIGHTS = ("ENVIRONMENT", "POINT")
# The per-point parameters the preview reads, in rk_points' texel order after the base colour.
POINT_PARAMS = ("specular", "roughness", "metallic")
TEXELS_PER_POINT = 3  # rk_points: base colour rgba; specular, roughness, metallic; specular tint rgb
MAX_VERTICES = 1 << 24  # vid is a float attribute


def read_sources() -> dict:
    d = glsl.shader_dir()
    return {key: (d / name).read_text() for key, name in FILES.items()}


def model_index(model: str) -> int:
    """RK_MODEL_* of a model name (checked against the types file, so the two cannot drift)."""
    m = str(model).upper()
    if m not in MODELS:
        raise ValueError(f"model: expected one of {', '.join(MODELS)}, got {model!r}")
    text = read_sources()["types"]
    hit = re.search(rf"^#define\s+RK_MODEL_{m}\s+(\d+)", text, re.M)
    if hit is None:
        raise RuntimeError(f"{FILES['types']} does not define RK_MODEL_{m}")
    return int(hit.group(1))


def standalone_library(version: str = "330 core") -> str:
    """The header (types, block, push constants, samplers) and the library, for a plain OpenGL
    fragment shader with its own ``main`` (tests shading analytic normals)."""
    src = read_sources()
    return "\n".join(glsl.standalone_header(INTERFACE, src["types"], version) + [src["lib"]])


def standalone_sources(version: str = "330 core") -> tuple[str, str]:
    """(vertex, fragment) for a plain OpenGL context: a header from :data:`INTERFACE`, then the
    same files Blender compiles."""
    return glsl.standalone_from(INTERFACE, read_sources(), version)


def normal_matrix(model_matrix) -> np.ndarray:
    """The inverse transpose of a model matrix's 3×3 part, as a 4×4 (pseudo-inverse for a
    singular matrix, so an object scaled to zero gives no NaN)."""
    m = np.asarray(model_matrix, np.float64).reshape(4, 4)[:3, :3]
    out = np.eye(4)
    out[:3, :3] = np.linalg.pinv(m).T
    return out


def light_index(light: str) -> int:
    """RK_LIGHT_* of a light name (checked against the types file)."""
    name = str(light).upper()
    if name not in LIGHTS:
        raise ValueError(f"light: expected one of {', '.join(LIGHTS)}, got {light!r}")
    hit = re.search(rf"^#define\s+RK_LIGHT_{name}\s+(\d+)", read_sources()["types"], re.M)
    if hit is None:
        raise RuntimeError(f"{FILES['types']} does not define RK_LIGHT_{name}")
    return int(hit.group(1))


def pack_block(view_projection, eye, levels: int, model: str, irradiance_coeffs, *, textures: int = 0,
               tint=(1.0, 1.0, 1.0, 1.0), scale=(1.0, 1.0, 1.0), model_matrix=None, spec_tint=(1.0, 1.0, 1.0),
               light: str = "ENVIRONMENT", light_position=(0.0, 0.0, 0.0), light_intensity: float = 0.0) -> bytes:
    """The std140 ``RokebyAppearance`` block (:data:`BLOCK_BYTES` bytes). ``textures``: the
    :data:`TEXTURE_BITS` of the parameters on image textures; ``tint``, ``scale`` and
    ``spec_tint``: the global sliders (diffuse tint; specular, roughness, metallic scales; specular
    colour); ``model_matrix``: the object's (for its normal matrix; identity when None);
    ``light``: 'ENVIRONMENT' (the prefiltered world) or 'POINT' (one point light at
    ``light_position`` of ``light_intensity``, Fraser's second view)."""
    if not np.isfinite(np.asarray(light_position, np.float64)).all() or not np.isfinite(light_intensity) or light_intensity < 0:
        raise ValueError(f"light: position must be finite and intensity finite and >= 0, got {light_position!r}, {light_intensity!r}")
    vp = np.asarray(view_projection, np.float32).reshape(4, 4)
    sh = np.asarray(irradiance_coeffs, np.float32).reshape(3, 9)
    out = np.zeros(BLOCK_BYTES // 4, np.float32)
    out[0:16] = vp.T.ravel()  # column-major
    out[16:19] = np.asarray(eye, np.float32).reshape(3)
    out[20:24].view(np.int32)[:] = (int(levels), model_index(model), int(textures), light_index(light))
    out[24:60].reshape(9, 4)[:, :3] = sh.T
    t = np.asarray(tint, np.float32).ravel()
    out[60:64] = np.append(t, 1.0)[:4] if t.size == 3 else t.reshape(4)
    out[64:67] = np.asarray(scale, np.float32).reshape(3)
    out[68:84] = normal_matrix(np.eye(4) if model_matrix is None else model_matrix).T.ravel()  # column-major
    out[84:87] = np.asarray(spec_tint, np.float32).ravel()[:3]
    out[87] = 1.0
    out[88:91] = np.asarray(light_position, np.float32).reshape(3)
    out[91] = float(light_intensity)
    return out.tobytes()


def level_params(model: str, roughness=envmaps.ROUGHNESS_LEVELS) -> list[float]:
    """The lobe parameter of each prefiltered level for a model, at Blender roughnesses."""
    r = np.asarray(roughness, np.float64)
    alpha = r * r
    m = str(model).upper()
    if m == "PRINCIPLED":
        return [float(x) for x in r]
    if m == "PHONG":
        return [float(x) for x in np.minimum((2.0 / np.maximum(alpha, 1e-4) ** 2 - 2.0) / 4.0, 1e6)]
    if m == "TORRANCE_SPARROW":
        return [float(x) for x in alpha]
    raise ValueError(f"model: expected one of {', '.join(MODELS)}, got {model!r}")


def atlas(levels, height: int | None = None) -> np.ndarray:
    """The prefiltered levels (lat-long arrays of any sizes, sharpest first) resampled to one
    height × 2·height grid each and stacked top to bottom: (L·height, 2·height, 3) float32."""
    if len(levels) == 0:
        raise ValueError("levels: need at least one level")
    h = int(height) if height is not None else max(int(lv.shape[0]) for lv in levels)
    parts = []
    for lv in levels:
        lv = np.asarray(lv, np.float32)[..., :3]
        if lv.shape[:2] != (h, 2 * h):
            lv = envmaps.convert(lv, "latlong", "latlong", h)
        parts.append(lv)
    return np.ascontiguousarray(np.concatenate(parts, axis=0))


@lru_cache(maxsize=4)
def brdf_lut(size: int = 32, samples: int = 1024) -> np.ndarray:
    """GGX directional albedo as (scale A, bias B) of F0 (Karis 2013): (size, size, 2) float32,
    rows roughness 0…1, columns n·v 0…1 (texel centres at the ends). Importance-sampled with a
    Hammersley set, Smith height-correlated visibility and Schlick's Fresnel; α = roughness²."""
    nv = np.clip(np.linspace(0.0, 1.0, size), 1e-3, 1.0)
    rough = np.linspace(0.0, 1.0, size)
    i = np.arange(samples)
    u1 = (i + 0.5) / samples
    u2 = np.array([int(f"{k:032b}"[::-1], 2) for k in i], np.float64) / 2.0**32  # radical inverse
    out = np.zeros((size, size, 2), np.float64)
    for a_i, r in enumerate(rough):
        a = max(r * r, 1e-4)
        cos_h = np.sqrt((1 - u1) / (1 + (a * a - 1) * u1))
        sin_h = np.sqrt(1 - cos_h**2)
        phi = 2 * np.pi * u2
        h = np.stack([sin_h * np.cos(phi), sin_h * np.sin(phi), cos_h], -1)  # (S, 3)
        v = np.stack([np.sqrt(1 - nv**2), np.zeros_like(nv), nv], -1)  # (N, 3)
        vh = v @ h.T  # (N, S)
        l_z = 2 * vh * h[None, :, 2] - v[:, None, 2]
        ok = (l_z > 0) & (vh > 0)
        nl = np.where(ok, l_z, 0.0)
        k = a * a
        nvv = nv[:, None]
        vis = 0.5 / (nl * np.sqrt(nvv**2 * (1 - k) + k) + nvv * np.sqrt(nl**2 * (1 - k) + k) + 1e-30)
        g = np.where(ok, vis * nl * 4 * vh / np.maximum(h[None, :, 2], 1e-12), 0.0)
        fc = (1 - np.clip(vh, 0, 1)) ** 5
        out[a_i, :, 0] = np.mean(g * (1 - fc), axis=1)
        out[a_i, :, 1] = np.mean(g * fc, axis=1)
    return out.astype(np.float32)


def _lut_lookup(lut, n_dot_v, roughness):
    s = lut.shape[0]
    p = np.stack(np.broadcast_arrays(np.clip(n_dot_v, 0, 1) * (s - 1), np.clip(roughness, 0, 1) * (s - 1)), -1)
    p0 = np.floor(p).astype(int)
    f = p - p0
    p1 = np.minimum(p0 + 1, s - 1)
    t = lambda x, y: lut[y, x]  # noqa: E731 - rows roughness, columns n·v
    a = t(p0[..., 0], p0[..., 1]) * (1 - f[..., :1]) + t(p1[..., 0], p0[..., 1]) * f[..., :1]
    b = t(p0[..., 0], p1[..., 1]) * (1 - f[..., :1]) + t(p1[..., 0], p1[..., 1]) * f[..., :1]
    return a * (1 - f[..., 1:]) + b * f[..., 1:]


def shade_reference(atlas_px, levels: int, irradiance_coeffs, n, v, base, specular, roughness, metallic,
                    model: str = "PRINCIPLED", lut=None, spec_tint=(1.0, 1.0, 1.0)) -> np.ndarray:
    """numpy twin of rk_shade_tinted (for tests and CPU previews): (..., 3) normals/views → (..., 3)."""
    h = atlas_px.shape[0] // levels
    lv = [atlas_px[k * h:(k + 1) * h] for k in range(levels)]
    n = np.asarray(n, np.float64)
    v = np.broadcast_to(np.asarray(v, np.float64), n.shape)
    nv = np.clip(np.sum(n * v, axis=-1, keepdims=True), 0.0, 1.0)
    r = 2 * np.sum(n * v, axis=-1, keepdims=True) * n - v
    spec = envmaps.lookup_levels(lv, [k / (levels - 1) if levels > 1 else 0.0 for k in range(levels)], r, roughness)
    base = np.asarray(base, np.float64)
    tint = np.asarray(spec_tint, np.float64)
    f0 = (1 - metallic) * 0.08 * specular * tint + metallic * base
    diffuse = base * (1 - metallic) * envmaps.sh_irradiance(irradiance_coeffs, n)
    m = str(model).upper()
    if m == "PRINCIPLED":
        ab = _lut_lookup(brdf_lut() if lut is None else lut, nv[..., 0], roughness).astype(np.float64)
        e_d = 0.08 * specular * tint * ab[..., :1] + ab[..., 1:]
        return diffuse * (1 - e_d) + spec * (f0 * ab[..., :1] + ab[..., 1:])
    if m == "TORRANCE_SPARROW":
        return diffuse + spec * (f0 + (1 - f0) * (1 - nv) ** 5)
    if m == "PHONG":
        return diffuse + spec * f0
    raise ValueError(f"model: expected one of {', '.join(MODELS)}, got {model!r}")


def shade_point_reference(n, v, p, light_position, light_intensity: float, base, specular, roughness, metallic,
                          model: str = "PRINCIPLED", spec_tint=(1.0, 1.0, 1.0), lut=None) -> np.ndarray:
    """numpy twin of rk_shade_point: (..., 3) normals, views, points → (..., 3) radiance under one
    point light (Fraser's second view; each model's BRDF evaluated directly, 1/d² falloff)."""
    n = np.asarray(n, np.float64)
    v = np.broadcast_to(np.asarray(v, np.float64), n.shape)
    to_l = np.asarray(light_position, np.float64) - np.asarray(p, np.float64)
    d2 = np.maximum(np.sum(to_l * to_l, axis=-1, keepdims=True), 1e-8)
    ll = to_l / np.sqrt(d2)
    nl = np.sum(n * ll, axis=-1, keepdims=True)
    nv = np.clip(np.sum(n * v, axis=-1, keepdims=True), 1e-3, 1.0)
    h = ll + v
    h /= np.linalg.norm(h, axis=-1, keepdims=True)
    nh = np.clip(np.sum(n * h, axis=-1, keepdims=True), 0.0, 1.0)
    vh = np.clip(np.sum(v * h, axis=-1, keepdims=True), 0.0, 1.0)
    alpha = max(roughness * roughness, 1e-3)
    base = np.asarray(base, np.float64)
    tint = np.asarray(spec_tint, np.float64)
    f0 = (1 - metallic) * 0.08 * specular * tint + metallic * base
    diffuse = base * (1 - metallic) / np.pi
    m = str(model).upper()
    nlp = np.maximum(nl, 1e-8)
    if m == "PRINCIPLED":
        a2 = alpha * alpha
        q = nh * nh * (a2 - 1) + 1
        d = a2 / (np.pi * q * q)
        vis = 0.5 / (nlp * np.sqrt(nv * nv * (1 - a2) + a2) + nv * np.sqrt(nlp * nlp * (1 - a2) + a2))
        f = f0 + (1 - f0) * (1 - vh) ** 5
        ab = _lut_lookup(brdf_lut() if lut is None else lut, nv[..., 0], roughness).astype(np.float64)
        e_d = 0.08 * specular * tint * ab[..., :1] + ab[..., 1:]
        out = (diffuse * (1 - e_d) + d * vis * f) * nlp
    elif m == "TORRANCE_SPARROW":
        th = np.arccos(nh)
        s = np.exp(-(th / alpha) ** 2) / (np.pi * alpha * alpha)
        out = diffuse * nlp + (f0 + (1 - f0) * (1 - nv) ** 5) * s / (4 * nv)
    elif m == "PHONG":
        sigma = min((2 / (alpha * alpha) - 2) / 4, 1e6)
        r = 2 * np.sum(n * v, axis=-1, keepdims=True) * n - v
        rl = np.maximum(np.sum(r * ll, axis=-1, keepdims=True), 1e-8)
        out = diffuse * nlp + f0 * (1 + sigma) / (2 * np.pi) * rl**sigma
    else:
        raise ValueError(f"model: expected one of {', '.join(MODELS)}, got {model!r}")
    return np.where(nl > 0, out * light_intensity / d2, 0.0)


# --- the final-render model ------------------------------------------------------------
# Renders use Blender's Principled BSDF (GGX) whatever the preview model. A fit was measured and
# rejected (docs/addon.md, "Final-render model"): the GGX roughness whose prefiltering lobe is
# closest to Phong's or Torrance–Sparrow's (relative L2 of the normalised lobes) leaves 20 % lobe
# error at low roughness (GGX's tails) and made the image difference *larger* at roughness ≥ 0.5
# (rough GGX loses energy, which these two models do not). So the panel states the difference,
# measured with :func:`render_difference`, instead of claiming a match.

RENDER_DIFFERENCE_ROWS = 128  # the world is resampled to this height first (both models alike)


def render_difference(pixels, model: str, base=(0.8, 0.8, 0.8), specular: float = 0.5, roughness: float = 0.5,
                      metallic: float = 0.0, size: int = 64, spec_tint=(1.0, 1.0, 1.0)) -> float:
    """How much a render (Principled/GGX) differs from ``model``'s preview of the same painted
    values under the lat-long world ``pixels``: mean |render − preview| / mean |preview| over a
    sphere seen head-on (``size``² pixels), both shaded as the preview shades them (the
    Principled preview matches Cycles within 4 %, tests/appearance/test_appearance.py). The world is
    resampled to RENDER_DIFFERENCE_ROWS rows first. 0 for PRINCIPLED."""
    m = str(model).upper()
    if m not in MODELS:
        raise ValueError(f"model: expected one of {', '.join(MODELS)}, got {model!r}")
    px = np.asarray(pixels, np.float32)[..., :3]
    if px.ndim != 3 or px.shape[0] < 2 or px.shape[1] != 2 * px.shape[0]:
        raise ValueError(f"pixels: expected a lat-long world (H, 2H, 3+), got {np.shape(pixels)}")
    if not np.isfinite(px).all():
        raise ValueError("pixels: the world contains NaN or inf")
    if m == "PRINCIPLED":
        return 0.0
    if px.shape[0] > RENDER_DIFFERENCE_ROWS:
        px = envmaps.convert(px, "latlong", "latlong", RENDER_DIFFERENCE_ROWS, supersample=2)
    ys, xs = np.mgrid[0:size, 0:size] + 0.5
    p = np.stack([xs / size * 2 - 1, ys / size * 2 - 1], -1)
    inside = (p**2).sum(-1) < 0.98
    n = np.stack([p[..., 0], -np.sqrt(np.maximum(1 - (p**2).sum(-1), 0)), p[..., 1]], -1)[inside]
    v = np.array([0.0, -1.0, 0.0])
    irr = np.asarray(envmaps.irradiance(px, size=8)["irradiance_coeffs"], np.float64)
    shaded = {}
    for mm in (m, "PRINCIPLED"):
        lv = envmaps.prefilter(px, LOBE[mm], level_params(mm))
        at = atlas(lv, height=px.shape[0])
        shaded[mm] = shade_reference(at, len(lv), irr, n, v, np.asarray(base, np.float64)[:3], specular, roughness, metallic,
                                     model=mm, spec_tint=np.asarray(spec_tint, np.float64)[:3])
    preview, render = shaded[m], shaded["PRINCIPLED"]
    return float(np.abs(render - preview).mean() / max(np.abs(preview).mean(), 1e-30))
