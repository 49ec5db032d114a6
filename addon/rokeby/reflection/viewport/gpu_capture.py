"""The scene around a mirror captured on the GPU, as the 3D view draws it (the paper's per-object
cube map, §6.3): six 90° views from the capture point, each drawn by Blender itself
(``GPUOffScreen.draw_view3d``), plus a distance
pass of Rokeby's own (``shaders/rokeby_distance_*.glsl``: |x - c| of the nearest surface), then
resampled to the lat-long panorama the preview shader looks up (``cube_to_latlong``). The mirror is
hidden while it is drawn and the overlays (handles, grid) are off; nothing is written to the file.
The views are drawn in the 3D view's Solid shading (its lighting and colour settings; materials
show their Viewport Display colour) whatever the view shows: Material Preview's EEVEE compiles
materials in the background and leaves an object out until its shader is ready, so a capture
taken then would miss objects for good.

It is the fast route where a window exists (tens of milliseconds on a software renderer, where a
Cycles capture takes tenths of seconds to seconds); its colours are the viewport's, not F12's, so
the preview's per-pixel agreement with Cycles belongs to the Cycles capture (``scene_env``), the
default. The add-on preferences choose (*Scene Capture*).

The maths (face views, resampling) is bpy-free and tested without Blender.
"""

from __future__ import annotations

import numpy as np

from ...core import latlong

# Each face: (forward, up). The view looks along forward; right = forward × up.
FACES = (
    ((1.0, 0.0, 0.0), (0.0, 0.0, 1.0)),
    ((-1.0, 0.0, 0.0), (0.0, 0.0, 1.0)),
    ((0.0, 1.0, 0.0), (0.0, 0.0, 1.0)),
    ((0.0, -1.0, 0.0), (0.0, 0.0, 1.0)),
    ((0.0, 0.0, 1.0), (0.0, 1.0, 0.0)),
    ((0.0, 0.0, -1.0), (0.0, 1.0, 0.0)),
)

DISTANCE_FILES = {"types": None, "lib": None, "vertex": "rokeby_distance_vert.glsl", "fragment": "rokeby_distance_frag.glsl"}
DISTANCE_INTERFACE = {
    "vertex_in": [(0, "VEC3", "rk_position")],
    "vertex_out": [("smooth", "VEC3", "rk_v_world")],
    "push_constant": [("MAT4", "rk_view_projection"), ("VEC3", "rk_capture_origin")],
    "sampler": [],
    "uniform_buf": [],
    "fragment_out": [(0, "VEC4", "rk_out")],
}
DISTANCE_INTERFACE_NAME = "rokeby_distance_iface"

CAPTURING = [False]  # True while the six views are drawn: the preview's draw handler stays out


def face_rotations() -> np.ndarray:
    """(6, 3, 3): each face's world -> view rotation (rows: right, up, back), as OpenGL looks down -z."""
    out = np.empty((6, 3, 3))
    for i, (f, u) in enumerate(FACES):
        f, u = np.asarray(f), np.asarray(u)
        out[i] = (np.cross(f, u), u, -f)
    return out


def face_matrices(origin, near: float, far: float) -> tuple:
    """(views (6, 4, 4), projection (4, 4)): world -> view of each face from ``origin``, and the
    square 90° perspective projection (OpenGL clip space) they share."""
    rot = face_rotations()
    views = np.zeros((6, 4, 4))
    views[:, :3, :3] = rot
    views[:, :3, 3] = -rot @ np.asarray(origin, np.float64)
    views[:, 3, 3] = 1.0
    proj = np.array([[1.0, 0.0, 0.0, 0.0], [0.0, 1.0, 0.0, 0.0],
                     [0.0, 0.0, -(far + near) / (far - near), -2.0 * far * near / (far - near)], [0.0, 0.0, -1.0, 0.0]])
    return views, proj


def latlong_directions(width: int) -> np.ndarray:
    """(width / 2, width, 3) unit directions of a lat-long panorama's texel centres (Blender's
    convention, ``rokeby.core.latlong``; row 0 at the bottom)."""
    h = width // 2
    u, v = np.meshgrid((np.arange(width) + 0.5) / width, (np.arange(h) + 0.5) / h)
    return latlong.uv_to_direction(u, v)


def cube_to_latlong(faces: np.ndarray, width: int, *, nearest_channels: tuple = ()) -> np.ndarray:
    """Resample six face images ``faces`` (6, S, S, C) (row 0 at the bottom, as OpenGL reads them
    back; views of ``face_matrices``) to a lat-long panorama (width / 2, width, C). Channels are
    filtered bilinearly, except ``nearest_channels`` (a distance must not be averaged across an
    object's outline)."""
    faces = np.asarray(faces)
    n, s = faces.shape[0], faces.shape[1]
    if faces.ndim != 4 or n != 6 or faces.shape[2] != s:
        raise ValueError(f"faces: expected (6, S, S, C), got {faces.shape}")
    if width < 4 or width % 2:
        raise ValueError(f"width: expected an even number >= 4, got {width}")
    d = latlong_directions(width).reshape(-1, 3)
    rot = face_rotations()
    forward = -rot[:, 2, :]  # (6, 3)
    face = np.argmax(d @ forward.T, axis=1)
    pv = np.einsum("nij,nj->ni", rot[face], d)
    depth = -pv[:, 2]  # > 0: the chosen face looks most directly at d
    x = (pv[:, 0] / depth * 0.5 + 0.5) * s - 0.5
    y = (pv[:, 1] / depth * 0.5 + 0.5) * s - 0.5
    x0 = np.clip(np.floor(x).astype(np.int64), 0, s - 1)
    y0 = np.clip(np.floor(y).astype(np.int64), 0, s - 1)
    x1 = np.minimum(x0 + 1, s - 1)
    y1 = np.minimum(y0 + 1, s - 1)
    fx = np.clip(x - x0, 0.0, 1.0)[:, None]
    fy = np.clip(y - y0, 0.0, 1.0)[:, None]
    out = (faces[face, y0, x0] * (1 - fx) * (1 - fy) + faces[face, y0, x1] * fx * (1 - fy)
           + faces[face, y1, x0] * (1 - fx) * fy + faces[face, y1, x1] * fx * fy)
    if nearest_channels:
        xn = np.clip(np.rint(x).astype(np.int64), 0, s - 1)
        yn = np.clip(np.rint(y).astype(np.int64), 0, s - 1)
        ch = list(nearest_channels)
        out[:, ch] = faces[face, yn, xn][:, ch]
    return out.reshape(width // 2, width, faces.shape[3]).astype(np.float32)


# --- in Blender --------------------------------------------------------------------------------


def view_of(scene):
    """(window, area, space, region) of the largest 3D view showing ``scene``, or None."""
    import bpy  # noqa: PLC0415

    best = None
    for window in getattr(getattr(bpy.context, "window_manager", None), "windows", []):
        if window.scene != scene:
            continue
        for area in window.screen.areas:
            if area.type != "VIEW_3D":
                continue
            region = next((r for r in area.regions if r.type == "WINDOW"), None)
            if region is not None and (best is None or area.width * area.height > best[1].width * best[1].height):
                best = (window, area, area.spaces.active, region)
    return best


def look_of(space) -> str:
    """What the capture's colours depend on in the view ``space``: its Solid shading settings ("" while
    the view shows another shading: Blender answers its settings for that one)."""
    sh = space.shading
    if sh.type != "SOLID":
        return ""
    return "|".join(str(getattr(sh, a, "")) for a in ("light", "color_type", "single_color", "background_type",
                                                      "background_color", "studio_light", "studiolight_intensity",
                                                      "use_scene_lights", "use_scene_world", "show_cavity", "show_shadows"))


_shader = None


def _distance_shader():
    global _shader
    if _shader is None:
        from ...blender.gpu import create_shader  # noqa: PLC0415
        from ...core.shaders import shader_dir  # noqa: PLC0415

        d = shader_dir()
        src = {"types": "", "lib": "", "vertex": (d / DISTANCE_FILES["vertex"]).read_text(),
               "fragment": (d / DISTANCE_FILES["fragment"]).read_text()}
        _shader = create_shader(DISTANCE_INTERFACE, DISTANCE_INTERFACE_NAME, src)
    return _shader


def scene_triangles(depsgraph, skip) -> np.ndarray:
    """(T * 3, 3) float32 world-space corners of every triangle the viewport shows (evaluated mesh
    data of each visible instance), leaving out the object ``skip`` (the mirror)."""
    parts = []
    for inst in depsgraph.object_instances:
        ob = inst.object
        if ob.original == skip or ob.type not in {"MESH", "CURVE", "SURFACE", "FONT", "META"}:
            continue
        try:
            me = ob.data if ob.type == "MESH" else ob.to_mesh()
        except RuntimeError:
            continue
        if me is None:
            continue
        try:
            n_v, n_t = len(me.vertices), len(me.loop_triangles)
            if not (n_v and n_t):
                continue
            co = np.empty(n_v * 3, np.float32)
            me.vertices.foreach_get("co", co)
            tri = np.empty(n_t * 3, np.int32)
            me.loop_triangles.foreach_get("vertices", tri)
        finally:
            if ob.type != "MESH":
                ob.to_mesh_clear()
        m = np.array(inst.matrix_world, np.float64)
        world = co.reshape(-1, 3) @ m[:3, :3].T + m[:3, 3]
        parts.append(world[tri].astype(np.float32))
    return np.concatenate(parts) if parts else np.zeros((0, 3), np.float32)


def capture(mirror, scene, origin, width: int, *, size: int | None = None, view=None) -> tuple:
    """Capture the scene around ``mirror`` from ``origin`` on the GPU, as the 3D view ``view``
    ((window, area, space, region); default: ``view_of(scene)``) draws it. Returns (colour
    (width / 2, width, 3) linear RGB, distance (width / 2, width) with inf where nothing was drawn,
    seconds per stage, the view's Solid shading settings it was drawn with (``look_of``)). Raises
    LookupError without a 3D view (background mode)."""
    import time  # noqa: PLC0415

    import bpy  # noqa: PLC0415
    import gpu  # noqa: PLC0415
    from gpu_extras.batch import batch_for_shader  # noqa: PLC0415
    from mathutils import Matrix  # noqa: PLC0415

    from .. import guard  # noqa: PLC0415

    view = view or view_of(scene)
    if view is None:
        raise LookupError("no 3D view shows the scene: the GPU capture needs a window")
    window, _area, space, region = view
    size = size or max(16, width // 2)
    radius = max(float(max(mirror.dimensions)) * 0.5, 1e-4)
    near, far = 1e-3 * radius, 1e6 * radius
    views, proj = face_matrices(origin, near, far)
    times = {}
    colour = np.empty((6, size, size, 4), np.float32)
    distance = np.empty((6, size, size, 1), np.float32)
    view_layer = window.view_layer
    was_hidden = mirror.hide_get(view_layer=view_layer)
    overlays = space.overlay.show_overlays
    shading = space.shading.type
    off = None
    with guard.suspended():
        CAPTURING[0] = True
        try:
            t0 = time.perf_counter()
            mirror.hide_set(True, view_layer=view_layer)
            space.overlay.show_overlays = False
            space.shading.type = "SOLID"
            look = look_of(space)
            view_layer.update()
            dg = bpy.context.evaluated_depsgraph_get()
            off = gpu.types.GPUOffScreen(size, size, format="RGBA32F")
            pm = Matrix(proj.tolist())
            t1 = time.perf_counter()
            for i in range(6):
                off.draw_view3d(scene, view_layer, space, region, Matrix(views[i].tolist()), pm, do_color_management=False)
                buf = off.texture_color.read()
                buf.dimensions = size * size * 4
                colour[i] = np.array(buf, np.float32).reshape(size, size, 4)
            t2 = time.perf_counter()
            corners = scene_triangles(dg, mirror)
            t3 = time.perf_counter()
            sh = _distance_shader()
            batch = batch_for_shader(sh, "TRIS", {"rk_position": corners}) if len(corners) else None
            with off.bind():
                fb = gpu.state.active_framebuffer_get()
                gpu.state.depth_test_set("LESS_EQUAL")
                gpu.state.depth_mask_set(True)
                try:
                    for i in range(6):
                        fb.clear(color=(0.0, 0.0, 0.0, 0.0), depth=1.0)
                        if batch is not None:
                            sh.bind()
                            sh.uniform_float("rk_view_projection", Matrix((proj @ views[i]).tolist()))
                            sh.uniform_float("rk_capture_origin", tuple(float(v) for v in origin))
                            batch.draw(sh)
                        buf = fb.read_color(0, 0, size, size, 4, 0, "FLOAT")
                        buf.dimensions = size * size * 4
                        distance[i, ..., 0] = np.array(buf, np.float32).reshape(size, size, 4)[..., 0]
                finally:
                    gpu.state.depth_mask_set(False)
                    gpu.state.depth_test_set("NONE")
            t4 = time.perf_counter()
        finally:
            if off is not None:
                off.free()
            space.overlay.show_overlays = overlays
            space.shading.type = shading
            mirror.hide_set(was_hidden, view_layer=view_layer)
            view_layer.update()
            CAPTURING[0] = False
    faces = np.concatenate([colour[..., :3], distance], axis=-1)
    pano = cube_to_latlong(faces, width, nearest_channels=(3,))
    t5 = time.perf_counter()
    times.update(views=t2 - t1, triangles=t3 - t2, distance=t4 - t3, resample=t5 - t4, total=t5 - t0)
    dist = np.where(pano[..., 3] > 0, pano[..., 3], np.inf).astype(np.float32)
    return np.ascontiguousarray(pano[..., :3]), dist, times, look
