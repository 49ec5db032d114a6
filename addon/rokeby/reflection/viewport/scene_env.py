"""The scene seen from each previewed mirror: what the viewport preview looks e(q) up in.

The paper (§6.3) renders one cube map of the scene from the centre of every reflecting object
and reads the edited direction from it. Rokeby captures an equirectangular panorama from the
mirror's centre (``reflmap.capture_origin``) with Cycles (``reflmap._render_panorama``: the same
renderer, materials, lights and world as F12; the mirror hidden from camera rays only, so it still
shadows and lights the rest as in F12; the add-on's handles are empties and never render), plus the distance of every texel from the centre. The preview shader
stores 1/distance beside the colour (0 where the world is seen) and corrects the lookup for the
point q on the surface (``rk_scene_lookup`` in shaders/rokeby_field_lib.glsl): near objects land
where a ray from q, not from the centre, meets them.

Kept current, never in the way:

- a capture is redone only when what it shows changed: ``fingerprint`` digests the capture point,
  its settings, the world, and every other object that renders (transform, evaluated vertex
  positions, materials and their node values, lights' settings). Handles are empties and the
  field the mirror stores changes no vertex position, so handle drags never recapture;
- in a window, depsgraph updates only mark the previews dirty; a timer captures once the updates
  have paused for ``DEBOUNCE_SECONDS`` and no transform runs (a transform in progress postpones it
  until it is confirmed or cancelled), with
  progress shown on the cursor while it renders;
- captures are cached per mirror (runtime only, never saved: a reload recaptures on first draw);
  ``stats`` counts them, and each records its time and memory for the sidebar and ``make bench``.

Background mode (scripts, tests) has no event loop: ``ensure`` captures synchronously.
"""

from __future__ import annotations

import hashlib
import time
from dataclasses import dataclass

import numpy as np

from ...blender import compat
from ..render import reflmap
from . import gpu_capture

DEFAULT_WIDTH = 256  # panorama width (height = width / 2)
DEFAULT_SAMPLES = 16
DEBOUNCE_SECONDS = 0.4


@dataclass
class SceneCapture:
    """One mirror's capture: ``texels`` (H, W, 4) float32, linear RGB and 1/distance from
    ``origin`` (0 where the world is seen), row 0 at the bottom, Blender's lat-long convention."""

    texels: np.ndarray
    origin: np.ndarray
    fingerprint: str
    seconds: float
    width: int
    samples: int
    serial: int
    world_image: str = ""  # the world's lat-long image standing in for the world's texels ("" for none)
    world_scale: tuple | None = None  # its scale to the capture (the Background strength and colour nodes)
    route: str = "CYCLES"  # CYCLES (as F12 renders) or VIEWPORT (drawn on the GPU as the 3D view draws)
    stages: dict | None = None  # seconds per stage of a VIEWPORT capture (views, triangles, distance, resample)
    look: str = ""  # a VIEWPORT capture: the 3D view's shading it was drawn with (gpu_capture.look_of)

    @property
    def nbytes(self) -> int:
        return int(self.texels.nbytes)

    @property
    def colour(self) -> np.ndarray:
        return self.texels[..., :3]

    @property
    def distance(self) -> np.ndarray:
        with np.errstate(divide="ignore"):
            return np.where(self.texels[..., 3] > 0, 1.0 / self.texels[..., 3], np.inf)


_captures: dict = {}  # mirror session_uid -> SceneCapture
_dirty = False
_pending = False
_last_change = 0.0
_serial = 0
stats = {"captures": 0, "fingerprints": 0}


def _key(mirror):
    return mirror.session_uid


def current(mirror) -> SceneCapture | None:
    """The cached capture of ``mirror`` (maybe stale until the next refresh), or None."""
    return _captures.get(_key(mirror))


def forget(mirror=None):
    """Drop the cached capture of ``mirror`` (of every mirror with None)."""
    if mirror is None:
        _captures.clear()
    else:
        _captures.pop(_key(mirror), None)


# --- what a capture shows ------------------------------------------------------------------------

_SKIPPED_TYPES = {"EMPTY", "CAMERA", "ARMATURE", "SPEAKER", "LIGHT_PROBE", "LIGHTPROBE"}


def _socket_values(h, tree, seen):
    """Digest a node tree's nodes, values and links into ``h`` (group trees once each)."""
    if tree is None or tree.as_pointer() in seen:
        return
    seen.add(tree.as_pointer())
    for node in tree.nodes:
        h.update(f"{node.bl_idname}|{node.name}|{node.mute}|".encode())
        for sock in node.inputs:
            value = getattr(sock, "default_value", None)
            if value is not None and not sock.is_linked:
                h.update(repr(tuple(value) if hasattr(value, "__len__") and not isinstance(value, str) else value).encode())
        image = getattr(node, "image", None)
        if image is not None:
            h.update(f"img|{image.name}|{image.filepath}|{image.is_dirty}".encode())
        sub = getattr(node, "node_tree", None)
        if sub is not None:
            _socket_values(h, sub, seen)
    for link in tree.links:
        h.update(f"{link.from_node.name}.{link.from_socket.identifier}>{link.to_node.name}.{link.to_socket.identifier}".encode())


def fingerprint(mirror, scene, depsgraph=None, *, width: int = DEFAULT_WIDTH, samples: int = DEFAULT_SAMPLES, route: str = "CYCLES",
                look: str = "") -> str:
    """A digest of everything a capture of ``mirror`` shows: the capture point and settings (the
    route, and for a VIEWPORT capture the 3D view's shading, ``look``), the world, and every other
    rendering object's transform, evaluated vertex positions, materials (node values) and light
    settings. Empties (the handles) are left out."""
    import bpy  # noqa: PLC0415

    stats["fingerprints"] += 1
    dg = depsgraph if depsgraph is not None else bpy.context.evaluated_depsgraph_get()
    h = hashlib.blake2b(digest_size=16)
    h.update(np.round(reflmap.capture_origin(mirror, dg), 6).tobytes())
    h.update(f"{width}|{samples}|{route}|{look}".encode())
    world = scene.world
    h.update(repr(world.name if world else None).encode())
    seen: set = set()
    if world is not None and compat.node_tree_of(world) is not None:
        _socket_values(h, world.node_tree, seen)
    elif world is not None:
        h.update(repr(tuple(world.color)).encode())
    for ob in sorted(scene.objects, key=lambda o: o.name):
        if ob == mirror or ob.type in _SKIPPED_TYPES:
            continue
        if ob.hide_render or not ob.visible_get():
            h.update(f"{ob.name}|hidden".encode())
            continue
        ev = ob.evaluated_get(dg)
        h.update(f"{ob.name}|{ob.type}|{getattr(ob.data, 'name', '')}|".encode())
        h.update(np.array(ev.matrix_world, dtype=np.float64).round(7).tobytes())
        if ob.type == "LIGHT":
            light = ob.data
            for attr in ("type", "energy", "color", "shadow_soft_size", "spot_size", "spot_blend", "angle", "size", "size_y", "shape"):
                value = getattr(light, attr, None)
                h.update(repr(tuple(value) if hasattr(value, "__len__") and not isinstance(value, str) else value).encode())
            if compat.node_tree_of(light) is not None:
                _socket_values(h, light.node_tree, seen)
            continue
        data = ev.data
        if ob.type == "MESH" and data is not None:
            co = np.empty(len(data.vertices) * 3, np.float32)
            data.vertices.foreach_get("co", co)
            h.update(co.tobytes())
            h.update(str(len(data.polygons)).encode())
        for slot in ob.material_slots:
            mat = slot.material
            h.update(repr(mat.name if mat else None).encode())
            if mat is not None:
                h.update(repr(tuple(mat.diffuse_color)).encode())
                if compat.node_tree_of(mat) is not None:
                    _socket_values(h, mat.node_tree, seen)
    return h.hexdigest()


def world_image(scene):
    """The world's Environment Texture image (equirectangular, not muted), or None."""
    world = scene.world
    if world is not None and compat.node_tree_of(world) is not None:
        for node in world.node_tree.nodes:
            if node.type == "TEX_ENVIRONMENT" and node.image is not None and node.projection == "EQUIRECTANGULAR" and not node.mute:
                return node.image
    return None


def fit_world(texels: np.ndarray, image) -> tuple | None:
    """The per-channel scale taking ``image`` (the world's lat-long image) to the world's texels
    of a capture (1/distance = 0), or None where the image does not explain them (a world with a
    texture mapping or colour nodes other than a scale, or too few world texels to tell)."""
    w, h = image.size
    if w < 2 or h < 2:
        return None
    px = np.empty(w * h * image.channels, np.float32)
    image.pixels.foreach_get(px)
    px = px.reshape(h, w, image.channels)[..., :3]
    ch, cw = texels.shape[:2]
    # the image averaged over each capture texel (box), as the capture's pixel filter does
    if h % ch == 0 and w % cw == 0:
        img = px.reshape(ch, h // ch, cw, w // cw, 3).mean((1, 3))
    else:
        from ...core import latlong  # noqa: PLC0415

        u, v = np.meshgrid((np.arange(cw) + 0.5) / cw, (np.arange(ch) + 0.5) / ch)
        img = reflmap.sample(px, latlong.uv_to_direction(u, v))
    world = texels[..., 3] == 0
    # away from objects: texels whose neighbours are world too
    inner = world & np.roll(world, 1, 0) & np.roll(world, -1, 0) & np.roll(world, 1, 1) & np.roll(world, -1, 1)
    if inner.sum() < 64:
        return None
    a, b = img[inner].astype(np.float64), texels[inner][:, :3].astype(np.float64)
    # ratio of sums without the brightest texels (a sun's few texels would decide a fit alone)
    keep = a.sum(1) <= np.percentile(a.sum(1), 99)
    a, b = a[keep], b[keep]
    scale = b.sum(0) / np.maximum(a.sum(0), 1e-30)
    if not np.all(np.isfinite(scale)) or np.any(scale < 0):
        return None
    resid = np.abs(a * scale - b).sum() / max(np.abs(b).sum(), 1e-30)
    # Texel averages of a detailed HDR differ from point samples by ~10%; a wrong mapping by far more.
    return tuple(float(x) for x in scale) if resid < 0.25 else None


# --- capturing -----------------------------------------------------------------------------------


def route_of(scene) -> tuple:
    """(route, 3D view or None): VIEWPORT with the view it draws like where the add-on preferences
    ask for the GPU capture and a window shows ``scene``; else CYCLES."""
    import bpy  # noqa: PLC0415

    from ...blender import prefs  # noqa: PLC0415

    if not bpy.app.background and getattr(prefs.get(), "scene_capture", "CYCLES") == "VIEWPORT":
        view = gpu_capture.view_of(scene)
        if view is not None:
            return "VIEWPORT", view
    return "CYCLES", None


def capture(mirror, scene=None, *, width: int = DEFAULT_WIDTH, samples: int = DEFAULT_SAMPLES, denoise: bool = False, depsgraph=None,
            route: str | None = None) -> SceneCapture:
    """Capture the scene around ``mirror`` now (colour and distance) and cache it: with Cycles, or
    (``route`` VIEWPORT; default: ``route_of``) on the GPU as the largest 3D view showing the
    scene draws it (``gpu_capture``)."""
    global _serial
    import bpy  # noqa: PLC0415

    scene = scene if scene is not None else bpy.context.scene
    reflmap._resolution(width)
    chosen, view = route_of(scene)
    if route == "VIEWPORT" and view is None:
        view = gpu_capture.view_of(scene)
        if view is None:
            raise LookupError("route: VIEWPORT needs a 3D view showing the scene (a window); none is open")
    route = route or chosen
    dg = depsgraph if depsgraph is not None else bpy.context.evaluated_depsgraph_get()
    origin = reflmap.capture_origin(mirror, dg)
    t0 = time.perf_counter()
    stages, look = None, ""
    if route == "VIEWPORT":
        colour, dist, stages, look = gpu_capture.capture(mirror, scene, origin, width, view=view)
        dg = bpy.context.evaluated_depsgraph_get()
    else:
        colour, dist = reflmap._render_panorama(scene, mirror, origin, width, int(samples), distance=True, denoise=denoise, camera_only=True)
    seconds = time.perf_counter() - t0
    print_ = fingerprint(mirror, scene, dg, width=width, samples=samples, route=route, look=look)
    texels = np.empty(colour.shape[:2] + (4,), np.float32)
    texels[..., :3] = np.nan_to_num(colour, nan=0.0, posinf=0.0, neginf=0.0)
    with np.errstate(divide="ignore"):
        texels[..., 3] = np.where(np.isfinite(dist) & (dist > 0), 1.0 / dist, 0.0)
    _serial += 1
    stats["captures"] += 1
    image = world_image(scene) if route == "CYCLES" else None  # the viewport draws its own background
    scale = fit_world(texels, image) if image is not None else None
    cap = SceneCapture(texels, origin, print_, seconds, width, int(samples), _serial,
                       world_image=image.name if scale is not None else "", world_scale=scale, route=route, stages=stages, look=look)
    _captures[_key(mirror)] = cap
    return cap


def _settings(scene, cap) -> tuple:
    """(route, look) a capture of ``scene`` would be taken with now (see ``route_of``); a 3D view
    showing another shading than Solid keeps ``cap``'s look (the capture draws Solid shading)."""
    route, view = route_of(scene)
    look = gpu_capture.look_of(view[2]) if view is not None else ""
    if route == "VIEWPORT" and not look and cap is not None:
        look = cap.look
    return route, look


def is_current(mirror, scene, depsgraph=None) -> bool:
    cap = current(mirror)
    if cap is None:
        return False
    route, look = _settings(scene, cap)
    return cap.fingerprint == fingerprint(mirror, scene, depsgraph, width=cap.width, samples=cap.samples, route=route, look=look)


def ensure(mirror, scene=None, *, width: int | None = None, samples: int | None = None, depsgraph=None) -> SceneCapture:
    """The capture of ``mirror``, captured again only when what it shows changed (or settings)."""
    import bpy  # noqa: PLC0415

    scene = scene if scene is not None else bpy.context.scene
    cap = current(mirror)
    width = width or (cap.width if cap is not None else DEFAULT_WIDTH)
    samples = samples or (cap.samples if cap is not None else DEFAULT_SAMPLES)
    route, look = _settings(scene, cap)
    if cap is not None and cap.width == width and cap.samples == samples \
            and cap.fingerprint == fingerprint(mirror, scene, depsgraph, width=width, samples=samples, route=route, look=look):
        return cap
    return capture(mirror, scene, width=width, samples=samples, depsgraph=depsgraph)


def previewed(scene) -> list:
    """The mirrors of ``scene`` whose preview is drawn (the scene switch on, the mirror's too)."""
    from ...core import schema  # noqa: PLC0415
    from .. import scene_inputs  # noqa: PLC0415

    if not getattr(scene, schema.SCENE_VIEWPORT_PREVIEW_PROP, False):
        return []
    return [ob for ob in scene_inputs.mirrors_of(scene) if ob.type == "MESH" and ob.rokeby.enabled and ob.rokeby.show_preview and ob.visible_get()]


def refresh(scene=None) -> int:
    """Bring every previewed mirror's capture up to date (what the window's timer runs); returns
    how many were captured. Progress shows on the cursor while it works."""
    global _dirty
    import bpy  # noqa: PLC0415

    scenes = [scene] if scene is not None else [w.scene for w in getattr(bpy.context.window_manager, "windows", [])] or [bpy.context.scene]
    _dirty = False
    done = 0
    wm = bpy.context.window_manager
    todo = [(sc, ob) for sc in scenes if sc is not None for ob in previewed(sc)]
    progress = wm is not None and bool(todo) and not bpy.app.background
    if progress:
        wm.progress_begin(0, len(todo))
    try:
        for i, (sc, ob) in enumerate(todo):
            before = current(ob)
            try:
                cap = ensure(ob, sc)
            except Exception as exc:  # noqa: BLE001 - kept for the sidebar, the preview keeps the old capture
                _errors[ob.name] = f"{type(exc).__name__}: {exc}"
                continue
            _errors.pop(ob.name, None)
            done += cap is not before
            if progress:
                wm.progress_update(i + 1)
    finally:
        if progress:
            wm.progress_end()
    return done


_errors: dict = {}


def error_of(mirror) -> str | None:
    return _errors.get(getattr(mirror, "name", None))


# --- live: depsgraph updates mark dirty, a debounced timer captures ------------------------------


def request():
    """Something may have changed (or a preview has no capture yet): capture once the updates
    pause (a window), never from inside a draw."""
    global _dirty, _pending, _last_change
    _dirty = True
    _last_change = time.perf_counter()
    if not _pending:
        from .. import evaluate  # noqa: PLC0415

        _pending = True
        evaluate._schedule(_timer, DEBOUNCE_SECONDS)


def transform_running() -> bool:
    """Whether a window runs a transform (G, R, S, a gizmo drag): the mouse holding still inside
    one is no pause; the capture waits for its confirm or cancel."""
    import bpy  # noqa: PLC0415

    for window in getattr(getattr(bpy.context, "window_manager", None), "windows", []):
        for op in getattr(window, "modal_operators", ()):
            if op.bl_idname.startswith(("TRANSFORM_OT_", "transform.")):
                return True
    return False


def shaders_compiling() -> bool:
    """Whether Blender compiles material shaders now (EEVEE draws an object only once its shader is
    ready): a GPU capture taken meanwhile would miss objects, so it waits."""
    import bpy  # noqa: PLC0415

    if bpy.app.background:  # no jobs there (and the query crashes Blender as a Python module)
        return False
    try:
        return bool(bpy.app.is_job_running("SHADER_COMPILATION"))
    except (AttributeError, TypeError, ValueError):  # a Blender without the job query
        return False


def _timer():
    global _pending
    from .. import guard  # noqa: PLC0415

    wait = DEBOUNCE_SECONDS - (time.perf_counter() - _last_change)
    if wait > 0 or guard.active() or transform_running() or shaders_compiling():
        return max(wait, 0.1)
    _pending = False
    try:
        if refresh():
            _redraw()
    except Exception as exc:  # noqa: BLE001 - a timer must never raise into Blender
        print(f"Rokeby: scene capture failed: {type(exc).__name__}: {exc}")
    return None


def _redraw():
    import bpy  # noqa: PLC0415

    wm = getattr(bpy.context, "window_manager", None)
    for window in getattr(wm, "windows", []):
        for area in window.screen.areas:
            if area.type == "VIEW_3D":
                area.tag_redraw()


def check_look(scene, space) -> None:
    """A 3D view is drawn with ``space``'s shading: a VIEWPORT capture drawn with other Solid shading
    settings is taken again (changing them updates no depsgraph)."""
    if not _captures or space is None or getattr(space, "type", None) != "VIEW_3D":
        return
    view = gpu_capture.view_of(scene)
    if view is None or view[2] != space:  # the capture draws like the largest 3D view only
        return
    look = gpu_capture.look_of(space)
    if not look:  # another shading than Solid: the capture keeps the Solid look it was drawn with
        return
    for ob in previewed(scene):
        cap = current(ob)
        if cap is not None and cap.route == "VIEWPORT" and cap.look != look:
            request()
            return


def on_depsgraph_update(scene, depsgraph):
    """A window's depsgraph update: when any preview shows a capture, look again after a pause
    (``refresh`` recaptures only what changed; a handle drag changes nothing it shows)."""
    from .. import guard, handlers  # noqa: PLC0415

    if guard.active() or not _captures or not handlers.in_a_window():
        return
    if previewed(scene):
        request()


def register():
    from ...blender import hooks  # noqa: PLC0415

    hooks.add("reflection-preview", "depsgraph_update_post", on_depsgraph_update)
    hooks.add("reflection-preview", "load_post", on_load)


def on_load(*_args):
    """Another file: its mirrors are captured when their preview is first drawn."""
    global _pending
    _captures.clear()
    _errors.clear()
    _pending = False  # loading a file drops the timers


def unregister():
    global _pending, _dirty
    from ...blender import hooks  # noqa: PLC0415

    hooks.remove("reflection-preview")
    _captures.clear()
    _errors.clear()
    _pending = _dirty = False
