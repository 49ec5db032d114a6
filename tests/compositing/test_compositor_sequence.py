"""Compositing where compositors work, and sequences (Zubiaga et al. edit normals in a
node-based compositor): Use in Compositor feeds the recomposited image into the scene's compositor
as an Image node that later recomposites keep current (a render through the artist's chain shows
each edit); ``python -m rokeby.composite --sequence`` recomposites a folder of frames with progress,
resumes after a failure, and runs one frame per process with --frame. bpy in background mode."""

import os
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

bpy = pytest.importorskip("bpy")

import rokeby  # noqa: E402
from support import cycles  # noqa: E402
from rokeby.blender import compat  # noqa: E402
from rokeby import compositing as C  # noqa: E402
from rokeby import envmaps  # noqa: E402
from rokeby.core import schema  # noqa: E402


def _render_frame(path):
    bpy.ops.wm.read_factory_settings(use_empty=True)
    sc = cycles(bpy.context.scene, 24, 4)
    sc.render.resolution_y = 16
    envmaps.use_studio_world(sc, "forest")
    bpy.ops.mesh.primitive_uv_sphere_add(segments=24, ring_count=12)
    bpy.ops.object.shade_smooth()
    mat = bpy.data.materials.new("red")
    mat.use_nodes = True
    mat.node_tree.nodes["Principled BSDF"].inputs["Roughness"].default_value = 0.3
    bpy.context.object.data.materials.append(mat)
    bpy.ops.object.camera_add(location=(0.0, -4.0, 0.0), rotation=(np.pi / 2, 0, 0))
    sc.camera = bpy.context.object
    C.render_passes(sc, str(path))


@pytest.fixture(scope="module")
def frame(tmp_path_factory):
    path = tmp_path_factory.mktemp("frame") / "shot_0001.exr"
    _render_frame(path)
    return path


def _image(img):
    w, h = img.size
    px = np.empty(w * h * 4, np.float32)
    img.pixels.foreach_get(px)
    return px.reshape(h, w, 4)[::-1, :, :3]  # top row first


def _composite(tmp_path, name):
    sc = bpy.context.scene
    sc.render.use_compositing = True
    compat.set_single_layer_exr(sc.render.image_settings, "32")
    sc.render.filepath = str(tmp_path / name)
    bpy.ops.render.render(write_still=True)
    return envmaps.read_exr(tmp_path / f"{name}.exr")[..., :3]


def test_use_in_compositor_feeds_an_image_node_that_follows_every_recomposite(frame, tmp_path):
    """The node reads the recomposited image, a Viewer shows it (backdrop), the Composite node is
    left alone; chained into the Composite by the artist, a render outputs the recomposited frame,
    and after another edit (Recomposite Render) the same chain outputs the new frame."""
    _render_frame(tmp_path / "scene.exr")  # this scene, its passes on
    rokeby.register()
    try:
        assert bpy.ops.rokeby.composite_edit(filepath=str(frame), edit="EMBOSS", amount=0.3) == {"FINISHED"}
        img = bpy.data.images["Rokeby Recomposited"]
        first = _image(img).copy()
        sc = bpy.context.scene
        tree0 = compat.compositor_tree(sc, create=True)  # the compositor as this Blender makes it
        before = sorted((lk.from_node.name, lk.to_node.name) for lk in tree0.links if lk.to_node.bl_idname != "CompositorNodeViewer")
        assert bpy.ops.rokeby.composite_to_compositor() == {"FINISHED"}
        tree = compat.compositor_tree(bpy.context.scene)
        node = tree.nodes[schema.COMPOSITOR_NODE]
        assert node.image == img
        viewer = next(n for n in tree.nodes if n.bl_idname == "CompositorNodeViewer")
        assert viewer.inputs[0].links[0].from_node == node
        assert sorted((lk.from_node.name, lk.to_node.name) for lk in tree.links if lk.to_node.bl_idname != "CompositorNodeViewer") == before
        # the artist's chain: our image into the Composite through an Exposure node of 0 stops
        expo = tree.nodes.new("CompositorNodeExposure")
        tree.links.new(node.outputs["Image"], expo.inputs["Image"])
        tree.links.new(expo.outputs["Image"], compat.compositor_output(tree))
        out1 = _composite(tmp_path, "c1")
        np.testing.assert_allclose(out1, first, rtol=1e-4, atol=1e-5)
        assert bpy.ops.rokeby.composite_edit(filepath=str(frame), edit="EMBOSS", amount=0.9) == {"FINISHED"}
        second = _image(bpy.data.images["Rokeby Recomposited"]).copy()
        assert np.abs(second - first).max() > 1e-3  # a different edit
        out2 = _composite(tmp_path, "c2")
        np.testing.assert_allclose(out2, second, rtol=1e-4, atol=1e-5)
        # a frame of another size makes a new image: the node follows it
        new = C.show_image("Rokeby Recomposited", np.full((8, 10, 3), 0.25, np.float32))
        assert tree.nodes[schema.COMPOSITOR_NODE].image == new and tuple(new.size) == (10, 8)
        with pytest.raises(RuntimeError, match="no image 'Nothing'"):
            bpy.ops.rokeby.composite_to_compositor(image_name="Nothing")
    finally:
        rokeby.unregister()


def _cli(*args):
    return subprocess.run([sys.executable, "-m", "rokeby.composite", *map(str, args)], capture_output=True, text=True,
                          cwd=Path(rokeby.__file__).resolve().parents[1], timeout=600)


def test_cli_sequence_reports_progress_resumes_and_runs_one_frame_per_process(frame, tmp_path):
    frames = tmp_path / "frames"
    frames.mkdir()
    for k in (1, 2, 3):
        shutil.copy(frame, frames / f"shot_{k:04d}.exr")
    (frames / "shot_0004.exr").write_bytes(b"not an EXR")  # a broken frame: the others still run
    (frames / "notes.txt").write_text("not a frame")
    out = tmp_path / "out"
    seq = ["--sequence", frames, out, "--pattern", "shot_####.exr", "--emboss", "0.4", "--skip-existing"]
    r = _cli(*seq)
    assert r.returncode == 1, r.stderr[-2000:]
    assert "Traceback" not in r.stderr
    for k in (1, 2, 3):
        assert f"frame {k}/4 shot_{k:04d}.exr: done" in r.stderr, r.stderr
    assert "frame 4/4 shot_0004.exr: failed" in r.stderr and "1 frame(s) failed: shot_0004.exr" in r.stderr
    assert sorted(os.listdir(out)) == ["shot_0001.exr", "shot_0002.exr", "shot_0003.exr"]  # no partial file left
    inp = C.read_exr(str(frame))
    got = envmaps.read_exr(out / "shot_0002.exr")[..., :3]
    assert got.shape == inp.image[..., :3].shape and np.isfinite(got).all()
    assert (np.abs(got - inp.image[..., :3]) > 1e-4).any(-1).sum() > 10  # recomposited, not copied
    # resume: the fixed frame is done, the others are kept as they were
    kept = {n: os.stat(out / n).st_mtime_ns for n in os.listdir(out)}
    shutil.copy(frame, frames / "shot_0004.exr")
    r = _cli(*seq)
    assert r.returncode == 0, r.stderr[-2000:]
    assert "frame 1/4 shot_0001.exr: skipped (done before)" in r.stderr and "frame 4/4 shot_0004.exr: done" in r.stderr
    assert {n: os.stat(out / n).st_mtime_ns for n in kept} == kept
    assert sorted(os.listdir(out)) == [f"shot_{k:04d}.exr" for k in (1, 2, 3, 4)]
    # one frame per process (a farm task array): only frame 3, same output as the whole run
    solo = tmp_path / "solo"
    r = _cli("--sequence", frames, solo, "--pattern", "shot_####.exr", "--emboss", "0.4", "--frame", 3)
    assert r.returncode == 0, r.stderr[-2000:]
    assert os.listdir(solo) == ["shot_0003.exr"]
    np.testing.assert_array_equal(envmaps.read_exr(solo / "shot_0003.exr"), envmaps.read_exr(out / "shot_0003.exr"))
    # bad uses: one line, status 2
    for args, msg in ((("--sequence", frames, solo, "--frame", 9, "--emboss", "0.4"), "--frame: 9 is not in 1..4"),
                      (("--sequence", frames, frames, "--emboss", "0.4"), "must differ from the input folder"),
                      (("--sequence", frames, solo, "--pattern", "none_*.exr"), "no frames matching"),
                      ((frames / "shot_0001.exr", solo / "x.exr", "--frame", 2), "--frame needs --sequence")):
        r = _cli(*args)
        assert r.returncode == 2 and msg in r.stderr and "Traceback" not in r.stderr, (args, r.stderr[-1500:])
