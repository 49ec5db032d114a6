"""Node helpers of the Blender layer (no feature knowledge): all or nothing on a node tree.

``snapshot`` records what an edit may change in a node tree (nodes, links, the given custom keys
on its nodes, group assignments), ``restore`` puts it back, ``atomic`` runs an edit under them.
Used by the render node groups of reflection editing and by ``rokeby.blender.transaction``.
"""

from __future__ import annotations

import bpy

from ..core import schema


def snapshot(tree, keys=()) -> dict:
    """What an install may change in ``tree``: its nodes, links, our keys on the artist's nodes and
    the group each group node uses (for :func:`restore` after a failure half way)."""
    return {
        "nodes": {nd.as_pointer() for nd in tree.nodes},
        "links": {(lk.from_node.as_pointer(), lk.from_socket.identifier, lk.to_node.as_pointer(), lk.to_socket.identifier) for lk in tree.links},
        "keys": {nd.as_pointer(): {k: nd[k] for k in keys if k in nd} for nd in tree.nodes},
        "key_names": tuple(keys),
        "groups": {nd.as_pointer(): nd.node_tree for nd in tree.nodes if nd.bl_idname == "ShaderNodeGroup"},
        "node_groups": {g.as_pointer() for g in bpy.data.node_groups},
    }


def atomic(tree, keys, fn):
    """``fn()`` on ``tree``, all or nothing: an exception restores the tree (:func:`restore`),
    including the custom properties ``keys`` on its nodes, and is raised again."""
    snap = snapshot(tree, keys)
    try:
        return fn()
    except BaseException:
        restore(tree, snap)
        raise


def restore(tree, snap) -> None:
    """Put ``tree`` back as :func:`snapshot` found it: nodes added since go (with their links), links
    added since go, links removed since come back, our keys and group assignments are reset, and
    group copies made since are removed."""
    for nd in [nd for nd in tree.nodes if nd.as_pointer() not in snap["nodes"]]:
        tree.nodes.remove(nd)
    nodes = {nd.as_pointer(): nd for nd in tree.nodes}
    for lk in list(tree.links):
        if (lk.from_node.as_pointer(), lk.from_socket.identifier, lk.to_node.as_pointer(), lk.to_socket.identifier) not in snap["links"]:
            tree.links.remove(lk)
    now = {(lk.from_node.as_pointer(), lk.from_socket.identifier, lk.to_node.as_pointer(), lk.to_socket.identifier) for lk in tree.links}
    for key in snap["links"] - now:
        a, out_id, b, in_id = key
        if a in nodes and b in nodes:
            out = next((sk for sk in nodes[a].outputs if sk.identifier == out_id), None)
            inp = next((sk for sk in nodes[b].inputs if sk.identifier == in_id), None)
            if out is not None and inp is not None:
                tree.links.new(out, inp)
    for ptr, nd in nodes.items():
        keys = snap["keys"].get(ptr, {})
        for k in snap["key_names"]:
            if k in keys:
                nd[k] = keys[k]
            elif k in nd:
                del nd[k]
        if ptr in snap["groups"] and nd.node_tree != snap["groups"][ptr]:
            nd.node_tree = snap["groups"][ptr]
    for g in [g for g in bpy.data.node_groups if g.as_pointer() not in snap["node_groups"] and g.get(schema.COPY_OF_KEY) is not None and g.users == 0]:
        bpy.data.node_groups.remove(g)
