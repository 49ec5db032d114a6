"""Runs the viewport preview's GLSL (shaders/) outside Blender: moderngl on a headless EGL context
(Mesa llvmpipe on machines without a GPU). Shared by tests/reflection/test_glsl.py and bench/viewport.py.

The shader is compiled from rokeby.reflection.viewport.glsl.standalone_sources(), i.e. the same files the Blender
draw handler compiles; the field's inputs are packed by rokeby.reflection.viewport.glsl as in the add-on."""

from __future__ import annotations

import numpy as np

from rokeby.reflection.viewport import glsl


def look_at(eye, target, up=(0.0, 0.0, 1.0)) -> np.ndarray:
    eye, target, up = (np.asarray(a, np.float64) for a in (eye, target, up))
    f = target - eye
    f /= np.linalg.norm(f)
    s = np.cross(f, up)
    s /= np.linalg.norm(s)
    u = np.cross(s, f)
    m = np.eye(4)
    m[0, :3], m[1, :3], m[2, :3] = s, u, -f
    m[:3, 3] = -m[:3, :3] @ eye
    return m


def perspective(fov_y_deg: float, aspect: float, near: float, far: float) -> np.ndarray:
    t = 1.0 / np.tan(np.radians(fov_y_deg) / 2)
    m = np.zeros((4, 4))
    m[0, 0], m[1, 1] = t / aspect, t
    m[2, 2], m[2, 3] = (far + near) / (near - far), 2 * far * near / (near - far)
    m[3, 2] = -1.0
    return m


def create_context():
    import moderngl

    return moderngl.create_context(standalone=True, backend="egl")


class Renderer:
    """The preview program on an RGBA32F framebuffer of (width, height)."""

    def __init__(self, ctx, width: int, height: int):
        self.ctx = ctx
        self.width, self.height = width, height
        vs, fs = glsl.standalone_sources()
        self.program = ctx.program(vertex_shader=vs, fragment_shader=fs)
        self.fbo = ctx.framebuffer(color_attachments=[ctx.texture((width, height), 4, dtype="f4")], depth_attachment=ctx.depth_renderbuffer((width, height)))
        self.ubo = ctx.buffer(reserve=glsl.BLOCK_SIZE)
        self.program["rk_field_block"].binding = 0
        self.vao = None
        self.vertex_tex = None
        self.env_tex = None
        self.env_mode = glsl.ENV_SKY
        self.env_origin = None
        self._dummy = ctx.texture((1, 1), 4, np.zeros(4, np.float32).tobytes(), dtype="f4")

    def set_mesh(self, vertices, normals, triangles):
        soup = glsl.triangle_soup(vertices, normals, triangles)
        data = np.hstack([soup["rk_position"], soup["rk_normal"], soup["rk_vertex_ids"]]).astype("f4")
        self.vbo = self.ctx.buffer(data.tobytes())
        self.vao = self.ctx.vertex_array(self.program, [(self.vbo, "3f 3f 3f", "rk_position", "rk_normal", "rk_vertex_ids")])

    def set_plan(self, plan: glsl.FieldPlan):
        self.plan = plan
        h, w, _ = plan.vertex_data.shape
        self.vertex_tex = self.ctx.texture((w, h), 4, plan.vertex_data.tobytes(), dtype="f4")
        self.vertex_tex.filter = (self.ctx.NEAREST, self.ctx.NEAREST) if hasattr(self.ctx, "NEAREST") else self.vertex_tex.filter

    def set_environment(self, image):
        """image: (H, W, 3|4) float32, row 0 at the bottom (Blender's image convention)."""
        import moderngl

        img = np.asarray(image, np.float32)
        if img.shape[2] == 3:
            img = np.concatenate([img, np.ones(img.shape[:2] + (1,), np.float32)], axis=2)
        self.env_tex = self.ctx.texture((img.shape[1], img.shape[0]), 4, np.ascontiguousarray(img).tobytes(), dtype="f4")
        self.env_tex.filter = (moderngl.LINEAR, moderngl.LINEAR)
        self.env_tex.repeat_x, self.env_tex.repeat_y = True, False
        self.env_mode, self.env_origin = glsl.ENV_IMAGE, None

    def set_scene_capture(self, texels, origin):
        """texels: (H, W, 4) float32 lat-long, linear RGB and 1/distance from ``origin`` (0 for the
        world), row 0 at the bottom: the scene captured from the mirror (ENV_SCENE)."""
        img = np.ascontiguousarray(texels, np.float32)
        self.env_tex = self.ctx.texture((img.shape[1], img.shape[0]), 4, img.tobytes(), dtype="f4")
        self.env_mode, self.env_origin = glsl.ENV_SCENE, tuple(map(float, origin))

    def render(self, view_projection, eye, output=glsl.OUT_DIRECTION, *, srgb=False, finish=True, parallax=True) -> np.ndarray | None:
        """One frame; returns (H, W, 4) float32 with row 0 at the top, alpha 0 where no mirror."""
        self.ubo.write(glsl.pack_field(self.plan, eye, output=output, env=self.env_mode, env_origin=self.env_origin, parallax=parallax, srgb=srgb))
        self.ubo.bind_to_uniform_block(0)
        (self.vertex_tex or self._dummy).use(0)
        (self.env_tex or self._dummy).use(1)
        self._dummy.use(2)
        for name, unit in (("rk_vertex_data", 0), ("rk_env", 1), ("rk_world", 2)):
            if name in self.program:
                self.program[name].value = unit
        self.program["rk_view_projection"].write(np.asarray(view_projection, "f4").T.tobytes())
        if "rk_depth_bias" in self.program:
            self.program["rk_depth_bias"].value = 0.0
        self.fbo.use()
        self.fbo.clear(0.0, 0.0, 0.0, 0.0, depth=1.0)
        import moderngl

        self.ctx.enable(moderngl.DEPTH_TEST)
        self.vao.render(moderngl.TRIANGLES)
        if not finish:
            return None
        raw = self.fbo.read(components=4, dtype="f4")
        return np.frombuffer(raw, np.float32).reshape(self.height, self.width, 4)[::-1].copy()
