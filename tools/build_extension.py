"""`make dist`: the installable Blender extension zip, dist/rokeby-<version>.zip.

Blender 4.2+ extension layout: the add-on package's files at the zip root, blender_manifest.toml
among them, the checkout's GLSL (shaders/) as shaders/ next to them, and the native core's wheel
under wheels/. The manifest in the zip is generated from
addon/rokeby/blender_manifest.toml with the real wheel filename (``wheels = [...]``) and the
platform that wheel runs on; the source manifest is never edited.

The output is reproducible: entries are sorted, timestamps fixed, so a second run with the same
inputs writes the same bytes (and leaves an up-to-date zip untouched).

    python tools/build_extension.py [--wheels target/wheels] [--out dist] [--addon addon/rokeby]
"""

from __future__ import annotations

import argparse
import io
import json
import os
import re
import sys
import tomllib
import zipfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
WHEEL_NAME = "rokeby_native"
EXCLUDED_DIRS = {"__pycache__", "tests", ".pytest_cache", ".hypothesis"}
EXCLUDED_SUFFIXES = (".pyc", ".pyo", ".orig", ".rej", "~")
FIXED_TIME = (2024, 1, 1, 0, 0, 0)

# Wheel platform tag -> Blender's platform names (as blender_ext.py maps them).
_PLATFORMS = [
    (re.compile(r"^(manylinux|musllinux)_\d+_\d+_x86_64$|^linux_x86_64$|^manylinux\d+_x86_64$"), "linux-x64"),
    (re.compile(r"^(manylinux|musllinux)_\d+_\d+_aarch64$|^linux_aarch64$"), "linux-arm64"),
    (re.compile(r"^macosx_\d+_\d+_x86_64$"), "macos-x64"),
    (re.compile(r"^macosx_\d+_\d+_arm64$"), "macos-arm64"),
    (re.compile(r"^win_amd64$"), "windows-x64"),
    (re.compile(r"^win_arm64$"), "windows-arm64"),
]


class BuildError(RuntimeError):
    pass


def wheel_tags(filename: str) -> tuple[str, str, str]:
    """(python, abi, platform) tags of a wheel filename (name-version[-build]-py-abi-plat.whl)."""
    parts = filename[: -len(".whl")].split("-")
    if not filename.endswith(".whl") or len(parts) not in (5, 6):
        raise BuildError(f"{filename}: not a wheel filename")
    return parts[-3], parts[-2], parts[-1]


def blender_platforms(filename: str) -> list[str]:
    out = []
    for tag in wheel_tags(filename)[2].split("."):
        for pattern, name in _PLATFORMS:
            if pattern.match(tag) and name not in out:
                out.append(name)
    if not out:
        raise BuildError(f"{filename}: no Blender platform for wheel platform '{wheel_tags(filename)[2]}'")
    return out


def find_wheel(wheel_dir: Path, version: str) -> Path:
    found = sorted(wheel_dir.glob(f"{WHEEL_NAME}-*.whl"))
    if not found:
        raise BuildError(f"no {WHEEL_NAME} wheel in {wheel_dir}: run `make native` first")
    if len(found) > 1:
        raise BuildError(f"several {WHEEL_NAME} wheels in {wheel_dir} ({', '.join(p.name for p in found)}): remove the stale ones")
    wheel = found[0]
    wheel_version = wheel.name.split("-")[1]
    if wheel_version != version:
        raise BuildError(f"{wheel.name}: version {wheel_version} differs from the manifest's {version}")
    return wheel


def find_extra_wheels(extra_dir: "Path | None", native: Path) -> list[Path]:
    """Wheels of the Python packages the add-on imports that Blender does not ship (OpenEXR, for
    the compositing tools), downloaded by `make dist` into ``extra_dir``; only those for a Python
    the native wheel loads in (its own; with the stable ABI, ``abi3``, every CPython from its
    own on: Blender 4.2-5.0 bundle 3.11, 5.1+ 3.13) and its platform are taken. Blender installs,
    of the wheels a manifest lists, those for its own Python."""
    if extra_dir is None or not extra_dir.is_dir():
        return []
    platforms = set(blender_platforms(native.name))
    out = []
    for w in sorted(extra_dir.glob("*.whl")):
        wpy, _wabi, wplat = wheel_tags(w.name)
        if pythons_overlap(native.name, wpy) and (wplat == "any" or set(blender_platforms(w.name)) & platforms):
            out.append(w)
    return out


def pythons_overlap(native_name: str, python_tag: str) -> bool:
    """Whether a wheel for ``python_tag`` can load beside the native wheel. A stable-ABI (abi3) native
    wheel tagged cp311 loads in every CPython from 3.11 on, so the extra wheels of each of those versions
    go into the zip (Blender installs the one for its own Python); a version-specific native wheel takes
    only its own version's."""
    py, abi, _plat = wheel_tags(native_name)
    tags = python_tag.split(".")
    if any(t in ("py3", py) for t in tags):
        return True
    if abi != "abi3" or not py.startswith("cp3"):
        return False
    floor = int(py[3:])
    return any(t.startswith("cp3") and t[3:].isdigit() and int(t[3:]) >= floor for t in tags)


def manifest_text(source: str, wheel_name: "str | list[str]", platforms: list[str]) -> str:
    """The source manifest with ``wheels`` and ``platforms`` set (top-level keys, so they go before
    the first table); any existing or commented-out wheels/platforms lines are dropped."""
    lines = [ln for ln in source.splitlines() if not re.match(r"^\s*#?\s*(wheels|platforms)\s*=", ln)]
    first_table = next((i for i, ln in enumerate(lines) if re.match(r"^\s*\[", ln)), len(lines))
    while first_table > 0 and lines[first_table - 1].strip() == "":
        first_table -= 1
    added = [
        "",
        "# Generated by tools/build_extension.py from the wheel that `make native` built.",
        f"platforms = {json.dumps(platforms)}",
        f"wheels = {json.dumps(['./wheels/' + n for n in ([wheel_name] if isinstance(wheel_name, str) else wheel_name)])}",
    ]
    text = "\n".join(lines[:first_table] + added + lines[first_table:]) + "\n"
    tomllib.loads(text)  # refuse to write a manifest that does not parse
    return text


def package_files(addon: Path):
    for dirpath, dirnames, filenames in os.walk(addon):
        dirnames[:] = sorted(d for d in dirnames if d not in EXCLUDED_DIRS and not d.startswith("."))
        for name in sorted(filenames):
            if name.endswith(EXCLUDED_SUFFIXES) or name.startswith("."):
                continue
            path = Path(dirpath) / name
            yield path, path.relative_to(addon).as_posix()


def _entry(name: str) -> zipfile.ZipInfo:
    info = zipfile.ZipInfo(name, FIXED_TIME)
    info.compress_type = zipfile.ZIP_DEFLATED
    info.external_attr = 0o644 << 16
    return info


def build(addon: Path, wheel_dir: Path, out_dir: Path, shaders: "Path | None" = None, extra_wheels: "Path | None" = None) -> Path:
    """Build (or leave in place, when identical) ``out_dir/rokeby-<version>.zip``; returns its path."""
    source = (addon / "blender_manifest.toml").read_text()
    meta = tomllib.loads(source)
    for key in ("schema_version", "id", "version", "name", "type", "blender_version_min", "license", "maintainer", "tagline"):
        if key not in meta:
            raise BuildError(f"{addon / 'blender_manifest.toml'}: missing '{key}'")
    wheel = find_wheel(wheel_dir, meta["version"])
    extra = find_extra_wheels(extra_wheels, wheel)
    manifest = manifest_text(source, [wheel.name, *(w.name for w in extra)], blender_platforms(wheel.name))

    buf = io.BytesIO()
    with zipfile.ZipFile(buf, "w") as zf:
        for path, name in package_files(addon):
            data = manifest.encode() if name == "blender_manifest.toml" else path.read_bytes()
            zf.writestr(_entry(name), data)
        if shaders is not None and shaders.is_dir():
            # The GLSL of the viewport preview: rokeby.glsl looks for shaders/ next to the package.
            for path, name in package_files(shaders):
                zf.writestr(_entry(f"shaders/{name}"), path.read_bytes())
        for w in (wheel, *extra):
            zf.writestr(_entry(f"wheels/{w.name}"), w.read_bytes())
    data = buf.getvalue()

    out_dir.mkdir(parents=True, exist_ok=True)
    target = out_dir / f"{meta['id']}-{meta['version']}.zip"
    if target.exists() and target.read_bytes() == data:
        return target
    tmp = target.with_suffix(".zip.tmp")
    tmp.write_bytes(data)
    tmp.replace(target)
    return target


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--addon", type=Path, default=ROOT / "addon" / "rokeby")
    ap.add_argument("--wheels", type=Path, default=ROOT / "target" / "wheels")
    ap.add_argument("--out", type=Path, default=ROOT / "dist")
    ap.add_argument("--shaders", type=Path, default=ROOT / "shaders", help="GLSL folder packed as shaders/ (if it exists)")
    ap.add_argument("--extra-wheels", type=Path, default=None,
                    help="folder of wheels of packages Blender lacks (OpenEXR), bundled when they fit the native wheel")
    args = ap.parse_args(argv)
    try:
        path = build(args.addon, args.wheels, args.out, args.shaders, args.extra_wheels)
    except BuildError as exc:
        print(f"build_extension: {exc}", file=sys.stderr)
        return 1
    with zipfile.ZipFile(path) as zf:
        names = zf.namelist()
    wheels = [n for n in names if n.startswith("wheels/")]
    print(f"{path.relative_to(ROOT) if path.is_relative_to(ROOT) else path}: {len(names) - len(wheels)} add-on files + {', '.join(wheels)} ({path.stat().st_size / 1e6:.1f} MB)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
