"""8-bit (LDR) environment images: rokeby.envmaps.read_image reads PNG and JPEG as
Fraser's implementation does, sRGB-decoded to linear, row 0 at the top. The PNGs are written here
byte by byte (zlib + CRC, no image library), so the expected values do not come from the loader
under test."""

import struct
import zlib

import numpy as np
import pytest

from rokeby import envmaps


def write_png(path, data: np.ndarray, bit_depth: int = 8):
    """A PNG of (H, W, C) unsigned integers (C = 1, 3 or 4), filter 0 on every row."""
    h, w, c = data.shape
    colour_type = {1: 0, 3: 2, 4: 6}[c]
    dt = ">u2" if bit_depth == 16 else "u1"
    raw = b"".join(b"\x00" + np.ascontiguousarray(data[y], dt).tobytes() for y in range(h))

    def chunk(kind, body):
        return struct.pack(">I", len(body)) + kind + body + struct.pack(">I", zlib.crc32(kind + body) & 0xFFFFFFFF)

    ihdr = struct.pack(">IIBBBBB", w, h, bit_depth, colour_type, 0, 0, 0)
    path.write_bytes(b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", ihdr) + chunk(b"IDAT", zlib.compress(raw)) + chunk(b"IEND", b""))
    return path


def srgb_reference(code, top):
    v = np.asarray(code, np.float64) / top
    return np.where(v <= 0.04045, v / 12.92, ((v + 0.055) / 1.055) ** 2.4)


def test_srgb_decoding_is_the_iec_curve():
    np.testing.assert_allclose(envmaps.srgb_to_linear([0.0, 0.04045, 0.5, 1.0]), [0.0, 0.04045 / 12.92, 0.21404114, 1.0], rtol=1e-6)
    x = np.linspace(0, 1, 1001)
    y = envmaps.srgb_to_linear(x)
    assert (np.diff(y) > 0).all()  # monotonic, continuous at the knee
    assert abs(0.04045 / 12.92 - ((0.04045 + 0.055) / 1.055) ** 2.4) < 1e-7


def test_png_is_read_linear_and_top_down(tmp_path):
    """Every 8-bit code in a 16×16 RGB PNG: read_image gives the sRGB-decoded value of each byte,
    row 0 the file's first row; an RGBA PNG keeps its alpha undecoded; a 16-bit PNG decodes
    its 65535 levels the same way."""
    pytest.importorskip("bpy")
    codes = np.arange(256, dtype=np.uint8).reshape(16, 16)
    data = np.stack([codes, codes[::-1], np.full_like(codes, 200)], -1)
    got = envmaps.read_image(write_png(tmp_path / "env.png", data))
    assert got.shape == (16, 16, 3) and got.dtype == np.float32
    np.testing.assert_allclose(got, srgb_reference(data, 255), rtol=1e-5, atol=1e-6)
    rgba = np.concatenate([data, codes[..., None]], -1)
    got = envmaps.read_image(write_png(tmp_path / "alpha.PNG", rgba))
    assert got.shape == (16, 16, 4)
    np.testing.assert_allclose(got[..., :3], srgb_reference(data, 255), rtol=1e-5, atol=1e-6)
    np.testing.assert_allclose(got[..., 3], codes / 255.0, atol=1e-6)
    deep = (np.arange(16 * 8 * 3, dtype=np.int64).reshape(8, 16, 3) * 170 % 65536).astype(np.uint16)
    got = envmaps.read_image(write_png(tmp_path / "deep.png", deep, bit_depth=16))
    np.testing.assert_allclose(got, srgb_reference(deep, 65535), rtol=1e-4, atol=2e-5)


def test_jpeg_is_read_linear(tmp_path):
    """A JPEG of two flat halves (sRGB codes 64 and 230, written by Blender's encoder at full
    quality) reads as their decoded linear values within the codec's rounding, brighter half on
    the right, and is usable as an environment: prefiltered and integrated for irradiance."""
    bpy = pytest.importorskip("bpy")
    w, h = 32, 16
    img = bpy.data.images.new("ldr", w, h)
    img.colorspace_settings.name = "Non-Color"
    px = np.zeros((h, w, 4), np.float32)
    px[..., 3] = 1.0
    px[:, : w // 2, :3] = 64 / 255
    px[:, w // 2:, :3] = 230 / 255
    img.pixels.foreach_set(px.ravel())
    img.filepath_raw = str(tmp_path / "env.jpg")
    img.file_format = "JPEG"
    bpy.context.scene.render.image_settings.quality = 100
    img.save()
    bpy.data.images.remove(img)
    got = envmaps.read_image(tmp_path / "env.jpg")
    assert got.shape == (h, w, 3)
    np.testing.assert_allclose(got[:, 2:12], srgb_reference(64, 255), atol=3e-3)
    np.testing.assert_allclose(got[:, 20:30], srgb_reference(230, 255), atol=1.5e-2)
    irr = envmaps.irradiance(got, size=8)["irradiance_coeffs"]
    assert np.isfinite(irr).all() and np.asarray(irr)[:, 0].min() > 0


def test_bad_ldr_files_are_refused_by_name(tmp_path):
    pytest.importorskip("bpy")
    (tmp_path / "text.png").write_text("not a png")
    with pytest.raises(ValueError, match=r"text\.png.*not a readable PNG or JPEG"):
        envmaps.read_image(tmp_path / "text.png")
    with pytest.raises(FileNotFoundError, match="missing.jpg"):
        envmaps.read_image(tmp_path / "missing.jpg")
    with pytest.raises(ValueError, match="expected an OpenEXR"):
        envmaps.read_image(tmp_path / "x.tif")


@pytest.mark.parametrize("colorspace", ["sRGB", "Non-Color"])
def test_an_ldr_world_lights_the_appearance_preview_as_cycles_renders_it(tmp_path, colorspace):
    """A PNG world (flat codes 200, 128, 30) as the scene's Environment Texture: the values the
    appearance preview prefilters (``world_pixels``) are those Cycles renders when the camera looks
    at that world — sRGB-decoded for an sRGB image (Blender's ``Image.pixels`` gives an 8-bit
    image's stored codes, which the preview once took as linear: 0.78 for 0.58), as stored for
    Non-Color."""
    bpy = pytest.importorskip("bpy")
    from support import cycles
    from rokeby.appearance import preview as appearance_preview

    codes = np.array([200, 128, 30], np.uint8)
    path = write_png(tmp_path / "world.png", np.broadcast_to(codes, (8, 16, 3)).copy())
    bpy.ops.wm.read_factory_settings(use_empty=True)
    sc = cycles(bpy.context.scene, 4, 1)
    world = bpy.data.worlds.new("LDR")
    sc.world = world
    world.use_nodes = True
    env = world.node_tree.nodes.new("ShaderNodeTexEnvironment")
    env.image = bpy.data.images.load(str(path))
    env.image.colorspace_settings.name = colorspace
    world.node_tree.links.new(env.outputs["Color"], world.node_tree.nodes["Background"].inputs["Color"])
    sc.camera = bpy.data.objects.new("Cam", bpy.data.cameras.new("Cam"))
    sc.collection.objects.link(sc.camera)
    sc.render.image_settings.file_format = "OPEN_EXR"
    sc.render.filepath = str(tmp_path / "render")
    bpy.ops.render.render(write_still=True)
    rendered = envmaps.read_exr(tmp_path / "render.exr")[..., :3].reshape(-1, 3).mean(axis=0)
    want = srgb_reference(codes, 255) if colorspace == "sRGB" else codes / 255.0
    np.testing.assert_allclose(rendered, want, rtol=2e-3)  # what a render shows of the world
    px = appearance_preview.world_pixels(sc)
    assert px.shape == (8, 16, 4)
    np.testing.assert_allclose(px[..., :3].reshape(-1, 3), np.broadcast_to(rendered, (128, 3)), rtol=2e-3)
