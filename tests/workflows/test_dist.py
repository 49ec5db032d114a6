"""The installable extension zip (`make dist`): what a user installing it in Blender would hit."""

import json
import os
import subprocess
import sys
import textwrap
import tomllib
import zipfile
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]

import build_extension as be  # noqa: E402

WHEELS = ROOT / "target" / "wheels"


def _wheel_or_skip():
    if not list(WHEELS.glob("rokeby_native-*.whl")):
        pytest.skip("no rokeby_native wheel in target/wheels (make native builds it)")


@pytest.fixture(scope="module")
def built(tmp_path_factory):
    _wheel_or_skip()
    out = tmp_path_factory.mktemp("dist")
    path = be.build(ROOT / "addon" / "rokeby", WHEELS, out, ROOT / "shaders")
    return path


def test_zip_layout_and_manifest(built):
    source = tomllib.loads((ROOT / "addon" / "rokeby" / "blender_manifest.toml").read_text())
    assert built.name == f"rokeby-{source['version']}.zip"
    with zipfile.ZipFile(built) as zf:
        assert zf.testzip() is None
        names = zf.namelist()
        manifest = tomllib.loads(zf.read("blender_manifest.toml").decode())
        init = zf.read("__init__.py").decode()
    # The add-on package at the root, nothing from development.
    assert "__init__.py" in names and "def register" in init
    assert all(not n.startswith(("rokeby/", "addon/")) for n in names)
    assert not [n for n in names if "__pycache__" in n or n.endswith((".pyc", ".pyo")) or n.split("/")[0] in ("tests", ".pytest_cache")]
    # Every subpackage of the layered add-on (docs/architecture.md) travels, with its modules.
    for name in ("api/__init__.py", "reflection/api.py", "compositing/api.py", "shadow/api.py", "farm/api.py", "core/__init__.py", "core/schema.py", "core/native.py", "blender/compat.py", "blender/hooks.py",
                 "reflection/evaluate.py", "reflection/render/shading.py", "reflection/viewport/glsl.py", "reflection/operators.py",
                 "reflection/props.py", "reflection/ui.py", "reflection/handlers.py", "envmaps/__init__.py", "appearance/ui.py",
                 "shadow/__init__.py", "compositing/blender_gpu.py"):
        assert name in names, name
    source_modules = sorted(p.relative_to(ROOT / "addon" / "rokeby").as_posix() for p in (ROOT / "addon" / "rokeby").rglob("*.py")
                            if "__pycache__" not in p.parts)
    assert [m for m in source_modules if m not in names] == []
    for key in ("schema_version", "id", "version", "name", "tagline", "maintainer", "type", "blender_version_min", "license"):
        assert manifest[key] == source[key], key
    assert manifest["type"] == "add-on" and manifest["id"] == "rokeby"
    # Every listed wheel is in the zip, and the zip holds no wheel that is not listed.
    listed = [w.removeprefix("./") for w in manifest["wheels"]]
    assert listed and all(w.startswith("wheels/") for w in listed)
    assert sorted(listed) == sorted(n for n in names if n.startswith("wheels/"))
    assert manifest["platforms"] == ["linux-x64"] or sys.platform != "linux"


def test_the_zip_carries_only_the_native_wheel_which_installs_on_this_python(built):
    """One zip for every supported Blender: the native wheel is built for the stable ABI (abi3, CPython 3.11
    and later: Blender 4.2-5.0 embed 3.11, Blender 5.1 and later 3.13) and loads on this Python. It is the
    only wheel: EXRs are read and written by it (the pure-Rust `exr` crate), and no OpenEXR wheel comes
    along, whose own OpenEXR C library would collide with the one a Blender build links (Debian's
    Blender died with SIGBUS on the first EXR read)."""
    from packaging.tags import sys_tags
    from packaging.utils import parse_wheel_filename

    here = set(sys_tags())
    with zipfile.ZipFile(built) as zf:
        manifest = tomllib.loads(zf.read("blender_manifest.toml").decode())
        names = zf.namelist()
        (entry,) = manifest["wheels"]
        name = entry.removeprefix("./")
        dist, version, _build, tags = parse_wheel_filename(Path(name).name)
        assert dist == "rokeby-native" and str(version) == manifest["version"], name
        assert {(t.interpreter, t.abi) for t in tags} == {("cp311", "abi3")}, name
        assert tags & here, f"the native wheel does not install on this Python ({sys.version_info[:2]}, {sys.platform}): {name}"
        with zipfile.ZipFile(zf.open(name)) as whl:  # a real wheel with the extension module
            assert any(n.startswith("rokeby_native/") and n.endswith(".so") for n in whl.namelist()) or sys.platform != "linux"
        assert [n for n in names if n.startswith("wheels/")] == [name]
        assert not [n for n in names if "openexr" in n.lower() and not n.endswith(".py")], names


def test_blender_validates_the_zip(built):
    """Blender's own extension validator (blender_ext.py from bpy's bl_pkg) accepts the zip."""
    bpy = pytest.importorskip("bpy")
    cli = Path(bpy.utils.system_resource("SCRIPTS")) / "addons_core" / "bl_pkg" / "cli" / "blender_ext.py"
    if not cli.exists():
        pytest.skip(f"{cli} not found")
    run = subprocess.run([sys.executable, str(cli), "validate", str(built)], capture_output=True, text=True, timeout=120)
    assert run.returncode == 0, run.stdout + run.stderr


def test_build_is_idempotent_and_refuses_bad_input(built, tmp_path):
    before = built.read_bytes()
    assert be.build(ROOT / "addon" / "rokeby", WHEELS, built.parent, ROOT / "shaders") == built
    assert built.read_bytes() == before
    # A second, stale wheel is an error, not a silent pick.
    stale = tmp_path / "wheels"
    stale.mkdir()
    wheel = next(WHEELS.glob("rokeby_native-*.whl"))
    (stale / wheel.name).write_bytes(wheel.read_bytes())
    name, version, *tags = wheel.name.split("-")
    (stale / "-".join([name, version + ".post1", *tags])).write_bytes(b"")
    with pytest.raises(be.BuildError, match="several"):
        be.build(ROOT / "addon" / "rokeby", stale, tmp_path / "out")
    with pytest.raises(be.BuildError, match="no rokeby_native wheel"):
        be.build(ROOT / "addon" / "rokeby", tmp_path / "empty", tmp_path / "out")


def test_manifest_text_keeps_tables_and_parses():
    src = 'id = "x"\n# wheels = ["./wheels/old.whl"]\n\n[permissions]\nfiles = "y"\n'
    text = be.manifest_text(src, "a-1.0-cp311-cp311-manylinux_2_34_x86_64.whl", ["linux-x64"])
    data = tomllib.loads(text)
    assert data["wheels"] == ["./wheels/a-1.0-cp311-cp311-manylinux_2_34_x86_64.whl"]
    assert data["platforms"] == ["linux-x64"] and data["permissions"] == {"files": "y"}
    assert "old.whl" not in text
    assert be.blender_platforms("a-1.0-cp311-cp311-win_amd64.whl") == ["windows-x64"]
    with pytest.raises(be.BuildError):
        be.blender_platforms("a-1.0-cp311-cp311-any.whl")


INSTALL = textwrap.dedent(
    """
    import importlib.machinery, json, os, sys
    SITE = os.path.join(os.environ["BLENDER_USER_RESOURCES"], "extensions", ".local", "lib",
                        "python%d.%d" % sys.version_info[:2], "site-packages")

    class OnlyTheExtensionsWheel:
        # rokeby_native may be importable from this venv: allow it only from the wheel that
        # Blender extracted for the extension, so the test fails if the zip's wheel is unusable.
        def find_spec(self, name, path=None, target=None):
            if name == "rokeby_native":
                spec = importlib.machinery.PathFinder.find_spec(name, [SITE])
                if spec is None:
                    raise ImportError("rokeby_native not installed from the extension's wheel")
                return spec
            return None

    sys.meta_path.insert(0, OnlyTheExtensionsWheel())
    import bpy
    prefs = bpy.context.preferences
    repo = prefs.extensions.repos.new(name="Throwaway", module="throwaway",
                                      custom_directory=os.environ["ROKEBY_TEST_REPO"], source="USER")
    result = bpy.ops.extensions.package_install_files(filepath=os.environ["ROKEBY_TEST_ZIP"],
                                                      repo="throwaway", enable_on_install=True)
    mod = sys.modules.get("bl_ext.throwaway.rokeby")
    out = {"result": sorted(result), "enabled": "bl_ext.throwaway.rokeby" in prefs.addons.keys(),
           "file": getattr(mod, "__file__", None), "registered": bool(mod and mod.is_registered())}
    if mod is not None:
        import importlib
        api = importlib.import_module("bl_ext.throwaway.rokeby.api")
        native = importlib.import_module("bl_ext.throwaway.rokeby.core.native")
        out["native_file"] = native.module().__file__ if native.available() else None
        bpy.ops.mesh.primitive_plane_add(size=2.0)
        plane = bpy.context.object
        api.add_mirror(plane)
        api.add_constraint(plane, (0.0, 0.0, 0.0), (0.5, 0.0, 2.0), eye=(0.0, -1.0, 2.0))
        rep = api.evaluate()[plane.name]
        out["status"] = rep.status
        out["operators"] = hasattr(bpy.ops.rokeby, "render_nodes")
        mod.unregister()
    print("RESULT " + json.dumps(out))
    """
)


def test_installs_and_registers_in_a_throwaway_blender_user_repo(built, tmp_path):
    pytest.importorskip("bpy")
    env = dict(os.environ)
    env["BLENDER_USER_RESOURCES"] = str(tmp_path / "user")
    env["ROKEBY_TEST_REPO"] = str(tmp_path / "repo")
    env["ROKEBY_TEST_ZIP"] = str(built)
    run = subprocess.run([sys.executable, "-c", INSTALL], env=env, capture_output=True, text=True, timeout=300, cwd=tmp_path)
    line = next((ln for ln in run.stdout.splitlines() if ln.startswith("RESULT ")), None)
    assert run.returncode == 0 and line, run.stdout[-3000:] + run.stderr[-3000:]
    out = json.loads(line[len("RESULT "):])
    assert out["result"] == ["FINISHED"]
    assert out["enabled"] and out["registered"]
    assert Path(out["file"]).is_relative_to(tmp_path / "repo"), out["file"]  # the zip's copy, not the checkout's
    assert (tmp_path / "repo" / "rokeby" / "shaders").is_dir()
    assert out["native_file"] and Path(out["native_file"]).is_relative_to(tmp_path / "user"), out["native_file"]  # from the zip's wheel
    assert out["status"] in ("OK", "WARNING") and out["operators"]  # evaluated with the zip's wheel
