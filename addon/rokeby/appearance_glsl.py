"""GLSL of the appearance preview under environment light (issue 8): the prefiltered GGX chain in
one texture atlas and the order-2 SH irradiance, shaded with the painted Principled parameters
(split sum without the albedo table: F0 = mix(0.08·specular, base, metallic); diffuse
base·(1 − metallic)·E(n)/π). Plain GLSL 3.30 functions, tested against numpy
(:func:`rokeby.envmaps.lookup_levels`, :func:`rokeby.envmaps.sh_irradiance`) with moderngl on EGL;
the Blender draw handler that would use them is not written yet (docs/envmaps.md).

The atlas stacks the levels top to bottom, each resampled to the same H×W lat-long grid (row 0 at
the top, Blender's convention); lookups are bilinear with texelFetch, wrapping in u and crossing
the poles at u + ½, exactly like rokeby_core::envmap.
"""

from __future__ import annotations

import numpy as np

from . import envmaps

GLSL = r"""
uniform sampler2D rk_env_atlas;
uniform int rk_env_levels;
uniform vec3 rk_sh[9];
const float RK_PI = 3.14159265358979;

vec2 rk_equirect_uv(vec3 d)
{
  return vec2(0.5 - atan(d.y, d.x) / (2.0 * RK_PI), atan(d.z, length(d.xy)) / RK_PI + 0.5);
}

vec3 rk_level_texel(int level, int i, int j, int h, int w)
{
  if (i < 0) { i = -1 - i; j += w / 2; }
  else if (i >= h) { i = 2 * h - 1 - i; j += w / 2; }
  i = clamp(i, 0, h - 1);
  j = ((j % w) + w) % w;
  return texelFetch(rk_env_atlas, ivec2(j, level * h + i), 0).rgb;
}

vec3 rk_level(vec3 d, int level)
{
  ivec2 size = textureSize(rk_env_atlas, 0);
  int w = size.x;
  int h = size.y / rk_env_levels;
  vec2 uv = rk_equirect_uv(normalize(d));
  float x = uv.x * float(w) - 0.5;
  float y = (1.0 - uv.y) * float(h) - 0.5;
  float x0 = floor(x), y0 = floor(y);
  float fx = x - x0, fy = y - y0;
  int j0 = int(x0), i0 = int(y0);
  return (1.0 - fx) * (1.0 - fy) * rk_level_texel(level, i0, j0, h, w)
       + fx * (1.0 - fy) * rk_level_texel(level, i0, j0 + 1, h, w)
       + (1.0 - fx) * fy * rk_level_texel(level, i0 + 1, j0, h, w)
       + fx * fy * rk_level_texel(level, i0 + 1, j0 + 1, h, w);
}

/* Prefiltered radiance for a Blender roughness: levels at roughness l / (levels - 1). */
vec3 rk_specular(vec3 r, float roughness)
{
  float x = clamp(roughness, 0.0, 1.0) * float(rk_env_levels - 1);
  int l0 = min(int(floor(x)), rk_env_levels - 1);
  int l1 = min(l0 + 1, rk_env_levels - 1);
  return mix(rk_level(r, l0), rk_level(r, l1), x - float(l0));
}

/* E(n)/pi from the irradiance coefficients (Ramamoorthi & Hanrahan 2001; rokeby_core::sh basis). */
vec3 rk_irradiance(vec3 n)
{
  n = normalize(n);
  return rk_sh[0] * 0.28209479177387814
       + rk_sh[1] * (0.4886025119029199 * n.y)
       + rk_sh[2] * (0.4886025119029199 * n.z)
       + rk_sh[3] * (0.4886025119029199 * n.x)
       + rk_sh[4] * (1.0925484305920792 * n.x * n.y)
       + rk_sh[5] * (1.0925484305920792 * n.y * n.z)
       + rk_sh[6] * (0.31539156525252005 * (3.0 * n.z * n.z - 1.0))
       + rk_sh[7] * (1.0925484305920792 * n.x * n.z)
       + rk_sh[8] * (0.5462742152960396 * (n.x * n.x - n.y * n.y));
}

/* n: shading normal, v: direction to the viewer (both unit, world space). */
vec3 rk_shade(vec3 n, vec3 v, vec3 base, float specular, float roughness, float metallic)
{
  vec3 r = reflect(-v, n);
  vec3 f0 = mix(vec3(0.08 * specular), base, metallic);
  return base * (1.0 - metallic) * rk_irradiance(n) + f0 * rk_specular(r, roughness);
}
"""


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


def shade_reference(atlas_px, levels: int, irradiance_coeffs, n, v, base, specular, roughness, metallic) -> np.ndarray:
    """numpy twin of rk_shade (for tests and CPU previews): (..., 3) normals/views → (..., 3)."""
    h = atlas_px.shape[0] // levels
    lv = [atlas_px[k * h:(k + 1) * h] for k in range(levels)]
    n = np.asarray(n, np.float64)
    v = np.asarray(v, np.float64)
    r = 2 * np.sum(n * v, axis=-1, keepdims=True) * n - v
    spec = envmaps.lookup_levels(lv, [k / (levels - 1) if levels > 1 else 0.0 for k in range(levels)], r, roughness)
    base = np.asarray(base, np.float64)
    f0 = (1 - metallic) * 0.08 * specular + metallic * base
    return base * (1 - metallic) * envmaps.sh_irradiance(irradiance_coeffs, n) + f0 * spec
