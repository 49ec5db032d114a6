"""Runs the native fuzz suite (tests/native/fuzz/fuzz_native.py) briefly, in a subprocess under
an address-space limit (tests/native/fuzz/run_fuzz.py): every rokeby_native function and method and the
bpy-free file readers on random, empty, huge, non-finite and non-contiguous input must return
finite output or raise ValueError/TypeError/MemoryError/NumericalError — no crash, abort, hang
or RuntimeError. `make fuzz-py` runs the same suite with many more examples."""

import os
import subprocess
import sys
import time
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]


@pytest.mark.slow  # 60 examples of every entry point in a subprocess: about 100 s on the shared 2-core machine
def test_native_fuzz_suite_survives_under_an_address_space_limit():
    env = {k: v for k, v in os.environ.items() if k != "ROKEBY_MAX_ALLOC_BYTES"}
    t0 = time.perf_counter()
    r = subprocess.run([sys.executable, str(ROOT / "tests/native/fuzz/run_fuzz.py"), "--examples", "60"],
                       cwd=ROOT, env=env, capture_output=True, text=True, timeout=300)
    took = time.perf_counter() - t0
    print(f"fuzz subprocess: {took:.1f} s")
    assert r.returncode == 0, f"exit {r.returncode} (a negative code is the signal that killed it)\n{r.stdout[-6000:]}\n{r.stderr[-3000:]}"
    assert " passed" in r.stdout and "failed" not in r.stdout, r.stdout[-3000:]
