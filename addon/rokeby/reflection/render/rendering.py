"""Final renders follow the edit with no extra step: the render nodes of every mirror are kept
in sync with its materials after each evaluation.

A mirror whose final-render edits are on (``rokeby.render_edits``, the default), that is enabled
and has at least one enabled constraint gets the render nodes of its ``render_mode`` in each of
its edited materials (rokeby.reflection.render.shading for ray-traced reflections, rokeby.reflection.render.reflmap for reflection-map
mode, rokeby.reflection.render.refraction for refraction BSDFs). This happens when the mirror gains its first
constraint, when a material is assigned or swapped, when a slot is added, and when a material's
node tree changes; a Principled or Glossy BSDF inside a node group is edited through a copy of the
group local to that material, so the group used elsewhere stays unedited (rokeby.reflection.render.shading).

A material keeps its nodes while any mirror using it has final-render edits on. When none does
(Edit Final Renders turned off, the mirror removed), the nodes come out again and the material is
restored exactly. (A mirror without a constraint, or disabled, keeps them: its field is then the
identity, which renders the physical mirror.)

Each mirror's report says whether F12 shows its edit (``MirrorReport.renders`` and
``render_note``), and a mirror whose edit will not render (no material, no BSDF to edit, a
reflection-map mirror without a map) gets a warning instead of OK.

The work is skipped while nothing it depends on changed (a key of the mirrors' settings and
material slots), so an update costs a tuple comparison per mirror.
"""

from __future__ import annotations

from . import reflmap, refraction, shading
from ...core.errors import RokebyError

_KEYS: dict = {}
_NOTES: dict = {}


def reset():
    """Forget what was synced (after loading a file or undo): the next sync re-checks."""
    _KEYS.clear()
    _NOTES.clear()


def edited_materials(mirror) -> list:
    """The materials whose reflections are edited: every material of the mirror unless a subset
    was chosen (``rokeby.all_materials`` off and ``rokeby.materials``)."""
    s = mirror.rokeby
    if s.all_materials:
        mats = [slot.material for slot in mirror.material_slots if slot.material is not None]
    else:
        mats = [item.material for item in s.materials if item.material is not None]
    return list(dict.fromkeys(mats))


def wanted(mirror) -> bool:
    """Whether final renders should show ``mirror``'s edit (its nodes are installed)."""
    s = mirror.rokeby
    return bool(kept(mirror) and s.enabled and any(c.enabled for c in s.constraints))


def kept(mirror) -> bool:
    """Whether ``mirror``'s render nodes may stay in its materials: while its final-render edits
    are on. (Without a constraint, or disabled, its field is the identity, which renders the
    physical mirror through the nodes too; they are not taken out for that.)"""
    s = mirror.rokeby
    return bool(s.is_mirror and s.render_edits)


def install(mirror) -> int:
    """Install the render nodes of ``mirror``'s render mode in its edited materials (the other
    mode's nodes come out); returns how many BSDF inputs or BSDFs were wired."""
    mats = edited_materials(mirror)
    refracted = sum(refraction.install(mat) for mat in mats)
    if mirror.rokeby.render_mode == "REFLECTION_MAP":
        if reflmap.image_for(mirror) is None:
            raise RokebyError(f"mirror '{mirror.name}' is in reflection-map mode but has no map: capture one first (Capture Map in the mirror's Render panel)")
        for mat in mats:
            shading.uninstall(mat)
        return refracted + sum(reflmap.install(mat, mirror) for mat in mats)
    for mat in mats:
        reflmap.uninstall(mat)
    return refracted + sum(shading.install(mat) for mat in mats)


def uninstall_material(mat) -> bool:
    return bool(shading.uninstall(mat)) | bool(reflmap.uninstall(mat)) | bool(refraction.uninstall(mat))


def installed(mat) -> bool:
    return shading.installed(mat) or reflmap.installed(mat) or refraction.installed(mat)


def _key(mirror) -> tuple:
    s = mirror.rokeby
    slots = tuple(slot.material.session_uid if slot.material is not None else 0 for slot in mirror.material_slots)
    chosen = () if s.all_materials else tuple(item.material.session_uid if item.material else 0 for item in s.materials)
    image = reflmap.image_for(mirror) if s.render_mode == "REFLECTION_MAP" else None
    return (wanted(mirror), kept(mirror), s.render_mode, slots, s.all_materials, chosen, image.session_uid if image is not None else 0, shading.VERSION)


def _note(mirror, count: int) -> tuple:
    mats = edited_materials(mirror)
    if not mirror.material_slots or not mats:
        return False, "renders show no reflection to edit: the mirror has no material (add a reflective one)"
    if count == 0:
        names = ", ".join(m.name for m in mats)
        return False, f"renders do not show the edit: no Glossy, Anisotropic, Principled, Glass or Refraction BSDF to edit in {names}"
    return True, f"renders show the edit ({count} BSDF input(s) in {len(mats)} material(s))"


def sync_scene(scene, reports=None, *, changed_materials=(), force=False) -> bool:
    """Install or remove render nodes so that renders show exactly the mirrors that want it;
    fills each mirror's report (``renders``, ``render_note``). ``changed_materials``: materials
    or node trees Blender reported as edited (their nodes are checked again). Returns whether
    anything was (re)installed or removed. Never raises: problems go into the reports."""
    from .. import pointers  # noqa: PLC0415 - what the add-on owns: no pass over the scene's objects

    mirrors = [ob for ob in pointers.mirrors(scene) if ob.type == "MESH" and (reports is None or ob.name in reports)]
    done = _KEYS.setdefault(scene.session_uid, {})
    if not mirrors and not done and not force:
        return False  # nothing to do: no cost in scenes without mirrors
    changed = set(changed_materials)
    keys = {m.session_uid: _key(m) for m in mirrors}
    touched = False
    if changed and done == keys and not force:
        # Only materials were edited: bring the mirrors that use them up to date, nothing else.
        for m in mirrors:
            if wanted(m) and any(mat in changed or mat.node_tree in changed for mat in edited_materials(m)):
                touched |= _install_noted(m)
        changed = set()
    dirty = force or done != keys
    if dirty:
        want = {}
        for m in mirrors:
            for mat in edited_materials(m):
                want.setdefault(mat, []).append(m)
        # Materials that were edited for a mirror and no longer are (anywhere in the file: a
        # mirror deleted or removed leaves its old materials behind).
        import bpy  # noqa: PLC0415

        wanted_mats = {mat for mat, ms in want.items() if any(kept(m) for m in ms)}
        # Candidates: this scene's mirrors' materials, and materials no mirror in the file uses
        # any more; a material edited for a mirror of another scene is that scene's business.
        elsewhere, elsewhere_wanted = set(), set()
        for ob in pointers.mirrors():
            if ob.type == "MESH" and ob not in mirrors:
                mats = edited_materials(ob)
                elsewhere.update(mats)
                if kept(ob):
                    elsewhere_wanted.update(mats)
        for mat in bpy.data.materials:
            if mat in wanted_mats or mat in elsewhere_wanted or (mat in elsewhere and mat not in want) or not installed(mat):
                continue
            try:
                touched |= uninstall_material(mat)
            except RokebyError:
                continue  # its split BSDF cannot be rebuilt: kept as is (Remove Render Edits says why)
        for m in mirrors:
            uid = m.session_uid
            if wanted(m) and (done.get(uid) != keys[uid] or force or any(mat in changed or mat.node_tree in changed for mat in edited_materials(m))):
                touched |= _install_noted(m)
        done.clear()
        done.update(keys)
    for m in mirrors:
        if not wanted(m):
            s = m.rokeby
            why = ("Edit Final Renders is off" if not s.render_edits else
                   "the mirror is disabled" if not s.enabled else "it has no enabled constraint")
            _NOTES[m.session_uid] = (None, f"renders show no edit: {why}")
        rep = (reports or {}).get(m.name)
        if rep is None:
            from .. import mirror_state  # noqa: PLC0415

            rep = mirror_state.report_of(m)
        note = _NOTES.get(m.session_uid)
        if rep is None or note is None:
            continue
        rep.renders, rep.render_note = note
        if note[0] is False and rep.status in ("OK", "WARNING") and note[1] not in rep.messages:
            rep.warn(note[1])
    return touched


def _install_noted(m) -> bool:
    try:
        count = install(m)
        _NOTES[m.session_uid] = _note(m, count)
        return True
    except RokebyError as exc:
        _NOTES[m.session_uid] = (False, f"renders do not show the edit: {exc}")
        return False
