"""Files written by the previous release load with the new code and keep their meaning.

The previous release's add-on (a git worktree of PREVIOUS_RELEASE, its addon/ on PYTHONPATH) runs
tests/blend_fixtures/feature_fixtures.py to build one scene per feature and save it; the current code
opens each file in a fresh process. What a user sees must be the same: each mirror's report status,
the stored fields (within 1e-5) and a tiny Cycles render (32 px, fixed seed: equal within noise).
See docs/saved-data.md."""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[2]
SCRIPT = Path("tests") / "blend_fixtures" / "feature_fixtures.py"
# The last released stop: files it writes must load with this code. Move it forward (one line)
# when a release is cut; never to a commit whose files the current code cannot read.
PREVIOUS_RELEASE = "59f8664"
# The Blender releases the previous release ran on (its test suite): files it wrote exist only there.
# 59f8664 was tested on 4.5 only; the next release adds 4.2, 5.0 and 5.3 (the matrix).
PREVIOUS_RELEASE_BLENDERS = ("4.5",)
FIELD_TOL = 1e-5
# The fixtures script renders each feature in Cycles in its own bpy processes (the automatic marks of
# tests/conftest.py do not see into it).
pytestmark = [pytest.mark.blender, pytest.mark.cycles]
# Same scene, same seed, same sample count: a render differs only by floating-point noise.
PIXEL_MEAN_TOL = 2e-3
PIXEL_MAX_TOL = 0.05


def _run(cmd, cwd=None, env=None, timeout=300):
    return subprocess.run(cmd, cwd=cwd, env=env, capture_output=True, text=True, timeout=timeout)


def _result(r, what):
    line = next((ln for ln in r.stdout.splitlines() if ln.startswith("RESULT ")), None)
    if r.returncode != 0 or line is None:
        pytest.fail(f"{what} failed (rc {r.returncode}):\n{r.stdout[-3000:]}\n{r.stderr[-3000:]}")
    return json.loads(line[len("RESULT "):])


@pytest.fixture(scope="module")
def old_tree(tmp_path_factory):
    """A detached worktree of PREVIOUS_RELEASE (removed afterwards); skips, saying why, where git
    or the commit is not there (a shallow clone, a source tarball)."""
    import bpy

    here = "%d.%d" % tuple(bpy.app.version[:2])
    if here not in PREVIOUS_RELEASE_BLENDERS:
        pytest.skip(f"the previous release {PREVIOUS_RELEASE} ran on Blender {', '.join(PREVIOUS_RELEASE_BLENDERS)} only: "
                    f"it wrote no Blender {here} files to keep")
    git = shutil.which("git")
    if git is None:
        pytest.skip("git is not installed: cannot check out the previous release to write fixtures")
    if _run([git, "-C", str(ROOT), "rev-parse", "--git-dir"]).returncode != 0:
        pytest.skip(f"{ROOT} is not a git checkout: cannot check out the previous release {PREVIOUS_RELEASE}")
    if _run([git, "-C", str(ROOT), "cat-file", "-e", f"{PREVIOUS_RELEASE}^{{commit}}"]).returncode != 0:
        pytest.skip(f"commit {PREVIOUS_RELEASE} (the previous release) is not in this clone (shallow clone? "
                    f"`git fetch --unshallow` brings it)")
    tree = tmp_path_factory.mktemp("previous") / "tree"
    r = _run([git, "-C", str(ROOT), "worktree", "add", "--detach", str(tree), PREVIOUS_RELEASE])
    if r.returncode != 0:
        pytest.fail(f"git worktree add of {PREVIOUS_RELEASE} failed: {r.stderr}")
    try:
        yield tree
    finally:
        _run([git, "-C", str(ROOT), "worktree", "remove", "--force", str(tree)])
        _run([git, "-C", str(ROOT), "worktree", "prune"])


def _env(addon: Path, *extra: Path) -> dict:
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join(map(str, (addon, *extra)))
    return env


# The previous release calls rokeby_native by the names it had then (see its sitecustomize.py).
PREVIOUS_NATIVE = ROOT / "tests" / "blend_fixtures" / "previous_native"


@pytest.fixture(scope="module")
def written(old_tree, tmp_path_factory):
    """The previous release's fixtures: its own feature_fixtures.py, or this one copied into its tree
    (it uses only entry points that existed there)."""
    script = old_tree / SCRIPT
    if not script.exists():
        script.parent.mkdir(parents=True, exist_ok=True)
        shutil.copy(ROOT / SCRIPT, script)
    out = tmp_path_factory.mktemp("fixtures")
    _result(_run([sys.executable, str(script), "write", str(out)], cwd=old_tree, env=_env(old_tree / "addon", PREVIOUS_NATIVE)),
            f"writing the fixtures with {PREVIOUS_RELEASE}")
    return out, json.loads((out / "fixtures.json").read_text())


@pytest.fixture(scope="module")
def loaded(written):
    out, _ = written
    return _result(_run([sys.executable, str(ROOT / SCRIPT), "load", str(out)], cwd=ROOT, env=_env(ROOT / "addon")),
                   "loading the fixtures with the current code")


FEATURES = ("reflection", "shadow", "appearance", "compositing", "reflmap")


@pytest.mark.parametrize("feature", FEATURES)
def test_previous_release_files_keep_their_reports_fields_and_renders(feature, written, loaded):
    before, after = written[1][feature], loaded[feature]
    assert after["reports"] == before["reports"], f"{feature}: reports changed on load: {before['reports']} → {after['reports']}"
    assert sorted(after["fields"]) == sorted(before["fields"]), f"{feature}: stored fields changed: {sorted(before['fields'])} → {sorted(after['fields'])}"
    for key, old in before["fields"].items():
        new = after["fields"][key]
        if old is None or isinstance(old, str):
            assert new == old, f"{feature}: {key}: {old!r} → {new!r}"
        else:
            np.testing.assert_allclose(np.asarray(new), np.asarray(old), atol=FIELD_TOL, err_msg=f"{feature}: {key}")
    a, b = np.asarray(before["pixels"]), np.asarray(after["pixels"])
    assert a.shape == b.shape and float(a.mean()) > 1e-3, f"{feature}: the fixture render is black or missing"
    d = np.abs(a - b)
    assert d.mean() <= PIXEL_MEAN_TOL and d.max() <= PIXEL_MAX_TOL, (
        f"{feature}: the render of the previous release's file changed: mean |Δ| {d.mean():.2e}, max {d.max():.2e}")


def test_the_fixtures_hold_each_features_data(written):
    """The comparison above means something: every feature's fixture has what it is meant to hold."""
    f = written[1]
    assert set(f) == set(FEATURES)
    assert set(f["reflection"]["reports"]) == {"Ball", "Glass"}
    assert f["reflection"]["fields"]["Ball/stored_field"] is not None
    assert f["reflection"]["fields"]["Glass/stored_refraction"] is not None
    assert any(k.endswith("/shadow_mesh") for k in f["shadow"]["fields"])
    assert {"PaintedPoints/base_color", "PaintedTexture/roughness"} <= set(f["appearance"]["fields"])
    assert f["reflmap"]["reports"] == {"MapBall": f["reflmap"]["reports"]["MapBall"]}
