"""The bend scenario every method is judged on (DESIGN section 4).

Take the longest bounding-box axis of ``points`` (n, 3); anchors are the vertices in its
lowest 10 %, the handle the vertices in its highest 10 %. The handle is rotated 45 degrees
about its centroid around the shortest axis and shifted by 25 % of the longest extent along
the middle axis.
"""

from dataclasses import dataclass

import numpy as np


@dataclass
class BendScenario:
    """anchor_ids (a,), handle_ids (h,) vertex ids; rotation (3, 3); pivot (3,); shift (3,)."""

    anchor_ids: np.ndarray
    handle_ids: np.ndarray
    rotation: np.ndarray
    pivot: np.ndarray
    shift: np.ndarray

    def move(self, points):
        """``points`` (r, 3) carried by the handle's rigid motion."""
        return (points - self.pivot) @ self.rotation.T + self.pivot + self.shift

    def motion(self, fraction=1.0):
        """(4, 4) rigid motion of the handle ``fraction`` of the way: the rotation's angle and the
        shift both scaled by ``fraction`` (about the same axis and pivot)."""
        r = self.rotation
        axis = np.array([r[2, 1] - r[1, 2], r[0, 2] - r[2, 0], r[1, 0] - r[0, 1]])
        sine = np.linalg.norm(axis) / 2
        angle = np.arctan2(sine, (np.trace(r) - 1) / 2) * fraction
        out = np.eye(4)
        if sine > 0:
            k = axis / (2 * sine)
            cross = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
            out[:3, :3] = np.eye(3) + np.sin(angle) * cross + (1 - np.cos(angle)) * cross @ cross
        out[:3, 3] = self.pivot - out[:3, :3] @ self.pivot + fraction * self.shift
        return out

    def proxy_constraints(self, surface):
        """For a scenario over the detail vertices of ``surface`` (a SkinDetachedSurface): the
        constrained proxy ids (c,) (anchors first, then the handle) and their targets (c, 3),
        every corner of every proxy face the selections bind to held (handles before 0.2)."""
        handle = surface.proxy_vertices_for(self.handle_ids)
        anchors = np.setdiff1d(surface.proxy_vertices_for(self.anchor_ids), handle)
        rest = surface.proxy_vertices
        return np.concatenate([anchors, handle]), np.concatenate([rest[anchors], self.move(rest[handle])])


    def proxy_groups(self, surface):
        """(m,) rigid group of every proxy vertex of ``surface``: 0 anchors, 1 the handle, -1 free
        (for ``surface.reconstruct(..., groups=...)``)."""
        ids, _ = self.proxy_constraints(surface)
        handle = surface.proxy_vertices_for(self.handle_ids)
        groups = np.full(surface.proxy_vertices.shape[0], -1, dtype=np.int64)
        groups[ids] = 0
        groups[handle] = 1
        return groups

    def held_rig(self, surface):
        """The scenario as the add-on rigs it
        (:mod:`skin_detach_addon.core.detached_surface.held_detail`): a dict with the held proxy ids
        (c,) sorted, their targets (c, 3), ``groups`` (m,), the ``layout`` (Layout: the anchors' and
        the handle's detail held), ``pulls`` (two (s, m) drop-row matrices for DualLaplacian) and
        ``motions`` (identity, the handle's motion)."""
        from skin_detach_addon.core.detached_surface.held_detail import Layout, held_proxy_vertices

        handle = held_proxy_vertices(surface, self.handle_ids)
        anchors = np.setdiff1d(held_proxy_vertices(surface, self.anchor_ids), handle)
        rest = surface.proxy_vertices
        groups = np.full(rest.shape[0], -1, dtype=np.int64)
        groups[anchors], groups[handle] = 0, 1
        ids = np.flatnonzero(groups >= 0)
        targets = np.where((groups[ids] == 1)[:, None], self.move(rest[ids]), rest[ids])
        layout = Layout(groups, [(0, self.anchor_ids), (1, self.handle_ids)])
        pulls = surface.drop_rows([detail for _, detail in layout.held], groups)
        return dict(ids=ids, targets=targets, groups=groups, layout=layout, pulls=pulls,
                    motions=[np.eye(4), self.motion()])


def bend_scenario(points, angle_degrees=45.0, shift_fraction=0.25, band=0.10):
    """:class:`BendScenario` of ``points`` (n, 3)."""
    extent = points.max(axis=0) - points.min(axis=0)
    longest, middle, shortest = np.argsort(extent)[::-1]
    coordinate = points[:, longest]
    low, high = coordinate.min(), coordinate.max()
    anchors = np.flatnonzero(coordinate <= low + band * (high - low))
    handle = np.flatnonzero(coordinate >= high - band * (high - low))
    theta = np.radians(angle_degrees)
    axis = np.zeros(3)
    axis[shortest] = 1.0
    cross = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
    rotation = np.eye(3) + np.sin(theta) * cross + (1 - np.cos(theta)) * cross @ cross
    shift = np.zeros(3)
    shift[middle] = shift_fraction * extent[longest]
    return BendScenario(anchors, handle, rotation, points[handle].mean(axis=0), shift)
