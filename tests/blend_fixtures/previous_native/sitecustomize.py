"""rokeby_native as the previous release (test_saved_fixtures.PREVIOUS_RELEASE) calls it.

tests/workflows/test_saved_fixtures.py runs the previous release's add-on with this checkout's
rokeby_native wheel to write the files its users have. That add-on calls the core by flat names
(``rokeby_native.rotation_field``, ``env_prefilter``, ``exr_read``, ...), which are now functions of
the area submodules (``rokeby_native.reflection.rotation_field``, ...). This folder is put on the
PYTHONPATH of that process only; Python imports this module at start-up (``site``), and it adds the
flat names to the module as the same function objects, so the previous release computes exactly
what it computed with its own wheel. Remove it once PREVIOUS_RELEASE has the submodules."""

# Flat name in the previous release -> (submodule, name there).
FLAT_NAMES = {
    **{n: ("reflection", n) for n in ("rotation_field", "edited_directions", "view_blend", "view_blend_render_rows",
                                      "view_blend_rotation_vectors", "ortho", "field_kernel")},
    **{n: ("geometry", n) for n in ("geodesic_distances", "interpolate", "GeodesicSolver")},
    "env_convert": ("envmaps", "convert"), "env_sample": ("envmaps", "sample"),
    "env_prefilter": ("envmaps", "prefilter"), "env_irradiance": ("envmaps", "irradiance"),
    "env_reference": ("envmaps", "prefilter_reference"),
    "rgbe_decode": ("envmaps", "rgbe_decode"), "rgbe_encode": ("envmaps", "rgbe_encode"),
    "shadow_silhouettes": ("shadows", "silhouettes"), "shadow_falloff": ("shadows", "falloff_factor"),
    "ShadowEditor": ("shadows", "ShadowEditor"),
    **{n: ("compositing", n) for n in ("sh_fit", "sh_eval", "reflect_dirs", "reflection_env", "fill_holes",
                                       "envmap_lookup", "recomposite", "Recompositor", "normals_bilateral",
                                       "normals_bump", "normals_emboss", "normals_noise_decal")},
    "exr_read": ("exr_io", "read"), "exr_write": ("exr_io", "write"),
}


def _add_flat_names() -> None:
    try:
        import rokeby_native
    except ImportError:
        return  # no wheel: the previous release reports that itself
    for flat, (area, name) in FLAT_NAMES.items():
        setattr(rokeby_native, flat, getattr(getattr(rokeby_native, area), name))


_add_flat_names()
