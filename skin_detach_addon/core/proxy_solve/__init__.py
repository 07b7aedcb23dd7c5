"""The proxy solve (paper section 3.3): dual Laplacian editing of the proxy under its handles, the
rotated and pulled energies minimised by a projected Newton iteration with a lagged Hessian
factor, the volume kept, within a budget counted in work done."""

from .dual_laplacian import DualLaplacian, DualLaplacianResult, deform_proxy
from .proxy_solves import ProxySolves

__all__ = ["DualLaplacian", "DualLaplacianResult", "ProxySolves", "deform_proxy"]
