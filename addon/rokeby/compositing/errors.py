"""The compositing feature's errors (bad input: ValueError), shared by its backends."""

from __future__ import annotations


class CompositingError(ValueError):
    pass


class MissingPasses(CompositingError):
    def __init__(self, missing, path=""):
        self.missing = list(missing)
        where = f" in {path}" if path else ""
        super().__init__(
            f"missing render passes{where}: {', '.join(self.missing)} "
            "(click Set Up Compositing Passes, View Layer properties ▸ Rokeby Compositing, before rendering)"
        )
