"""``rokeby.api`` is explicit and documented: it exports exactly the ``__all__`` of each feature's
``api`` module (nothing private, nothing else), and its section of docs/python-api.md describes
every exported name while describing no function that is not exported.

A name counts as documented when it opens a code span of the section's prose (`` `add_mirror(obj,
…)` ``, `` `MirrorReport` ``, `` `api.RokebyError` ``); a code span that opens with a bare call
(`` `subdivide_midpoint(v, f)` ``) names a function of rokeby.api, so it must be exported. Dotted
names of other modules (`` `rokeby.core.meshio.load_obj(path)` ``) are not rokeby.api's.

``test_the_check_*`` run the same checks on small synthetic documents and modules, so a check that
stopped finding problems would fail too.
"""

from __future__ import annotations

import re
import types
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
DOC = ROOT / "docs" / "python-api.md"
SECTION = "## `rokeby.api`"
FENCE = re.compile(r"^[ \t]*(`{3,}|~{3,}).*?^[ \t]*\1[ \t]*$", re.M | re.S)
SPAN = re.compile(r"(?<!`)`([^`]+)`(?!`)")
HEAD = re.compile(r"\s*(?:rokeby\.)?(?:api\.)?([A-Za-z_]\w*)(\s*\()?")


def api_section(text: str) -> str:
    """The ``rokeby.api`` section of the document: from its heading to the next level-2 heading."""
    start = text.index(SECTION)
    nxt = re.search(r"^## ", text[start + len(SECTION):], re.M)
    return text[start: start + len(SECTION) + nxt.start()] if nxt else text[start:]


def documented(section: str) -> tuple[set[str], set[str]]:
    """(names the prose documents, of them the ones written as calls), code blocks left out."""
    prose = FENCE.sub("", section)
    names, calls = set(), set()
    for span in SPAN.findall(prose):
        text = " ".join(span.split())
        m = HEAD.match(text)
        if m is None:
            continue
        rest = text[m.end(1):]
        dotted_other = rest.startswith(".") or (text.lstrip().startswith("rokeby.") and not text.lstrip().startswith("rokeby.api."))
        if dotted_other:
            continue
        names.add(m.group(1))
        if m.group(2):
            calls.add(m.group(1))
    return names, calls


def problems(api: types.ModuleType, features: list[types.ModuleType], section: str) -> list[str]:
    """What is wrong with ``api`` (the facade), ``features`` (each feature's api module) and the
    document section."""
    out = []
    exported = list(api.__all__)
    expected = [name for feature in features for name in feature.__all__]
    if exported != expected:
        out.append(f"rokeby.api.__all__ is not the features' __all__ in order: extra {sorted(set(exported) - set(expected))}, "
                   f"missing {sorted(set(expected) - set(exported))}")
    if len(set(exported)) != len(exported):
        out.append(f"a name is exported twice: {sorted(n for n in set(exported) if exported.count(n) > 1)}")
    for feature in features:
        for name in feature.__all__:
            if name.startswith("_"):
                out.append(f"{feature.__name__}.__all__ exports the private name {name}")
            elif not hasattr(feature, name):
                out.append(f"{feature.__name__}.__all__ names {name}, which it does not define")
            elif getattr(api, name, None) is not getattr(feature, name):
                out.append(f"rokeby.api.{name} is not {feature.__name__}.{name}")
    public = {n for n in vars(api) if not n.startswith("_")}
    if public - set(exported):
        out.append(f"rokeby.api has public names outside __all__: {sorted(public - set(exported))}")
    names, calls = documented(section)
    for name in exported:
        if name not in names:
            out.append(f"rokeby.api.{name} is not documented in the rokeby.api section of docs/python-api.md")
    for name in sorted(calls - set(exported)):
        out.append(f"docs/python-api.md documents {name}(...) as rokeby.api's, but it is not in rokeby.api.__all__")
    return out


def _features():
    from rokeby.appearance import api as appearance
    from rokeby.compositing import api as compositing
    from rokeby.envmaps import api as envmaps
    from rokeby.farm import api as farm
    from rokeby.reflection import api as reflection
    from rokeby.shadow import api as shadow

    return [reflection, compositing, shadow, appearance, envmaps, farm]


def test_rokeby_api_exports_the_features_entry_points_and_documents_them():
    from rokeby import api

    found = problems(api, _features(), api_section(DOC.read_text(encoding="utf-8")))
    assert not found, "\n".join(found)


def test_every_feature_api_is_reexported():
    """Each feature package with an ``api.py`` is one of the facade's sources (a new feature's
    entry points cannot be left out of rokeby.api)."""
    pkg = ROOT / "addon" / "rokeby"
    with_api = sorted(p.parent.name for p in pkg.glob("*/api.py"))
    assert with_api == sorted(m.__name__.split(".")[1] for m in _features())
    # every feature package (not the core, the Blender layer or the facade) has one
    packages = sorted(p.parent.name for p in pkg.glob("*/__init__.py") if p.parent.name not in ("core", "blender", "api"))
    assert packages == with_api, f"feature packages without an api.py: {sorted(set(packages) - set(with_api))}"


# --- the check itself, on synthetic modules and documents ---------------------------------------------

def _module(name, **attrs):
    m = types.ModuleType(name)
    for k, v in attrs.items():
        setattr(m, k, v)
    return m


def _f():
    return None


def _g():
    return None


DOC_OK = """# Python API

## `rokeby_native`

- `view_blend(parts)` is the core's.

## `rokeby.api` (the scripting API)

- `add_mirror(obj, *, metric)` and `remove_mirror(obj)`; a `MirrorReport`
  per mirror, and `api.RokebyError`.
- `rokeby.core.meshio.load_obj(path)` is another module's.

```python
api.add_mirror(obj)
```
"""


@pytest.fixture
def synthetic():
    err = type("RokebyError", (ValueError,), {})
    report = type("MirrorReport", (), {})
    feature = _module("rokeby.reflection.api", __all__=["add_mirror", "remove_mirror", "MirrorReport", "RokebyError"],
                      add_mirror=_f, remove_mirror=_g, MirrorReport=report, RokebyError=err, _index=_f)
    api = _module("rokeby.api", __all__=list(feature.__all__), add_mirror=_f, remove_mirror=_g, MirrorReport=report,
                  RokebyError=err, _reflection=feature)
    return api, feature


def test_the_check_passes_a_documented_explicit_api(synthetic):
    api, feature = synthetic
    assert problems(api, [feature], api_section(DOC_OK)) == []


def test_the_check_fails_on_an_undocumented_name(synthetic):
    api, feature = synthetic
    doc = DOC_OK.replace(" and `remove_mirror(obj)`", "")
    assert problems(api, [feature], api_section(doc)) == [
        "rokeby.api.remove_mirror is not documented in the rokeby.api section of docs/python-api.md"]


def test_the_check_fails_on_a_documented_function_that_is_not_exported(synthetic):
    api, feature = synthetic
    doc = DOC_OK.replace("per mirror,", "per mirror, `subdivide_midpoint(v,\n  f)` splits triangles,")
    assert problems(api, [feature], api_section(doc)) == [
        "docs/python-api.md documents subdivide_midpoint(...) as rokeby.api's, but it is not in rokeby.api.__all__"]


def test_the_check_reads_only_the_api_section_and_its_prose(synthetic):
    api, feature = synthetic
    # A name used only in a code block, or only in another section, is not documented.
    doc = DOC_OK.replace("- `add_mirror(obj, *, metric)` and ", "- ").replace("`view_blend(parts)`", "`add_mirror(obj)`")
    assert problems(api, [feature], api_section(doc)) == [
        "rokeby.api.add_mirror is not documented in the rokeby.api section of docs/python-api.md"]


def test_the_check_fails_on_private_and_extra_exports(synthetic):
    api, feature = synthetic
    api.__all__ = [*api.__all__, "_index"]
    api._index = _f
    api.helper = _g  # public, but not in __all__
    found = problems(api, [feature], api_section(DOC_OK))
    assert any("extra ['_index']" in p for p in found), found
    assert "rokeby.api has public names outside __all__: ['helper']" in found
    assert "rokeby.api._index is not documented in the rokeby.api section of docs/python-api.md" in found


def test_the_check_fails_when_the_facade_and_the_feature_disagree(synthetic):
    api, feature = synthetic
    api.remove_mirror = _f  # another function under the same name
    feature.__all__ = [*feature.__all__, "_index"]
    api.__all__ = list(feature.__all__)
    api._index = _f
    found = problems(api, [feature], api_section(DOC_OK))
    assert "rokeby.api.remove_mirror is not rokeby.reflection.api.remove_mirror" in found
    assert "rokeby.reflection.api.__all__ exports the private name _index" in found
