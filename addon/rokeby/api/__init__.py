"""rokeby.api — the scripting API of Rokeby, used by background scripts (render farms, pipelines):
the entry points of every feature in one place.

This is the facade of the layered add-on (docs/architecture.md): it implements nothing and
re-exports exactly the ``__all__`` of each feature's ``api`` module, in this order, so
``rokeby.api.<name>`` is the very function the feature's operators call:

- ``rokeby.reflection.api``: reflection editing (maths helpers, mirrors, constraints, regions,
  render nodes, reflection maps, highlights, refraction);
- ``rokeby.compositing.api``: shape editing at the compositing stage (passes, recompositing, the
  normal brush);
- ``rokeby.shadow.api``: shadow boundary editing;
- ``rokeby.appearance.api``: appearance (BRDF) painting;
- ``rokeby.envmaps.api``: the HDR worlds bpy ships and HDR image files;
- ``rokeby.farm.api``: render-farm job bundles (bpy-free).

Every name is documented in docs/python-api.md (tests/workflows/test_api_docs.py checks both
ways). Data moves as numpy arrays (``foreach_get``/``foreach_set``), never with Python loops over
vertices. Functions that need Blender import ``bpy`` lazily, so the maths helpers work in any
Python with numpy and rokeby_native.
"""

from ..compositing.api import (
    open_normal_brush,
    paint_normals,
    recomposite_exr,
    recomposite_exr_pixels,
    recomposite_render,
    setup_compositing_passes,
    use_in_compositor,
)
from ..farm.api import write_recomposite_job, write_render_job
from ..reflection.api import (
    MeshArrays,
    MirrorReport,
    RokebyError,
    add_constraint,
    add_highlight_constraint,
    add_mirror,
    add_region,
    capture_preview_scene,
    capture_reflection_map,
    constraint_row,
    constraint_view,
    edited_directions,
    edited_materials,
    edited_reflections,
    evaluate,
    field,
    freeze,
    geodesic_distances,
    geodesic_solver,
    install_render_nodes,
    ior_from_material,
    mesh_arrays,
    mirror_of,
    physical_highlight,
    physical_reflected_point,
    quat_angle,
    reflect,
    reflection_map,
    refract,
    refraction_field,
    remove_constraint,
    remove_mirror,
    remove_region,
    remove_render_nodes,
    report,
    reset_stats,
    rotate,
    rotation_field,
    set_edited_materials,
    set_ior,
    stats,
    stored_field,
    stored_refraction,
)
from ..shadow.api import apply_shadow_edit, remove_shadow_edit, start_shadow_edit
from ..appearance.api import (
    appearance_values,
    paint_appearance,
    remove_appearance_painting,
    set_appearance_scale,
    setup_appearance_painting,
)
from ..envmaps.api import read_exr, read_hdr, studio_world, use_studio_world, write_exr, write_hdr

__all__ = [
    # rokeby.reflection.api
    "reflect", "constraint_row", "physical_reflected_point", "MeshArrays", "mesh_arrays",
    "rotation_field", "edited_directions", "rotate", "quat_angle", "geodesic_solver",
    "geodesic_distances", "add_mirror", "remove_mirror", "mirror_of", "add_constraint",
    "remove_constraint", "add_region", "remove_region", "evaluate", "freeze", "edited_materials",
    "install_render_nodes", "remove_render_nodes", "capture_reflection_map", "reflection_map",
    "capture_preview_scene", "set_edited_materials", "constraint_view", "edited_reflections",
    "report", "field", "stored_field", "refract", "refraction_field", "stored_refraction",
    "set_ior", "ior_from_material", "physical_highlight", "add_highlight_constraint", "stats",
    "reset_stats", "RokebyError", "MirrorReport",
    # rokeby.compositing.api
    "setup_compositing_passes", "recomposite_render", "recomposite_exr", "recomposite_exr_pixels",
    "use_in_compositor", "open_normal_brush", "paint_normals",
    # rokeby.shadow.api
    "start_shadow_edit", "apply_shadow_edit", "remove_shadow_edit",
    # rokeby.appearance.api
    "setup_appearance_painting", "paint_appearance", "appearance_values", "set_appearance_scale",
    "remove_appearance_painting",
    # rokeby.envmaps.api
    "studio_world", "use_studio_world", "read_exr", "write_exr", "read_hdr", "write_hdr",
    # rokeby.farm.api
    "write_render_job", "write_recomposite_job",
]
