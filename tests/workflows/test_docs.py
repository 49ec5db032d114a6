"""Documentation examples run as written (problem 8).

Every fenced ```python block of README.md and docs/*.md is extracted and executed: the blocks of
one file run in order, in one namespace, in a fresh bpy process (tests/support/doc_runner.py: Blender's
default startup scene, small renders, at most 4 Cycles samples per render). A block that is not
meant to run carries an HTML comment right before its fence,

    <!-- not run: why (and where it is run or tested instead) -->

and shows up here as a skipped test with that reason; a marker anywhere else, an empty reason, or
an untagged block that looks like Python is an error. A failure names the file, the block and its
line, with the traceback in the document's own line numbers.

Also: ``python -m rokeby.composite`` with a missing input, height image or output folder exits
with status 2 and one line naming it (no traceback).
"""

from __future__ import annotations

import functools
import json
import os
import re
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
DOCS = [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]
PYTHON = {"python", "py", "python3"}
FENCE = re.compile(r"^(?P<indent>[ \t]*)(?P<fence>`{3,}|~{3,})(?P<info>[^`]*)$")
MARKER = re.compile(r"^<!--\s*not run\s*:\s*(?P<reason>.*?)\s*-->$")
ANY_MARKER = re.compile(r"^\s*<!--\s*not run\b", re.IGNORECASE)  # a marker line (not one quoted in `code`)
LOOKS_LIKE_PYTHON = re.compile(r"^\s*(import \w|from [\w.]+ import |>>> )")
PER_FILE_TIMEOUT = 300


@dataclass(frozen=True)
class Block:
    path: Path
    index: int  # 1-based, among the file's Python blocks
    line: int  # the block's first code line (1-based)
    code: str
    skip: str | None  # the reason of its "not run" marker

    @property
    def name(self) -> str:
        return f"{self.path.relative_to(ROOT)}:{self.line}"

    def describe(self) -> str:
        return f"{self.path.relative_to(ROOT)}, Python block {self.index} (code from line {self.line})"


def _dedent(lines, indent: str):
    n = len(indent.expandtabs(4))
    out = []
    for ln in lines:
        lead = len(ln) - len(ln.lstrip(" \t"))
        out.append(ln[min(lead, n):])
    return "\n".join(out) + "\n"


@functools.lru_cache(maxsize=None)
def extract(path: Path):
    """(Python blocks, problems) of one Markdown file."""
    lines = path.read_text(encoding="utf-8").splitlines()
    rel = path.relative_to(ROOT)
    blocks, problems, used_markers = [], [], set()
    i = 0
    while i < len(lines):
        m = FENCE.match(lines[i])
        if m is None:
            i += 1
            continue
        fence, indent = m["fence"], m["indent"]
        info = m["info"].strip()
        lang = info.split()[0].lower().strip("{}.") if info else ""
        close = re.compile(rf"^[ \t]*{re.escape(fence[0])}{{{len(fence)},}}\s*$")
        j = i + 1
        while j < len(lines) and not close.match(lines[j]):
            j += 1
        body = lines[i + 1 : j]
        if j >= len(lines):
            problems.append(f"{rel}:{i + 1}: the code fence is never closed")
        k = i - 1
        while k >= 0 and not lines[k].strip():
            k -= 1
        marker = MARKER.match(lines[k].strip()) if k >= 0 else None
        if lang in PYTHON:
            skip = None
            if marker is not None:
                used_markers.add(k)
                skip = marker["reason"]
                if not skip:
                    problems.append(f"{rel}:{k + 1}: a 'not run' marker without a reason")
            blocks.append(Block(path, len(blocks) + 1, i + 2, _dedent(body, indent), skip))
        elif not lang and any(LOOKS_LIKE_PYTHON.match(b) for b in body):
            problems.append(f"{rel}:{i + 1}: an untagged code block that looks like Python: tag it ```python "
                            "(it then runs, or needs a '<!-- not run: reason -->' marker) or ```text")
        i = j + 1
    for k, ln in enumerate(lines):
        if ANY_MARKER.match(ln) and k not in used_markers:
            problems.append(f"{rel}:{k + 1}: a 'not run' marker that is not right before a ```python block "
                            "(or not of the form '<!-- not run: reason -->')")
    return tuple(blocks), tuple(problems)


ALL_BLOCKS = [b for p in DOCS for b in extract(p)[0]]


@functools.lru_cache(maxsize=None)
def run_file(path: Path) -> dict:
    """Runs the file's runnable blocks in one fresh bpy process: {line: result}."""
    import tempfile

    runnable = [{"line": b.line, "code": b.code} for b in extract(path)[0] if b.skip is None]
    if not runnable:
        return {}
    work = Path(tempfile.mkdtemp(prefix="rokeby_docs_"))
    (work / "blocks.json").write_text(json.dumps(runnable))
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join([str(ROOT / "addon"), str(ROOT / "tests"), env.get("PYTHONPATH", "")])
    try:
        r = subprocess.run([sys.executable, str(ROOT / "tests" / "support" / "doc_runner.py"), str(path.relative_to(ROOT)),
                            str(work / "blocks.json"), str(work / "results.json")],
                           capture_output=True, text=True, cwd=work, env=env, timeout=PER_FILE_TIMEOUT)
    except subprocess.TimeoutExpired:
        return {b["line"]: {"ok": False, "error": f"the file's blocks ran past {PER_FILE_TIMEOUT} s"} for b in runnable}
    res = work / "results.json"
    if not res.exists():
        tail = (r.stdout[-1500:] + r.stderr[-2500:]).strip()
        return {b["line"]: {"ok": False, "error": f"the block runner died (rc {r.returncode}):\n{tail}"} for b in runnable}
    out = {d["line"]: d for d in json.loads(res.read_text())}
    for b in runnable:
        out.setdefault(b["line"], {"ok": False, "error": "no result (the runner stopped before this block)"})
    return out


# Each file's blocks run in a fresh bpy process that renders (Cycles, small): marked by hand, the
# automatic marks (tests/conftest.py) do not see into the documents.
@pytest.mark.blender
@pytest.mark.cycles
@pytest.mark.parametrize("block", ALL_BLOCKS, ids=[b.name for b in ALL_BLOCKS])
def test_doc_block_runs_as_written(block):
    if block.skip is not None:
        pytest.skip(f"{block.describe()}: not run: {block.skip}")
    results = run_file(block.path)
    r = results[block.line]
    if not r["ok"]:
        earlier = [b.index for b in extract(block.path)[0] if b.line < block.line and b.skip is None and not results[b.line]["ok"]]
        note = f" (block {earlier[0]} of this file failed before it; this one may only depend on it)" if earlier else ""
        pytest.fail(f"{block.describe()} fails as written{note}:\n{r['error']}", pytrace=False)


def test_every_python_block_runs_or_says_why_not():
    problems = [p for path in DOCS for p in extract(path)[1]]
    assert not problems, "\n".join(problems)
    ran = [b for b in ALL_BLOCKS if b.skip is None]
    marked = [b for b in ALL_BLOCKS if b.skip is not None]
    for path in DOCS:
        blocks = extract(path)[0]
        if blocks:
            print(f"{path.relative_to(ROOT)}: {sum(b.skip is None for b in blocks)} run, {sum(b.skip is not None for b in blocks)} not run")
    for b in marked:
        print(f"not run: {b.name}: {b.skip}")
    assert ran, "no documentation block runs"
    # Every Python block is either run or marked: the two lists cover them all.
    assert len(ran) + len(marked) == len(ALL_BLOCKS)


def test_the_marker_rules_catch_mistakes(tmp_path, monkeypatch):
    """The extractor itself: a marked block is skipped with its reason, an unmarked one runs, and
    stray or empty markers and untagged Python are reported with file and line."""
    monkeypatch.setattr(sys.modules[__name__], "ROOT", tmp_path)
    doc = tmp_path / "x.md"
    doc.write_text("text\n\n<!-- not run: needs a GPU -->\n```python\nimport gpu\n```\n\n- item\n\n  ```python\n  x = 1\n  ```\n\n"
                   "<!-- not run: -->\n```python\ny = 2\n```\n\n<!-- not run: stray -->\n\n```sh\nls\n```\n\n```\nimport os\n```\n"
                   "Mark with `<!-- not run: reason -->`.\n")
    blocks, problems = extract.__wrapped__(doc)
    assert [(b.index, b.line, b.code, b.skip) for b in blocks] == [
        (1, 5, "import gpu\n", "needs a GPU"), (2, 11, "x = 1\n", None), (3, 16, "y = 2\n", "")]
    assert any("x.md:14: a 'not run' marker without a reason" in p for p in problems), problems
    assert any("x.md:19: a 'not run' marker that is not right before" in p for p in problems), problems
    assert any("x.md:25: an untagged code block that looks like Python" in p for p in problems), problems
    assert len(problems) == 3, problems  # a marker quoted in `code` is no marker


# --- python -m rokeby.composite: missing files ------------------------------------------------------

def _composite(*args):
    return subprocess.run([sys.executable, "-m", "rokeby.composite", *map(str, args)], capture_output=True, text=True,
                          cwd=ROOT / "addon", env={**os.environ, "PYTHONPATH": str(ROOT / "addon")}, timeout=120)


@pytest.mark.parametrize("case", ["input", "--bump", "output folder"])
def test_composite_missing_file_is_one_line_and_status_2(case, tmp_path):
    frame = tmp_path / "frame.exr"
    frame.write_bytes(b"not read: the files are checked first")
    out = tmp_path / "out.exr"
    args, words = {
        "input": ([tmp_path / "missing.exr", out], f"input: no such file: {tmp_path / 'missing.exr'}"),
        "--bump": ([frame, out, "--bump", tmp_path / "missing.exr"], f"--bump: no such file: {tmp_path / 'missing.exr'}"),
        "output folder": ([frame, tmp_path / "nowhere" / "out.exr"], f"output: the folder {tmp_path / 'nowhere'} does not exist"),
    }[case]
    r = _composite(*args)
    lines = [ln for ln in r.stderr.splitlines() if ln.strip()]
    assert r.returncode == 2, (r.returncode, r.stderr)
    assert lines == [f"rokeby.composite: {words}"], r.stderr
    assert not out.exists()


def test_composite_unreadable_height_image_is_a_named_error(tmp_path):
    from rokeby import compositing as C
    from rokeby.composite import _read_height

    bad = tmp_path / "height.exr"
    bad.write_bytes(b"not an EXR")
    with pytest.raises(C.CompositingError, match="--bump: cannot read the height image"):
        _read_height(str(bad), (4, 4))
    import numpy as np

    np.save(tmp_path / "h.npy", np.zeros((3, 5), np.float32))
    with pytest.raises(C.CompositingError, match=r"--bump: height image .* is 5×3, the frame is 4×4"):
        _read_height(str(tmp_path / "h.npy"), (4, 4))
