"""Cancel reaches the user: Ctrl-C (SIGINT) stops ``python -m rokeby.composite`` in
the middle of long native work with exit status 130, one line and no partial output file; an
operation cancelled from another thread (what an operator's Esc does: ``rokeby_native.cancel()``)
raises KeyboardInterrupt and leaves the scene as it was."""

import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import numpy as np
import pytest

bpy = pytest.importorskip("bpy")

import rokeby  # noqa: E402


@pytest.fixture(scope="module")
def big_frame(tmp_path_factory):
    """A multilayer EXR with the passes of setup_passes, blown up to 3072×2304 (each pixel of a
    tiny Cycles render repeated): reading and reconstructing take about 6 s on a quiet 2-core machine
    and the bilateral smoothing at σ = 50 about 15 s more, so a cancel sent after 10 s finds the
    native work under way whatever the machine's load."""
    import OpenEXR
    from support.compositing import pass_scene

    from rokeby import compositing as C

    sc = pass_scene()
    sc.render.resolution_x, sc.render.resolution_y = 32, 24
    sc.cycles.samples = 2
    folder = tmp_path_factory.mktemp("cancel")
    small = folder / "small.exr"
    C.render_passes(sc, str(small))
    with OpenEXR.File(str(small)) as f:
        # Every part: up to 4.5 one part holds every pass; from 5.0 there is one part per pass.
        ch = {name: np.repeat(np.repeat(np.asarray(c.pixels), 96, 0), 96, 1) for part in f.parts for name, c in part.channels.items()}
    big = folder / "big.exr"
    with OpenEXR.File({"compression": OpenEXR.NO_COMPRESSION, "type": OpenEXR.scanlineimage}, ch) as f:
        f.write(str(big))
    return big


def test_cli_ctrl_c_exits_130_with_one_line_and_no_output(big_frame, tmp_path):
    out = tmp_path / "out.exr"
    report = tmp_path / "r.json"
    p = subprocess.Popen([sys.executable, "-m", "rokeby.composite", str(big_frame), str(out), "--smooth", "50",
                          "--report", str(report)],
                         stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                         cwd=Path(rokeby.__file__).resolve().parents[1])
    time.sleep(10.0)  # reading, reconstructing: the smoothing is under way by now
    assert p.poll() is None, p.communicate()[1][-2000:]
    t0 = time.perf_counter()
    p.send_signal(signal.SIGINT)
    _out, err = p.communicate(timeout=60)
    waited = time.perf_counter() - t0
    assert p.returncode == 130, (p.returncode, err[-2000:])
    lines = err.strip().splitlines()
    assert "Traceback" not in err and lines[-1] == "rokeby.composite: cancelled", err[-2000:]
    assert all(ln.startswith("rokeby.composite: ") for ln in lines), err[-2000:]
    assert waited < 20, waited
    assert sorted(x.name for x in tmp_path.iterdir()) == []  # no output, no report, no partial file


def test_cli_ctrl_c_while_reading_the_frame_exits_130(big_frame, tmp_path):
    """Ctrl-C early, while the EXR is read: the first arrays rokeby_native makes then must not turn
    the KeyboardInterrupt into a panic (numpy's C API is looked up when rokeby_native is imported)."""
    out = tmp_path / "out.exr"
    p = subprocess.Popen([sys.executable, "-m", "rokeby.composite", str(big_frame), str(out), "--smooth", "50"],
                         stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                         cwd=Path(rokeby.__file__).resolve().parents[1])
    time.sleep(1.5)  # reading the 1.2 GB frame takes seconds
    p.send_signal(signal.SIGINT)
    _out, err = p.communicate(timeout=60)
    assert p.returncode == 130, (p.returncode, err[-2000:])
    assert "panicked" not in err and err.strip().splitlines()[-1] == "rokeby.composite: cancelled", err[-2000:]
    assert sorted(x.name for x in tmp_path.iterdir()) == []


def test_cancel_from_a_timer_thread_leaves_the_scene_unchanged(big_frame):
    """The operator path: the API entry the Recomposite operator runs (api.recomposite_exr),
    cancelled from another thread while its native smoothing runs, as Esc does
    (rokeby.core.native.cancel()): KeyboardInterrupt soon after, and the scene exactly as before (no
    image made or changed)."""
    from support.atomic_harness import diff, snapshot

    from rokeby import api, compositing
    from rokeby.core import native

    bpy.ops.wm.read_factory_settings(use_empty=True)
    rokeby.register()
    compositing.close_render()
    before = snapshot()
    fired = []

    def esc():
        time.sleep(10.0)  # reading and reconstructing first; then the smoothing runs for long
        fired.append(time.perf_counter())
        native.cancel()

    timer = threading.Thread(target=esc)
    timer.start()
    try:
        with pytest.raises(KeyboardInterrupt):
            api.recomposite_exr(str(big_frame), edit="smooth", amount=50.0, warn=False)
        stopped = time.perf_counter()
    finally:
        timer.join()
    assert fired and stopped - fired[0] < 10, "the call did not stop soon after cancel()"
    assert not diff(before, snapshot())
    compositing.close_render()


def test_recomposite_operator_reports_cancelled(big_frame, capfd):
    """The Recomposite Render operator (synchronous here: no window) cancelled from a timer
    thread: {'CANCELLED'}, the report says so, and no image was made."""
    from support.atomic_harness import diff, snapshot

    from rokeby import compositing
    from rokeby.compositing import ui as compositing_ui
    from rokeby.core import native

    bpy.ops.wm.read_factory_settings(use_empty=True)
    rokeby.register()
    compositing.close_render()
    before = snapshot()
    timer = threading.Timer(10.0, native.cancel)
    timer.start()
    try:
        r = bpy.ops.rokeby.composite_edit(filepath=str(big_frame), edit="SMOOTH", amount=50.0, backend="CPU")
    finally:
        timer.cancel()
    assert r == {"CANCELLED"}
    assert compositing_ui.CANCELLED in capfd.readouterr().out
    assert not diff(before, snapshot())
    compositing.close_render()
