"""What a Rokeby farm job runs inside the worker's Blender (embedded verbatim in the job template):

    blender -b --python-exit-code 1 --python worker.py -- check VERSION
    blender -b FILE --python-exit-code 1 --python worker.py -- render FIRST COUNT END OUT_DIR VERSION MARKER_KEY
    blender -b --python-exit-code 1 --python worker.py -- recomposite FIRST COUNT END IN_DIR OUT_DIR PATTERN VERSION [EDIT OPTIONS]

``check`` (the job environment ``RokebyAddonCheck``, once per worker session, after the zip was
installed): the Rokeby add-on is enabled in this Blender and is VERSION, the version of the job's
zip; otherwise exit 1 with one line saying what is wrong.

``render``: frames FIRST..min(FIRST + COUNT - 1, END) of FILE into OUT_DIR as ``frame_NNNN.<ext>``.
It refuses to render unless the add-on is enabled and is VERSION, and, when FILE's scene carries the
marker MARKER_KEY (the version that saved it: ``marker.py``), that version too. Without the add-on a
file with Rokeby edits renders them as they were saved, at every frame, with no error.

``recomposite``: frames FIRST..min(FIRST + COUNT - 1, END) (1-based, in frame order) of the EXR
sequence IN_DIR/PATTERN through the enabled add-on's ``python -m rokeby.composite --sequence
… --frame K --skip-existing`` with the EDIT OPTIONS, into OUT_DIR under the frames' names. It runs
inside Blender because that is where the job's zip installed Rokeby and its native core.

Both write each frame under a temporary name and rename it when whole (a killed task leaves no
partial frame under a final name; its temporary files are removed when the task runs again), skip
a frame whose output exists (a rerun finishes what is missing), and exit non-zero when any frame
failed. SIGTERM or SIGINT (a cancel from the job's runner) stops the task: the render after the
frame being rendered (Blender does not run Python while it renders), the recompositing at once;
neither leaves a partial frame.

This file imports nothing of Rokeby: it finds the add-on that this Blender has enabled. It never
holds two braces in a row: the template's embedded files are format strings.
"""

import glob
import importlib
import os
import signal
import sys

import bpy


def _fail(msg: str, status: int = 1) -> None:
    print(f"rokeby.farm: {msg}", file=sys.stderr, flush=True)
    sys.exit(status)


def _rokeby_module():
    """The enabled add-on's module (``rokeby``, or an extension's ``bl_ext.<repo>.rokeby``), or None."""
    for name in bpy.context.preferences.addons.keys():
        if name == "rokeby" or name.endswith(".rokeby"):
            mod = sys.modules.get(name)
            if mod is None:
                try:
                    mod = importlib.import_module(name)
                except ImportError:
                    return None
            return mod
    return None


def _require(version: str):
    """The enabled Rokeby module, which is ``version``; else the task fails with one line."""
    mod = _rokeby_module()
    if mod is None:
        _fail("the Rokeby add-on is not enabled in this Blender (the job's environment installs it from the bundle's "
              "extension zip; without it a file with Rokeby edits renders them frozen as saved, so this task refuses)")
    have = getattr(mod, "__version__", None)
    if have != version:
        _fail(f"the Rokeby add-on enabled here ({mod.__name__}) is version {have}; the job was exported with {version}")
    return mod


def check(argv) -> int:
    (version,) = argv
    mod = _require(version)
    print(f"rokeby.farm: Rokeby {version} is enabled in Blender {bpy.app.version_string} ({mod.__name__}, "
          f"{os.path.dirname(mod.__file__)})", flush=True)
    return 0


def _chunk(argv):
    first, size, end = int(argv[0]), int(argv[1]), int(argv[2])
    return first, min(first + size - 1, end)


_stop = []


def _on_stop_flag(*_args):
    _stop.append(True)


def render(argv) -> int:
    first, last = _chunk(argv)
    out_dir, version, marker_key = argv[3], argv[4], argv[5]
    mod = _require(version)
    sc = bpy.context.scene
    saved = sc.get(marker_key)
    if saved is not None and str(saved) != mod.__version__:
        _fail(f"the file was saved with Rokeby {saved}, the add-on enabled here is {mod.__version__}: export the job "
              f"with the extension zip of Rokeby {saved}, or open and save the file with Rokeby {mod.__version__}")
    for sig in (signal.SIGTERM, signal.SIGINT):
        signal.signal(sig, _on_stop_flag)
    os.makedirs(out_dir, exist_ok=True)
    ext = sc.render.file_extension
    for frame in range(first, last + 1):  # what an earlier, killed run of this task left
        for stale in glob.glob(os.path.join(glob.escape(out_dir), f".partial_{frame:04d}_*")):
            os.remove(stale)
    failed = []
    for frame in range(first, last + 1):
        if _stop:
            _fail(f"cancelled before frame {frame}")
        final = os.path.join(out_dir, f"frame_{frame:04d}{ext}")
        if os.path.exists(final):
            print(f"rokeby.farm: frame {frame}: done already, skipped", flush=True)
            continue
        part = os.path.join(out_dir, f".partial_{frame:04d}_{os.getpid()}{ext}")
        try:
            sc.frame_set(frame)
            sc.render.filepath = part
            bpy.ops.render.render(write_still=True)
            if _stop:
                raise RuntimeError("cancelled")
            if not os.path.isfile(part):
                raise RuntimeError(f"Blender wrote no file for it (output format {sc.render.image_settings.file_format})")
            os.replace(part, final)
            print(f"rokeby.farm: frame {frame}: {final}", flush=True)
        except Exception as exc:  # noqa: BLE001 - reported, and the task fails
            failed.append(frame)
            print(f"rokeby.farm: frame {frame} failed: {exc}", file=sys.stderr, flush=True)
        finally:
            if os.path.exists(part):
                os.remove(part)
        if _stop:
            _fail(f"cancelled at frame {frame} (no partial file left)")
    if failed:
        _fail(f"{len(failed)} frame(s) failed: {failed}")
    return 0


def recomposite(argv) -> int:
    first, last = _chunk(argv)
    in_dir, out_dir, pattern, version, edit = argv[3], argv[4], argv[5], argv[6], argv[7:]
    mod = _require(version)
    composite = importlib.import_module(f"{mod.__name__}.composite")
    native = importlib.import_module(f"{mod.__name__}.core.native")
    frames = importlib.import_module(f"{mod.__name__}.compositing").sequence_frames(in_dir, pattern)
    if len(frames) < last:
        _fail(f"{in_dir} has {len(frames)} frame(s) matching '{pattern}'; this task's frames are {first}-{last}")
    os.makedirs(out_dir, exist_ok=True)
    for k in range(first, last + 1):  # temporary files an earlier, killed run of these frames left
        name = os.path.basename(frames[k - 1])
        for stale in glob.glob(os.path.join(glob.escape(out_dir), f".{glob.escape(name)}.partial-*")):
            os.remove(stale)

    def interrupted(*_args):
        native.cancel()  # native work in flight stops at its next row
        raise KeyboardInterrupt

    for sig in (signal.SIGTERM, signal.SIGINT):
        signal.signal(sig, interrupted)
    failed = []
    try:
        for k in range(first, last + 1):
            args = ["--sequence", in_dir, out_dir, "--pattern", pattern, "--frame", str(k), "--skip-existing", *edit]
            rc = composite.main(args)  # writes whole and renames; SIGINT/SIGTERM inside: status 130, no file
            if rc == 130:
                _fail(f"cancelled at frame {k} (no partial file left)")
            if rc != 0:
                failed.append(k)
    except KeyboardInterrupt:  # between two frames
        _fail("cancelled (no partial file left)")
    if failed:
        _fail(f"{len(failed)} frame(s) failed: {failed} (the lines above say why)")
    return 0


def main(argv) -> int:
    commands = {"check": check, "render": render, "recomposite": recomposite}
    if not argv or argv[0] not in commands:
        _fail(f"usage: worker.py -- {'|'.join(commands)} ARGS (got {argv})", 2)
    return commands[argv[0]](argv[1:])


if __name__ == "__main__":
    sys.exit(main(sys.argv[sys.argv.index("--") + 1:] if "--" in sys.argv else []))
