"""A :class:`.surface.SkinDetachedSurface` kept as the little that cannot be recomputed quickly.

A built surface is the proxy, the carrier (the proxy vertex each welded detail vertex collapsed
into) and the skin bound from them; the skin is made from the detail mesh, the proxy and the
carrier by :func:`.prepared_mesh.prepare_mesh` and :func:`.skin.bind_skin` in a few seconds at
millions of vertices, and it is 2-3 times the mesh's own size. :func:`compact_arrays` keeps the
proxy, the carrier in the narrowest signed integer type its range allows, the topology fingerprint
and the build figures; :func:`surface_from_compact` makes the surface again from them and the
detail mesh with the same functions :meth:`.surface.SkinDetachedSurface.build` uses, so it is
bit for bit the one the build made.

    arrays = compact_arrays(surface)
    surface_from_compact(arrays, points (n, 3), triangles (f, 3)) -> SkinDetachedSurface

A :class:`.surface.Preview` is kept likewise (:func:`compact_preview_arrays`): its points,
triangles, carrier, representatives and riders; its skin is bound again from them over the
detail's proxy (:func:`preview_from_compact`), as the build bound it: the vertex normals of its own
triangles, the same :func:`.skin.bind_skin`.
"""

import hashlib
import json

import numpy as np

from ..errors import SkinDetachError
from ..geometry import half_edge_graph, vertex_normals
from .prepared_mesh import prepare_mesh
from .skin import bind_skin, check_coefficients
from .surface import FORMAT_TAG, FORMAT_VERSION, Preview, SkinDetachedSurface, topology_fingerprint
from ..validation import as_points, as_triangles

COMPACT_TAG = "skin_detach_compact_surface"
#: Tag of a preview kept compact (:func:`compact_preview_arrays`); a preview stored whole has
#: :data:`.surface.FORMAT_TAG`.
COMPACT_PREVIEW_TAG = "skin_detach_compact_preview"
#: Version of the compact arrays; others are refused.
COMPACT_VERSION = 1
#: Integer types a carrier may be stored in, narrowest first.
CARRIER_TYPES = (np.int8, np.int16, np.int32)
#: A proxy vertex lies within this many diagonals of the detail's bounding box (the build's do,
#: simplified from it); one farther is a damaged record.
PROXY_REACH = 10.0
#: Share of :func:`surface_from_compact`'s time each stage ends at (measured at 3.2M vertices).
STAGES = (("welding the mesh", 0.45), ("binding the skin", 1.0))


#: Elements hashed at a time by :func:`content_digests` (an integer array is widened to int64 a
#: piece at a time).
DIGEST_PIECE = 1 << 20


def content_digests(arrays):
    """{key: hex digest} of every value of ``arrays`` (a dict of numpy arrays, numbers, strings):
    what a stored binding holds, to tell it from well-formed but other data on reading (a carrier
    set to -1, a proxy vertex moved, a face flipped or dropped all pass the checks of shapes and
    ranges and deform the mesh wrong). The digest is of the values, not of how they are stored:
    numbers of any type hash alike (integers as int64, floats as float64: a float32 value is a float64
    one exactly), strings as UTF-8, every array flat."""
    digests = {}
    for key in sorted(arrays):
        value = arrays[key]
        digest = hashlib.blake2b(digest_size=16)
        if isinstance(value, (str, np.str_)) or (isinstance(value, np.ndarray) and value.dtype.kind in "US"):
            digest.update(b"s" + str(value).encode("utf-8"))
        else:
            flat = np.asarray(value).ravel()
            wide = np.dtype(np.int64) if flat.dtype.kind in "iub" else np.dtype(np.float64)
            digest.update(wide.str.encode("ascii"))
            for a in range(0, flat.shape[0], DIGEST_PIECE):
                digest.update(np.ascontiguousarray(flat[a:a + DIGEST_PIECE], dtype=wide).data)
        digests[key] = digest.hexdigest()
    return digests


def check_digests(arrays, expected, source):
    """Raise :class:`SkinDetachError` naming the first key of ``expected`` ({key: hex digest},
    :func:`content_digests` of what was stored) whose value in ``arrays`` is missing or has another
    digest: data changed after it was stored."""
    for key in sorted(expected):
        if key not in arrays:
            raise SkinDetachError(f"{source} {key}: expected the stored values the build wrote, it is missing; "
                                  f"rebuild the skin")
        found = content_digests({key: arrays[key]})[key]
        if found != expected[key]:
            raise SkinDetachError(f"{source} {key}: expected the values the build stored (digest "
                                  f"{expected[key][:12]}), got others (digest {found[:12]}): the binding was "
                                  f"changed outside Skin Detach; rebuild the skin")


def narrowest(values, low, high):
    """``values`` as the narrowest type of :data:`CARRIER_TYPES` that holds every integer of
    [``low``, ``high``] (a new array)."""
    for kind in CARRIER_TYPES:
        info = np.iinfo(kind)
        if info.min <= low and high <= info.max:
            return np.asarray(values).astype(kind)
    raise SkinDetachError(f"carrier: expected values within int32, got [{low}, {high}]")


def compact_arrays(surface):
    """Dict of plain arrays (numbers and 0-d strings) that :func:`surface_from_compact` reads back:
    the proxy (m, 3) float64 and (k, 3) int32, the carrier (u,) in the narrowest type holding
    [-1, m), the detail's topology fingerprint and the build figures (JSON)."""
    m = surface.proxy_vertices.shape[0]
    return {"format_tag": np.array(COMPACT_TAG), "format_version": np.array(COMPACT_VERSION),
            "proxy_vertices": surface.proxy_vertices, "proxy_faces": surface.proxy_faces.astype(np.int32),
            "carrier": narrowest(surface.carrier, -1, m - 1), "fingerprint": np.array(surface.fingerprint),
            "stats": np.array(json.dumps(surface.stats)), **surface.rider_arrays()}


def surface_from_compact(arrays, points, triangles, source="arrays", progress=None):
    """The :class:`SkinDetachedSurface` of ``arrays`` (:func:`compact_arrays`) over the detail mesh
    ``points`` (n, 3) (float32 or float64, the positions it was built from) and ``triangles``
    (f, 3), its detail triangles attached and its skin bound again as the build bound it.
    ``progress(fraction, stage)``, if given, is called before each stage. Anything malformed
    (wrong types, shapes or versions, a proxy index or a carrier out of range, another topology,
    unreadable figures) raises :class:`SkinDetachError` naming ``source`` and the field."""
    report = progress if progress is not None else (lambda fraction, stage: None)
    try:
        proxy_vertices, proxy_faces, carrier, fingerprint, stats = _checked(arrays, source)
    except SkinDetachError:
        raise
    except (TypeError, ValueError, KeyError, AttributeError, IndexError, OverflowError) as exc:
        raise SkinDetachError(f"{source}: expected the compact arrays of a Skin Detach binding, got malformed data "
                              f"({type(exc).__name__}: {exc}); rebuild the skin") from None
    points = as_points(f"{source} points", points)
    faces = as_triangles(f"{source} triangles", triangles, points.shape[0], narrow=True)
    if topology_fingerprint(points.shape[0], faces) != fingerprint:
        raise SkinDetachError(f"{source}: expected the detail topology it was built from, got another "
                              f"({points.shape[0]} vertices, {faces.shape[0]} triangles); rebuild the skin")
    low, high = points.min(axis=0), points.max(axis=0)
    reach = PROXY_REACH * max(float(np.linalg.norm(high - low)), 1e-300)
    if ((proxy_vertices < low - reach) | (proxy_vertices > high + reach)).any():
        raise SkinDetachError(f"{source} proxy_vertices: expected points within {PROXY_REACH:g} diagonals of the "
                              f"detail mesh's bounding box, got some as far as "
                              f"{float(np.abs(proxy_vertices).max()):.3g}; rebuild the skin")
    report(0.0, STAGES[0][0])
    mesh = prepare_mesh(points, faces, components=False)  # scipy's labelling holds the GIL: not needed
    u = mesh.points.shape[0]
    if carrier.shape != (u,):
        raise SkinDetachError(f"{source} carrier: expected ({u},) (one per welded detail vertex), got "
                              f"{carrier.shape}; rebuild the skin")
    report(STAGES[0][1], STAGES[1][0])
    skin, _ = bind_skin(mesh.points, mesh.normals, carrier, proxy_vertices, proxy_faces)
    check_coefficients(skin, source)
    surface = SkinDetachedSurface(proxy_vertices, proxy_faces, mesh.weld, carrier, skin, fingerprint, stats)
    edges = mesh.graph
    if mesh.degenerate.size:  # as the build gives them: every face's edges, dropped ones too
        edges = edges + half_edge_graph(mesh.degenerate, u)
    del mesh
    surface.attach_topology(faces, edges)
    if "rider_ids" in arrays:
        try:
            ids = np.asarray(arrays["rider_ids"]).astype(np.int64).ravel()
            starts = np.asarray(arrays["rider_starts"]).astype(np.int64).ravel()
        except (KeyError, TypeError, ValueError) as exc:
            raise SkinDetachError(f"{source}: expected rider_ids and rider_starts, got malformed data "
                                  f"({type(exc).__name__}: {exc}); rebuild the skin") from None
        still = np.asarray(arrays["still_ids"]).astype(np.int64).ravel() if "still_ids" in arrays else None
        surface.set_riders(ids, starts, points, still=still)
    report(STAGES[1][1], "done")
    return surface


def _checked(arrays, source):
    """(proxy vertices (m, 3) float64, proxy faces (k, 3) int64, carrier (u,) int64, fingerprint,
    stats dict) of ``arrays``, each checked."""
    if str(arrays.get("format_tag", "")) != COMPACT_TAG:
        raise SkinDetachError(f"{source}: expected format_tag {COMPACT_TAG!r}, got {str(arrays.get('format_tag'))!r}")
    version = int(arrays.get("format_version", -1))
    if version != COMPACT_VERSION:
        raise SkinDetachError(f"{source}: expected compact format version {COMPACT_VERSION}, got {version}; "
                              f"rebuild the skin")
    missing = {"proxy_vertices", "proxy_faces", "carrier", "fingerprint", "stats"} - arrays.keys()
    if missing:
        raise SkinDetachError(f"{source}: expected arrays {sorted(missing)}, they are missing")
    proxy_vertices = as_points(f"{source} proxy_vertices",
                               np.asarray(arrays["proxy_vertices"], dtype=np.float64).reshape(-1, 3))
    faces = np.asarray(arrays["proxy_faces"])
    if faces.dtype.kind not in "iu":
        raise SkinDetachError(f"{source} proxy_faces: expected integers, got {faces.dtype}; rebuild the skin")
    proxy_faces = as_triangles(f"{source} proxy_faces", faces.astype(np.int64).reshape(-1, 3),
                               proxy_vertices.shape[0])
    carrier = np.asarray(arrays["carrier"])
    if carrier.ndim != 1 or carrier.dtype.kind != "i":
        raise SkinDetachError(f"{source} carrier: expected a flat array of signed integers, got {carrier.shape} "
                              f"{carrier.dtype}; rebuild the skin")
    m = proxy_vertices.shape[0]
    if carrier.size and (carrier.min() < -1 or carrier.max() >= m):
        raise SkinDetachError(f"{source} carrier: expected proxy vertex ids in [-1, {m}), got values in "
                              f"[{int(carrier.min())}, {int(carrier.max())}]; rebuild the skin")
    stats = json.loads(str(arrays["stats"]))
    if not isinstance(stats, dict):
        raise SkinDetachError(f"{source}: expected the build figures as a JSON object, got {type(stats).__name__}")
    return proxy_vertices, proxy_faces, carrier.astype(np.int64), str(arrays["fingerprint"]), stats


def compact_preview_arrays(preview):
    """Dict of plain arrays that :func:`preview_from_compact` reads back: the preview's points
    (c, 3) float64, triangles (q, 3) int32, carrier (c,) int32, representatives (c,) int64 when it
    has them, its riders, the fingerprint and figures; not its skin, nor the proxy (the detail's)."""
    surface = preview.surface
    arrays = {"format_tag": np.array(COMPACT_PREVIEW_TAG), "format_version": np.array(COMPACT_VERSION),
              "points": preview.points, "triangles": np.asarray(preview.triangles).astype(np.int32),
              "carrier": np.asarray(surface.carrier).astype(np.int32), "fingerprint": np.array(surface.fingerprint),
              "stats": np.array(json.dumps(surface.stats)), **surface.rider_arrays()}
    if preview.representatives is not None:
        arrays["representatives"] = preview.representatives
    return arrays


def preview_from_compact(arrays, proxy_vertices, proxy_faces, source="arrays"):
    """The :class:`.surface.Preview` of ``arrays`` (:func:`compact_preview_arrays`) over the
    detail's proxy ``proxy_vertices`` (m, 3) and ``proxy_faces`` (k, 3), its skin bound again as
    the build bound it; the result is checked as :meth:`.surface.Preview.from_arrays` checks a
    preview stored whole. Anything malformed raises :class:`SkinDetachError` naming ``source``."""
    if str(arrays.get("format_tag", "")) != COMPACT_PREVIEW_TAG:
        raise SkinDetachError(f"{source}: expected format_tag {COMPACT_PREVIEW_TAG!r}, got "
                              f"{str(arrays.get('format_tag'))!r}; rebuild the skin")
    missing = {"points", "triangles", "carrier", "fingerprint", "stats"} - arrays.keys()
    if missing:
        raise SkinDetachError(f"{source}: expected arrays {sorted(missing)}, they are missing; rebuild the skin")
    try:
        version = int(arrays.get("format_version", -1))
        points = as_points(f"{source} points", np.asarray(arrays["points"], dtype=np.float64).reshape(-1, 3))
        faces = np.asarray(arrays["triangles"])
        carrier = np.asarray(arrays["carrier"])
        if faces.dtype.kind not in "iu" or carrier.dtype.kind not in "iu":
            raise SkinDetachError(f"{source} triangles and carrier: expected integers, got {faces.dtype} and "
                                  f"{carrier.dtype}; rebuild the skin")
        triangles = as_triangles(f"{source} triangles", faces.astype(np.int64).reshape(-1, 3), points.shape[0])
        carrier = carrier.astype(np.int64).ravel()
    except (TypeError, ValueError) as exc:
        raise SkinDetachError(f"{source}: expected the compact arrays of a preview, got malformed data "
                              f"({type(exc).__name__}: {exc}); rebuild the skin") from None
    if version != COMPACT_VERSION:
        raise SkinDetachError(f"{source}: expected compact format version {COMPACT_VERSION}, got {version}; "
                              f"rebuild the skin")
    c, m = points.shape[0], proxy_vertices.shape[0]
    if carrier.shape != (c,) or (carrier.size and (carrier.min() < -1 or carrier.max() >= m)):
        raise SkinDetachError(f"{source} carrier: expected ({c},) proxy vertex ids in [-1, {m}), got {carrier.shape} "
                              f"in [{carrier.min(initial=0)}, {carrier.max(initial=0)}]; rebuild the skin")
    skin, _ = bind_skin(points, vertex_normals(points, triangles), carrier, proxy_vertices, proxy_faces)
    whole = {f"skin_{name}": getattr(skin, name) for name in ("vertex", "face", "bary", "height", "weight", "case")}
    whole.update({key: arrays[key] for key in ("fingerprint", "stats", "representatives", "rider_ids",
                                               "rider_starts", "still_ids") if key in arrays})
    whole.update(format_tag=np.array(FORMAT_TAG), format_version=np.array(FORMAT_VERSION), points=points,
                 triangles=triangles, proxy_vertices=proxy_vertices, proxy_faces=proxy_faces, weld=np.arange(c),
                 carrier=carrier)
    return Preview.from_arrays(whole, source)
