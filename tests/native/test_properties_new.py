"""Property-based tests of the rokeby_native entry points of compositing, environment maps and shadows:
rokeby_native.compositing (sh_fit, sh_eval, reflect_dirs, reflection_env, fill_holes, envmap_lookup,
recomposite), rokeby_native.envmaps (convert, sample, prefilter, irradiance, prefilter_reference)
and rokeby_native.shadows (silhouettes, falloff_factor, ShadowEditor).

Random valid arrays must give results of the right shape and dtype that are finite and satisfy a
property of the maths; adversarial arrays (wrong shapes, NaN, inf, empty, wrong dtype) must raise
ValueError/TypeError whose message names the argument, never a pyo3 PanicException (a
BaseException, which the `pytest.raises` below would not catch) or a crash. Seeded and bounded."""

import numpy as np
import pytest
import rokeby_native as rn
from hypothesis import given, settings
from hypothesis import strategies as st
from support.reference import uv_sphere

FEW = settings(max_examples=25, deadline=None, derandomize=True)
SOME = settings(max_examples=60, deadline=None, derandomize=True)
SLOW = settings(max_examples=6, deadline=None, derandomize=True)

seeds = st.integers(0, 2**32 - 1)
BAD_FLOATS = st.sampled_from([np.nan, np.inf, -np.inf])
LAYOUTS = ["latlong", "cube", "sphere", "paraboloid"]


def raises_naming(name, fn, *args, **kwargs):
    """fn(*args, **kwargs) raises ValueError/TypeError (or OverflowError for a negative index)
    whose message names `name`."""
    with pytest.raises((ValueError, TypeError, OverflowError)) as e:
        fn(*args, **kwargs)
    assert name in str(e.value), f"{type(e.value).__name__}: {e.value!r} does not name {name!r}"


def unit(rng, n):
    v = rng.normal(size=(n, 3))
    return (v / np.linalg.norm(v, axis=1, keepdims=True)).astype(np.float32)


def with_bad_entry(a, data, value):
    a = np.array(a, copy=True)
    idx = tuple(data.draw(st.integers(0, s - 1)) for s in a.shape)
    a[idx] = value
    return a


def env_shape(layout, size, c):
    return {"latlong": (size, 2 * size, c), "cube": (6, size, size, c), "sphere": (size, size, c), "paraboloid": (2, size, size, c)}[layout]


def smooth_env(layout, size, c, rng):
    """A smooth environment L(d) = a + b·d per channel, as a lat-long map converted to `layout`."""
    a = rng.uniform(1.0, 2.0, c)
    b = rng.uniform(-0.5, 0.5, (c, 3))
    h, w = 64, 128
    th = np.pi * (np.arange(h) + 0.5) / h
    ph = 2 * np.pi * (np.arange(w) + 0.5) / w
    # Any direction convention will do: the map is a smooth function of the texel's direction.
    d = np.stack([np.outer(np.sin(th), np.cos(ph)), np.outer(np.sin(th), np.sin(ph)), np.repeat(np.cos(th)[:, None], w, 1)], -1)
    ll = (a + d @ b.T).astype(np.float32)
    return ll if layout == "latlong" and size == h else rn.envmaps.convert(ll, "latlong", layout, size, 2)


# ---------------------------------------------------------------------------------------------
# sh_fit / sh_eval (eq. 1)


@SOME
@given(seed=seeds, n=st.integers(12, 200), c=st.integers(1, 4))
def test_sh_fit_recovers_sh_eval(seed, n, c):
    rng = np.random.default_rng(seed)
    coeffs = rng.normal(size=(c, 9))
    normals = unit(rng, n) * rng.uniform(0.5, 3.0, (n, 1)).astype(np.float32)  # need not be unit
    values = rn.compositing.sh_eval(coeffs, normals)
    assert values.dtype == np.float32 and values.shape == (n, c) and np.all(np.isfinite(values))
    for method in ["ls", "qp"]:
        r = rn.compositing.sh_fit(normals, values, method=method)
        assert r["coeffs"].shape == (c, 9) and r["coeffs"].dtype == np.float64
        assert np.all(np.isfinite(r["coeffs"])) and r["pixels"] == n and r["masked"] == 0
        # float32 values: the recovered coefficients are exact up to the input's rounding.
        np.testing.assert_allclose(r["coeffs"], coeffs, atol=2e-3 * (1 + np.abs(coeffs).max()))
        assert np.all(r["rms_residual"] >= 0)
    # The constrained fit keeps D(n) ≥ D0 on arbitrary (non-SH) data.
    raw = rng.normal(size=(n, c)).astype(np.float32)
    q = rn.compositing.sh_fit(normals, raw, method="qp")
    assert np.all(q["max_residual"] <= 1e-6 * (1 + np.abs(raw).max()))
    assert np.all(rn.compositing.sh_eval(q["coeffs"], normals) >= raw - 1e-4 * (1 + np.abs(raw).max()))


@FEW
@given(seed=seeds, data=st.data(), bad=BAD_FLOATS)
def test_sh_fit_leaves_out_bad_rows(seed, data, bad):
    rng = np.random.default_rng(seed)
    coeffs = rng.normal(size=(1, 9))
    normals = unit(rng, 40)
    values = rn.compositing.sh_eval(coeffs, normals)
    nb = with_bad_entry(normals, data, bad)
    r = rn.compositing.sh_fit(nb, values, method="ls")
    assert r["masked"] == 1 and r["pixels"] == 39
    np.testing.assert_allclose(r["coeffs"], coeffs, atol=2e-3 * (1 + np.abs(coeffs).max()))


@FEW
@given(n=st.integers(0, 5), k=st.sampled_from([1, 2, 4]), dtype=st.sampled_from(["U3", "O", "complex64"]))
def test_sh_adversarial(n, k, dtype):
    good_n = unit(np.random.default_rng(0), 20)
    good_v = np.ones((20, 1), np.float32)
    raises_naming("normals", rn.compositing.sh_fit, np.ones((20, k), np.float32), good_v)
    raises_naming("normals", rn.compositing.sh_fit, np.ones((20, 3, 1), np.float32), good_v)
    raises_naming("normals", rn.compositing.sh_fit, good_n.astype(dtype), good_v)
    raises_naming("values", rn.compositing.sh_fit, good_n, good_v[: max(0, 20 - n - 1)])
    raises_naming("normals", rn.compositing.sh_fit, np.zeros((n, 3), np.float32), np.ones((n, 1), np.float32))  # zero normals
    raises_naming("normals", rn.compositing.sh_fit, good_n, np.full((20, 1), np.nan, np.float32))  # nothing usable
    raises_naming("method", rn.compositing.sh_fit, good_n, good_v, method="lsqr")
    raises_naming("coeffs", rn.compositing.sh_eval, np.ones((1, 9 - k)), good_n)
    raises_naming("normals", rn.compositing.sh_eval, np.ones((1, 9)), np.ones((20, k), np.float32))


# ---------------------------------------------------------------------------------------------
# reflect_dirs, envmap_lookup, fill_holes, reflection_env (§3.2)


@SOME
@given(seed=seeds, h=st.integers(1, 9), w=st.integers(1, 9), ortho=st.booleans())
def test_reflect_dirs_is_a_mirror(seed, h, w, ortho):
    rng = np.random.default_rng(seed)
    n = unit(rng, h * w).reshape(h, w, 3) * 2.0
    v = unit(rng, 1)[0] if ortho else unit(rng, h * w).reshape(h, w, 3)
    r = rn.compositing.reflect_dirs(n, v)
    assert r.shape == (h, w, 3) and r.dtype == np.float32 and np.all(np.isfinite(r))
    nn = n / np.linalg.norm(n, axis=-1, keepdims=True)
    vv = np.broadcast_to(v, r.shape)
    np.testing.assert_allclose(np.linalg.norm(r, axis=-1), 1.0, atol=1e-5)
    np.testing.assert_allclose(np.sum(r * nn, -1), np.sum(vv * nn, -1), atol=1e-5)  # same angle to n
    np.testing.assert_allclose(np.cross(r + vv, nn), 0.0, atol=1e-5)  # r + v along n


def test_reflect_dirs_adversarial():
    n = unit(np.random.default_rng(0), 12).reshape(3, 4, 3)
    raises_naming("normals", rn.compositing.reflect_dirs, n.reshape(12, 3), n)
    raises_naming("view", rn.compositing.reflect_dirs, n, n[:2])
    raises_naming("normals", rn.compositing.reflect_dirs, n.astype("U4"), n)
    r = rn.compositing.reflect_dirs(np.where(np.arange(3)[:, None, None] == 0, np.nan, n).astype(np.float32), n)
    assert np.all(np.isnan(r[0])) and np.all(np.isfinite(r[1:]))  # bad pixels are NaN, not errors


@SOME
@given(seed=seeds, s=st.integers(2, 12), c=st.integers(1, 4))
def test_envmap_lookup_is_a_bilinear_mean(seed, s, c):
    rng = np.random.default_rng(seed)
    m = rng.uniform(-2, 3, (2, s, s, c)).astype(np.float32)
    d = rng.normal(size=(5, 7, 3)).astype(np.float32)
    out = rn.compositing.envmap_lookup(m, d)
    assert out.shape == (5, 7, c) and out.dtype == np.float32 and np.all(np.isfinite(out))
    assert np.all(out >= m.min() - 1e-5) and np.all(out <= m.max() + 1e-5)
    k = rng.uniform(-1, 1, c).astype(np.float32)
    np.testing.assert_allclose(rn.compositing.envmap_lookup(np.broadcast_to(k, m.shape).copy(), d), np.broadcast_to(k, out.shape), atol=1e-6)


@FEW
@given(data=st.data(), bad=BAD_FLOATS)
def test_envmap_lookup_adversarial(data, bad):
    m = np.ones((2, 4, 4, 3), np.float32)
    raises_naming("map", rn.compositing.envmap_lookup, with_bad_entry(m, data, bad), np.ones((1, 3)))
    raises_naming("map", rn.compositing.envmap_lookup, np.ones((2, 4, 5, 3), np.float32), np.ones((1, 3)))
    raises_naming("map", rn.compositing.envmap_lookup, np.ones((3, 4, 4, 3), np.float32), np.ones((1, 3)))
    raises_naming("map", rn.compositing.envmap_lookup, np.ones((2, 0, 0, 3), np.float32), np.ones((1, 3)))
    raises_naming("dirs", rn.compositing.envmap_lookup, m, np.ones((2, 2)))


def disk(s):
    u = (np.arange(s) + 0.5) * 2 / s - 1
    return (u[None, :] ** 2 + u[:, None] ** 2) <= 1


@SOME
@given(seed=seeds, s=st.integers(3, 16), c=st.integers(1, 3), frac=st.floats(0.05, 0.9))
def test_fill_holes_keeps_data_and_the_maximum_principle(seed, s, c, frac):
    rng = np.random.default_rng(seed)
    m = rng.uniform(-1, 2, (2, s, s, c)).astype(np.float32)
    covered = (rng.uniform(size=(2, s, s)) < frac) & disk(s)[None]
    covered[0, s // 2, s // 2] = True
    out = rn.compositing.fill_holes(m, covered)
    assert out.shape == m.shape and out.dtype == np.float32 and np.all(np.isfinite(out))
    np.testing.assert_array_equal(out[covered], m[covered])  # Dirichlet values stay
    inside = np.broadcast_to(disk(s)[None], covered.shape)
    lo, hi = m[covered].min(0), m[covered].max(0)
    assert np.all(out[inside] >= lo - 1e-4) and np.all(out[inside] <= hi + 1e-4)  # harmonic: no new extremes


def test_fill_holes_adversarial():
    m = np.ones((2, 4, 4, 3), np.float32)
    cov = np.ones((2, 4, 4), bool)
    raises_naming("covered", rn.compositing.fill_holes, m, np.zeros((2, 4, 4), bool))
    raises_naming("covered", rn.compositing.fill_holes, m, cov[:, :3])
    raises_naming("map", rn.compositing.fill_holes, m[:, :3], cov)
    raises_naming("map", rn.compositing.fill_holes, np.full_like(m, np.inf), cov)


def sphere_image(hw):
    """An orthographic view of a mirror sphere: normals (H, W, 3), mask, view +Z."""
    y, x = np.mgrid[0:hw, 0:hw]
    u, v = (x + 0.5) / hw * 2 - 1, 1 - (y + 0.5) / hw * 2
    z2 = 1 - u * u - v * v
    mask = z2 > 0.02
    n = np.stack([u, v, np.sqrt(np.clip(z2, 0, None))], -1).astype(np.float32)
    n[~mask] = [0, 0, 1]
    return n, mask.astype(np.float32)


@SLOW
@given(seed=seeds, size=st.sampled_from([8, 16]))
def test_reflection_env_recovers_a_linear_environment(seed, size):
    rng = np.random.default_rng(seed)
    n, mask = sphere_image(40)
    r = rn.compositing.reflect_dirs(n, np.array([0, 0, 1], np.float32))
    a, b = rng.uniform(1, 2, 3), rng.uniform(-0.4, 0.4, (3, 3))
    values = (a + r @ b.T).astype(np.float32)
    out = rn.compositing.reflection_env(r, values, mask, size=size, blur_sigma=0.0)
    m = out["map"]
    assert m.shape == (2, size, size, 3) and m.dtype == np.float32 and np.all(np.isfinite(m))
    assert 0.3 < out["coverage"] <= 1.0
    # Directions seen by the sphere's interior come back as the environment's values.
    d = r[mask > 0][::7]
    d = d[d[:, 2] > -0.5]
    np.testing.assert_allclose(rn.compositing.envmap_lookup(m, d), a + d @ b.T, atol=0.15)


def test_reflection_env_adversarial():
    n, mask = sphere_image(16)
    r = rn.compositing.reflect_dirs(n, np.array([0, 0, 1], np.float32))
    vals = np.ones_like(r)
    raises_naming("mask", rn.compositing.reflection_env, r, vals, mask[:-1])
    raises_naming("values", rn.compositing.reflection_env, r, vals[:, :-1], mask)
    raises_naming("size", rn.compositing.reflection_env, r, vals, mask, size=0)
    raises_naming("stage", rn.compositing.reflection_env, r, vals, mask, stage="half")
    raises_naming("mask", rn.compositing.reflection_env, r, vals, np.zeros_like(mask))  # covers nothing
    raises_naming("depth", rn.compositing.reflection_env, r, vals, mask, depth=np.ones((3, 3), np.float32))
    for kw in [dict(max_edge_angle=np.nan), dict(blur_sigma=-1.0), dict(blur_sigma=np.nan), dict(min_coverage=np.nan), dict(min_coverage=2.0), dict(max_depth_jump=np.nan)]:
        raises_naming(next(iter(kw)), rn.compositing.reflection_env, r, vals, mask, size=8, **kw)
    # NaN pixels are left out, not errors.
    rb = r.copy()
    rb[8, 8] = np.nan
    assert np.all(np.isfinite(rn.compositing.reflection_env(rb, vals, mask, size=8)["map"]))


# ---------------------------------------------------------------------------------------------
# recomposite (eqs. 3–5)


def recomposite_inputs(rng, h, w, npatch):
    ids = rng.integers(-1, npatch + 1, (h, w)).astype(np.int32)
    n = unit(rng, h * w).reshape(h, w, 3)
    n[..., 2] = np.abs(n[..., 2]) + 0.1
    img = rng.uniform(0, 1, (h, w, 3)).astype(np.float32)
    dif = rng.uniform(0, 1, (h, w, 3)).astype(np.float32)
    ref = rng.uniform(0, 1, (h, w, 3)).astype(np.float32)
    patches = [{"sh": rng.normal(size=(3, 9)), "env": rng.uniform(0, 1, (2, 4, 4, 3)).astype(np.float32)} for _ in range(npatch)]
    return ids, n, img, dif, ref, patches


@SOME
@given(seed=seeds, h=st.integers(1, 8), w=st.integers(1, 8), npatch=st.integers(0, 3), gamma=st.floats(0.5, 2.5))
def test_recomposite_unmodified_normals_return_the_image(seed, h, w, npatch, gamma):
    rng = np.random.default_rng(seed)
    ids, n, img, dif, ref, patches = recomposite_inputs(rng, h, w, npatch)
    view = np.array([0, 0, 1], np.float32)
    out, stats = rn.compositing.recomposite(ids, n, n.copy(), view, dif, ref, img, patches, gamma=gamma)
    assert out.shape == (h, w, 3) and out.dtype == np.float32
    np.testing.assert_array_equal(out, img)
    # Edited normals: finite output, pixels outside every patch unchanged.
    e = unit(rng, h * w).reshape(h, w, 3)
    out, stats = rn.compositing.recomposite(ids, n, e, view, dif, ref, img, patches, gamma=gamma, alpha=np.ones((h, w), np.float32))
    assert np.all(np.isfinite(out))
    outside = (ids < 0) | (ids >= npatch)
    np.testing.assert_array_equal(out[outside], img[outside])
    assert stats["edited"] + stats["masked"] <= int((~outside).sum())
    # α = 0 everywhere: eq. 5 adds nothing.
    out0, _ = rn.compositing.recomposite(ids, n, e, view, dif, ref, img, patches, gamma=gamma, alpha=np.zeros((h, w), np.float32))
    np.testing.assert_allclose(out0, img, atol=1e-6)


@FEW
@given(seed=seeds, data=st.data(), bad=BAD_FLOATS)
def test_recomposite_adversarial(seed, data, bad):
    rng = np.random.default_rng(seed)
    ids, n, img, dif, ref, patches = recomposite_inputs(rng, 4, 5, 2)
    ids[:] = 0
    e = unit(rng, 20).reshape(4, 5, 3)
    v = np.array([0, 0, 1], np.float32)
    # A non-finite input pixel is left as the image (masked), never an error or a NaN elsewhere.
    db = with_bad_entry(dif, data, bad)
    out, st_ = rn.compositing.recomposite(ids, n, e, v, db, ref, img, patches)
    bad_px = ~np.all(np.isfinite(db), -1)
    np.testing.assert_array_equal(out[bad_px], img[bad_px])
    assert np.all(np.isfinite(out)) and st_["masked"] >= 1
    raises_naming("normals", rn.compositing.recomposite, ids, n[:3], e, v, dif, ref, img, patches)
    raises_naming("edited_normals", rn.compositing.recomposite, ids, n, e[..., :2], v, dif, ref, img, patches)
    raises_naming("view", rn.compositing.recomposite, ids, n, e, v[:2], dif, ref, img, patches)
    raises_naming("image", rn.compositing.recomposite, ids, n, e, v, dif, ref, img[:, :4], patches)
    raises_naming("alpha", rn.compositing.recomposite, ids, n, e, v, dif, ref, img, patches, alpha=np.ones((2, 2), np.float32))
    raises_naming("patches", rn.compositing.recomposite, ids, n, e, v, dif, ref, img, "not a list")
    raises_naming("patches[1]", rn.compositing.recomposite, ids, n, e, v, dif, ref, img, [patches[0], 3])
    raises_naming("patches[0].sh", rn.compositing.recomposite, ids, n, e, v, dif, ref, img, [{"sh": np.ones((3, 8))}])
    raises_naming("patches[0].env", rn.compositing.recomposite, ids, n, e, v, dif, ref, img, [{"env": np.ones((2, 4, 4, 2), np.float32)}])
    raises_naming("patches[0].env", rn.compositing.recomposite, ids, n, e, v, dif, ref, img, [{"env": np.ones((2, 0, 0, 3), np.float32)}])
    raises_naming("gamma", rn.compositing.recomposite, ids, n, e, v, dif, ref, img, patches, gamma=0.0)
    raises_naming("epsilon", rn.compositing.recomposite, ids, n, e, v, dif, ref, img, patches, epsilon=-1.0)
    raises_naming("k_d", rn.compositing.recomposite, ids, n, e, v, dif, ref, img, patches, k_d=np.nan)
    raises_naming("ids", rn.compositing.recomposite, ids.astype(np.float32)[:2], n, e, v, dif, ref, img, patches)


# ---------------------------------------------------------------------------------------------
# environment maps


@FEW
@given(seed=seeds, src=st.sampled_from(LAYOUTS), dst=st.sampled_from(LAYOUTS), size=st.integers(2, 12), c=st.integers(1, 3), ss=st.integers(1, 3))
def test_env_convert_shapes_constants_and_range(seed, src, dst, size, c, ss):
    rng = np.random.default_rng(seed)
    k = rng.uniform(-1, 2, c).astype(np.float32)
    const = np.broadcast_to(k, env_shape(src, size, c)).copy()
    out = rn.envmaps.convert(const, src, dst, size, ss)
    assert out.shape == env_shape(dst, size, c) and out.dtype == np.float32
    np.testing.assert_allclose(out, np.broadcast_to(k, out.shape), atol=1e-5)
    m = rng.uniform(-1, 2, env_shape(src, size, c)).astype(np.float32)
    out = rn.envmaps.convert(m, src, dst, size, ss)
    assert np.all(np.isfinite(out)) and out.min() >= m.min() - 1e-5 and out.max() <= m.max() + 1e-5


@SLOW
@given(seed=seeds, via=st.sampled_from(["cube", "paraboloid", "sphere"]))
def test_env_convert_round_trips_a_smooth_environment(seed, via):
    rng = np.random.default_rng(seed)
    ll = smooth_env("latlong", 64, 3, rng)
    there = rn.envmaps.convert(ll, "latlong", via, 64, 2)
    back = rn.envmaps.convert(there, via, "latlong", 64, 2)
    err = np.abs(back - ll)
    # The sphere map squeezes the hemisphere behind it into its rim: judge it by the median.
    assert (np.median(err) if via == "sphere" else err.max()) < 0.03, f"round trip through {via}: error {err.max():.3g}"


@SOME
@given(seed=seeds, layout=st.sampled_from(LAYOUTS), size=st.integers(2, 10), c=st.integers(1, 3))
def test_env_sample_is_a_bilinear_mean(seed, layout, size, c):
    rng = np.random.default_rng(seed)
    m = rng.uniform(-1, 2, env_shape(layout, size, c)).astype(np.float32)
    d = rng.normal(size=(3, 4, 3)).astype(np.float32)
    out = rn.envmaps.sample(m, layout, d)
    assert out.shape == (3, 4, c) and out.dtype == np.float32 and np.all(np.isfinite(out))
    assert out.min() >= m.min() - 1e-5 and out.max() <= m.max() + 1e-5
    # Scale invariance: directions need not be unit.
    np.testing.assert_allclose(rn.envmaps.sample(m, layout, d * 7.5), out, atol=1e-5)


@FEW
@given(data=st.data(), bad=BAD_FLOATS, layout=st.sampled_from(LAYOUTS))
def test_environment_adversarial(data, bad, layout):
    m = np.ones(env_shape(layout, 4, 3), np.float32)
    raises_naming("image", rn.envmaps.convert, with_bad_entry(m, data, bad), layout, "latlong", 4)
    raises_naming("image", rn.envmaps.convert, m[..., :0], layout, "latlong", 4)
    raises_naming("image", rn.envmaps.convert, m.reshape(-1), layout, "latlong", 4)
    raises_naming("image", rn.envmaps.convert, m.astype("U3"), layout, "latlong", 4)
    raises_naming("layout_out", rn.envmaps.convert, m, layout, "octahedral", 4)
    raises_naming("size", rn.envmaps.convert, m, layout, "cube", 0)
    raises_naming("supersample", rn.envmaps.convert, m, layout, "cube", 4, 0)
    raises_naming("directions", rn.envmaps.sample, m, layout, np.zeros((2, 3), np.float32))
    raises_naming("directions", rn.envmaps.sample, m, layout, with_bad_entry(np.ones((2, 3)), data, bad))
    raises_naming("directions", rn.envmaps.sample, m, layout, np.ones((2, 4)))
    raises_naming("layout", rn.envmaps.sample, m, "Cube ", np.ones((1, 3)))
    ll = np.ones((4, 8, 3), np.float32)
    raises_naming("lobe", rn.envmaps.prefilter, ll, "blinn", [1.0])
    raises_naming("params[0]", rn.envmaps.prefilter, ll, "phong", [bad])
    raises_naming("params[1]", rn.envmaps.prefilter, ll, "ggx", [0.5, 1.5])
    raises_naming("params[0]", rn.envmaps.prefilter, ll, "torrance_sparrow", [-0.1])
    raises_naming("params[0]", rn.envmaps.prefilter, ll, "gaussian", [bad])
    raises_naming("image", rn.envmaps.prefilter, np.ones((4, 9, 3), np.float32), "gaussian", [0.3])  # odd width
    raises_naming("texels_per_radius", rn.envmaps.prefilter, ll, "phong", [1.0], texels_per_radius=0.0)
    raises_naming("tail", rn.envmaps.prefilter, ll, "phong", [1.0], tail=bad)
    raises_naming("image", rn.envmaps.prefilter, np.ones((4, 4, 3), np.float32)[:1], "phong", [1.0])
    raises_naming("image", rn.envmaps.irradiance, with_bad_entry(ll, data, bad))
    raises_naming("size", rn.envmaps.irradiance, ll, 0)
    raises_naming("directions", rn.envmaps.prefilter_reference, ll, "lambert", np.zeros((1, 3)))
    raises_naming("lobe", rn.envmaps.prefilter_reference, ll, "mirror", np.ones((1, 3)))


@FEW
@given(seed=seeds, lobe=st.sampled_from(["phong", "ggx", "torrance_sparrow", "gaussian"]), h=st.sampled_from([8, 16]), c=st.integers(1, 3))
def test_env_prefilter_and_reference_are_normalised_means(seed, lobe, h, c):
    rng = np.random.default_rng(seed)
    params = {"phong": [0.0, 5.0, 200.0], "ggx": [0.0, 0.3, 1.0], "torrance_sparrow": [0.0, 0.2, 0.8], "gaussian": [0.0, 0.3, 1.0]}[lobe]  # σ = 0 Phong: uniform
    k = rng.uniform(0.1, 2, c).astype(np.float32)
    const = np.broadcast_to(k, (h, 2 * h, c)).copy()
    levels = rn.envmaps.prefilter(const, lobe, params)
    assert len(levels) == len(params)
    for lv in levels:
        assert lv.ndim == 3 and lv.shape[2] == c and lv.shape[1] == 2 * lv.shape[0] and lv.dtype == np.float32
        np.testing.assert_allclose(lv, np.broadcast_to(k, lv.shape), rtol=1e-4)
    if lobe != "phong":
        np.testing.assert_array_equal(levels[0], const)  # the mirror lobe copies the input
    m = rng.uniform(0, 2, (h, 2 * h, c)).astype(np.float32)
    for lv in rn.envmaps.prefilter(m, lobe, params):
        assert np.all(np.isfinite(lv)) and lv.min() >= m.min() - 1e-4 and lv.max() <= m.max() + 1e-4
    d = rng.normal(size=(6, 3))
    for p in params:
        ref = rn.envmaps.prefilter_reference(const, lobe, d, p)
        assert ref.shape == (6, c) and ref.dtype == np.float64
        np.testing.assert_allclose(ref, np.broadcast_to(k, ref.shape), rtol=1e-6)
    # The seed's quadrature (sin θ at texel centres) is within a few percent of the exact E/π.
    np.testing.assert_allclose(rn.envmaps.prefilter_reference(const, "lambert", d), np.broadcast_to(k, (6, c)), rtol=3e-2)


@FEW
@given(seed=seeds, h=st.sampled_from([16, 32]), size=st.integers(2, 16), c=st.integers(1, 3))
def test_env_irradiance_of_a_constant_is_the_constant(seed, h, size, c):
    # Texel-centre quadrature leaks a constant into the l = 2 terms on coarse maps (0.65% at 8×16,
    # 0.16% at 16×32, 0.04% at 32×64): checked where it is below 2e-3.
    rng = np.random.default_rng(seed)
    k = rng.uniform(0.1, 2, c).astype(np.float32)
    r = rn.envmaps.irradiance(np.broadcast_to(k, (h, 2 * h, c)).copy(), size)
    assert r["image"].shape == (size, 2 * size, c) and r["coeffs"].shape == (c, 9)
    np.testing.assert_allclose(r["image"], np.broadcast_to(k, r["image"].shape), rtol=2e-3)
    np.testing.assert_allclose(r["coeffs"][:, 0], k * np.sqrt(4 * np.pi), rtol=1e-4)  # L00 = k·4π·Y00
    np.testing.assert_allclose(r["coeffs"][:, 1:4], 0, atol=1e-4)  # odd terms cancel by symmetry
    np.testing.assert_allclose(r["coeffs"][:, 4:], 0, atol=2e-2 * k.max())
    # SH irradiance of a random map against the brute-force reference (order 2 is within ~10%).
    m = rng.uniform(0.5, 1.5, (h, 2 * h, c)).astype(np.float32)
    ir = rn.envmaps.irradiance(m, size)
    d = rng.normal(size=(8, 3))
    ref = rn.envmaps.prefilter_reference(m, "lambert", d)
    np.testing.assert_allclose(rn.compositing.sh_eval(ir["irradiance_coeffs"], d.astype(np.float32)), ref, rtol=0.1)


# ---------------------------------------------------------------------------------------------
# shadow editing


PLANE_V = np.array([[-30, -30, 0], [30, -30, 0], [30, 30, 0], [-30, 30, 0]], np.float32)
PLANE_F = np.array([[0, 1, 2], [0, 2, 3]], np.int64)
vec3 = st.tuples(*[st.floats(-1, 1)] * 3).filter(lambda t: np.linalg.norm(t) > 0.2)


@SOME
@given(c=st.tuples(*[st.floats(-2, 2)] * 3), r=st.floats(0.1, 3.0), d=vec3, point=st.booleans(), dist=st.floats(2.0, 10.0))
def test_sphere_silhouette_is_the_tangent_circle(c, r, d, point, dist):
    c, d = np.asarray(c), np.asarray(d) / np.linalg.norm(d)
    v, f = uv_sphere(c, r, 16, 24)
    normals = (v - c.astype(np.float32)) / np.float32(r)  # exact normals: silhouette on the true sphere's edges
    if point:
        light = c - d * dist * r
        loops = rn.shadows.silhouettes(v, f, light_position=light, normals=normals)
    else:
        loops = rn.shadows.silhouettes(v, f, light_direction=d, normals=normals)
    assert len(loops) >= 1
    big = loops[0]
    k = len(big["points"])
    assert big["points"].shape == (k, 3) and big["points"].dtype == np.float32 and big["edges"].shape == (k, 2)
    assert big["alpha"].shape == (k,) and np.all((big["alpha"] >= 0) & (big["alpha"] <= 1))
    p = big["points"].astype(np.float64) - c
    # Points lie on the mesh's edges (chords): within the chord sag of the sphere.
    sag = r * (1 - np.cos(np.pi / 16))
    assert np.all(np.abs(np.linalg.norm(p, axis=1) - r) <= sag + 1e-4 * (1 + r))
    if point:
        to_light = light - (p + c)
        g = np.sum(p * to_light, 1) / (r * np.linalg.norm(to_light, axis=1))  # n·l̂ on the tangent cone: 0
    else:
        g = p @ d / r
    assert np.max(np.abs(g)) < 0.2, f"silhouette off the tangent circle by {np.max(np.abs(g)):.3f}"
    assert big["length"] == pytest.approx(np.sum(np.linalg.norm(np.roll(big["points"], -1, 0) - big["points"], axis=1)), rel=1e-4)
    assert big["length"] <= 2 * np.pi * r * 1.01


@FEW
@given(data=st.data(), bad=BAD_FLOATS)
def test_shadow_silhouettes_adversarial(data, bad):
    v, f = uv_sphere((0, 0, 2), 1.0, 6, 8)
    L = dict(light_direction=[0, 0, -1])
    raises_naming("vertices", rn.shadows.silhouettes, with_bad_entry(v, data, bad), f, **L)
    raises_naming("vertices", rn.shadows.silhouettes, v[:, :2], f, **L)
    raises_naming("faces", rn.shadows.silhouettes, v, f[:-1], **L)  # open mesh
    raises_naming("faces", rn.shadows.silhouettes, v, np.where(f == 0, len(v), f), **L)  # out of range
    raises_naming("faces", rn.shadows.silhouettes, v, f.astype(np.float32) + 0.5, **L)
    raises_naming("faces", rn.shadows.silhouettes, v, np.zeros((0, 3), np.int64), **L)
    raises_naming("light", rn.shadows.silhouettes, v, f)
    raises_naming("light", rn.shadows.silhouettes, v, f, light_direction=[0, 0, 1], light_position=[0, 0, 9])
    raises_naming("light", rn.shadows.silhouettes, v, f, light_direction=[0, 0, 0])
    raises_naming("light", rn.shadows.silhouettes, v, f, light_direction=[0, 0, 1e300])
    raises_naming("light", rn.shadows.silhouettes, v, f, light_position=[0, bad, 9])
    raises_naming("normals", rn.shadows.silhouettes, v, f, normals=v[:-1], **L)


@SOME
@given(a=vec3, b=vec3, beta=st.floats(0, 50))
def test_shadow_falloff_is_a_clamped_power(a, b, beta):
    a, b = np.asarray(a), np.asarray(b)
    x = rn.shadows.falloff_factor(a, b, beta)
    c = float(a @ b / np.linalg.norm(a) / np.linalg.norm(b))
    assert 0.0 <= x <= 1.0
    assert x == pytest.approx(1.0 if beta == 0 else max(c, 0.0) ** beta, rel=1e-5, abs=1e-9)
    assert rn.shadows.falloff_factor(a, 3.0 * a, beta) == pytest.approx(1.0)
    raises_naming("beta", rn.shadows.falloff_factor, a, b, -beta - 1e-3)
    raises_naming("beta", rn.shadows.falloff_factor, a, b, np.nan)
    raises_naming("light", rn.shadows.falloff_factor, a, [0, 0, 0], beta)
    raises_naming("light", rn.shadows.falloff_factor, [np.inf, 0, 0], b, beta)


def make_editor(light):
    v, f = uv_sphere((0, 0, 1.5), 0.5, 16, 24)
    return rn.shadows.ShadowEditor(v, f, PLANE_V, PLANE_F, light_position=light, min_loop_vertices=10), v


lights = st.tuples(st.floats(-1.5, 1.5), st.floats(-1.5, 1.5), st.floats(4.0, 8.0))


@SLOW
@given(light=lights, seed=seeds, style=st.sampled_from(["affine", "similarity", "rigid"]))
def test_editor_drag_at_rest_is_the_identity_and_reset_restores(light, seed, style):
    ed, v = make_editor(np.asarray(light))
    rng = np.random.default_rng(seed)
    loops = ed.loops()
    assert loops and loops[0]["active"]
    k = len(loops[0]["points"])
    h = ed.handles(0)
    assert h["points"].shape == (k, 3) and np.all(np.isfinite(h["points"])) and np.all(h["hit"])
    np.testing.assert_allclose(h["points"][:, 2], 0.0, atol=1e-4)  # on the ground plane
    a, m, b = sorted(rng.choice(k, 3, replace=False))
    # Dragging a handle onto itself: the MLS deformation at rest is the identity.
    r = ed.drag(0, (int(a), int(b)), int(m), h["points"][m], style=style)
    assert r["silhouette"].shape == (k, 3) and r["silhouette"].dtype == np.float32
    np.testing.assert_allclose(r["silhouette"], loops[0]["points"], atol=1e-4)
    np.testing.assert_allclose(ed.shadow_mesh(), v, atol=1e-4)
    # A real drag moves things, finitely; reset gives the caster back.
    r = ed.drag(0, (int(a), int(b)), int(m), h["points"][m] + np.array([0.3, -0.2, 0.0], np.float32), style=style, noise_amplitude=0.01, noise_frequency=20.0)
    assert np.all(np.isfinite(r["silhouette"])) and np.all(np.isfinite(r["moved_to"]))
    assert set(r["segment"].tolist()) >= {a, m, b}
    ed.commit()
    sm = ed.shadow_mesh()
    assert sm.shape == v.shape and np.all(np.isfinite(sm)) and np.abs(sm - v).max() > 1e-4
    ed.reset()
    np.testing.assert_allclose(ed.shadow_mesh(), v, atol=1e-4)


@FEW
@given(bad=BAD_FLOATS, light=lights)
def test_editor_adversarial(bad, light):
    v, f = uv_sphere((0, 0, 1.5), 0.5, 8, 12)
    ed = rn.shadows.ShadowEditor(v, f, PLANE_V, PLANE_F, light_position=np.asarray(light), min_loop_vertices=4)
    k = len(ed.loops()[0]["points"])
    t = ed.handles(0)["points"][1]
    raises_naming("loop", ed.drag, 99, (0, 2), 1, t)
    raises_naming("loop", ed.drag, -1, (0, 2), 1, t)
    raises_naming("target", ed.drag, 0, (0, 2), 1, [0, bad, 0])
    raises_naming("target", ed.drag, 0, (0, 2), 1, [0, 0])
    raises_naming("style", ed.drag, 0, (0, 2), 1, t, style="bendy")
    raises_naming("moved", ed.drag, 0, (0, 2), k + 5, t)
    raises_naming("moved", ed.drag, 0, (0, 2), -1, t)
    raises_naming("fixed", ed.drag, 0, (-3, 2), 1, t)
    raises_naming("loop", ed.handles, 7)
    raises_naming("eye", ed.handles, 0, eye=[bad, 0, 1])
    np.testing.assert_allclose(ed.shadow_mesh(), v, atol=1e-4)  # bad drags changed nothing
    raises_naming("light", rn.shadows.ShadowEditor, v, f, PLANE_V, PLANE_F, light_position=[0, 0, 1.5])  # inside the caster
    raises_naming("receiver_vertices", rn.shadows.ShadowEditor, v, f, PLANE_V[:, :2], PLANE_F, light_position=light)
    raises_naming("receiver_faces", rn.shadows.ShadowEditor, v, f, PLANE_V, PLANE_F + 4, light_position=light)
    raises_naming("w_z", rn.shadows.ShadowEditor, v, f, PLANE_V, PLANE_F, light_position=light, w_z=bad)
    raises_naming("constraint_weight", rn.shadows.ShadowEditor, v, f, PLANE_V, PLANE_F, light_position=light, constraint_weight=0.0)
    raises_naming("vertices", rn.shadows.ShadowEditor, np.where(np.arange(len(v))[:, None] == 3, bad, v).astype(np.float32), f, PLANE_V, PLANE_F, light_position=light)
