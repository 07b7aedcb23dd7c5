"""Pure numpy/scipy core of Skin Detach: no bpy here (a test proves it). Two halves, as in the
paper: :mod:`.detached_surface` (the detail bound as a skin to a small proxy, and rebuilt from it)
and :mod:`.proxy_solve` (the proxy deformed by dual Laplacian editing), over the shared
:mod:`.errors`, :mod:`.validation`, :mod:`.threads` and :mod:`.geometry`; neither half imports the
other (a test checks it)."""

from .detached_surface import SkinDetachedSurface
from .errors import SkinDetachError
from .proxy_solve import DualLaplacian, DualLaplacianResult, deform_proxy

__all__ = ["DualLaplacian", "DualLaplacianResult", "SkinDetachError", "SkinDetachedSurface", "deform_proxy"]
