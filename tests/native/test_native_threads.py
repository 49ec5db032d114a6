"""rokeby_native from many Python threads: the GIL is released around the native work,
so calls really run at once. On shared read-only arrays each call must give bit-identical results
to the same call made alone; an array written by another thread while a call reads it (which the
contract forbids: docs/errors.md, "The native core") must still never produce NaN."""

import threading

import numpy as np
import rokeby_native as rn


def fib(n):
    i = np.arange(n) + 0.5
    phi = np.arccos(1 - 2 * i / n)
    th = np.pi * (1 + 5**0.5) * i
    return np.stack([np.cos(th) * np.sin(phi), np.sin(th) * np.sin(phi), np.cos(phi)], -1).astype(np.float32)


def readonly(a):
    a = np.ascontiguousarray(a)
    a.flags.writeable = False
    return a


def shared_inputs():
    rng = np.random.default_rng(7)
    h, w = 48, 64
    n = rng.normal(size=(h, w, 3)).astype(np.float32)
    n[..., 2] = np.abs(n[..., 2]) + 0.2
    n /= np.linalg.norm(n, axis=-1, keepdims=True)
    hw = 40
    y, x = np.mgrid[0:hw, 0:hw]
    u, v = (x + 0.5) / hw * 2 - 1, 1 - (y + 0.5) / hw * 2
    z2 = 1 - u * u - v * v
    sn = np.stack([u, v, np.sqrt(np.clip(z2, 0, None))], -1).astype(np.float32)
    refl = rn.compositing.reflect_dirs(sn, np.array([0, 0, 1], np.float32))
    d = fib(500)
    lat = rng.random((16, 32, 3)).astype(np.float32)
    verts = rng.normal(size=(200, 3)).astype(np.float32)
    constraints = np.concatenate([rng.normal(size=(3, 3)), fib(3), fib(3)[::-1]], 1).astype(np.float32)
    return {k: readonly(a) for k, a in dict(
        n=n, depth=(1 + rng.random((h, w))).astype(np.float32), refl=refl, refl_vals=(1.5 + 0.3 * refl).astype(np.float32),
        refl_mask=(z2 > 0.02).astype(np.float32), d=d, vals=(1 + d @ rng.normal(size=(3, 3)) * 0.3).astype(np.float32),
        coeffs=rng.normal(size=(3, 9)), lat=lat, verts=verts, constraints=constraints, mats=rng.normal(size=(300, 3, 3)).astype(np.float32),
    ).items()}


CALLS = {
    "reflect_dirs": lambda a: rn.compositing.reflect_dirs(a["n"], np.array([0, 0, 1], np.float32)),
    "sh_eval": lambda a: rn.compositing.sh_eval(a["coeffs"], a["d"]),
    "sh_fit": lambda a: rn.compositing.sh_fit(a["d"], a["vals"])["coeffs"],
    "normals_bilateral": lambda a: rn.compositing.normals_bilateral(a["n"], a["depth"], sigma_s=2.0),
    "normals_emboss": lambda a: rn.compositing.normals_emboss(a["n"], 0.5),
    "reflection_env": lambda a: rn.compositing.reflection_env(a["refl"], a["refl_vals"], a["refl_mask"], size=16)["map"],
    "envmaps.sample": lambda a: rn.envmaps.sample(a["lat"], "latlong", a["d"]),
    "envmaps.prefilter": lambda a: rn.envmaps.prefilter(a["lat"], "ggx", [0.3])[0],
    "rotation_field": lambda a: rn.reflection.rotation_field(a["verts"], a["constraints"]),
    "ortho": lambda a: rn.reflection.ortho(a["mats"]),
}


def test_eight_threads_on_shared_arrays_match_single_threaded_bit_for_bit():
    a = shared_inputs()
    expected = {k: np.array(f(a)) for k, f in CALLS.items()}
    names = sorted(CALLS)
    errors, mismatches = [], []
    barrier = threading.Barrier(8)

    def worker(t):
        try:
            barrier.wait()
            for i in range(30):
                k = names[(t + i) % len(names)]
                out = np.array(CALLS[k](a))
                if out.tobytes() != expected[k].tobytes():
                    mismatches.append(k)
        except BaseException as e:  # noqa: BLE001 - reported below
            errors.append(f"{type(e).__name__}: {e}")

    threads = [threading.Thread(target=worker, args=(t,)) for t in range(8)]
    for th in threads:
        th.start()
    for th in threads:
        th.join(120)
    assert not any(th.is_alive() for th in threads), "a native call hung"
    assert not errors, errors
    assert not mismatches, sorted(set(mismatches))


def test_writing_into_sh_fit_input_while_it_runs_never_returns_nan():
    """Forbidden by the contract, but it must not turn into NaN: each call gives finite coefficients
    (of some mix of the old and new values) or raises ValueError."""
    d = fib(200_000)
    vals = np.ones((len(d), 3), np.float32)
    stop = threading.Event()

    def writer():
        rng = np.random.default_rng(1)
        while not stop.is_set():
            i = int(rng.integers(0, len(vals) - 1000))
            vals[i:i + 1000] = rng.choice(np.array([np.nan, np.inf, 1e30, -1e30, 2.0], np.float32), size=(1000, 3))

    th = threading.Thread(target=writer)
    th.start()
    outcomes = []
    try:
        for _ in range(6):
            for method in ("ls", "qp"):
                try:
                    c = rn.compositing.sh_fit(d, vals, method)["coeffs"]
                except ValueError:
                    outcomes.append("ValueError")
                    continue
                assert np.isfinite(c).all(), f"sh_fit({method}) returned {c}"
                outcomes.append("finite")
    finally:
        stop.set()
        th.join()
    assert len(outcomes) == 12


def test_writing_into_reflection_env_values_while_it_runs_never_returns_nan():
    hw = 160
    y, x = np.mgrid[0:hw, 0:hw]
    u, v = (x + 0.5) / hw * 2 - 1, 1 - (y + 0.5) / hw * 2
    z2 = 1 - u * u - v * v
    n = np.stack([u, v, np.sqrt(np.clip(z2, 0, None))], -1).astype(np.float32)
    r = rn.compositing.reflect_dirs(n, np.array([0, 0, 1], np.float32))
    mask = (z2 > 0.02).astype(np.float32)
    values = (1.5 + 0.3 * r).astype(np.float32)
    stop = threading.Event()

    def writer():
        rng = np.random.default_rng(2)
        while not stop.is_set():
            i = int(rng.integers(0, hw - 4))
            values[i:i + 4] = rng.choice(np.array([np.nan, np.inf, 1e30, -1e30, 2.0], np.float32), size=(4, hw, 3))

    th = threading.Thread(target=writer)
    th.start()
    try:
        for _ in range(4):
            try:
                m = rn.compositing.reflection_env(r, values, mask, size=32)["map"]
            except ValueError:
                continue
            assert np.isfinite(m).all()
    finally:
        stop.set()
        th.join()
