"""Type stubs of `rokeby_native`, the pyo3 binding of rokeby-core (rust/rokeby-py).

One submodule per area of the core, named as the core's folders (rust/rokeby-core/src) and the
binding's files (rust/rokeby-py/src) are: `reflection`, `geometry`, `envmaps`, `shadows`,
`compositing` and `exr_io`; the top level holds what spans them.

Maintained by hand; tests/native/test_native_stubs.py checks that every public name of the built
module and of each submodule has a stub here and that each function's parameters (names, kinds,
defaults) match the module's `__text_signature__`. Array arguments accept anything
`numpy.asarray` reads (float32/float64; float64 is stored as float32), index arrays integers.
Errors: bad input → ValueError/TypeError naming the argument, memory → MemoryError, a numerical
failure → NumericalError (a RuntimeError), cancelled → KeyboardInterrupt, a bug in the core →
RuntimeError. See docs/errors.md.
"""

from . import compositing as compositing
from . import envmaps as envmaps
from . import exr_io as exr_io
from . import geometry as geometry
from . import reflection as reflection
from . import shadows as shadows

__version__: str

class NumericalError(RuntimeError):
    """A numerical method of the core failed on input that passed validation (a factorisation
    broke down, an iteration did not converge)."""

def cancel() -> None: ...
