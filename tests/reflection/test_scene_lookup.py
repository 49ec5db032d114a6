"""The preview's lookup in the scene captured from the mirror (shaders/rokeby_field_lib.glsl,
``rk_scene_direction``), run with moderngl from the same files Blender compiles.

An analytic scene: a mirror ball of radius 1 at the origin, coloured balls at 1.5 to 6 radii and
a smooth sky. Its "capture" is made here by ray tracing from the ball's centre (colour and
1/distance per texel, as ``scene_env.capture`` stores Cycles' result). The reference is a ray
traced from each mirror pixel's own point q in the shader's own direction e(q). The distance-
corrected lookup must agree with it; the centre-only lookup (the paper's cube map) may not, and
the test reports by how much."""

import numpy as np
import pytest

moderngl = pytest.importorskip("moderngl")

from support.gl_harness import Renderer, create_context, look_at, perspective  # noqa: E402
from rokeby.reflection.viewport import glsl  # noqa: E402
from rokeby.core import latlong  # noqa: E402

W, H = 160, 120
CAPTURE_W = 512
# centre, radius, colour: near (1.6 radii) to far (6 radii), around the ball
BALLS = [
    ((0.0, -1.9, -0.2), 0.35, (0.9, 0.1, 0.6)),  # magenta, close, between the ball and the eye
    ((1.7, -1.2, 0.6), 0.45, (0.1, 0.4, 0.9)),
    ((-2.4, -0.8, -0.9), 0.6, (0.95, 0.8, 0.1)),
    ((0.5, 3.5, 1.5), 1.2, (0.2, 0.8, 0.2)),
    ((-4.5, 3.0, 2.0), 1.5, (0.9, 0.3, 0.1)),
]
EYE = np.array([0.6, -5.0, 0.9])


def sky(d):
    d = np.asarray(d, np.float64)
    return np.stack([0.35 + 0.25 * d[..., 2], 0.45 + 0.2 * d[..., 0], 0.6 + 0.15 * d[..., 1]], -1)


def trace(origins, dirs):
    """Nearest ball hit along each ray (t > 1e-4): (colour (N, 3), distance (N,), inf for none)."""
    o, d = np.asarray(origins, np.float64), np.asarray(dirs, np.float64)
    d = d / np.linalg.norm(d, axis=-1, keepdims=True)
    best = np.full(len(d), np.inf)
    colour = sky(d)
    for c, r, col in BALLS:
        oc = o - np.asarray(c)
        b = np.sum(oc * d, -1)
        disc = b * b - (np.sum(oc * oc, -1) - r * r)
        sq = np.sqrt(np.maximum(disc, 0.0))
        t = np.where(-b - sq > 1e-4, -b - sq, -b + sq)
        hit = (disc > 0) & (t > 1e-4) & (t < best)
        n = (o + t[:, None] * d - np.asarray(c)) / r
        shade = np.asarray(col) * (0.55 + 0.45 * n[:, 2:3])  # varies over the ball: placement shows
        colour = np.where(hit[:, None], shade, colour)
        best = np.where(hit, t, best)
    return colour, best


def capture(width=CAPTURE_W):
    h = width // 2
    u = (np.arange(width) + 0.5) / width
    v = (np.arange(h) + 0.5) / h
    uu, vv = np.meshgrid(u, v)
    dirs = latlong.uv_to_direction(uu, vv).reshape(-1, 3)
    colour, dist = trace(np.zeros_like(dirs), dirs)
    texels = np.empty((h * width, 4), np.float32)
    texels[:, :3] = colour
    texels[:, 3] = np.where(np.isfinite(dist), 1.0 / dist, 0.0)
    return texels.reshape(h, width, 4)


def uv_sphere(segments=96, rings=48):
    lat = np.linspace(-np.pi / 2, np.pi / 2, rings + 1)
    lon = np.linspace(0, 2 * np.pi, segments, endpoint=False)
    la, lo = np.meshgrid(lat, lon, indexing="ij")
    v = np.stack([np.cos(la) * np.cos(lo), np.cos(la) * np.sin(lo), np.sin(la)], -1).reshape(-1, 3)
    tris = []
    for i in range(rings):
        for j in range(segments):
            a, b = i * segments + j, i * segments + (j + 1) % segments
            c, d = a + segments, b + segments
            tris += [(a, b, d), (a, d, c)]
    return v.astype(np.float32), np.array(tris, np.int32)


@pytest.fixture(scope="module")
def frames():
    try:
        ctx = create_context()
    except Exception as exc:  # noqa: BLE001
        pytest.fail(f"no headless EGL context (Mesa llvmpipe is expected on this machine): {exc}")
    v, f = uv_sphere()
    r = Renderer(ctx, W, H)
    r.set_mesh(v, v, f)
    r.set_scene_capture(capture(), (0.0, 0.0, 0.0))
    vp = perspective(30, W / H, 0.1, 100.0) @ look_at(EYE, (0, 0, 0))
    out = {}
    for rows in ("plain", "edited"):
        c = np.zeros((0, 9))
        if rows == "edited":
            # the green handle on the magenta ball, seen at a red handle on the upper left
            p = np.array([-0.45, -0.75, 0.48])
            p /= np.linalg.norm(p)
            g = np.array(BALLS[0][0])
            c = np.array([[*p, *(p - EYE) / np.linalg.norm(p - EYE), *(g - p) / np.linalg.norm(g - p)]])
            c[0, 3:6] = c[0, 3:6] - 2 * np.dot(c[0, 3:6], p) * p  # r: the physical reflection at p
        r.set_plan(glsl.plan_field(c, n_vertices=len(v)))
        out[rows] = {
            "pos": r.render(vp, EYE, glsl.OUT_POSITION),
            "dir": r.render(vp, EYE, glsl.OUT_DIRECTION),
            "corrected": r.render(vp, EYE, glsl.OUT_COLOR, parallax=True),
            "centre": r.render(vp, EYE, glsl.OUT_COLOR, parallax=False),
        }
        if rows == "edited":
            out[rows]["red"] = p
    return out


def _errors(fr):
    mask = fr["pos"][..., 3] > 0
    # Leave out the ball's outline (a pixel there mixes two things).
    inner = mask.copy()
    for dy, dx in ((1, 0), (-1, 0), (0, 1), (0, -1)):
        inner &= np.roll(mask, (dy, dx), (0, 1))
    want, _t = trace(fr["pos"][inner][:, :3], fr["dir"][inner][:, :3])
    res = {}
    for key in ("corrected", "centre"):
        diff = np.abs(fr[key][inner][:, :3] - want).mean(-1)
        res[key] = (float(diff.mean()), float(np.percentile(diff, 95)))
    return res, int(inner.sum())


@pytest.mark.parametrize("rows", ["plain", "edited"])
def test_distance_corrected_lookup_matches_a_ray_from_q(frames, rows):
    res, n = _errors(frames[rows])
    print(f"{rows}: {n} pixels; corrected mean {res['corrected'][0]:.4f} p95 {res['corrected'][1]:.4f}; "
          f"centre-only mean {res['centre'][0]:.4f} p95 {res['centre'][1]:.4f}")
    assert n > 4000
    assert res["corrected"][0] <= 0.01 and res["corrected"][1] <= 0.05, res
    # The centre-only lookup puts the near balls in the wrong place: clearly worse.
    assert res["centre"][0] >= 3 * res["corrected"][0], res


def test_the_object_under_the_green_handle_shows_at_the_red_handle(frames):
    """The constraint's green handle is on the magenta ball (1.6 radii from the centre): the
    corrected preview shows magenta at the red handle's pixel; the centre-only one does not."""
    fr = frames["edited"]
    pos = fr["pos"]
    mask = pos[..., 3] > 0
    d = np.linalg.norm(pos[..., :3] - fr["red"], axis=-1)
    d[~mask] = np.inf
    y, x = np.unravel_index(np.argmin(d), d.shape)
    assert d[y, x] < 0.05
    magenta = np.array(BALLS[0][2])
    got = fr["corrected"][y, x, :3]
    # the ball's shading scales its colour: compare hue (normalised colour)
    unit = lambda c: np.asarray(c) / np.linalg.norm(c)  # noqa: E731
    assert np.dot(unit(got), unit(magenta)) > 0.98, got
    assert np.dot(unit(fr["centre"][y, x, :3]), unit(magenta)) < 0.95, fr["centre"][y, x, :3]
