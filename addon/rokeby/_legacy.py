"""Old module paths keep working: ``rokeby.evaluate``, ``rokeby.shading``, ``rokeby.appearance_ui``,
... name the modules that moved into the layered packages (docs/architecture.md).

``import rokeby.evaluate`` (or ``from rokeby import evaluate``) gives the very module object
``rokeby.reflection.evaluate``, so attributes, private names and monkeypatching act on the one
module the add-on uses. Only the paths below are aliased; new code imports the new paths.
"""

from __future__ import annotations

import importlib
import importlib.abc
import importlib.util
import sys

# old name (under the add-on's package) -> new name, both relative to the package
MOVED = {
    "meshio": "core.meshio",
    "words": "core.words",
    "native": "core.native",
    "compat": "blender.compat",
    "transaction": "blender.transaction",
    "progress": "blender.progress",
    "prefs": "blender.prefs",
    "evaluate": "reflection.evaluate",
    "duplicates": "reflection.duplicates",
    "props": "reflection.props",
    "operators": "reflection.operators",
    "ui": "reflection.ui",
    "handlers": "reflection.handlers",
    "registry": "reflection.registry",
    "shading": "reflection.render.shading",
    "refraction": "reflection.render.refraction",
    "rendering": "reflection.render.rendering",
    "reflmap": "reflection.render.reflmap",
    "viewport": "reflection.viewport.draw",
    "glsl": "reflection.viewport.glsl",
    "appearance_glsl": "appearance.glsl",
    "appearance_preview": "appearance.preview",
    "appearance_ui": "appearance.ui",
    "shadow_ui": "shadow.ui",
    "compositing_ui": "compositing.ui",
    "compositing_brush": "compositing.brush",
    "compositing_brush_ui": "compositing.brush_ui",
    "recomposite_gpu": "compositing.blender_gpu",
}


class _Aliases(importlib.abc.MetaPathFinder, importlib.abc.Loader):
    """Finds ``<package>.<old>`` and loads it as the module ``<package>.<new>`` already is."""

    def __init__(self, package: str):
        self.package = package

    def _target(self, fullname: str) -> "str | None":
        head, _, old = fullname.rpartition(".")
        if head != self.package or old not in MOVED:
            return None
        return f"{self.package}.{MOVED[old]}"

    def find_spec(self, fullname, path=None, target=None):
        if self._target(fullname) is None:
            return None
        return importlib.util.spec_from_loader(fullname, self)

    def create_module(self, spec):
        module = importlib.import_module(self._target(spec.name))
        self._spec = module.__spec__
        return module

    def exec_module(self, module):
        module.__spec__ = self._spec  # the import machinery set the alias's spec on the real module


def install(package: str) -> None:
    if not any(isinstance(f, _Aliases) and f.package == package for f in sys.meta_path):
        sys.meta_path.append(_Aliases(package))

