"""Reconstruction (§3): per object/material patch (IndexOB × IndexMA), the SH diffuse environment
(eq. 1; the QP of §3.1 or least squares) of D0 = DiffDir + DiffInd, and the dual-paraboloid
reflection environment (eq. 2, hole filling, regularisation) of R0 = GlossDir + GlossInd, in
screen space.

Patches covering fewer than ``min_pixels`` pixels, and reflection maps whose recovered directions
cover less than ``min_coverage`` of the sphere, are not edited: the image keeps its input values
there, and the report (and a RuntimeWarning) says so."""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass, field

import numpy as np

from ..core import native
from .errors import CompositingError
from .passes import Passes
from .screen import screen_space


def patch_ids(index_ob: np.ndarray, index_ma: np.ndarray) -> tuple[np.ndarray, list[tuple[int, int]]]:
    """One id per (object index, material index) pair with object index > 0; −1 elsewhere."""
    ob = np.rint(np.nan_to_num(index_ob, nan=0)).astype(np.int64)
    ma = np.rint(np.nan_to_num(index_ma, nan=0)).astype(np.int64)
    key = ob * (1 << 20) + ma
    valid = ob > 0
    keys, inv = np.unique(key[valid], return_inverse=True)
    ids = np.full(ob.shape, -1, np.int32)
    ids[valid] = inv
    return ids, [(int(k >> 20), int(k & ((1 << 20) - 1))) for k in keys]


@dataclass
class PatchReport:
    key: tuple[int, int]
    pixels: int
    diffuse: str            # "qp"/"ls" fit, or why not
    reflection: str         # "ok" or why not
    sh_rms_residual: float = float("nan")
    sh_max_residual: float = float("nan")
    coverage: float = 0.0
    filled_texels: int = 0
    noise_sigma: tuple = ()  # per channel: the estimated noise of D0 (``pixel_noise``), when measured
    sh_tolerance: tuple = ()  # per channel: the QP's tolerance τ (D(n) ≥ D0 − τ), when not 0


@dataclass
class Reconstruction:
    ids: np.ndarray
    keys: list
    patches: list           # per id: {"sh": (3, 9) | None, "env": (2, S, S, 3) | None}
    reports: list
    normals: np.ndarray     # screen-space normals the environments were fitted to
    view: np.ndarray
    timings: dict = field(default_factory=dict)

    def warnings(self) -> list[str]:
        return self.warnings_of(self.reports)

    @staticmethod
    def warnings_of(reports) -> list[str]:
        """What a user should hear of these patch reports: patches left unedited, large holes."""
        out = []
        for r in reports:
            if r.diffuse not in ("qp", "ls"):
                out.append(f"patch {r.key}: diffuse not edited: {r.diffuse}")
            if r.reflection != "ok":
                out.append(f"patch {r.key}: reflection not edited: {r.reflection}")
            elif r.coverage < 0.5:
                out.append(f"patch {r.key}: holes cover {100 * (1 - r.coverage):.0f}% of the sphere of reflected "
                           "directions: strongly edited reflections are extrapolated")
        return out


def pixel_noise(values: np.ndarray, mask: np.ndarray) -> np.ndarray:
    """Per channel, the standard deviation of the per-pixel noise of ``values`` (H, W, C) on ``mask``
    (H, W): from the differences of horizontally and vertically adjacent pixels both in the mask,
    σ = 1.4826 · median|Δ| / √2 (the median absolute deviation of the difference of two independent
    noisy pixels; robust to the few pairs that straddle an edge or a shading change). Zeros when
    fewer than 16 pairs exist. Path-traced passes have independent noise per pixel; smooth shading
    changes little between neighbours."""
    rows, cols = np.flatnonzero(mask.any(1)), np.flatnonzero(mask.any(0))
    if len(rows) == 0:
        return np.zeros(values.shape[-1])
    box = (slice(rows[0], rows[-1] + 1), slice(cols[0], cols[-1] + 1))  # the patch's bounding box
    values, mask = values[box], mask[box]
    diffs = []
    for axis in (0, 1):
        a = np.swapaxes(values, 0, axis)
        m = np.swapaxes(mask, 0, axis)
        both = m[1:] & m[:-1]
        diffs.append((a[1:] - a[:-1])[both])
    d = np.concatenate(diffs, 0)
    if len(d) < 16:
        return np.zeros(values.shape[-1])
    return 1.4826 * np.median(np.abs(d), axis=0) / np.sqrt(2.0)


# The reflection maps' texels per paraboloid face the native core accepts (reflection_env's size).
ENV_SIZES = (8, 4096)


def reconstruct(p: Passes, *, method: str = "qp", env_size: int = 128, min_pixels: int = 64,
                min_coverage: float = 0.01, blur_sigma: float = 2.0, occlusion_threshold: float = 0.5,
                noise_tolerance: float = 0.0, warn: bool = True) -> Reconstruction:
    """Diffuse (SH) and reflection (dual paraboloid) environments for every object/material patch.

    ``method``: 'qp' (§3.1: D(n) ≥ D0 at every pixel, so that the residual is occlusion) or 'ls'
    (least squares, the fast option). ``noise_tolerance`` κ (for 'qp'): the constraint becomes
    D(n) ≥ D0 − κσ with σ the patch's pixel noise (``pixel_noise``) — on a path-traced render the
    paper's QP (κ = 0) rises to the noisiest pixel; κ ≈ 2 leaves the noise to the residual."""
    import time

    if isinstance(env_size, bool) or not isinstance(env_size, (int, np.integer)) or not ENV_SIZES[0] <= env_size <= ENV_SIZES[1]:
        raise CompositingError(f"env_size: texels per paraboloid face must be a whole number from {ENV_SIZES[0]} to {ENV_SIZES[1]}, got {env_size!r}")
    if not (math.isfinite(noise_tolerance) and noise_tolerance >= 0):
        raise CompositingError(f"noise_tolerance: must be finite and ≥ 0 (in noise standard deviations), got {noise_tolerance}")
    if noise_tolerance > 0 and method != "qp":
        raise CompositingError(f"noise_tolerance: only the 'qp' fit has constraints to relax (method is {method!r})")

    nm = native.module()
    p.validate()
    normals, view = screen_space(p)
    ids, keys = patch_ids(p.index_ob, p.index_ma)
    d0 = p.diff_dir + p.diff_ind
    r0 = p.gloss_dir + p.gloss_ind
    finite = np.isfinite(normals).all(-1) & (np.abs(normals).sum(-1) > 0) & np.isfinite(d0).all(-1) & np.isfinite(r0).all(-1)
    refl = nm.compositing.reflect_dirs(normals, view)
    patches, reports = [], []
    t_sh = t_env = 0.0
    for k, key in enumerate(keys):
        m = (ids == k) & finite
        n_px = int(m.sum())
        rep = PatchReport(key=key, pixels=n_px, diffuse="", reflection="")
        entry = {"sh": None, "env": None}
        if n_px < min_pixels:
            rep.diffuse = rep.reflection = f"covers only {n_px} pixels (< min_pixels = {min_pixels}): left unchanged"
        else:
            t0 = time.perf_counter()
            tol = None
            if noise_tolerance > 0:
                sigma = pixel_noise(d0, m)
                tol = noise_tolerance * sigma
                rep.noise_sigma, rep.sh_tolerance = tuple(map(float, sigma)), tuple(map(float, tol))
            fit = nm.compositing.sh_fit(normals[m], d0[m], method, tol)
            t_sh += time.perf_counter() - t0
            entry["sh"] = fit["coeffs"]
            rep.diffuse = method
            rep.sh_rms_residual = float(fit["rms_residual"].max())
            rep.sh_max_residual = float(fit["max_residual"].max())
            if not (r0[m] > 0).any():
                rep.reflection = "no reflection shading on this patch"
            else:
                mask = (m & (p.reflocc >= occlusion_threshold)).astype(np.float32)
                t0 = time.perf_counter()
                try:
                    env = nm.compositing.reflection_env(refl, r0, mask, p.depth, size=env_size, blur_sigma=blur_sigma, min_coverage=min_coverage)
                    entry["env"] = env["map"]
                    rep.reflection = "ok"
                    rep.coverage = float(env["coverage"])
                    rep.filled_texels = int(env["filled_texels"])
                except ValueError as exc:
                    rep.reflection = str(exc)
                t_env += time.perf_counter() - t0
        patches.append(entry)
        reports.append(rep)
    rec = Reconstruction(ids=ids, keys=keys, patches=patches, reports=reports, normals=normals, view=view,
                         timings={"diffuse_s": t_sh, "reflection_s": t_env})
    if warn:
        for msg in rec.warnings():
            warnings.warn(msg, RuntimeWarning, stacklevel=2)
    return rec
