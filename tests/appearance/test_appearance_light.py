"""Fraser's point-light view: rk_shade_point in shaders/rokeby_appearance_lib.glsl, the
painted parameters under one movable point light, run with moderngl on headless EGL against its
numpy twin (appearance_glsl.shade_point_reference) for the three preview models; the highlight
follows the light. And the specular tint in the environment-lit shading (rk_shade_tinted)."""

import numpy as np
import pytest

from rokeby import envmaps
from rokeby.appearance import glsl as appearance_glsl
from support.appearance import sphere_shader

moderngl = pytest.importorskip("moderngl")

SIZE = 48
BODY = """\
  vec3 v = vec3(0.0, -1.0, 0.0);
  if (rk_appearance.options.w == RK_LIGHT_POINT) {
    frag = vec4(rk_shade_point(n, v, n, u_base, u_spec, u_rough, u_metal, u_tint), 1.0);
  } else {
    frag = vec4(rk_shade_tinted(n, v, u_base, u_spec, u_rough, u_metal, u_tint), 1.0);
  }"""


@pytest.fixture(scope="module")
def gl():
    sh = sphere_shader(BODY, uniforms=" uniform vec3 u_tint;", size=SIZE)
    ctx, prog, vao, fbo, p, inside, n = sh.ctx, sh.prog, sh.vao, sh.fbo, sh.p, sh.inside, sh.n

    def draw(block, base, spec, rough, metal, tint=(1.0, 1.0, 1.0)):
        ubo = ctx.buffer(block)
        ubo.bind_to_uniform_block(0)
        prog["rk_appearance_block"].binding = 0
        prog["u_base"].value, prog["u_spec"].value, prog["u_rough"].value, prog["u_metal"].value = base, spec, rough, metal
        prog["u_tint"].value = tint
        fbo.use()
        fbo.clear()
        vao.render(moderngl.TRIANGLE_STRIP)
        ubo.release()
        return np.frombuffer(fbo.read(components=4, dtype="f4"), np.float32).reshape(SIZE, SIZE, 4)[..., :3].copy()

    yield {"ctx": ctx, "draw": draw, "n": n, "inside": inside, "p": p}
    ctx.release()


IRR = np.zeros((3, 9))
CASES = [((0.02, 0.02, 0.02), 1.0, 0.25, 0.0, (1.0, 0.3, 0.1)), ((0.8, 0.3, 0.2), 0.5, 0.6, 0.0, (1.0, 1.0, 1.0)),
         ((0.9, 0.8, 0.6), 0.5, 0.35, 1.0, (1.0, 1.0, 1.0))]


@pytest.mark.parametrize("model", appearance_glsl.MODELS)
def test_point_light_view_matches_numpy_and_follows_the_light(gl, model):
    """rk_shade_point against shade_point_reference (glossy tinted plastic, rough plastic, metal),
    and the highlight's centroid moves to the side and height the light moved to."""
    n, inside = gl["n"], gl["inside"]
    v = np.array([0.0, -1.0, 0.0])
    for base, spec, rough, metal, tint in CASES:
        light = (2.0, -3.0, 1.0)
        block = appearance_glsl.pack_block(np.eye(4), (0.0, -1e4, 0.0), 1, model, IRR, light="POINT", light_position=light, light_intensity=20.0)
        got = gl["draw"](block, base, spec, rough, metal, tint)[inside]
        want = appearance_glsl.shade_point_reference(n[inside], v, n[inside], light, 20.0, np.array(base), spec, rough, metal, model=model, spec_tint=tint)
        assert np.isfinite(got).all()
        rel = np.abs(got - want).mean() / np.abs(want).mean()
        assert rel < 2e-3, (model, base, rel)
    centroids = {}
    for light in ((3.0, -3.0, 0.0), (-3.0, -3.0, 0.0), (0.0, -3.0, 3.0)):
        block = appearance_glsl.pack_block(np.eye(4), (0.0, -1e4, 0.0), 1, model, IRR, light="POINT", light_position=light, light_intensity=20.0)
        img = gl["draw"](block, (0.0, 0.0, 0.0), 1.0, 0.2, 0.0).sum(axis=2)  # black plastic: only the highlight
        w = np.where(img >= 0.5 * img.max(), img, 0.0)
        p = gl["p"]
        centroids[light] = ((w * p[..., 0]).sum() / w.sum(), (w * p[..., 1]).sum() / w.sum())
    (rx, ry), (lx, ly), (ux, uy) = centroids.values()
    # the mirror direction halfway between view and light: x ≈ ±0.38 on the unit disk
    assert rx > 0.2 and lx < -0.2 and abs(ry) < 0.05 and abs(ly) < 0.05, centroids
    assert uy > 0.2 and abs(ux) < 0.05, centroids


def test_specular_tint_under_the_environment_matches_numpy(gl):
    """rk_shade_tinted with a red tint on black plastic under forest.exr: the numpy twin, and the
    highlight's red share is what the tint makes of F0 (white: neutral)."""
    im = envmaps.read_exr(envmaps.studio_world("forest"))
    irr = envmaps.irradiance(im, size=8)["irradiance_coeffs"]
    lv = envmaps.prefilter(im, "ggx", appearance_glsl.level_params("PRINCIPLED"))
    at = appearance_glsl.atlas(lv, height=64)
    tex = gl["ctx"].texture((at.shape[1], at.shape[0]), 3, at.tobytes(), dtype="f4")
    tex.use(0)
    n, inside = gl["n"][gl["inside"]], gl["inside"]
    block = appearance_glsl.pack_block(np.eye(4), (0.0, -1e4, 0.0), len(lv), "PRINCIPLED", irr)
    out = {}
    for tint in ((1.0, 1.0, 1.0), (1.0, 0.0, 0.0)):
        got = gl["draw"](block, (0.0, 0.0, 0.0), 1.0, 0.2, 0.0, tint)[inside]
        want = appearance_glsl.shade_reference(at, len(lv), irr, n, np.array([0.0, -1.0, 0.0]), np.zeros(3), 1.0, 0.2, 0.0, spec_tint=tint)
        rel = np.abs(got - want).mean() / np.abs(want).mean()
        assert rel < 2e-3, (tint, rel)
        out[tint] = got.mean(axis=0)
    white, red = out[(1.0, 1.0, 1.0)], out[(1.0, 0.0, 0.0)]
    assert red[0] > 0.9 * white[0] and red[1] < 0.7 * white[1], (white, red)  # the Fresnel bias B stays white
    tex.release()


def test_render_difference_is_measured_not_claimed():
    """Renders use Principled (GGX) whatever the preview model: the measured difference is 0 for
    the Principled preview and well above 0 for Phong and Torrance–Sparrow (rough metal most:
    rough GGX loses energy, the seed's models do not); bad worlds are refused by name."""
    im = envmaps.read_exr(envmaps.studio_world("forest"))
    assert appearance_glsl.render_difference(im, "PRINCIPLED", roughness=0.6, metallic=1.0) == 0.0
    d = {m: appearance_glsl.render_difference(im, m, base=(0.9, 0.9, 0.9), roughness=0.6, metallic=1.0) for m in ("PHONG", "TORRANCE_SPARROW")}
    assert all(0.1 < x < 1.0 for x in d.values()), d
    smooth = appearance_glsl.render_difference(im, "PHONG", base=(0.9, 0.9, 0.9), roughness=0.1, metallic=1.0)
    assert 0.01 < smooth < d["PHONG"], (smooth, d)
    with pytest.raises(ValueError, match="lat-long"):
        appearance_glsl.render_difference(np.ones((8, 8, 3), np.float32), "PHONG")
    with pytest.raises(ValueError, match="NaN"):
        appearance_glsl.render_difference(np.full((8, 16, 3), np.nan, np.float32), "PHONG")
    with pytest.raises(ValueError, match="model"):
        appearance_glsl.render_difference(im, "BLINN")


@pytest.mark.slow  # a fresh bpy process and its GPU context: over 20 s on the shared 2-core machine
def test_viewport_draws_the_point_lit_view_beside_the_environment_lit_one():
    """tests/appearance/appearance_light_check.py in a fresh bpy process, through Blender's gpu module and
    the viewport handler's draw_view: 'BESIDE' draws the environment-lit ball unchanged and, to
    its right on screen, a copy under the point light that matches the numpy twin; the copy's
    highlight moves right, left and up with the light; a red specular colour turns it red, also
    when painted with the brush on a texture target (both views)."""
    from support.bpy_process import run_check

    res = run_check("appearance/appearance_light_check.py")
    assert res["env_covered_left"] > 0.15 and res["env_covered_right"] == 0.0, res
    assert res["beside_covered_right"] > 0.15 and res["left_same"] < 1e-6, res
    assert res["point_rel"] < 0.05, res
    (rx, ry), (lx, ly), (ux, uy) = res["highlight_light_right"], res["highlight_light_left"], res["highlight_light_up"]
    assert rx - lx > 4 and abs(ry - ly) < 1.5 and uy - ry > 3, res
    w, r = res["highlight_white"], res["highlight_red"]
    assert max(w) / min(w) < 1.3 and r[0] > 0.5 * w[0] and r[1] < 0.3 * r[0] and r[2] < 0.3 * r[0], res
    # Specular colour painted with the brush on a texture target: the preview shows it red in the
    # environment-lit view and in the point-lit one, from the image (the attribute stays white).
    t = res["texture"]
    assert t["attribute_green_min"] == 1.0 and t["image_green_max"] < 0.3, t
    (e0, e1), (p0, p1) = t["env_green_share"], t["point_green_share"]
    print(f"G/R before/after: environment view {e0:.3f} -> {e1:.3f}, point-lit view {p0:.3f} -> {p1:.3f}")
    assert e0 > 0.7 and p0 > 0.7 and e1 < 0.35 and p1 < 0.35, t
