"""The one place the add-on imports the Rust core ``rokeby_native``.

Everything else in the add-on goes through this module, so a missing or broken native build
shows up as one clear message (in the sidebar and as an exception) instead of import errors
scattered through the code.
"""

from __future__ import annotations

try:
    import rokeby_native as _native
    IMPORT_ERROR: Exception | None = None
except ImportError as exc:  # pragma: no cover - exercised only on broken installs
    _native = None
    IMPORT_ERROR = exc


class NativeUnavailable(RuntimeError):
    pass


def available() -> bool:
    return _native is not None


def version() -> str:
    return _native.__version__ if _native is not None else "not installed"


def module():
    """The ``rokeby_native`` module, or a clear error saying how to build it."""
    if _native is None:
        raise NativeUnavailable(
            "Rokeby's native core (rokeby_native) is not installed: run `make` in the Rokeby "
            f"checkout, or install the extension zip that bundles its wheel ({IMPORT_ERROR})"
        )
    return _native


def rotation_field(*args, **kwargs):
    return module().rotation_field(*args, **kwargs)


def edited_directions(*args, **kwargs):
    return module().edited_directions(*args, **kwargs)


def ortho(*args, **kwargs):
    return module().ortho(*args, **kwargs)


def view_blend(*args, **kwargs):
    return module().view_blend(*args, **kwargs)


def view_blend_render_rows(*args, **kwargs):
    return module().view_blend_render_rows(*args, **kwargs)


def view_blend_rotation_vectors(*args, **kwargs):
    return module().view_blend_rotation_vectors(*args, **kwargs)
