"""Peer solvers for the compositing diffuse fit (run in .venv-peers): numpy.linalg.lstsq (least squares)
and quadprog.solve_qp (min |B c - d|^2 subject to B c >= d, per channel), on the pixels of bench/tradeoffs.py."""

import sys
import time

import numpy as np


def sh_basis(n):
    c0, c1, c2 = 0.282094791773878, 0.488602511902920, 1.092548430592079
    x, y, z = n[..., 0], n[..., 1], n[..., 2]
    return np.stack([np.full_like(x, c0), c1 * y, c1 * z, c1 * x, c2 * x * y, c2 * y * z,
                     0.315391565252520 * (3 * z * z - 1), c2 * x * z, 0.546274215296040 * (x * x - y * y)], -1)


def main(inp, outp):
    z = np.load(inp)
    n, d = z["n"], z["d"]
    out = {}
    t = time.perf_counter()
    B = sh_basis(n)
    c = np.linalg.lstsq(B, d, rcond=None)[0].T
    out["lstsq_s"] = time.perf_counter() - t
    out["lstsq_coeffs"] = c
    try:
        import quadprog

        t = time.perf_counter()
        B = sh_basis(n)
        G = B.T @ B
        C = np.ascontiguousarray(B.T)
        cs = [quadprog.solve_qp(G, B.T @ d[:, k], C, d[:, k], 0)[0] for k in range(d.shape[1])]
        out["quadprog_s"] = time.perf_counter() - t
        out["quadprog_coeffs"] = np.array(cs)
        out["quadprog_version"] = getattr(quadprog, "__version__", "")
    except Exception as e:  # noqa: BLE001 - reported in the table
        out["quadprog_error"] = f"{type(e).__name__}: {e}"[:120]
    np.savez(outp, **out)


if __name__ == "__main__":
    main(sys.argv[1], sys.argv[2])
