"""Shape editing at the compositing stage: reconstruction and recompositing."""

from __future__ import annotations

import json
import os
import subprocess
import tempfile
import sys
from pathlib import Path


from common import ROOT, against_goal  # noqa: E402


COMPOSITING_MARKER = "## Compositing-stage shape editing: "


def compositing_section(emit):
    """reconstruction stages and recompositing (bench/compositing.py in fresh processes,
    on 1 thread like the paper's single core, and on all threads)."""
    runs = {}
    with tempfile.TemporaryDirectory() as tmp:
        for threads in (1, os.cpu_count()):
            out = Path(tmp) / f"comp{threads}.json"
            env = dict(os.environ, RAYON_NUM_THREADS=str(threads))
            subprocess.run([sys.executable, str(ROOT / "bench" / "compositing.py"), "--json", str(out)], check=True, stdout=subprocess.DEVNULL, env=env)
            runs[threads] = json.loads(out.read_text())
        # The goal is stated on 2 threads: the per-edit times once more on exactly 2.
        edit_json = Path(tmp) / "edit2.json"
        subprocess.run([sys.executable, str(ROOT / "bench" / "compositing.py"), "--edit-only", "--json", str(edit_json)], check=True,
                       stdout=subprocess.DEVNULL, env=dict(os.environ, RAYON_NUM_THREADS="2"))
        edit2 = json.loads(edit_json.read_text())["edit"]
        loop_json = Path(tmp) / "loop.json"
        loop_run = subprocess.run([sys.executable, str(ROOT / "bench" / "composite_edit_loop.py"), "--json", str(loop_json)],
                                  stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
        edit_loop = json.loads(loop_json.read_text()) if loop_run.returncode == 0 else {"error": loop_run.stderr[-400:]}
    one, many = runs[1], runs[os.cpu_count()]
    emit(COMPOSITING_MARKER + "reconstruction stages and recompositing (Zubiaga et al. 2016)")
    emit()
    emit("Synthetic, exact inputs (bench/compositing.py): an orthographic sphere of the given width whose normals")
    emit("carry a procedural bump (the Gauss map folds, sheets overlap), shaded by a known order-2 SH diffuse")
    emit("environment with 20% of pixels darkened by half (occlusion) plus noise, and a known reflection environment.")
    emit("Medians of 3 runs; `1 thr` = RAYON_NUM_THREADS=1 (the paper's single core), `N thr` = all cores.")
    emit("The paper's single-core i7-4790K timings (Table 1; its image sizes are not given): diffuse 14-184 ms,")
    emit("partial reflection 26-470 ms, hole filling 192-6000 ms. Goal: a tenth of those on this machine.")
    emit()
    emit("| patch | pixels | map | diffuse LS (ms) 1 thr / N thr | diffuse QP (ms) 1 thr / N thr | partial refl. (ms) 1 thr / N thr | hole texels | hole filling (ms) 1 thr / N thr | blur (ms) | coverage |")
    emit("|---|---:|---:|---|---|---|---:|---|---:|---:|")
    for a, b in zip(one["stages"], many["stages"]):
        emit(f"| {a['width']}² {a['region']} | {a['pixels']:,} | 2x{a['env_size']}² | {a['diffuse_ls_ms']:.1f} / {b['diffuse_ls_ms']:.1f} | {a['diffuse_qp_ms']:.1f} / {b['diffuse_qp_ms']:.1f} | "
             f"{a['partial_ms']:.0f} / {b['partial_ms']:.0f} | {a['hole_texels']:,} | {a['fill_ms']:.1f} / {b['fill_ms']:.1f} | {b['blur_ms']:.1f} | {a['coverage']:.0%} |")
    emit()
    emit("Diffuse fit against the true (unoccluded) environment, relative RMS over the sphere, and the largest")
    emit("residual D0 - D(n) (the QP's constraint: never positive):")
    emit()
    emit("| patch | LS rel. RMS | QP rel. RMS | LS max residual | QP max residual | QP active-set steps (R, G, B) | reflection map mean abs. error |")
    emit("|---|---:|---:|---:|---:|---|---:|")
    for a in one["stages"]:
        emit(f"| {a['width']}² {a['region']}, map 2x{a['env_size']}² | {a['diffuse_ls_rel_rms']:.3f} | {a['diffuse_qp_rel_rms']:.3f} | {a['ls_max_residual']:.3f} | {a['qp_max_residual']:.1e} | {', '.join(map(str, a['qp_iterations']))} | {a['reflection_mean_abs_err']:.4f} |")
    emit()
    r1, rn_ = one["recomposite"], many["recomposite"]
    emit(f"Recompositing (eqs. 3-5), {r1['width']}x{r1['height']}, {r1['patches']} patches (SH + 2x{r1['env_size']}² map each),")
    emit(f"{r1['edited_fraction']:.0%} of the pixels edited: {r1['recomposite_ms']:.0f} ms on 1 thread, {rn_['recomposite_ms']:.0f} ms on {os.cpu_count()};")
    emit(f"unmodified normals (every pixel takes the exact-identity path): {rn_['recomposite_identity_ms']:.0f} ms. Goal: under 33 ms.")
    emit()
    emit("Per edit of that frame with the passes held in Rust (rokeby_native.compositing.Recompositor: only ñ passed, read in")
    emit("place, the result written into the same buffer, overflow checked in the kernel's store), against the same session")
    emit("keeping per pixel unit n and v, the validity and eq. 5's subtracted term (prepared=True; off by default: no faster")
    emit("on a quiet machine) and the one-shot path in the same run (rokeby_native.compositing.recomposite converting the passes and")
    emit("patches again, a new image, then the add-on's pass over it for non-finite pixels); medians of alternating runs.")
    emit("Memory-bound estimate: the bytes an edit must move (every pixel's ids, n, ñ, I read and I~ written; the edited")
    emit("pixels' D0, R0, c_D, c_R, α's) at the bandwidth of a 32 MB numpy copy measured in the same process.")
    emit()
    emit("| threads | per edit (ms) | goal (ms) | with the terms (ms) | one-shot path (ms) | session / one-shot | memory bound (ms) | same bits |")
    emit("|---|---:|---:|---:|---:|---:|---:|---|")
    rows = [("1", r1), ("2", edit2)] + ([(str(os.cpu_count()), rn_)] if os.cpu_count() not in (1, 2) else [])
    for label, r in rows:
        if "edit_ms" in r:
            emit(f"| {label} | **{r['edit_ms']:.1f}** ({r['edit_runs']} runs) | {r['edit_goal_ms']:.0f} (on 2) | {r['edit_prepared_ms']:.1f} | {r['edit_old_ms']:.1f} | "
                 f"{r['edit_ms'] / r['edit_old_ms']:.2f} | {r['edit_memory_bound_ms']:.1f} ({r['edit_bytes_mb']:.0f} MB at {r['bandwidth_gbs']:.1f} GB/s) | {r['edit_same_bits']} |")
    if "edit_ms" in edit2:  # goal: recompositing a 1080p edit in at most 8 ms on 2 threads
        emit()
        emit(f"Per edit on 2 threads: {against_goal(edit2['edit_ms'], edit2['edit_goal_ms'], 'ms')}.")
    if "prepared_mb" in edit2:
        emit()
        emit(f"The per-pixel terms take {edit2['prepared_mb']:.0f} MB for the frame; making the session takes {edit2['make_prepared_ms']:.0f} ms with them, "
             f"{edit2['make_ms']:.0f} ms without (2 threads).")
    if "glsl_ms" in rn_:
        emit(f"GLSL path (shaders/rokeby_recomposite_frag.glsl, moderngl/EGL on {rn_['glsl_renderer']}; no GPU lent), same frame with uploads and")
        emit(f"read-back: {rn_['glsl_ms']:.0f} ms per frame; largest difference from the Rust core {rn_['glsl_max_rel_diff']:.1e} relative (float32 shader).")
        if "glsl_session_ms" in rn_:
            emit(f"The next frame of an interactive session (RecompositeSession: only the edited normals written): "
                 f"{rn_['glsl_session_ms']:.0f} ms; the draw and read-back alone: {rn_['glsl_draw_only_ms']:.0f} ms (llvmpipe's shading).")
    else:
        emit(f"GLSL path not measured: {rn_.get('glsl_error', 'no result')}.")
    emit(f"Peak memory of the benchmark process after it: {rn_['peak_rss_mb']:.0f} MB ({rn_['inputs_mb']:.0f} MB of it the float32 input buffers).")
    emit()
    emit("*Recomposite Render*'s loop (bench/composite_edit_loop.py: `api.recomposite_exr` on a Cycles frame with three")
    emit("objects and the passes, in bpy): the first edit of the file reads and reconstructs it; each further edit of the")
    emit("same frame (one change in the operator's redo panel) costs the normal edit, eqs. 3-5 and writing the Blender image.")
    if "error" in edit_loop:
        emit(f"Not measured: {edit_loop['error']}")
    else:
        emit()
        emit("| backend | frame | first edit (open) | next edit: normals | eqs. 3-5 | image | total |")
        emit("|---|---|---:|---:|---:|---:|---:|")
        for key, label in (("cpu", "CPU (Rust)"), ("blender_gpu", f"Blender gpu ({edit_loop.get('renderer', '?')})")):
            r = edit_loop.get(key)
            if r is None:
                emit(f"| {label} | not measured: {edit_loop.get(key + '_error', '?')} | | | | | |")
                continue
            emit(f"| {label} | {edit_loop['width']}x{edit_loop['height']}, {r['edited']:,} px edited | {r['first_ms']:.0f} ms ({r['first_open_ms']:.0f}) "
                 f"| {r['edit_ms']:.1f} ms | {r['recomposite_ms']:.0f} ms | {r['show_ms']:.0f} ms | {r['total_ms']:.0f} ms |")
    emit()
    emit(f"Load average at the end: {os.getloadavg()[0]:.1f} on {os.cpu_count()} CPUs (other jobs shared the machine).")
    emit()
