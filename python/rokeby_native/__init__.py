from .rokeby_native import *

__doc__ = rokeby_native.__doc__
if hasattr(rokeby_native, "__all__"):
    __all__ = rokeby_native.__all__
