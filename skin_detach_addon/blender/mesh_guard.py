"""The guard of a bound mesh while a drag shows its preview and never snapshots the mesh itself."""

from . import mesh_io


class MeshGuard:
    """Keeps the mesh's state for the cancel of a drag that shows the preview: such a drag writes
    the mesh only in its confirm, so it snapshots only the proxy and the handles; should anything
    else write the mesh meanwhile (a save settling the preview), the guard keeps the mesh's
    snapshot (:func:`mesh_io.snapshot`) from before that write, for the cancel to restore.

    armed     a previewing drag runs (between :meth:`arm` and :meth:`release`)
    snapshot  the mesh's snapshot kept before the first write while armed, or None
    """

    def __init__(self):
        self.armed = False
        self.snapshot = None

    def arm(self):
        """A previewing drag starts: the next write of the mesh keeps its snapshot first."""
        self.armed, self.snapshot = True, None

    def before_write(self, mesh=None, take=None):
        """The bound ``mesh`` is about to be written: keep its snapshot when armed and none is kept
        yet (``take()``, instead, makes the snapshot: every object of a rig of several)."""
        if self.armed and self.snapshot is None:
            self.snapshot = take() if take is not None else mesh_io.snapshot(mesh)

    def release(self):
        """The drag ends: disarm and return the snapshot kept meanwhile, or None (not written)."""
        kept = self.snapshot
        self.armed, self.snapshot = False, None
        return kept
