"""One task of a Rokeby render job, run inside the worker's Blender:
``blender -b FILE --python-exit-code 1 --python render_task.py -- FIRST COUNT END OUT_DIR VERSION``.

Renders frames FIRST..min(FIRST + COUNT - 1, END) of FILE into OUT_DIR as ``frame_NNNN.<ext>``. It refuses to render
unless the Rokeby add-on is enabled in this Blender and is VERSION (the version the job was
exported with): without the add-on a file with Rokeby edits renders the field as it was saved, at
every frame, with no error. Each frame is rendered to a temporary name and renamed when whole, so a
killed task leaves no partial output; a frame whose file exists is skipped, so a rerun finishes
what is missing. The exit status is non-zero when any frame failed.

This file is copied verbatim into the job template (an embedded file): it imports nothing of Rokeby.
"""

import os
import signal
import sys

import bpy


def _fail(msg: str) -> None:
    print(f"rokeby.farm: {msg}", file=sys.stderr, flush=True)
    sys.exit(1)


def _rokeby_module():
    """The enabled add-on's module (``rokeby`` or an extension ``bl_ext.<repo>.rokeby``), or None."""
    for name in bpy.context.preferences.addons.keys():
        if name == "rokeby" or name.endswith(".rokeby"):
            return sys.modules.get(name)
    return None


def main(argv) -> int:
    first, size, end = int(argv[0]), int(argv[1]), int(argv[2])
    last, out_dir, version = min(first + size - 1, end), argv[3], argv[4]
    mod = _rokeby_module()
    if mod is None:
        _fail("the Rokeby add-on is not enabled in this Blender (the job's environment installs it from "
              "the bundle's extension zip); refusing to render a frozen field")
    have = getattr(mod, "__version__", None)
    if have != version:
        _fail(f"the Rokeby add-on here is version {have}, the job was exported with {version}")
    stop = []
    for sig in (signal.SIGTERM, signal.SIGINT):
        signal.signal(sig, lambda *_: stop.append(True))
    sc = bpy.context.scene
    os.makedirs(out_dir, exist_ok=True)
    ext = sc.render.file_extension
    for name in os.listdir(out_dir):  # what an earlier, killed run of this task left
        if name.startswith(".partial_") and first <= int(name.split("_")[1]) <= last:
            os.remove(os.path.join(out_dir, name))
    failed = []
    for frame in range(first, last + 1):
        if stop:
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
            if stop:
                raise RuntimeError("cancelled")
            os.replace(part, final)
            print(f"rokeby.farm: frame {frame}: {final}", flush=True)
        except Exception as exc:  # noqa: BLE001 - reported, and the task fails
            failed.append(frame)
            print(f"rokeby.farm: frame {frame} failed: {exc}", file=sys.stderr, flush=True)
        finally:
            if os.path.exists(part):
                os.remove(part)
        if stop:
            _fail(f"cancelled at frame {frame} (no partial file left)")
    if failed:
        _fail(f"{len(failed)} frame(s) failed: {failed}")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[sys.argv.index("--") + 1:]))
