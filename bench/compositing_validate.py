"""Validation of compositing-stage shape editing (issue #6) with Cycles renders.

Protocol (after the paper's Figs. 6 and 9), tiny renders so that it runs on a shared machine:

* A: a shared mesh (teapot.obj) under one of bpy's HDR worlds, with a glossy red material;
* B: a unit sphere with the same material and world, seen by an orthographic camera with the same
  orientation — the reference prefiltered environments (a "Lit Sphere"): at each pixel its
  diffuse pass is D_true(n) and its glossy pass R_true(r), for n and r of that pixel;
* C: A re-rendered with a bump (Noise texture → Bump → the BSDF normal), the ground truth of an edit.

Measured: A's reconstructed diffuse SH (QP and LS) evaluated at B's normals against B's diffuse
pass; A's reflection map looked up at B's reflected directions against B's glossy pass; A
recomposited with C's normals against the C render (and, as the baseline, A unedited against C).
Writes docs/compositing.md's numbers (stdout, or --json) and a side-by-side PNG.

    python bench/compositing_validate.py [--json OUT] [--png docs/compositing_bump.png]
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "addon"))
SHARED = ROOT.parent / "shared"


def scene(kind, hdr, w, h, samples, mesh=None):
    import bpy

    bpy.ops.wm.read_factory_settings(use_empty=True)
    sc = bpy.context.scene
    sc.render.engine = "CYCLES"
    sc.cycles.samples, sc.cycles.device, sc.cycles.use_denoising = samples, "CPU", False
    sc.cycles.seed = 7
    sc.render.resolution_x, sc.render.resolution_y, sc.render.resolution_percentage = w, h, 100
    from rokeby import envmaps

    envmaps.use_studio_world(sc, hdr.removesuffix(".exr"))
    if kind == "sphere":
        bpy.ops.mesh.primitive_uv_sphere_add(segments=96, ring_count=48, radius=1.0)
        ob = bpy.context.object
    else:
        bpy.ops.wm.obj_import(filepath=str(mesh), forward_axis="Y", up_axis="Z")
        ob = bpy.context.selected_objects[0]
        bpy.context.view_layer.objects.active = ob
        bpy.ops.object.origin_set(type="ORIGIN_GEOMETRY", center="BOUNDS")
        ob.location = (0, 0, 0)
        s = 2.0 / max(ob.dimensions)
        ob.scale = (s, s, s)
    bpy.ops.object.shade_smooth()
    mat = bpy.data.materials.new("red")
    mat.use_nodes = True
    nt = mat.node_tree
    b = nt.nodes["Principled BSDF"]
    b.inputs["Base Color"].default_value = (0.7, 0.15, 0.1, 1)
    b.inputs["Roughness"].default_value = 0.15
    b.inputs["Metallic"].default_value = 0.0
    if kind == "bumped":
        noise = nt.nodes.new("ShaderNodeTexNoise")
        noise.inputs["Scale"].default_value = 12.0
        bump = nt.nodes.new("ShaderNodeBump")
        bump.inputs["Strength"].default_value = 1.0
        nt.links.new(noise.outputs["Fac"], bump.inputs["Height"])
        nt.links.new(bump.outputs["Normal"], b.inputs["Normal"])
    ob.data.materials.clear()
    ob.data.materials.append(mat)
    rot = (1.3, 0.0, 0.35)
    if kind == "sphere":
        bpy.ops.object.camera_add(rotation=rot)
        cam = bpy.context.object
        cam.data.type = "ORTHO"
        cam.data.ortho_scale = 2.6
    else:
        bpy.ops.object.camera_add(rotation=rot)
        cam = bpy.context.object
        cam.data.lens = 110
    # Back along the camera's view axis.
    import mathutils

    cam.location = mathutils.Matrix.Rotation(0, 3, "Z") @ (cam.matrix_world.to_3x3() @ mathutils.Vector((0, 0, 7.0)))
    sc.camera = cam
    return sc


def tonemap(img):
    return np.clip(img / (1 + img), 0, 1) ** (1 / 2.2)


def main():
    import bpy

    from rokeby import compositing as C
    import rokeby_native as rn

    ap = argparse.ArgumentParser()
    ap.add_argument("--json")
    ap.add_argument("--png", default=str(ROOT / "docs" / "compositing_bump.png"))
    ap.add_argument("--hdr", default="forest.exr")
    ap.add_argument("--mesh", default=str(SHARED / "meshes" / "teapot.obj"))
    ap.add_argument("--size", default="160,120")
    ap.add_argument("--samples", type=int, default=128)
    a = ap.parse_args()
    w, h = (int(v) for v in a.size.split(","))
    out = {"hdr": a.hdr, "mesh": Path(a.mesh).name, "width": w, "height": h, "samples": a.samples}
    with tempfile.TemporaryDirectory() as tmp:
        pa = C.render_passes(scene("mesh", a.hdr, w, h, a.samples, a.mesh), f"{tmp}/a.exr")
        pb = C.render_passes(scene("sphere", a.hdr, w, h, a.samples), f"{tmp}/b.exr")
        pc = C.render_passes(scene("bumped", a.hdr, w, h, a.samples, a.mesh), f"{tmp}/c.exr")
    nb, vb = C.screen_space(pb)
    sphere = pb.index_ob > 0
    # Directions B shows away from its rim (the rim's pixels mix with the background).
    inner = sphere & (nb[..., 2] > 0.3)
    db = (pb.diff_dir + pb.diff_ind)[inner]
    rb = (pb.gloss_dir + pb.gloss_ind)[inner]
    for method in ("qp", "ls"):
        rec = C.reconstruct(pa, method=method, warn=False)
        k = int(np.argmax([r.pixels for r in rec.reports]))
        rep = rec.reports[k]
        d = rn.sh_eval(rec.patches[k]["sh"], nb[inner])
        out[f"diffuse_{method}_rel_rms"] = float(np.sqrt(((d - db) ** 2).mean()) / db.mean())
        out[f"diffuse_{method}_rel_mean_abs"] = float(np.abs(d - db).mean() / db.mean())
    out["patch_pixels"] = rep.pixels
    out["reflection_coverage"] = rep.coverage
    # The sphere's own SH (LS) as a floor: what order 2 can do at all.
    own = rn.sh_fit(nb[inner], db, "ls")["coeffs"]
    out["diffuse_sphere_own_sh_rel_rms"] = float(np.sqrt(((rn.sh_eval(own, nb[inner]) - db) ** 2).mean()) / db.mean())
    env = rec.patches[k]["env"]
    rdir = rn.reflect_dirs(nb, vb)[inner]
    r = rn.envmap_lookup(env, rdir)
    out["reflection_rel_mean_abs"] = float(np.abs(r - rb).mean() / rb.mean())
    # Only where A's pixels recovered the direction (no hole filling involved).
    part = rn.reflection_env(rn.reflect_dirs(rec.normals, rec.view), pa.gloss_dir + pa.gloss_ind,
                             ((rec.ids == k) & (pa.reflocc >= 0.5)).astype(np.float32), pa.depth, stage="partial")
    cov = rn.envmap_lookup(part["covered"][..., None].astype(np.float32), rdir)[:, 0] > 0.999
    out["reflection_covered_fraction_of_sphere_pixels"] = float(cov.mean())
    out["reflection_rel_mean_abs_covered"] = float(np.abs(r - rb)[cov].mean() / rb[cov].mean())
    out["reflection_mean_reference"] = float(rb.mean())
    # The bump: A recomposited with C's normals against the C render (same camera, same pixels).
    rec = C.reconstruct(pa, warn=False)
    nc, _ = C.screen_space(pc)
    obj = (rec.ids >= 0) & (pc.index_ob > 0)
    edited = np.where(obj[..., None], nc, rec.normals)
    comp, stats = C.recomposite(pa, rec, edited)
    ref = pc.image
    scale = ref[obj].mean()
    out["bump_recomposited_rel_mean_abs"] = float(np.abs(comp - ref)[obj].mean() / scale)
    out["bump_unedited_rel_mean_abs"] = float(np.abs(pa.image - ref)[obj].mean() / scale)
    out["bump_recomposited_minus_unedited_detail_corr"] = float(np.corrcoef((comp - pa.image)[obj].ravel(), (ref - pa.image)[obj].ravel())[0, 1])
    side = np.concatenate([tonemap(pa.image), tonemap(comp), tonemap(ref)], 1)
    img = C.show_image("validation", side.astype(np.float32))
    img.filepath_raw = a.png
    img.file_format = "PNG"
    img.save()
    out["png"] = str(Path(a.png).relative_to(ROOT)) if Path(a.png).is_relative_to(ROOT) else a.png
    text = json.dumps(out, indent=1)
    if a.json:
        Path(a.json).write_text(text)
    print(text)


if __name__ == "__main__":
    main()
