"""A brush that paints normal edits on a rendered frame (Zubiaga et al. 2016 edit the
normal buffer interactively where compositors work).

The brush edits the frame's screen-space normal buffer under a stroke with the compositing
tools of ``rokeby.compositing`` (the Rust core's ``normals`` module) and recomposites only the
pixels the stroke reached (``RecompositeSession.window``: eqs. 3–5 are per pixel; the Rust
core holds the passes, reads the window of the normal-edit layer and writes the window of the
image in place, nothing repacked per dab), so each stroke step costs the dab's window, not the
frame:

* ``emboss``: the core's emboss (n_z → β n_z, β = ``EMBOSS_BETA``) blended in by strength × falloff:
  the surface under the stroke bulges, its shading gains contrast.
* ``bump``: a raised ridge along the stroke, the core's bump of the height
  h = ``BUMP_HEIGHT`` · strength · radius · falloff (pixels).
* ``smooth``: the core's cross-bilateral smoothing with depth (σ_s = radius / 4, 0.5 to 4
  pixels) blended in by strength × falloff: normal variation, and the shading's, drops.

The falloff of a stroke is the largest of its dabs' (1 − d²/r²)²₊ (dabs every radius/4 along
the stroke), so a stroke's result does not depend on how many steps delivered its points; each
stroke edits the normals as they were before it, and strokes accumulate. Pixels the stroke does
not reach keep their bits (normals and image).

``BrushSession`` holds one frame (``compositing.open_render``), the normal-edit layer, the
recomposited image and the strokes with what they replaced (to undo them). The Blender side:
``open_brush`` / ``paint_stroke`` write the result into a Blender image (``compositing.show_image``,
which keeps the compositor's Image node current) and record each stroke on that image (ID
properties ``schema.BRUSH_STROKES_KEY``, ``schema.BRUSH_SOURCE_KEY``), so that Blender's undo steps hold the strokes and
``sync_after_undo`` brings the pixels back in line; a file saved and opened again replays them.
"""

from __future__ import annotations

import itertools
import math
import time
from dataclasses import dataclass, field

import numpy as np

from .. import compositing as comp
from . import compositor_input
from ..core import schema

MODES = ("emboss", "bump", "smooth")
EMBOSS_BETA = 0.25  # β of the emboss at full strength and falloff
BUMP_HEIGHT = 0.5  # ridge height per unit strength, in brush radii
SMOOTH_SIGMA = (0.5, 4.0)  # σ_s = radius / 4, clamped to this (pixels)
MAX_RADIUS = 1000.0  # pixels

# ID properties on the brushed Blender image (saved in the .blend): schema.BRUSH_STROKES_KEY,
# schema.BRUSH_SOURCE_KEY and schema.BRUSH_BASE_KEY.
NO_BASE = {"edit": "none", "amount": 0.0, "k_d": 1.0, "k_r": 1.0, "fit": "qp", "noise_tolerance": 0.0}

_IDS = itertools.count(int(time.time() * 1000) % (1 << 30))


class BrushError(comp.CompositingError):
    pass


# --- the brush's maths ----------------------------------------------------------------------

def check_brush(radius, strength, mode) -> None:
    """A clear error for a radius that is not positive and finite, a strength outside (0, 1] or an
    unknown mode."""
    if isinstance(radius, bool) or not isinstance(radius, (int, float, np.integer, np.floating)) \
            or not (math.isfinite(radius) and 0 < radius <= MAX_RADIUS):
        raise BrushError(f"radius: must be a number of pixels above 0 and at most {MAX_RADIUS:g}, got {radius!r}")
    if isinstance(strength, bool) or not isinstance(strength, (int, float, np.integer, np.floating)) \
            or not (math.isfinite(strength) and 0 < strength <= 1):
        raise BrushError(f"strength: must be in (0, 1], got {strength!r}")
    if mode not in MODES:
        raise BrushError(f"mode: unknown {mode!r} (expected one of {', '.join(map(repr, MODES))})")


def stroke_points(points) -> np.ndarray:
    """``points`` as an (N, 2) float64 array of (row, col) pixels (row 0 at the top, pixel centres
    at whole numbers), checked: at least one, all finite."""
    try:
        p = np.asarray(points, np.float64)
    except (TypeError, ValueError):
        raise BrushError(f"stroke: expected (row, col) pixel positions, got {points!r}") from None
    if p.ndim == 1 and p.shape == (2,):
        p = p[None]
    if p.ndim != 2 or p.shape[1] != 2 or len(p) == 0:
        raise BrushError(f"stroke: expected at least one (row, col) pixel position, got an array of shape {p.shape}")
    if not np.isfinite(p).all():
        raise BrushError("stroke: the pixel positions must be finite")
    return p


def dabs(points: np.ndarray, radius: float, previous=None) -> np.ndarray:
    """The dab centres of a stroke through ``points`` ((N, 2) rows, cols), at most radius/4 apart:
    ``points`` themselves and evenly spaced ones between consecutive points (and from
    ``previous``, the stroke's last point so far, which is not repeated)."""
    step = max(radius / 4.0, 0.5)
    path = points if previous is None else np.vstack([np.asarray(previous, np.float64)[None], points])
    out = [] if previous is not None else [path[:1]]
    for a, b in zip(path[:-1], path[1:]):
        k = max(1, int(math.ceil(np.hypot(*(b - a)) / step)))
        t = np.arange(1, k + 1, dtype=np.float64)[:, None] / k
        out.append(a + t * (b - a))
    return np.vstack(out) if out else np.zeros((0, 2))


def falloff(centres: np.ndarray, radius: float, rows: slice, cols: slice) -> np.ndarray:
    """(h, w) float32 over the window rows × cols: the largest (1 − d²/r²)²₊ of the dabs
    ``centres`` (d: distance to a dab centre in pixels)."""
    r0, c0 = rows.start, cols.start
    h, w = rows.stop - r0, cols.stop - c0
    out = np.zeros((h, w), np.float32)
    reach = math.ceil(radius)
    for cy, cx in centres:
        y0, y1 = max(int(math.floor(cy)) - reach, r0), min(int(math.ceil(cy)) + reach + 1, r0 + h)
        x0, x1 = max(int(math.floor(cx)) - reach, c0), min(int(math.ceil(cx)) + reach + 1, c0 + w)
        if y0 >= y1 or x0 >= x1:
            continue
        yy = (np.arange(y0, y1, dtype=np.float64) - cy)[:, None]
        xx = (np.arange(x0, x1, dtype=np.float64) - cx)[None, :]
        f = np.clip(1.0 - (yy * yy + xx * xx) / (radius * radius), 0.0, None) ** 2
        sub = out[y0 - r0:y1 - r0, x0 - c0:x1 - c0]
        np.maximum(sub, f.astype(np.float32), out=sub)
    return out


def _blend(n: np.ndarray, e: np.ndarray, t: np.ndarray) -> np.ndarray:
    """unit((1 − t) n + t e) where t > 0 and the tool changed the normal; n (its bits) elsewhere."""
    changed = (t > 0) & (e != n).any(-1)
    m = (1.0 - t[..., None]) * n + t[..., None] * e
    norm = np.linalg.norm(m, axis=-1, keepdims=True)
    with np.errstate(invalid="ignore", divide="ignore"):
        m = np.where(norm > 1e-12, m / norm, 0.0).astype(np.float32)
    return np.where(changed[..., None], m, n)


def smooth_sigma(radius: float) -> float:
    return float(min(max(radius / 4.0, SMOOTH_SIGMA[0]), SMOOTH_SIGMA[1]))


def margin(mode: str, radius: float) -> int:
    """How many pixels beyond the pixels it changes a mode reads (the bump's central differences,
    the smoothing's window)."""
    if mode == "bump":
        return 1
    if mode == "smooth":
        return max(1, math.ceil(2.0 * smooth_sigma(radius)))
    return 0


def edit_window(mode: str, normals: np.ndarray, weight: np.ndarray, strength: float, radius: float,
                depth: np.ndarray, on: np.ndarray, smoothed: np.ndarray | None = None) -> np.ndarray:
    """The brush's edit of the normals (h, w, 3) of a window under the falloff ``weight`` (h, w),
    on the patches' pixels ``on``; ``depth`` for the smoothing (``smoothed``: the smoothed
    normals where weight > 0, when already computed). Pixels with zero weight keep their bits."""
    if mode == "emboss":
        return _blend(normals, comp.emboss(normals, EMBOSS_BETA, mask=on), strength * weight)
    if mode == "bump":
        return comp.bump(normals, (BUMP_HEIGHT * strength * radius) * weight, 1.0, mask=on & (weight > 0))
    if mode == "smooth":
        if smoothed is None:
            smoothed = comp.bilateral_smooth(normals, depth, sigma_s=smooth_sigma(radius), mask=on & (weight > 0))
        return _blend(normals, smoothed, strength * weight)
    raise BrushError(f"mode: unknown {mode!r} (expected one of {', '.join(map(repr, MODES))})")


# --- a frame open for painting ----------------------------------------------------------------

@dataclass
class Stroke:
    """One stroke: its dab path (the points given, (row, col) pixels), radius (pixels), strength
    and mode. ``ident`` tells strokes apart across undo steps."""

    points: np.ndarray
    radius: float
    strength: float
    mode: str
    ident: int = field(default_factory=lambda: next(_IDS))

    def record(self) -> dict:
        """The stroke as an ID property value (``schema.BRUSH_STROKES_KEY``)."""
        return {"id": int(self.ident), "mode": MODES.index(self.mode), "radius": float(self.radius),
                "strength": float(self.strength), "points": [float(x) for x in self.points.reshape(-1)]}

    @staticmethod
    def from_record(rec) -> "Stroke":
        mode = int(rec["mode"])
        if not 0 <= mode < len(MODES):
            raise BrushError(f"stroke record: unknown mode number {mode}")
        pts = np.asarray(list(rec["points"]), np.float64).reshape(-1, 2)
        return Stroke(pts, float(rec["radius"]), float(rec["strength"]), MODES[mode], int(rec["id"]))


@dataclass
class _Applied:
    stroke: Stroke
    rows: slice
    cols: slice
    normals: np.ndarray  # the layer's pixels in rows × cols before the stroke
    image: np.ndarray  # the recomposited pixels there before it


class BrushSession:
    """A rendered frame open for painting normal edits. ``layer``: the edited normals (H, W, 3);
    ``image``: the recomposited frame (H, W, 3) float32, top row first; ``strokes``: the strokes
    applied, oldest first. One stroke at a time is in progress (``begin`` … ``extend`` … ``end``
    or ``cancel``); ``paint`` does all of it for a stroke given whole."""

    def __init__(self, opened: "comp.RenderEdit", image_name: str | None = None, base: dict | None = None):
        self.opened = opened
        self.path = opened.path
        self.image_name = image_name
        rec, p = opened.reconstruction, opened.passes
        self.shape = p.shape
        # The strokes add to ``base``: the one-knob edit the image showed when the brush opened
        # it (Render and Recomposite's; none: the render itself, bit for bit).
        self.base_edit = {**NO_BASE, **(base or {})}
        b = self.base_edit
        self.k_d, self.k_r = float(b["k_d"]), float(b["k_r"])
        self.base = comp.edit_normals(p, rec, b["edit"], float(b["amount"])) if b["edit"] != "none" else rec.normals
        self.layer = np.array(self.base, np.float32, copy=True)
        self.on = rec.ids >= 0
        self.depth = p.depth
        self.image, _stats = opened.session(self.layer, k_d=self.k_d, k_r=self.k_r)
        self.image = np.ascontiguousarray(self.image, np.float32)
        h, w = self.shape
        self.rgba = np.ones((h, w, 4), np.float32)  # the image as Blender stores it: bottom row first, α = 1
        self.rgba[..., :3] = self.image[::-1]
        self._applied: list[_Applied] = []
        self._active = None
        self.timings: dict = {}

    @property
    def strokes(self) -> list:
        return [a.stroke for a in self._applied]

    @property
    def painting(self) -> bool:
        return self._active is not None

    def _put(self, rows: slice, cols: slice, pixels: np.ndarray) -> None:
        """Writes recomposited pixels into the window rows × cols of ``image`` and ``rgba``."""
        h = self.shape[0]
        self.image[rows, cols] = pixels
        self.rgba[h - rows.stop:h - rows.start, cols, :3] = pixels[::-1]

    def records(self) -> list:
        return [s.record() for s in self.strokes]

    # a stroke in steps (the modal operator)
    def begin(self, radius: float, strength: float, mode: str) -> None:
        check_brush(radius, strength, mode)
        if self._active is not None:
            raise BrushError("a stroke is already in progress: end or cancel it first")
        self._active = {"stroke": Stroke(np.zeros((0, 2)), float(radius), float(strength), mode), "dabs": np.zeros((0, 2)),
                        "before_n": self.layer.copy(), "before_i": self.image.copy(), "box": None}

    def extend(self, points) -> tuple | None:
        """Adds ``points`` ((row, col) pixels) to the stroke in progress and recomposites the pixels
        they reach; returns the window (rows, cols) that changed, or None when the new dabs miss the
        image."""
        a = self._active
        if a is None:
            raise BrushError("no stroke in progress: begin one first")
        t0 = time.perf_counter()
        pts = stroke_points(points)
        s = a["stroke"]
        new = dabs(pts, s.radius, s.points[-1] if len(s.points) else None)
        s.points = np.vstack([s.points, pts])
        a["dabs"] = np.vstack([a["dabs"], new])
        h, w = self.shape
        reach = math.ceil(s.radius) + margin(s.mode, s.radius) + 1
        lo, hi = np.floor(new.min(0)).astype(int) - reach, np.ceil(new.max(0)).astype(int) + reach + 1
        rows, cols = slice(max(lo[0], 0), min(hi[0], h)), slice(max(lo[1], 0), min(hi[1], w))
        if rows.start >= rows.stop or cols.start >= cols.stop:
            return None
        m = margin(s.mode, s.radius)
        rin = slice(max(rows.start - m, 0), min(rows.stop + m, h))
        cin = slice(max(cols.start - m, 0), min(cols.stop + m, w))
        near = a["dabs"][(a["dabs"][:, 0] > rin.start - s.radius) & (a["dabs"][:, 0] < rin.stop + s.radius)
                         & (a["dabs"][:, 1] > cin.start - s.radius) & (a["dabs"][:, 1] < cin.stop + s.radius)]
        weight = falloff(near, s.radius, rin, cin)
        smoothed = self._smoothed(a, rin, cin, weight) if s.mode == "smooth" else None
        edited = edit_window(s.mode, a["before_n"][rin, cin], weight, s.strength, s.radius, self.depth[rin, cin],
                             self.on[rin, cin], smoothed)
        inner = (slice(rows.start - rin.start, rows.stop - rin.start), slice(cols.start - cin.start, cols.stop - cin.start))
        self.layer[rows, cols] = edited[inner]
        t1 = time.perf_counter()
        # The core reads the window of the layer and writes it straight into the image.
        self.opened.session.window(self.layer, rows, cols, out=self.image, k_d=self.k_d, k_r=self.k_r)
        h = self.shape[0]
        self.rgba[h - rows.stop:h - rows.start, cols, :3] = self.image[rows, cols][::-1]
        box = a["box"]
        a["box"] = (rows, cols) if box is None else (slice(min(box[0].start, rows.start), max(box[0].stop, rows.stop)),
                                                      slice(min(box[1].start, cols.start), max(box[1].stop, cols.stop)))
        self.timings = {"edit_s": t1 - t0, "recomposite_s": time.perf_counter() - t1, "pixels": (rows.stop - rows.start) * (cols.stop - cols.start)}
        return rows, cols

    def _smoothed(self, a: dict, rin: slice, cin: slice, weight: np.ndarray) -> np.ndarray:
        """The smoothed normals before the stroke over the window, each pixel smoothed once per
        stroke (the smoothing reads only the normals before the stroke): the pixels the new dabs
        reach are within the window by the smoothing's margin."""
        if "smooth" not in a:
            a["smooth"] = np.zeros_like(self.layer)
            a["smooth_done"] = np.zeros(self.shape, bool)
        s = a["stroke"]
        need = self.on[rin, cin] & (weight > 0) & ~a["smooth_done"][rin, cin]
        if need.any():
            got = comp.bilateral_smooth(a["before_n"][rin, cin], self.depth[rin, cin], sigma_s=smooth_sigma(s.radius), mask=need)
            a["smooth"][rin, cin][need] = got[need]
            a["smooth_done"][rin, cin] |= need
        return a["smooth"][rin, cin]

    def end(self) -> Stroke | None:
        """Ends the stroke in progress: it becomes the last of ``strokes`` (None, and nothing
        recorded, when it never reached the image)."""
        a, self._active = self._active, None
        if a is None:
            raise BrushError("no stroke in progress: begin one first")
        if a["box"] is None:
            return None
        rows, cols = a["box"]
        self._applied.append(_Applied(a["stroke"], rows, cols, a["before_n"][rows, cols].copy(), a["before_i"][rows, cols].copy()))
        return a["stroke"]

    def cancel(self) -> None:
        """Drops the stroke in progress: normals and image as they were before it."""
        a, self._active = self._active, None
        if a is not None and a["box"] is not None:
            rows, cols = a["box"]
            self.layer[rows, cols] = a["before_n"][rows, cols]
            self._put(rows, cols, a["before_i"][rows, cols])

    def paint(self, points, radius: float, strength: float, mode: str) -> Stroke:
        """A whole stroke through ``points``; an error when none of its dabs reaches the image
        (nothing changes then)."""
        check_brush(radius, strength, mode)
        pts = stroke_points(points)
        self.begin(radius, strength, mode)
        try:
            self.extend(pts)
        except BaseException:
            self.cancel()
            raise
        stroke = self.end()
        if stroke is None:
            h, w = self.shape
            raise BrushError(f"stroke: every dab of radius {radius:g} lies outside the {w}×{h} image "
                             f"(points are (row, col) pixels, row 0 at the top; got {pts.tolist()[:4]})")
        return stroke

    def undo(self) -> Stroke:
        """Takes the last stroke back (normals and image bit for bit as before it)."""
        if self._active is not None:
            self.cancel()
        if not self._applied:
            raise BrushError("no stroke to undo")
        a = self._applied.pop()
        self.layer[a.rows, a.cols] = a.normals
        self._put(a.rows, a.cols, a.image)
        return a.stroke

    def sync(self, records) -> bool:
        """Makes the strokes those of ``records`` (``Stroke.record`` dicts, oldest first: what an
        undo or redo step left on the image): strokes after the first difference are undone, the
        records' strokes from there applied. Returns whether anything changed."""
        want = [Stroke.from_record(r) for r in records]
        have = self.strokes
        k = 0
        while k < min(len(want), len(have)) and want[k].ident == have[k].ident:
            k += 1
        if k == len(want) == len(have):
            return False
        while len(self._applied) > k:
            self.undo()
        for s in want[k:]:
            self.begin(s.radius, s.strength, s.mode)
            self._active["stroke"].ident = s.ident
            self.extend(s.points)
            self.end()
        return True


# --- Blender: the image, the sessions, undo ---------------------------------------------------

_SESSIONS: dict = {}  # image name → BrushSession


def session_for(image_name: str) -> BrushSession:
    """The brush session painting the image ``image_name``."""
    s = _SESSIONS.get(image_name)
    if s is None:
        raise BrushError(f"image '{image_name}': no brush is open on it (click Paint Normals in the Image Editor's "
                         "Rokeby tab, with a frame rendered by Render and Recomposite)")
    return s


def has_session(image_name: str) -> bool:
    return image_name in _SESSIONS


def close_all() -> None:
    _SESSIONS.clear()


def _show(session: BrushSession):
    img = comp.show_image(session.image_name, session.image)  # keeps the compositor's Image node current
    img[schema.BRUSH_SOURCE_KEY] = session.path
    return img


def _record(session: BrushSession, img) -> None:
    img[schema.BRUSH_STROKES_KEY] = session.records()
    if session.strokes:
        img.use_fake_user = True  # painted: kept in the file (with its strokes) even where no editor shows it


def open_brush(path: str, image_name: str = schema.RECOMPOSITED_IMAGE, *, fit: str = "qp",
               noise_tolerance: float = 0.0):
    """Opens the multilayer EXR ``path`` (rendered with the compositing passes) for painting on
    the Blender image ``image_name`` and shows it there: the render recomposited with the strokes
    the image records for this file (none for a new image: the render itself). Reuses the frame
    ``compositing.open_render`` keeps, and the session already open on the image for the same
    file. Returns the ``BrushSession``."""
    import bpy  # noqa: PLC0415

    if not image_name:
        raise BrushError("image_name: give the name of the image to paint on")
    img = bpy.data.images.get(image_name)
    shown = img is not None and img.get(schema.BRUSH_SOURCE_KEY) == path and img.get(schema.BRUSH_BASE_KEY) is not None
    base = img[schema.BRUSH_BASE_KEY].to_dict() if shown else None
    if base is not None:  # the image shows a one-knob edit: the strokes go on top of it, with its fit
        fit, noise_tolerance = str(base.get("fit", fit)), float(base.get("noise_tolerance", noise_tolerance))
    opened = comp.open_render(path, backend="cpu", warn=False, method=fit, noise_tolerance=noise_tolerance)
    s = _SESSIONS.get(image_name)
    if s is None or s.opened is not opened or s.opened.reconstructed or s.base_edit != {**NO_BASE, **(base or {})}:
        s = BrushSession(opened, image_name, base)
        _SESSIONS[image_name] = s
    if img is not None and img.get(schema.BRUSH_SOURCE_KEY) == path:
        s.sync(list(img.get(schema.BRUSH_STROKES_KEY, [])))
    img = _show(s)
    _record(s, img)
    return s


def record_edit(img, path: str, *, edit: str, amount: float, k_d: float = 1.0, k_r: float = 1.0, fit: str = "qp",
                noise_tolerance: float = 0.0) -> None:
    """Records on the Blender image ``img`` that it now shows the one-knob edit of the EXR ``path``
    (Render and Recomposite, Recomposite Render) and no strokes: Paint Normals opened on it
    starts from what it shows. A brush open on the image is closed (its pixels are replaced)."""
    img[schema.BRUSH_SOURCE_KEY] = path
    img[schema.BRUSH_BASE_KEY] = {"edit": str(edit), "amount": float(amount), "k_d": float(k_d), "k_r": float(k_r), "fit": str(fit),
                     "noise_tolerance": float(noise_tolerance)}
    img[schema.BRUSH_STROKES_KEY] = []
    _SESSIONS.pop(img.name, None)


def show_step(session: BrushSession):
    """Writes the session's image into its Blender image (the compositor's node follows): the
    whole image from the session's Blender-ordered copy, without reordering it per step."""
    import bpy  # noqa: PLC0415

    img = bpy.data.images.get(session.image_name)
    h, w = session.shape
    if img is None or tuple(img.size) != (w, h) or not img.is_float or img.get(schema.BRUSH_SOURCE_KEY) != session.path:
        return _show(session)
    img.pixels.foreach_set(session.rgba.reshape(-1))
    img.update()
    compositor_input._keep_compositor_current(img)
    return img


def finish_stroke(session: BrushSession):
    """Ends the stroke in progress and records the strokes on the image (the next undo step
    holds them). Returns the stroke (None if it never reached the image)."""
    stroke = session.end()
    img = show_step(session)
    _record(session, img)
    return stroke


def paint_stroke(session: BrushSession, points_px, radius: float, strength: float, mode: str) -> dict:
    """Paints one stroke through ``points_px`` ((row, col) pixels of the frame, row 0 at the
    top) with ``radius`` pixels, ``strength`` in (0, 1] and ``mode`` ('emboss', 'bump',
    'smooth'), writes the result into the session's Blender image and records the stroke on it.
    Returns {'stroke', 'changed_pixels', 'seconds'}. Background scripts push an undo step
    themselves (``bpy.ops.ed.undo_push``) if they want one per stroke, as the operator does."""
    if session is None:
        raise BrushError("session: none given (open the frame for painting first)")
    t0 = time.perf_counter()
    before = session.image.copy()
    stroke = session.paint(points_px, radius, strength, mode)
    if session.image_name:
        img = show_step(session)
        _record(session, img)
    changed = int((session.image != before).any(-1).sum())
    return {"stroke": stroke, "changed_pixels": changed, "seconds": time.perf_counter() - t0}


def sync_after_undo() -> int:
    """undo_post / redo_post: each open brush takes the strokes the step left on its image and,
    where they changed, shows them. Returns how many images changed."""
    import bpy  # noqa: PLC0415

    done = 0
    for name, s in list(_SESSIONS.items()):
        img = bpy.data.images.get(name)
        if img is None or img.get(schema.BRUSH_SOURCE_KEY, s.path) != s.path:
            s.cancel()
            continue
        was_painting = s.painting  # (not from the UI: the brush holds Ctrl+Z until the stroke ends)
        s.cancel()
        # Only when the strokes changed: undo keeps an image's pixels as they are, and they may be
        # another edit's now (Recomposite Render into the same image), which an unrelated undo
        # must not overwrite.
        if s.sync(list(img.get(schema.BRUSH_STROKES_KEY, []))) or was_painting:
            show_step(s)
            done += 1
    return done


# --- the Image Editor's coordinates -----------------------------------------------------------

def view_to_pixel(u: float, v: float, size) -> tuple:
    """(row, col) pixel of the point (u, v) of an Image Editor's view (0..1 across the image, v up)
    on an image of ``size`` (width, height): rows from the top, pixel centres at whole numbers."""
    w, h = size
    return (1.0 - v) * h - 0.5, u * w - 0.5


def region_to_pixel(region, size, x: float, y: float) -> tuple:
    """(row, col) of the image pixel under region coordinates (x, y) of an Image Editor."""
    u, v = region.view2d.region_to_view(x, y)
    return view_to_pixel(u, v, size)
