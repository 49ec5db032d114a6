"""The shadow edit's falloff (Mattausch et al. §6.2) follows the light on its own: the add-on's
handlers set (l_initial · l_current)^β whenever the light moves or the frame changes."""

import numpy as np
import pytest

bpy = pytest.importorskip("bpy")

import rokeby  # noqa: E402
from rokeby import api, shadow  # noqa: E402
from rokeby.core import schema  # noqa: E402
from support.shadow import LIGHT, blender_scene  # noqa: E402


def _edit(beta):
    _bpy, sc, ball, lamp, ground = blender_scene()
    rokeby.register()
    s = api.start_shadow_edit(ball, lamp, [ground], min_loop_vertices=10)
    h = s.handles(0)["points"].astype(np.float64)
    n, m = len(h), int(np.argmax(h[:, 0]))
    c = h.mean(axis=0)
    s.drag(0, ((m - n // 5) % n, (m + n // 5) % n), m, c + (h[m] - c) * 1.35)
    s.commit()
    ob, _twin = api.apply_shadow_edit(s, falloff_beta=beta)
    return sc, lamp, ob


def _key(ob):
    return ob.data.shape_keys.key_blocks[schema.SHADOW_EDIT_KEY].value


def test_falloff_follows_the_light_through_the_handlers():
    sc, lamp, ob = _edit(8.0)
    assert ob["rokeby_falloff_beta"] == 8.0 and _key(ob) == pytest.approx(1.0)
    lamp.location = (4.0, 0.0, 1.5)  # far from where the edit was made
    sc.view_layers[0].update()  # the depsgraph handler runs
    k = _key(ob)
    assert 0.0 <= k < 0.2
    assert k == pytest.approx(shadow.falloff_factor(ob, lamp, 8.0), abs=1e-6)
    lamp.location = tuple(LIGHT)  # back: full strength again
    sc.view_layers[0].update()
    assert _key(ob) == pytest.approx(1.0, abs=1e-4)
    # Keyframed light: frame changes update it too.
    lamp.keyframe_insert("location", frame=1)
    lamp.location = (4.0, 0.0, 1.5)
    lamp.keyframe_insert("location", frame=10)
    sc.frame_set(10)
    assert _key(ob) == pytest.approx(k, abs=1e-4)
    sc.frame_set(1)
    assert _key(ob) == pytest.approx(1.0, abs=1e-4)
    # Settled: another update writes nothing.
    assert shadow.sync_falloffs(sc) == 0


def test_no_falloff_by_default_and_bad_beta_refused():
    sc, lamp, ob = _edit(0.0)
    lamp.location = (4.0, 0.0, 1.5)
    sc.view_layers[0].update()
    assert _key(ob) == pytest.approx(1.0)
    with pytest.raises(ValueError, match="falloff_beta"):
        shadow.apply(None, falloff_beta=-1.0)
