"""Which proxy vertices a handle holds: those its selection owns.

Arrays: detail vertices (n,) and their welded ids (u,) (``surface.weld`` (n,) -> u), proxy
vertices (m,), a selection ``ids`` (k,) of detail vertex ids.

Holding every corner of every proxy face a selection binds to pins about a third of the proxy
for an armadillo's leg: the proxy bends only outside that, and stretches there. A handle holds
the proxy vertices its selection *owns* (:func:`proxy_ownership` at least :data:`OWNED`: nearly
all of the skin's weight on them comes from selected vertices); the rest of the selection pulls
the free proxy around its border towards the handle's motion
(:class:`.pulled_energy.PulledEnergy`), and :class:`.detail_fit.DetailFit` puts it exactly
where the handle says.
"""

import numpy as np

from .validation import as_vertex_ids

#: A proxy vertex is held by a selection that brings at least this share of the skin's weight on it.
OWNED = 0.9
#: A selection owning fewer proxy vertices than this (smaller than the proxy's faces) holds every
#: corner of the faces it binds to instead, as handles always did: three free corners could not
#: carry its rotation.
MIN_OWNED = 3


def proxy_ownership(surface, ids):
    """(m,) float: the share of the skin's weight on each proxy vertex that comes from the detail
    vertices ``ids`` (k,) (0 where no detail binds). The skin's weight of an association on a
    corner is its rest-area weight times the corner's barycentric (negatives count as 0)."""
    skin = surface.skin
    u = skin.case.shape[0]
    selected = np.zeros(u, dtype=bool)
    selected[surface.weld[as_vertex_ids("ids", ids, surface.n_detail)]] = True
    share = skin.weight[:, None] * np.clip(skin.bary, 0.0, None)
    corners = surface.proxy_faces[skin.face].ravel()
    m = surface.proxy_vertices.shape[0]
    total = np.bincount(corners, weights=share.ravel(), minlength=m)
    mine = np.bincount(corners, weights=(share * selected[skin.vertex][:, None]).ravel(), minlength=m)
    return np.divide(mine, total, out=np.zeros(m), where=total > 0)


def held_proxy_vertices(surface, ids):
    """(c,) sorted proxy vertex ids a handle of detail vertices ``ids`` (k,) holds: those it owns
    (:func:`proxy_ownership` >= :data:`OWNED`), or, for a selection owning fewer than
    :data:`MIN_OWNED`, every corner of every face it binds to (``surface.proxy_vertices_for``)."""
    owned = np.flatnonzero(proxy_ownership(surface, ids) >= OWNED)
    return owned if owned.size >= MIN_OWNED else surface.proxy_vertices_for(ids)


