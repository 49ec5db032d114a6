"""The painted parameters (Fraser, §"Painting") and where their values live. Fraser's brushes and
their attributes (point domain, on the original mesh, so modifiers interpolate them and Cycles and
EEVEE both render them):

============  =============================  ==========================================
brush         attribute                      Principled BSDF input
============  =============================  ==========================================
diffuse       ``rokeby_base_color`` (RGBA)   Base Color
specular      ``rokeby_specular``            Specular IOR Level (k_s)
sharpen/blur  ``rokeby_roughness``           Roughness (sharpen lowers, blur raises)
stretch       ``rokeby_anisotropic``         Anisotropic, and its direction ``rokeby_anisotropic_rotation``
                                             (Anisotropic Rotation) from the stroke direction
metallic      ``rokeby_metallic``            Metallic (energy between diffuse and specular)
specular_tint ``rokeby_specular_tint`` (RGBA) Specular Tint (Fraser's Step 6: the highlight's colour)
============  =============================  ==========================================

On a texture target (``texture.py``) a parameter's values are an image read by the Image Texture
node ``rokeby_tex_<param>`` (:func:`_texture_image`)."""

from __future__ import annotations

from ..core import schema, words


# brush → (attribute, Principled input, default when the material has no value, clamp range)
PARAMS = {
    "diffuse": (schema.APPEARANCE_ATTRIBUTES["diffuse"], "Base Color", (0.8, 0.8, 0.8, 1.0), (0.0, 1.0)),
    "specular": (schema.APPEARANCE_ATTRIBUTES["specular"], "Specular IOR Level", 0.5, (0.0, 1.0)),
    "roughness": (schema.APPEARANCE_ATTRIBUTES["roughness"], "Roughness", 0.5, (0.0, 1.0)),
    "anisotropic": (schema.APPEARANCE_ATTRIBUTES["anisotropic"], "Anisotropic", 0.0, (0.0, 1.0)),
    "anisotropic_rotation": (schema.APPEARANCE_ATTRIBUTES["anisotropic_rotation"], "Anisotropic Rotation", 0.0, (0.0, 1.0)),
    "metallic": (schema.APPEARANCE_ATTRIBUTES["metallic"], "Metallic", 0.0, (0.0, 1.0)),
    # Fraser's proposed Step 6 ("change the colour of specular highlights"): Blender's specular
    # tint, the colour of the dielectric reflection at normal incidence (F0 · tint; on metals it
    # tints the grazing edge, Blender's F82 tint).
    "specular_tint": (schema.APPEARANCE_ATTRIBUTES["specular_tint"], "Specular Tint", (1.0, 1.0, 1.0, 1.0), (0.0, 1.0)),
}
# The colour parameters (RGBA attributes, Mix (Multiply) global nodes, RGB brushes).
COLORS = ("diffuse", "specular_tint")
# Largest colour component a brush or tint accepts: room for HDR albedo tricks, far from float32's
# overflow (3.4e38), so no painted or blended value can become inf in the attribute or image.
MAX_COLOR = 1e4
# Fraser's brush names on top of the parameters.
BRUSHES = {"sharpen": ("roughness", "SUBTRACT"), "blur": ("roughness", "ADD"), "stretch": ("anisotropic", "ADD")}


def _check_mesh(obj):
    if obj is None:
        raise ValueError("obj: is None")
    if obj.type != "MESH":
        raise ValueError(f"obj: '{obj.name}' is {words.kind(obj.type)}, not a mesh")
    if len(obj.data.vertices) == 0:
        raise ValueError(f"obj: '{obj.name}' has no vertices to paint")


def _tex_node(obj, param):
    mat = obj.active_material
    if mat is None or not mat.use_nodes:
        return None
    return mat.node_tree.nodes.get(schema.APPEARANCE_NODE_PREFIX + "tex_" + param)


def _texture_image(obj, param):
    tex = _tex_node(obj, param)
    if tex is None or tex.image is None or not tex.outputs["Color"].is_linked:
        return None
    return tex.image
