"""Pure numpy/scipy core of Skin Detach: no bpy here (a test proves it)."""

from .dual_laplacian import DualLaplacian, DualLaplacianResult, deform_proxy
from .errors import SkinDetachError
from .surface import SkinDetachedSurface

__all__ = ["DualLaplacian", "DualLaplacianResult", "SkinDetachError", "SkinDetachedSurface", "deform_proxy"]
