"""The skin-detached surface (paper sections 3.1 and 3.2, the rebuild of eq. 10/11): the detail
mesh prepared, simplified to a small proxy by checked collapses and bound to it as a skin whose
weights are diffused across the proxy's seams, then rebuilt from a deformed proxy with the
handles' held detail placed exactly."""

from .held_detail import HeldPlacement, Layout
from .stretch import SkinStretch
from .surface import Preview, SkinDetachedSurface

__all__ = ["HeldPlacement", "Layout", "Preview", "SkinDetachedSurface", "SkinStretch"]
