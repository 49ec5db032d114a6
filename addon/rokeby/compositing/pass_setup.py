"""Blender side of the passes: :func:`setup_passes` enables the Cycles passes the method needs —
Normal, Diffuse and Glossy direct/indirect/colour, object and material index, ambient occlusion
(α_D), depth — and three AOVs written by nodes added to every material: ``rokeby_reflocc``
(reflection occlusion α_R: an Ambient Occlusion node with *Only Local* around the reflected
direction, so only self-reflections count), ``rokeby_incoming_cam`` (the view vector in camera
space) and ``rokeby_camera_x``/``_y`` (the world axes in camera space: the camera's rotation in
every frame, so an EXR alone is enough — no camera data to carry along); :func:`render_passes`
renders them and reads them back."""

from __future__ import annotations

from ..blender import transaction
from ..core import schema
from .exr_io import read_exr
from .passes import PASSES, Passes


def _material_nodes(mat) -> None:
    """Adds (once; again, whole, when an artist deleted a part) the AOV outputs of the reflection
    occlusion, the camera rotation and the view vector."""
    nt = mat.node_tree
    ours = [n for n in nt.nodes if n.get(schema.COMPOSITING_NODE_KEY)]
    have = {n.aov_name for n in ours if n.bl_idname == "ShaderNodeOutputAOV" and n.inputs[0].is_linked}
    if have >= {schema.AOV_REFLOCC, schema.AOV_CAMERA_X, schema.AOV_CAMERA_Y, schema.AOV_INCOMING_CAM}:
        return
    for n in ours:
        nt.nodes.remove(n)
    def node(kind, label):
        n = nt.nodes.new(kind)
        n.label = f"{schema.COMPOSITING_NODE_TAG}: {label}"
        n[schema.COMPOSITING_NODE_KEY] = True
        n.location = (-900, -600 - 120 * len([x for x in nt.nodes if x.get(schema.COMPOSITING_NODE_KEY)]))
        return n
    tex = node("ShaderNodeTexCoord", "reflection")
    ao = node("ShaderNodeAmbientOcclusion", "self-reflection occlusion")
    ao.only_local = True
    ao.samples = 8
    ao.inputs["Distance"].default_value = 1e4
    nt.links.new(tex.outputs["Reflection"], ao.inputs["Normal"])
    out_r = node("ShaderNodeOutputAOV", schema.AOV_REFLOCC)
    out_r.aov_name = schema.AOV_REFLOCC
    nt.links.new(ao.outputs["AO"], out_r.inputs["Value"])
    geo = node("ShaderNodeNewGeometry", "view vector")
    # The world X and Y axes in camera space: the camera's rotation, exact at every pixel.
    for name, axis in ((schema.AOV_CAMERA_X, (1.0, 0.0, 0.0)), (schema.AOV_CAMERA_Y, (0.0, 1.0, 0.0))):
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
    out_c = node("ShaderNodeOutputAOV", schema.AOV_INCOMING_CAM)
    out_c.aov_name = schema.AOV_INCOMING_CAM
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
    for name, kind in ((schema.AOV_REFLOCC, "VALUE"), (schema.AOV_CAMERA_X, "COLOR"), (schema.AOV_CAMERA_Y, "COLOR"), (schema.AOV_INCOMING_CAM, "COLOR")):
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
