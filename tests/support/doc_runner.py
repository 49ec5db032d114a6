"""Runs the Python blocks of one Markdown file, in order and in one namespace (as a reader pastes
them one after another into Blender's Python console), in this fresh bpy process; used by
tests/workflows/test_docs.py.

    python tests/support/doc_runner.py DOC.md BLOCKS.json RESULTS.json

BLOCKS.json: [{"line": first code line (1-based), "code": the block's text}, ...]. Each block is
compiled with the Markdown file's name and its own line numbers, so a traceback points into the
document. Before the first block: Blender's default startup scene (Cube, Light, Camera, as a new
file gives it), renders made small (32 × 24 pixels, Cycles on the CPU without denoising), and a
``render_init`` handler that caps the samples of every render (also those a block asks for, such
as a reflection-map capture) at 4 Cycles / 1 EEVEE samples: the blocks' own numbers stay, only the
noise differs. RESULTS.json: [{"line", "ok", "seconds", "error"}, ...] (a traceback for a block
that raised).
"""

from __future__ import annotations

import json
import os
import sys
import time
import traceback
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT / "addon"))  # this checkout's add-on, whatever the environment points at

MAX_CYCLES_SAMPLES = 4
MAX_EEVEE_SAMPLES = 1


def _cap(scene, *_args):
    cy = getattr(scene, "cycles", None)
    if cy is not None:
        if cy.samples > MAX_CYCLES_SAMPLES:
            cy.samples = MAX_CYCLES_SAMPLES
        cy.use_denoising = False
        cy.device = "CPU"
    ee = getattr(scene, "eevee", None)
    if ee is not None and ee.taa_render_samples > MAX_EEVEE_SAMPLES:
        ee.taa_render_samples = MAX_EEVEE_SAMPLES


def prelude() -> None:
    import bpy
    from bpy.app.handlers import persistent

    bpy.ops.wm.read_factory_settings(use_empty=False)
    sc = bpy.context.scene
    sc.render.resolution_x, sc.render.resolution_y, sc.render.resolution_percentage = 32, 24, 100
    _cap(sc)
    bpy.app.handlers.render_init.append(persistent(_cap))


def main(argv) -> int:
    doc, blocks_path, results_path = argv[1], Path(argv[2]), Path(argv[3])
    blocks = json.loads(blocks_path.read_text())
    results = []
    try:
        prelude()
    except Exception:  # noqa: BLE001 - reported per block
        err = "the harness's prelude failed:\n" + traceback.format_exc()
        results = [{"line": b["line"], "ok": False, "seconds": 0.0, "error": err} for b in blocks]
        blocks = []
    ns: dict = {"__name__": "__main__"}
    for b in blocks:
        t0 = time.perf_counter()
        try:
            exec(compile("\n" * (b["line"] - 1) + b["code"], doc, "exec"), ns)  # noqa: S102 - the document's own code
            results.append({"line": b["line"], "ok": True, "seconds": time.perf_counter() - t0, "error": ""})
        except BaseException:  # noqa: BLE001 - SystemExit and KeyboardInterrupt from a block are failures too
            results.append({"line": b["line"], "ok": False, "seconds": time.perf_counter() - t0, "error": traceback.format_exc()})
    results_path.write_text(json.dumps(results))
    sys.stdout.flush()
    sys.stderr.flush()
    # No interpreter shutdown: a block may leave registered classes or handlers behind, and bpy as
    # a module can hang at exit then. The results are written.
    os._exit(0)


if __name__ == "__main__":
    main(sys.argv)
