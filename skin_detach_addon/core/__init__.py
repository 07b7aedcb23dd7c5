"""Pure numpy/scipy core of Skin Detach: no bpy here (a test proves it)."""

from .errors import SkinDetachError
from .surface import SkinDetachedSurface

__all__ = ["SkinDetachError", "SkinDetachedSurface"]
