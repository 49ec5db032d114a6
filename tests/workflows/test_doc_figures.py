"""One figure per claim: the guides quote docs/benchmarks.md, and name what the code does.

Speed and accuracy figures live in docs/benchmarks.md (written by ``make bench``, each section with
its machine and date). README.md and the other guides quote them as links to the table they come
from, with the row (or the sentence) named in the link's title:

    a green-handle move takes [12.7–16.8 ms](benchmarks.md#green-handle-move-at-100k-vertices "whole update")

This test checks, for every such citation, that the heading exists, that the quoted row exists in
that section, and that every number in the link's text is a number of that row (rounded as quoted:
``13`` quotes 12.7, ``0.2 %`` quotes 0.16 %). A range may quote several rows: every row or
paragraph of the section that holds the title counts, and a title may name several rows separated
by " ; ". A plain link to a section (no figure in its text, no title) is only checked for its
anchor. A timing or an error figure outside such a link (``12 ms``, ``56 MP/s``, ``3 % mean
error``, ``4× faster``) fails, unless it is a goal (the word "goal" next to it, or a table's goal
column), the paper's own figure, or listed in ``ALLOWED`` with its reason (settings the code
enforces, test bounds). The detection is a set of patterns, not a parser of English: a figure
written in words ("half a second") is not found.

docs/benchmarks.md itself must name its machine, and every section holding figures a date.

It also checks what the guides name against the code: the geodesic methods (labels, identifiers,
saved item numbers, the default of new mirrors, the property's own default and ``rokeby_native``'s)
in docs/addon.md and docs/geodesics.md; the region kinds, distance metrics, polar methods and
generating eyes (and the eye's default) in docs/addon.md; docs/architecture.md's opening (the
data-flow picture, then the "To change …, start in …" table, whose every path must exist); and the
README's guide list, which must start with the architecture guide.
"""

from __future__ import annotations

import inspect
import re
import unicodedata
from dataclasses import dataclass
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
BENCH = ROOT / "docs" / "benchmarks.md"
GUIDES = [ROOT / "README.md", *sorted(p for p in (ROOT / "docs").glob("*.md") if p.name != "benchmarks.md")]

# --- docs/benchmarks.md: sections, rows, numbers ----------------------------------------------

HEADING = re.compile(r"^(#{1,6})\s+(.*?)\s*#*\s*$")
NUMBER = re.compile(r"(?<![\w.])[-−]?\d[\d,]*(?:\.\d+)?(?:[eE][-−+]?\d+)?")


def slug(heading: str) -> str:
    """GitHub's anchor for a heading: lower case, punctuation dropped, spaces to hyphens."""
    text = re.sub(r"`|\*", "", heading).strip().lower()
    out = []
    for ch in text:
        cat = unicodedata.category(ch)
        if ch in " -":
            out.append("-" if ch == " " else ch)
        elif ch == "_" or cat[0] in "LN" or cat == "Mn":
            out.append(ch)
    return "".join(out)


def _blocks(lines: list[str]) -> list[str]:
    """A section's units: each table row, each line of a code block, each paragraph (joined)."""
    units, para, fenced = [], [], False
    for ln in lines:
        if ln.lstrip().startswith("```"):
            fenced = not fenced
            if para:
                units.append(" ".join(para))
                para = []
            continue
        if fenced or ln.lstrip().startswith("|"):
            if para:
                units.append(" ".join(para))
                para = []
            if ln.strip():
                units.append(ln.strip())
        elif ln.strip():
            para.append(ln.strip())
        elif para:
            units.append(" ".join(para))
            para = []
    if para:
        units.append(" ".join(para))
    return units


LEVELS: dict[str, int] = {}


def bench_sections() -> dict[str, list[str]]:
    """anchor -> the units (rows, paragraphs) between that heading and the next heading."""
    sections: dict[str, list[str]] = {}
    seen: dict[str, int] = {}
    current, lines, fenced = None, [], False

    def close():
        if current is not None:
            sections[current] = _blocks(lines)

    for ln in BENCH.read_text().splitlines():
        if ln.lstrip().startswith("```"):
            fenced = not fenced
        m = None if fenced else HEADING.match(ln)
        if m:
            close()
            base = slug(m.group(2))
            n = seen.get(base, 0)
            seen[base] = n + 1
            current, lines = (base if n == 0 else f"{base}-{n}"), []
            LEVELS[current] = len(m.group(1))
        else:
            lines.append(ln)
    close()
    return sections


def numbers(text: str) -> list[str]:
    """The numbers of a text as written ("1,599,008", "0.16", "4e-7"; "13–17" gives 13 and 17)."""
    text = text.replace("−", "-")
    return [m.group(0).lstrip("-").replace(",", "") for m in NUMBER.finditer(text.replace("–", " – "))]


def quotes(quoted: str, value: str) -> bool:
    """Does ``quoted`` (as written in a guide) quote ``value`` (as written in the table)?"""
    q, v = float(quoted), float(value)
    if "e" in quoted.lower():
        mant, _, exp = quoted.lower().partition("e")
        step = 10.0 ** (int(exp) - (len(mant.split(".")[1]) if "." in mant else 0))
    else:
        step = 10.0 ** -(len(quoted.split(".")[1]) if "." in quoted else 0)
    return abs(q - v) <= step / 2 + 1e-12 * max(1.0, abs(v))


# --- the guides: citations and bare figures ----------------------------------------------------

CITATION = re.compile(r"\[(?P<text>[^\]\n]+)\]\((?P<path>(?:docs/)?benchmarks\.md)#(?P<anchor>[^\s)]+)(?:\s+\"(?P<row>[^\"]*)\")?\)")

# A timing or an error figure: a number or range with a unit of time or throughput, or a percentage,
# angle or ratio said to be an error, an accuracy or a speed-up.
_NUM = r"(?<![\w.×/-])\d[\d,]*(?:\.\d+)?(?:\s?[–-]\s?\d[\d,]*(?:\.\d+)?)?"
FIGURE = re.compile(
    rf"{_NUM}\s?(?:ms|µs|ns|s|seconds?|minutes?|MP/s|megapixels/s|fps|GFLOP/s|GB/s|M instructions)(?![\w/])"
    rf"|{_NUM}\s?%"
    rf"|{_NUM}×(?!\s?\d)"
)

ERROR_WORDS = re.compile(r"error|accura|over-?estimat|too long|\bmean\b|p99|percentile|off by", re.IGNORECASE)

# Figures in guides that are not measurements: goals, settings, limits the code enforces, the
# papers' own numbers. (guide, text of the figure, the words around it that identify it) -> why.
ALLOWED: dict[tuple[str, str, str], str] = {
    ("docs/envmaps.md", "6 minutes", "pre-rendered for 6 minutes per image"): "the paper's (Fraser's) figure",
    ("docs/addon.md", "0.25 s", "updates pause for 0.25 s"): "a setting: geodesic_cache.SETTLE_INTERVAL",
    ("docs/addon.md", "0.4 s", "it runs at most every 0.4 s"): "a setting: evaluate.ESTIMATE_INTERVAL",
    ("docs/addon.md", "0.4 s", '("Scene (Cycles) 0.4 s, 0.5 MB")'): "an example of the status text",
    ("docs/addon.md", "0.4 s", "until the changes pause (0.4 s"): "a setting: scene_env.DEBOUNCE_SECONDS",
    ("docs/envmaps.md", "5×", "world turned half a turn to be 5× worse"): "a test's bound (tests/envmaps/test_envmap.py)",
    ("docs/geodesics.md", "0.25 %", "≤ 0.25 % mean error, never below exact"): "a test's bound (tests/reflection/test_geodesic_accuracy.py)",
    ("docs/farm.md", "120 s", "SIGKILL 120 s"): "a setting: farm.api.CANCEL_NOTICE_S",
    ("docs/development.md", "20 s", "takes more than about 20 s"): "the rule for the `slow` test marker",
    ("docs/development.md", "20 s", "above about 20 s on the shared"): "the rule for the `slow` test marker",
    ("docs/development.md", "4 minutes", "about 4 minutes"): "how long a one-off set-up step takes, not a figure of Rokeby's",
    ("docs/development.md", "10–12 minutes", "The leg takes 10–12 minutes"): "how long a test leg takes, not a figure of Rokeby's",
    ("docs/development.md", "15–120 s", "15–120 s each"): "how long a test leg takes, not a figure of Rokeby's",
    ("docs/development.md", "1.5 minutes", "about 1.5 minutes"): "how long a one-off set-up step takes, not a figure of Rokeby's",
}


@dataclass(frozen=True)
class Figure:
    guide: str
    line: int
    text: str
    context: str


def _strip_markup(line: str) -> str:
    """The line without inline code, citations, link targets and HTML comments."""
    line = re.sub(r"<!--.*?-->", " ", line)
    line = re.sub(r"`[^`]*`", " ", line)
    line = CITATION.sub(" ", line)
    return re.sub(r"\]\([^)]*\)", "]", line)


def bare_figures(path: Path) -> list[Figure]:
    found, fenced, header = [], False, None
    for i, raw in enumerate(path.read_text().splitlines(), 1):
        if raw.lstrip().startswith(("```", "~~~")):
            fenced = not fenced
            continue
        if fenced:
            continue
        line = _strip_markup(raw)
        if not line.lstrip().startswith("|"):
            header = None
        elif header is None:
            header = [c.strip() for c in line.strip().strip("|").split("|")]
        for m in FIGURE.finditer(line):
            if header is not None and line.lstrip().startswith("|"):
                column = line[:m.start()].count("|") - 1
                if 0 <= column < len(header) and re.search(r"\bgoal|\bpaper", header[column], re.IGNORECASE):
                    continue  # the goal or the paper's column of a table
            if m.group(0).endswith("%") and not ERROR_WORDS.search(line[max(0, m.start() - 40): m.end() + 40]):
                continue  # a share of something (pixels, a radius), not an error figure
            before, after = line[max(0, m.start() - 30): m.start()], line[m.end(): m.end() + 20]
            if re.search(r"\bgoals?\b|\bpaper\b|paper's|Table 1|GTX", before, re.IGNORECASE) or re.match(r"[^.;,()]{0,15}\bgoals?\b", after):
                continue  # a target, or the paper's own figure, not a measurement of ours
            found.append(Figure(path.relative_to(ROOT).as_posix(), i, m.group(0), line.strip()))
    return found


def citations():
    for path in GUIDES:
        for i, line in enumerate(path.read_text().splitlines(), 1):
            for m in CITATION.finditer(line):
                yield pytest.param(path, i, m, id=f"{path.relative_to(ROOT)}:{i}")


@pytest.fixture(scope="module")
def sections():
    return bench_sections()


def test_benchmarks_name_machine_and_date():
    text = BENCH.read_text()
    assert re.search(r"^Machine: .+", text, re.MULTILINE), "docs/benchmarks.md: no 'Machine:' line"
    dated = False  # a ### subsection may take its date from its ## section
    for anchor, units in bench_sections().items():
        level = LEVELS[anchor]
        body = " ".join(units)
        has_date = bool(re.search(r"\b20\d\d-\d\d-\d\d\b", body))
        if level <= 2:
            dated = has_date
        if level == 1 or not re.search(r"\d\s?(?:ms|s|%|MP/s|MB)\b", body):
            continue
        assert has_date or (level > 2 and dated), f"docs/benchmarks.md, section #{anchor}: its figures say no date (a 'Run: YYYY-MM-DD' line)"


@pytest.mark.parametrize("path, line, m", list(citations()))
def test_citation_quotes_its_table(path, line, m, sections):
    where = f"{path.relative_to(ROOT)}:{line}: [{m['text']}]({m['path']}#{m['anchor']})"
    expected = "docs/benchmarks.md" if path.parent == ROOT else "benchmarks.md"
    assert m["path"] == expected, f"{where}: link to {expected} from this file"
    assert m["anchor"] in sections, f"{where}: docs/benchmarks.md has no heading with the anchor #{m['anchor']}"
    if not m["row"] and not numbers(m["text"]):
        return  # a link to the section, quoting nothing
    assert m["row"], f'{where}: name the row or sentence quoted in the link\'s title: (benchmarks.md#{m["anchor"]} "row")'
    wanted = " ".join(m["row"].split())
    selectors = [w.strip() for w in wanted.split(" ; ")]
    units = [u for u in sections[m["anchor"]] if any(w in " ".join(u.split()) for w in selectors)]
    assert units, f"{where}: section #{m['anchor']} has no row or sentence containing {wanted!r}"
    quoted = numbers(m["text"])
    assert quoted, f"{where}: the link's text holds no figure"
    available = [n for u in units for n in numbers(u)]
    missing = [q for q in quoted if not any(quotes(q, v) for v in available)]
    assert not missing, (f"{where}: {', '.join(missing)} not in the cited row(s) of #{m['anchor']} "
                         f"(containing {wanted!r}): {units[0][:300]}")


@pytest.mark.parametrize("path", GUIDES, ids=lambda p: str(p.relative_to(ROOT)))
def test_no_uncited_figure(path):
    rel = path.relative_to(ROOT).as_posix()
    bad = []
    for f in bare_figures(path):
        if any(g == rel and t == f.text and c in f.context for (g, t, c) in ALLOWED):
            continue
        bad.append(f"{f.guide}:{f.line}: {f.text!r} in: {f.context[:160]}")
    assert not bad, ("timing/accuracy figures without a citation of docs/benchmarks.md (quote the row as "
                     "[figure](benchmarks.md#section \"row\"), or remove the figure):\n" + "\n".join(bad))


def test_allowed_entries_still_match():
    """Every ALLOWED entry still names a figure in its guide (a stale entry would hide a new one)."""
    stale = []
    for (guide, text, context), _why in ALLOWED.items():
        figs = bare_figures(ROOT / guide)
        if not any(f.text == text and context in f.context for f in figs):
            stale.append((guide, text, context))
    assert not stale, f"ALLOWED entries that no longer match a figure: {stale}"


def test_no_machine_paths_in_guides():
    for path in GUIDES:
        for i, line in enumerate(path.read_text().splitlines(), 1):
            assert not re.search(r"(?<![\w.])/(?:work|home|Users|root)/", line), \
                f"{path.relative_to(ROOT)}:{i}: a machine's absolute path: {line.strip()}"


# --- docs/architecture.md and the README's guide list ----------------------------------------

def _section(text: str, heading: str) -> str:
    start = text.index(heading)
    nxt = re.search(r"^#{1,2} ", text[start + len(heading):], re.MULTILINE)
    return text[start: start + len(heading) + (nxt.start() if nxt else len(text))]


def test_architecture_opens_with_data_flow_and_start_here_table():
    text = (ROOT / "docs" / "architecture.md").read_text()
    headings = re.findall(r"^## (.+)$", text, re.MULTILINE)
    assert headings[:2] == ["The data flow", "To change …, start in …"], headings[:3]
    flow = _section(text, "## The data flow")
    assert "```" in flow and "rokeby_native" in flow and "▼" in flow, "the data-flow picture is missing"


def test_architecture_table_paths_exist():
    table = _section((ROOT / "docs" / "architecture.md").read_text(), "## To change …, start in …")
    rows = [ln for ln in table.splitlines() if ln.startswith("|") and not ln.startswith("|---")][1:]
    assert len(rows) >= 20, f"the table holds {len(rows)} rows"
    missing = []
    for row in rows:
        cells = [c.strip() for c in row.strip().strip("|").split("|")]
        paths = [p for p in re.findall(r"`([^`]+)`", cells[-1]) if "/" in p or "." in p]
        assert paths, f"docs/architecture.md: the row {cells[0]!r} names no file"
        missing += [f"{cells[0]!r}: {p}" for p in paths if not (ROOT / p).exists()]
    assert not missing, "docs/architecture.md, 'To change …, start in …': paths that do not exist:\n" + "\n".join(missing)


def test_readme_links_architecture_first_among_guides():
    guides = _section((ROOT / "README.md").read_text(), "## Guides")
    first = re.search(r"^- \[[^\]]+\]\(([^)]+)\)", guides, re.MULTILINE)
    assert first and first.group(1) == "docs/architecture.md", f"README's first guide: {first and first.group(1)}"


# --- method lists and defaults the guides name, against the code -------------------------------

@pytest.fixture(scope="module")
def reflection_props():
    pytest.importorskip("bpy")
    from rokeby.reflection import props

    return props


def _default(props_module, cls_name: str, prop: str) -> str:
    ann = getattr(props_module, cls_name).__annotations__[prop]
    if isinstance(ann, str):  # postponed annotations: the EnumProperty(...) call as written
        return re.search(r"default=['\"](\w+)['\"]", ann).group(1)
    return ann.keywords["default"]


def _add_mirror_default(name: str) -> str:
    from rokeby import api

    return inspect.signature(api.add_mirror).parameters[name].default


def test_addon_md_geodesic_methods_match_the_enum(reflection_props):
    text = (ROOT / "docs" / "addon.md").read_text()
    bullet = text[text.index("with the *Geodesic method*"):]
    bullet = bullet[: bullet.index("\n  - ")]
    documented = re.findall(r"\*([^*]+)\*\s*\(`([A-Z_]+)`, (?:item )?(\d+)", bullet)
    code = [(label, ident, number) for ident, label, _desc, _icon, number in reflection_props.GEODESIC_METHODS]
    assert sorted((lab, i, int(n)) for lab, i, n in documented) == sorted(code), (
        f"docs/addon.md lists {documented}; reflection/props.py GEODESIC_METHODS: {code}")
    # the default of new mirrors, and the property's own default (what old files read)
    new_default = _add_mirror_default("geodesic_method")
    label = dict((i, lab) for lab, i, _n in code)[new_default]
    assert re.search(rf"\*{re.escape(label)}\*[^*]*the default of new\s+mirrors", bullet), (
        f"docs/addon.md must name {label!r} ({new_default}) as the default of new mirrors")
    prop_default = _default(reflection_props, "RokebyMirror", "geodesic_method")
    label = dict((i, lab) for lab, i, _n in code)[prop_default]
    assert re.search(rf"\*{re.escape(label)}\*[^*]*the property's default", bullet), (
        f"docs/addon.md must name {label!r} ({prop_default}) as the property's default")


def test_geodesics_md_methods_and_defaults_match_the_code(reflection_props):
    text = (ROOT / "docs" / "geodesics.md").read_text()
    table = _section(text, "## The methods")
    rows = [ln for ln in table.splitlines() if ln.startswith('| `"')]
    methods = {re.match(r'\| `"(\w+)"`', r).group(1): r for r in rows}
    code = {ident.lower() for ident, *_ in reflection_props.GEODESIC_METHODS}
    assert set(methods) == code, f"docs/geodesics.md's table: {sorted(methods)}; the enum: {sorted(code)}"
    new_default = _add_mirror_default("geodesic_method").lower()
    marked = [m for m, r in methods.items() if "(the default" in r]
    assert marked == [new_default], f"docs/geodesics.md marks {marked} as the default; new mirrors get {new_default}"
    stub = _native_stubs()
    native_defaults = set(re.findall(r'method: _GeodesicMethod = "(\w+)"', stub))
    assert native_defaults == {new_default}, f"rokeby_native's defaults {native_defaults} differ from new mirrors' {new_default}"
    # "Accurate (default)" (dense_graph, item 4), ...: labels and item numbers in the prose
    named = re.findall(r'"([^"]+)"\s*\((\w+)?,?\s*item (\d+)\)', _section(text, "## The methods"))
    named += [(lab, "", n) for lab, n in re.findall(r'"([^"]+)"\s*\(item (\d+)\)', table)]
    by_label = {label: (ident, number) for ident, label, _d, _i, number in reflection_props.GEODESIC_METHODS}
    assert named, "docs/geodesics.md names no method label with its item number"
    for label, ident, number in named:
        assert label in by_label, f"docs/geodesics.md names {label!r}, not a label of the enum"
        assert int(number) == by_label[label][1], f"docs/geodesics.md: {label!r} is item {by_label[label][1]}, not {number}"
        if ident:
            assert ident.upper() == by_label[label][0], f"docs/geodesics.md: {label!r} is {by_label[label][0]}, not {ident}"


def _native_stubs() -> str:
    """rokeby_native's type stubs (python/rokeby_native/*.pyi), one text."""
    return "\n".join(p.read_text() for p in sorted((ROOT / "python" / "rokeby_native").glob("*.pyi")))


def test_readme_names_the_default_geodesic_method(reflection_props):
    text = (ROOT / "README.md").read_text()
    assert "the dense geodesic graph by default" in text
    assert _add_mirror_default("geodesic_method") == "DENSE_GRAPH", "README.md names the dense graph as the default"


@pytest.mark.parametrize("enum_name, doc_phrase", [
    ("REGION_KINDS", "- **Regions**"),
    ("METRICS", "  - Distance:"),
    ("POLAR_METHODS", "  - Polar"),
    ("EYE_SOURCES", "  - Eye"),
])
def test_addon_md_names_every_item(reflection_props, enum_name, doc_phrase):
    """Each enum's items appear by their labels in docs/addon.md's paragraph about them, and the
    paragraph names no label the enum lacks."""
    text = (ROOT / "docs" / "addon.md").read_text()
    start = text.index(doc_phrase)
    end = text.find("\n- ", start + len(doc_phrase)) if doc_phrase.startswith("- ") else text.find("\n  - ", start + len(doc_phrase))
    para = text[start:end]
    labels = [item[1] for item in getattr(reflection_props, enum_name)]
    for label in labels:
        assert f"*{label}*" in para, f"docs/addon.md ({doc_phrase.strip()}): {label!r} of {enum_name} is not named"
    if enum_name == "EYE_SOURCES":
        default = _default(reflection_props, "RokebyMirror", "eye_source")
        label = dict((i[0], i[1]) for i in reflection_props.EYE_SOURCES)[default]
        assert f"*{label}* (the default)" in para, f"docs/addon.md must name {label!r} as the eye's default"


def _anchors(path: Path) -> set[str]:
    seen: dict[str, int] = {}
    out, fenced = set(), False
    for ln in path.read_text().splitlines():
        if ln.lstrip().startswith("```"):
            fenced = not fenced
        m = None if fenced else HEADING.match(ln)
        if m:
            base = slug(m.group(2))
            n = seen.get(base, 0)
            seen[base] = n + 1
            out.add(base if n == 0 else f"{base}-{n}")
    return out


def test_links_between_guides_reach_their_headings():
    """A figure moved to docs/benchmarks.md leaves links behind: each #anchor must still exist."""
    bad = []
    for path in [*GUIDES, BENCH]:
        for i, line in enumerate(path.read_text().splitlines(), 1):
            for m in re.finditer(r"\]\(([^)\s#]*)#([^)\s\"]+)", line):
                target = (path.parent / m.group(1)) if m.group(1) else path
                if target.suffix == ".md" and target.exists() and m.group(2) not in _anchors(target):
                    bad.append(f"{path.relative_to(ROOT)}:{i}: {m.group(1)}#{m.group(2)}")
    assert not bad, "links to headings that do not exist:\n" + "\n".join(bad)


def test_whole_bench_run_keeps_the_sections_it_does_not_write(monkeypatch):
    """``make bench`` rewrites docs/benchmarks.md; the sections it does not produce (measurements
    moved here from the guides, each dated) must survive, since the guides quote them."""
    import importlib.util

    import sys

    # bench/run.py imports its siblings as a script does and puts tests/ on sys.path: undo both after.
    monkeypatch.setattr(sys, "path", [str(ROOT / "bench"), *sys.path])
    before = set(sys.modules)
    try:
        spec = importlib.util.spec_from_file_location("bench_run", ROOT / "bench" / "run.py")
        run = importlib.util.module_from_spec(spec)
        spec.loader.exec_module(run)
    finally:
        bench = str(ROOT / "bench")
        for name in set(sys.modules) - before:
            if str(getattr(sys.modules[name], "__file__", "") or "").startswith(bench):
                del sys.modules[name]
    old = "# R\n\nMachine: m\n\n## A\n\nRun: 2026-01-01.\n\n| x | 1 ms |\n\n## Hand\n\nRun: 2026-01-02.\n\n2 ms\n\n## B\n\nb\n"
    new = "# R\n\nMachine: n\n\n## A\n\nRun: 2026-02-01.\n\n| x | 3 ms |\n\n## B\n\nb2\n"
    merged = run.keep_other_sections(new, old)
    assert merged.startswith(new.rstrip("\n")), merged
    assert "## Hand\n\nRun: 2026-01-02.\n\n2 ms" in merged and "1 ms" not in merged and merged.count("## B") == 1
    assert run.keep_other_sections(BENCH.read_text(), BENCH.read_text()) == BENCH.read_text()


def test_python_api_md_geodesic_methods_match_the_stub_and_the_enum(reflection_props):
    stub = _native_stubs()
    literal = re.search(r"_GeodesicMethod = Literal\[([^\]]*)\]", stub).group(1)
    native = re.findall(r'"(\w+)"', literal)
    assert set(native) == {ident.lower() for ident, *_ in reflection_props.GEODESIC_METHODS}, (native, "the enum")
    text = (ROOT / "docs" / "python-api.md").read_text()
    start = text.index("`method` is one of")
    sentence = text[start: text.index(")).", start)]
    named = re.findall(r'`"(\w+)"`', sentence)
    assert sorted(named) == sorted(native), f"docs/python-api.md names {named}; the stub {native}"
    assert named[0] == _add_mirror_default("geodesic_method").lower() and "(the default" in sentence
