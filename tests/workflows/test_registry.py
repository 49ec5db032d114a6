"""Heavy scenes (problem 5): the add-on's handlers never scan the scene's objects.

What the add-on owns is kept in ``rokeby.reflection.registry``; these tests check that it finds exactly the
mirrors a full scan finds after every everyday operation (add, remove, Shift+D and Alt+D copies,
rename, delete with X, undo, save and reload), and that a depsgraph update costs the add-on's
Python the same number of executed lines with 100 or 2,000 unrelated objects, with no Rokeby data
and with one mirror (counted, not timed: the time is in ``make bench``, bench/heavy_scene.py)."""

import math
import os
import sys

import pytest

bpy = pytest.importorskip("bpy")

import rokeby  # noqa: E402
from rokeby import api  # noqa: E402
from rokeby.reflection import scene_inputs  # noqa: E402

try:
    from rokeby.reflection import registry  # noqa: E402
except ImportError:  # the add-on before the registry: the line counts below still compare
    registry = None

ADDON = os.path.dirname(rokeby.__file__)


def _scene(n_props: int):
    bpy.ops.wm.read_factory_settings(use_empty=True)
    rokeby.register()
    sc = bpy.context.scene
    me = bpy.data.meshes.new("Prop")
    for i in range(n_props):
        ob = bpy.data.objects.new(f"Prop {i:05d}", me)
        ob.location = (i % 50, i // 50, 0.0)
        sc.collection.objects.link(ob)
    cam = bpy.data.objects.new("Camera", bpy.data.cameras.new("Camera"))
    sc.collection.objects.link(cam)
    sc.camera = cam
    cam.location = (0.0, -4.0, 0.0)
    cam.rotation_euler = (math.pi / 2, 0.0, 0.0)
    for _ in range(3):  # settle: the updates that creating the scene causes
        sc.view_layers[0].update()
    return sc


def _ball(name="Ball", location=(0.0, 0.0, 0.0)):
    bpy.ops.mesh.primitive_uv_sphere_add(segments=24, ring_count=12, location=location)
    ball = bpy.context.object
    ball.name = name
    return ball


def _mirror(name="Ball", location=(0.0, 0.0, 0.0)):
    ball = _ball(name, location)
    api.add_mirror(ball)
    x, y, z = location
    api.add_constraint(ball, (x, y - 1.0, z), (x + 1.0, y - 3.0, z + 2.0))
    api.add_region(ball, "EUCLIDEAN", center=(x, y - 1.0, z), radius=0.8)
    api.evaluate()
    return ball


def _lines_per_update(sc, steps=4):
    """Lines of the add-on's Python executed by ``steps`` depsgraph updates that move an
    unrelated object (sys.settrace: a scan of the scene's objects shows as lines per object)."""
    n = [0]

    def local(frame, event, arg):
        if event == "line":
            n[0] += 1
        return local

    def glob(frame, event, arg):
        return local if frame.f_code.co_filename.startswith(ADDON) else None

    mover = bpy.data.objects["Prop 00000"]
    for _ in range(2):  # warm-up (first evaluation after a change)
        mover.location.x += 0.01
        sc.view_layers[0].update()
    rebuilds = registry.stats()["rebuilds"] if registry else 0
    old = sys.gettrace()
    sys.settrace(glob)
    try:
        for _ in range(steps):
            mover.location.x += 0.01
            sc.view_layers[0].update()
    finally:
        sys.settrace(old)
    return n[0], (registry.stats()["rebuilds"] if registry else 0) - rebuilds


@pytest.mark.parametrize("with_mirror", [False, True], ids=["no Rokeby data", "one mirror"])
def test_an_update_costs_the_same_with_100_or_2000_unrelated_objects(with_mirror):
    counts = {}
    for n in (100, 2000):
        sc = _scene(n)
        if with_mirror:
            _mirror()
        lines, rebuilds = _lines_per_update(sc)
        assert rebuilds == 0  # moving an object changes nothing the registry keeps
        counts[n] = lines
    assert counts[100] == counts[2000], counts
    if not with_mirror:
        # A flag test and a length per update; no evaluation, no material or shadow pass.
        assert counts[2000] <= 4 * 40, counts
    rokeby.unregister()
    rokeby.register()


def _brute(scene=None):
    objs = bpy.data.objects if scene is None else scene.objects
    return sorted(ob.name for ob in objs if ob.rokeby.is_mirror)


def _check(sc, what):
    sc.view_layers[0].update()
    got = sorted(ob.name for ob in registry.mirrors())
    assert got == _brute(), (what, got, _brute())
    assert sorted(ob.name for ob in scene_inputs.mirrors_of(sc)) == _brute(sc), what
    assert sorted(api.evaluate(sc)) == _brute(sc), what


def _select_only(ob):
    bpy.ops.object.select_all(action="DESELECT")
    ob.select_set(True)
    bpy.context.view_layer.objects.active = ob


def test_registry_finds_the_mirrors_after_everyday_operations(tmp_path):
    sc = _scene(50)
    _check(sc, "empty")
    a = _mirror("A")
    _check(sc, "add_mirror")
    b = _mirror("B", (3.0, 0.0, 0.0))
    _check(sc, "second mirror")
    # A script setting the flag itself.
    c = _ball("C", (-3.0, 0.0, 0.0))
    c.rokeby.is_mirror = True
    _check(sc, "is_mirror set directly")
    api.remove_mirror(c)
    _check(sc, "remove_mirror")
    a.name = "A renamed"
    _check(sc, "rename")
    _select_only(a)
    bpy.ops.object.duplicate()  # Shift+D
    _check(sc, "Shift+D")
    _select_only(b)
    bpy.ops.object.duplicate(linked=True)  # Alt+D
    _check(sc, "Alt+D")
    bpy.ops.ed.undo_push(message="copies")
    _select_only(bpy.data.objects["B"])
    bpy.ops.object.delete()  # X
    _check(sc, "delete with X")
    bpy.ops.ed.undo_push(message="delete")
    bpy.ops.ed.undo()
    sc = bpy.context.scene  # undo replaces the scene's Python object
    _check(sc, "undo")
    assert "B" in _brute()
    bpy.ops.ed.redo()
    sc = bpy.context.scene
    _check(sc, "redo")
    bpy.ops.ed.undo()
    sc = bpy.context.scene
    _check(sc, "undo again")
    # A mirror unlinked from the scene (kept in the file) is no longer the scene's.
    a = bpy.data.objects["A renamed"]
    for coll in list(a.users_collection):
        coll.objects.unlink(a)
    sc.view_layers[0].update()
    assert "A renamed" in _brute() and "A renamed" not in _brute(sc)
    _check(sc, "unlinked")
    sc.collection.objects.link(a)
    _check(sc, "linked again")
    path = tmp_path / "registry.blend"
    bpy.ops.wm.save_as_mainfile(filepath=str(path))
    bpy.ops.wm.read_factory_settings(use_empty=True)
    assert registry.mirrors() == []
    bpy.ops.wm.open_mainfile(filepath=str(path))
    sc = bpy.context.scene
    _check(sc, "load")
    assert "A renamed" in _brute(sc)
    # Deleted by a script and another object made in the same step (same count): the stale
    # reference is noticed.
    victim = bpy.data.objects["A renamed"]
    bpy.data.objects.remove(victim, do_unlink=True)
    sc.collection.objects.link(bpy.data.objects.new("Newcomer", None))
    _check(sc, "delete + add in one step")
