"""Runs inside a real Blender window (``blender --python driver.py -- OUT SCENARIO ZIP``): loads the
scenario file, calls its ``scenario(ui)`` generator and steps it from ``bpy.app.timers``, so that
Blender's event loop (drawing, X input, modal operators) runs between the steps. What the scenario
yields says when to continue:

- ``yield`` (None): on the next timer tick (~0.05 s);
- ``yield 0.5``: after that many seconds (use sparingly: wait on state with ``ui.until``);
- ``yield from ui.until(pred, timeout, what)``: when ``pred()`` is true (polled every 0.1 s).

The scenario fills ``ui.result`` (a JSON-able dict); when it ends, or raises, the driver writes
OUT/result.json (``result``, ``error`` with the traceback or None, ``shots``, ``steps``) and exits
Blender. The ``UI`` class below is the whole API a scenario uses (see tests/gui/README.md)."""

from __future__ import annotations

import importlib.util
import json
import os
import subprocess
import sys
import time
import traceback

import bpy

ARGS = sys.argv[sys.argv.index("--") + 1:]
OUT, SCENARIO, ZIP = ARGS[0], ARGS[1], ARGS[2]
ADDON = "bl_ext.user_default.rokeby"


class UI:
    """What a scenario drives the window with: X input (xdotool), waiting on state, screenshots,
    screen coordinates of regions and 3D points, and the add-on's install."""

    def __init__(self):
        self.out = OUT
        self.zip = ZIP
        self.result: dict = {}
        self.shots: list = []
        self.log: list = []

    # --- state ---------------------------------------------------------------------------------
    def note(self, text: str) -> None:
        """A line in result.json's ``steps`` and on stdout (what the scenario was doing)."""
        line = f"{time.monotonic() - T0:7.2f} s  {text}"
        self.log.append(line)
        print("[gui]", line, flush=True)

    @property
    def window(self):
        return bpy.context.window_manager.windows[0]

    def area(self, kind: str = "VIEW_3D"):
        """The largest area of ``kind`` in the window."""
        areas = [a for a in self.window.screen.areas if a.type == kind]
        return max(areas, key=lambda a: a.width * a.height) if areas else None

    def region(self, kind: str = "WINDOW", area=None):
        area = area or self.area()
        return next(r for r in area.regions if r.type == kind)

    def override(self, area=None, region_type: str = "WINDOW"):
        """A context override on the window (and an area and its region): ``with ui.override(): ...``."""
        area = area or self.area()
        if area is None:
            return bpy.context.temp_override(window=self.window, screen=self.window.screen)
        return bpy.context.temp_override(window=self.window, screen=self.window.screen, area=area,
                                         region=self.region(region_type, area))

    def now(self) -> float:
        """Seconds on a monotonic clock (for durations a scenario reports)."""
        return time.monotonic()

    # --- waiting --------------------------------------------------------------------------------
    def until(self, pred, timeout: float = 60.0, what: str | None = None):
        """``yield from ui.until(pred)``: continue when ``pred()`` is true; TimeoutError after ``timeout`` s.
        Returns pred's value."""
        t = time.monotonic()
        while True:
            try:
                ok = pred()
            except Exception:  # noqa: BLE001 - not there yet (a region not made, an object not added)
                ok = False
            if ok:
                return ok
            if time.monotonic() - t > timeout:
                raise TimeoutError(f"waited {timeout:.0f} s for {what or getattr(pred, '__name__', pred)}")
            yield 0.1

    def redraws(self, n: int = 2):
        """``yield from ui.redraws()``: draw the whole window ``n`` times now (wm.redraw_timer, which
        returns once drawn and swapped), a timer tick after each so that queued events are handled:
        afterwards the screen, sidebar included, shows the current state."""
        for _ in range(n):
            with bpy.context.temp_override(window=self.window):
                bpy.ops.wm.redraw_timer(type="DRAW_WIN_SWAP", iterations=1)
            yield 0.02

    # --- X input ----------------------------------------------------------------------------------
    def xdo(self, *args) -> None:
        subprocess.run(["xdotool", *map(str, args)], check=True, timeout=30)

    def move(self, x: float, y: float):
        """``yield from ui.move(x, y)``: the pointer to screen pixel (x, y) (top-left origin), then one tick."""
        self.xdo("mousemove", int(round(x)), int(round(y)))
        yield 0.05

    def press(self, button: int = 1):
        self.xdo("mousedown", button)
        yield 0.05

    def release(self, button: int = 1):
        self.xdo("mouseup", button)
        yield 0.05

    def click(self, x: float, y: float, button: int = 1, settle: int = 1):
        """Move, press and release as separate steps (a click sent at once can be swallowed after a
        tooltip), each followed by ``settle`` redraws of the window region."""
        yield from self.move(x, y)
        yield from self.redraws(settle)
        yield from self.press(button)
        yield from self.release(button)
        yield from self.redraws(settle)

    def drag(self, points, settle: int = 1):
        """Press at ``points[0]``, move through the others, release: a press-drag-release with the
        window drawn ``settle`` times after each step, and twice after the release."""
        yield from self.move(*points[0])
        yield from self.redraws(settle)
        yield from self.press()
        yield from self.redraws(settle)
        for x, y in points[1:]:
            yield from self.move(x, y)
            yield from self.redraws(settle)
        yield from self.release()
        yield from self.redraws(2)

    def search(self, text: str, run: bool = True):
        """F3 (the operator search) under the pointer, ``text`` typed; Return runs the first match
        unless ``run`` is False (the menu left open)."""
        yield from self.key("F3")
        yield from self.redraws(2)
        yield from self.type(text)
        yield from self.redraws(3)
        if run:
            yield from self.key("Return")
            yield from self.redraws(2)

    def key(self, *keys: str):
        """``yield from ui.key("g")``, ``ui.key("ctrl+z")``, ``ui.key("shift+alt+c")``: xdotool key names."""
        self.xdo("key", *keys)
        yield 0.05

    def type(self, text: str):
        self.xdo("type", "--delay", 20, text)
        yield 0.05

    # --- coordinates --------------------------------------------------------------------------------
    def screen_xy(self, region, rx: float, ry: float) -> tuple:
        """Screen pixel (top-left origin, what xdotool takes) of region pixel (rx, ry) (bottom-left origin)."""
        return region.x + rx, self.window.height - (region.y + ry)

    def point_xy(self, p, area=None) -> tuple:
        """Screen pixel of the 3D point ``p`` in the 3D view ``area`` (default: the largest)."""
        from bpy_extras.view3d_utils import location_3d_to_region_2d

        region = self.region("WINDOW", area)
        q = location_3d_to_region_2d(region, region.data, p)
        if q is None:
            raise ValueError(f"{tuple(p)} is behind the view")
        return self.screen_xy(region, q.x, q.y)

    # --- pictures ---------------------------------------------------------------------------------
    def screenshot(self, name: str, crop=None) -> str:
        """The whole X screen as OUT/<name>.png (ImageMagick's import); ``crop`` = (x, y, w, h) in screen
        pixels keeps a part (a region: ``ui.region_box(region)``)."""
        path = os.path.join(self.out, f"{name}.png")
        cmd = ["import", "-window", "root"]
        if crop is not None:
            x, y, w, h = (int(v) for v in crop)
            cmd += ["-crop", f"{w}x{h}+{x}+{y}", "+repage"]
        subprocess.run([*cmd, path], check=True, timeout=60)
        self.shots.append(os.path.basename(path))
        self.note(f"screenshot {name}.png")
        return path

    def region_box(self, region) -> tuple:
        """(x, y, w, h) of a region in screen pixels (top-left origin), for ``screenshot(crop=...)``."""
        return region.x, self.window.height - region.y - region.height, region.width, region.height

    # --- the add-on ---------------------------------------------------------------------------------
    def install(self):
        """``yield from ui.install()``: the zip through Install from Disk into the user repository,
        enabled on install (as Edit ▸ Preferences ▸ Get Extensions ▸ Install from Disk does)."""
        with bpy.context.temp_override(window=self.window):
            r = bpy.ops.extensions.package_install_files(filepath=self.zip, repo="user_default", enable_on_install=True)
        self.note(f"package_install_files: {r}")
        yield from self.until(lambda: ADDON in bpy.context.preferences.addons, 60, "the add-on enabled")
        return sys.modules[ADDON]

    def start(self):
        """``yield from ui.start()``: what every scenario opens with: the window up, the splash
        dismissed with Esc, the zip installed and enabled (``install``); returns the add-on."""
        yield from self.until(lambda: self.area() is not None, 60, "the window")
        yield from self.move(800, 500)
        yield from self.key("Escape")  # the splash
        yield from self.redraws(2)
        return (yield from self.install())

    def pixels(self, path: str):
        """A screenshot's pixels as a float array (H, W, 4) in [0, 1], row 0 at the top (screen
        order, as ``screen_xy`` counts), read with Blender's image loader."""
        import numpy as np

        img = bpy.data.images.load(path)
        try:
            w, h = img.size
            px = np.empty(w * h * 4, np.float32)
            img.pixels.foreach_get(px)
        finally:
            bpy.data.images.remove(img)
        return px.reshape(h, w, 4)[::-1]

    def addon(self, sub: str = ""):
        """The installed add-on's package (``bl_ext.user_default.rokeby``), or one of its modules:
        ``ui.addon("api")`` is rokeby.api, ``ui.addon("appearance.preview")``."""
        import importlib

        return importlib.import_module(ADDON + (f".{sub}" if sub else ""))

    def show_sidebar_tab(self, category: str = "Rokeby", area=None):
        """``yield from ui.show_sidebar_tab()``: the 3D view's sidebar shown and its ``category`` tab
        made active by clicking the tabs (the tab is read-only from Python): the tab strip at the
        sidebar's right edge is clicked from the top down until ``category`` is active."""
        area = area or self.area()
        area.spaces.active.show_region_ui = True
        yield from self.redraws(2)
        ui_region = self.region("UI", area)
        scale = bpy.context.preferences.system.ui_scale
        x = ui_region.width - 10 * scale
        for ry in range(ui_region.height - int(15 * scale), 0, -int(24 * scale)):
            if ui_region.active_panel_category == category:
                break
            before = ui_region.active_panel_category
            yield from self.click(*self.screen_xy(ui_region, x, ry))
            yield from self._settle(lambda before=before: ui_region.active_panel_category != before, 1.5)
        if ui_region.active_panel_category != category:
            raise RuntimeError(f"no sidebar tab {category!r} (active: {ui_region.active_panel_category!r})")
        yield from self.redraws(2)
        return ui_region

    def _settle(self, pred, seconds: float):
        """Continue when ``pred()`` is true or after ``seconds`` (for something that may not happen)."""
        t = time.monotonic()
        while time.monotonic() - t < seconds and not pred():
            yield 0.1


T0 = time.monotonic()
ui = UI()
_state = {"gen": None, "error": None, "done": False}


def _finish():
    payload = {"result": ui.result, "error": _state["error"], "shots": ui.shots, "steps": ui.log,
               "blender": bpy.app.version_string, "seconds": round(time.monotonic() - T0, 2)}
    with open(os.path.join(OUT, "result.json"), "w") as f:
        json.dump(payload, f, indent=1, default=str)
    print("[gui] done in", payload["seconds"], "s", "(error)" if _state["error"] else "", flush=True)
    sys.stdout.flush()
    sys.stderr.flush()
    # No save prompt, no clean-up that could hang: the results are written.
    os._exit(0)


def _step():
    gen = _state["gen"]
    try:
        if gen is None:
            sys.path.insert(0, os.path.dirname(SCENARIO))  # scenarios import their shared scenes.py
            spec = importlib.util.spec_from_file_location("gui_scenario", SCENARIO)
            mod = importlib.util.module_from_spec(spec)
            spec.loader.exec_module(mod)
            gen = _state["gen"] = mod.scenario(ui)
        wait = next(gen)
    except StopIteration:
        _finish()
        return None
    except BaseException:  # noqa: BLE001 - reported in result.json
        _state["error"] = traceback.format_exc()
        print(_state["error"], file=sys.stderr, flush=True)
        try:
            ui.screenshot("error")
        except Exception:  # noqa: BLE001
            pass
        _finish()
        return None
    return 0.05 if wait is None else max(0.01, float(wait))


# The first step after the window is up and the file loaded.
bpy.app.timers.register(_step, first_interval=0.5, persistent=True)
