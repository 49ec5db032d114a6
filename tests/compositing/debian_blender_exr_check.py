"""Run by tests/compositing/test_exr_io.py inside Debian 13's own Blender (4.3.2, linked with
Debian's libOpenEXRCore; background mode): installs the extension zip from disk into a fresh user
configuration, runs Render and Recomposite on a tiny Cycles scene and prints one JSON line. With
a zip that bundled the OpenEXR wheel, Blender died here right after saving the EXR (SIGBUS or
SIGSEGV)."""
import json
import os
import sys

import bpy

zip_path, out = sys.argv[sys.argv.index("--") + 1:]
os.makedirs(out, exist_ok=True)
res = {"blender": bpy.app.version_string}
r = bpy.ops.extensions.package_install_files(filepath=zip_path, repo="user_default", enable_on_install=True)
res["install"] = sorted(r)
bpy.ops.wm.read_factory_settings(use_empty=True)
import addon_utils  # noqa: E402

addon_utils.enable("bl_ext.user_default.rokeby", default_set=True)
sc = bpy.context.scene
sc.render.engine = "CYCLES"
sc.cycles.samples, sc.cycles.device, sc.cycles.use_denoising = 4, "CPU", False
sc.render.resolution_x, sc.render.resolution_y, sc.render.resolution_percentage = 32, 24, 100
bpy.ops.mesh.primitive_uv_sphere_add()
mat = bpy.data.materials.new("red")
mat.use_nodes = True
bpy.context.object.data.materials.append(mat)
bpy.ops.object.camera_add(location=(0, -5, 0), rotation=(1.5708, 0, 0))
sc.camera = bpy.context.object
bpy.ops.object.light_add(type="SUN")
sc.world = bpy.data.worlds.new("W")
frame = os.path.join(out, "frame.exr")
print("ROKEBY-CHECK: running Render and Recomposite", flush=True)
r = bpy.ops.rokeby.composite_render(filepath=frame)
res["operator"] = sorted(r)
res["exr_exists"] = os.path.exists(frame)
res["openexr_imported"] = "OpenEXR" in sys.modules
exr = sys.modules.get("bl_ext.user_default.rokeby.core.exr")
if exr is not None and os.path.exists(frame):
    parts = exr.read(frame)
    res["channels"] = len(parts[0].channels)
    res["compression"] = parts[0].compression
img = [i.name for i in bpy.data.images if "ecomposit" in i.name]
res["images"] = img
print("ROKEBY-CHECK " + json.dumps(res), flush=True)
