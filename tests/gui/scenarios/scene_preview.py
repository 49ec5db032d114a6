"""The scene preview in a real window: a chrome ball with coloured cubes around it, a constraint
whose green handle sits on the magenta cube. With Viewport Preview on (Solid shading) the window
captures the scene by itself (the debounced timer, never from inside a draw), and the screenshot's
pixel at the red handle shows the magenta cube, as a Cycles render of the same view does. A handle
dragged with G and the mouse triggers no capture; a cube dragged with G triggers none while the
mouse moves and exactly one after the click that confirms it."""

import os
import sys

import bpy
import numpy as np

import scenes

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", ".."))  # tests/: the shared scene helpers
from support.scene_preview import material, mirror_material  # noqa: E402

MAGENTA = (0.8, 0.05, 0.5)
EYE = (1.2, -6.8, 1.4)


def build(ui):
    sc = bpy.context.scene
    for ob in list(bpy.data.objects):
        if ob.type == "MESH":
            bpy.data.objects.remove(ob)
    sc.render.engine = "CYCLES"
    sc.cycles.device = "CPU"
    sc.view_settings.view_transform = "Standard"  # screenshots and renders both plain sRGB
    sc.world.use_nodes = True
    sc.world.node_tree.nodes["Background"].inputs["Color"].default_value = (0.05, 0.05, 0.05, 1.0)
    with ui.override():
        bpy.ops.mesh.primitive_uv_sphere_add(segments=64, ring_count=32, radius=1.0, location=(0, 0, 0))
        bpy.ops.object.shade_smooth()
    mirror = bpy.context.view_layer.objects.active
    mirror.name = "Mirror"
    mirror.data.materials.append(mirror_material())
    cubes = {}
    for name, loc, size, colour in (("Magenta", (0.35, -1.75, -1.35), 0.6, MAGENTA),
                                     ("Red", (1.9, -1.0, 0.3), 0.6, (0.8, 0.1, 0.05)),
                                     ("Yellow", (-2.0, -1.2, 0.6), 0.6, (0.85, 0.7, 0.05))):
        with ui.override():
            bpy.ops.mesh.primitive_cube_add(size=size, location=loc)
        ob = bpy.context.view_layer.objects.active
        ob.name = name
        ob.data.materials.append(material(name, colour, emission=1.0))  # its colour reads the same from every side
        cubes[name] = ob
    return sc, mirror, cubes


def ring_at(ui, shot, p, box, radius=8):
    """The screenshot's sRGB colour just around the screen point of ``p``: the median over a ring of
    ``radius`` pixels above and beside it (the handle's square covers the point itself, the line
    to the green handle runs below it)."""
    x, y = ui.point_xy(p)
    x, y = x - box[0], y - box[1]  # the screenshot is of the region (box: its place on the screen)
    px = ui.pixels(shot)
    angles = np.radians(np.arange(-30, 211, 15))  # above and to both sides, screen y down
    xs = np.round(x + radius * np.cos(angles)).astype(int)
    ys = np.round(y - radius * np.sin(angles)).astype(int)
    return [round(float(v), 4) for v in np.median(px[ys, xs, :3], axis=0)], [int(round(x)), int(round(y))]


def scenario(ui):
    rokeby = yield from ui.start()
    api = ui.addon("api")
    scene_env = ui.addon("reflection.viewport.scene_env")
    schema = ui.addon("core.schema")
    sc, mirror, cubes = build(ui)
    api.add_mirror(mirror)
    # The scene camera: the field's reflected directions are the ones it sees (the render eye).
    from mathutils import Vector

    bpy.data.objects.remove(bpy.data.objects["Camera"])
    cam = bpy.data.objects.new("Camera", bpy.data.cameras.new("Camera"))
    sc.collection.objects.link(cam)
    sc.camera = cam
    cam.location = EYE
    cam.rotation_euler = (-Vector(EYE)).to_track_quat("-Z", "Y").to_euler()
    sc.render.resolution_x, sc.render.resolution_y, sc.render.resolution_percentage = 480, 320, 100
    # The red handle on the ball's front, the green one on the magenta cube.
    api.add_constraint(mirror, (0.35, -0.9, -0.25), tuple(cubes["Magenta"].location))
    api.evaluate(sc, force=True)
    c = mirror.rokeby.constraints[0]
    red, green = c.surface_handle, c.target_handle
    # The view: through the camera, Solid shading, the preview on.
    area = ui.area()
    space = area.spaces.active
    space.shading.type = "SOLID"
    space.overlay.show_floor = False
    space.overlay.show_axis_x = space.overlay.show_axis_y = False
    rv3d = ui.region("WINDOW", area).data
    rv3d.view_perspective = "CAMERA"
    with ui.override():
        bpy.ops.view3d.view_center_camera()
    rv3d.view_camera_zoom -= 12  # the whole frame and the magenta cube (the green handle) in the view
    with ui.override():
        bpy.ops.ed.undo_push(message="scene set up")
    yield from ui.redraws(2)
    ui.screenshot("preview-off", crop=ui.region_box(ui.region("WINDOW")))
    off_shot = ui.shots[-1]
    r = ui.result
    r["captures_before"] = scene_env.stats["captures"]
    setattr(sc, schema.SCENE_VIEWPORT_PREVIEW_PROP, True)
    # The first draw asks for a capture; the window's timer takes it once nothing changes.
    t_first = ui.now()
    for _ in range(3):
        yield from ui.redraws(1)
    yield from ui.until(lambda: scene_env.current(mirror) is not None, 120, "the first scene capture")
    r["first_capture_after_s"] = round(ui.now() - t_first, 2)
    cap = scene_env.current(mirror)
    r["capture"] = {"seconds": round(cap.seconds, 3), "bytes": cap.nbytes, "width": cap.width}
    r["captures_after_first"] = scene_env.stats["captures"]
    yield from ui.redraws(3)
    shot = ui.screenshot("preview-on", crop=ui.region_box(ui.region("WINDOW")))
    region = ui.region("WINDOW")
    box = ui.region_box(region)

    def at(path, p):
        return ring_at(ui, path, p, box)

    import os

    r["red_handle_on"], r["red_handle_px"] = at(shot, red.matrix_world.translation)
    r["red_handle_off"], _ = at(os.path.join(ui.out, off_shot), red.matrix_world.translation)
    r["offscreen"] = offscreen_at(ui, sc, mirror, red)
    # A Cycles render of the camera: the preview's pixel against the renderer's.
    sc.cycles.samples = 16
    sc.cycles.use_denoising = False
    with ui.override():
        bpy.ops.render.render()
    path = os.path.join(ui.out, "render.png")
    bpy.data.images["Render Result"].save_render(path)
    from bpy_extras.object_utils import world_to_camera_view

    uvw = world_to_camera_view(sc, cam, red.matrix_world.translation)
    px = ui.pixels(path)
    h, w = px.shape[:2]
    x, y = int(uvw.x * w), int((1.0 - uvw.y) * h)
    r["red_handle_render"] = [round(float(v), 4) for v in np.median(px[y - 1:y + 2, x - 1:x + 2, :3].reshape(-1, 3), axis=0)]
    ui.shots.append("render.png")
    yield from ui.redraws(2)
    yield from ui.until(lambda: not scene_env._pending, 60, "no capture pending")

    # A green-handle drag with G and the mouse: the field changes, the scene does not: no capture.
    n0 = scene_env.stats["captures"]
    r["green_before"] = [round(float(v), 4) for v in green.location]
    yield from scenes.grab(ui, green, 25, -10)
    yield 1.5  # past the debounce: a capture would have run by now
    yield from ui.redraws(2)
    r["captures_handle_drag"] = scene_env.stats["captures"] - n0
    r["green_moved"] = [round(float(v), 4) for v in green.location]

    # A cube dragged with G: none while the mouse moves, one after the confirming click.
    cube = cubes["Red"]
    n0 = scene_env.stats["captures"]
    counts = []

    def during():
        counts.append(scene_env.stats["captures"] - n0)

    yield from scenes.grab(ui, cube, 40, 20, steps=8, each=during, finish=None)
    yield 1.0  # the mouse held still inside the transform: still no capture
    during()
    yield from ui.press()
    yield from ui.release()
    yield from ui.redraws(1)
    r["captures_during_cube_drag"] = counts
    yield from ui.until(lambda: scene_env.stats["captures"] > n0, 60, "the capture after the cube moved")
    yield 1.5
    yield from ui.redraws(2)
    r["captures_after_cube_drag"] = scene_env.stats["captures"] - n0
    r["cube_moved"] = [round(float(v), 4) for v in cube.location]
    ui.screenshot("cube-moved", crop=ui.region_box(ui.region("WINDOW")))
    r["addon_version"] = getattr(rokeby, "__version__", None)

    # The GPU capture (add-on preferences ▸ Scene Capture ▸ Viewport): the six views drawn by the
    # window as its 3D view draws them, Capture Scene for Preview from the sidebar's operator.
    prefs = ui.addon("blender.prefs")
    prefs.get().scene_capture = "VIEWPORT"
    n0 = scene_env.stats["captures"]
    with ui.override():
        r["gpu_capture_op"] = sorted(bpy.ops.rokeby.preview_capture())
    cap = scene_env.current(mirror)
    r["gpu"] = {"route": cap.route, "seconds": round(cap.seconds, 4), "stages": {k: round(v, 4) for k, v in (cap.stages or {}).items()},
                "captures": scene_env.stats["captures"] - n0, "mirror_visible": mirror.visible_get(),
                "overlays": ui.area().spaces.active.overlay.show_overlays}
    yield from ui.redraws(3)
    shot = ui.screenshot("preview-gpu", crop=ui.region_box(ui.region("WINDOW")))
    box = ui.region_box(ui.region("WINDOW"))
    r["gpu"]["red_handle"], _ = ring_at(ui, shot, red.matrix_world.translation, box)
    # Nothing changed since: a refresh keeps it. Material Preview keeps it too (the capture is drawn
    # in Solid shading) and shows it; another Solid lighting (Flat) recaptures.
    r["gpu"]["refresh_again"] = scene_env.refresh(sc)
    space = ui.area().spaces.active
    space.shading.type = "MATERIAL"
    yield from ui.redraws(3)
    yield 2.0
    yield from ui.redraws(2)
    r["gpu"]["captures_material"] = scene_env.stats["captures"] - n0
    shot = ui.screenshot("preview-gpu-material", crop=ui.region_box(ui.region("WINDOW")))
    r["gpu"]["red_handle_material"], _ = ring_at(ui, shot, red.matrix_world.translation, box)
    space.shading.type = "SOLID"
    space.shading.light = "FLAT"
    yield from ui.redraws(2)
    yield from ui.until(lambda: scene_env.stats["captures"] > n0 + 1, 30, "the capture after the Solid lighting changed")
    r["gpu"]["captures_after_flat"] = scene_env.stats["captures"] - n0
    last = scene_env.current(mirror)
    r["gpu"]["again"] = {"route": last.route, "seconds": round(last.seconds, 4), "stages": {k: round(v, 4) for k, v in (last.stages or {}).items()}}
    prefs.get().scene_capture = "CYCLES"


def offscreen_at(ui, sc, mirror, red):
    """The preview drawn offscreen through the window's GPU context with the same view (draw_mirror),
    read at the red handle's pixel: the parallax-corrected and the centre-only lookups, and the
    edited direction e(q) there beside the constraint's own e_n."""
    import gpu
    from bpy_extras.view3d_utils import location_3d_to_region_2d

    draw = ui.addon("reflection.viewport.draw")
    glsl = ui.addon("reflection.viewport.glsl")
    mirror_state = ui.addon("reflection.mirror_state")
    region = ui.region("WINDOW")
    rv3d = region.data
    eye = tuple(rv3d.view_matrix.inverted().translation)
    rows = np.asarray(mirror_state.state_of(mirror).field_inputs[0])
    out = {"constraint_e": np.round(rows[0, 6:9], 4).tolist()}
    q = location_3d_to_region_2d(region, rv3d, red.matrix_world.translation)
    x, y = int(round(q.x)), int(round(q.y))
    off = gpu.types.GPUOffScreen(region.width, region.height, format="RGBA32F")
    try:
        with off.bind():
            fb = gpu.state.active_framebuffer_get()
            for key, kw in (("corrected", {}), ("centre", {"parallax": False}), ("direction", {"output": glsl.OUT_DIRECTION})):
                fb.clear(color=(0.0, 0.0, 0.0, 0.0), depth=1.0)
                draw.draw_mirror(mirror, sc, np.array(rv3d.perspective_matrix), eye, **kw)
                out[key] = [round(v, 4) for v in fb.read_color(x, y, 1, 1, 4, 0, "FLOAT").to_list()[0][0][:3]]
    finally:
        off.free()
    return out
