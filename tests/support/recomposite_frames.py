"""Frames and bad inputs shared by the GLSL recompositing tests: tests/compositing/test_recomposite_glsl.py
(moderngl) and tests/compositing/recomposite_blender_gpu_check.py (Blender's gpu module)."""

from __future__ import annotations

import numpy as np


def frame(h=96, w=160, seed=3):
    """Five patches (SH + map, SH only, map only, None, SH + map), a patch index beyond the list,
    background, perspective view vectors, reflectance buffers, NaN pixels; half the rows edited."""
    rng = np.random.default_rng(seed)
    ids = np.full((h, w), -1, np.int32)
    cols = np.array_split(np.arange(w), 6)
    for k, c in enumerate(cols):
        ids[8:h - 8, c[0]:c[-1] + 1] = k  # id 5: no such patch
    yy, xx = np.mgrid[0:h, 0:w].astype(np.float32)
    n = np.stack([np.sin(xx / 17.0), np.cos(yy / 23.0), np.full_like(xx, 1.2)], -1)
    n /= np.linalg.norm(n, axis=-1, keepdims=True)
    e = n.copy()
    e[: h // 2, :, 2] *= 0.5
    e[: h // 2, :, 0] += 0.2 * np.sin(xx[: h // 2] / 5.0)
    view = np.stack([(xx - w / 2) / w * -0.5, (yy - h / 2) / h * -0.5, np.ones_like(xx)], -1).astype(np.float32)
    sh = np.array([[1.2, 0.3, 0.5, -0.2, 0.1, 0.05, 0.15, -0.05, 0.04],
                   [1.0, 0.2, 0.45, -0.1, 0.05, 0.02, 0.1, -0.04, 0.03],
                   [0.9, 0.1, 0.4, 0.0, 0.02, 0.01, 0.08, -0.02, 0.02]])
    env = lambda: np.abs(rng.normal(size=(2, 32, 32, 3))).astype(np.float32)  # noqa: E731
    patches = [{"sh": sh, "env": env()}, {"sh": 0.5 * sh, "env": None}, {"sh": None, "env": env()}, None,
               {"sh": -0.3 * sh, "env": env()}]
    d0 = np.abs(rng.normal(size=(h, w, 3))).astype(np.float32)
    r0 = np.abs(rng.normal(size=(h, w, 3))).astype(np.float32)
    img = (d0 + r0 + 0.1).astype(np.float32)
    d0[h // 5, 3] = np.nan
    e[h // 4, w // 2] = np.nan
    ad = rng.uniform(0.5, 1, (h, w)).astype(np.float32)
    ar = rng.uniform(0.5, 1, (h, w)).astype(np.float32)
    a = np.full((h, w), 0.9, np.float32)
    dc = rng.uniform(0.2, 1, (h, w, 3)).astype(np.float32)
    rc = rng.uniform(0.2, 1, (h, w, 3)).astype(np.float32)
    args = (ids, n, e, view, d0, r0, img, patches)
    kw = dict(alpha_d=ad, alpha_r=ar, alpha=a, diffuse_color=dc, reflection_color=rc)
    return args, kw


def bad_inputs():
    """(the keyword arguments of a small valid frame, [(changes to them, the CompositingError message
    they must raise)]): call the recompositor with ``**{**base, **change}``."""
    (ids, n, e, view, d0, r0, img, patches), _kw = frame(h=16, w=24)
    base = dict(ids=ids, normals=n, edited_normals=e, view=view, diffuse=d0, reflection=r0, image=img, patches=patches)
    return base, [
        (dict(edited_normals=e[:, :-1]), "edited_normals: expected shape"),
        (dict(ids=ids[:-1]), "ids: expected shape"),
        (dict(ids=ids.astype(object)), "ids: expected integer patch indices"),
        (dict(view=view[..., :2]), "view: expected shape"),
        (dict(normals=n[..., 0]), "normals: expected shape"),
        (dict(alpha_d=np.ones((3, 3), np.float32)), "alpha_d: expected shape"),
        (dict(gamma=0.0), "gamma: must be positive"),
        (dict(epsilon=-1.0), "epsilon: must be positive"),
        (dict(k_d=float("nan")), "k_d"),
        (dict(patches={"sh": None}), "patches: must be a list"),
        (dict(patches=[1]), r"patches\[0\]: must be a dict"),
        (dict(patches=[{"sh": np.zeros((3, 4))}]), r"patches\[0\]\.sh: expected finite"),
        (dict(patches=[{"env": np.zeros((2, 8, 8, 2), np.float32)}]), r"patches\[0\]\.env: expected 3 channels"),
        (dict(patches=[{"env": np.zeros((8, 8, 3), np.float32)}]), r"patches\[0\]\.env: expected a dual-paraboloid"),
        (dict(patches=[{"env": np.zeros((2, 8, 8, 3), np.float32)}, {"env": np.zeros((2, 16, 16, 3), np.float32)}]),
         "one reflection-map size"),
    ]


def passes_and_reconstruction(args, kw):
    """``frame()``'s arrays as ``compositing.Passes`` and a ``Reconstruction``, so that
    ``compositing.recomposite(p, rec, e)`` and ``RecompositeSession`` recomposite that frame (alpha
    = 1: ``Passes`` has no per-pixel α; D0 and R0 are the direct passes, the indirect ones zero)."""
    from rokeby import compositing as C

    ids, n, _e, view, d0, r0, img, patches = args
    h, w = ids.shape
    zero3 = np.zeros((h, w, 3), np.float32)
    p = C.Passes(image=img, normal=n, diff_dir=d0, diff_ind=zero3, diff_col=kw["diffuse_color"], gloss_dir=r0,
                 gloss_ind=zero3, gloss_col=kw["reflection_color"], index_ob=np.zeros((h, w), np.float32),
                 index_ma=np.zeros((h, w), np.float32), ao=np.repeat(kw["alpha_d"][..., None], 3, -1),
                 depth=np.ones((h, w), np.float32), reflocc=kw["alpha_r"], camera_x=zero3, camera_y=zero3,
                 incoming_cam=zero3)
    rec = C.Reconstruction(ids=ids, keys=[], patches=patches, reports=[], normals=n, view=view)
    return p, rec
