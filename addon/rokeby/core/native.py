"""The one place the add-on imports the Rust core ``rokeby_native``.

Everything else in the add-on goes through this module, so a missing or broken native build
shows up as one clear message (in the sidebar and as an exception) instead of import errors
scattered through the code.
"""

from __future__ import annotations

import contextlib
import threading

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


def is_extension() -> bool:
    """Whether the add-on runs as a Blender extension (installed from the zip: its package is
    ``bl_ext.<repository>.rokeby``) rather than from a checkout."""
    return (__package__ or "").startswith("bl_ext.")


def missing_hint() -> str:
    """What to do when the native core did not load, for the way the add-on is installed: an
    extension user has no checkout and no `make`."""
    if is_extension():
        return ("The extension's native wheel (rokeby_native) failed to load: reinstall Rokeby from a zip made for "
                "this platform and Blender version (Edit ▸ Preferences ▸ Get Extensions), then restart Blender")
    return "Build it: run `make` in the Rokeby checkout, or install the extension zip, which bundles its wheel"


class _Checked:
    """``rokeby_native`` with a look at the cancel request before each use: a cancel that came
    between two native calls (the core's own flag is cleared by the next cancellable call) still
    stops the operation at its next native call."""

    def __getattr__(self, name):
        check_cancelled()
        return getattr(_native, name)


_CHECKED = _Checked()
_CANCEL = threading.Event()


def module():
    """The ``rokeby_native`` module, or a clear error saying how to get it."""
    if _native is None:
        raise NativeUnavailable(f"Rokeby's native core (rokeby_native) is not available. {missing_hint()} ({IMPORT_ERROR})")
    return _CHECKED


def cancel() -> None:
    """Stop the running operation: the cancellable native calls in flight stop at their next row
    and the next native call of the operation does not start (both raise KeyboardInterrupt).
    Callable from any thread (an operator's Esc, a signal handler). The request holds until the
    next operation starts (``cancellable``)."""
    _CANCEL.set()
    if _native is not None and hasattr(_native, "cancel"):
        _native.cancel()


def check_cancelled() -> None:
    """KeyboardInterrupt when ``cancel()`` was called during the running operation."""
    if _CANCEL.is_set():
        raise KeyboardInterrupt("cancelled")


@contextlib.contextmanager
def cancellable():
    """An operation that ``cancel()`` can stop: earlier requests are forgotten at its start and
    at its end."""
    _CANCEL.clear()
    try:
        yield
    finally:
        _CANCEL.clear()


def rotation_field(*args, **kwargs):
    return module().reflection.rotation_field(*args, **kwargs)


def edited_directions(*args, **kwargs):
    return module().reflection.edited_directions(*args, **kwargs)


def ortho(*args, **kwargs):
    return module().reflection.ortho(*args, **kwargs)


def view_blend(*args, **kwargs):
    return module().reflection.view_blend(*args, **kwargs)


def view_blend_render_rows(*args, **kwargs):
    return module().reflection.view_blend_render_rows(*args, **kwargs)


def view_blend_rotation_vectors(*args, **kwargs):
    return module().reflection.view_blend_rotation_vectors(*args, **kwargs)
