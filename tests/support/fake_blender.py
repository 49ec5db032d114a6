"""TEST-ONLY: a `blender` executable built on bpy (Blender as a Python module), for running the farm
jobs' commands where no Blender binary is installed. Not a Blender: it implements exactly the
command forms of the job templates (rokeby/farm/api.py), as Blender 4.2+ treats them:

    blender --command extension install-file -r REPO [-e] ZIP
        Checks that ZIP is a Blender extension zip (blender_manifest.toml with an id, a version and
        the wheels it lists inside), unpacks it as REPO's extension, and with -e (--enable) records
        it as enabled. Exit 1 with an "Error: …" line when it cannot (as Blender does).
    blender -b [FILE] [--python-exit-code N] --python SCRIPT [-- ARGS]
        A fresh Python process with bpy: enables the installed add-on as Blender enables a user's
        add-ons at start-up (a failure is printed and leaves it disabled), opens FILE, runs SCRIPT
        with sys.argv as Blender gives it (ARGS after '--'); SystemExit's code is the exit status, an
        exception exits N (--python-exit-code), the end of the script exits 0.

Its state (what is installed and enabled) lives in $ROKEBY_FAKE_BLENDER_HOME, as Blender's user
configuration would. The native core comes from the test environment (the zip's wheels are not
installed into it). Anything else is refused with exit 2, so a template that starts using another
command form fails its test instead of passing by accident.
"""

from __future__ import annotations

import sys
from pathlib import Path

SCRIPT = r'''#!{python}
# TEST-ONLY stand-in for `blender` (tests/support/fake_blender.py says what it implements).
import os, runpy, sys, tomllib, zipfile
from pathlib import Path

HOME = Path(os.environ["ROKEBY_FAKE_BLENDER_HOME"])
argv = sys.argv[1:]


def refuse(why):
    print(f"fake blender: {{why}}: {{argv}}", file=sys.stderr)
    sys.exit(2)


def install(rest):
    if "-r" not in rest or not rest or rest[-1].startswith("-"):
        refuse("install-file needs -r REPO and the zip")
    repo, zpath = rest[rest.index("-r") + 1], rest[-1]
    try:
        with zipfile.ZipFile(zpath) as z:
            meta = tomllib.loads(z.read("blender_manifest.toml").decode())
            for key in ("id", "version", "type"):
                if key not in meta:
                    raise ValueError(f"blender_manifest.toml has no '{{key}}'")
            for wheel in meta.get("wheels", []):
                z.getinfo(wheel.removeprefix("./"))  # a listed wheel that is missing: KeyError
            dest = HOME / "extensions" / repo / meta["id"]
            dest.mkdir(parents=True, exist_ok=True)
            z.extractall(dest)
    except Exception as exc:  # noqa: BLE001 - reported as Blender reports a failed install
        print(f"Error: cannot install {{zpath}}: {{exc}}", file=sys.stderr)
        sys.exit(1)
    if "-e" in rest or "--enable" in rest:
        (HOME / "enabled").write_text(f"{{dest.parent}}\n{{meta['id']}}")
    print(f'Installed "{{meta["id"]}}"')
    sys.exit(0)


def background(rest):
    blend = None
    if rest and not rest[0].startswith("-"):
        blend, rest = rest[0], rest[1:]
    head = rest[: rest.index("--")] if "--" in rest else rest
    exit_code = 0
    if head[:1] == ["--python-exit-code"]:
        exit_code, head = int(head[1]), head[2:]
    if len(head) != 2 or head[0] != "--python":
        refuse("expected -b [FILE] [--python-exit-code N] --python SCRIPT [-- ARGS]")
    script = head[1]
    import bpy  # first: it puts Blender's own modules (addon_utils) on the path
    import addon_utils

    enabled = HOME / "enabled"
    if enabled.exists():
        folder, name = enabled.read_text().split("\n")
        sys.path.insert(0, folder)
        for mod in [m for m in sys.modules if m == name or m.startswith(name + ".")]:
            del sys.modules[mod]  # the test environment's own copy: the installed one is enabled
        addon_utils.enable(name, default_set=True)  # prints the error and stays disabled when it fails
    if blend is not None:
        bpy.ops.wm.open_mainfile(filepath=blend)
    sys.argv = [sys.argv[0], "-b", *([blend] if blend else []), *rest]
    try:
        runpy.run_path(script, run_name="__main__")
    except SystemExit as exc:
        code = exc.code
        if code is not None and not isinstance(code, int):
            print(code, file=sys.stderr)
            code = 1
        sys.exit(code or 0)
    except BaseException:
        import traceback

        traceback.print_exc()
        sys.exit(exit_code)
    sys.exit(0)


if argv[:3] == ["--command", "extension", "install-file"]:
    install(argv[3:])
if argv[:1] == ["-b"]:
    background(argv[1:])
refuse("unsupported command line")
'''


def write(folder: Path) -> Path:
    """Writes the stand-in as ``folder/blender`` (executable, run by this test's Python); returns it."""
    exe = Path(folder) / "blender"
    exe.parent.mkdir(parents=True, exist_ok=True)
    exe.write_text(SCRIPT.format(python=sys.executable))
    exe.chmod(0o755)
    return exe
