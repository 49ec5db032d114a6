"""The what-you-see-is-what-F12-renders harness (tests/reflection/test_wysiwyg.py, reused by
tests/workflows/test_shared.py): a direction-coded world (its colour is 0.5 d + 0.5 for the
direction d a ray leaves in), perfect Glossy mirrors, AOVs carrying each hit's position and smooth
normal, 1-sample Cycles renders read back as reflected directions, and the directions the
viewport preview evaluates at the same hits."""

import numpy as np
import pytest

from support import cycles

bpy = pytest.importorskip("bpy")

import rokeby  # noqa: E402
from rokeby.blender import compat  # noqa: E402
from rokeby.reflection import mirror_state  # noqa: E402
from rokeby.core import native  # noqa: E402

SIZE = 64
EYE = (0.0, -4.0, 0.0)


def direction_world(sc):
    world = bpy.data.worlds.new("Directions")
    sc.world = world
    world.use_nodes = True
    nt = world.node_tree
    coords = nt.nodes.new("ShaderNodeTexCoord")
    code = nt.nodes.new("ShaderNodeVectorMath")
    code.operation = "MULTIPLY_ADD"
    code.inputs[1].default_value = code.inputs[2].default_value = (0.5, 0.5, 0.5)
    nt.links.new(coords.outputs["Generated"], code.inputs[0])
    nt.links.new(code.outputs[0], nt.nodes["Background"].inputs["Color"])
    nt.nodes["Background"].inputs["Strength"].default_value = 1.0


def mirror_material(name="Mirror"):
    """A perfect white Glossy BSDF that also writes its hit's position and smooth normal as AOVs."""
    mat = bpy.data.materials.new(name)
    mat.use_nodes = True
    nt = mat.node_tree
    nt.nodes.remove(nt.nodes["Principled BSDF"])
    glossy = nt.nodes.new("ShaderNodeBsdfGlossy")
    glossy.inputs["Roughness"].default_value = 0.0
    glossy.inputs["Color"].default_value = (1.0, 1.0, 1.0, 1.0)
    nt.links.new(glossy.outputs["BSDF"], nt.nodes["Material Output"].inputs["Surface"])
    add_aovs(nt)
    return mat


def add_aovs(nt):
    geo = nt.nodes.new("ShaderNodeNewGeometry")
    for name, socket in (("P", "Position"), ("N", "Normal")):
        aov = nt.nodes.new("ShaderNodeOutputAOV")
        aov.aov_name = name
        nt.links.new(geo.outputs[socket], aov.inputs["Color"])


def new_scene():
    bpy.ops.wm.read_factory_settings(use_empty=True)
    rokeby.register()
    mirror_state.reset()
    sc = bpy.context.scene
    cycles(sc, SIZE, 1, seed=1)
    sc.cycles.filter_width = 0.01
    compat.set_multilayer_exr(sc.render.image_settings, "32")
    vl = sc.view_layers[0]
    for name in ("P", "N"):
        aov = vl.aovs.add()
        aov.name, aov.type = name, "COLOR"
    direction_world(sc)
    cam = bpy.data.objects.new("Camera", bpy.data.cameras.new("Camera"))
    sc.collection.objects.link(cam)
    sc.camera = cam
    cam.location = EYE
    cam.rotation_euler = (np.pi / 2, 0.0, 0.0)
    return sc


def sphere(segments, rings, name="Ball", mat=None):
    bpy.ops.mesh.primitive_uv_sphere_add(segments=segments, ring_count=rings)
    bpy.ops.object.shade_smooth()
    ob = bpy.context.object
    ob.name = name
    ob.data.materials.append(mat if mat is not None else mirror_material())
    return ob


def read_layers(path):
    import OpenEXR

    with OpenEXR.File(str(path), separate_channels=True) as f:
        ch = {k: v for part in f.parts for k, v in part.channels.items()}  # one part per pass from 5.0
        out = {}
        for key in ("Combined", "P", "N"):
            names = sorted(k for k in ch if k.split(".")[-2:-1] == [key])
            by = {k.split(".")[-1]: np.asarray(ch[k].pixels, dtype=np.float64) for k in names}
            out[key] = np.stack([by["R"], by["G"], by["B"]], -1)
    return out


def render(tmp_path, name):
    sc = bpy.context.scene
    sc.render.filepath = str(tmp_path / f"{name}.exr")
    bpy.ops.render.render(write_still=True)
    return read_layers(sc.render.filepath)


def directions(layers):
    d = layers["Combined"] * 2.0 - 1.0
    return d / np.maximum(np.linalg.norm(d, axis=-1, keepdims=True), 1e-12)


def hit_mask(layers):
    return np.linalg.norm(layers["N"], axis=-1) > 0.5


def preview_directions(mirror, layers, eye=EYE):
    """What the viewport preview evaluates at each hit pixel: ``edited_directions`` of the field's
    own inputs at the rendered positions and normals."""
    st = mirror_state.state_of(mirror)
    rows, dist, regions = st.field_inputs
    assert dist is None and all(r["kind"] == "euclidean" for r in regions), "Euclidean fields only here"
    m = hit_mask(layers)
    p = layers["P"][m].astype(np.float32)
    n = layers["N"][m]
    n = (n / np.linalg.norm(n, axis=-1, keepdims=True)).astype(np.float32)
    kwargs = {"regions": regions} if regions else {}
    return m, native.edited_directions(p, n, eye, rows, **kwargs)


def angles_deg(a, b):
    return np.degrees(np.arccos(np.clip((a * b).sum(-1), -1.0, 1.0)))


def agreement(mirror, layers, eye=EYE):
    """Angles between rendered and previewed directions at the hit pixels where the edited
    direction stays above the surface (renders fold the others back about the tangent plane, the
    preview looks them up unfolded; the status reports their share)."""
    m, want = preview_directions(mirror, layers, eye)
    n = layers["N"][m]
    above = (want * (n / np.linalg.norm(n, axis=-1, keepdims=True))).sum(-1) > 0.0
    return angles_deg(directions(layers)[m], want)[above]


def physical(layers, eye=EYE):
    m = hit_mask(layers)
    p, n = layers["P"][m], layers["N"][m]
    n = n / np.linalg.norm(n, axis=-1, keepdims=True)
    i = p - np.array(eye)
    i /= np.linalg.norm(i, axis=-1, keepdims=True)
    return m, i - 2.0 * (i * n).sum(-1, keepdims=True) * n


def drag(mirror, index, to):
    mirror.rokeby.constraints[index].target_handle.location = to
