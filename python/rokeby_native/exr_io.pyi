"""rokeby_native.exr_io: OpenEXR files in pure Rust (no OpenEXR C library in the process),
rust/rokeby-core/src/exr_io.rs."""

from collections.abc import Sequence
from typing import Any

from ._types import _Array

def read(data: bytes, dwa: bool = False) -> list[dict[str, Any]]: ...
def write(
    channels: dict[str, _Array],
    header: dict[str, str] | None = None,
    compression: str = "zip",
    half: Sequence[str] | None = None,
) -> bytes: ...
