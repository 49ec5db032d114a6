"""The appearance preview's GLSL drawn outside Blender: an orthographic unit sphere filling a
square framebuffer, each pixel shaded by a fragment-shader body written against
shaders/rokeby_appearance_lib.glsl (moderngl on a headless EGL context; the test is skipped
where there is none). Shared by tests/appearance/test_appearance.py (environment-lit views) and
test_appearance_light.py (the point-light view)."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

SPHERE_FS = """
uniform vec3 u_base; uniform float u_spec; uniform float u_rough; uniform float u_metal;{uniforms}
out vec4 frag;
void main() {{
  vec2 p = (gl_FragCoord.xy / {size:.1f}) * 2.0 - 1.0;
  float rho2 = dot(p, p);
  if (rho2 >= 1.0) {{ frag = vec4(0.0); return; }}
  vec3 n = vec3(p.x, -sqrt(1.0 - rho2), p.y);
{body}
}}"""


def sphere_shader(body: str, uniforms: str = "", size: int = 48) -> SimpleNamespace:
    """Compiles the library plus a fragment shader whose ``main`` has the view-space sphere normal
    ``n`` (the camera looks along +y) and the painted parameters ``u_base``, ``u_spec``,
    ``u_rough``, ``u_metal`` (and ``uniforms``), then runs ``body``. The GGX albedo table is bound
    to unit 1, the environment atlas is expected on unit 0.

    Returns ``ctx``, ``prog``, ``vao`` (a fullscreen strip), ``fbo`` (``size``² RGBA32F), and the
    pixel grid: ``p`` (x, y in [-1, 1], row 0 = bottom, as glReadPixels), ``n`` (the sphere normal at
    each pixel) and ``inside`` (pixels well inside the disk)."""
    moderngl = pytest.importorskip("moderngl")
    from rokeby.appearance import glsl as appearance_glsl

    try:
        ctx = moderngl.create_context(standalone=True, backend="egl")
    except Exception as e:  # noqa: BLE001 - no EGL here
        pytest.skip(f"no headless EGL context: {e}")
    vs = "#version 330\nin vec2 pos; void main() { gl_Position = vec4(pos, 0.0, 1.0); }"
    fs = appearance_glsl.standalone_library() + SPHERE_FS.format(uniforms=uniforms, size=size, body=body)
    prog = ctx.program(vertex_shader=vs, fragment_shader=fs)
    assert prog["rk_appearance_block"].size == appearance_glsl.BLOCK_BYTES  # the driver's std140 layout
    lut = appearance_glsl.brdf_lut()
    lut_tex = ctx.texture(lut.shape[1::-1], 2, np.ascontiguousarray(lut).tobytes(), dtype="f4")
    lut_tex.use(1)
    prog["rk_brdf_lut"].value = 1
    prog["rk_env_atlas"].value = 0
    quad = ctx.buffer(np.array([-1, -1, 1, -1, -1, 1, 1, 1], "f4").tobytes())
    vao = ctx.vertex_array(prog, [(quad, "2f", "pos")])
    fbo = ctx.framebuffer(color_attachments=[ctx.texture((size, size), 4, dtype="f4")])
    ys, xs = np.mgrid[0:size, 0:size] + 0.5
    p = np.stack([xs / size * 2 - 1, ys / size * 2 - 1], -1)  # row 0 = bottom, as glReadPixels
    inside = (p**2).sum(-1) < 0.95
    n = np.stack([p[..., 0], -np.sqrt(np.maximum(1 - (p**2).sum(-1), 0)), p[..., 1]], -1)
    return SimpleNamespace(ctx=ctx, prog=prog, vao=vao, fbo=fbo, size=size, p=p, n=n, inside=inside)
