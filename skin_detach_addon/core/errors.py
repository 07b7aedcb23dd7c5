"""The project's own exception type.

Everything in ``core`` that rejects input raises :class:`SkinDetachError`; the Blender
operators turn it into an error report in one place.
"""


class SkinDetachError(ValueError):
    """Bad input or stale data: the message names the argument, the expected and the actual value."""
