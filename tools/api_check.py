"""Static check of the add-on against the newest Blender Python API (`make lint`).

basedpyright (a standard type checker) reads addon/rokeby with the stubs of the newest Blender release
(fake-bpy-module-latest, pinned in requirements-lint.txt). A full type check of Blender code is mostly noise
(`Object.data` is a union of fourteen types, nodes are typed as the base `Node`, the add-on's own registered
properties are unknown to the stubs), so this script keeps the diagnostics that mean "this API is not in the
newest Blender", and fails on any of them:

- an attribute that no class of the stubs has at all (`bpy.types`, `gpu`, `mathutils`, ...), other than the
  add-on's own registered properties (names starting with "rokeby");
- a string that is not among an enum's items where the stubs type the parameter or property as a Literal
  (an engine id, an image format, a builtin shader that was renamed or removed);
- an import of a Blender module or name that does not exist.

Reach: the checker sees Blender API use where it can infer the type (values reached from `bpy.data`,
`bpy.types` classes, annotated parameters); `bpy.context.<member>` is untyped in the stubs, and in an unannotated
function taking `scene`, `scene.node_tree` is invisible to it. Dynamic enums (render engine ids, builtin shader names) are typed `str` in the stubs. Both are
covered at run time by the Blender test matrix (`make test-blender`), which is the real guard.

Code that must name an older release's API on purpose lives in the compatibility module
(addon/rokeby/blender/compat.py); its diagnostics are listed for information and do not fail the check.

    python tools/api_check.py [--json OUT]
"""

from __future__ import annotations

import argparse
import json
import re
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
TARGET = ROOT / "addon" / "rokeby"
ON_PURPOSE = {"compat.py"}
# Properties that add-ons bundled with Blender register at start-up (Cycles' settings): real in every
# Blender the add-on runs in, absent from the stubs of the core API.
BUNDLED_ADDON_PROPERTIES = {"cycles", "cycles_curves", "cycles_visibility"}
BLENDER_MODULES = ("bpy", "bmesh", "gpu", "gpu_extras", "mathutils", "bpy_extras", "blf", "bl_math", "idprop", "aud", "imbuf")


class Stubs:
    """What the newest Blender's API stubs name: each class with its bases and own attributes, and every
    quoted string (enum items)."""

    def __init__(self, site: Path):
        self.own: dict[str, set[str]] = {}
        self.bases: dict[str, list[str]] = {}
        self.strings: set[str] = set()
        head = re.compile(r"^class\s+([A-Za-z_][A-Za-z0-9_]*)\s*(?:\(([^)]*)\))?\s*:", re.M)
        attr = re.compile(r"^    (?:def\s+)?([A-Za-z_][A-Za-z0-9_]*)\s*[:(=]", re.M)
        quoted = re.compile(r"[\"']([A-Za-z0-9_]+)[\"']")
        for mod in BLENDER_MODULES + ("_bpy_types", "bl_ui", "bpy_types"):
            folder = site / f"{mod}-stubs"
            for p in folder.rglob("*.pyi") if folder.is_dir() else ():
                text = p.read_text(encoding="utf-8", errors="replace")
                self.strings.update(quoted.findall(text))
                heads = list(head.finditer(text))
                for i, m in enumerate(heads):
                    body = text[m.end(): heads[i + 1].start() if i + 1 < len(heads) else len(text)]
                    name = m.group(1)
                    self.own.setdefault(name, set()).update(attr.findall(body))
                    bases = [b.strip().split("[")[0].split(".")[-1] for b in (m.group(2) or "").split(",") if b.strip()]
                    self.bases.setdefault(name, []).extend(bases)
        self.children: dict[str, set[str]] = {}
        for name, bases in self.bases.items():
            for b in bases:
                self.children.setdefault(b, set()).add(name)
        self.strings.update(self.own)

    def has(self, cls: str, name: str) -> bool:
        """``name`` on ``cls``, a base of it, or a subclass (code typed by a base class, a node typed as
        ``Node``, reaches a subclass's attribute)."""
        return self._reaches(cls, name, self.bases) or self._reaches(cls, name, self.children)

    def _reaches(self, cls: str, name: str, step: dict) -> bool:
        """Whether a class reached from ``cls`` through ``step`` (bases or children) defines ``name``."""
        seen, todo = set(), [cls]
        while todo:
            c = todo.pop()
            if c in seen:
                continue
            seen.add(c)
            if name in self.own.get(c, ()):
                return True
            todo.extend(step.get(c, ()))
        return False


def run_checker(python: str) -> dict:
    cfg = {"include": [str(TARGET)], "pythonVersion": "3.11", "typeCheckingMode": "basic"}
    cfg_path = ROOT / "target" / "api_check.pyrightconfig.json"
    cfg_path.parent.mkdir(exist_ok=True)
    cfg_path.write_text(json.dumps(cfg))
    exe = Path(python).parent / "basedpyright"
    run = subprocess.run([str(exe), "--project", str(cfg_path), "--pythonpath", python, "--outputjson"],
                         capture_output=True, text=True, cwd=ROOT)
    if not run.stdout.strip().startswith("{"):
        sys.exit(f"api_check: basedpyright did not run: {run.stderr.strip()[:500]}")
    return json.loads(run.stdout)


def classify(diag: dict, stubs: Stubs, union_sites: set) -> str | None:
    rule, msg = diag.get("rule", ""), " ".join(diag["message"].split())
    if rule in ("reportArgumentType", "reportAssignmentType", "reportCallIssue", "reportAttributeAccessIssue"):
        # The value given (the first Literal of the message), when the stubs type the target as a Literal
        # and the value is not an item of any enum (nor a class name) the newest Blender has.
        m = re.search(r'(?i:type) "Literal\[\'([A-Za-z0-9_]+)\'\]" (?:cannot be assigned|is not assignable)', msg)
        if m:
            return f"enum item not in the newest Blender API: '{m.group(1)}'" if m.group(1) not in stubs.strings else None
    if rule == "reportAttributeAccessIssue":
        m = re.search(r'attribute "([^"]+)" for class "(?:type\[)?([^"\]]+)\]?"', msg)
        if m and m.group(2) in stubs.own and not m.group(1).startswith("rokeby") \
                and m.group(1) not in BUNDLED_ADDON_PROPERTIES and site_of(diag) not in union_sites \
                and not stubs.has(m.group(2), m.group(1)):
            return f"not in the newest Blender API: {m.group(2)}.{m.group(1)}"
    if rule in ("reportMissingImports", "reportAttributeAccessIssue") and re.search(r'"(%s)[.\w]*"' % "|".join(BLENDER_MODULES), msg):
        return f"Blender module or name missing: {msg}"
    return None


def site_of(diag: dict) -> tuple:
    return diag["file"], diag["range"]["start"]["line"], diag["range"]["start"]["character"]


def union_sites(diags: list) -> set:
    """Places where one attribute is reported for several classes: an expression typed as a union
    (``Object.data`` is any of fourteen ID types) that the code narrows at run time; not a missing API."""
    count: dict = {}
    for d in diags:
        if d.get("rule") == "reportAttributeAccessIssue":
            count[site_of(d)] = count.get(site_of(d), 0) + 1
    return {k for k, n in count.items() if n > 1}


def main() -> int:
    ap = argparse.ArgumentParser()
    ap.add_argument("--json")
    a = ap.parse_args()
    python = sys.executable
    site = Path(subprocess.run([python, "-c", "import sysconfig; print(sysconfig.get_paths()['purelib'])"],
                               capture_output=True, text=True, check=True).stdout.strip())
    stubs = Stubs(site)
    if len(stubs.own) < 1000:
        sys.exit(f"api_check: the Blender API stubs were not found under {site} (pip install -r requirements-lint.txt)")
    data = run_checker(python)
    found, info = [], []
    unions = union_sites(data["generalDiagnostics"])
    for d in data["generalDiagnostics"]:
        why = classify(d, stubs, unions)
        if why is None:
            continue
        where = f"{Path(d['file']).relative_to(ROOT)}:{d['range']['start']['line'] + 1}"
        (info if Path(d["file"]).name in ON_PURPOSE else found).append(f"{where}: {why}")
    for line in sorted(set(info)):
        print(f"(compat, on purpose) {line}")
    for line in sorted(set(found)):
        print(line)
    print(f"api_check: {len(set(found))} use(s) of API missing from the newest Blender "
          f"({data['summary']['filesAnalyzed']} files, {len(stubs.own)} API classes known)")
    if a.json:
        Path(a.json).write_text(json.dumps({"found": sorted(set(found)), "compat": sorted(set(info))}, indent=1))
    return 1 if found else 0


if __name__ == "__main__":
    sys.exit(main())
