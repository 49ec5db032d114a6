"""The viewport preview's GLSL (shaders/) against rokeby_native.reflection.edited_directions.

The shader is compiled with moderngl on a headless EGL context (Mesa llvmpipe here) from the same
files the Blender draw handler compiles (rokeby.reflection.viewport.glsl). A real mesh (spot) is rasterised; the
shader's own per-pixel position, normal, barycentric coordinates and vertex ids are read back and
given to the Rust reference, so both evaluate e(q) at exactly the same inputs.

Tolerance: the shader works in float32, Rust in float64. Over all covered pixels the angle between
the two directions must be below 1e-5 rad on average and below 3e-3 rad everywhere (measured:
about 4e-7 mean and under 1e-3 max; the largest differences sit next to a constraint, where the
twist of R about e_n is ill-conditioned but hardly moves e).
"""

import numpy as np
import pytest

moderngl = pytest.importorskip("moderngl")
rn = pytest.importorskip("rokeby_native")

from support import mesh_path  # noqa: E402
from support.gl_harness import Renderer, create_context, look_at, perspective  # noqa: E402
from support.reference import random_constraints  # noqa: E402
from rokeby.reflection.viewport import glsl  # noqa: E402
from rokeby.core.meshio import load_obj, vertex_normals  # noqa: E402

MEAN_TOL, MAX_TOL = 1e-5, 3e-3
W, H = 128, 96


def angle(a, b):
    a, b = np.asarray(a, np.float64), np.asarray(b, np.float64)
    return np.arctan2(np.linalg.norm(np.cross(a, b), axis=-1), np.sum(a * b, axis=-1))


@pytest.fixture(scope="module")
def scene():
    try:
        ctx = create_context()
    except Exception as exc:  # noqa: BLE001
        pytest.fail(f"no headless EGL context (Mesa llvmpipe is expected on this machine): {exc}")
    v, f = load_obj(mesh_path("spot.obj"))
    n = vertex_normals(v, f)
    r = Renderer(ctx, W, H)
    r.set_mesh(v, n, f)
    centre = v.mean(0)
    eye = (centre + np.array([0.3, -2.2, 0.7])).astype(np.float32)
    vp = perspective(40, W / H, 0.1, 100.0) @ look_at(eye, centre)
    r.set_plan(glsl.plan_field(np.zeros((0, 9)), n_vertices=len(v)))
    gbuf = {mode: r.render(vp, eye, mode) for mode in (glsl.OUT_POSITION, glsl.OUT_NORMAL, glsl.OUT_BARY, glsl.OUT_VERTEX_IDS)}
    mask = gbuf[glsl.OUT_POSITION][..., 3] > 0
    assert mask.sum() > 2000, "the mesh should cover a good part of the frame"
    return {
        "renderer": r,
        "v": v,
        "f": f,
        "n": n,
        "eye": eye,
        "vp": vp,
        "mask": mask,
        "pos": gbuf[glsl.OUT_POSITION][mask][:, :3],
        "nrm": gbuf[glsl.OUT_NORMAL][mask][:, :3],
        "bary": gbuf[glsl.OUT_BARY][mask][:, :3],
        "vids": np.rint(gbuf[glsl.OUT_VERTEX_IDS][mask][:, :3]).astype(np.int64),
    }


def shader_directions(s, rows, **plan_kwargs):
    r = s["renderer"]
    r.set_plan(glsl.plan_field(rows, n_vertices=len(s["v"]), **plan_kwargs))
    out = r.render(s["vp"], s["eye"], glsl.OUT_DIRECTION)
    assert np.array_equal(out[..., 3] > 0, s["mask"]), "coverage changed between passes"
    return out[s["mask"]][:, :3]


def per_pixel(s, per_vertex):
    """Per-vertex values (..., V) interpolated at the pixels as the shader does (+inf stays)."""
    vals = np.asarray(per_vertex, np.float64)[..., s["vids"]]  # (..., N, 3)
    out = np.sum(vals * s["bary"], axis=-1)
    return np.where(np.isinf(vals).any(axis=-1), np.inf, out).astype(np.float32)


def check(got, want):
    err = angle(got, want)
    assert np.all(np.isfinite(got))
    assert err.mean() < MEAN_TOL and err.max() < MAX_TOL, f"mean {err.mean():.2e}, max {err.max():.2e} rad"
    return err


def test_uniform_block_layout_matches_the_driver(scene):
    prog = scene["renderer"].program
    assert prog["rk_field_block"].size == glsl.BLOCK_SIZE
    assert glsl.MAX_CONSTRAINTS == 64 and glsl.MAX_REGIONS == 8


def test_gbuffer_is_the_rasterised_mesh(scene):
    """The read-back inputs are what the shader used: bary sums to 1 and positions lie on the
    triangles the vertex ids name."""
    s = scene
    np.testing.assert_allclose(s["bary"].sum(1), 1.0, atol=5e-4)  # perspective-correct interpolation in float32
    recon = np.einsum("nk,nkj->nj", s["bary"], s["v"][s["vids"]])
    np.testing.assert_allclose(recon, s["pos"], atol=1e-3)


def test_no_constraints_gives_the_physical_reflection(scene):
    s = scene
    got = shader_directions(s, np.zeros((0, 9), np.float32))
    want = rn.reflection.edited_directions(s["pos"], s["nrm"], s["eye"], np.zeros((0, 9), np.float32))
    i = s["pos"] - s["eye"]
    i /= np.linalg.norm(i, axis=1, keepdims=True)
    nn = s["nrm"] / np.linalg.norm(s["nrm"], axis=1, keepdims=True)
    mirror = i - 2 * np.sum(i * nn, 1, keepdims=True) * nn
    check(got, want)
    check(got, mirror)


@pytest.mark.parametrize("k", [1, 2, 8, 32, 64])
def test_euclidean_field_matches_rust(scene, k):
    s = scene
    rng = np.random.default_rng(100 + k)
    rows = random_constraints(rng, k, 0, max_edit=0.8, min_edit=0.1, at=s["v"])
    got = shader_directions(s, rows)
    want = rn.reflection.edited_directions(s["pos"], s["nrm"], s["eye"], rows)
    check(got, want)
    # The edit is visible: the directions differ from the physical reflection.
    plain = rn.reflection.edited_directions(s["pos"], s["nrm"], s["eye"], rows[:0])
    assert angle(got, plain).mean() > 0.05


@pytest.mark.parametrize("method", ["heat", "dijkstra"])
def test_per_vertex_geodesic_distances_match_rust(scene, method):
    s = scene
    rng = np.random.default_rng(7)
    picks = rng.choice(len(s["v"]), 6, replace=False)
    rows = random_constraints(rng, 6, 0, max_edit=0.8, min_edit=0.1)
    rows[:, :3] = s["v"][picks]
    d = rn.geometry.GeodesicSolver(s["v"], s["f"]).distances([int(i) for i in picks], method=method)
    got = shader_directions(s, rows, distances=d)
    want = rn.reflection.edited_directions(s["pos"], s["nrm"], s["eye"], rows, distances=per_pixel(s, d))
    check(got, want)
    # Geodesic and Euclidean fields differ on this non-convex mesh: the distances were used.
    euclid = rn.reflection.edited_directions(s["pos"], s["nrm"], s["eye"], rows)
    assert angle(got, euclid).max() > 1e-2


def test_regions_euclidean_and_per_vertex_match_rust(scene):
    s = scene
    v = s["v"]
    rng = np.random.default_rng(11)
    picks = rng.choice(len(v), 5, replace=False)
    rows = random_constraints(rng, 5, 0, max_edit=0.9, min_edit=0.2)
    rows[:, :3] = v[picks]
    size = float(np.linalg.norm(v.max(0) - v.min(0)))
    # A Euclidean region around constraint 0 and a per-vertex region (a smooth blob, as a
    # geodesic or free-form region gives) around constraint 3; they overlap partly.
    c0 = v[picks[0]]
    d3 = np.linalg.norm(v - v[picks[3]], axis=1)
    t = np.clip((d3 - 0.15 * size) / (0.2 * size), 0, 1)
    values = (1 - t * t * (3 - 2 * t)).astype(np.float32)
    at = values[picks]
    regions = [
        {"kind": "euclidean", "center": c0.tolist(), "radius": 0.4 * size, "border": 0.2 * size},
        {"kind": "weights", "values": values, "at_constraints": at},
    ]
    plan = glsl.plan_field(rows, regions, n_vertices=len(v))
    assert len(plan.groups) == 2 and all(len(g.members) >= 1 for g in plan.groups)
    got = shader_directions(s, rows, regions=regions)
    px_regions = [regions[0], {"kind": "weights", "values": per_pixel(s, values), "at_constraints": at}]
    want = rn.reflection.edited_directions(s["pos"], s["nrm"], s["eye"], rows, regions=px_regions)
    check(got, want)
    plain = rn.reflection.edited_directions(s["pos"], s["nrm"], s["eye"], rows[:0])
    outside = angle(want, plain) == 0
    assert 0.05 < outside.mean() < 0.95, "part of the mirror lies outside both regions"
    assert np.all(angle(got[outside], plain[outside]) < 1e-5), "outside every region the reflection is unchanged"
    # With per-vertex distances and regions together.
    d = rn.geometry.GeodesicSolver(v, s["f"]).distances([int(i) for i in picks], method="dijkstra")
    got = shader_directions(s, rows, regions=regions, distances=d)
    want = rn.reflection.edited_directions(s["pos"], s["nrm"], s["eye"], rows, regions=px_regions, distances=per_pixel(s, d))
    check(got, want)


def test_regions_without_constraints_change_nothing(scene):
    s = scene
    rows = random_constraints(np.random.default_rng(3), 3, 0, at=s["v"])
    far = (s["v"].max(0) + 100.0).tolist()
    regions = [{"kind": "euclidean", "center": far, "radius": 1.0, "border": 0.5}]
    got = shader_directions(s, rows, regions=regions)
    check(got, rn.reflection.edited_directions(s["pos"], s["nrm"], s["eye"], rows[:0]))


def test_half_turns_and_rank_deficient_inputs(scene):
    s = scene
    v = s["v"]
    rng = np.random.default_rng(5)
    # One constraint asking for the opposite direction: a half turn about glam's
    # any_orthonormal_vector(r), the same everywhere.
    r = np.array([0.3, -0.5, 0.8])
    r /= np.linalg.norm(r)
    one = np.array([[*v[10], *r, *(-r)]], np.float32)
    got = shader_directions(s, one)
    check(got, rn.reflection.edited_directions(s["pos"], s["nrm"], s["eye"], one))
    # Two constraints, both half turns: M = -(w1 r1 r1^T + w2 r2 r2^T) is rank 2 and negative
    # semi-definite; ortho(M) is the half turn about r1 x r2.
    r2 = np.array([-0.6, 0.2, 0.7])
    r2 /= np.linalg.norm(r2)
    two = np.array([[*v[10], *r, *(-r)], [*v[2000], *r2, *(-r2)]], np.float32)
    got = shader_directions(s, two)
    check(got, rn.reflection.edited_directions(s["pos"], s["nrm"], s["eye"], two))
    # A pixel exactly on a constraint: interpolation, with a rank-1 M there whose twist the
    # other constraints choose (ortho_tiebreak).
    rows = random_constraints(rng, 3, 0, max_edit=0.8, min_edit=0.2, at=v)
    hit = len(s["pos"]) // 2
    rows[0, :3] = s["pos"][hit]
    got = shader_directions(s, rows)
    want = rn.reflection.edited_directions(s["pos"], s["nrm"], s["eye"], rows)
    check(got, want)
    assert angle(got[hit:hit + 1], want[hit:hit + 1])[0] < 1e-4


def test_environment_lookup_follows_blenders_equirectangular_convention(scene):
    """A colour-coded lat-long image (16 x 8 cells): each mirror pixel shows the cell that
    Blender's Environment Texture node reads for the reflected direction d:
    u = 0.5 - atan2(d.y, d.x) / 2pi, v = 0.5 + atan2(d.z, hypot(d.x, d.y)) / pi, row 0 at the
    bottom (EEVEE's node_tex_environment_equirectangular; rokeby.reflection.render.reflmap.direction_to_uv)."""
    s = scene
    r = s["renderer"]
    cells_u, cells_v, px = 16, 8, 8
    cu, cv = np.meshgrid(np.arange(cells_u), np.arange(cells_v))
    colours = np.stack([(cu + 0.5) / cells_u, (cv + 0.5) / cells_v, ((cu * 7 + cv * 3) % 5) / 4.0], -1)
    image = np.repeat(np.repeat(colours, px, axis=0), px, axis=1).astype(np.float32)  # row 0 = v near 0
    r.set_environment(image)
    try:
        r.set_plan(glsl.plan_field(np.zeros((0, 9)), n_vertices=len(s["v"])))
        out = r.render(s["vp"], s["eye"], glsl.OUT_COLOR)[s["mask"]][:, :3]
    finally:
        r.env_tex = None
    d = rn.reflection.edited_directions(s["pos"], s["nrm"], s["eye"], np.zeros((0, 9), np.float32)).astype(np.float64)
    u = 0.5 - np.arctan2(d[:, 1], d[:, 0]) / (2 * np.pi)
    vv = np.arctan2(d[:, 2], np.hypot(d[:, 0], d[:, 1])) / np.pi + 0.5
    fu, fv = u * cells_u, vv * cells_v
    # away from cell borders (bilinear filtering mixes neighbours there)
    inner = (np.abs(fu - np.round(fu)) > 0.1) & (np.abs(fv - np.round(fv)) > 0.1)
    iu, iv = np.floor(fu).astype(int) % cells_u, np.clip(np.floor(fv).astype(int), 0, cells_v - 1)
    want = colours[iv, iu]
    assert inner.sum() > 1000 and len({(a, b) for a, b in zip(iu[inner], iv[inner])}) >= 8
    np.testing.assert_allclose(out[inner], want[inner], atol=1e-4)
    # The u axis is not mirrored and v is not flipped: a mismatch would show here.
    assert np.mean(np.all(np.abs(out[inner] - colours[cells_v - 1 - iv, iu][inner]) < 1e-4, axis=1)) < 0.5
    assert np.mean(np.all(np.abs(out[inner] - colours[iv, cells_u - 1 - iu][inner]) < 1e-4, axis=1)) < 0.5


def test_beyond_the_constraint_limit_the_per_vertex_field_is_shown(scene):
    s = scene
    v = s["v"]
    rows = random_constraints(np.random.default_rng(9), glsl.MAX_CONSTRAINTS + 6, 0, max_edit=0.6, at=v)
    with pytest.raises(ValueError, match="needs the stored rotation vectors"):
        glsl.plan_field(rows, n_vertices=len(v))
    rv = rn.reflection.rotation_field(v, rows, output="rotation_vector")
    plan = glsl.plan_field(rows, n_vertices=len(v), rotations=rv)
    assert plan.mode == glsl.PER_VERTEX_FIELD and "70 constraints" in plan.message and "per-vertex" in plan.message
    got = shader_directions(s, rows, rotations=rv)
    # e = R(interpolated rotation vector) r, as the render node group does.
    rvp = per_pixel(s, rv.T).T.astype(np.float64)
    physical = rn.reflection.edited_directions(s["pos"], s["nrm"], s["eye"], rows[:0]).astype(np.float64)
    ang = np.linalg.norm(rvp, axis=1, keepdims=True)
    k = rvp / np.maximum(ang, 1e-30)
    want = physical * np.cos(ang) + np.cross(k, physical) * np.sin(ang) + k * np.sum(k * physical, 1, keepdims=True) * (1 - np.cos(ang))
    check(got, want)


@pytest.mark.parametrize(
    "kwargs, words",
    [
        (dict(rows=np.zeros((2, 8))), "expected shape (K, 9)"),
        (dict(rows=np.array([[0, 0, 0, 0, 0, 0, 0, 0, 1.0]])), "row 0: r (columns 3-5) has zero length"),
        (dict(rows=np.zeros((0, 9)), distances=np.zeros((1, 5))), "distances: expected shape (0, 10)"),
        (dict(rows=np.zeros((0, 9)), regions=[{"kind": "euclidean", "center": [0, 0, 0], "radius": 0.0}]), "radius must be finite and > 0"),
        (dict(rows=np.zeros((0, 9)), regions=[{"kind": "weights", "values": np.ones(3), "at_constraints": []}]), "values has 3 entries but the mesh has 10 vertices"),
        (dict(rows=np.zeros((0, 9)), regions=[{"kind": "cube"}]), "unknown kind 'cube'"),
    ],
)
def test_plan_rejects_bad_input_with_clear_errors(kwargs, words):
    rows = kwargs.pop("rows")
    with pytest.raises(ValueError) as info:
        glsl.plan_field(rows, n_vertices=10, **kwargs)
    assert words in str(info.value)


def test_triangle_soup_rejects_bad_indices():
    v = np.zeros((3, 3), np.float32)
    with pytest.raises(ValueError, match="vertex index out of range"):
        glsl.triangle_soup(v, v, np.array([[0, 1, 3]]))


@pytest.mark.slow  # a fresh bpy process, its GPU context and shader compile: 215 s measured on the shared 2-core machine
def test_blender_compiles_and_draws_the_same_shader_offscreen():
    """The add-on's own draw path (rokeby.reflection.viewport.draw: GPUShaderCreateInfo from shaders/, batches,
    uniform block, textures, overlays) in bpy, offscreen, against the Rust reference on the
    evaluator's inputs (3 constraints in a Euclidean region on a UV sphere)."""
    pytest.importorskip("bpy")
    from support.bpy_process import run_check

    res = run_check("reflection/blender_viewport_check.py")
    assert res["error"] is None and res["status"] is None
    assert res["covered"] > 1000
    assert res["mean_err"] < MEAN_TOL and res["max_err"] < MAX_TOL, res
    assert res["edited_fraction"] > 0.5, "the edit shows on most of the mirror"
    assert res["drawn"] == 1 and res["drawn_pixels"] > res["covered"], "the overlays draw beyond the mirror"
    # The shadow-editing overlay (#7) draws its boundary lines through Blender's gpu module too.
    assert res["shadow_lines"] > 20 and res["shadow_overlay_pixels"] > 20, res


def test_region_border_lines_lie_on_the_level_set():
    pytest.importorskip("bpy")
    from rokeby.reflection.viewport import draw as viewport

    xs, ys = np.meshgrid(np.linspace(0, 1, 21), np.linspace(0, 1, 21))
    v = np.stack([xs.ravel(), ys.ravel(), np.zeros(xs.size)], 1).astype(np.float32)
    idx = np.arange(21 * 21).reshape(21, 21)
    a, b, c, d = idx[:-1, :-1].ravel(), idx[:-1, 1:].ravel(), idx[1:, :-1].ravel(), idx[1:, 1:].ravel()
    tris = np.concatenate([np.stack([a, b, d], 1), np.stack([a, d, c], 1)])
    seg = viewport.iso_segments(v, tris, v[:, 0] * 0.8 + 0.1, 0.5)  # crosses at x = 0.5
    assert len(seg) == 2 * 2 * 20  # two segments per row of cells (two triangles each)
    np.testing.assert_allclose(seg[:, 0], 0.5, atol=1e-6)
    assert seg[:, 1].min() == 0 and seg[:, 1].max() == 1
    ring = viewport.circle((1, 2, 3), 2.0, (1, 0, 0), (0, 0, 1))
    np.testing.assert_allclose(np.linalg.norm(ring - [1, 2, 3], axis=1), 2.0, atol=1e-5)
