"""Local shape editing at the compositing stage (Zubiaga, Guennebaud, Vergne, Barla, EGSR 2016).

The compositing artist edits the normal buffer; diffuse and reflection shading follow without
re-rendering. Pipeline (numerics in the Rust core, reached through ``native``):

1. ``setup_passes``: the Cycles passes the method needs — Normal, Diffuse and Glossy
   direct/indirect/colour, object and material index, ambient occlusion (α_D), depth, and three
   AOVs written by nodes added to every material: ``rokeby_reflocc`` (reflection occlusion α_R:
   an Ambient Occlusion node with *Only Local* around the reflected direction, so only
   self-reflections count), ``rokeby_incoming_cam`` (the view vector in camera space) and
   ``rokeby_camera_x``/``_y`` (the world axes in camera space: the camera's rotation in every
   frame, so an EXR alone is enough — no camera data to carry along).
2. ``read_exr``: the passes from a multilayer OpenEXR (read by the Rust core, ``core.exr``); missing
   passes are named.
3. ``reconstruct``: per object/material patch (IndexOB × IndexMA), the SH diffuse environment
   (eq. 1; the QP of §3.1 or least squares) of D0 = DiffDir + DiffInd, and the dual-paraboloid
   reflection environment (eq. 2, hole filling, regularisation) of R0 = GlossDir + GlossInd, in
   screen space (Blender's camera space: x right, y up, z towards the viewer).
4. ``recomposite``: eqs. 3–5 with edited normals; reflectance passes DiffCol/GlossCol multiply the
   reconstructed illumination (the paper's §6 extension). Unmodified normals give the input image
   back bit for bit.
5. Normal-editing tools: ``emboss`` (n_z → β n_z), ``bump`` (height image) with ``ripple`` (the
   paper's fading 2D ripple decal), ``bilateral_smooth`` (cross-bilateral on (n_x, n_y) with depth).

Patches covering fewer than ``min_pixels`` pixels, and reflection maps whose recovered directions
cover less than ``min_coverage`` of the sphere, are not edited: the image keeps its input values
there, and the report (and a RuntimeWarning) says so.
"""

from __future__ import annotations

import glob
import math
import os
import re
import time
import warnings
import weakref
from dataclasses import dataclass, field

import numpy as np

from ..core import exr, native
from ..blender import transaction
from ..core import schema

AOV_REFLOCC = schema.AOV_REFLOCC
AOV_CAMERA_X = schema.AOV_CAMERA_X
AOV_CAMERA_Y = schema.AOV_CAMERA_Y
AOV_INCOMING_CAM = schema.AOV_INCOMING_CAM
NODE_TAG = schema.COMPOSITING_NODE_TAG

# Pass name in a Blender multilayer EXR → (field, number of channels).
PASSES = {
    "Combined": ("image", 4),
    "Normal": ("normal", 3),
    "DiffDir": ("diff_dir", 3),
    "DiffInd": ("diff_ind", 3),
    "DiffCol": ("diff_col", 3),
    "GlossDir": ("gloss_dir", 3),
    "GlossInd": ("gloss_ind", 3),
    "GlossCol": ("gloss_col", 3),
    "IndexOB": ("index_ob", 1),
    "IndexMA": ("index_ma", 1),
    "AO": ("ao", 3),
    "Depth": ("depth", 1),
    AOV_REFLOCC: ("reflocc", 1),
    AOV_CAMERA_X: ("camera_x", 3),
    AOV_CAMERA_Y: ("camera_y", 3),
    AOV_INCOMING_CAM: ("incoming_cam", 3),
}

# The names the passes have in a multilayer EXR: up to Blender 4.5 the short ones of PASSES, from
# 5.0 the long ones (the channel names then read "ViewLayer.Diffuse Direct", ".Object Index.X").
# The reader accepts either, so frames from any release load; errors name the short ones.
PASS_NAMES_LONG = {
    "DiffDir": "Diffuse Direct", "DiffInd": "Diffuse Indirect", "DiffCol": "Diffuse Color",
    "GlossDir": "Glossy Direct", "GlossInd": "Glossy Indirect", "GlossCol": "Glossy Color",
    "IndexOB": "Object Index", "IndexMA": "Material Index", "AO": "Ambient Occlusion",
}


def exr_pass_names(name: str) -> tuple:
    """The names pass ``name`` (a key of PASSES, or any render pass) may have in a multilayer EXR."""
    return (name, PASS_NAMES_LONG[name]) if name in PASS_NAMES_LONG else (name,)


# Blender's Vector Transform "Camera" space has z pointing forward; Blender's camera object (and
# our screen space) has z towards the viewer.
_CAM_FLIP = np.diag([1.0, 1.0, -1.0])


from .errors import CompositingError, MissingPasses  # noqa: E402


# --- Blender side -------------------------------------------------------------------------------

def _material_nodes(mat) -> None:
    """Adds (once; again, whole, when an artist deleted a part) the AOV outputs of the reflection
    occlusion, the camera rotation and the view vector."""
    nt = mat.node_tree
    ours = [n for n in nt.nodes if n.get(schema.COMPOSITING_NODE_KEY)]
    have = {n.aov_name for n in ours if n.bl_idname == "ShaderNodeOutputAOV" and n.inputs[0].is_linked}
    if have >= {AOV_REFLOCC, AOV_CAMERA_X, AOV_CAMERA_Y, AOV_INCOMING_CAM}:
        return
    for n in ours:
        nt.nodes.remove(n)
    def node(kind, label):
        n = nt.nodes.new(kind)
        n.label = f"{NODE_TAG}: {label}"
        n[schema.COMPOSITING_NODE_KEY] = True
        n.location = (-900, -600 - 120 * len([x for x in nt.nodes if x.get(schema.COMPOSITING_NODE_KEY)]))
        return n
    tex = node("ShaderNodeTexCoord", "reflection")
    ao = node("ShaderNodeAmbientOcclusion", "self-reflection occlusion")
    ao.only_local = True
    ao.samples = 8
    ao.inputs["Distance"].default_value = 1e4
    nt.links.new(tex.outputs["Reflection"], ao.inputs["Normal"])
    out_r = node("ShaderNodeOutputAOV", AOV_REFLOCC)
    out_r.aov_name = AOV_REFLOCC
    nt.links.new(ao.outputs["AO"], out_r.inputs["Value"])
    geo = node("ShaderNodeNewGeometry", "view vector")
    # The world X and Y axes in camera space: the camera's rotation, exact at every pixel.
    for name, axis in ((AOV_CAMERA_X, (1.0, 0.0, 0.0)), (AOV_CAMERA_Y, (0.0, 1.0, 0.0))):
        ax = node("ShaderNodeCombineXYZ", f"world axis {name[-1]}")
        ax.inputs[0].default_value, ax.inputs[1].default_value, ax.inputs[2].default_value = axis
        tr = node("ShaderNodeVectorTransform", f"world axis {name[-1]} in camera space")
        tr.vector_type, tr.convert_from, tr.convert_to = "VECTOR", "WORLD", "CAMERA"
        nt.links.new(ax.outputs["Vector"], tr.inputs["Vector"])
        out = node("ShaderNodeOutputAOV", name)
        out.aov_name = name
        nt.links.new(tr.outputs["Vector"], out.inputs["Color"])
    vt = node("ShaderNodeVectorTransform", "view vector in camera space")
    vt.vector_type, vt.convert_from, vt.convert_to = "VECTOR", "WORLD", "CAMERA"
    nt.links.new(geo.outputs["Incoming"], vt.inputs["Vector"])
    out_c = node("ShaderNodeOutputAOV", AOV_INCOMING_CAM)
    out_c.aov_name = AOV_INCOMING_CAM
    nt.links.new(vt.outputs["Vector"], out_c.inputs["Color"])


@transaction.atomic
def setup_passes(scene, view_layer=None) -> list[str]:
    """Enables on ``view_layer`` (default: the scene's first) every pass the method needs, adds the
    reflection-occlusion and view-vector AOVs (and their nodes in every material of the scene's
    meshes), gives objects and materials without one a unique pass index, and sets the output to a
    32-bit multilayer EXR. Returns the pass names (as in the EXR)."""
    vl = view_layer or scene.view_layers[0]
    for attr in ("use_pass_normal", "use_pass_diffuse_direct", "use_pass_diffuse_indirect", "use_pass_diffuse_color",
                 "use_pass_glossy_direct", "use_pass_glossy_indirect", "use_pass_glossy_color", "use_pass_object_index",
                 "use_pass_material_index", "use_pass_ambient_occlusion", "use_pass_z"):
        setattr(vl, attr, True)
    have = {a.name for a in vl.aovs}
    for name, kind in ((AOV_REFLOCC, "VALUE"), (AOV_CAMERA_X, "COLOR"), (AOV_CAMERA_Y, "COLOR"), (AOV_INCOMING_CAM, "COLOR")):
        if name not in have:
            a = vl.aovs.add()
            a.name, a.type = name, kind
    meshes = [o for o in scene.objects if o.type == "MESH"]
    used = {o.pass_index for o in meshes if o.pass_index}
    nxt = max(used, default=0) + 1
    mats = []
    for o in meshes:
        if not o.pass_index:
            o.pass_index = nxt
            nxt += 1
        for slot in o.material_slots:
            if slot.material is not None and slot.material not in mats:
                mats.append(slot.material)
    mused = {m.pass_index for m in mats if m.pass_index}
    mnxt = max(mused, default=0) + 1
    for m in mats:
        if not m.pass_index:
            m.pass_index = mnxt
            mnxt += 1
        if not m.use_nodes:
            m.use_nodes = True
        _material_nodes(m)
    from ..blender import compat  # noqa: PLC0415

    compat.set_multilayer_exr(scene.render.image_settings, "32")
    return list(PASSES)


def render_passes(scene, path: str) -> "Passes":
    """Renders ``scene`` (after ``setup_passes``) to the multilayer EXR ``path`` and reads it."""
    import bpy

    setup_passes(scene)
    old = scene.render.filepath
    try:
        scene.render.filepath = path
        bpy.ops.render.render(write_still=True, scene=scene.name)
    finally:
        scene.render.filepath = old
    return read_exr(path)


def show_image(name: str, pixels: np.ndarray):
    """The recomposited image as a new (or updated) Blender image: (H, W, 3) linear, top row first."""
    import bpy

    h, w = pixels.shape[:2]
    img = bpy.data.images.get(name)
    if img is None or tuple(img.size) != (w, h):
        if img is not None:
            bpy.data.images.remove(img)
        img = bpy.data.images.new(name, w, h, alpha=True, float_buffer=True)
    rgba = np.empty((h, w, 4), np.float32)
    rgba[..., :3] = pixels[::-1]  # Blender stores the bottom row first
    rgba[..., 3] = 1.0
    img.pixels.foreach_set(rgba.reshape(-1))
    img.update()
    _keep_compositor_current(img)
    return img


def sequence_frames(directory: str, pattern: str = "*.exr") -> list[str]:
    """The frames of a sequence, in frame order: files in ``directory`` matching ``pattern``, a
    glob ('*.exr', 'shot_*.exr') or a frame-number pattern with '#' for each digit
    ('shot_####.exr'). Numbers sort by value (frame_2 before frame_10). The add-on's sequence
    operator and ``python -m rokeby.composite --sequence`` both list frames with this."""
    if not directory or not os.path.isdir(directory):
        raise CompositingError(f"folder: {directory!r} is not a folder")
    if "#" in pattern:
        regex = re.compile("^" + re.sub(r"#+", lambda m: rf"\d{{{len(m.group())}}}", re.escape(pattern).replace(r"\#", "#")) + "$")
        names = [n for n in os.listdir(directory) if regex.match(n)]
    else:
        names = [os.path.basename(f) for f in glob.glob(os.path.join(glob.escape(directory), pattern))]
    key = lambda n: [int(s) if s.isdigit() else s for s in re.split(r"(\d+)", n)]  # noqa: E731
    return [os.path.join(directory, n) for n in sorted(names, key=key) if os.path.isfile(os.path.join(directory, n))]


# --- the compositor's input ------------------------------------------------------------
# Zubiaga et al. edit normals inside a node-based compositor. Rokeby's recompositing runs outside
# Blender's compositor (Rust or GLSL), so its result enters the compositor as an Image node named
# COMPOSITOR_NODE that every recomposite of the same image keeps pointing at the current pixels
# (show_image → _keep_compositor_current): the artist chains it with other compositor nodes, and a
# Viewer shows it in the backdrop. The Composite node (what F12 renders write) is not touched.
COMPOSITOR_NODE = schema.COMPOSITOR_NODE
COMPOSITOR_IMAGE_KEY = schema.COMPOSITOR_IMAGE_KEY  # custom property on that node: the image it follows


def feed_compositor(scene, image):
    """Puts ``image`` (a recomposited Blender image) into ``scene``'s compositor: turns the
    compositor on, adds (or reuses) the Image node COMPOSITOR_NODE reading it, and feeds the
    Viewer with it (one is added when the tree has none) so the backdrop shows it, as clicking a
    node with Ctrl+Shift does. The Composite node (what renders write) and the artist's other
    links stay as they are. Returns the node; later recomposites of the same image name update
    what it reads."""
    if image is None:
        raise CompositingError("image: none given: click Render and Recomposite (or Recomposite Render) first")
    if scene is None:
        raise CompositingError("scene: none given")
    from ..blender import compat  # noqa: PLC0415

    tree = compat.compositor_tree(scene, create=True)
    node = tree.nodes.get(COMPOSITOR_NODE)
    if node is None or node.bl_idname != "CompositorNodeImage":
        node = tree.nodes.new("CompositorNodeImage")
        node.name = COMPOSITOR_NODE
        node.label = schema.RECOMPOSITED_IMAGE
        xs = [n.location.x for n in tree.nodes if n != node]
        node.location = (min(xs) if xs else 0.0, min((n.location.y for n in tree.nodes if n != node), default=0.0) - 350.0)
    node.image = image
    node[COMPOSITOR_IMAGE_KEY] = image.name
    viewer = next((n for n in tree.nodes if n.bl_idname == "CompositorNodeViewer"), None)
    if viewer is None:
        viewer = tree.nodes.new("CompositorNodeViewer")
        viewer.location = (node.location.x + 300.0, node.location.y)
    tree.links.new(node.outputs["Image"], viewer.inputs[0])
    return node


def _keep_compositor_current(img) -> None:
    """Every scene's COMPOSITOR_NODE that follows ``img``'s name reads ``img`` (show_image makes a
    new image when the frame size changes) and the compositor sees the new pixels."""
    import bpy

    from ..blender import compat  # noqa: PLC0415

    for sc in bpy.data.scenes:
        tree = compat.compositor_tree(sc)
        node = tree.nodes.get(COMPOSITOR_NODE) if tree is not None else None
        if node is not None and node.get(COMPOSITOR_IMAGE_KEY) == img.name:
            if node.image != img:
                node.image = img
            tree.update_tag()


# --- passes -------------------------------------------------------------------------------------

@dataclass
class Passes:
    """Render passes of one frame, (H, W[, C]) float32 arrays, top row first."""
    image: np.ndarray
    normal: np.ndarray
    diff_dir: np.ndarray
    diff_ind: np.ndarray
    diff_col: np.ndarray
    gloss_dir: np.ndarray
    gloss_ind: np.ndarray
    gloss_col: np.ndarray
    index_ob: np.ndarray
    index_ma: np.ndarray
    ao: np.ndarray
    depth: np.ndarray
    reflocc: np.ndarray
    camera_x: np.ndarray
    camera_y: np.ndarray
    incoming_cam: np.ndarray
    alpha: np.ndarray | None = None
    header: dict = field(default_factory=dict)

    @property
    def shape(self):
        return self.image.shape[:2]

    def validate(self) -> None:
        h, w = self.shape
        for name, (attr, ch) in PASSES.items():
            a = getattr(self, attr)
            want = (h, w) if ch == 1 else (h, w, 3)
            if a.shape != want:
                raise CompositingError(f"pass {name}: expected shape {want} like Combined, got {a.shape}")


def _layer_channels(part_channels: dict, layer: str | None):
    layers = sorted({k.split(".")[0] for k in part_channels if "." in k})
    if layer is None:
        if not layers:
            raise CompositingError("not a Blender multilayer EXR (no 'Layer.Pass' channels)")
        layer = layers[0]
    elif layer not in layers:
        raise CompositingError(f"view layer {layer!r} not in the EXR (it has {layers})")
    return layer


def read_exr(path: str, layer: str | None = None) -> Passes:
    """Reads a Blender multilayer EXR (one view layer, default the first) into ``Passes``. A file
    that is not a readable EXR (truncated, corrupted, a compression or layout the reader does not
    take) is a ``CompositingError`` naming it and what is wrong; a missing or unreadable one stays
    an ``OSError``."""
    try:
        parts = exr.read(path)
    except exr.ExrError as exc:
        raise CompositingError(f"{path}: not a readable multilayer EXR (truncated or corrupted?): {exc.why}") from None
    if not parts:
        raise CompositingError(f"{path}: not a readable multilayer EXR (truncated or corrupted?): it has no image parts")
    return _passes(path, parts, layer)


def _pass_pixels(chans: dict, bases: list) -> "np.ndarray | None":
    """The pixels of the first of ``bases`` (``Layer.Pass``) the channels hold: R, G, B[, A] (the
    group OpenEXR's reader makes of them), or X[YZ], R[GB], V, Z; None when none is there."""
    for base in bases:
        rgb = exr.colour(chans, base + ".")
        if rgb is not None:
            return rgb
        for suffixes in ("XYZ", "RGB", "X", "V", "Z", "R"):
            keys = [f"{base}.{c}" for c in suffixes]
            if all(k in chans for k in keys):
                return np.stack([np.asarray(chans[k], np.float32) for k in keys], -1)
    return None


def _passes(path, parts: list, layer: str | None) -> Passes:
    # Blender 5.0+ writes a multilayer EXR as one part per pass by default (up to 4.5, and with
    # "interleave", one part): the channel names carry the layer and pass either way.
    chans = {}
    for p in parts:
        chans.update(p.channels)
    layer = _layer_channels(chans, layer)
    arrays, missing = {}, []
    for name, (attr, ch) in PASSES.items():
        a = _pass_pixels(chans, [f"{layer}.{n}" for n in exr_pass_names(name)])
        if a is None:
            missing.append(name)
            continue
        if a.ndim == 2:
            a = a[..., None]
        if ch == 1:
            a = a[..., 0]
        elif a.shape[-1] >= 3:
            a = a[..., :3]
        else:
            raise CompositingError(f"pass {name}: expected 3 channels, got {a.shape[-1]}")
        arrays[attr] = np.ascontiguousarray(a)
    if missing:
        raise MissingPasses(missing, str(path))
    comb = exr.colour(chans, f"{layer}.Combined.")
    alpha = comb[..., 3].copy() if comb is not None and comb.shape[2] == 4 else None
    header = {k: v for k, v in parts[0].header.items() if isinstance(v, (str, int, float))}
    p = Passes(alpha=alpha, header=header, **arrays)
    p.validate()
    return p


def write_exr(path: str, image: np.ndarray, header: dict | None = None) -> None:
    """Writes an (H, W, 3) float32 image as an RGB EXR (float channels R, G, B, ZIP compressed,
    the string attributes of ``header`` but File and Date), whole or not at all."""
    hdr = {k: v for k, v in (header or {}).items() if isinstance(v, str) and k not in ("File", "Date")}
    data = exr.encode(exr.split("", np.asarray(image, np.float32)[..., :3]), hdr, "zip")
    transaction.write_whole(path, lambda tmp: exr.save(tmp, data))  # no half-written file, the old one kept on failure


# --- screen space -------------------------------------------------------------------------------

def _unit(a: np.ndarray) -> np.ndarray:
    n = np.linalg.norm(a, axis=-1, keepdims=True)
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(n > 1e-12, a / n, 0.0).astype(np.float32)


def camera_rotation(camera_x: np.ndarray, camera_y: np.ndarray) -> np.ndarray:
    """World → screen-space rotation (3×3) from the AOVs holding the world X and Y axes in Blender's
    shader camera space (z forward) at every surface pixel: their mean over the pixels, flipped to
    z towards the viewer, completed by the cross product and re-orthonormalised (SVD)."""
    x = camera_x.reshape(-1, 3).astype(np.float64)
    y = camera_y.reshape(-1, 3).astype(np.float64)
    ok = (np.abs(np.linalg.norm(x, axis=1) - 1) < 1e-3) & (np.abs(np.linalg.norm(y, axis=1) - 1) < 1e-3)
    if not ok.any():
        raise CompositingError(f"passes {AOV_CAMERA_X}/{AOV_CAMERA_Y}: no surface pixel holds the camera rotation "
                               "(a material without the AOV outputs? Set Up Compositing Passes adds them again)")
    cx = _CAM_FLIP @ x[ok].mean(0)
    cy = _CAM_FLIP @ y[ok].mean(0)
    m = np.stack([cx, cy, np.cross(cx, cy)], 1)  # columns: world axes in screen space
    u, _s, vt = np.linalg.svd(m)
    return u @ vt


def screen_space(p: Passes) -> tuple[np.ndarray, np.ndarray]:
    """Screen-space normals and view vectors (H, W, 3) float32; zero where there is no surface."""
    rot = camera_rotation(p.camera_x, p.camera_y)
    n = _unit(p.normal @ rot.T.astype(np.float32))
    v = _unit(p.incoming_cam * _CAM_FLIP.diagonal().astype(np.float32))
    return n, v


def patch_ids(index_ob: np.ndarray, index_ma: np.ndarray) -> tuple[np.ndarray, list[tuple[int, int]]]:
    """One id per (object index, material index) pair with object index > 0; −1 elsewhere."""
    ob = np.rint(np.nan_to_num(index_ob, nan=0)).astype(np.int64)
    ma = np.rint(np.nan_to_num(index_ma, nan=0)).astype(np.int64)
    key = ob * (1 << 20) + ma
    valid = ob > 0
    keys, inv = np.unique(key[valid], return_inverse=True)
    ids = np.full(ob.shape, -1, np.int32)
    ids[valid] = inv
    return ids, [(int(k >> 20), int(k & ((1 << 20) - 1))) for k in keys]


# --- reconstruction -----------------------------------------------------------------------------

@dataclass
class PatchReport:
    key: tuple[int, int]
    pixels: int
    diffuse: str            # "qp"/"ls" fit, or why not
    reflection: str         # "ok" or why not
    sh_rms_residual: float = float("nan")
    sh_max_residual: float = float("nan")
    coverage: float = 0.0
    filled_texels: int = 0
    noise_sigma: tuple = ()  # per channel: the estimated noise of D0 (``pixel_noise``), when measured
    sh_tolerance: tuple = ()  # per channel: the QP's tolerance τ (D(n) ≥ D0 − τ), when not 0


@dataclass
class Reconstruction:
    ids: np.ndarray
    keys: list
    patches: list           # per id: {"sh": (3, 9) | None, "env": (2, S, S, 3) | None}
    reports: list
    normals: np.ndarray     # screen-space normals the environments were fitted to
    view: np.ndarray
    timings: dict = field(default_factory=dict)

    def warnings(self) -> list[str]:
        return self.warnings_of(self.reports)

    @staticmethod
    def warnings_of(reports) -> list[str]:
        """What a user should hear of these patch reports: patches left unedited, large holes."""
        out = []
        for r in reports:
            if r.diffuse not in ("qp", "ls"):
                out.append(f"patch {r.key}: diffuse not edited: {r.diffuse}")
            if r.reflection != "ok":
                out.append(f"patch {r.key}: reflection not edited: {r.reflection}")
            elif r.coverage < 0.5:
                out.append(f"patch {r.key}: holes cover {100 * (1 - r.coverage):.0f}% of the sphere of reflected "
                           "directions: strongly edited reflections are extrapolated")
        return out


def pixel_noise(values: np.ndarray, mask: np.ndarray) -> np.ndarray:
    """Per channel, the standard deviation of the per-pixel noise of ``values`` (H, W, C) on ``mask``
    (H, W): from the differences of horizontally and vertically adjacent pixels both in the mask,
    σ = 1.4826 · median|Δ| / √2 (the median absolute deviation of the difference of two independent
    noisy pixels; robust to the few pairs that straddle an edge or a shading change). Zeros when
    fewer than 16 pairs exist. Path-traced passes have independent noise per pixel; smooth shading
    changes little between neighbours."""
    rows, cols = np.flatnonzero(mask.any(1)), np.flatnonzero(mask.any(0))
    if len(rows) == 0:
        return np.zeros(values.shape[-1])
    box = (slice(rows[0], rows[-1] + 1), slice(cols[0], cols[-1] + 1))  # the patch's bounding box
    values, mask = values[box], mask[box]
    diffs = []
    for axis in (0, 1):
        a = np.swapaxes(values, 0, axis)
        m = np.swapaxes(mask, 0, axis)
        both = m[1:] & m[:-1]
        diffs.append((a[1:] - a[:-1])[both])
    d = np.concatenate(diffs, 0)
    if len(d) < 16:
        return np.zeros(values.shape[-1])
    return 1.4826 * np.median(np.abs(d), axis=0) / np.sqrt(2.0)


# The reflection maps' texels per paraboloid face the native core accepts (reflection_env's size).
ENV_SIZES = (8, 4096)


def reconstruct(p: Passes, *, method: str = "qp", env_size: int = 128, min_pixels: int = 64,
                min_coverage: float = 0.01, blur_sigma: float = 2.0, occlusion_threshold: float = 0.5,
                noise_tolerance: float = 0.0, warn: bool = True) -> Reconstruction:
    """Diffuse (SH) and reflection (dual paraboloid) environments for every object/material patch.

    ``method``: 'qp' (§3.1: D(n) ≥ D0 at every pixel, so that the residual is occlusion) or 'ls'
    (least squares, the fast option). ``noise_tolerance`` κ (for 'qp'): the constraint becomes
    D(n) ≥ D0 − κσ with σ the patch's pixel noise (``pixel_noise``) — on a path-traced render the
    paper's QP (κ = 0) rises to the noisiest pixel; κ ≈ 2 leaves the noise to the residual."""
    import time

    if isinstance(env_size, bool) or not isinstance(env_size, (int, np.integer)) or not ENV_SIZES[0] <= env_size <= ENV_SIZES[1]:
        raise CompositingError(f"env_size: texels per paraboloid face must be a whole number from {ENV_SIZES[0]} to {ENV_SIZES[1]}, got {env_size!r}")
    if not (math.isfinite(noise_tolerance) and noise_tolerance >= 0):
        raise CompositingError(f"noise_tolerance: must be finite and ≥ 0 (in noise standard deviations), got {noise_tolerance}")
    if noise_tolerance > 0 and method != "qp":
        raise CompositingError(f"noise_tolerance: only the 'qp' fit has constraints to relax (method is {method!r})")

    nm = native.module()
    p.validate()
    normals, view = screen_space(p)
    ids, keys = patch_ids(p.index_ob, p.index_ma)
    d0 = p.diff_dir + p.diff_ind
    r0 = p.gloss_dir + p.gloss_ind
    finite = np.isfinite(normals).all(-1) & (np.abs(normals).sum(-1) > 0) & np.isfinite(d0).all(-1) & np.isfinite(r0).all(-1)
    refl = nm.compositing.reflect_dirs(normals, view)
    patches, reports = [], []
    t_sh = t_env = 0.0
    for k, key in enumerate(keys):
        m = (ids == k) & finite
        n_px = int(m.sum())
        rep = PatchReport(key=key, pixels=n_px, diffuse="", reflection="")
        entry = {"sh": None, "env": None}
        if n_px < min_pixels:
            rep.diffuse = rep.reflection = f"covers only {n_px} pixels (< min_pixels = {min_pixels}): left unchanged"
        else:
            t0 = time.perf_counter()
            tol = None
            if noise_tolerance > 0:
                sigma = pixel_noise(d0, m)
                tol = noise_tolerance * sigma
                rep.noise_sigma, rep.sh_tolerance = tuple(map(float, sigma)), tuple(map(float, tol))
            fit = nm.compositing.sh_fit(normals[m], d0[m], method, tol)
            t_sh += time.perf_counter() - t0
            entry["sh"] = fit["coeffs"]
            rep.diffuse = method
            rep.sh_rms_residual = float(fit["rms_residual"].max())
            rep.sh_max_residual = float(fit["max_residual"].max())
            if not (r0[m] > 0).any():
                rep.reflection = "no reflection shading on this patch"
            else:
                mask = (m & (p.reflocc >= occlusion_threshold)).astype(np.float32)
                t0 = time.perf_counter()
                try:
                    env = nm.compositing.reflection_env(refl, r0, mask, p.depth, size=env_size, blur_sigma=blur_sigma, min_coverage=min_coverage)
                    entry["env"] = env["map"]
                    rep.reflection = "ok"
                    rep.coverage = float(env["coverage"])
                    rep.filled_texels = int(env["filled_texels"])
                except ValueError as exc:
                    rep.reflection = str(exc)
                t_env += time.perf_counter() - t0
        patches.append(entry)
        reports.append(rep)
    rec = Reconstruction(ids=ids, keys=keys, patches=patches, reports=reports, normals=normals, view=view,
                         timings={"diffuse_s": t_sh, "reflection_s": t_env})
    if warn:
        for msg in rec.warnings():
            warnings.warn(msg, RuntimeWarning, stacklevel=2)
    return rec


RECOMPOSITE_BACKENDS = ("cpu", "blender_gpu", "moderngl")


def recomposite(p: Passes, rec: Reconstruction, edited_normals: np.ndarray, *, k_d: float = 1.0,
                k_r: float = 1.0, use_occlusion: bool = True, backend: str = "cpu") -> tuple[np.ndarray, dict]:
    """Eqs. 3–5: the image (H, W, 3) with the edited screen-space normals. Returns (image, stats).

    ``backend``: 'cpu' (the Rust core, f32), 'blender_gpu' (the GLSL shader drawn by Blender's
    ``gpu`` module, ``rokeby.compositing.blender_gpu``; in background mode the first call makes the GPU
    context with one 8×8 EEVEE render) or 'moderngl' (the same shader on a headless EGL context).
    All three agree within 1e-4 relative and give unmodified normals back bit for bit. For many
    edits of one frame (a slider), ``RecompositeSession`` packs and uploads the passes once."""
    if backend == "cpu":  # one frame: the passes read in place, not copied into a session's core
        h, w = p.shape
        e = np.asarray(edited_normals)
        if e.shape != (h, w, 3):
            raise CompositingError(f"edited_normals: expected shape {(h, w, 3)} like the passes, got {e.shape}")
        _check_k(k_d, k_r)
        a, kw = _recomposite_args(p, rec, use_occlusion)
        out = native.module().compositing.recomposite(a[0], a[1], e, *a[3:], **kw, k_d=k_d, k_r=k_r)
        _check_output(out, a[6])
        return out
    return RecompositeSession(p, rec, use_occlusion=use_occlusion, backend=backend)(edited_normals, k_d=k_d, k_r=k_r)


def _recomposite_args(p: Passes, rec: Reconstruction, use_occlusion: bool) -> tuple[tuple, dict]:
    """``rokeby_native.compositing.recomposite``'s arguments (edited_normals None) and keywords for a frame."""
    ao = p.ao.mean(-1) if p.ao.ndim == 3 else p.ao
    args = (rec.ids, rec.normals, None, rec.view, p.diff_dir + p.diff_ind, p.gloss_dir + p.gloss_ind, p.image, rec.patches)
    kw = {"alpha_d": np.clip(ao, 0, 1) if use_occlusion else None,
          "alpha_r": np.clip(p.reflocc, 0, 1) if use_occlusion else None,
          "diffuse_color": p.diff_col, "reflection_color": p.gloss_col}
    return args, kw


class RecompositeSession:
    """Interactive recompositing of one rendered frame: an artist's slider loop. The passes and the
    reconstruction are checked and packed once, here; each call takes new edited normals (and
    k_D, k_R) and returns (image, stats) as ``recomposite`` does. On the CPU backend the passes
    are held by the Rust core (``rokeby_native.compositing.Recompositor``), each call passes only the edited
    normals and writes into ``out`` (or a new array), the GIL released, and the core refuses
    overflow itself (no pass over the result here). On a GLSL backend only the edited normals go to
    the GPU again: the other ten images and the reflection maps stay there, as long as no other
    frame is drawn by the same backend in between (then the next call uploads all). The passes and
    the reconstruction are read when the session is made (and, on a GLSL backend, uploaded on its
    first call): change them in place and make a new session. ``timings`` holds the last call's
    seconds ('check', 'recomposite', 'total')."""

    def __init__(self, p: Passes, rec: Reconstruction, *, use_occlusion: bool = True, backend: str = "cpu"):
        if backend not in RECOMPOSITE_BACKENDS:
            raise CompositingError(f"backend: unknown {backend!r} (expected one of {', '.join(map(repr, RECOMPOSITE_BACKENDS))})")
        self.shape = p.shape
        self.backend = backend
        self._args, self._kw = _recomposite_args(p, rec, use_occlusion)
        self._frame = None  # the GLSL backends' packed frame, made on the first call
        self._buffer = None
        self._native = None
        if backend == "cpu":  # the core holds the passes now: only the GLSL backends need the arrays again
            self._core()
            self._args = (None, None, None, None, None, None, p.image, rec.patches)
            self._kw = {}
        self.timings: dict = {}

    @property
    def buffer(self) -> np.ndarray:
        """A (H, W, 3) float32 array of the session's, for ``out=`` when the caller copies the image
        elsewhere before the next call (into a Blender image): no new array per edit."""
        if self._buffer is None:
            self._buffer = np.empty((*self.shape, 3), np.float32)
        return self._buffer

    def _check(self, edited_normals) -> np.ndarray:
        h, w = self.shape
        e = np.asarray(edited_normals)
        if e.shape != (h, w, 3):
            raise CompositingError(f"edited_normals: expected shape {(h, w, 3)} like the passes, got {e.shape}")
        return e

    def __call__(self, edited_normals, *, k_d: float = 1.0, k_r: float = 1.0, out: np.ndarray | None = None) -> tuple[np.ndarray, dict]:
        """``out``: a (H, W, 3) float32 C-contiguous array to write the image into (CPU backend;
        e.g. ``buffer``), returned; None: a new one."""
        t0 = time.perf_counter()
        e = self._check(edited_normals)
        _check_k(k_d, k_r)
        if self.backend == "cpu":
            t1 = time.perf_counter()
            if out is None:
                out = np.empty((*self.shape, 3), np.float32)
            result = out, self._run(out, e, None, None, k_d, k_r)
        else:
            if self._frame is None:
                a = self._args
                self._frame = recomposite_frame(a[0], a[1], e, *a[3:], **self._kw, k_d=k_d, k_r=k_r)
                changed = None
            else:
                self._frame.set_edit(e, k_d, k_r)
                changed = ("rk_edited",)  # the backend uploads all if it drew another frame since
            t1 = time.perf_counter()
            result = self._backend().draw(self._frame, changed)
            _check_output(result, self._args[6])
            if out is not None:
                out[...] = result[0]
                result = out, result[1]
        t2 = time.perf_counter()
        self.timings = {"check": t1 - t0, "recomposite": t2 - t1, "total": t2 - t0}
        return result

    def _core(self):
        """The passes copied into the Rust core once (``rokeby_native.compositing.Recompositor``): the CPU
        backend's frames and every backend's windows."""
        if self._native is None:
            a = self._args
            self._native = native.module().compositing.Recompositor(a[0], a[1], *a[3:], **self._kw)
        return self._native

    def _run(self, out, edited, rows, cols, k_d, k_r) -> dict:
        try:
            return self._core().run(out, edited, rows, cols, k_d, k_r)
        except ValueError as exc:
            if "overflows float32" in str(exc):
                raise CompositingError(f"the recomposited image has non-finite pixels where the render is finite (k_d, k_r or "
                                       f"the edit too large for float32?); {exc}") from None
            raise CompositingError(str(exc)) from None

    def window(self, edited_normals, rows: slice, cols: slice, *, k_d: float = 1.0, k_r: float = 1.0,
               out: np.ndarray | None = None) -> tuple[np.ndarray, dict]:
        """Eqs. 3–5 on the pixels rows × cols only, by the Rust core whatever the backend: the
        equations are per pixel, so the result equals those pixels of a whole-frame call. For a
        brush that changes a small part of the frame (``rokeby.compositing.brush``).
        ``edited_normals``: the window's ñ (rh, rw, 3), or the whole frame's (H, W, 3) of which
        the window is read. ``out``: None (a new (rh, rw, 3) array), an (rh, rw, 3) array, or the
        whole (H, W, 3) image of which only the window is written; float32, C-contiguous."""
        e = np.asarray(edited_normals)
        h, w = self.shape
        rr, cc = range(h)[rows], range(w)[cols]
        wshape = (len(rr), len(cc), 3)
        if e.shape not in (wshape, (h, w, 3)):
            raise CompositingError(f"edited_normals: expected shape {wshape} like the window (or {(h, w, 3)}), got {e.shape}")
        _check_k(k_d, k_r)
        if out is None:
            out = np.empty(wshape, np.float32)
        return out, self._run(out, e, rows, cols, k_d, k_r)

    def _backend(self):
        if self.backend == "blender_gpu":
            from . import blender_gpu as in_blender  # noqa: PLC0415

            in_blender.ensure_context()
            return in_blender.blender_recompositor()
        return gl_recompositor()


EDITS = ("emboss", "ripple", "noise", "smooth", "none")


def edit_normals(p: Passes, rec: Reconstruction, edit: str, amount: float) -> np.ndarray:
    """The one-knob edits of the operators and ``rokeby.api`` on the patches' pixels: 'emboss'
    (β = amount), 'ripple' or 'noise' (a decal at the centre, strength amount), 'smooth'
    (cross-bilateral with depth, σ = amount pixels) or 'none' (the shown normals: material edits
    k_D, k_R only)."""
    n = rec.normals
    on = rec.ids >= 0
    if edit == "emboss":
        return emboss(n, amount, mask=on)
    if edit == "ripple":
        return bump(n, ripple(p.shape), amount, mask=on)
    if edit == "noise":
        return bump(n, noise_decal(p.shape), amount, mask=on)
    if edit == "smooth":
        return bilateral_smooth(n, p.depth, sigma_s=amount, mask=on)
    if edit == "none":
        return n
    raise CompositingError(f"edit: unknown {edit!r} (expected one of {', '.join(map(repr, EDITS))})")


@dataclass
class RenderEdit:
    """A rendered frame open for editing: its passes, its reconstruction and a recompositing
    session, kept by ``open_render`` between edits of the same file."""

    path: str
    passes: Passes
    reconstruction: Reconstruction
    session: RecompositeSession
    fit: tuple = ("qp", 0.0)  # the reconstruction's (method, noise_tolerance)
    reused: bool = False  # whether open_render found the file already open
    reconstructed: bool = True  # whether the last open_render reconstructed it


_OPEN: dict = {}  # the one frame open for editing (its arrays are ~150 MB at 1920×1080)


def _file_key(path: str) -> tuple:
    import os  # noqa: PLC0415

    st = os.stat(path)  # the change time and inode too: a coarse-clock filesystem may keep mtime and size
    return os.path.realpath(path), st.st_mtime_ns, st.st_ctime_ns, st.st_ino, st.st_size


def open_render(path: str, *, backend: str = "cpu", passes: Passes | None = None, warn: bool = True,
                method: str = "qp", noise_tolerance: float = 0.0) -> RenderEdit:
    """The multilayer EXR ``path`` (rendered after ``setup_passes``) read, reconstructed and ready to
    recomposite. The last file opened stays open: opening it again while the file is unchanged
    (same modification and change times, inode and size) reuses its passes; with the same diffuse
    fit (``method``, ``noise_tolerance``: see ``reconstruct``) its reconstruction, and with the same
    backend its session too (on a GLSL backend the passes stay on the GPU), so that trying edit
    after edit costs only the edit and the recompositing. A changed file is read again.
    ``passes``: the file's passes if the caller has just read them (``render_passes``); ``warn``:
    reconstruction warnings as Python warnings (when reconstructing; ``.reconstruction.warnings()``
    lists them in any case)."""
    if backend not in RECOMPOSITE_BACKENDS:
        raise CompositingError(f"backend: unknown {backend!r} (expected one of {', '.join(map(repr, RECOMPOSITE_BACKENDS))})")
    fit = (method, float(noise_tolerance))
    try:
        key = _file_key(path)
    except OSError as exc:
        raise CompositingError(f"{path}: cannot open the rendered passes ({exc.strerror or exc})") from None
    got = _OPEN.get("frame")
    if got is not None and got[0] == key:
        opened = got[1]
        opened.reconstructed = opened.fit != fit
        if opened.reconstructed:  # another diffuse fit of the same passes: reconstruct, no reading
            opened.reconstruction = reconstruct(opened.passes, method=method, noise_tolerance=noise_tolerance, warn=warn)
            opened.fit = fit
            opened.session = RecompositeSession(opened.passes, opened.reconstruction, backend=backend)
        elif opened.session.backend != backend:  # same reconstruction, another backend: a new session
            opened.session = RecompositeSession(opened.passes, opened.reconstruction, backend=backend)
        opened.reused = True
        return opened
    _OPEN.clear()  # before reading the next one: only one frame's arrays at a time
    p = passes if passes is not None else read_exr(path)
    rec = reconstruct(p, method=method, noise_tolerance=noise_tolerance, warn=warn)
    opened = RenderEdit(path=path, passes=p, reconstruction=rec,
                        session=RecompositeSession(p, rec, backend=backend), fit=fit)
    _OPEN["frame"] = (key, opened)
    return opened


def close_render() -> None:
    """Forgets the frame ``open_render`` keeps (and its memory)."""
    _OPEN.clear()


# --- the GLSL path (eqs. 3–5 in shaders/rokeby_recomposite_*.glsl) and its moderngl backend: gl.py ------

from .gl import _check_k, _check_output, gl_recompositor, recomposite_frame  # noqa: E402


# --- normal-editing tools (screen-space normals (H, W, 3); `mask` (H, W) limits the edit) ---------

def _native_edit(fn, *args, **kw) -> np.ndarray:
    """A normal tool of the Rust core (``rokeby_core::normals``), its ValueErrors as CompositingError."""
    try:
        return fn(*args, **kw)
    except ValueError as exc:
        raise CompositingError(str(exc)) from None


def emboss(normals: np.ndarray, beta: float, mask=None) -> np.ndarray:
    """Normal embossing (LUMO): n_z → β n_z, renormalised; β ∈ (0, 1] makes the surface bulge.
    Background pixels (|n|₁ = 0), pixels outside ``mask`` (H, W; > 0.5 edits) and pixels the edit
    leaves unchanged keep their input bits (``rokeby_core::normals``, rows in parallel)."""
    if not 0 < beta <= 1:
        raise CompositingError(f"beta: must be in (0, 1], got {beta}")
    return _native_edit(native.module().compositing.normals_emboss, normals, beta, mask)


def _decal_place(shape, center, radius):
    """(row, col, radius) of a decal: the frame's centre and 0.35·min(H, W) by default; given
    ones must be finite (and the radius positive)."""
    h, w = shape
    cy, cx = (h / 2, w / 2) if center is None else (float(center[0]), float(center[1]))
    if not (math.isfinite(cy) and math.isfinite(cx)):
        raise CompositingError(f"center: must be finite pixel coordinates, got {center!r}")
    if radius is None:
        radius = 0.35 * min(h, w)
    elif not (math.isfinite(radius) and radius > 0):
        raise CompositingError(f"radius: must be positive and finite (pixels), got {radius}")
    return cy, cx, float(radius)


def ripple(shape, center=None, wavelength: float = 24.0, radius: float | None = None) -> np.ndarray:
    """The paper's fading 2D ripple height field (pixels): cos(2π d/λ)·(1 − d/radius)₊²."""
    h, w = shape
    cy, cx, radius = _decal_place(shape, center, radius)
    if not (math.isfinite(wavelength) and wavelength > 0):
        raise CompositingError(f"wavelength: must be positive and finite (pixels), got {wavelength}")
    yy, xx = np.mgrid[0:h, 0:w].astype(np.float32)
    d = np.hypot(yy - cy, xx - cx)
    return (np.cos(2 * math.pi * d / wavelength) * np.clip(1 - d / radius, 0, None) ** 2).astype(np.float32)


def noise_decal(shape, size: float = 16.0, octaves: int = 3, seed: int = 0, center=None,
                radius: float | None = None) -> np.ndarray:
    """A procedural noise bump decal (H, W): fractal gradient noise of feature size ``size`` pixels
    and ``octaves`` octaves, seeded, faded like ``ripple`` by (1 − d/radius)₊² around ``center``
    ((row, col) pixels; default the frame's centre, radius 0.35·min(H, W)). Heights in pixels,
    within about ±size/4, so that ``bump(n, noise_decal(...), s)`` tilts normals alike at any size."""
    h, w = shape
    cy, cx, radius = _decal_place(shape, center, radius)
    if not (isinstance(seed, (int, np.integer)) and 0 <= seed < 2 ** 32):
        raise CompositingError(f"seed: expected an integer in [0, 2^32), got {seed!r}")
    if not (isinstance(octaves, (int, np.integer)) and 1 <= octaves <= 8):
        raise CompositingError(f"octaves: must be 1 to 8, got {octaves!r}")
    return _native_edit(native.module().compositing.normals_noise_decal, int(h), int(w), float(size), int(octaves), int(seed),
                        (float(cx), float(cy)), float(radius))


def bump(normals: np.ndarray, height: np.ndarray, strength: float = 1.0, mask=None) -> np.ndarray:
    """Bump mapping in screen space: ñ = normalize(n − s ∇h), ∇h = (∂h/∂col, −∂h/∂row, 0)
    (rows go down, screen y goes up; the gradient as ``np.gradient`` takes it); ``height`` (H, W)
    in pixels of height per pixel. Kept pixels as for ``emboss``."""
    height = np.asarray(height)
    if height.shape != np.shape(normals)[:2]:
        raise CompositingError(f"height: expected shape {np.shape(normals)[:2]} like the normals, got {height.shape}")
    return _native_edit(native.module().compositing.normals_bump, normals, height, float(strength), mask)


def bilateral_smooth(normals: np.ndarray, depth: np.ndarray, sigma_s: float = 3.0, sigma_d: float = 0.02,
                     mask=None) -> np.ndarray:
    """Cross-bilateral filter of the projected normals (n_x, n_y) with a depth range kernel
    (relative depth difference, σ_d), so occluding contours are kept; n_z = √(1 − |n̄|²). Window
    radius ⌈2σ_s⌉ (σ_s ≤ 50 pixels); pixels without a finite depth or normal neither move nor
    weigh. Kept pixels as for ``emboss``."""
    return _native_edit(native.module().compositing.normals_bilateral, normals, depth, float(sigma_s), float(sigma_d), mask)


# --- Command line: python -m rokeby.composite, and the farm's recompositing job ----------------

def _pair(text: str) -> tuple[float, float]:
    import argparse  # noqa: PLC0415

    try:
        x, y = (float(v) for v in text.split(","))
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected X,Y in pixels, got {text!r}") from None
    return x, y


def _indices(text: str) -> list[int]:
    import argparse  # noqa: PLC0415

    try:
        return [int(v) for v in text.split(",")]
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected comma-separated object pass indices, got {text!r}") from None


def command_parser(prog: str = "python -m rokeby.composite", description: str | None = None, parser_class=None):
    """The argument parser of ``python -m rokeby.composite`` (its files, sequence options and edit
    options), ``parser_class`` an ``argparse.ArgumentParser`` subclass (how errors are reported)."""
    import argparse  # noqa: PLC0415

    ap = (parser_class or argparse.ArgumentParser)(prog=prog, description=description)
    ap.add_argument("input", help="Blender multilayer EXR with the passes of setup_passes (with --sequence: the folder of frames)")
    ap.add_argument("output", help="recomposited RGB EXR (with --sequence: the output folder)")
    ap.add_argument("--sequence", action="store_true", help="input and output are folders: recomposite every frame")
    ap.add_argument("--pattern", default="*.exr", help="with --sequence: which files are frames, a glob or '#' per digit (default *.exr)")
    ap.add_argument("--frame", type=int, metavar="K", help="with --sequence: only the K-th frame (1-based, frame order): one process per frame")
    ap.add_argument("--skip-existing", action="store_true", help="an output that exists is kept and its frame skipped (resume a stopped run)")
    ap.add_argument("--layer", help="view layer (default: the first in the file)")
    ap.add_argument("--emboss", type=float, metavar="BETA", help="n_z → β n_z, β in (0, 1]")
    ap.add_argument("--ripple", type=float, metavar="STRENGTH", help="fading 2D ripple decal of this strength")
    ap.add_argument("--ripple-center", type=_pair, metavar="X,Y", help="ripple centre in pixels (default: image centre)")
    ap.add_argument("--ripple-wavelength", type=float, default=24.0, metavar="PX")
    ap.add_argument("--ripple-radius", type=float, metavar="PX")
    ap.add_argument("--noise", type=float, metavar="STRENGTH", help="fading procedural noise bump decal of this strength")
    ap.add_argument("--noise-size", type=float, default=16.0, metavar="PX", help="its feature size (default 16)")
    ap.add_argument("--noise-octaves", type=int, default=3, metavar="N")
    ap.add_argument("--noise-seed", type=int, default=0)
    ap.add_argument("--noise-center", type=_pair, metavar="X,Y", help="its centre in pixels (default: image centre)")
    ap.add_argument("--noise-radius", type=float, metavar="PX")
    ap.add_argument("--bump", metavar="HEIGHT", help="height image (EXR or .npy, frame-sized)")
    ap.add_argument("--bump-strength", type=float, default=1.0)
    ap.add_argument("--smooth", type=float, metavar="SIGMA_PX", help="cross-bilateral smoothing of normals with depth")
    ap.add_argument("--smooth-depth", type=float, default=0.02, metavar="REL", help="depth range kernel σ (relative)")
    ap.add_argument("--objects", type=_indices, help="comma-separated object pass indices to edit (default: all)")
    ap.add_argument("--fit", choices=("qp", "ls"), default="qp", help="diffuse SH fit (default: the QP)")
    ap.add_argument("--noise-tolerance", type=float, default=0.0, metavar="KAPPA",
                    help="the QP's constraint D(n) >= D0 - KAPPA*sigma, sigma the pixel noise of the diffuse pass "
                         "(default 0: the paper's QP; about 2-3 for a noisy render)")
    ap.add_argument("--env-size", type=int, default=128, help="texels per paraboloid face")
    ap.add_argument("--kd", type=float, default=1.0, help="diffuse intensity k_D")
    ap.add_argument("--kr", type=float, default=1.0, help="reflection intensity k_R")
    ap.add_argument("--backend", choices=RECOMPOSITE_BACKENDS, default="cpu",
                    help="eqs. 3-5 on the CPU (Rust core, default), or the GLSL shader on a headless EGL context (moderngl) "
                         "or through Blender's gpu module (blender_gpu: bpy in this process; its context costs one tiny EEVEE render)")
    ap.add_argument("--report", metavar="JSON", help="write per-patch reconstruction report and timings")
    return ap


def edit_options(options) -> list[str]:
    """Checks ``options``, edit options of ``python -m rokeby.composite`` (``["--emboss", "0.6"]``:
    everything but the files, ``--sequence``, ``--pattern``, ``--frame``, ``--skip-existing`` and
    ``--report``, which a sequence job sets per frame), as that command will parse them; returns
    them as strings. A bad flag or value, or a ``--bump`` image that is not a file, is a
    ``CompositingError`` naming it."""
    import argparse  # noqa: PLC0415

    class _Raising(argparse.ArgumentParser):
        def error(self, message):
            raise CompositingError(f"edit options: {message}")

    options = [str(v) for v in options]
    if any(v in ("-h", "--help") for v in options):
        raise CompositingError("edit options: --help is not an edit option")
    a = command_parser(parser_class=_Raising).parse_args(["in.exr", "out.exr", *options])
    for flag, given in (("--sequence", a.sequence), ("--pattern", a.pattern != "*.exr"), ("--frame", a.frame is not None),
                        ("--skip-existing", a.skip_existing), ("--report", a.report is not None)):
        if given:
            raise CompositingError(f"edit options: {flag} is not an edit option (the job sets it for each frame)")
    _check_k(a.kd, a.kr)
    if a.bump is not None and not os.path.isfile(a.bump):
        raise CompositingError(f"edit options: --bump: no such file: {a.bump}")
    return options


def one_knob_options(edit: str, amount: float, *, k_d: float = 1.0, k_r: float = 1.0, fit: str = "qp",
                     noise_tolerance: float = 0.0, backend: str = "cpu") -> list[str]:
    """The ``python -m rokeby.composite`` edit options of a one-knob edit as the operators and
    ``recomposite_exr`` apply it (:func:`edit_normals`): the same pixels, frame by frame."""
    if edit not in EDITS:
        raise CompositingError(f"edit: unknown {edit!r} (expected one of {', '.join(map(repr, EDITS))})")
    out = [] if edit == "none" else [f"--{edit}", repr(float(amount))]
    if float(k_d) != 1.0:
        out += ["--kd", repr(float(k_d))]
    if float(k_r) != 1.0:
        out += ["--kr", repr(float(k_r))]
    if fit != "qp":
        out += ["--fit", fit]
    if float(noise_tolerance) != 0.0:
        out += ["--noise-tolerance", repr(float(noise_tolerance))]
    if backend != "cpu":
        out += ["--backend", backend]
    return edit_options(out)
