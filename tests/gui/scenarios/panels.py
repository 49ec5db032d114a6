"""Every Rokeby panel drawn at the default sidebar width, all of them open, with a mirror that has a
constraint (its status rows), appearance painting set up with the preview on (the Appearance rows),
and the redo panel of Set Up Appearance Painting run from F3 search: the texts cut on screen."""

import os
import sys

import bpy

sys.path.insert(0, os.path.dirname(__file__))
import textfit


def open_all_panels(prefix):
    """Registers the add-on's panels again without DEFAULT_CLOSED, so that each one draws (as a user
    opening each header would have them); parents first."""
    classes = [getattr(bpy.types, n) for n in dir(bpy.types) if n.startswith(prefix)]
    by_id = {getattr(c, "bl_idname", c.__name__): c for c in classes}

    def depth(c):
        d, p = 0, getattr(c, "bl_parent_id", "")
        while p:
            d, p = d + 1, getattr(by_id.get(p), "bl_parent_id", "")
        return d

    classes.sort(key=depth)
    for c in reversed(classes):
        bpy.utils.unregister_class(c)
    for c in classes:
        c.bl_options = set(c.bl_options) - {"DEFAULT_CLOSED"} if hasattr(c, "bl_options") else set()
        bpy.utils.register_class(c)
    return classes


def measure(ui, region, log, what):
    width = region.width - ui.result["margins_px"]
    cuts = {}
    for pid, tree in log.items():
        c = textfit.cut_texts(tree, width)
        if c:
            cuts[pid] = c
    ui.result.setdefault("cut", {}).update({f"{what}:{k}": v for k, v in cuts.items()})
    ui.result.setdefault("drawn", []).extend(f"{what}:{k}" for k in log)


def scenario(ui):
    yield from ui.start()
    api = ui.addon("api")
    scene = bpy.context.scene
    s = textfit.scale()
    # The panel's layout width is the sidebar's minus the tab strip and the panel margins.
    ui.result["margins_px"] = round(20 * s + 2 * 8 * s + 16 * s, 1)

    # A mirror (a smooth sphere) with one constraint, evaluated: the status rows.
    with ui.override():
        bpy.ops.mesh.primitive_uv_sphere_add(segments=48, ring_count=24, radius=1.0, location=(0, 0, 0))
        bpy.ops.object.shade_smooth()
    sphere = bpy.context.view_layer.objects.active
    sphere.name = "Mirror"
    mirror = api.add_mirror(sphere)
    api.add_constraint(mirror, (0.66, -0.62, 0.44), (3.0, -1.0, 2.0))
    api.evaluate(scene, force=True)

    classes = open_all_panels(textfit.PANEL_PREFIX)
    log = {}
    for c in classes:
        textfit.record(c, log)
    region = yield from ui.show_sidebar_tab("Rokeby")
    yield from ui.redraws(3)
    ui.result["region_width"] = region.width
    ui.screenshot("mirror-sidebar", crop=ui.region_box(region))
    measure(ui, region, log, "mirror")

    # Appearance painting on the cube, the preview on (the Brush sub-panel's preview rows).
    cube = bpy.data.objects["Cube"]
    for ob in bpy.context.view_layer.objects:
        ob.select_set(ob == cube)
    bpy.context.view_layer.objects.active = cube
    ui.addon("appearance").setup(cube)
    ui.addon("appearance.preview").enable(True)
    log.clear()
    yield from ui.redraws(3)
    ui.screenshot("appearance-sidebar", crop=ui.region_box(region))
    measure(ui, region, log, "appearance")

    # The redo panel of Set Up Appearance Painting, run as a user would: F3, its name, Return.
    x, y = ui.screen_xy(ui.region("WINDOW"), 400, 400)
    yield from ui.move(x, y)
    yield from ui.search(bpy.ops.rokeby.appearance_setup.get_rna_type().name, run=False)
    yield from ui.key("Return")
    hud = yield from ui.until(lambda: next((r for r in ui.area().regions if r.type == "HUD" and r.width > 1), None), 20, "the redo panel")
    yield from ui.redraws(3)
    style = bpy.context.preferences.ui_styles[0]
    title = bpy.ops.rokeby.appearance_setup.get_rna_type().name
    # The collapsed redo panel's title starts 24 px in and stops 8 px before the edge (measured).
    need = textfit.text_width(title, style.panel_title.points) + 32 * s
    ui.result["hud"] = {"title": title, "need": round(need, 1), "room": hud.width}
    # Every Rokeby operator with a redo panel gets the same collapsed title room.
    over = {}
    for name in dir(bpy.types):
        cls = getattr(bpy.types, name)
        idname = getattr(cls, "bl_idname", "")
        if not (isinstance(idname, str) and idname.startswith("rokeby.")) or "REGISTER" not in getattr(cls, "bl_options", set()):
            continue
        n = textfit.text_width(cls.bl_label, style.panel_title.points) + 32 * s
        if n > hud.width:
            over[cls.bl_label] = round(n, 1)
    ui.result["redo_titles_cut"] = over
    ui.screenshot("redo-panel", crop=(hud.x - 10, ui.window.height - hud.y - hud.height - 10, hud.width + 20, hud.height + 20))
