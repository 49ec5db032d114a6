"""Environment-map toolkit through rokeby.envmaps: the shipped HDR worlds read with
OpenEXR, conversions and lookups in Blender's convention, SH irradiance and specular prefiltering
against the seed's brute-force sum, writing results, bad input."""

import numpy as np
import pytest

from rokeby import envmaps, reflmap

WORLDS = ("city", "courtyard", "forest", "interior", "night", "studio", "sunrise", "sunset")


@pytest.fixture(scope="module")
def worlds():
    return {name: envmaps.read_exr(envmaps.studio_world(name)) for name in WORLDS}


def fibonacci(n):
    i = np.arange(n) + 0.5
    z = 1 - 2 * i / n
    r = np.sqrt(1 - z * z)
    a = np.pi * (3 - np.sqrt(5)) * np.arange(n)
    return np.stack([r * np.cos(a), r * np.sin(a), z], axis=-1)


def test_shipped_worlds_read_as_hdr(worlds):
    for name, im in worlds.items():
        assert im.shape == (512, 1024, 3) and im.dtype == np.float32, name
        assert np.isfinite(im).all(), name
        assert im.max() > 1.0, f"{name} is not HDR"


def test_latlong_lookup_is_blenders_convention(rng):
    """Our lat-long coordinates agree with reflmap.direction_to_uv (checked against EEVEE's
    Environment Texture node there): a texel-coded image is read back at its own texel."""
    h, w = 32, 64
    code = np.arange(h * w, dtype=np.float32).reshape(h, w, 1)
    d = rng.normal(size=(500, 3))
    uv = reflmap.direction_to_uv(d)
    col = np.floor(uv[:, 0] * w).astype(int) % w
    row_from_bottom = np.clip(np.floor(uv[:, 1] * h).astype(int), 0, h - 1)
    # Lookup exactly at the texel centre of reflmap's texel (bilinear returns that texel).
    centres_uv = np.stack([(col + 0.5) / w, (row_from_bottom + 0.5) / h], axis=-1)
    dirs = reflmap.uv_to_direction(centres_uv[:, 0], centres_uv[:, 1])
    got = envmaps.sample(code, "latlong", dirs)[:, 0]
    want = (h - 1 - row_from_bottom) * w + col  # row 0 of our arrays is the top
    np.testing.assert_allclose(got, want, atol=1e-3)


@pytest.mark.parametrize("layout", ["cube", "sphere", "paraboloid"])
def test_conversions_round_trip_on_a_smooth_world(worlds, layout):
    """A rough prefiltered level of a real world (smooth) survives latlong → layout → latlong."""
    smooth = envmaps.prefilter(worlds["courtyard"], "ggx", [0.6])[0]
    size = 96
    mid = envmaps.convert(smooth, "latlong", layout, size, supersample=2)
    expected_shape = {"cube": (6, size, size, 3), "sphere": (size, size, 3), "paraboloid": (2, size, size, 3)}[layout]
    assert mid.shape == expected_shape
    back = envmaps.convert(mid, layout, "latlong", smooth.shape[0])
    h = back.shape[0]
    keep = np.ones(back.shape[:2], bool)
    if layout == "sphere":
        # the disk's rim squeezes the back hemisphere (−Z, the mirror ball's far side): compare
        # the directions with z > −0.5 only
        d = reflmap.uv_to_direction(*np.meshgrid((np.arange(back.shape[1]) + 0.5) / back.shape[1], 1 - (np.arange(h) + 0.5) / h))
        keep = d[..., 2] > -0.5
    rel = np.abs(back - smooth)[keep].mean() / smooth[keep].mean()
    assert rel < 0.01, f"{layout}: mean relative change {rel:.4f}"


def test_sample_shapes_and_cube_faces():
    cube = np.zeros((6, 4, 4, 2), np.float32)
    for f in range(6):
        cube[f] = f
    d = np.array([[1, 0, 0], [-1, 0, 0], [0, 1, 0], [0, -1, 0], [0, 0, 1], [0, 0, -1]], float)
    got = envmaps.sample(cube, "cube", d.reshape(2, 3, 3))
    assert got.shape == (2, 3, 2)
    np.testing.assert_allclose(got.reshape(6, 2)[:, 0], np.arange(6))


def test_constant_world_stays_constant():
    const = np.ones((64, 128, 3), np.float32) * np.array([0.5, 2.0, 8.0], np.float32)
    for lobe, params in (("ggx", envmaps.ROUGHNESS_LEVELS), ("phong", [1, 16, 256]), ("torrance_sparrow", [0.05, 0.3])):
        for lv in envmaps.prefilter(const, lobe, params):
            np.testing.assert_allclose(lv, np.broadcast_to(const[0, 0], lv.shape), rtol=2e-5)
    irr = envmaps.irradiance(const, size=16)
    np.testing.assert_allclose(irr["image"], np.broadcast_to(const[0, 0], irr["image"].shape), rtol=3e-4)


def test_sh_irradiance_on_the_shipped_worlds(worlds):
    """Order-2 SH against the exact (brute-force) irradiance: Ramamoorthi & Hanrahan report about
    1% average error for typical lighting; bright small suns do worse (figures in docs/benchmarks.md)."""
    normals = fibonacci(64)
    errs = {}
    for name in ("courtyard", "studio", "forest"):
        im = worlds[name]
        irr = envmaps.irradiance(im, size=64)
        sh = envmaps.sh_irradiance(irr["irradiance_coeffs"], normals)
        exact = envmaps.reference(im, "lambert", normals)
        lum = lambda a: a @ np.array([0.2126, 0.7152, 0.0722])  # noqa: E731
        errs[name] = np.abs(lum(sh) - lum(exact)).mean() / lum(exact).mean()
        # the map is the same function
        mapped = envmaps.sample(irr["image"], "latlong", normals)
        np.testing.assert_allclose(mapped, sh, rtol=0.02, atol=1e-3 * exact.mean())
    assert max(errs.values()) < 0.1, errs
    assert min(errs.values()) > 1e-5, errs  # the truncation is real: a test that can fail


def test_prefilter_of_a_shipped_world_against_brute_force(worlds):
    """GGX levels of sunset.exr (a sun 6000× the sky) at texel centres of each level against the
    seed's sum over all 512×1024 texels."""
    im = worlds["sunset"]
    rough = [0.0, 2 / 7, 5 / 7]
    levels = envmaps.prefilter(im, "ggx", rough)
    assert levels[0].shape == im.shape and np.array_equal(levels[0], im)
    rng = np.random.default_rng(7)
    for r, lv in zip(rough[1:], levels[1:]):
        h, w = lv.shape[:2]
        rows, cols = rng.integers(0, h, 24), rng.integers(0, w, 24)
        u, v = (cols + 0.5) / w, 1 - (rows + 0.5) / h
        d = reflmap.uv_to_direction(u, v)
        ref = envmaps.reference(im, "ggx", d, param=r)
        got = lv[rows, cols]
        rel = np.abs(got - ref).sum() / np.abs(ref).sum()
        assert rel < 0.02, f"roughness {r}: mean relative error {rel:.4f}"


def test_results_written_and_read_back(tmp_path, worlds):
    lv = envmaps.prefilter(worlds["studio"], "phong", [64])[0]
    p = envmaps.write_exr(tmp_path / "studio_phong64.exr", lv)
    np.testing.assert_array_equal(envmaps.read_exr(p), lv)
    cube = envmaps.convert(worlds["studio"], "latlong", "cube", 32)
    for f in range(6):
        envmaps.write_exr(tmp_path / f"face{f}.exr", cube[f])
    assert np.array_equal(envmaps.read_exr(tmp_path / "face4.exr"), cube[4])


def test_radiance_hdr_files_round_trip_and_agree_with_blender(tmp_path, worlds):
    """Radiance RGBE (.hdr) files, the other format HDRIs come in: ours round-trip within the
    format's precision (8-bit mantissas, one shared exponent); Blender reads the files we write
    as we do, and we read the files Blender writes as it reads them; read_image picks the reader by
    suffix; broken files are ValueErrors naming the file."""
    bpy = pytest.importorskip("bpy")
    im = worlds["forest"][..., :3]
    ours = envmaps.write_hdr(tmp_path / "forest.hdr", im)
    im = np.maximum(im, 0)  # the HDR has a few slightly negative texels: RGBE stores 0 there
    back = envmaps.read_hdr(ours)
    assert back.shape == im.shape and back.dtype == np.float32
    peak = im.max(axis=-1, keepdims=True)
    assert (np.abs(back - im) <= peak / 256 * 1.0001 + 1e-30).all()  # rounded mantissas: ½ unit ≤ 1/256 of the pixel's largest
    raw = im.shape[0] * im.shape[1] * 4  # flat RGBE; run-length encoding of a photograph saves little, but never costs much
    assert ours.stat().st_size <= 1.01 * raw + 200
    np.testing.assert_array_equal(envmaps.read_image(ours), back)

    def blender_pixels(path):
        img = bpy.data.images.load(str(path))
        w, h = img.size
        px = np.empty(w * h * 4, np.float32)
        img.pixels.foreach_get(px)
        bpy.data.images.remove(img)
        return envmaps.flip_rows(px.reshape(h, w, 4))[..., :3]

    np.testing.assert_allclose(blender_pixels(ours), back, rtol=1e-6, atol=1e-30)
    # Blender's writer, our reader
    h, w = im.shape[:2]
    img = bpy.data.images.new("to_hdr", w, h, alpha=True, float_buffer=True)
    rgba = np.concatenate([im, np.ones((h, w, 1), np.float32)], -1)
    img.pixels.foreach_set(envmaps.flip_rows(rgba).ravel())
    img.filepath_raw = str(tmp_path / "blender.hdr")
    img.file_format = "HDR"
    img.save()
    bpy.data.images.remove(img)
    theirs = envmaps.read_hdr(tmp_path / "blender.hdr")  # (Image.save applies Blender's colour management)
    assert theirs.shape == im.shape and theirs.max() > 1.0
    np.testing.assert_allclose(theirs, blender_pixels(tmp_path / "blender.hdr"), rtol=1e-6, atol=1e-30)
    # broken files
    (tmp_path / "cut.hdr").write_bytes(ours.read_bytes()[:5000])
    with pytest.raises(ValueError, match=r"cut\.hdr.*(ends in scanline|truncated)"):
        envmaps.read_hdr(tmp_path / "cut.hdr")
    (tmp_path / "text.hdr").write_text("P3 2 2 255")
    with pytest.raises(ValueError, match="not a Radiance"):
        envmaps.read_image(tmp_path / "text.hdr")
    with pytest.raises(ValueError, match="not finite"):
        envmaps.write_hdr(tmp_path / "nan.hdr", np.full((2, 2, 3), np.nan, np.float32))
    with pytest.raises(ValueError, match="expected an OpenEXR"):
        envmaps.read_image(tmp_path / "x.tif")


def test_bad_input_gives_clear_errors():
    good = np.ones((8, 16, 3), np.float32)
    bad = good.copy()
    bad[2, 5, 1] = np.nan
    with pytest.raises(ValueError, match=r"image: value at row 2, column 5, channel 1 is NaN"):
        envmaps.prefilter(bad)
    bad[2, 5, 1] = np.inf
    with pytest.raises(ValueError, match="inf"):
        envmaps.irradiance(bad)
    with pytest.raises(ValueError, match=r"latlong map must have shape \(H, W, C\), got \(8, 16\)"):
        envmaps.prefilter(good[..., 0])
    with pytest.raises(ValueError, match=r"cube map must have shape \(6, S, S, C\)"):
        envmaps.convert(np.ones((5, 4, 4, 3)), "cube", "latlong", 8)
    with pytest.raises(ValueError, match="faces must be square"):
        envmaps.convert(np.ones((6, 4, 5, 3)), "cube", "latlong", 8)
    with pytest.raises(ValueError, match=r"params\[1\]: .*roughness must be in \[0, 1\], got 1.5"):
        envmaps.prefilter(good, "ggx", [0.2, 1.5])
    with pytest.raises(ValueError, match=r"params\[0\]: .*exponent σ must be finite and ≥ 0, got -2"):
        envmaps.prefilter(good, "phong", [-2])
    with pytest.raises(ValueError, match="Torrance–Sparrow σ"):
        envmaps.reference(good, "torrance_sparrow", [[0, 0, 1]], param=-0.1)
    with pytest.raises(ValueError, match='unknown lobe "blinn"'):
        envmaps.prefilter(good, "blinn", [1])
    with pytest.raises(ValueError, match='layout_out: unknown layout "octahedral"'):
        envmaps.convert(good, "latlong", "octahedral", 8)
    with pytest.raises(ValueError, match=r"directions: expected shape \(\.\.\., 3\)"):
        envmaps.sample(good, "latlong", np.ones((4, 2)))
    with pytest.raises(ValueError, match="direction 1 is zero or not finite"):
        envmaps.sample(good, "latlong", [[0, 0, 1], [0, 0, 0]])
    with pytest.raises(ValueError, match="texels_per_radius"):
        envmaps.prefilter(good, "ggx", [0.5], texels_per_radius=0)
    with pytest.raises(ValueError, match="params: need at least one"):
        envmaps.prefilter(good, "ggx", [])
    with pytest.raises(ValueError, match="NaN or inf"):
        envmaps.write_exr("/tmp/never.exr", bad)
    with pytest.raises(ValueError, match="4 GiB"):
        envmaps.convert(good, "latlong", "cube", 10**6)
    with pytest.raises(ValueError, match="no world 'moon'"):
        envmaps.studio_world("moon")


def test_preview_matches_a_cycles_render_of_the_same_sphere(tmp_path):
    """A white metallic Principled sphere (roughness 0.3, multiscatter GGX, F ≈ 1) under
    sunset.exr, orthographic camera, against the preview's lookup of the prefiltered GGX chain in
    the reflected direction (split sum, n = v = r), over the pixels with n·v > 0.5. The same lookup
    with the world turned half a turn (the wrong lat-long convention) is far off."""
    bpy = pytest.importorskip("bpy")
    rough = 0.3
    bpy.ops.wm.read_factory_settings(use_empty=True)
    sc = bpy.context.scene
    world = bpy.data.worlds.new("HDR")
    world.use_nodes = True
    env = world.node_tree.nodes.new("ShaderNodeTexEnvironment")
    env.image = bpy.data.images.load(str(envmaps.studio_world("sunset")))
    world.node_tree.links.new(env.outputs["Color"], world.node_tree.nodes["Background"].inputs["Color"])
    sc.world = world
    bpy.ops.mesh.primitive_uv_sphere_add(segments=128, ring_count=64, radius=1.0)
    bpy.ops.object.shade_smooth()
    mat = bpy.data.materials.new("Metal")
    mat.use_nodes = True
    bsdf = mat.node_tree.nodes["Principled BSDF"]
    bsdf.inputs["Base Color"].default_value = (1, 1, 1, 1)
    bsdf.inputs["Metallic"].default_value = 1.0
    bsdf.inputs["Roughness"].default_value = rough
    bpy.context.object.data.materials.append(mat)
    cam = bpy.data.objects.new("Cam", bpy.data.cameras.new("Cam"))
    sc.collection.objects.link(cam)
    cam.location = (0, -10, 0)
    cam.rotation_euler = (np.pi / 2, 0, 0)
    cam.data.type = "ORTHO"
    cam.data.ortho_scale = 2.2
    sc.camera = cam
    sc.render.engine = "CYCLES"
    sc.cycles.device = "CPU"
    sc.cycles.samples = 64
    sc.cycles.use_denoising = False
    sc.cycles.seed = 5
    sc.cycles.filter_width = 0.01
    sc.render.resolution_x = sc.render.resolution_y = 64
    sc.render.resolution_percentage = 100
    sc.render.image_settings.file_format = "OPEN_EXR"
    sc.render.filepath = str(tmp_path / "ball")
    bpy.ops.render.render(write_still=True)
    img = envmaps.read_exr(tmp_path / "ball.exr")[..., :3]

    levels = envmaps.prefilter(envmaps.read_exr(envmaps.studio_world("sunset")), "ggx", envmaps.ROUGHNESS_LEVELS)
    h, w = img.shape[:2]
    j, i = np.meshgrid(np.arange(w), np.arange(h))
    x, z = ((j + 0.5) / w - 0.5) * 2.2, (0.5 - (i + 0.5) / h) * 2.2
    ok = x * x + z * z < 0.75
    n = np.stack([x, -np.sqrt(np.maximum(1 - x * x - z * z, 0)), z], -1)[ok]
    v = np.array([0.0, -1.0, 0.0])
    r = 2 * (n @ v)[:, None] * n - v
    lum = np.array([0.2126, 0.7152, 0.0722])
    render = img[ok] @ lum
    preview = envmaps.lookup_levels(levels, envmaps.ROUGHNESS_LEVELS, r, rough) @ lum
    wrong = envmaps.lookup_levels(levels, envmaps.ROUGHNESS_LEVELS, r * [-1, -1, 1], rough) @ lum
    err = np.abs(preview - render).mean() / render.mean()
    err_wrong = np.abs(wrong - render).mean() / render.mean()
    assert err < 0.08, f"preview against Cycles: mean relative error {err:.3f}"
    assert abs(preview.mean() / render.mean() - 1) < 0.05
    assert err_wrong > 5 * err, (err, err_wrong)


def test_lookup_levels_interpolates_between_levels(rng):
    im = rng.random((32, 64, 3)).astype(np.float32)
    params = [0.0, 0.5, 1.0]
    lv = envmaps.prefilter(im, "ggx", params)
    d = rng.normal(size=(6, 3))
    one, two = envmaps.sample(lv[1], "latlong", d), envmaps.sample(lv[2], "latlong", d)
    np.testing.assert_allclose(envmaps.lookup_levels(lv, params, d, 0.5), one, rtol=1e-6)
    np.testing.assert_allclose(envmaps.lookup_levels(lv, params, d, 0.75), 0.5 * (one + two), rtol=1e-6)
    np.testing.assert_allclose(envmaps.lookup_levels(lv, params, d, 7.0), two, rtol=1e-6)  # clamped
    with pytest.raises(ValueError, match="one value per level"):
        envmaps.lookup_levels(lv, [0.0, 1.0], d, 0.5)
