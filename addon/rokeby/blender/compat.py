"""What differs between the Blender releases Rokeby runs on (4.2 LTS, 4.5 LTS, 5.0, 5.1+), in one
place. Every other module asks here; none tests versions or catches version errors itself.

Each answer is a feature test of the running Blender (what its RNA declares), not a version
number, and is computed once:

* **EEVEE's engine id** (:func:`eevee_engine`): ``BLENDER_EEVEE_NEXT`` in 4.2-4.5,
  ``BLENDER_EEVEE`` from 5.0 — the one ``RenderSettings.engine`` declares.
* **Multilayer EXR output** (:func:`set_multilayer_exr`, :func:`is_multilayer_exr`,
  :func:`set_single_layer_exr`): up to 4.5 the file format ``OPEN_EXR_MULTILAYER``; from 5.0 the
  media type ``MULTI_LAYER_IMAGE`` of ``ImageFormatSettings`` (the format then reads
  ``OPEN_EXR_MULTILAYER`` again, but cannot be set while the media type is ``IMAGE``).
* **Built-in shaders** (:func:`builtin_shader`): ``POINT_FLAT_COLOR`` (round points) is missing in
  4.2; points are then drawn with ``FLAT_COLOR``. Which names exist is known only where the gpu
  module can draw, so it is asked once, at the first draw.
* **The scene's compositor tree** (:func:`compositor_tree`, :func:`compositor_output`):
  ``scene.node_tree`` (with ``scene.use_nodes``) up to 4.5; from 5.0 a compositing node group,
  ``scene.compositing_node_group``, whose Group Output is the result.
* **Geometry Nodes modifier inputs** (:func:`modifier_input`, :func:`set_modifier_input`): ID
  properties of the modifier (``mod["Socket_2"]``) up to 5.1; from 5.2 RNA properties,
  ``mod.properties.inputs.<identifier>.value``.
* **Storage of Python-defined properties** (:func:`stored_group`): the registered
  ``PointerProperty`` groups live among the ID's custom properties up to 4.5; from 5.0 apart from
  them (``ID.bl_system_properties_get``).
* **ID types the depsgraph names** (:func:`depsgraph_id_types`): the ids
  ``Depsgraph.id_type_updated`` accepts; a type a release does not name is left out.
* **Text drawn into images** (:func:`blf_draws_into_images`): ``blf.bind_imbuf`` and
  ``blf.draw_buffer`` exist from 4.3; 4.2 draws text only on the screen.
* **Node custom properties** (``node["key"]``) work on every supported release (tests/workflows/test_compat.py
  checks it on each leg); nothing to choose.
"""

from __future__ import annotations

import functools

import bpy


def _enum_ids(struct, prop: str) -> set:
    """The identifiers an RNA enum declares (statically: the class, not an instance)."""
    return {item.identifier for item in struct.bl_rna.properties[prop].enum_items}


# --- render engine -----------------------------------------------------------------------------

@functools.cache
def eevee_engine() -> str:
    """The engine id of EEVEE in this Blender: ``BLENDER_EEVEE_NEXT`` (4.2-4.5) or ``BLENDER_EEVEE``."""
    ids = _enum_ids(bpy.types.RenderSettings, "engine")
    for name in ("BLENDER_EEVEE_NEXT", "BLENDER_EEVEE"):
        if name in ids:
            return name
    raise RuntimeError(f"this Blender declares no EEVEE render engine (engines: {sorted(ids)})")


def is_eevee(engine: str) -> bool:
    """Whether ``engine`` (a ``scene.render.engine`` value) is EEVEE, under either id."""
    return engine in ("BLENDER_EEVEE_NEXT", "BLENDER_EEVEE")


# --- node trees of materials, worlds and lights ----------------------------------------------------

_USE_NODES_DEPRECATED: dict = {}


def node_tree_of(idblock):
    """The node tree that shapes ``idblock`` (a material, world or light), or None: its
    ``node_tree`` where ``use_nodes`` is on; from Blender 5.0, where reading ``use_nodes`` warns
    that it is deprecated (node trees always apply), the node tree alone (decided once per type,
    by that warning)."""
    import warnings  # noqa: PLC0415

    tree = getattr(idblock, "node_tree", None)
    if tree is None:
        return None
    kind = type(idblock).__name__
    if kind not in _USE_NODES_DEPRECATED:
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            on = getattr(idblock, "use_nodes", True)
        _USE_NODES_DEPRECATED[kind] = any(issubclass(w.category, DeprecationWarning) for w in caught)
        if not _USE_NODES_DEPRECATED[kind]:
            return tree if on else None
    if _USE_NODES_DEPRECATED[kind]:
        return tree
    return tree if getattr(idblock, "use_nodes", True) else None


# --- image output ------------------------------------------------------------------------------

@functools.cache
def _media_types() -> bool:
    """Whether ``ImageFormatSettings`` chooses multilayer output by media type (5.0+)."""
    props = bpy.types.ImageFormatSettings.bl_rna.properties
    return "media_type" in props and "MULTI_LAYER_IMAGE" in _enum_ids(bpy.types.ImageFormatSettings, "media_type")


def set_multilayer_exr(settings, color_depth: "str | None" = "32") -> None:
    """Makes ``settings`` (an ``ImageFormatSettings``: ``scene.render.image_settings``, a file
    output's) write a multilayer OpenEXR (every pass of every view layer in one file)."""
    if _media_types():
        settings.media_type = "MULTI_LAYER_IMAGE"
    settings.file_format = "OPEN_EXR_MULTILAYER"
    if color_depth is not None:
        settings.color_depth = color_depth


def single_layer_exr_items() -> tuple:
    """The (attribute, value) pairs of ``ImageFormatSettings`` that make it write a plain
    (single-layer) OpenEXR, in the order to set them (and to restore the old values in)."""
    return ((("media_type", "IMAGE"),) if _media_types() else ()) + (("file_format", "OPEN_EXR"),)


def set_single_layer_exr(settings, color_depth: "str | None" = None) -> None:
    """Makes ``settings`` write a plain (single-layer) OpenEXR: the combined image only."""
    for attr, value in single_layer_exr_items():
        setattr(settings, attr, value)
    if color_depth is not None:
        settings.color_depth = color_depth


def is_multilayer_exr(settings) -> bool:
    """Whether ``settings`` writes a multilayer OpenEXR."""
    if _media_types() and settings.media_type != "MULTI_LAYER_IMAGE":
        return False
    return settings.file_format == "OPEN_EXR_MULTILAYER"


# --- gpu built-in shaders ----------------------------------------------------------------------

# A built-in shader and the one that draws the same where it is missing (4.2 has no POINT_*).
_BUILTIN_FALLBACK = {"POINT_FLAT_COLOR": "FLAT_COLOR", "POINT_UNIFORM_COLOR": "UNIFORM_COLOR"}
_builtin_names: dict = {}  # asked name -> the name this Blender has


def builtin_shader(name: str):
    """``gpu.shader.from_builtin(name)``, or its stand-in where this Blender lacks ``name`` (call it
    where the gpu module can draw: a draw handler, an offscreen buffer)."""
    import gpu  # noqa: PLC0415

    have = _builtin_names.get(name)
    if have is None:
        have = name
        try:
            shader = gpu.shader.from_builtin(name)
        except ValueError:  # "expected a string in (...)": not a built-in shader of this release
            if name not in _BUILTIN_FALLBACK:
                raise
            have = _BUILTIN_FALLBACK[name]
            shader = gpu.shader.from_builtin(have)
        _builtin_names[name] = have
        return shader
    return gpu.shader.from_builtin(have)


def shader_depth_write(info, value: str) -> None:
    """Declares how a shader writes gl_FragDepth (``GPUShaderCreateInfo.depth_write``, where the
    release has it; OpenGL needs no declaration, so a release without it compiles the same)."""
    if hasattr(info, "depth_write"):
        info.depth_write(value)


def builtin_shader_name(name: str) -> "str | None":
    """The built-in shader :func:`builtin_shader` uses for ``name`` (None until it was first
    asked in a process that can draw)."""
    return _builtin_names.get(name)


# --- the depsgraph ------------------------------------------------------------------------------

@functools.cache
def _depsgraph_id_types() -> frozenset:
    fn = bpy.types.Depsgraph.bl_rna.functions["id_type_updated"]
    return frozenset(item.identifier for item in fn.parameters["id_type"].enum_items)


@functools.cache
def depsgraph_id_types(types: tuple) -> tuple:
    """Those of ``types`` (ID type ids: "MESH", "NODETREE", ...) that ``Depsgraph.id_type_updated``
    accepts in this Blender, in their order."""
    have = _depsgraph_id_types()
    return tuple(t for t in types if t in have)


# --- text ------------------------------------------------------------------------------------

def blf_draws_into_images() -> bool:
    """Whether ``blf`` can draw text into an image buffer (``blf.bind_imbuf``, 4.3+)."""
    import blf  # noqa: PLC0415

    return hasattr(blf, "bind_imbuf") and hasattr(blf, "draw_buffer")


# --- the compositor ----------------------------------------------------------------------------

@functools.cache
def _compositing_node_groups() -> bool:
    return "compositing_node_group" in bpy.types.Scene.bl_rna.properties


def compositor_tree(scene, create: bool = False):
    """The node tree that composites ``scene``'s renders (None when it has none and ``create`` is
    False). With ``create``, one is made and switched on: a new compositing node group holding a
    Render Layers node (5.0+), or ``scene.use_nodes`` (up to 4.5: Render Layers and Composite)."""
    if _compositing_node_groups():
        tree = scene.compositing_node_group
        if tree is None and create:
            tree = bpy.data.node_groups.new(f"{scene.name} Compositing", "CompositorNodeTree")
            tree.nodes.new("CompositorNodeRLayers")
            scene.compositing_node_group = tree
        return tree
    if create and not scene.use_nodes:
        scene.use_nodes = True
    return scene.node_tree if scene.use_nodes else None


def compositor_output(tree):
    """The input socket whose image is the composited result in ``tree``: the Composite node's
    (made if missing, up to 4.5) or the Group Output's ``Image`` (5.0+; socket made if missing)."""
    if _compositing_node_groups():
        if not any(item.item_type == "SOCKET" and item.in_out == "OUTPUT" and item.name == "Image" for item in tree.interface.items_tree):
            tree.interface.new_socket("Image", in_out="OUTPUT", socket_type="NodeSocketColor")
        out = next((n for n in tree.nodes if n.bl_idname == "NodeGroupOutput"), None) or tree.nodes.new("NodeGroupOutput")
        return out.inputs["Image"]
    comp = next((n for n in tree.nodes if n.bl_idname == "CompositorNodeComposite"), None) or tree.nodes.new("CompositorNodeComposite")
    return comp.inputs["Image"]


# --- Geometry Nodes modifier inputs ------------------------------------------------------------

@functools.cache
def _modifier_rna_inputs() -> bool:
    """Whether Geometry Nodes modifier inputs are RNA properties (``mod.properties.inputs``, 5.2+)."""
    return "properties" in bpy.types.NodesModifier.bl_rna.properties


def modifier_input(mod, identifier: str, default=None):
    """The value of input ``identifier`` (the interface socket's identifier, ``Socket_N``) of the
    Geometry Nodes modifier ``mod``, or ``default`` when it has none."""
    if _modifier_rna_inputs():
        props = mod.properties
        item = getattr(props.inputs, identifier, None) if props is not None else None
        return default if item is None else item.value
    return mod.get(identifier, default)


def set_modifier_input(mod, identifier: str, value) -> None:
    """Sets input ``identifier`` of the Geometry Nodes modifier ``mod`` to ``value``. Writing an RNA
    input (5.2+) does not tag the object for re-evaluation by itself: it is tagged here."""
    if _modifier_rna_inputs():
        getattr(mod.properties.inputs, identifier).value = value
        mod.id_data.update_tag()
    else:
        mod[identifier] = value


def _plain(v):
    if hasattr(v, "to_dict"):
        return v.to_dict()
    if hasattr(v, "to_list"):
        return v.to_list()
    if hasattr(v, "__len__") and not isinstance(v, str) and not hasattr(v, "bl_rna"):
        return list(v)
    return v


def modifier_inputs(mod) -> dict:
    """Everything the Geometry Nodes modifier ``mod`` stores for its inputs (values, and whether and
    which attribute an input reads), as plain values, for :func:`set_modifier_inputs` to put back:
    its ID properties up to 5.1; from 5.2 the writable RNA properties of each input
    (``value``, ``type``, ``attribute_name``, ...)."""
    if _modifier_rna_inputs():
        props = mod.properties
        out: dict = {}
        if props is None:
            return out
        for ident in dir(props.inputs):
            item = getattr(props.inputs, ident, None)
            if ident.startswith("_") or item is None or not hasattr(item, "bl_rna") or ident in ("bl_rna", "rna_type"):
                continue
            out[ident] = {p.identifier: _plain(getattr(item, p.identifier)) for p in item.bl_rna.properties
                          if not p.is_readonly and p.identifier not in ("name", "rna_type") and p.type != "POINTER"}
        return out
    return {k: _plain(mod[k]) for k in mod.keys()}


def set_modifier_inputs(mod, saved: dict) -> None:
    """Puts back what :func:`modifier_inputs` returned (keys the modifier no longer has are skipped;
    up to 5.1, ID properties added since are removed)."""
    if _modifier_rna_inputs():
        props = mod.properties
        if props is None:
            return
        for ident, values in saved.items():
            item = getattr(props.inputs, ident, None)
            if item is None:
                continue
            for name, v in values.items():
                if getattr(item, name, None) != v:
                    setattr(item, name, v)
        mod.id_data.update_tag()
        return
    for k in [k for k in mod.keys() if k not in saved]:
        del mod[k]
    for k, v in saved.items():
        if mod.get(k) != v:
            mod[k] = v


# --- where Python-defined properties are stored ------------------------------------------------

@functools.cache
def _system_properties() -> bool:
    """Whether registered properties are stored apart from custom ones (5.0+). ``hasattr`` on the
    class does not see the RNA function: ask RNA."""
    return "bl_system_properties_get" in bpy.types.ID.bl_rna.functions


def system_properties(owner):
    """The container of ``owner``'s registered (Python-defined) properties where it is kept apart from
    its custom properties (5.0+: ``bl_system_properties_get()``; None until something was stored),
    or None where both live together (up to 4.5: ``owner.keys()`` already lists them)."""
    if not _system_properties():
        return None
    get = getattr(owner, "bl_system_properties_get", None)
    if get is None:
        return None
    try:
        return get()
    except (TypeError, RuntimeError):
        return None


def stored_group(idblock, name: str):
    """The stored ID property group of the registered ``PointerProperty`` ``name`` of ``idblock``
    (None until something was written to it): one dict lookup, no RNA, so the handlers can scan
    many objects cheaply."""
    if _system_properties():
        props = idblock.bl_system_properties_get()
        return props.get(name) if props is not None else None
    return idblock.get(name)


def shape_key_points(key_block):
    """The collection to foreach_get/foreach_set a mesh shape key's coordinates through:
    ``ShapeKey.points`` (raw-array access, ~20x faster on large meshes) where Blender has it,
    else ``ShapeKey.data`` (per-item access)."""
    return key_block.points if hasattr(key_block, "points") else key_block.data
