import ast
import importlib
import inspect
import re
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest
from hypothesis import settings

from support import mesh_path

# Seeded and bounded: the same examples on every run, no database written into the checkout.
settings.register_profile("rokeby", derandomize=True, database=None, deadline=None, max_examples=200)
settings.load_profile("rokeby")


@pytest.fixture(scope="session")
def spot():
    from rokeby.core.meshio import load_obj, vertex_normals

    v, f = load_obj(mesh_path("spot.obj"))
    return v, f, vertex_normals(v, f)


@pytest.fixture
def rng():
    return np.random.default_rng(20091001)


# --- markers ---------------------------------------------------------------------------------------
# blender / cycles / eevee / gl are put on each test from what it runs: the source of the test, of
# its fixtures and of every function or class of tests/ they reach (support helpers, a module's own
# helpers), with docstrings and comments left out, plus the *_check.py script a test runs in a
# fresh bpy process. A parametrised render engine ("CYCLES", "EEVEE...") decides for its own case.
# `slow` is put by hand (@pytest.mark.slow, measured) where a test takes more than about 20 s.
# See docs/development.md, "Running the tests".

TESTS = Path(__file__).resolve().parent
_ENGINE_CYCLES = "CYCLES"
_MARK_PATTERNS = {
    "blender": re.compile(r"\bbpy\b"),
    "cycles": re.compile(r"'CYCLES'|(?<![\w.])cycles\("),
    "eevee": re.compile(r"eevee_engine\(|'BLENDER_EEVEE|gpu_context\("),
    "gl": re.compile(r"\bmoderngl\b|\bgpu\b|gpu_context\(|offscreen_pixels\(|GLRecompositor|sphere_shader\(|gl_harness|create_context\("),
}
_CHECK_SCRIPT = re.compile(r"'([\w/]*_check\.py)'")
_SPLIT = "\n#--- strings emptied ---\n"
_CODE_ONLY = {"blender", "gl"}  # read in the string-free half of each text
_MODERNGL_BACKEND = re.compile(r"'moderngl'")
_IMPORTORSKIP_BPY = re.compile(r"importorskip\('bpy'\)")
_BPY_AT_MODULE_LEVEL = re.compile(r"importorskip\('bpy'\)|^import bpy$|^from bpy\b", re.M)


_STRING = re.compile(r"[rbuf]*'(?:[^'\\\n]|\\.)*'|[rbuf]*\"(?:[^\"\\\n]|\\.)*\"")  # string literals


def _parse(source: str):
    """The syntax tree of ``source`` with docstrings dropped; None when it does not parse."""
    try:
        tree = ast.parse(textwrap.dedent(source))
    except SyntaxError:
        return None
    for node in ast.walk(tree):
        body = getattr(node, "body", None)
        if isinstance(body, list) and body and isinstance(body[0], ast.Expr) \
                and isinstance(body[0].value, ast.Constant) and isinstance(body[0].value.value, str):
            body[0] = ast.Pass()
    return tree


def _code_text(source, tree=None) -> str:
    """``source`` without docstrings and comments (ast round trip), then the same code once more
    with every string emptied (what the ``blender`` and ``gl`` patterns read: a string that only
    mentions bpy or gpu is not a use); '' when it does not parse."""
    tree = tree if tree is not None else _parse(source)
    if tree is None:
        return ""
    with_strings = ast.unparse(tree)
    return with_strings + _SPLIT + _STRING.sub("''", with_strings)


def _in_tests(obj) -> bool:
    try:
        return Path(inspect.getsourcefile(obj)).resolve().is_relative_to(TESTS)
    except (TypeError, OSError):
        return False


_OBJ_CACHE: dict = {}
_MODULE_BPY: dict = {}


def _text_and_refs(obj):
    """The code text of ``obj`` and the functions and classes of tests/ it names (cached)."""
    key = id(obj)
    if key in _OBJ_CACHE:
        return _OBJ_CACHE[key][1:]
    text, refs, tree = "", [], None
    if _in_tests(obj):
        try:
            tree = _parse(inspect.getsource(obj))
        except (OSError, TypeError):
            tree = None
        text = _code_text(None, tree) if tree is not None else ""
    if text:
        scope = dict(getattr(obj, "__globals__", None) or vars(sys.modules.get(obj.__module__, object)))
        for node in ast.walk(tree):  # names a function body imports from support
            if isinstance(node, ast.ImportFrom) and node.module and node.module.split(".")[0] == "support":
                try:
                    mod = importlib.import_module(node.module)
                except BaseException:  # noqa: BLE001 - a skip (no bpy) or an error: nothing to follow
                    continue
                for a in node.names:
                    scope[a.asname or a.name] = getattr(mod, a.name, None) or sys.modules.get(f"{node.module}.{a.name}")
        for node in ast.walk(tree):
            target = None
            if isinstance(node, ast.Name):
                target = scope.get(node.id)
            elif isinstance(node, ast.Attribute):  # module.name, package.module.name
                chain = [node.attr]
                base = node.value
                while isinstance(base, ast.Attribute):
                    chain.append(base.attr)
                    base = base.value
                target = scope.get(base.id) if isinstance(base, ast.Name) else None
                for attr in reversed(chain):
                    target = getattr(target, attr, None) if inspect.ismodule(target) else None
            if (inspect.isfunction(target) or inspect.isclass(target)) and target is not obj:
                refs.append(target)
    _OBJ_CACHE[key] = (obj, text, refs)  # obj kept alive so that its id is not reused
    return text, refs


def _text_marks(text: str, here: Path) -> set:
    """The marks one code text (from _code_text) asks for, with the *_check.py scripts it runs
    (found below tests/ or next to ``here``)."""
    with_strings, _, code_only = text.partition(_SPLIT)
    marks = {name for name, pattern in _MARK_PATTERNS.items()
             if pattern.search(code_only if name in _CODE_ONLY else with_strings)}
    if _IMPORTORSKIP_BPY.search(with_strings):
        marks.add("blender")
    if _MODERNGL_BACKEND.search(with_strings):  # backend="moderngl", --backend moderngl
        marks.add("gl")
    for script in set(_CHECK_SCRIPT.findall(with_strings)):
        for base in (TESTS, here):
            if (base / script).is_file():
                marks |= _text_marks(_code_text((base / script).read_text()), base)
                break
    return marks


_MARKS: dict = {}


def _reached_marks(obj) -> set:
    """The marks of ``obj`` and of every function or class of tests/ it reaches (memoised; a cycle
    of helpers is cut where it closes)."""
    key = id(obj)
    if key in _MARKS:
        return _MARKS[key][1]
    marks: set = set()
    _MARKS[key] = (obj, marks)  # in progress: a cycle sees what is known so far
    text, refs = _text_and_refs(obj)
    if text:
        marks |= _text_marks(text, Path(inspect.getsourcefile(obj)).parent)
    for ref in refs:
        marks |= _reached_marks(ref)
    return marks


def _bpy_at_module_level(path) -> bool:
    if path not in _MODULE_BPY:
        module_level = [n for n in ast.parse(Path(path).read_text()).body
                        if not isinstance(n, (ast.FunctionDef, ast.ClassDef, ast.AsyncFunctionDef))]
        _MODULE_BPY[path] = bool(_BPY_AT_MODULE_LEVEL.search("\n".join(ast.unparse(n) for n in module_level)))
    return _MODULE_BPY[path]


def _auto_marks(item) -> set:
    fixtures = [fd.func for defs in item._fixtureinfo.name2fixturedefs.values() for fd in defs]
    marks = set()
    for root in (item.function, *fixtures):
        marks |= _reached_marks(inspect.unwrap(root))
    if _bpy_at_module_level(item.path):
        marks.add("blender")
    engines = {v for v in getattr(getattr(item, "callspec", None), "params", {}).values()
               if isinstance(v, str) and (v == _ENGINE_CYCLES or v.startswith("EEVEE") or v.startswith("BLENDER_EEVEE"))}
    if engines:  # a parametrised engine decides for its own case
        marks.discard("cycles")
        marks.discard("eevee")
        marks |= {"cycles" if e == _ENGINE_CYCLES else "eevee" for e in engines}
    if marks & {"cycles", "eevee"}:
        marks.add("blender")
    return marks


def pytest_collection_modifyitems(config, items):
    cache = {}
    for item in items:
        if not isinstance(item, pytest.Function):
            continue
        key = (item.path, item.originalname, tuple(sorted(getattr(getattr(item, "callspec", None), "params", {}).items(), key=str)))
        try:
            marks = cache.setdefault(str(key), _auto_marks(item))
        except Exception:  # noqa: BLE001 - a test this cannot read keeps its hand-written marks
            continue
        for name in sorted(marks):
            item.add_marker(name)


# --- the window leg ----------------------------------------------------------------------------------
# tests/gui/ runs real Blender windows (make test-gui, inside tools/guiroot): `pytest` without
# arguments (make test, the Blender matrix) never collects it; naming it (`pytest tests/gui`) does.
_GUI = TESTS / "gui"


def pytest_ignore_collect(collection_path, config):
    path = Path(collection_path).resolve()
    if path != _GUI and _GUI not in path.parents:
        return None
    for arg in config.args:
        named = Path(str(arg).split("::")[0]).resolve()
        if named == _GUI or _GUI in named.parents:
            return None
    return True
