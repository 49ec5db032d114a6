"""Benchmark: local shape editing at the compositing stage, per stage.

Inputs are synthetic so that they are exact and the same on every run: an orthographic sphere whose
normals carry a procedural bump (so the Gauss map folds, patches overlap and the reflection map has
holes, as with real objects), shaded by a known smooth environment; 20% of its pixels are darkened
(occlusion) and all carry a little noise. Stages:

* diffuse: the order-2 SH fit, least squares and the QP (D(n) >= D0), and their error against the
  true, unoccluded SH environment over the sphere;
* reflection: partial reconstruction (eq. 2), hole filling (sparse LU), regularisation; also with
  only a quarter of the sphere as the patch (large holes);
* recompositing (eqs. 3-5) of a 1920x1080 frame with ten patches, each with an SH and a 128² map,
  half the pixels edited; and the process's peak memory for it.

    python bench/compositing.py [--json OUT] [--sizes 512,1024] [--edit-only]

Threads: RAYON_NUM_THREADS (set it before starting; 1 = the paper's single core).
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests"))


def median_time(fn, repeat=3):
    ts = []
    out = None
    for _ in range(repeat):
        t = time.perf_counter()
        out = fn()
        ts.append(time.perf_counter() - t)
    return float(np.median(ts)), out


def sh_basis(n):
    c0, c1, c2 = 0.282094791773878, 0.488602511902920, 1.092548430592079
    x, y, z = n[..., 0], n[..., 1], n[..., 2]
    return np.stack([np.full_like(x, c0), c1 * y, c1 * z, c1 * x, c2 * x * y, c2 * y * z,
                     0.315391565252520 * (3 * z * z - 1), c2 * x * z, 0.546274215296040 * (x * x - y * y)], -1)


TRUE_SH = np.array([[1.2, 0.3, 0.5, -0.2, 0.1, 0.05, 0.15, -0.05, 0.04],
                    [1.0, 0.2, 0.45, -0.1, 0.05, 0.02, 0.1, -0.04, 0.03],
                    [0.9, 0.1, 0.4, 0.0, 0.02, 0.01, 0.08, -0.02, 0.02]])


def reflection_env(r):
    return np.stack([0.5 + 0.3 * r[..., 0] + 0.2 * r[..., 1] * r[..., 2] + 0.2 * np.clip(r[..., 2], 0, 1) ** 8,
                     0.4 + 0.1 * np.sin(3 * r[..., 2]) + 0.1 * r[..., 0] * r[..., 1],
                     0.3 + 0.2 * r[..., 1] + 0.1 * np.cos(4 * r[..., 0])], -1).astype(np.float32)


def bumpy_sphere(w, rng):
    import rokeby_native as rn

    yy, xx = (np.mgrid[0:w, 0:w] + 0.5) / w * 2 - 1
    s = xx ** 2 + yy ** 2
    inside = s < 0.98
    z = np.sqrt(np.clip(1 - s, 0, 1))
    n = np.stack([xx, yy, z], -1)
    # A procedural bump: folds in the Gauss map (overlapping sheets) like real objects.
    a = 0.25
    n[..., 0] += a * np.sin(9 * np.pi * xx) * np.cos(5 * np.pi * yy)
    n[..., 1] += a * np.cos(7 * np.pi * yy) * np.sin(4 * np.pi * xx)
    n /= np.linalg.norm(n, axis=-1, keepdims=True)
    n[~inside] = 0
    n = n.astype(np.float32)
    d_true = (sh_basis(n.astype(np.float64)) @ TRUE_SH.T).astype(np.float32)
    occl = rng.random((w, w)) < 0.2
    d0 = d_true * np.where(occl, 0.5, 1.0)[..., None] + rng.normal(0, 0.01, (w, w, 3)).astype(np.float32)
    r = rn.compositing.reflect_dirs(n, np.array([0, 0, 1.0]))
    r0 = np.where(inside[..., None], reflection_env(np.nan_to_num(r)), 0).astype(np.float32)
    depth = np.where(inside, 5 - z, np.inf).astype(np.float32)
    return n, inside, d0, r, r0, depth


def sphere_dirs(k=20000):
    i = np.arange(k) + 0.5
    z = 1 - 2 * i / k
    rr = np.sqrt(1 - z * z)
    phi = np.pi * (3 - np.sqrt(5)) * i
    return np.stack([rr * np.cos(phi), rr * np.sin(phi), z], -1)


def stages(w, rng, env_size, region="whole"):
    import rokeby_native as rn

    n, inside, d0, r, r0, depth = bumpy_sphere(w, rng)
    if region == "quarter":
        # Only the lower-left quarter of the sphere is the patch: large holes to fill.
        inside = inside & (np.arange(w)[None, :] < w // 2) & (np.arange(w)[:, None] < w // 2)
    px = int(inside.sum())
    nm, dm = n[inside], d0[inside]
    t_ls, ls = median_time(lambda: rn.compositing.sh_fit(nm, dm, "ls"))
    t_qp, qp = median_time(lambda: rn.compositing.sh_fit(nm, dm, "qp"))
    dirs = sphere_dirs()
    truth = sh_basis(dirs) @ TRUE_SH.T
    err = {m: float(np.sqrt(((sh_basis(dirs) @ f["coeffs"].T - truth) ** 2).mean()) / np.abs(truth).mean())
           for m, f in (("ls", ls), ("qp", qp))}
    mask = inside.astype(np.float32)
    t_part, part = median_time(lambda: rn.compositing.reflection_env(r, r0, mask, depth, size=env_size, stage="partial"))
    t_fill_total, full = median_time(lambda: rn.compositing.reflection_env(r, r0, mask, depth, size=env_size, blur_sigma=0.0))
    t_blur_total, _ = median_time(lambda: rn.compositing.reflection_env(r, r0, mask, depth, size=env_size))
    # Hole filling alone, on the same holes (the pure solve, incl. the texels beyond the equator).
    t_fill, _ = median_time(lambda: rn.compositing.fill_holes(part["map"], part["covered"]))
    s = env_size
    uv = (np.arange(s) + 0.5) / s * 2 - 1
    disk = (uv[None, :] ** 2 + uv[:, None] ** 2) <= 1
    cov = part["covered"] | ~disk[None]
    ok = np.isfinite(dirs).all(1)
    look = rn.compositing.envmap_lookup(full["map"], dirs[ok])
    visible = dirs[:, 2] > -0.3  # reflected directions the front of a sphere shows, not only at its rim
    env_err = float(np.abs(look - reflection_env(dirs))[visible].mean())
    return {
        "width": w, "region": region, "pixels": px, "env_size": env_size,
        "diffuse_ls_ms": 1e3 * t_ls, "diffuse_qp_ms": 1e3 * t_qp, "qp_iterations": [int(x) for x in qp["iterations"]],
        "diffuse_ls_rel_rms": err["ls"], "diffuse_qp_rel_rms": err["qp"],
        "ls_max_residual": float(ls["max_residual"].max()), "qp_max_residual": float(qp["max_residual"].max()),
        "partial_ms": 1e3 * t_part, "coverage": float(part["coverage"]), "triangles": int(part["triangles"]),
        "hole_texels": int((~cov).sum()), "fill_ms": 1e3 * t_fill,
        "partial_plus_fill_ms": 1e3 * t_fill_total, "partial_fill_blur_ms": 1e3 * t_blur_total,
        "blur_ms": 1e3 * max(t_blur_total - t_fill_total, 0.0),
        "reflection_mean_abs_err": env_err,
    }


def hd_frame(rng, w=1920, h=1080, patches=10, env_size=128):
    """The recompositing benchmark's frame: ``patches`` vertical patches (SH + a 2×env_size² map
    each) between 80-pixel margins, smooth normals (as on rendered objects: neighbouring pixels
    look up neighbouring texels) edited in the top half, α_D = α_R = 0.9, reflectance buffers.
    Returns (positional args, keyword args) of ``rokeby_native.compositing.recomposite``."""
    ids = np.full((h, w), -1, np.int32)
    for k, c in enumerate(np.array_split(np.arange(w), patches)):
        ids[80:h - 80, c[0]:c[-1] + 1] = k
    yy, xx = np.mgrid[0:h, 0:w].astype(np.float32)
    n = np.stack([np.sin(xx / 37.0), np.cos(yy / 53.0), np.full_like(xx, 1.2)], -1)
    n /= np.linalg.norm(n, axis=-1, keepdims=True)
    e = n.copy()
    e[: h // 2, :, 2] *= 0.5
    env = np.abs(rng.normal(size=(2, env_size, env_size, 3))).astype(np.float32)
    pts = [{"sh": TRUE_SH, "env": env} for _ in range(patches)]
    d0 = np.abs(rng.normal(size=(h, w, 3))).astype(np.float32)
    r0 = np.abs(rng.normal(size=(h, w, 3))).astype(np.float32)
    a = np.ones((h, w), np.float32) * 0.9
    view = np.zeros((h, w, 3), np.float32)
    view[..., 2] = 1
    return (ids, n, e, view, d0, r0, d0 + r0, pts), dict(alpha_d=a, alpha_r=a, diffuse_color=d0, reflection_color=r0)


def recomposite_bench(rng, w=1920, h=1080, patches=10, env_size=128, repeat=5):
    import rokeby_native as rn

    args, kw = hd_frame(rng, w, h, patches, env_size)
    ids, n, e, view, d0, r0, img, pts = args
    a = kw["alpha_d"]
    before = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    run = lambda: rn.compositing.recomposite(*args, **kw)  # noqa: E731
    run()
    ts = []
    for _ in range(repeat):
        t = time.perf_counter()
        run()
        ts.append(time.perf_counter() - t)
    t_id = median_time(lambda: rn.compositing.recomposite(ids, n, n, view, d0, r0, img, pts, alpha_d=a, alpha_r=a), repeat)[0]
    edit = session_bench(args, kw)
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    return {"width": w, "height": h, "patches": patches, "env_size": env_size, "edited_fraction": 0.5 * (h - 160) / h,
            "recomposite_ms": 1e3 * float(np.median(ts)), "recomposite_identity_ms": 1e3 * t_id,
            "peak_rss_mb": peak / 1024, "rss_before_mb": before / 1024,
            "inputs_mb": sum(x.nbytes for x in (ids, n, e, view, d0, r0, img, a, a)) / 2 ** 20,
            **edit, **glsl_bench(run, args, kw, repeat)}


EDIT_GOAL_MS = 8.0  # goal: one recompositing edit of a 1080p frame with ten patches, on 2 threads


def session_bench(args, kw, repeat=9):
    """Per-edit time of an artist's loop: ``rokeby_native.compositing.Recompositor`` holding the
    passes (the default session), each edit passing only the edited normals and writing into the
    same buffer, against the same session keeping the per-pixel terms that do not depend on ñ
    (``prepared=True``) and the one-shot path in the same run (``rokeby_native.compositing.recomposite``
    converting every pass and the patches again, a new image, and the add-on's pass over it for
    non-finite pixels), medians of ``repeat`` alternating runs. And the memory-bound estimate: the bytes one edit has
    to move (every pixel's ids, n, ñ and I read, I~ written; the edited pixels' shading,
    reflectance and α's read) at the bandwidth of a large numpy copy measured here."""
    import rokeby_native as rn

    ids, n, e, view, d0, r0, img, pts = args
    t = time.perf_counter()
    s = rn.compositing.Recompositor(ids, n, view, d0, r0, img, pts, **kw)
    t_make = time.perf_counter() - t
    t = time.perf_counter()
    prepped = rn.compositing.Recompositor(ids, n, view, d0, r0, img, pts, **kw, prepared=True)
    t_make_prepared = time.perf_counter() - t
    out = np.empty_like(img)
    out_prepared = np.empty_like(img)

    def old():
        o, _ = rn.compositing.recomposite(*args, **kw)
        np.isfinite(o).all()

    new = lambda: s.run(out, e)  # noqa: E731
    prepared = lambda: prepped.run(out_prepared, e)  # noqa: E731
    ref, _ = rn.compositing.recomposite(*args, **kw)
    new()
    prepared()
    same = out.tobytes() == ref.tobytes() == out_prepared.tobytes()
    t_new, t_old, t_prepared = [], [], []
    for _ in range(repeat):  # alternating: all see the same load
        for fn, ts in ((new, t_new), (old, t_old), (prepared, t_prepared)):
            t = time.perf_counter()
            fn()
            ts.append(time.perf_counter() - t)
    edited = int(((ids >= 0) & (e != n).any(-1)).sum())
    px = ids.size
    moved = px * (4 + 12 * 4) + edited * (12 * 4 + 4 * 3)  # ids, n, ñ, I, I~; D0, R0, c_D, c_R, α's
    src = np.ones(2 ** 25 // 4, np.float32)  # 32 MB: beyond the caches
    dst = np.empty_like(src)
    t_copy, _ = median_time(lambda: np.copyto(dst, src), 5)
    bandwidth = 2 * src.nbytes / t_copy  # bytes read + written per second
    return {"edit_ms": 1e3 * float(np.median(t_new)), "edit_old_ms": 1e3 * float(np.median(t_old)),
            "edit_prepared_ms": 1e3 * float(np.median(t_prepared)), "prepared_mb": prepped.prepared_bytes / 2 ** 20,
            "make_ms": 1e3 * t_make, "make_prepared_ms": 1e3 * t_make_prepared,
            "edit_runs": repeat, "edit_same_bits": same, "edit_goal_ms": EDIT_GOAL_MS,
            "edit_bytes_mb": moved / 2 ** 20, "bandwidth_gbs": bandwidth / 1e9,
            "edit_memory_bound_ms": 1e3 * moved / bandwidth}


def glsl_bench(run_cpu, args, kw, repeat):
    """The same frame through the GLSL path (shaders/rokeby_recomposite_frag.glsl on moderngl/EGL):
    per frame with uploads and read-back, and its largest relative difference from the Rust core."""
    try:
        sys.path.insert(0, str(ROOT / "addon"))
        from rokeby.compositing import gl as GL

        gl = GL.GLRecompositor()
    except Exception as exc:  # no moderngl or no EGL
        return {"glsl_error": str(exc)}
    out, _ = gl(*args, **kw)
    t, _ = median_time(lambda: gl(*args, **kw), repeat)
    # An interactive session's frame (RecompositeSession): only the edited normals are written;
    # and the draw alone (nothing written: shading and read-back), what a GPU would have left.
    f = GL.recomposite_frame(*args, **kw)
    gl.draw(f)
    e = args[2]

    def session_frame():
        f.set_edit(e, 1.0, 1.0)
        gl.draw(f, ("rk_edited",))

    t_session, _ = median_time(session_frame, repeat)
    t_draw, _ = median_time(lambda: gl.draw(f, ()), repeat)
    ref, _ = run_cpu()
    return {"glsl_ms": 1e3 * t, "glsl_session_ms": 1e3 * t_session, "glsl_draw_only_ms": 1e3 * t_draw,
            "glsl_renderer": gl.ctx.info.get("GL_RENDERER", "?"),
            "glsl_max_rel_diff": float((np.abs(out.astype(np.float64) - ref) / (1 + np.abs(ref))).max())}


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--json")
    ap.add_argument("--sizes", default="512,1024")
    ap.add_argument("--env-size", type=int, default=128)
    ap.add_argument("--edit-only", action="store_true", help="only the per-edit times (session_bench) at 1920x1080")
    args = ap.parse_args()
    rng = np.random.default_rng(2016)
    if args.edit_only:
        out = {"threads": os.environ.get("RAYON_NUM_THREADS", str(os.cpu_count())), "edit": session_bench(*hd_frame(rng))}
        text = json.dumps(out, indent=1)
        if args.json:
            Path(args.json).write_text(text)
        print(text)
        return
    rows = [stages(int(s), rng, args.env_size) for s in args.sizes.split(",")]
    rows.append(stages(int(args.sizes.split(",")[0]), rng, 256))
    rows.append(stages(int(args.sizes.split(",")[-1]), rng, 256, "quarter"))
    rec = recomposite_bench(rng)
    out = {"threads": os.environ.get("RAYON_NUM_THREADS", str(os.cpu_count())), "stages": rows, "recomposite": rec}
    text = json.dumps(out, indent=1)
    if args.json:
        Path(args.json).write_text(text)
    print(text)


if __name__ == "__main__":
    main()
