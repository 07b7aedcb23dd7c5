"""The figures of a binding the panel and :func:`api.figures` show: the core build figures
stored with the binding, and the last step's figures of this session."""

import json

from . import binding as stored

#: Build figures the add-on reads back, and the type each must have (a damaged one is dropped).
_COUNTS = ("detail_vertices", "proxy_vertices", "proxy_faces", "target_faces", "preview_vertices")


def last_step(obj):
    """Figures of the last step of ``obj``'s binding in this session (dict), or None."""
    binding = stored.cached(obj)
    return None if binding is None else binding.last_step


def stats_of(obj):
    """The core build figures stored with the binding (dict), or {} (also when unreadable). Counts
    that are not non-negative integers, ``seconds`` that is not a dict of numbers and a
    ``target_reached`` that is not a bool are left out, so readers may trust what is there."""
    record = stored.readable_record(obj)
    if record is None:
        return {}
    try:
        stats = json.loads(str(record.get("stats", "{}")))
    except ValueError:
        return {}
    if not isinstance(stats, dict):
        return {}
    for key in _COUNTS:
        value = stats.get(key)
        if key in stats and (isinstance(value, bool) or not isinstance(value, int) or value < 0):
            del stats[key]
    seconds = stats.get("seconds")
    if "seconds" in stats and not (isinstance(seconds, dict) and all(
            isinstance(v, (int, float)) and not isinstance(v, bool) for v in seconds.values())):
        del stats["seconds"]
    if "target_reached" in stats and not isinstance(stats["target_reached"], bool):
        del stats["target_reached"]
    return stats
