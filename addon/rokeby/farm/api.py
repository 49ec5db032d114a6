"""Job bundles for render farms, written as Deadline Cloud reads them and ``openjd run`` runs them:
a folder with ``template.yaml`` (Open Job Description, ``jobtemplate-2023-09``),
``parameter_values.yaml`` and the extension zip. bpy-free: a pipeline writes bundles from any Python.

Two jobs, each with the same two job-level environments (entered once per worker session):
``RokebyAddon`` installs the bundle's zip into the worker's Blender (``blender --command extension
install-file -r user_default -e ZIP``, Blender 4.2+), and ``RokebyAddonCheck`` checks in a fresh
Blender that Rokeby is enabled and is the zip's version (else the job fails there, before any task).

- The render job: one step, one task per chunk of frames, one Blender process per task
  (``worker.py render``), which refuses to render unless the add-on is enabled and is the version
  the job was exported with and the file was saved with (``marker.py``).
- The recompositing job: one step over a folder of multilayer EXRs, one task per chunk of frames,
  each frame through ``python -m rokeby.composite --sequence … --frame K`` inside the worker's
  Blender (``worker.py recomposite``), where the job's zip installed Rokeby and its native core.
"""

from __future__ import annotations

__all__ = ["write_render_job", "write_recomposite_job"]

import json
import os
import re
import shutil
import tempfile
import zipfile
from pathlib import Path

from ..core import schema
from ..core.errors import RokebyError

SPEC = "jobtemplate-2023-09"
_HERE = Path(__file__).resolve().parent
EXTENSION_ID = "rokeby"
# How long a cancelled task has between SIGTERM and SIGKILL: a render stops after the frame it is on.
CANCEL_NOTICE_S = 120


def addon_version() -> str:
    """The version of this add-on, as its manifest (blender_manifest.toml) states it."""
    text = (_HERE.parent / "blender_manifest.toml").read_text()
    m = re.search(r'^version\s*=\s*"([^"]+)"', text, re.M)
    if not m:
        raise RokebyError("blender_manifest.toml: has no version")
    return m.group(1)


def _frames(frames) -> tuple[int, int]:
    if isinstance(frames, str):
        m = re.fullmatch(r"\s*(-?\d+)\s*(?:-\s*(-?\d+)\s*)?", frames)
        if not m:
            raise RokebyError(f"frames: expected A-B or A, got {frames!r}")
        a = int(m.group(1))
        b = int(m.group(2)) if m.group(2) is not None else a
    else:
        a, b = (int(x) for x in frames)
    if b < a:
        raise RokebyError(f"frames: the last frame {b} is before the first {a}")
    return a, b


def _chunk(chunk) -> int:
    if int(chunk) != chunk or int(chunk) < 1:
        raise RokebyError(f"chunk: at least 1 frame per task, got {chunk}")
    return int(chunk)


# --- the extension zip ---------------------------------------------------------------------------

def zip_version(path) -> str:
    """The version of the Rokeby extension zip ``path`` (its blender_manifest.toml); a
    ``RokebyError`` naming the problem when it is no such zip."""
    import tomllib  # noqa: PLC0415

    path = Path(path)
    try:
        with zipfile.ZipFile(path) as z:
            meta = tomllib.loads(z.read("blender_manifest.toml").decode())
    except KeyError:
        raise RokebyError(f"zip_path: {path} has no blender_manifest.toml at its root: not a Blender extension zip") from None
    except (zipfile.BadZipFile, OSError, UnicodeDecodeError, tomllib.TOMLDecodeError) as exc:
        raise RokebyError(f"zip_path: {path} is not a Blender extension zip ({exc})") from None
    if meta.get("id") != EXTENSION_ID or not isinstance(meta.get("version"), str):
        raise RokebyError(f"zip_path: {path} is the extension '{meta.get('id')}', not Rokeby's")
    if not meta.get("wheels"):
        raise RokebyError(f"zip_path: {path} carries no wheels (the native core): build it with `make dist`")
    return meta["version"]


def _checkout() -> "Path | None":
    """The project checkout this add-on runs from (addon/rokeby beside tools/build_extension.py), if any."""
    root = _HERE.parents[2]
    if (root / "tools" / "build_extension.py").is_file() and (root / "addon" / "rokeby").resolve() == _HERE.parent:
        return root
    return None


def _build_from_checkout(root: Path, dest: Path) -> Path:
    """The extension zip of the checkout's add-on as `make dist` builds it (tools/build_extension.py)
    from the native wheel `make native` built, written into ``dest``."""
    import importlib.util  # noqa: PLC0415

    spec = importlib.util.spec_from_file_location("_rokeby_build_extension", root / "tools" / "build_extension.py")
    be = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(be)
    try:
        return Path(be.build(root / "addon" / "rokeby", root / "target" / "wheels", dest, root / "shaders"))
    except (be.BuildError, OSError) as exc:
        raise RokebyError(f"zip_path: cannot build the extension zip from the checkout {root}: {exc} "
                          "(or pass the zip that `make dist` wrote, dist/rokeby-<version>.zip)") from None


def _installed() -> bool:
    """Whether this add-on runs as an installed extension (its folder holds the zip's wheels/)."""
    return (_HERE.parent / "wheels").is_dir() and any((_HERE.parent / "wheels").glob("*.whl"))


def _pack_installed(dest: Path) -> Path:
    """The installed extension's folder (manifest, add-on files, wheels/) as a zip in ``dest``."""
    root = _HERE.parent
    out = dest / f"{EXTENSION_ID}-{addon_version()}.zip"
    with zipfile.ZipFile(out, "w", zipfile.ZIP_DEFLATED) as z:
        for f in sorted(root.rglob("*")):
            if f.is_file() and "__pycache__" not in f.parts and f.suffix != ".pyc":
                z.write(f, f.relative_to(root).as_posix())
    return out


def _extension_zip(zip_path, dest: Path) -> Path:
    """The zip for the bundle, written into the (temporary) folder ``dest``: ``zip_path`` when given;
    else, running from the project checkout, the zip built from it (as `make dist`); else, running
    as an installed extension, that extension packed as installed. Checked to be Rokeby's."""
    if zip_path is not None:
        z = Path(zip_path)
        if not z.is_file():
            raise RokebyError(f"zip_path: {z} is not a file (`make dist` builds dist/rokeby-<version>.zip)")
        zip_version(z)
        out = dest / z.name
        shutil.copyfile(z, out)
        return out
    root = _checkout()
    if root is not None:
        return _build_from_checkout(root, dest)
    if _installed():
        return _pack_installed(dest)
    raise RokebyError(f"zip_path: no extension zip: this add-on ({_HERE.parent}) is neither the project checkout nor an "
                      "installed extension; pass the zip (`make dist` builds dist/rokeby-<version>.zip)")


# --- templates -----------------------------------------------------------------------------------

def _common_parameters(first: int, last: int, chunk: int, what: str) -> list:
    return [
        {"name": "ExtensionZip", "type": "PATH", "objectType": "FILE", "dataFlow": "IN",
         "description": "The Rokeby extension zip installed into the worker's Blender."},
        {"name": "RokebyVersion", "type": "STRING", "description": "The version of the extension zip (and of the add-on every task requires)."},
        {"name": "FrameStart", "type": "INT", "default": first, "description": f"The first frame ({what})."},
        {"name": "FrameEnd", "type": "INT", "default": last, "description": f"The last frame ({what})."},
        {"name": "ChunkSize", "type": "INT", "default": chunk, "minValue": 1, "description": "Frames per task (one Blender process each)."},
        {"name": "BlenderExecutable", "type": "STRING", "default": "blender",
         "description": "The worker's Blender 4.2+ (a name on PATH or a path)."},
    ]


def _worker_file(name: str) -> dict:
    text = (_HERE / "worker.py").read_text()
    if "{" + "{" in text:  # embedded files are format strings
        raise RokebyError("farm/worker.py: holds two braces in a row, which the job template would read as a format string")
    return {"name": name, "type": "TEXT", "filename": "rokeby_farm_worker.py", "data": text}


def _blender_python(*args) -> list:
    """A background Blender running the embedded worker: ``-b [args] --python-exit-code 1 --python …``."""
    return ["-b", *args, "--python-exit-code", "1", "--python"]


def _environments() -> list:
    return [
        {
            "name": "RokebyAddon",
            "description": "Installs and enables the bundle's Rokeby extension in the worker's Blender.",
            "script": {"actions": {"onEnter": {
                "command": "{{Param.BlenderExecutable}}",
                "args": ["--command", "extension", "install-file", "-r", "user_default", "-e", "{{Param.ExtensionZip}}"],
            }}},
        },
        {
            "name": "RokebyAddonCheck",
            "description": "Checks in a fresh Blender that Rokeby is enabled and is the zip's version.",
            "script": {
                "embeddedFiles": [_worker_file("Worker")],
                "actions": {"onEnter": {
                    "command": "{{Param.BlenderExecutable}}",
                    "args": [*_blender_python(), "{{Env.File.Worker}}", "--", "check", "{{Param.RokebyVersion}}"],
                }},
            },
        },
    ]


def _step(name: str, args: list) -> dict:
    return {
        "name": name,
        "parameterSpace": {"taskParameterDefinitions": [
            {"name": "ChunkStart", "type": "INT", "range": "{{Param.FrameStart}}-{{Param.FrameEnd}}:{{Param.ChunkSize}}"},
        ]},
        "script": {
            "embeddedFiles": [_worker_file("Worker")],
            "actions": {"onRun": {
                "command": "{{Param.BlenderExecutable}}",
                "args": args,
                "cancelation": {"mode": "NOTIFY_THEN_TERMINATE", "notifyPeriodInSeconds": CANCEL_NOTICE_S},
            }},
        },
    }


def _job_name(prefix: str, name: str) -> str:
    return f"{prefix} {name}"[:120]


def render_template(first: int, last: int, chunk: int, name: str = "shot") -> dict:
    """The render job's template (a dict; JSON is valid YAML)."""
    return {
        "specificationVersion": SPEC,
        "name": _job_name("Rokeby render", name),
        "description": "Renders a saved .blend's frames with the Rokeby add-on installed on each worker (docs/farm.md).",
        "parameterDefinitions": [
            {"name": "BlendFile", "type": "PATH", "objectType": "FILE", "dataFlow": "IN", "description": "The saved .blend to render."},
            {"name": "OutputDir", "type": "PATH", "objectType": "DIRECTORY", "dataFlow": "OUT",
             "description": "Where frame_NNNN files are written."},
            *_common_parameters(first, last, chunk, "the scene's frame number"),
        ],
        "jobEnvironments": _environments(),
        "steps": [_step("Render", [
            *_blender_python("{{Param.BlendFile}}"), "{{Task.File.Worker}}", "--", "render", "{{Task.Param.ChunkStart}}",
            "{{Param.ChunkSize}}", "{{Param.FrameEnd}}", "{{Param.OutputDir}}", "{{Param.RokebyVersion}}",
            schema.SCENE_SAVED_WITH_KEY,
        ])],
    }


def recomposite_template(count: int, chunk: int, edit: list, name: str = "frames", bump: bool = False) -> dict:
    """The recompositing job's template: frames 1..``count`` of a sequence with the checked edit
    options ``edit`` (``--bump``'s image, when ``bump``, is the ``BumpImage`` parameter)."""
    edit = list(edit)
    if bump:
        edit = _bump_as_parameter(edit)
    params = [
        {"name": "InputDir", "type": "PATH", "objectType": "DIRECTORY", "dataFlow": "IN",
         "description": "The folder of multilayer EXR frames rendered with the compositing passes."},
        {"name": "OutputDir", "type": "PATH", "objectType": "DIRECTORY", "dataFlow": "OUT",
         "description": "Where the recomposited frames are written, under the input frames' names."},
        {"name": "FramePattern", "type": "STRING", "description": "Which files of InputDir are frames: a glob, or '#' per frame digit."},
        *_common_parameters(1, count, chunk, "its position among the frames matching FramePattern, 1-based"),
    ]
    if bump:
        params.append({"name": "BumpImage", "type": "PATH", "objectType": "FILE", "dataFlow": "IN",
                       "description": "The height image of --bump."})
    return {
        "specificationVersion": SPEC,
        "name": _job_name("Rokeby recomposite", name),
        "description": "python -m rokeby.composite --sequence, frame by frame, with the edit options "
                       + " ".join(edit).replace("{{Param.BumpImage}}", "BUMP") + " (docs/farm.md).",
        "parameterDefinitions": params,
        "jobEnvironments": _environments(),
        "steps": [_step("Recomposite", [
            *_blender_python(), "{{Task.File.Worker}}", "--", "recomposite", "{{Task.Param.ChunkStart}}", "{{Param.ChunkSize}}",
            "{{Param.FrameEnd}}", "{{Param.InputDir}}", "{{Param.OutputDir}}", "{{Param.FramePattern}}",
            "{{Param.RokebyVersion}}", *edit,
        ])],
    }


def _bump_path(edit: list) -> "str | None":
    for i, v in enumerate(edit):
        if v == "--bump" and i + 1 < len(edit):
            return edit[i + 1]
        if v.startswith("--bump="):
            return v[len("--bump="):]
    return None


def _bump_as_parameter(edit: list) -> list:
    out, i = [], 0
    while i < len(edit):
        if edit[i] == "--bump":
            out += ["--bump", "{{Param.BumpImage}}"]
            i += 2
            continue
        out.append("--bump={{Param.BumpImage}}" if edit[i].startswith("--bump=") else edit[i])
        i += 1
    return out


# --- bundles -------------------------------------------------------------------------------------

def _write_bundle(bundle_dir, template: dict, values: list, zip_path, saved_with: "str | None" = None) -> Path:
    """The bundle folder: the zip (see :func:`_extension_zip`), then ``parameter_values.yaml`` and
    ``template.yaml`` (JSON, which is YAML), each written whole and renamed; ``values`` gets the zip's
    path and version. Nothing is written to ``bundle_dir`` when the zip cannot be had, or is not
    ``saved_with``'s version."""
    bundle = Path(bundle_dir).resolve()
    bundle.parent.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory(dir=bundle.parent, prefix=f".{bundle.name}.") as tmp:
        z = _extension_zip(zip_path, Path(tmp))
        version = zip_version(z)
        if saved_with is not None and version != saved_with:
            raise RokebyError(f"zip_path: the extension zip is Rokeby {version}, the file was saved with Rokeby {saved_with} "
                              f"(its tasks would refuse to render it): pass the zip of Rokeby {saved_with}, or save the file "
                              f"with Rokeby {version}")
        bundle.mkdir(exist_ok=True)
        for old in bundle.glob(f"{EXTENSION_ID}-*.zip"):  # another version's zip of an earlier export
            if old.name != z.name:
                old.unlink()
        os.replace(z, bundle / z.name)
    values = [*values, {"name": "ExtensionZip", "value": str(bundle / z.name)}, {"name": "RokebyVersion", "value": version}]
    for name, data in (("template.yaml", template), ("parameter_values.yaml", {"parameterValues": values})):
        tmp = bundle / f".{name}.tmp"
        tmp.write_text(json.dumps(data, indent=2, ensure_ascii=False) + "\n")
        os.replace(tmp, bundle / name)
    return bundle


def write_render_job(blend, bundle_dir, *, frames=None, chunk: int = 1, zip_path=None, output_dir=None,
                     saved_with: "str | None" = None) -> Path:
    """Writes a job bundle that renders the saved ``blend`` on a farm: ``bundle_dir/template.yaml``,
    ``parameter_values.yaml`` and the extension zip (``zip_path``; by default, from the project
    checkout, the zip `make dist` builds, else the installed extension packed as installed).
    ``frames``: "A-B" or (A, B) (required: the file's own range is not known without Blender);
    ``chunk`` frames per task; ``output_dir`` default ``<blend's folder>/render``; ``saved_with``: the
    Rokeby version the file's scene marker names (the operator passes it), which must be the zip's.
    Returns the bundle folder. Bad arguments are ``RokebyError`` naming them; nothing is written then."""
    blend = Path(blend).resolve()
    if not blend.is_file() or blend.suffix != ".blend":
        raise RokebyError(f"blend: {blend} is not a saved .blend file")
    if frames is None:
        raise RokebyError("frames: give the frame range, e.g. '1-250'")
    first, last = _frames(frames)
    chunk = _chunk(chunk)
    out = Path(output_dir).resolve() if output_dir else blend.parent / "render"
    template = render_template(first, last, chunk, blend.name)
    values = [
        {"name": "BlendFile", "value": str(blend)},
        {"name": "OutputDir", "value": str(out)},
        {"name": "FrameStart", "value": first},
        {"name": "FrameEnd", "value": last},
        {"name": "ChunkSize", "value": chunk},
    ]
    return _write_bundle(bundle_dir, template, values, zip_path, saved_with)


def write_recomposite_job(input_dir, output_dir, bundle_dir, *, pattern: str = "*.exr", edit_options=(), chunk: int = 1,
                          zip_path=None) -> Path:
    """Writes a job bundle that recomposites the multilayer EXR frames of ``input_dir`` matching
    ``pattern`` (a glob, or '#' per frame digit) into ``output_dir``, frame by frame as
    ``python -m rokeby.composite --sequence input_dir output_dir --pattern P --frame K --skip-existing
    EDIT_OPTIONS`` does, ``chunk`` frames per task. ``edit_options``: that command's edit options
    (``["--emboss", "0.6"]``; ``rokeby.compositing.one_knob_options`` gives the operators' one-knob
    edit as options), checked now. The frames are counted now: the job covers those that exist.
    Zip and result as for :func:`write_render_job`."""
    from .. import compositing  # noqa: PLC0415 - numpy and the native core, only for this job

    src = Path(input_dir).resolve()
    if not src.is_dir():
        raise RokebyError(f"input_dir: {src} is not a folder")
    dst = Path(output_dir).resolve()
    if dst == src:
        raise RokebyError("output_dir: must differ from input_dir (the frames would be overwritten)")
    try:
        frames = compositing.sequence_frames(str(src), pattern)
        edit = compositing.edit_options(edit_options)
    except compositing.CompositingError as exc:
        raise RokebyError(str(exc)) from None
    if not frames:
        raise RokebyError(f"pattern: no frames matching '{pattern}' in {src}")
    chunk = _chunk(chunk)
    bump = _bump_path(edit)
    template = recomposite_template(len(frames), chunk, edit, src.name, bump=bump is not None)
    values = [
        {"name": "InputDir", "value": str(src)},
        {"name": "OutputDir", "value": str(dst)},
        {"name": "FramePattern", "value": pattern},
        {"name": "FrameStart", "value": 1},
        {"name": "FrameEnd", "value": len(frames)},
        {"name": "ChunkSize", "value": chunk},
    ]
    if bump is not None:
        values.append({"name": "BumpImage", "value": str(Path(bump).resolve())})
    return _write_bundle(bundle_dir, template, values, zip_path)
