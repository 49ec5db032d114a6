"""Environment maps for painting under environment light: reading and writing HDR
images (OpenEXR, and Radiance RGBE ``.hdr`` through the Rust core), reading 8-bit PNG/JPEG ones
(sRGB-decoded; Blender's image loader), conversions between lat-long, cube, sphere (mirror-ball) and dual-paraboloid
maps, order-2 SH irradiance, and specular prefiltering across roughness levels — all computed by
the Rust core (``rokeby_core::envmap``/``prefilter``) through :mod:`rokeby.core.native`.

Arrays are float32 with row 0 the top row of the image file (as OpenEXR reads it); Blender's
``Image.pixels`` are bottom-up, :func:`flip_rows` converts. Shapes per layout: latlong (H, W, C),
cube (6, S, S, C) in the order +X, −X, +Y, −Y, +Z, −Z, sphere (S, S, C), paraboloid (2, S, S, C).
Lat-long maps use Blender's equirectangular convention (+X at the image centre, as
:func:`rokeby.reflection.render.reflmap.direction_to_uv`). Formulas, algorithm and measured errors:
docs/envmaps.md.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..core import exr, native

LAYOUTS = ("latlong", "cube", "sphere", "paraboloid")
LOBES = ("phong", "ggx", "torrance_sparrow")

# Blender roughness of the default prefiltered levels (GGX, α = roughness²): level 0 is the
# environment itself.
ROUGHNESS_LEVELS = tuple(i / 7 for i in range(8))


def studio_world(name: str) -> Path:
    """Path of one of the HDR worlds bpy ships (city, courtyard, forest, interior, night, studio,
    sunrise, sunset)."""
    import bpy

    root = Path(bpy.utils.system_resource("DATAFILES")) / "studiolights" / "world"
    p = root / f"{name}.exr"
    if not p.exists():
        names = sorted(q.stem for q in root.glob("*.exr"))
        raise ValueError(f"studio_world: no world {name!r} (have {', '.join(names)})")
    return p


def use_studio_world(scene, name: str = "forest"):
    """Give ``scene`` a new world lit by one of the shipped HDRs (``studio_world``) through an
    Environment Texture node; returns the world."""
    import bpy

    world = bpy.data.worlds.new(name.capitalize())
    scene.world = world
    world.use_nodes = True
    env = world.node_tree.nodes.new("ShaderNodeTexEnvironment")
    env.image = bpy.data.images.load(str(studio_world(name)), check_existing=True)
    world.node_tree.links.new(env.outputs["Color"], world.node_tree.nodes["Background"].inputs["Color"])
    return world


def read_exr(path) -> np.ndarray:
    """An OpenEXR file's RGB (or RGBA, or single-channel Y) pixels as (H, W, C) float32, row 0 at
    the top (read by the Rust core: ``core.exr``, DWAA/DWAB included). A file that is not a
    readable EXR, or has none of those channels, raises ValueError naming it."""
    path = Path(path)
    if not path.exists():
        raise FileNotFoundError(f"read_exr: {path} does not exist")
    # DWAA/DWAB (Blender's studio worlds are DWAB) decoded too: a few texels may differ from
    # OpenEXR's decoding by a rounding, far below what lighting from the map shows.
    ch = exr.read(path, dwa=True)[0].channels
    px = exr.colour(ch)
    if px is None:
        if "Y" not in ch:
            raise ValueError(f"read_exr: {path} has no RGB/RGBA/Y channels (has {', '.join(ch)})")
        px = np.asarray(ch["Y"], np.float32)[..., None]
    return np.ascontiguousarray(px, dtype=np.float32)


def write_exr(path, pixels) -> Path:
    """Writes (H, W, 3|4) or (H, W) float pixels (row 0 at the top) as a float32 EXR (channels
    R, G, B[, A] or Y; ZIP compressed)."""
    px = np.asarray(pixels, dtype=np.float32)
    if px.ndim == 2:
        px = px[..., None]
    if px.ndim != 3 or px.shape[2] not in (1, 3, 4):
        raise ValueError(f"write_exr: pixels must have shape (H, W), (H, W, 3) or (H, W, 4), got {px.shape}")
    if not np.isfinite(px).all():
        raise ValueError("write_exr: pixels contain NaN or inf")
    data = exr.encode(exr.split("", px), None, "zip")
    path = Path(path)
    from ..blender import transaction  # noqa: PLC0415
    transaction.write_whole(path, lambda tmp: exr.save(tmp, data))  # no half-written file, the old one kept on failure
    return path


def read_hdr(path) -> np.ndarray:
    """A Radiance RGBE (``.hdr``) file's pixels as (H, W, 3) float32, row 0 at the top (the Rust
    core's decoder: flat and run-length encoded scanlines, the standard ``-Y H +X W``
    orientation; other variants raise ValueError saying what the file holds)."""
    path = Path(path)
    if not path.exists():
        raise FileNotFoundError(f"read_hdr: {path} does not exist")
    try:
        return native.module().envmaps.rgbe_decode(path.read_bytes())
    except ValueError as e:
        raise ValueError(f"read_hdr: {path}: {e}") from None


def write_hdr(path, pixels) -> Path:
    """Writes (H, W, 3|4) float pixels (row 0 at the top; alpha dropped) as a run-length encoded
    Radiance RGBE file: 8-bit mantissas with a shared exponent (within 1/128 of each pixel's
    largest channel); negative values become 0, NaN/inf are refused."""
    px = np.asarray(pixels, dtype=np.float32)
    if px.ndim != 3 or px.shape[2] not in (3, 4):
        raise ValueError(f"write_hdr: pixels must have shape (H, W, 3) or (H, W, 4), got {px.shape}")
    path = Path(path)
    path.write_bytes(native.module().envmaps.rgbe_encode(np.ascontiguousarray(px[..., :3])))
    return path


# 8-bit (LDR) environment images, as Fraser's implementation also loads: read through Blender's
# image loader (the only PNG/JPEG decoder in Rokeby's environment), sRGB-decoded to linear here.
LDR_SUFFIXES = (".png", ".jpg", ".jpeg")


def srgb_to_linear(values) -> np.ndarray:
    """The sRGB transfer function inverted (IEC 61966-2-1, the piecewise curve Blender's 'sRGB'
    colour space uses): v ≤ 0.04045 → v / 12.92, else ((v + 0.055) / 1.055)^2.4."""
    v = np.asarray(values, np.float64)
    return np.where(v <= 0.04045, v / 12.92, ((np.maximum(v, 0.0) + 0.055) / 1.055) ** 2.4).astype(np.float32)


def read_ldr(path) -> np.ndarray:
    """An 8-bit (or 16-bit PNG) environment image, PNG or JPEG, as (H, W, 3) float32 linear values
    (the file's sRGB-encoded values decoded with :func:`srgb_to_linear`; an alpha channel is
    kept, undecoded, as a 4th channel), row 0 at the top. Decoded by Blender's image loader (bpy
    is imported here, not at module import)."""
    path = Path(path)
    if not path.exists():
        raise FileNotFoundError(f"read_ldr: {path} does not exist")
    try:
        import bpy  # noqa: PLC0415
    except ImportError:
        raise ValueError(f"read_ldr: {path}: PNG/JPEG environments are decoded by Blender's image loader, and bpy is not importable here") from None
    try:
        img = bpy.data.images.load(str(path.resolve()), check_existing=False)
    except RuntimeError as e:
        raise ValueError(f"read_ldr: {path}: not a readable PNG or JPEG image ({e})") from None
    try:
        img.colorspace_settings.name = "Non-Color"  # the file's values as stored, decoded below
        w, h = img.size
        if w < 1 or h < 1 or not img.has_data:
            raise ValueError(f"read_ldr: {path}: not a readable PNG or JPEG image (no pixels)")
        # Blender's pixels are RGBA whatever the file holds; the depth says whether it had alpha
        # (8-bit: 8 grey, 16 grey+alpha, 24 RGB, 32 RGBA; float buffers: 96 RGB, 128 RGBA).
        alpha = img.depth in (16, 32, 128) if not (img.depth == 16 and img.is_float) else False
        px = np.empty(w * h * 4, np.float32)
        img.pixels.foreach_get(px)
    finally:
        bpy.data.images.remove(img)
    px = flip_rows(px.reshape(h, w, 4))
    if not np.isfinite(px).all():
        raise ValueError(f"read_ldr: {path}: decoded to non-finite values")
    rgb = srgb_to_linear(np.clip(px[..., :3], 0.0, 1.0))
    if alpha:
        return np.ascontiguousarray(np.concatenate([rgb, px[..., 3:4]], axis=-1))
    return np.ascontiguousarray(rgb)


def read_image(path) -> np.ndarray:
    """An environment image as (H, W, C) float32 linear values with row 0 at the top: HDR,
    OpenEXR (``.exr``) or Radiance (``.hdr``, ``.pic``), or 8-bit PNG/JPEG (``.png``, ``.jpg``,
    ``.jpeg``; sRGB-decoded, :func:`read_ldr`)."""
    suffix = Path(path).suffix.lower()
    if suffix == ".exr":
        return read_exr(path)
    if suffix in (".hdr", ".pic", ".rgbe"):
        return read_hdr(path)
    if suffix in LDR_SUFFIXES:
        return read_ldr(path)
    raise ValueError(f"read_image: {path}: expected an OpenEXR (.exr), Radiance (.hdr), PNG (.png) or JPEG (.jpg, .jpeg) file")


def flip_rows(pixels: np.ndarray) -> np.ndarray:
    """Top-down (file) rows ↔ bottom-up (Blender ``Image.pixels``) rows."""
    return np.ascontiguousarray(np.asarray(pixels)[::-1] if np.ndim(pixels) == 3 else np.asarray(pixels)[:, ::-1])


def convert(image, layout_in: str, layout_out: str, size: int, supersample: int = 1) -> np.ndarray:
    """The environment ``image`` (``layout_in``) on ``layout_out``: lat-long maps are size × 2·size,
    faces size × size; each texel averages supersample² bilinear, seam-correct lookups."""
    return native.module().envmaps.convert(image, layout_in, layout_out, int(size), int(supersample))


def sample(image, layout: str, directions) -> np.ndarray:
    """Bilinear, seam-correct lookups E(d): (..., 3) directions → (..., C)."""
    return native.module().envmaps.sample(image, layout, directions)


def prefilter(image, lobe: str = "ggx", params=ROUGHNESS_LEVELS, texels_per_radius: float = 6.0, tail: float = 1e-5) -> list:
    """Specular prefiltering of a lat-long image: one lat-long array per lobe parameter (GGX or
    Phong/Torrance–Sparrow σ), each at its own resolution (see docs/envmaps.md)."""
    return native.module().envmaps.prefilter(image, lobe, [float(p) for p in params], float(texels_per_radius), float(tail))


def irradiance(image, size: int = 32) -> dict:
    """Order-2 SH irradiance: {'coeffs', 'irradiance_coeffs', 'image'} (E(n)/π map, size × 2·size)."""
    return native.module().envmaps.irradiance(image, int(size))


def sh_irradiance(irradiance_coeffs, normals) -> np.ndarray:
    """E(n)/π from ``irradiance(...)['irradiance_coeffs']`` at (..., 3) normals (numpy, vectorised;
    the basis of rokeby_core::sh, Ramamoorthi & Hanrahan 2001)."""
    n = np.asarray(normals, dtype=np.float64)
    n = n / np.linalg.norm(n, axis=-1, keepdims=True)
    x, y, z = n[..., 0], n[..., 1], n[..., 2]
    basis = np.stack(
        [
            np.full_like(x, 0.28209479177387814),
            0.4886025119029199 * y,
            0.4886025119029199 * z,
            0.4886025119029199 * x,
            1.0925484305920792 * x * y,
            1.0925484305920792 * y * z,
            0.31539156525252005 * (3 * z * z - 1),
            1.0925484305920792 * x * z,
            0.5462742152960396 * (x * x - y * y),
        ],
        axis=-1,
    )
    return basis @ np.asarray(irradiance_coeffs, dtype=np.float64).T


def reference(image, lobe: str, directions, param: float = 0.0) -> np.ndarray:
    """The seed's brute-force sum over every texel (the validation reference): lobe 'phong',
    'ggx', 'torrance_sparrow' (normalised like the prefiltered maps) or 'lambert' (E(n)/π)."""
    return native.module().envmaps.prefilter_reference(image, lobe, directions, float(param))


def lookup_levels(levels, params, directions, param) -> np.ndarray:
    """Prefiltered radiance at (..., 3) reflected ``directions`` for a lobe parameter between the
    prefiltered ones: bilinear in each level's map, linear between the two levels that bracket
    ``param`` (a scalar, or one value per direction) — what a preview shader does with the chain."""
    params = np.asarray(params, np.float64)
    if params.ndim != 1 or len(params) != len(levels) or len(levels) == 0:
        raise ValueError(f"params: need one value per level ({len(levels)}), got shape {params.shape}")
    order = np.argsort(params)
    ps = params[order]
    d = np.asarray(directions, np.float64)
    p = np.broadcast_to(np.asarray(param, np.float64), d.shape[:-1])
    if not np.isfinite(p).all():
        raise ValueError("param: contains NaN or inf")
    samples = np.stack([sample(levels[i], "latlong", d) for i in order], axis=0)
    x = np.clip(p, ps[0], ps[-1])
    hi = np.clip(np.searchsorted(ps, x, side="right"), 1, len(ps) - 1) if len(ps) > 1 else np.zeros(x.shape, int)
    lo = np.maximum(hi - 1, 0)
    span = np.where(ps[hi] > ps[lo], ps[hi] - ps[lo], 1.0)
    t = np.clip((x - ps[lo]) / span, 0.0, 1.0)[..., None]
    idx = np.indices(x.shape)
    a = samples[(lo, *idx)]
    b = samples[(hi, *idx)]
    return (1 - t) * a + t * b
