"""Runs tests/native/fuzz/fuzz_native.py in this process under an address-space limit:

    python tests/native/fuzz/run_fuzz.py [--examples N] [--as-gib 4] [--max-alloc-gib 1] [pytest args...]

RLIMIT_AS (default 4 GiB) and ROKEBY_MAX_ALLOC_BYTES (default 1 GiB, read once per process by
the native core) are set before rokeby_native is imported, so that a huge allocation becomes a
MemoryError, and an abort or a runaway allocation ends this process, not the caller's pytest.
No bpy is imported here (Blender's allocator does not like RLIMIT_AS): only rokeby_native, numpy,
OpenEXR and the bpy-free readers. Exit status: pytest's (0 when every example held)."""

import argparse
import os
import resource
import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent
ROOT = HERE.parents[2]


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--examples", type=int, default=int(os.environ.get("FUZZ_PY_EXAMPLES", "20")))
    ap.add_argument("--as-gib", type=float, default=4.0)
    ap.add_argument("--max-alloc-gib", type=float, default=1.0)
    args, rest = ap.parse_known_args(argv)
    os.environ["FUZZ_PY_EXAMPLES"] = str(args.examples)
    os.environ["ROKEBY_MAX_ALLOC_BYTES"] = str(int(args.max_alloc_gib * 2**30))
    os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
    limit = int(args.as_gib * 2**30)
    resource.setrlimit(resource.RLIMIT_AS, (limit, limit))
    sys.path.insert(0, str(ROOT / "addon"))
    import pytest

    assert "bpy" not in sys.modules
    return pytest.main([str(HERE / "fuzz_native.py"), "-q", "--noconftest", "-p", "no:cacheprovider",
                        "--rootdir", str(HERE), "-o", "addopts=", *rest])


if __name__ == "__main__":
    sys.exit(main())
