"""The GLSL recompositing path drawn through Blender's own gpu module (rokeby.compositing.blender_gpu,
Zubiaga et al. 2016): the same shader files and interface as the moderngl path, compiled by
GPUShaderCreateInfo and drawn offscreen (RGBA32F) in a fresh bpy process
(tests/compositing/recomposite_blender_gpu_check.py), against the Rust core on the frames of
tests/compositing/test_recomposite_glsl.py."""

from __future__ import annotations

import re

import pytest

pytest.importorskip("bpy")
pytest.importorskip("rokeby_native")

from support.bpy_process import run_check  # noqa: E402

# The module's one fresh bpy process (its GPU context, every frame drawn) took about 30 s on the
# shared 2-core machine.
pytestmark = pytest.mark.slow

OPTIONS = [{}, {"k_d": 0.7, "k_r": 1.3, "gamma": 2.2}, {"epsilon": 0.2}]


@pytest.fixture(scope="module")
def res():
    return run_check("compositing/recomposite_blender_gpu_check.py", timeout=900)


def test_without_a_gpu_context_the_error_says_what_to_do(res):
    """In background mode before anything has drawn, the gpu module cannot draw: the error says so
    and names the way out; ensure_context() makes the context and leaves the file's scenes as they were."""
    assert res["has_context_before"] is False
    msg = res["no_context_error"]
    assert msg and "no context" in msg and "ensure_context()" in msg and "backend='cpu'" in msg
    assert res["has_context_after"] is True and res["scenes_kept"] is True


def test_unmodified_normals_give_the_input_back_bit_for_bit(res):
    # Exact, not within rounding: the RGBA32F offscreen stores and returns float32 unchanged.
    idn = res["identity"]
    assert idn["equal_input"] and idn["equal_rust"], idn
    assert idn["shape"] == [96, 160, 3] and idn["dtype"] == "float32"
    assert idn["stats"] == idn["rust_stats"] == {"edited": 0, "masked": 0}


@pytest.mark.parametrize("k", range(len(OPTIONS)), ids=["defaults", "kd-kr-gamma", "epsilon"])
def test_multi_patch_frame_agrees_with_rust(res, k):
    f = res["frames"][k]
    assert f["opts"] == OPTIONS[k]
    assert f["stats"] == f["rust_stats"] and f["stats"]["edited"] > 4000 and f["stats"]["masked"] >= 2
    assert f["nan"] == f["rust_nan"] == 0
    # float32 shader vs the core, measured on llvmpipe: 2.6e-6, 2.0e-6, 2.1e-5 (ε = 0.2: the asin branch of v).
    print("Blender gpu vs Rust, max relative error:", f["rel"])
    assert f["rel"] < 1e-4, f
    assert f["changed"] > 3000
    assert f["untouched_equal"]  # background, ids beyond the list and the patch without data: I exactly
    assert f["repeat_equal"]  # the same frame again (new textures, kept offscreen) gives the same pixels


def test_same_pixels_as_the_moderngl_path_and_both_in_one_process(res):
    """One shader file, one interface: Blender's compile and moderngl's agree (bit for bit on llvmpipe
    here; the bound allows another driver's rounding). Making or using the moderngl path in the same
    process leaves Blender's GL context current: before that was ensured, Blender's next draw went to
    moderngl's context (once 0.26 relative off; after glcontext's own restore, which leaves no context,
    Blender's next texture upload aborted the process)."""
    m = res["moderngl"]
    if "error" in m:
        pytest.skip(f"no moderngl context: {m['error']}")
    print("Blender gpu vs moderngl: max relative difference", m["rel"], "bitwise equal", m["equal"])
    assert m["rel"] < 1e-6, m
    assert m["blender_context_current"] and m["blender_after_equal"], m


def test_constant_view_and_no_optional_buffers(res):
    c = res["constant_view"]
    assert c["stats"] == c["rust_stats"] and c["rel"] < 1e-4, c


def test_reconstructed_sphere_edited_by_emboss(res):
    s = res["sphere"]
    assert s["stats"] == s["rust_stats"] and s["stats"]["edited"] > 5000 and s["rel"] < 1e-4, s


def test_bad_inputs_are_named(res):
    assert len(res["bad"]) >= 14
    for b in res["bad"]:
        assert b["raised"] == "CompositingError" and b["compositing_error"], b
        assert re.search(b["msg"], b["text"]), b


def test_compositing_recomposite_backend_option(res):
    """compositing.recomposite(..., backend='blender_gpu') (what api.recomposite_render and the
    Render and Recomposite operator call) matches backend='cpu'; unknown backends are named."""
    b = res["backend"]
    assert b["stats"] == b["cpu_stats"] and b["stats"]["edited"] > 4000 and b["rel"] < 1e-4, b
    assert b["identity_equal"] and b["identity_stats"] == {"edited": 0, "masked": 0}
    assert b["unknown"].startswith("backend: unknown 'metal'")


def test_session_makes_only_the_edited_normals_texture_per_frame(res):
    """RecompositeSession(backend='blender_gpu'): every frame matches the CPU path; after the first
    frame Blender makes one texture per frame (the edited normals) instead of twelve, and again all
    twelve after another frame was drawn in between; the last frame (no edit) is I bit for bit."""
    s = res["session"]
    assert [f["made"] for f in s] == [12, 1, 12, 1]
    for f in s:
        assert f["rel"] < 1e-4 and f["stats"] == f["cpu_stats"]
    assert s[-1]["identity_equal"] and s[-1]["stats"]["edited"] == 0


def test_module_needs_no_gpu_at_import():
    """Importing rokeby.compositing.blender_gpu touches no gpu call (this pytest process may have no context)."""
    from rokeby.compositing import blender_gpu as G

    assert isinstance(G.has_context(), bool)
    assert G._BLENDER is None
