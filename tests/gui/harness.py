"""Host side of the window leg (tests/gui/, ``make test-gui``): runs one real Blender window per call
inside tools/guiroot (Debian 13's blender 4.3 on Xvfb with Mesa's llvmpipe) and returns what its
scenario reported. The API (tests/gui/README.md):

    run_scenario(name, zip_path, timeout=300) -> Run
    scenario_result(name, zip_path, timeout=300) -> dict   (the result; fails on an error or traceback)

runs tests/gui/scenarios/<name>.py in a fresh Blender (fresh HOME, the zip installed by the scenario
with ``ui.install()``), with its output under target/gui/<name>/ (result.json, blender.log and the
screenshots). ``Run.result`` is the scenario's ``ui.result``; ``Run.error`` its traceback or None;
``Run.tracebacks`` the Python tracebacks Blender printed (drawing, operators, timers)."""

from __future__ import annotations

import json
import os
import re
import shutil
import subprocess
from dataclasses import dataclass, field
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[2]
GUIROOT = REPO / "tools" / "guiroot"
OUT = REPO / "target" / "gui"
SCENARIOS = Path(__file__).resolve().parent / "scenarios"


def unavailable_reason() -> str | None:
    """Why this machine cannot run a window (None when it can, possibly after a set-up)."""
    if os.name != "posix" or not hasattr(os, "geteuid"):
        return "the window leg needs Linux"
    if os.geteuid() != 0:
        return "the window leg needs root (tools/guiroot makes a Debian root with debootstrap and chroots into it)"
    if shutil.which("unshare") is None or shutil.which("chroot") is None:
        return "the window leg needs unshare and chroot (util-linux, coreutils)"
    if subprocess.run([str(GUIROOT), "--ready"]).returncode == 0:
        return None
    r = subprocess.run([str(GUIROOT), "--setup"], capture_output=True, text=True)
    if r.returncode != 0:
        return f"tools/guiroot --setup failed (no debootstrap or no Debian mirror?): {r.stderr.strip()[-400:]}"
    return None


@dataclass
class Run:
    name: str
    out: Path
    result: dict = field(default_factory=dict)
    error: str | None = None
    shots: list = field(default_factory=list)
    steps: list = field(default_factory=list)
    log: str = ""
    returncode: int = 0

    @property
    def tracebacks(self) -> list:
        """Each Python traceback Blender printed (its lines up to the exception line)."""
        return re.findall(r"Traceback \(most recent call last\):\n(?:[ \t].*\n)*.*", self.log)

    def describe(self) -> str:
        tail = "\n".join(self.log.splitlines()[-40:])
        return (f"window run {self.name} (output in {self.out}): rc {self.returncode}\n"
                f"error: {self.error}\nsteps:\n  " + "\n  ".join(self.steps[-25:]) + f"\nblender.log (tail):\n{tail}")


def run_scenario(name: str, zip_path: Path, timeout: int = 300) -> Run:
    """Run tests/gui/scenarios/<name>.py in a fresh Blender window; see the module docstring."""
    out = OUT / name
    shutil.rmtree(out, ignore_errors=True)
    out.mkdir(parents=True)
    scenario = SCENARIOS / f"{name}.py"
    assert scenario.is_file(), scenario
    proc = subprocess.run([str(GUIROOT), "bash", str(Path(__file__).resolve().parent / "xrun.sh"), str(out), str(scenario),
                           str(Path(zip_path).resolve()), str(timeout)],
                          capture_output=True, text=True, timeout=timeout + 120, cwd=REPO)
    log = (out / "blender.log").read_text(errors="replace") if (out / "blender.log").exists() else ""
    run = Run(name, out, log=proc.stdout + proc.stderr + log, returncode=proc.returncode)
    res = out / "result.json"
    if not res.exists():
        pytest.fail(f"no result.json: Blender died or hung (rc {proc.returncode})\n{run.describe()}")
    data = json.loads(res.read_text())
    run.result, run.error, run.shots, run.steps = data["result"], data["error"], data["shots"], data["steps"]
    return run


def scenario_result(name: str, zip_path: Path, timeout: int = 300) -> dict:
    """The result of a scenario that must run through: no error, no traceback in Blender's log."""
    run = run_scenario(name, zip_path, timeout)
    assert run.error is None, run.describe()
    assert not run.tracebacks, run.describe()
    return run.result
