"""Reflection-map mode (paper §6.3): per mirror, a panorama of the scene captured from the
mirror's centre and looked up in the edited direction e, instead of ray tracing.

Capture: Cycles renders an equirectangular panorama from the mirror's world-space bounding-box
centre (or from the object in ``rokeby.map_origin``), with the mirror itself hidden. Every
setting the capture changes (camera, resolution, engine, output format, the mirror's visibility)
is put back afterwards, also when the render fails; the temporary camera is deleted. The result
is a float image datablock "Rokeby Map <mirror>" plus a few blurred copies for rough materials
(one per roughness in schema.REFLMAP_ROUGHNESS_LEVELS, blurred by the Rust core's prefilter with its separable
Gaussian lobe, through :func:`rokeby.envmaps.prefilter`), stored

* as OpenEXR files in ``//rokeby_maps/`` next to the .blend when the file is saved (what an artist
  expects of a cache: small .blend, maps on disk, refreshed by "Capture"), or
* packed into the .blend when the file has never been saved (there is no "next to" yet).

Lookup: the group "Rokeby Reflection Map" computes, from "Rokeby Edited Direction", the
unfolded edited direction e (an edit below the surface simply shows what lies behind, as in the
paper), the Fresnel weight and the roughness blend factors; a per-mirror wrapper
"Rokeby Reflection Map: <mirror>" samples the mirror's images with Environment Texture nodes.
``install`` turns the specular lobe of each Glossy/Principled BSDF into an Emission of
lookup × Fresnel (the diffuse lobe is untouched); ``uninstall`` restores the material exactly.

Convention (Blender's, for Environment Texture nodes and the panorama camera): a world-space
direction d is stored at

    u = 0.5 − atan2(d.y, d.x) / 2π,    v = 0.5 + atan2(d.z, hypot(d.x, d.y)) / π

with v = 0 the bottom row (pixel row 0 of ``image.pixels``): +X is the centre of the image, +Y
at u = 0.25, −Y at u = 0.75, −X on the seam. ``direction_to_uv``/``uv_to_direction`` implement
it; ``image_for(mirror)`` gives the sharp image for the viewport.
"""

from __future__ import annotations

import hashlib
import json
import math
import os
import shutil
import tempfile
import time
import uuid

import numpy as np

from . import shading
from ... import envmaps
from ...blender import transaction
from .. import scene_inputs
from ...core.errors import RokebyError
from ...core import latlong, schema

# Widths of the panorama (height = width / 2); the UI offers these, the API any power of two.
RESOLUTIONS = (256, 512, 1024, 2048)
DEFAULT_RESOLUTION = 512
MIN_RESOLUTION, MAX_RESOLUTION = 32, 8192
DEFAULT_SAMPLES = 32
# File names in the cache: <sanitised mirror name, at most STEM_CHARS>-<map id, ID_CHARS hex>.exr
STEM_CHARS = 40
ID_CHARS = 12


def cache_dir() -> str:
    """Where FILE storage writes maps: the add-on preferences' Reflection Map Cache folder when set
    (a machine-level choice), else ``schema.REFLMAP_CACHE_DIR`` next to the .blend."""
    from ...blender import prefs  # noqa: PLC0415

    folder = prefs.get().cache_folder
    return folder.rstrip("/\\") + "/" if folder else schema.REFLMAP_CACHE_DIR
STORAGES = ("AUTO", "FILE", "PACK")
# Bumped when the groups built here change; forces a rebuild through shading._fresh_group.
MAP_VERSION = 1
# The panorama camera's rotation (XYZ Euler) that makes Cycles' equirectangular image match the
# Environment Texture convention above (checked by tests/reflection/test_reflmap.py).
PANO_ROTATION = (math.pi / 2, 0.0, -math.pi / 2)


# --- the lat-long convention -----------------------------------------------------------------


direction_to_uv = latlong.direction_to_uv  # one home: rokeby.core.latlong
uv_to_direction = latlong.uv_to_direction


def sample(pixels: np.ndarray, directions) -> np.ndarray:
    """Nearest texel of a lat-long ``pixels`` (H, W, C) array, row 0 at the bottom, in
    ``directions`` (…, 3): what the Environment Texture node reads (without filtering)."""
    h, w = pixels.shape[:2]
    uv = direction_to_uv(directions)
    x = np.clip((uv[..., 0] * w).astype(np.int64), 0, w - 1)
    y = np.clip((uv[..., 1] * h).astype(np.int64), 0, h - 1)
    return pixels[y, x]


# --- prefiltering for rough materials ----------------------------------------------------------


def lobe_width(roughness: float) -> float:
    """Angular standard deviation (radians) of the reflected lobe of a GGX/Beckmann surface of
    ``roughness`` (α = roughness², half-vector spread α/√2, doubled by the reflection)."""
    return math.sqrt(2.0) * roughness * roughness


def prefilter(px: np.ndarray, roughness_levels=schema.REFLMAP_ROUGHNESS_LEVELS) -> list:
    """The capture ``px`` (H, W, C) and one blurred copy per further roughness level: a Gaussian
    of :func:`lobe_width` radians on the sphere (the Rust core's ``Lobe::Gaussian``: made
    separable along meridians, wrapping over the poles, and parallels, wrapping at the seam), each
    at a resolution where σ spans 4 to 8 texels along the equator (≥ 32 wide): rough levels are
    small. Level 0 is ``px`` itself."""
    px = np.asarray(px)
    sigmas = [lobe_width(r) for r in roughness_levels[1:]]
    blurred = envmaps.prefilter(np.ascontiguousarray(px, dtype=np.float32), "gaussian", sigmas) if sigmas else []
    return [px] + [lv.astype(px.dtype, copy=False) for lv in blurred]


# --- capture -----------------------------------------------------------------------------------


def _of_mirrors(*args, **kwargs) -> list:
    """The materials an operation on mirrors may edit (pointers.of_mirrors)."""
    from .. import pointers  # noqa: PLC0415

    return pointers.of_mirrors(*args, **kwargs)


def image_name(mirror, level: int = 0) -> str:
    base = schema.REFLMAP_IMAGE_PREFIX + mirror.name
    return base if level == 0 else f"{base} r{schema.REFLMAP_ROUGHNESS_LEVELS[level]:g}"


def _safe(name: str) -> str:
    """``name`` with everything but ASCII letters, digits, '-' and '_' replaced by '_', at most
    STEM_CHARS long: no separators, dots or drive letters can reach a path."""
    return "".join(ch if (ch.isascii() and ch.isalnum()) or ch in "-_" else "_" for ch in name)[:STEM_CHARS] or "map"


def _others_with(mirror, attr: str, value) -> list:
    import bpy  # noqa: PLC0415

    out = []
    for ob in bpy.data.objects:
        s = getattr(ob, "rokeby", None)
        if ob != mirror and s is not None and s.is_mirror and value and getattr(s, attr) == value:
            out.append(ob)
    return out


def map_id(mirror) -> str:
    """The id in ``mirror``'s map file names: its stored ``map_id``, or a new one when it has
    none or shares it with another object (a Shift+D copy inherits it: whichever of the two is
    captured next gets its own, so neither overwrites the other's files). Not stored here:
    ``capture`` stores it once the capture succeeded."""
    mid = mirror.rokeby.map_id
    if not mid or _others_with(mirror, "map_id", mid):
        taken = {getattr(ob, "rokeby", None) and ob.rokeby.map_id for ob in _all_objects()}
        while True:
            mid = uuid.uuid4().hex[:ID_CHARS]
            if mid not in taken:
                break
    return mid


def _all_objects():
    import bpy  # noqa: PLC0415

    return bpy.data.objects


def map_stem(mirror, mid: str | None = None) -> str:
    """File stem of ``mirror``'s maps: its sanitised name (for people) and its map id (for
    uniqueness), e.g. ``Ball_L-3f2a9c01d4e7``."""
    return f"{_safe(mirror.name)}-{mid or map_id(mirror)}"


def _file_name(mirror, level: int, mid: str | None = None) -> str:
    stem = map_stem(mirror, mid)
    return f"{stem}.exr" if level == 0 else f"{stem}_r{schema.REFLMAP_ROUGHNESS_LEVELS[level]:g}.exr"


def _inside_cache(filepath: str) -> str:
    """The absolute path of ``filepath`` (a //-relative path), refused unless it lies inside
    the cache folder."""
    import bpy  # noqa: PLC0415

    absolute = os.path.realpath(bpy.path.abspath(filepath))
    root = os.path.realpath(bpy.path.abspath(cache_dir()))
    if os.path.commonpath([absolute, root]) != root or absolute == root:
        raise RokebyError(f"capture: the map file '{filepath}' would lie outside {cache_dir()}")
    return absolute


def _owned(mirror, img):
    """``img`` if no other mirror uses it as its map (a copy's inherited pointer), else None."""
    if img is None:
        return None
    for ob in _all_objects():
        s = getattr(ob, "rokeby", None)
        if ob == mirror or s is None or not s.is_mirror:
            continue
        if s.map_image == img or any(ref.image == img for ref in s.map_levels):
            return None
    return img


def capture_origin(mirror, depsgraph=None) -> np.ndarray:
    """Where the map of ``mirror`` is captured from: the location of ``rokeby.map_origin`` when
    set, else the centre of the mirror's world-space bounding box (of the evaluated mesh)."""
    import bpy  # noqa: PLC0415

    scene_inputs.require_mirror(mirror)
    origin = mirror.rokeby.map_origin
    if origin is not None:
        p = np.array(origin.matrix_world.translation, dtype=np.float64)
        if not np.all(np.isfinite(p)):
            raise RokebyError(f"capture point: '{origin.name}' has a non-finite location")
        return p
    dg = depsgraph if depsgraph is not None else bpy.context.evaluated_depsgraph_get()
    ob = mirror.evaluated_get(dg)
    m = np.array(ob.matrix_world, dtype=np.float64)
    corners = np.array([tuple(c) for c in ob.bound_box], dtype=np.float64)
    world = corners @ m[:3, :3].T + m[:3, 3]
    if not np.all(np.isfinite(world)):
        raise RokebyError(f"mirror: '{mirror.name}' has a non-finite transform")
    lo, hi = world.min(0), world.max(0)
    if not float(np.linalg.norm(hi - lo)) > 1e-9 * max(1.0, float(np.abs(world).max())):
        raise RokebyError(f"mirror: '{mirror.name}' has zero size (its bounding box is a point); there is no surface to capture a reflection map for")
    return (lo + hi) / 2


def _resolution(resolution) -> int:
    try:
        w = int(resolution)
    except (TypeError, ValueError):
        raise RokebyError(f"resolution: expected a width in pixels, got {resolution!r}") from None
    if w != resolution and str(w) != str(resolution):
        raise RokebyError(f"resolution: expected a whole number of pixels, got {resolution!r}")
    if not (MIN_RESOLUTION <= w <= MAX_RESOLUTION) or w & (w - 1):
        raise RokebyError(f"resolution: {resolution!r} must be a power of two from {MIN_RESOLUTION} to {MAX_RESOLUTION} (the width; the height is half of it)")
    return w


def _storage(storage: str) -> str:
    import bpy  # noqa: PLC0415

    if storage not in STORAGES:
        raise RokebyError(f"storage: '{storage}' is not one of {list(STORAGES)}")
    relative = cache_dir().startswith("//")
    if storage == "AUTO":
        return "FILE" if bpy.data.filepath or not relative else "PACK"
    if storage == "FILE" and relative and not bpy.data.filepath:
        raise RokebyError(f"storage: 'FILE' writes the map to {cache_dir()} next to the .blend, but this file has never been saved: save it first, or use storage='PACK'")
    return storage


class _Restorer:
    """Set attributes for the duration of a capture and put every one back afterwards (in the
    order they were set, so that e.g. an output format is restored before its colour depth)."""

    def __init__(self):
        self.saved = []

    def set(self, owner, attr, value):
        self.set_many(owner, ((attr, value),))

    def set_many(self, owner, pairs):
        """Record every old value first: setting one (a file format) may change another (its
        colour depth)."""
        self.saved.extend((owner, attr, getattr(owner, attr)) for attr, _v in pairs)
        for attr, value in pairs:
            setattr(owner, attr, value)

    def restore(self):
        errors = []
        for owner, attr, old in self.saved:
            try:
                setattr(owner, attr, old)
            except Exception as exc:  # noqa: BLE001 - restore the rest, then report
                errors.append(f"{attr}: {exc}")
        self.saved.clear()
        return errors


def _distance_material():
    """An emission material whose colour is the distance from the camera to the shaded point
    (Camera Data's View Distance: for a panoramic camera, the Euclidean distance from its centre)."""
    import bpy  # noqa: PLC0415

    mat = bpy.data.materials.new("Rokeby capture distance")
    mat.use_nodes = True
    nt = mat.node_tree
    nt.nodes.clear()
    cam = nt.nodes.new("ShaderNodeCameraData")
    emit = nt.nodes.new("ShaderNodeEmission")
    emit.inputs["Strength"].default_value = 1.0
    out = nt.nodes.new("ShaderNodeOutputMaterial")
    nt.links.new(cam.outputs["View Distance"], emit.inputs["Color"])
    nt.links.new(emit.outputs["Emission"], out.inputs["Surface"])
    return mat


def _read_exr(path: str, width: int, height: int, what: str) -> np.ndarray:
    """The RGBA pixels (H, W, 4) of the single-layer EXR ``path`` (Blender's own reader)."""
    import bpy  # noqa: PLC0415

    if not os.path.exists(path):
        raise RokebyError(f"{what}: Cycles wrote no image (was the render cancelled?)")
    img = bpy.data.images.load(path)
    try:
        if tuple(img.size) != (width, height):
            raise RokebyError(f"{what}: expected a {width}×{height} panorama, got {tuple(img.size)}")
        px = np.empty(width * height * 4, dtype=np.float32)
        img.pixels.foreach_get(px)
    finally:
        bpy.data.images.remove(img)
    return px.reshape(height, width, 4)


def _render_panorama(scene, mirror, origin, width: int, samples: int, *, distance: bool = False, denoise: bool | None = None,
                     camera_only: bool = False):
    """Render the equirectangular panorama (H, W, 3) float32, row 0 at the bottom.

    With ``distance``, returns (colour, distance): a second render of one sample with every
    surface replaced by an emission of its distance from ``origin`` (the view layers' material
    override; the world transparent) gives the distance per texel, +inf where the world is seen.
    ``denoise``: the colour render's denoising (None: the scene's setting). ``camera_only``: the
    mirror is hidden from camera rays only, so that it still shadows and lights the other objects
    as in a final render (else it is hidden from the render altogether)."""
    import bpy  # noqa: PLC0415

    from ...blender import compat  # noqa: PLC0415
    from .. import guard  # noqa: PLC0415 - the live-update handlers' suspension

    height = width // 2
    tmp = tempfile.mkdtemp(prefix="rokeby_capture_")
    path = os.path.join(tmp, "capture.exr")
    cam_data = cam = None
    undo = _Restorer()
    try:
        with guard.suspended():
            cam_data = bpy.data.cameras.new("Rokeby capture")
            cam_data.type = "PANO"
            cam_data.panorama_type = "EQUIRECTANGULAR"
            size = max(float(np.max(mirror.dimensions)), 1e-6)
            cam_data.clip_start = min(1e-3, 1e-3 * size)
            cam_data.clip_end = 1e7
            cam = bpy.data.objects.new("Rokeby capture", cam_data)
            cam.location = origin.tolist()
            cam.rotation_euler = PANO_ROTATION
            scene.collection.objects.link(cam)
            r = scene.render
            undo.set(scene, "camera", cam)
            undo.set(mirror, "visible_camera" if camera_only else "hide_render", not camera_only)
            undo.set(r, "engine", "CYCLES")
            undo.set_many(r, (
                ("resolution_x", width), ("resolution_y", height), ("resolution_percentage", 100),
                ("pixel_aspect_x", 1.0), ("pixel_aspect_y", 1.0), ("use_border", False),
                ("use_compositing", False), ("use_sequencer", False), ("use_multiview", False),
                ("use_motion_blur", False), ("film_transparent", False), ("use_single_layer", True),
                ("use_file_extension", False), ("filepath", path),
            ))
            im = r.image_settings
            undo.set_many(im, compat.single_layer_exr_items() + (("color_mode", "RGB"), ("color_depth", "32"), ("exr_codec", "ZIP"), ("color_management", "FOLLOW_SCENE")))
            undo.set(scene.cycles, "samples", int(samples))
            if denoise is not None:
                undo.set(scene.cycles, "use_denoising", bool(denoise))

            def render():
                if scene == bpy.context.scene:
                    bpy.ops.render.render(write_still=True)
                else:
                    bpy.ops.render.render(write_still=True, scene=scene.name)

            render()
            px = _read_exr(path, width, height, f"capture of '{mirror.name}'")
            if distance:
                # Its own restorer, undone first: it sets again what the colour render set.
                again = _Restorer()
                dist_mat = _distance_material()
                try:
                    dist_path = os.path.join(tmp, "distance.exr")
                    again.set(r, "filepath", dist_path)
                    again.set(r, "film_transparent", True)
                    again.set(im, "color_mode", "RGBA")
                    for attr, value in (("samples", 1), ("use_denoising", False), ("filter_width", 0.01), ("max_bounces", 0),
                                        ("transparent_max_bounces", 0), ("use_adaptive_sampling", False)):
                        again.set(scene.cycles, attr, value)
                    for vl in scene.view_layers:
                        again.set(vl, "material_override", dist_mat)
                    again.set(scene, "world", None)  # transparent anyway: no world lighting to prepare
                    render()
                    dpx = _read_exr(dist_path, width, height, f"distance capture of '{mirror.name}'")
                finally:
                    undone = again.restore()
                    bpy.data.materials.remove(dist_mat)
                if undone:
                    raise RokebyError(f"capture of '{mirror.name}': could not restore " + "; ".join(undone))
                covered = dpx[..., 3]
                with np.errstate(divide="ignore", invalid="ignore"):
                    dist = np.where(covered > 0.5, dpx[..., 0] / np.maximum(covered, 1e-6), np.inf).astype(np.float32)
    finally:
        errors = undo.restore()
        if cam is not None:
            bpy.data.objects.remove(cam, do_unlink=True)
        if cam_data is not None:
            bpy.data.cameras.remove(cam_data)
        shutil.rmtree(tmp, ignore_errors=True)
    if errors:
        raise RokebyError(f"capture of '{mirror.name}': could not restore " + "; ".join(errors))
    colour = px[..., :3]
    return (colour, dist) if distance else colour


def _store(name: str, px: np.ndarray, storage: str, filepath: str, old):
    """A float image ``name`` holding ``px`` (H, W, 3), saved to ``filepath`` (FILE) or packed.
    An existing image ``old`` is replaced everywhere it is used (materials, the viewport)."""
    import bpy  # noqa: PLC0415

    h, w = px.shape[:2]
    rgba = np.ones((h, w, 4), dtype=np.float32)
    rgba[..., :3] = px
    img = bpy.data.images.new(name + " (new)", w, h, alpha=False, float_buffer=True)
    try:
        img.pixels.foreach_set(rgba.ravel())
        img.file_format = "OPEN_EXR"
        img.use_half_precision = True
        if storage == "FILE":
            # Written under a temporary name and renamed over the old map only once the whole
            # capture has succeeded (``transaction.later``): a failure keeps the old files.
            absolute = bpy.path.abspath(filepath)
            os.makedirs(os.path.dirname(absolute), exist_ok=True)
            partial = f"{absolute}.partial-{uuid.uuid4().hex[:8]}.exr"
            transaction.on_rollback(lambda: os.path.exists(partial) and os.remove(partial))
            img.filepath_raw = partial
            img.save()

            def publish(img=img, partial=partial, absolute=absolute, filepath=filepath):
                # The old map is kept aside until the capture has succeeded.
                backup = None
                if os.path.exists(absolute):
                    backup = f"{absolute}.old-{uuid.uuid4().hex[:8]}"
                    os.replace(absolute, backup)
                    transaction.on_rollback(lambda: os.replace(backup, absolute))
                os.replace(partial, absolute)
                if backup is None:
                    transaction.on_rollback(lambda: os.path.exists(absolute) and os.remove(absolute))
                else:
                    transaction.later(lambda: os.path.exists(backup) and os.remove(backup))
                img.source = "FILE"
                img.filepath = filepath
                img.reload()
            transaction.at_end(publish)
        else:
            img.pack()
    except Exception:
        bpy.data.images.remove(img)
        raise
    if old is not None and old != img:
        try:
            old.user_remap(img)
            transaction.remove(old)
        except ReferenceError:
            pass
    img.name = name
    return img


def scene_fingerprint(mirror, scene=None) -> str:
    """A digest of what a capture sees: the capture point, the resolution, the world, and the
    name, data, transform and visibility of every other object. A map is stale when it differs
    (mesh edits that keep the vertex count, and material edits, are not detected)."""
    import bpy  # noqa: PLC0415

    scene = scene if scene is not None else bpy.context.scene
    h = hashlib.blake2b(digest_size=16)
    try:
        origin = capture_origin(mirror)
    except RokebyError:
        origin = np.full(3, np.nan)
    h.update(np.round(origin, 6).tobytes())
    h.update(str(mirror.rokeby.map_resolution).encode())
    h.update(repr(scene.world.name if scene.world else None).encode())
    for ob in sorted(scene.objects, key=lambda o: o.name):
        if ob == mirror:
            continue
        data = ob.data
        nverts = len(data.vertices) if ob.type == "MESH" else 0
        h.update(f"{ob.name}|{ob.type}|{getattr(data, 'name', '')}|{nverts}|{ob.hide_render}|".encode())
        h.update(np.round(np.array(ob.matrix_world, dtype=np.float64), 6).tobytes())
    return h.hexdigest()


def is_stale(mirror, scene=None) -> bool:
    """True when ``mirror`` has a map and the scene it saw has changed since (see
    ``scene_fingerprint``); False when it has no map."""
    s = mirror.rokeby
    if s.map_image is None:
        return False
    return s.map_fingerprint != scene_fingerprint(mirror, scene)


@transaction.atomic(materials=_of_mirrors)
def capture(mirror, *, resolution=None, samples=None, storage: str = "AUTO", scene=None):
    """Capture the reflection map of ``mirror`` and return its (sharp) image.

    ``resolution`` is the panorama's width (a power of two; height = width / 2; default: the
    mirror's ``map_resolution``), ``samples`` the Cycles samples (default: ``map_samples``).
    ``storage``: 'FILE' (OpenEXR in //rokeby_maps/ next to the .blend), 'PACK' (inside the
    .blend) or 'AUTO' (FILE when the .blend has been saved, else PACK). All arguments are checked
    before anything is rendered; the scene is left as it was, also on error."""
    import bpy  # noqa: PLC0415

    scene = scene if scene is not None else bpy.context.scene
    scene_inputs.require_mirror(mirror)
    s = mirror.rokeby
    width = _resolution(s.map_resolution if resolution is None else resolution)
    samples = s.map_samples if samples is None else samples
    if not isinstance(samples, (int, np.integer)) or samples < 1:
        raise RokebyError(f"samples: expected a whole number >= 1, got {samples!r}")
    storage = _storage(storage)
    from ...blender import registry  # noqa: PLC0415

    if not registry.in_scene(mirror, scene):
        raise RokebyError(f"mirror: '{mirror.name}' is not in scene '{scene.name}'")
    mid = map_id(mirror)
    paths = [cache_dir() + _file_name(mirror, k, mid) for k in range(len(schema.REFLMAP_ROUGHNESS_LEVELS))]
    if storage == "FILE":
        for path in paths:
            _inside_cache(path)
    origin = capture_origin(mirror)
    t0 = time.perf_counter()
    px = _render_panorama(scene, mirror, origin, width, int(samples))
    render_s = time.perf_counter() - t0
    if not np.all(np.isfinite(px)):
        raise RokebyError(f"capture of '{mirror.name}': the render has non-finite pixels")
    levels = prefilter(px)
    images = []
    old_levels = [ref.image for ref in s.map_levels]
    for k, level in enumerate(levels):
        # Images another mirror uses (a copy's inherited pointers) are left to it, never replaced.
        old = _owned(mirror, s.map_image if k == 0 else (old_levels[k - 1] if k - 1 < len(old_levels) else None))
        old = old or _owned(mirror, bpy.data.images.get(image_name(mirror, k)))
        images.append(_store(image_name(mirror, k), level, storage, paths[k], old))
    s.map_id = mid
    s.map_image = images[0]
    s.map_levels.clear()
    for img in images[1:]:
        s.map_levels.add().image = img
    if resolution is not None and str(width) in {item.identifier for item in s.bl_rna.properties["map_resolution"].enum_items}:
        s.map_resolution = str(width)
    s.map_fingerprint = scene_fingerprint(mirror, scene)
    s.map_capture_seconds = render_s
    _bind(mirror)
    return images[0]


def image_for(mirror):
    """The sharp lat-long image of ``mirror`` (bpy Image, Blender's equirectangular convention,
    see ``direction_to_uv``), or None when no map has been captured or it is not a mirror."""
    if mirror is None or not getattr(mirror, "rokeby", None) or not mirror.rokeby.is_mirror:
        return None
    return mirror.rokeby.map_image


def levels_for(mirror) -> list:
    """[(roughness, image), …] of ``mirror``'s map, sharpest first (empty without a map)."""
    img = image_for(mirror)
    if img is None:
        return []
    return [(schema.REFLMAP_ROUGHNESS_LEVELS[0], img)] + [(schema.REFLMAP_ROUGHNESS_LEVELS[k + 1], ref.image) for k, ref in enumerate(mirror.rokeby.map_levels)]


def clear(mirror):
    """Forget ``mirror``'s map: its images are removed (files in the cache stay on disk)."""
    import bpy  # noqa: PLC0415

    s = mirror.rokeby
    doomed = [s.map_image] + [ref.image for ref in s.map_levels]
    s.map_image = None
    s.map_levels.clear()
    s.map_fingerprint = ""
    for img in doomed:
        if img is not None:
            bpy.data.images.remove(img)


# --- shader nodes --------------------------------------------------------------------------------

_IN = [
    ("Normal", "NodeSocketVector", None),
    ("Color", "NodeSocketColor", (0.8, 0.8, 0.8, 1.0)),
    ("Metallic", "NodeSocketFloat", 1.0),
    ("Roughness", "NodeSocketFloat", 0.0),
    ("IOR", "NodeSocketFloat", 1.5),
    ("Specular IOR Level", "NodeSocketFloat", 0.5),
    ("Specular Tint", "NodeSocketColor", (1.0, 1.0, 1.0, 1.0)),
    ("Fresnel", "NodeSocketFloat", 1.0),
]


def _stale_version(name):
    import bpy  # noqa: PLC0415

    ng = bpy.data.node_groups.get(name)
    if ng is not None and ng.get(schema.REFLMAP_VERSION_KEY) != MAP_VERSION:
        ng[schema.VERSION_KEY] = -1  # _fresh_group rebuilds it in place


def _defaults(ng):
    inputs = {it.name: it for it in ng.interface.items_tree if getattr(it, "in_out", "") == "INPUT"}
    for name, _kind, default in _IN:
        if default is not None:
            inputs[name].default_value = default


def _mix_color(ng, factor, a, b, blend="MIX"):
    node = ng.nodes.new("ShaderNodeMix")
    node.data_type = "RGBA"
    node.blend_type = blend
    if isinstance(factor, float):
        node.inputs["Factor"].default_value = factor
    else:
        ng.links.new(factor, node.inputs["Factor"])
    for sock, src in ((node.inputs[6], a), (node.inputs[7], b)):
        if isinstance(src, tuple):
            sock.default_value = src
        else:
            ng.links.new(src, sock)
    return node.outputs[2]


def shared_group():
    """"Rokeby Reflection Map": Direction e (unfolded, world space), Specular Weight F (colour),
    Diffuse Color and the blend factors between roughness levels, from the BSDF's inputs.

    F: with Fresnel = 0 it is Color (a Glossy BSDF); else Schlick's approximation blended by
    Metallic between F0 = Color (metal) and F0 = ((IOR−1)/(IOR+1))² · 2·level · tint
    (dielectric), with the grazing term scaled by min(2·level, 1) so level 0 reflects nothing."""
    vec, col, flt = "NodeSocketVector", "NodeSocketColor", "NodeSocketFloat"
    _stale_version(schema.REFLMAP_SHARED_GROUP)
    outputs = [("Direction", "OUTPUT", vec), ("Specular Weight", "OUTPUT", col), ("Diffuse Color", "OUTPUT", col)]
    outputs += [(f"Level {k}", "OUTPUT", flt) for k in range(1, len(schema.REFLMAP_ROUGHNESS_LEVELS))]
    ng = shading._fresh_group(schema.REFLMAP_SHARED_GROUP, outputs + [(n, "INPUT", kind) for n, kind, _d in _IN])
    if ng is None:
        import bpy  # noqa: PLC0415

        return bpy.data.node_groups[schema.REFLMAP_SHARED_GROUP]
    ng[schema.REFLMAP_VERSION_KEY] = MAP_VERSION
    _defaults(ng)
    vm, sm = shading.vector_math, shading.scalar_math
    out = ng.nodes.new("NodeGroupOutput")
    gin = ng.nodes.new("NodeGroupInput")
    d = ng.nodes.new("ShaderNodeGroup")
    d.node_tree = shading.direction_group()
    ng.links.new(gin.outputs["Normal"], d.inputs["Normal"])
    ng.links.new(d.outputs["Direction"], out.inputs["Direction"])
    # Schlick: f5 = (1 − clamp(N·V))^5.
    cos = sm(ng, "MAXIMUM", vm(ng, "DOT_PRODUCT", d.outputs["Normal"], d.outputs["View"]).outputs["Value"], values=(0.0,))
    one_minus_cos = sm(ng, "SUBTRACT", values=(1.0,))
    ng.links.new(cos.outputs[0], one_minus_cos.inputs[1])
    f5 = sm(ng, "POWER", one_minus_cos.outputs[0], values=(5.0,))
    white = (1.0, 1.0, 1.0, 1.0)
    f_metal = _mix_color(ng, f5.outputs[0], gin.outputs["Color"], white)
    ratio = sm(ng, "DIVIDE", sm(ng, "SUBTRACT", gin.outputs["IOR"], values=(1.0,)).outputs[0], sm(ng, "ADD", gin.outputs["IOR"], values=(1.0,)).outputs[0])
    f0 = sm(ng, "MULTIPLY", sm(ng, "POWER", ratio.outputs[0], values=(2.0,)).outputs[0], sm(ng, "MULTIPLY", gin.outputs["Specular IOR Level"], values=(2.0,)).outputs[0])
    f0.use_clamp = True
    tint = _mix_color(ng, f0.outputs[0], (0.0, 0.0, 0.0, 1.0), gin.outputs["Specular Tint"])  # F0 · tint
    f_diel = _mix_color(ng, f5.outputs[0], tint, white)
    level = sm(ng, "MINIMUM", sm(ng, "MULTIPLY", gin.outputs["Specular IOR Level"], values=(2.0,)).outputs[0], values=(1.0,))
    f_diel = _mix_color(ng, level.outputs[0], (0.0, 0.0, 0.0, 1.0), f_diel)
    f_pr = _mix_color(ng, gin.outputs["Metallic"], f_diel, f_metal)
    fresnel = _mix_color(ng, gin.outputs["Fresnel"], gin.outputs["Color"], f_pr)
    ng.links.new(fresnel, out.inputs["Specular Weight"])
    one_minus_m = sm(ng, "SUBTRACT", values=(1.0,))
    ng.links.new(gin.outputs["Metallic"], one_minus_m.inputs[1])
    one_minus_m.use_clamp = True
    # Color × (1 − Metallic): a Mix from black to Color by (1 − Metallic).
    ng.links.new(_mix_color(ng, one_minus_m.outputs[0], (0.0, 0.0, 0.0, 1.0), gin.outputs["Color"]), out.inputs["Diffuse Color"])
    # Blend factors: level k takes over linearly between schema.REFLMAP_ROUGHNESS_LEVELS[k-1] and [k].
    for k in range(1, len(schema.REFLMAP_ROUGHNESS_LEVELS)):
        mr = ng.nodes.new("ShaderNodeMapRange")
        mr.clamp = True
        ng.links.new(gin.outputs["Roughness"], mr.inputs["Value"])
        mr.inputs["From Min"].default_value = schema.REFLMAP_ROUGHNESS_LEVELS[k - 1]
        mr.inputs["From Max"].default_value = schema.REFLMAP_ROUGHNESS_LEVELS[k]
        ng.links.new(mr.outputs["Result"], out.inputs[f"Level {k}"])
    return ng


def mirror_group(mirror):
    """"Rokeby Reflection Map: <mirror>": the shared group plus one Environment Texture per
    level of the mirror's map. Outputs Specular = lookup × Fresnel, Diffuse Color, Lookup and
    Direction."""
    import bpy  # noqa: PLC0415

    vec, col = "NodeSocketVector", "NodeSocketColor"
    name = schema.REFLMAP_MIRROR_GROUP_PREFIX + mirror.name
    _stale_version(name)
    outputs = [("Specular", "OUTPUT", col), ("Diffuse Color", "OUTPUT", col), ("Lookup", "OUTPUT", col), ("Direction", "OUTPUT", vec)]
    ng = shading._fresh_group(name, outputs + [(n, "INPUT", kind) for n, kind, _d in _IN])
    if ng is None:
        ng = bpy.data.node_groups[name]
        _bind_group(ng, mirror)
        return ng
    ng[schema.REFLMAP_VERSION_KEY] = MAP_VERSION
    _defaults(ng)
    out = ng.nodes.new("NodeGroupOutput")
    gin = ng.nodes.new("NodeGroupInput")
    sh = ng.nodes.new("ShaderNodeGroup")
    sh.node_tree = shared_group()
    for n, _kind, _d in _IN:
        ng.links.new(gin.outputs[n], sh.inputs[n])
    colour = None
    for k in range(len(schema.REFLMAP_ROUGHNESS_LEVELS)):
        env = ng.nodes.new("ShaderNodeTexEnvironment")
        env.name = f"Level {k}"
        env.interpolation = "Linear"
        env.projection = "EQUIRECTANGULAR"
        ng.links.new(sh.outputs["Direction"], env.inputs["Vector"])
        colour = env.outputs["Color"] if k == 0 else _mix_color(ng, sh.outputs[f"Level {k}"], colour, env.outputs["Color"])
    ng.links.new(colour, out.inputs["Lookup"])
    ng.links.new(_mix_color(ng, 1.0, colour, sh.outputs["Specular Weight"], "MULTIPLY"), out.inputs["Specular"])
    ng.links.new(sh.outputs["Diffuse Color"], out.inputs["Diffuse Color"])
    ng.links.new(sh.outputs["Direction"], out.inputs["Direction"])
    _bind_group(ng, mirror)
    return ng


def _bind_group(ng, mirror):
    images = [img for _r, img in levels_for(mirror)]
    for k in range(len(schema.REFLMAP_ROUGHNESS_LEVELS)):
        node = ng.nodes.get(f"Level {k}")
        if node is not None:
            # A missing level (an older capture) falls back to the sharpest one there is.
            node.image = images[k] if k < len(images) and images[k] is not None else (images[0] if images else None)


def _bind(mirror):
    import bpy  # noqa: PLC0415

    ng = bpy.data.node_groups.get(schema.REFLMAP_MIRROR_GROUP_PREFIX + mirror.name)
    if ng is not None:
        _bind_group(ng, mirror)


_PRINCIPLED_INPUTS = {"Normal": "Normal", "Base Color": "Color", "Metallic": "Metallic", "Roughness": "Roughness", "IOR": "IOR", "Specular IOR Level": "Specular IOR Level", "Specular Tint": "Specular Tint"}
_GLOSSY_INPUTS = {"Normal": "Normal", "Color": "Color", "Roughness": "Roughness"}
# Principled inputs switched off in map mode (the specular lobes); their values are saved.
_SWITCHED_OFF = ("Metallic", "Specular IOR Level")


def _feed(tree, bsdf, group, mapping):
    for src_name, dst_name in mapping.items():
        src = bsdf.inputs[src_name]
        if src.is_linked:
            tree.links.new(src.links[0].from_socket, group.inputs[dst_name])
        elif dst_name != "Normal":
            value = src.default_value
            group.inputs[dst_name].default_value = tuple(value) if hasattr(value, "__len__") else value


def _tag(node, bsdf, role):
    node[schema.REFLMAP_TAG] = role
    node[schema.REFLMAP_BSDF_KEY] = bsdf.name


def install(material, mirror) -> int:
    """Put ``material`` in reflection-map mode for ``mirror``: every Principled BSDF keeps its
    diffuse lobe (Metallic and Specular IOR Level set to 0, Base Color × (1 − Metallic)) and gets
    an Emission of lookup × Fresnel added; every Glossy BSDF is replaced by such an Emission.
    Returns how many BSDFs were converted. Installing again rebuilds from the original material."""
    if material is None or not material.use_nodes:
        return 0
    uninstall(material)
    tree = material.node_tree
    group_tree = mirror_group(mirror)
    count = 0
    for bsdf in list(tree.nodes):
        kind = bsdf.bl_idname
        if kind not in ("ShaderNodeBsdfPrincipled", "ShaderNodeBsdfGlossy", "ShaderNodeBsdfAnisotropic"):
            continue
        principled = kind == "ShaderNodeBsdfPrincipled"
        consumers = [lk.to_socket for lk in bsdf.outputs["BSDF"].links]
        g = tree.nodes.new("ShaderNodeGroup")
        g.node_tree = group_tree
        g.label = schema.FRAME_REFLECTION_MAP
        g.location = (bsdf.location.x - 300, bsdf.location.y - 250)
        _tag(g, bsdf, "group")
        _feed(tree, bsdf, g, _PRINCIPLED_INPUTS if principled else _GLOSSY_INPUTS)
        emit = tree.nodes.new("ShaderNodeEmission")
        emit.location = (bsdf.location.x + 300, bsdf.location.y - 250)
        emit.inputs["Strength"].default_value = 1.0
        _tag(emit, bsdf, "emission")
        tree.links.new(g.outputs["Specular"], emit.inputs["Color"])
        if principled:
            g[schema.REFLMAP_SAVED_KEY] = json.dumps({name: float(bsdf.inputs[name].default_value) for name in _SWITCHED_OFF})
            for name in _SWITCHED_OFF:
                for lk in list(bsdf.inputs[name].links):
                    tree.links.remove(lk)
                bsdf.inputs[name].default_value = 0.0
            tree.links.new(g.outputs["Diffuse Color"], bsdf.inputs["Base Color"])
            add = tree.nodes.new("ShaderNodeAddShader")
            add.location = (bsdf.location.x + 450, bsdf.location.y)
            _tag(add, bsdf, "add")
            tree.links.new(bsdf.outputs["BSDF"], add.inputs[0])
            tree.links.new(emit.outputs["Emission"], add.inputs[1])
            result = add.outputs["Shader"]
        else:
            g.inputs["Metallic"].default_value = 1.0
            g.inputs["Fresnel"].default_value = 0.0
            result = emit.outputs["Emission"]
        for sock in consumers:
            tree.links.new(result, sock)
        count += 1
    return count


def uninstall(material) -> bool:
    """Take reflection-map mode out of ``material``: links, values and nodes as they were."""
    if material is None or not material.use_nodes:
        return False
    tree = material.node_tree
    ours = [nd for nd in tree.nodes if nd.get(schema.REFLMAP_TAG)]
    by_bsdf: dict = {}
    for nd in ours:
        by_bsdf.setdefault(nd[schema.REFLMAP_BSDF_KEY], {})[nd[schema.REFLMAP_TAG]] = nd
    for bsdf_name, parts in by_bsdf.items():
        bsdf = tree.nodes.get(bsdf_name)
        g, emit, add = parts.get("group"), parts.get("emission"), parts.get("add")
        if bsdf is not None:
            result = add.outputs["Shader"] if add is not None else (emit.outputs["Emission"] if emit is not None else None)
            consumers = [lk.to_socket for lk in result.links] if result is not None else []
            if bsdf.bl_idname == "ShaderNodeBsdfPrincipled" and g is not None:
                saved = json.loads(g.get(schema.REFLMAP_SAVED_KEY, "{}"))
                for name, value in saved.items():
                    bsdf.inputs[name].default_value = value
                for name in ("Base Color",) + _SWITCHED_OFF:
                    upstream = g.inputs[_PRINCIPLED_INPUTS[name]].links
                    if upstream:
                        tree.links.new(upstream[0].from_socket, bsdf.inputs[name])
                    elif name == "Base Color":
                        for lk in list(bsdf.inputs[name].links):
                            tree.links.remove(lk)
            for sock in consumers:
                tree.links.new(bsdf.outputs["BSDF"], sock)
        for nd in parts.values():
            transaction.remove_node(tree, nd)
    return bool(ours)


def installed(material) -> bool:
    """Whether ``material`` is in reflection-map mode."""
    return material is not None and material.use_nodes and any(nd.get(schema.REFLMAP_TAG) for nd in material.node_tree.nodes)
