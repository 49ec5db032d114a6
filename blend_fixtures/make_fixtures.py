"""Generate the .blend fixtures of the test suite (nothing binary is committed).

    python blend_fixtures/make_fixtures.py OUT_DIR [--shared PATH]

Each builder makes a scene with bpy (background mode) through ``rokeby.api`` and can save it; the
tests call the builders directly and save into a temporary folder.

- ``keyframed_spot``: Keenan Crane's spot (a real mesh from ../shared/meshes) as a chrome
  mirror, a camera, two reflection constraints whose green handles are keyframed at frames 1 and 20, a
  Euclidean region, and a floor the physical reflections hit.
- ``plane_mirror``: a flat subdivided chrome plane (normal exactly +Z) and a camera at the eye
  the tests use, where the expected field can be computed independently of Blender; ``animate_shape_key`` makes it deform over time.
"""

from __future__ import annotations

import argparse
import os
import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent


def _shared(arg=None) -> Path:
    if arg:
        return Path(arg)
    return Path(os.environ.get("ROKEBY_SHARED", ROOT.parent / "shared"))


def _fresh():
    import bpy

    bpy.ops.wm.read_factory_settings(use_empty=True)
    import rokeby

    rokeby.register()
    return bpy


def import_obj(path: Path, name: str):
    import bpy

    bpy.ops.wm.obj_import(filepath=str(path), forward_axis="Y", up_axis="Z")
    ob = bpy.context.selected_objects[0]
    ob.name = name
    return ob


def chrome(name="Mirror Chrome"):
    """A mirror-like material (metallic Principled BSDF, roughness 0): what a mirror is given."""
    import bpy

    mat = bpy.data.materials.new(name)
    mat.use_nodes = True
    bsdf = mat.node_tree.nodes["Principled BSDF"]
    bsdf.inputs["Metallic"].default_value = 1.0
    bsdf.inputs["Roughness"].default_value = 0.0
    return mat


def keyframed_spot(shared=None):
    """The spot scene; returns (mirror, constraint indices)."""
    bpy = _fresh()
    from rokeby import api

    scene = bpy.context.scene
    mirror = import_obj(_shared(shared) / "meshes" / "spot.obj", "Spot")
    mirror.data.materials.clear()
    mirror.data.materials.append(chrome())
    bpy.ops.mesh.primitive_plane_add(size=20.0, location=(0.0, 0.0, -1.0))
    bpy.context.object.name = "Floor"
    cam_data = bpy.data.cameras.new("Camera")
    cam = bpy.data.objects.new("Camera", cam_data)
    scene.collection.objects.link(cam)
    cam.location = (0.0, -4.0, 0.6)
    scene.camera = cam
    api.add_mirror(mirror)
    eye = (0.0, -4.0, 0.6)
    k1 = api.add_constraint(mirror, (0.1, -0.5, 0.3), eye=eye, name="Left")
    k2 = api.add_constraint(mirror, (-0.2, -0.3, -0.2), eye=eye, name="Low")
    for k, (a, b) in zip((k1, k2), (((0.0, 0.0, 0.0), (1.5, 0.0, 1.0)), ((0.0, 0.0, 0.0), (-1.0, 0.5, 0.8)))):
        green = mirror.rokeby.constraints[k].target_handle
        base = green.location.copy()
        for frame, offset in ((1, a), (20, b)):
            green.location = (base[0] + offset[0], base[1] + offset[1], base[2] + offset[2])
            green.keyframe_insert("location", frame=frame)
    api.add_region(mirror, "EUCLIDEAN", center=(0.0, -0.5, 0.2), radius=1.2, border=0.4, name="Face")
    scene.frame_start, scene.frame_end = 1, 20
    scene.frame_set(1)
    return mirror, (k1, k2)


def plane_mirror():
    """A flat mirror in the XY plane (normal +Z); returns (mirror, eye)."""
    bpy = _fresh()
    from rokeby import api

    bpy.ops.mesh.primitive_grid_add(x_subdivisions=40, y_subdivisions=30, size=4.0, location=(0.0, 0.0, 0.0))
    mirror = bpy.context.object
    mirror.name = "Plane"
    mirror.data.materials.append(chrome())
    eye = (0.3, -3.0, 2.0)
    cam = bpy.data.objects.new("Camera", bpy.data.cameras.new("Camera"))
    bpy.context.scene.collection.objects.link(cam)
    cam.location = eye
    bpy.context.scene.camera = cam
    api.add_mirror(mirror)
    return mirror, eye


def animate_shape_key(mirror, name: str, height, frames=(1, 20)):
    """Give ``mirror`` a shape key whose z = height(x, y) (numpy, on the base positions), keyed
    from 0 at frames[0] to 1 at frames[1]; returns the shape key's (V, 3) positions."""
    import numpy as np

    if mirror.data.shape_keys is None:
        mirror.shape_key_add(name="Basis")
    key = mirror.shape_key_add(name=name)
    co = np.empty(len(mirror.data.vertices) * 3, np.float32)
    mirror.data.vertices.foreach_get("co", co)
    co = co.reshape(-1, 3)
    co[:, 2] = height(co[:, 0], co[:, 1])
    key.data.foreach_set("co", co.ravel())
    for value, frame in zip((0.0, 1.0), frames):
        key.value = value
        key.keyframe_insert("value", frame=frame)
    return co


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("out", type=Path)
    ap.add_argument("--shared", default=None)
    args = ap.parse_args(argv)
    args.out.mkdir(parents=True, exist_ok=True)
    import bpy

    for builder in ("keyframed_spot", "plane_mirror"):
        fn = globals()[builder]
        fn(args.shared) if builder == "keyframed_spot" else fn()
        from rokeby import api

        api.evaluate(force=True)
        path = args.out / f"{builder}.blend"
        bpy.ops.wm.save_as_mainfile(filepath=str(path))
        print(f"wrote {path}")
    return 0


if __name__ == "__main__":
    sys.path.insert(0, str(ROOT / "addon"))
    sys.exit(main())
