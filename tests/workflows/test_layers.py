"""The add-on's layers point one way (docs/architecture.md), checked on its source with ``ast``.

    core (bpy-free)  ←  blender (feature-agnostic Blender layer)  ←  features  ←  facade (api, scripts)

Every import is read, function-level ones included (a lazy import is still a dependency), and
resolved to the module it names. The check fails on

- an import cycle between modules;
- an upward import (core importing blender, a feature or the facade; blender importing a
  feature or the facade; a feature importing the facade);
- a feature importing another feature's internals (only the other feature's package, its
  public entry points, may be imported) — and a cycle between features;
- ``rokeby_native`` imported anywhere but ``rokeby/core/native.py``;
- a module of the package that belongs to no layer, or an import of a path that is no module of
  the package (such as ``rokeby.evaluate``: each module has one path, ``rokeby.reflection.evaluate``);
- a name that is saved in .blend files or EXRs (``rokeby.core.schema``) spelled as a literal
  anywhere but the schema module.

``test_the_check_fails_on_*`` run the same check on small synthetic import graphs, so a check
that stopped finding violations would fail too.
"""

from __future__ import annotations

import ast
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
PKG = ROOT / "addon" / "rokeby"
PACKAGE = "rokeby"

FEATURES = ("reflection", "envmaps", "appearance", "shadow", "compositing", "farm")
FACADE = ("api", "composite", "demo", "demo_scene")  # and the package's __init__
RANK = {"core": 0, "blender": 1, "feature": 2, "facade": 3}
NATIVE_HOME = f"{PACKAGE}.core.native"

# Edges that break the rules today, each with the reason it is not yet fixed. The test requires
# the found violations to be exactly these: a new violation fails, and so does a fixed one that is
# still listed (remove it from here).
KNOWN: dict[str, str] = {}


def _modules(root: Path, package: str) -> dict[str, tuple[Path, bool]]:
    out = {}
    for path in sorted(root.rglob("*.py")):
        if "__pycache__" in path.parts:
            continue
        parts = list(path.relative_to(root).with_suffix("").parts)
        is_pkg = parts[-1] == "__init__"
        if is_pkg:
            parts = parts[:-1]
        out[".".join([package, *parts])] = (path, is_pkg)
    return out


def import_graph(root: Path = PKG, package: str = PACKAGE) -> dict[str, dict[str, int]]:
    """module -> {imported module: first line}; targets outside the package are kept only for
    ``rokeby_native``; an import of a path that is no module of the package is kept as is (and
    reported by :func:`violations`)."""
    mods = _modules(root, package)
    graph: dict[str, dict[str, int]] = {m: {} for m in mods}
    for mod, (path, is_pkg) in mods.items():
        here = mod.split(".") if is_pkg else mod.split(".")[:-1]
        for node in ast.walk(ast.parse(path.read_text(), str(path))):
            targets = []
            if isinstance(node, ast.ImportFrom):
                if node.level:
                    base = here[: len(here) - (node.level - 1)]
                    target = ".".join(base + ([node.module] if node.module else []))
                else:
                    target = node.module or ""
                if target != package and not target.startswith(package + ".") and target != "rokeby_native":
                    continue
                subs = [f"{target}.{a.name}" for a in node.names if f"{target}.{a.name}" in mods]
                targets += subs
                if len(subs) < len(node.names):  # names from the module itself (or an unknown path)
                    targets.append(target)
            elif isinstance(node, ast.Import):
                targets += [a.name for a in node.names if a.name == package or a.name.startswith(package + ".") or a.name == "rokeby_native"]
            for t in targets:
                if t != mod:
                    graph[mod].setdefault(t, node.lineno)
    return graph


def layer(mod: str, package: str = PACKAGE) -> "tuple[str, str | None] | None":
    parts = mod.split(".")[1:]
    if not parts:
        return ("facade", None)
    head = parts[0]
    if head in ("core", "blender"):
        return (head, None)
    if head in FEATURES:
        return ("feature", head)
    if head in FACADE and len(parts) == 1:
        return ("facade", None)
    return None


def _cycles(graph: dict[str, dict[str, int]]) -> list[list[str]]:
    index, low, stack, on, out = {}, {}, [], set(), []
    counter = [0]
    sys.setrecursionlimit(max(sys.getrecursionlimit(), 10000))

    def visit(v):
        index[v] = low[v] = counter[0]
        counter[0] += 1
        stack.append(v)
        on.add(v)
        for w in graph.get(v, {}):
            if w not in graph:
                continue
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            scc = []
            while True:
                w = stack.pop()
                on.discard(w)
                scc.append(w)
                if w == v:
                    break
            if len(scc) > 1:
                out.append(sorted(scc))

    for v in sorted(graph):
        if v not in index:
            visit(v)
    return sorted(out)


def violations(graph: dict[str, dict[str, int]], package: str = PACKAGE) -> dict[str, str]:
    """Every broken rule, keyed ``"src -> dst"`` (or ``"cycle: a b c"``), with what it breaks."""
    found = {}
    for src in sorted(graph):
        ls = layer(src, package)
        if ls is None:
            found[f"{src}"] = "module in no layer (core/, blender/, a feature package or the facade)"
            continue
        for dst, line in sorted(graph[src].items()):
            key = f"{src} -> {dst}"
            if dst == "rokeby_native":
                if src != f"{package}.core.native":
                    found[key] = f"line {line}: rokeby_native is imported only in core/native.py"
                continue
            if dst not in graph:
                found[key] = f"line {line}: not a module of the package (an old path? each module has one path)"
                continue
            ld = layer(dst, package)
            if ld is None:
                continue  # reported as a module in no layer
            if RANK[ld[0]] > RANK[ls[0]]:
                found[key] = f"line {line}: upward import ({ls[0]} must not import {ld[0]})"
            elif ls[0] == ld[0] == "feature" and ls[1] != ld[1] and dst != f"{package}.{ld[1]}":
                found[key] = f"line {line}: {ls[1]} imports {ld[1]}'s internals (only {package}.{ld[1]} itself)"
    for scc in _cycles({m: {d: n for d, n in e.items() if d in graph} for m, e in graph.items()}):
        found["cycle: " + " ".join(scc)] = "import cycle (function-level imports included)"
    return found


# --- the add-on ----------------------------------------------------------------------------------


def test_every_module_is_in_a_layer_and_the_graph_is_read():
    graph = import_graph()
    assert f"{PACKAGE}.core.schema" in graph and f"{PACKAGE}.core.native" in graph
    assert "rokeby_native" in graph[NATIVE_HOME]  # the parser sees the one native import
    assert f"{PACKAGE}.blender.compat" in graph[f"{PACKAGE}.reflection.field_carriers"]  # function-level import
    unplaced = [m for m in graph if layer(m) is None]
    assert not unplaced, unplaced


def test_layers_point_one_way():
    found = violations(import_graph())
    new = {k: v for k, v in found.items() if k not in KNOWN}
    fixed = [k for k in KNOWN if k not in found]
    assert not new, "imports against docs/architecture.md's layer map:\n" + "\n".join(f"  {k}: {v}" for k, v in new.items())
    assert not fixed, f"fixed, so remove from KNOWN in tests/test_layers.py: {fixed}"


def test_features_register_themselves_and_never_reach_the_facade():
    graph = import_graph()
    for feature in FEATURES:
        mods = [m for m in graph if m == f"{PACKAGE}.{feature}" or m.startswith(f"{PACKAGE}.{feature}.")]
        assert mods, feature
        for m in mods:
            facade = [d for d in graph[m] if d in graph and layer(d) == ("facade", None)]
            assert not facade or all(f"{m} -> {d}" in KNOWN for d in facade), (m, facade)


def _schema_values() -> dict[str, str]:
    import importlib.util

    spec = importlib.util.spec_from_file_location("_rokeby_schema_for_test", PKG / "core" / "schema.py")
    schema = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(schema)  # bpy-free: the core imports nothing of Blender
    values = {}
    for name, value in vars(schema).items():
        if name.isupper() and isinstance(value, str):
            values[value] = name
        elif name.isupper() and isinstance(value, dict):
            values.update({v: f"{name}[{k!r}]" for k, v in value.items() if isinstance(v, str)})
        elif name.isupper() and isinstance(value, tuple):
            values.update({v: name for v in value if isinstance(v, str)})
    # Names too short or too general to tell a saved name from other text: prefixes that many
    # names share, and registered property names (read as Python attributes: obj.rokeby).
    for general in (schema.NODE_GROUP_PREFIX, schema.APPEARANCE_NODE_PREFIX, schema.OBJECT_PROP):
        values.pop(general, None)
    return values


def saved_name_literals(root: Path = PKG, values: "dict[str, str] | None" = None) -> list[str]:
    values = _schema_values() if values is None else values
    hits = []
    for path in sorted(root.rglob("*.py")):
        if path == root / "core" / "schema.py" or "__pycache__" in path.parts:
            continue
        tree = ast.parse(path.read_text(), str(path))
        docstrings = {id(n.body[0].value) for n in ast.walk(tree)
                      if isinstance(n, (ast.Module, ast.ClassDef, ast.FunctionDef, ast.AsyncFunctionDef))
                      and n.body and isinstance(n.body[0], ast.Expr) and isinstance(n.body[0].value, ast.Constant)}
        # UI text that happens to read like a saved name: a panel's bl_label, a property's name=.
        ui_text = {id(n.value) for n in ast.walk(tree) if isinstance(n, ast.Assign)
                   and any(isinstance(t, ast.Name) and t.id == "bl_label" for t in n.targets)}
        ui_text |= {id(k.value) for n in ast.walk(tree) if isinstance(n, ast.Call) and getattr(n.func, "attr", getattr(n.func, "id", "")).endswith("Property")
                    for k in n.keywords if k.arg in ("name", "description")}
        for node in ast.walk(tree):
            if (isinstance(node, ast.Constant) and isinstance(node.value, str) and id(node) not in docstrings
                    and id(node) not in ui_text and node.value in values):
                hits.append(f"{path.relative_to(root)}:{node.lineno}: {node.value!r} is schema.{values[node.value]}")
    return hits


def test_saved_names_are_spelled_only_in_the_schema():
    hits = saved_name_literals()
    assert not hits, "use rokeby.core.schema's constant:\n" + "\n".join(hits)


def test_core_and_schema_import_without_blender():
    """The core is bpy-free: importing it with ``bpy``, ``gpu`` and ``mathutils`` unavailable works."""
    import subprocess
    import textwrap

    script = textwrap.dedent(f"""
        import sys
        for name in ("bpy", "gpu", "mathutils", "bmesh", "gpu_extras"):
            sys.modules[name] = None  # any import of them raises ImportError
        sys.path.insert(0, {str(PKG.parent)!r})
        import rokeby.core.schema, rokeby.core.vecmath, rokeby.core.latlong, rokeby.core.meshio, rokeby.core.shaders, rokeby.core.words
        print("SCHEMA", rokeby.core.schema.SCHEMA_VERSION)
    """)
    out = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    assert "SCHEMA " in out.stdout


# --- the check itself, on synthetic graphs ---------------------------------------------------------


def _write(tmp_path: Path, files: dict[str, str]) -> Path:
    root = tmp_path / "rokeby"
    for rel, text in {"__init__.py": "", "core/__init__.py": "", "blender/__init__.py": "", **files}.items():
        p = root / rel
        p.parent.mkdir(parents=True, exist_ok=True)
        p.write_text(text)
    return root


def test_the_check_passes_a_clean_layout(tmp_path):
    root = _write(tmp_path, {
        "core/native.py": "import rokeby_native\n",
        "core/vecmath.py": "import numpy\n",
        "blender/compat.py": "from ..core import vecmath\n",
        "envmaps/__init__.py": "from ..core import native\n",
        "appearance/__init__.py": "from .. import envmaps\nfrom ..blender import compat\n",
        "appearance/ui.py": "from .. import appearance\n",
        "api.py": "from .appearance import ui\nfrom . import envmaps\n",
    })
    assert violations(import_graph(root)) == {}


@pytest.mark.parametrize("files, expected", [
    # a cycle through function-level imports
    ({"shadow/__init__.py": "def f():\n    from . import ui\n", "shadow/ui.py": "from .. import shadow\n"},
     "cycle: rokeby.shadow rokeby.shadow.ui"),
    # core importing the Blender layer
    ({"core/vecmath.py": "def f():\n    from ..blender import compat\n", "blender/compat.py": ""},
     "rokeby.core.vecmath -> rokeby.blender.compat"),
    # the Blender layer importing a feature
    ({"blender/transaction.py": "from ..reflection import shading\n", "reflection/__init__.py": "", "reflection/shading.py": ""},
     "rokeby.blender.transaction -> rokeby.reflection.shading"),
    # a feature importing the facade
    ({"shadow/__init__.py": "def f():\n    from .. import api\n", "api.py": ""},
     "rokeby.shadow -> rokeby.api"),
    # a feature importing another feature's internals
    ({"shadow/__init__.py": "from ..reflection import registry\n", "reflection/__init__.py": "", "reflection/registry.py": ""},
     "rokeby.shadow -> rokeby.reflection.registry"),
    # rokeby_native outside core/native.py
    ({"compositing/__init__.py": "import rokeby_native\n"},
     "rokeby.compositing -> rokeby_native"),
    # a path that is no module of the package (an old one)
    ({"shadow/__init__.py": "from rokeby.evaluate import f\n"},
     "rokeby.shadow -> rokeby.evaluate"),
    # a module in no layer
    ({"helpers.py": "x = 1\n"}, "rokeby.helpers"),
])
def test_the_check_fails_on_a_violation(tmp_path, files, expected):
    found = violations(import_graph(_write(tmp_path, files)))
    assert expected in found, found


def test_the_check_fails_on_a_saved_name_literal(tmp_path):
    root = _write(tmp_path, {"shadow/__init__.py": '"""A docstring naming rokeby_light_initial."""\nKEY = "rokeby_light_initial"\n'})
    hits = saved_name_literals(root, {"rokeby_light_initial": "SHADOW_LIGHT_INITIAL_KEY"})
    assert len(hits) == 1 and "shadow/__init__.py:2" in hits[0]
