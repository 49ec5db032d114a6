"""`make demo`: the Rokeby Venus, rendered with Cycles before and after a reflection edit.

Builds the scene from code (rokeby.demo_scene): a figure (homer.obj from the shared meshes,
imported with Blender's OBJ importer) in front of a framed chrome mirror that, physically, shows
the figure's body. One constraint and one region make the mirror show the face instead ("the
mirror should reflect the face, not the body", Fig. 9a of Ritschel et al. 2009). Renders both
with Cycles on the CPU and writes out/demo/before.png, after.png and side_by_side.png.

    python -m rokeby.demo [--out out/demo] [--width 640 --height 360 --samples 24] [--shared PATH]
    python -m rokeby.demo --field [--mesh spot.obj]   # the field on a real mesh, in the terminal
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

import numpy as np


def _shared_dir(arg: str | None) -> Path:
    if arg:
        return Path(arg)
    if os.environ.get("ROKEBY_SHARED"):
        return Path(os.environ["ROKEBY_SHARED"])
    return Path(__file__).resolve().parents[3] / "shared"


def sphere_gbuffer(width: int, height: int, eye=(0.0, -3.0, 0.0), radius: float = 1.0):
    """A G-buffer (positions, normals, mask) of a unit mirror sphere at the origin seen from `eye`
    with a 40° pinhole camera looking at the origin; computed analytically with numpy."""
    eye = np.asarray(eye, np.float64)
    fwd = -eye / np.linalg.norm(eye)
    right = np.cross(fwd, [0.0, 0.0, 1.0])
    right /= np.linalg.norm(right)
    up = np.cross(right, fwd)
    t = np.tan(np.radians(20.0))
    xs = (np.arange(width) + 0.5) / width * 2 - 1
    ys = 1 - (np.arange(height) + 0.5) / height * 2
    dx, dy = np.meshgrid(xs * t * width / height, ys * t)
    d = fwd + dx[..., None] * right + dy[..., None] * up
    d /= np.linalg.norm(d, axis=-1, keepdims=True)
    b = d @ eye
    c = eye @ eye - radius * radius
    disc = b * b - c
    mask = disc > 0
    s = -b - np.sqrt(np.where(mask, disc, 0.0))
    pos = eye + s[..., None] * d
    nrm = pos / radius
    pos[~mask] = 0.0
    nrm[~mask] = (0.0, 0.0, 1.0)
    return pos.astype(np.float32), nrm.astype(np.float32), mask


def _bar(fraction: float, width: int = 30) -> str:
    n = int(round(fraction * width))
    return "#" * n + "." * (width - n)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--shared", default=None, help="the shared folder (default ../shared or $ROKEBY_SHARED)")
    ap.add_argument("--out", default="out/demo", help="where the pictures go (default out/demo)")
    ap.add_argument("--width", type=int, default=640)
    ap.add_argument("--height", type=int, default=360)
    ap.add_argument("--samples", type=int, default=24, help="Cycles samples per pixel (denoised)")
    ap.add_argument("--field", action="store_true", help="instead: the field on a real mesh, explained in the terminal")
    ap.add_argument("--mesh", default="spot.obj", help="with --field: file in <shared>/meshes (default spot.obj)")
    args = ap.parse_args(argv)
    if args.field:
        return field_tour(args)
    return venus(args)


def venus(args) -> int:
    """The Rokeby Venus: render before and after the edit, compose them, say what happened."""
    import bpy

    import rokeby

    from . import demo_scene as ds
    from .core import native

    shared = _shared_dir(args.shared)
    if not (shared / "meshes" / "homer.obj").exists():
        print(f"rokeby demo: {shared / 'meshes' / 'homer.obj'} not found (use --shared or ROKEBY_SHARED)", file=sys.stderr)
        return 2
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    t_start = time.perf_counter()
    print("Rokeby — the Rokeby Venus: the mirror should reflect the face, not the body (Ritschel et al. 2009, Fig. 9a)")
    print(f"Blender {bpy.app.version_string} (bpy, background), rokeby_native {native.version()}\n")
    demo = ds.build(shared, width=args.width, height=args.height, samples=args.samples)
    rokeby.register()
    sc = bpy.context.scene
    print(f"Scene: {demo.figure.name} (homer.obj, {len(demo.figure.data.vertices):,} vertices, {ds.FIGURE_HEIGHT} m tall) in front of a")
    print(f"  {demo.glass_size[0]} x {demo.glass_size[1]} m framed chrome mirror ('{demo.mirror.name}', {len(demo.mirror.data.vertices)} vertices), turned so that")
    print(f"  the camera sees the body in it; Cycles on the CPU, {args.width}x{args.height}, {args.samples} samples (denoised), seed {sc.cycles.seed}")

    def seen(view):
        return f"face {view['face'] * 100:3.0f}%, body {view['body'] * 100:3.0f}%, other {view['other'] * 100:3.0f}% of the glass; its centre sees the {view['centre_sees']} at {view['centre_height']:.2f} m"

    phys = ds.glass_view(demo, edited=False)
    print(f"\nPhysically (reflected rays cast from the camera): {seen(phys)}")
    t_before = ds.render(out / "before.png")
    print(f"  rendered {out / 'before.png'} in {t_before:.1f} s")

    info = ds.edit(demo)
    rep = info["report"]
    print("\nThe edit, through rokeby.api as the sidebar's operators do it:")
    print(f"  add_mirror('{demo.mirror.name}'); add_constraint at the glass's centre: red handle there, green handle on the physical")
    print(f"    reflection at {np.round(info['green_from'], 2).tolist()} (the body), dragged to {np.round(info['green_to'], 2).tolist()} (the face)")
    print(f"  add_region EUCLIDEAN around the glass, radius {info['radius']:.2f} m (constraints act only inside it)")
    print(f"  evaluate: {rep.status}, {rep.constraints_used} constraint, {rep.vertices} vertices, reflections turn by up to {np.degrees(api_turn(demo)):.1f} deg")
    print(f"  install_render_nodes: the node group feeds the edited normal to {info['wired']} BSDF input(s)")
    edited = ds.glass_view(demo, edited=True)
    print(f"Edited (the same rays, turned by the field):     {seen(edited)}")
    t_after = ds.render(out / "after.png")
    print(f"  rendered {out / 'after.png'} in {t_after:.1f} s")
    size = ds.side_by_side(out / "before.png", out / "after.png", out / "side_by_side.png",
                           ("Physical mirror: it shows the body", "Rokeby edit (1 constraint, 1 region): the face"))
    print(f"\nWrote {out / 'side_by_side.png'} ({size[0]}x{size[1]}) in {time.perf_counter() - t_start:.0f} s in all.")
    if not (edited["face"] > phys["face"] and edited["centre_sees"] == "face" and phys["centre_sees"] == "body"):
        print("rokeby demo: the edit did not move the reflection from the body to the face", file=sys.stderr)
        return 1
    print("Install the add-on in Blender from dist/rokeby-<version>.zip (Edit > Preferences > Get Extensions > Install from Disk);")
    print("`python -m rokeby.demo --field` explains the field on a real mesh in the terminal.")
    return 0


def api_turn(demo) -> float:
    """The largest turn of the mirror's field (radians)."""
    from . import api

    return float(api.quat_angle(api.field(demo.mirror)).max())


def field_tour(args) -> int:
    import bpy

    from . import api
    from .core import native

    path = _shared_dir(args.shared) / "meshes" / args.mesh
    if not path.exists():
        print(f"rokeby demo: mesh {path} not found (use --shared or ROKEBY_SHARED)", file=sys.stderr)
        return 2

    print("Rokeby — the reflection-rotation field of Ritschel et al. 2009 on a real mesh")
    print(f"Blender {bpy.app.version_string} (bpy, background), rokeby_native {native.version()}\n")

    bpy.ops.wm.read_factory_settings(use_empty=True)
    bpy.ops.wm.obj_import(filepath=str(path), forward_axis="NEGATIVE_Z", up_axis="Y")
    mirror = bpy.context.selected_objects[0]
    mirror.name = "Mirror"
    m = api.mesh_arrays(mirror)
    lo, hi = m.vertices.min(0), m.vertices.max(0)
    size = float(np.linalg.norm(hi - lo))
    centre = (lo + hi) / 2
    print(f"Mirror: {path.name}, {len(m.vertices):,} vertices, {len(m.triangles):,} triangles, {size:.2f} units across")

    # The generating view: in front of the mesh (Blender's -Y is the front view), a little above.
    eye = centre + np.array([0.0, -2.0 * size, 0.3 * size])
    facing = np.einsum("ij,ij->i", m.normals, (eye - m.vertices) / np.linalg.norm(eye - m.vertices, axis=1, keepdims=True))
    visible = np.flatnonzero(facing > 0.6)
    rng = np.random.default_rng(7)
    picks = rng.choice(visible, 3, replace=False)

    # "The mirror should reflect the face, not the body": each red handle gets a green handle
    # away from where the physical reflection goes (turned by 20-35 degrees).
    rows, turns = [], []
    for k, i in enumerate(picks):
        p, n = m.vertices[i], m.normals[i]
        phys = api.physical_reflected_point(p, n, eye, size)
        r = (phys - p) / np.linalg.norm(phys - p)
        axis = np.cross(r, [0.0, 0.0, 1.0]) if abs(r[2]) < 0.9 else np.cross(r, [1.0, 0.0, 0.0])
        axis /= np.linalg.norm(axis)
        ang = np.radians(20 + 7.5 * k)
        e = r * np.cos(ang) + np.cross(axis, r) * np.sin(ang) + axis * (axis @ r) * (1 - np.cos(ang))
        green = p + size * e
        rows.append(api.constraint_row(p, n, green, eye))
        turns.append(np.degrees(ang))
    c = np.array(rows)
    print(f"Eye (generating view) at {np.round(eye.astype(float), 2).tolist()}")
    print("Constraints (red handle on the mirror -> green handle to be seen there):")
    for k, (i, t) in enumerate(zip(picks, turns)):
        print(f"  #{k + 1}: vertex {i:>5} at {np.round(m.vertices[i].astype(float), 3).tolist()}, reflection turned by {t:.1f} deg")

    print("\nPer-vertex field R(q) = ortho(sum w_n e_n r_n^T), w_n = 1/d^2 (eq. 5):")
    for polar in ("exact", "fast"):
        t0 = time.perf_counter()
        q = api.rotation_field(m.vertices, c, polar=polar)
        dt = time.perf_counter() - t0
        hit = api.rotate(q[picks], c[:, 3:6])
        err = np.degrees(np.max(np.arctan2(np.linalg.norm(np.cross(hit, c[:, 6:9]), axis=1), np.sum(hit * c[:, 6:9], axis=1))))
        print(f"  polar={polar:<5}: {dt * 1e3:7.2f} ms for {len(q):,} vertices; at the red handles the edited ray misses the green handle by {err:.1e} deg")
    ang = np.degrees(api.quat_angle(q))
    print("  how far reflections turn across the mesh (degrees):")
    hist, edges = np.histogram(ang, bins=6)
    for h, a, b in zip(hist, edges[:-1], edges[1:]):
        print(f"    {a:5.1f}-{b:5.1f}  {_bar(h / len(ang))} {100 * h / len(ang):5.1f}%")

    radius = 0.15 * size
    centre1 = m.vertices[picks[0]]
    region = {"kind": "euclidean", "center": centre1.tolist(), "radius": radius, "border": 0.5 * radius}
    qr = api.rotation_field(m.vertices, c, regions=[region])
    ar = np.degrees(api.quat_angle(qr))
    inside = np.linalg.norm(m.vertices - centre1, axis=1) < radius
    members = np.flatnonzero(np.linalg.norm(c[:, :3] - centre1, axis=1) < radius) + 1
    print(f"\nWith a Euclidean region around constraint #1 (radius {radius:.2f}, border {0.5 * radius:.2f}):")
    print(f"  {inside.mean() * 100:.1f}% of vertices inside; the largest turn outside is {ar[~inside].max():.1e} deg (unchanged)")
    print(f"  constraints inside the region: {', '.join(f'#{k}' for k in members)}; the others act nowhere")
    print(f"  inside, turns go up to {ar.max():.1f} deg, fading to 0 across the border")

    w, h = 640, 480
    pos, nrm, mask = sphere_gbuffer(w, h)
    sphere_eye = np.array([0.0, -3.0, 0.0])
    front = pos[mask]
    cs = np.array([api.constraint_row(front[j], nrm[mask][j], front[j] + [0.0, -1.0, 1.0] + 0.3 * rng.normal(size=3), sphere_eye) for j in rng.choice(len(front), 4, replace=False)])
    api.edited_directions(pos[mask][:64], nrm[mask][:64], sphere_eye, cs)  # start the thread pool
    t0 = time.perf_counter()
    e = api.edited_directions(pos[mask], nrm[mask], sphere_eye, cs)
    dt = time.perf_counter() - t0
    print(f"\nPer-pixel path (paper §6.1) on a {w}x{h} G-buffer of a mirror sphere, 4 constraints:")
    print(f"  {mask.sum():,} surface pixels in {dt * 1e3:.1f} ms = {mask.sum() / dt / 1e6:.1f} megapixels/s on this CPU")
    print(f"  every edited direction is a unit vector: max | |e| - 1 | = {np.abs(np.linalg.norm(e, axis=1) - 1).max():.1e}")
    scene_model_demo(bpy, api, mirror, eye, size, picks, m)
    print("\nNext: `make test` runs the suite; `make bench` measures speed against the paper's GPU figures.")
    return 0


def scene_model_demo(bpy, api, mirror, eye, size, picks, m):
    """The add-on's scene model, driven the way the sidebar operators drive it."""
    import rokeby

    rokeby.register()
    print("\nThe add-on in the scene (rokeby.api, as the sidebar's operators use it):")
    api.add_mirror(mirror)
    k = api.add_constraint(mirror, m.vertices[picks[0]], eye=eye, name="Face")
    c = mirror.rokeby.constraints[k]
    rep = api.evaluate()[mirror.name]
    turn = np.degrees(api.quat_angle(api.field(mirror)).max())
    print(f"  a fresh constraint: red handle '{c.surface_handle.name}' on the surface (Shrinkwrap), green handle")
    print(f"  '{c.target_handle.name}' where the physical reflection lands -> largest turn {turn:.1e} deg (nothing changes)")
    green = c.target_handle
    start = green.location.copy()
    green.location.z += 0.5 * size
    api.reset_stats()
    bpy.context.view_layer.update()  # what a drag does: the depsgraph handler updates the field
    rep = api.report(mirror)
    print(f"  green handle dragged up: field recomputed by the depsgraph handler in {rep.python_ms + rep.native_ms:.1f} ms")
    print(f"    (Python {rep.python_ms:.1f} ms, Rust {rep.native_ms:.1f} ms), largest turn now {np.degrees(api.quat_angle(api.field(mirror)).max()):.1f} deg,")
    print(f"    written to the point attribute '{rokeby.core.schema.ROTATION_ATTRIBUTE}' of mesh '{mirror.data.name}'")
    api.reset_stats()
    for _ in range(3):
        api.evaluate()
        bpy.context.view_layer.update()
    s = api.stats()
    print(f"  three more evaluations with nothing changed: {s['recomputations']} recomputations, {s['skipped']} skipped by dirty tracking")
    green.location = start
    green.keyframe_insert("location", frame=1)
    green.location.x += 0.6 * size
    green.keyframe_insert("location", frame=20)
    turns = []
    for frame in (1, 10, 20):
        api.evaluate(frame=frame)
        turns.append(np.degrees(api.quat_angle(api.field(mirror)).mean()))
    print("  green handle keyframed at frames 1 and 20; mean turn per frame: " + ", ".join(f"frame {f}: {t:.2f} deg" for f, t in zip((1, 10, 20), turns)))
    mirror.rokeby.metric = "GEODESIC"
    rep = api.evaluate(frame=20)[mirror.name]
    print(f"  geodesic distances (heat method): {rep.status.lower()}, {rep.native_ms:.1f} ms in Rust for the first solve and factorisation")
    rokeby.unregister()


if __name__ == "__main__":
    sys.exit(main())
