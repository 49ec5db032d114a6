"""The recomposited image in Blender: a float image (:func:`show_image`) and the compositor's Image
node that reads it (:func:`feed_compositor`)."""

from __future__ import annotations

import numpy as np

from ..core import schema
from .errors import CompositingError


# --- the compositor's input ------------------------------------------------------------
# Zubiaga et al. edit normals inside a node-based compositor. Rokeby's recompositing runs outside
# Blender's compositor (Rust or GLSL), so its result enters the compositor as an Image node named
# schema.COMPOSITOR_NODE that every recomposite of the same image keeps pointing at the current pixels
# (show_image → _keep_compositor_current): the artist chains it with other compositor nodes, and a
# Viewer shows it in the backdrop. The Composite node (what F12 renders write) is not touched.


def show_image(name: str, pixels: np.ndarray):
    """The recomposited image as a new (or updated) Blender image: (H, W, 3) linear, top row first."""
    import bpy

    h, w = pixels.shape[:2]
    img = bpy.data.images.get(name)
    if img is None or tuple(img.size) != (w, h):
        if img is not None:
            bpy.data.images.remove(img)
        img = bpy.data.images.new(name, w, h, alpha=True, float_buffer=True)
    rgba = np.empty((h, w, 4), np.float32)
    rgba[..., :3] = pixels[::-1]  # Blender stores the bottom row first
    rgba[..., 3] = 1.0
    img.pixels.foreach_set(rgba.reshape(-1))
    img.update()
    _keep_compositor_current(img)
    return img


def feed_compositor(scene, image):
    """Puts ``image`` (a recomposited Blender image) into ``scene``'s compositor: turns the
    compositor on, adds (or reuses) the Image node schema.COMPOSITOR_NODE reading it, and feeds the
    Viewer with it (one is added when the tree has none) so the backdrop shows it, as clicking a
    node with Ctrl+Shift does. The Composite node (what renders write) and the artist's other
    links stay as they are. Returns the node; later recomposites of the same image name update
    what it reads."""
    if image is None:
        raise CompositingError("image: none given: click Render and Recomposite (or Recomposite Render) first")
    if scene is None:
        raise CompositingError("scene: none given")
    from ..blender import compat  # noqa: PLC0415

    tree = compat.compositor_tree(scene, create=True)
    node = tree.nodes.get(schema.COMPOSITOR_NODE)
    if node is None or node.bl_idname != "CompositorNodeImage":
        node = tree.nodes.new("CompositorNodeImage")
        node.name = schema.COMPOSITOR_NODE
        node.label = schema.RECOMPOSITED_IMAGE
        xs = [n.location.x for n in tree.nodes if n != node]
        node.location = (min(xs) if xs else 0.0, min((n.location.y for n in tree.nodes if n != node), default=0.0) - 350.0)
    node.image = image
    node[schema.COMPOSITOR_IMAGE_KEY] = image.name
    viewer = next((n for n in tree.nodes if n.bl_idname == "CompositorNodeViewer"), None)
    if viewer is None:
        viewer = tree.nodes.new("CompositorNodeViewer")
        viewer.location = (node.location.x + 300.0, node.location.y)
    tree.links.new(node.outputs["Image"], viewer.inputs[0])
    return node


def _keep_compositor_current(img) -> None:
    """Every scene's schema.COMPOSITOR_NODE that follows ``img``'s name reads ``img`` (show_image makes a
    new image when the frame size changes) and the compositor sees the new pixels."""
    import bpy

    from ..blender import compat  # noqa: PLC0415

    for sc in bpy.data.scenes:
        tree = compat.compositor_tree(sc)
        node = tree.nodes.get(schema.COMPOSITOR_NODE) if tree is not None else None
        if node is not None and node.get(schema.COMPOSITOR_IMAGE_KEY) == img.name:
            if node.image != img:
                node.image = img
            tree.update_tag()
