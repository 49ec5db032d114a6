"""Job bundles for render farms, written as Deadline Cloud reads them and ``openjd run`` runs them:
a folder with ``template.yaml`` (Open Job Description, ``jobtemplate-2023-09``),
``parameter_values.yaml`` and the extension zip. bpy-free: a pipeline writes bundles from any Python.

The render job: one job-level environment installs the bundle's zip into the worker's Blender once
per worker session (``blender --command extension install-file -r user_default -e ZIP``, Blender
4.2+); one step renders the frame range, one task per chunk of frames, one Blender process per
task (``render_task.py``, embedded in the template), which refuses to render unless the add-on is
enabled and is the version the job was exported with.
"""

from __future__ import annotations

import json
import os
import re
import shutil
from pathlib import Path

from ..core.errors import RokebyError

SPEC = "jobtemplate-2023-09"
_HERE = Path(__file__).resolve().parent


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


def _find_zip(zip_path) -> "Path | None":
    if zip_path is not None:
        z = Path(zip_path)
        if not z.is_file():
            raise RokebyError(f"zip_path: {z} is not a file (make dist builds dist/rokeby-<version>.zip)")
        return z
    want = f"rokeby-{addon_version()}.zip"
    for folder in (_HERE.parents[2] / "dist", Path.cwd() / "dist"):
        if (folder / want).is_file():
            return folder / want
    if (_HERE.parent / "wheels").is_dir():  # an installed extension: pack it as it was installed
        return None
    raise RokebyError(f"zip_path: no {want} found in dist/ (run `make dist`, or pass the extension zip's path)")


def _pack_installed(dest: Path) -> None:
    """The installed extension's folder (manifest, add-on files, wheels/) as a zip at ``dest``."""
    import zipfile

    root = _HERE.parent
    tmp = dest.with_name(f".{dest.name}.tmp")
    with zipfile.ZipFile(tmp, "w", zipfile.ZIP_DEFLATED) as z:
        for f in sorted(root.rglob("*")):
            if f.is_file() and "__pycache__" not in f.parts:
                z.write(f, f.relative_to(root).as_posix())
    os.replace(tmp, dest)


def render_template(first: int, last: int, chunk: int) -> dict:
    """The render job's template (a dict; JSON is valid YAML)."""
    task = (_HERE / "render_task.py").read_text()
    return {
        "specificationVersion": SPEC,
        "name": "Rokeby render {{RawParam.BlendFile}}",
        "parameterDefinitions": [
            {"name": "BlendFile", "type": "PATH", "objectType": "FILE", "dataFlow": "IN",
             "description": "The saved .blend to render."},
            {"name": "OutputDir", "type": "PATH", "objectType": "DIRECTORY", "dataFlow": "OUT",
             "description": "Where frame_NNNN files are written."},
            {"name": "ExtensionZip", "type": "PATH", "objectType": "FILE", "dataFlow": "IN",
             "description": "The Rokeby extension zip installed into the worker's Blender."},
            {"name": "RokebyVersion", "type": "STRING", "description": "The add-on version the job was exported with."},
            {"name": "FrameStart", "type": "INT", "default": first},
            {"name": "FrameEnd", "type": "INT", "default": last},
            {"name": "ChunkSize", "type": "INT", "default": chunk, "minValue": 1},
            {"name": "BlenderExecutable", "type": "STRING", "default": "blender",
             "description": "The worker's Blender 4.2+ (a name on PATH or a path)."},
        ],
        "jobEnvironments": [{
            "name": "RokebyAddon",
            "description": "Installs and enables the bundle's Rokeby extension in the worker's Blender.",
            "script": {"actions": {"onEnter": {
                "command": "{{Param.BlenderExecutable}}",
                "args": ["--command", "extension", "install-file", "-r", "user_default", "-e", "{{Param.ExtensionZip}}"],
            }}},
        }],
        "steps": [{
            "name": "Render",
            "parameterSpace": {"taskParameterDefinitions": [
                {"name": "ChunkStart", "type": "INT", "range": "{{Param.FrameStart}}-{{Param.FrameEnd}}:{{Param.ChunkSize}}"},
            ]},
            "script": {
                "embeddedFiles": [{"name": "RenderTask", "type": "TEXT", "filename": "render_task.py", "data": task}],
                "actions": {"onRun": {
                    "command": "{{Param.BlenderExecutable}}",
                    "args": ["-b", "{{Param.BlendFile}}", "--python-exit-code", "1", "--python", "{{Task.File.RenderTask}}",
                             "--", "{{Task.Param.ChunkStart}}", "{{Param.ChunkSize}}", "{{Param.FrameEnd}}",
                             "{{Param.OutputDir}}", "{{Param.RokebyVersion}}"],
                }},
            },
        }],
    }


def write_render_job(blend, bundle_dir, *, frames=None, chunk: int = 1, zip_path=None, output_dir=None) -> Path:
    """Writes a job bundle that renders the saved ``blend`` on a farm: ``bundle_dir/template.yaml``,
    ``parameter_values.yaml`` and the extension zip (``zip_path``, else ``dist/rokeby-<version>.zip``,
    else the installed extension packed as it was installed).
    ``frames``: "A-B" or (A, B) (required: the file's own range is not known without Blender);
    ``chunk`` frames per task; ``output_dir`` default
    ``<blend's folder>/render``. Returns the bundle folder. Bad arguments are ``RokebyError``
    naming them; nothing is written then."""
    blend = Path(blend).resolve()
    if not blend.is_file() or blend.suffix != ".blend":
        raise RokebyError(f"blend: {blend} is not a saved .blend file")
    if frames is None:
        raise RokebyError("frames: give the frame range, e.g. '1-250'")
    first, last = _frames(frames)
    if int(chunk) < 1:
        raise RokebyError(f"chunk: at least 1 frame per task, got {chunk}")
    z = _find_zip(zip_path)
    out = Path(output_dir).resolve() if output_dir else blend.parent / "render"
    bundle = Path(bundle_dir).resolve()
    bundle.mkdir(parents=True, exist_ok=True)
    name = z.name if z is not None else f"rokeby-{addon_version()}.zip"
    if z is not None:
        shutil.copyfile(z, bundle / name)
    else:
        _pack_installed(bundle / name)
    values = {"parameterValues": [
        {"name": "BlendFile", "value": str(blend)},
        {"name": "OutputDir", "value": str(out)},
        {"name": "ExtensionZip", "value": str(bundle / name)},
        {"name": "RokebyVersion", "value": addon_version()},
        {"name": "FrameStart", "value": first},
        {"name": "FrameEnd", "value": last},
        {"name": "ChunkSize", "value": int(chunk)},
    ]}
    for name, data in (("template.yaml", render_template(first, last, int(chunk))), ("parameter_values.yaml", values)):
        tmp = bundle / f".{name}.tmp"
        tmp.write_text(json.dumps(data, indent=2) + "\n")
        os.replace(tmp, bundle / name)
    return bundle
