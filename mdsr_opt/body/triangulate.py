"""Quality triangulation of a polygon with Shewchuk's Triangle: its size foreseen, its work capped, its angles
kept.

How many triangles a quality mesh needs is known before Triangle runs. Away from the boundary the area bound
sets it (about 1.6 triangles per ``max_area``); in a part of the body only ``w`` wide, the smallest angle
forces triangles about ``w`` across whatever the area bound, so a strip of length ``L`` and width ``w`` takes
about ``2 L / w`` triangles, and a run of edges shorter than the area bound's size puts a few triangles at
each. :func:`expected_triangles` adds these up; the widths come from openings of the body (shrunk by ``r``
and grown back with mitred corners, which removes exactly the parts narrower than ``2 r``), at radii falling
by ``sqrt(2)`` from the area bound's size until nothing narrower is left. A gap across a hole or a notch does
not count: Triangle refines only inside the body.

:func:`quality_triangulation` runs Triangle with a cap on the points it may add, so even a request the
estimate misjudges cannot exhaust memory, and then repairs the angles that Triangle leaves below the bound on
purpose: near an input corner narrower than 60 degrees, Triangle splits both edges at the same distances
from the corner ("concentric shells") and never splits a skinny triangle whose shortest edge joins two such
points, which guarantees termination but leaves angles down to about 20 degrees one triangle away from the
corner. A refinement pass (``r``) with those triangles' area bound halved splits them; every triangle then
meets ``min_angle`` (one pass has repaired every one of some 2000 fuzzed outlines).

Example
-------
>>> import numpy as np
>>> strip = np.array([[0, 0], [1, 0], [1, 1e-3], [0, 1e-3]])
>>> n, thin = expected_triangles([strip], max_area=1e-3, limit=1000)  # about 2000, over the limit
>>> n > 1000, round(thin.width, 6), round(thin.length, 2), thin.rings
(True, 0.001, 1.0, (0,))
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import shapely
import triangle as tr

from .polygons import corner_angles, triangle_angles

__all__ = ["ThinPart", "expected_triangles", "too_many_triangles", "quality_triangulation", "to_given_coordinates",
           "triangle_min_angles", "TRIANGLES_PER_AREA"]

#: Triangles per unit of ``area / max_area`` that Triangle makes when the area bound governs (measured:
#: 1.55 at min_angle 20, 1.58 at 30, 1.71 at 33, on squares, strips and discs of 1e3 to 1e6 triangles).
TRIANGLES_PER_AREA = 1.6
#: Triangles per ``w**2`` of a part ``w`` wide. Triangle splits a strip's sides at powers of two, so a strip
#: takes between 1.6 and 2.6 ``L / w`` triangles (measured at w = 1e-2 ... 1e-6, min_angle 30); the estimate
#: takes the upper end.
_TRIANGLES_PER_WIDTH2 = 2.6
#: Triangles at each boundary edge shorter than the area bound's size (measured: 4.2 to 4.7 on polygonal
#: discs of 100 to 10000 edges).
_TRIANGLES_PER_SHORT_EDGE = 5.0
#: Refinement passes that repair angles below the bound; one has always sufficed on the fuzzed outlines.
_REPAIR_PASSES = 4


@dataclass(frozen=True)
class ThinPart:
    """The part of a body whose width drives the triangle count, in the coordinates it was measured in.

    ``width`` is its width, ``length`` its area over its width, ``where`` a point inside it, ``rings`` the
    indices of the rings (0 the outline, 1... the holes) that bound it, and ``triangles`` the triangles it
    alone needs.
    """

    width: float
    length: float
    where: tuple[float, float]
    rings: tuple[int, ...]
    triangles: float


def _opening(body, r: float, mitre_limit: float, grow: float = 1.0):
    """The body without its parts narrower than ``2 r``: shrunk by ``r`` and grown back by ``grow r``,
    corners mitred.

    Mitred joins give every part at least ``2 r`` wide back, sharp corners included (round joins would cut
    each corner's tip, which is no thin part). Where an edge shorter than about ``r`` vanished in the
    shrinking, the grown body reaches past the body's own corner; only what it misses counts (see
    :func:`_narrower`).
    """
    return body.buffer(-r, join_style="mitre", mitre_limit=mitre_limit).buffer(
        grow * r, join_style="mitre", mitre_limit=mitre_limit)


def _narrower(body, r: float, mitre_limit: float) -> tuple[object, float]:
    """The parts of ``body`` narrower than about ``2 r``, and a bound on the error of their area.

    The body is first simplified to within ``r / 8`` (a jagged outline many times finer than ``r`` makes
    GEOS's offset curves loop on themselves, at a cost that grows with ``n r / spacing``), which moves a
    part's width by at most ``r / 4``. It is grown back ``r / 2**20`` further than it was shrunk, so the
    grown body's edges do not lie on the body's own (GEOS decides nearly shared edges slowly, or not at
    all); that leaves out a sliver ``r / 2**20`` wide of each thin part. Where GEOS still finds edges too
    close to decide (a ``TopologyException``), the difference is taken on a grid of ``r / 2**20``.
    """
    b = shapely.simplify(body, r / 8.0, preserve_topology=True)
    opened = _opening(b, r, mitre_limit, grow=1.0 + 2.0 ** -20)
    if not opened.is_valid:  # the grown pieces may touch: GEOS then returns an invalid multipolygon
        opened = opened.buffer(0)
    try:
        return shapely.difference(b, opened), 0.0
    except shapely.errors.GEOSException:
        grid = r * 2.0 ** -20
        return shapely.difference(b, opened, grid_size=grid), grid * (b.length + opened.length)


def expected_triangles(rings: list[np.ndarray], max_area: float, limit: float) -> tuple[float, ThinPart | None]:
    """The number of triangles a quality mesh of a polygon needs, foreseen from its area and its thin parts.

    Parameters
    ----------
    rings : list of (k, 2) arrays
        The outline and the holes, valid and disjoint, in coordinates of about unit size (the openings
        stop at radius ``1e-12``).
    max_area : float
        The area bound, in the same units squared.
    limit : float
        Stop measuring once the count exceeds this (the answer is then a lower bound).

    Returns
    -------
    count : float
        The expected number of triangles: 0.8 to 3.2 times what Triangle makes on strips, needles, gaps,
        rings, combs and fuzzed outlines of more than 3000 triangles (at min_angle 20 and 30; the high
        end for thin parts at small angles, where Triangle needs fewer).
    thin : ThinPart or None
        The part narrower than ``sqrt(max_area)`` that adds most triangles, or None if there is none; its
        width is measured to 0.1 % when ``count`` exceeds ``limit``, else to about 20 %.
    """
    body = shapely.Polygon(rings[0], holes=rings[1:])
    area, perimeter = float(body.area), float(body.length)
    h = float(np.sqrt(max_area))
    edges = np.concatenate([np.linalg.norm(np.roll(r, -1, axis=0) - r, axis=1) for r in rings])
    count = TRIANGLES_PER_AREA * area / max_area + _TRIANGLES_PER_SHORT_EDGE * float(np.sum(edges < h))
    ang = np.concatenate([corner_angles(r) for r in rings])
    sharpest = np.radians(min(np.min(ang), np.min(360.0 - ang)))
    mitre = 2.0 / np.sin(sharpest / 2.0)  # no corner of the body or of its outside is bevelled
    # openings at radii falling by sqrt(2): what the opening of radius r removes is narrower than 2 r
    r, prev, best = 0.5 * h, None, None
    while r > 1e-12:
        try:
            removed, error = _narrower(body, r, mitre)
        except shapely.errors.GEOSException:  # GEOS could not offset this outline: what is counted stands
            break                              # (Triangle's cap on added points still bounds the work)
        if prev is not None:  # the band narrower than 2 r_prev but not than 2 r: width about 2 r_prev / 2**0.25
            r0, g0 = prev
            w = 2.0 * r0 * 2.0 ** -0.25
            band = max(g0.area - removed.area, 0.0)
            extra = band * max(_TRIANGLES_PER_WIDTH2 / (w * w) - TRIANGLES_PER_AREA / max_area, 0.0)
            count += extra
            if extra > 0 and (best is None or extra > best[0]):
                best = (extra, w, band, r0, g0, removed)
            if count > limit:
                break
        # nothing narrower than 2 r is left: the removed area is rounding (an ulp along the boundary)
        if removed.area <= 1e-14 * perimeter + error:
            break
        prev = (r, removed)
        r /= np.sqrt(2.0)
    if best is None:
        return float(count), None
    extra, w, band, r0, wider, narrower = best
    try:
        region = shapely.difference(wider, narrower)
    except shapely.errors.GEOSException:
        region = wider
    parts = [g for g in getattr(region, "geoms", [region]) if not g.is_empty]
    p = max(parts, key=lambda g: g.area).representative_point() if parts else wider.representative_point()
    lo, hi = r0 / 2.0, r0  # p is narrower than 2 hi, not than 2 lo
    try:
        for _ in range(10 if count > limit else 0):  # its width for a refusal: twice the radius at which
            mid = np.sqrt(lo * hi)                   # the opening removes it, to 0.1 %
            lo, hi = (lo, mid) if shapely.contains_xy(_narrower(body, mid, mitre)[0], p.x, p.y) else (mid, hi)
        w = lo + hi if count > limit else w
    except shapely.errors.GEOSException:
        pass  # the band's width stands
    dist = [float(shapely.distance(shapely.linearrings(ring), p)) for ring in rings]
    near = tuple(i for i, d in enumerate(dist) if d <= w) or (int(np.argmin(dist)),)
    return float(count), ThinPart(width=float(w), length=float(band / w), where=(float(p.x), float(p.y)),
                                  rings=near, triangles=float(extra))


def too_many_triangles(expected: float, thin: ThinPart | None, names: list[str], scale: float,
                       centre: np.ndarray, max_area: float, limit: int) -> str:
    """Why a request is refused: ``expected`` triangles, over ``limit``, with the thin part that drives them.

    ``thin`` was measured in coordinates ``(x - centre) / scale``; the message gives the user's coordinates.
    ``names`` names the rings (the outline first).
    """
    if thin is None:
        return (f"the outline and holes would make about {expected:.3g} triangles at max_area={max_area:.6g} "
                f"(their many short edges take a few each), more than the limit max_triangles={limit}; "
                "simplify the outline, or raise the limit with max_triangles= (Mesh.from_polygon)")
    w, length = thin.width * scale, thin.length * scale
    x, y = np.asarray(thin.where) * scale + centre
    sides = [names[i] for i in thin.rings]
    if sides == ["outline"]:
        what = "the outline is"
    elif len(sides) == 1:
        what = f"the body beside {sides[0]} is"
    else:
        what = "the body between " + " and ".join(("the outline" if n == "outline" else n) for n in sides) + " is"
    rest = limit - (expected - thin.triangles)
    fits = (f"at that length it must be at least about {w * thin.triangles / rest:.3g} wide to fit the limit"
            if rest > 0 else "the rest of the body alone reaches the limit")
    return (f"{what} only about {w:.3g} wide near ({x:.6g}, {y:.6g}), over a length of about {length:.3g}: a "
            f"quality mesh needs triangles about that small there whatever max_area is, about {expected:.3g} "
            f"triangles in all, more than the limit max_triangles={limit}; {fits}. Widen that part or simplify "
            "the outline there, or raise the limit with max_triangles= (Mesh.from_polygon)")


def triangle_min_angles(vertices: np.ndarray, triangles: np.ndarray) -> np.ndarray:
    """The smallest interior angle of each triangle, in degrees."""
    return triangle_angles(vertices, triangles).min(axis=1)


def _switch_number(value: float) -> str:
    """A number as Triangle's command line reads it: digits and a point, never an exponent.

    Triangle's switch parser takes only ``0-9`` and ``.`` after ``a`` or ``q``; ``1e-05`` would be read as
    ``1`` (and ``e`` as another switch), which silently meshes far coarser than asked.
    """
    return np.format_float_positional(float(value), trim="-")


def quality_triangulation(vertices: np.ndarray, segments: np.ndarray, holes: np.ndarray | None,
                          min_angle: float, max_area: float,
                          max_steiner: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, bool]:
    """Quality-mesh a planar straight-line graph with Triangle, adding at most ``max_steiner`` points.

    Parameters
    ----------
    vertices, segments, holes
        Triangle's input: the rings' vertices, their segments and one point inside each hole (or None).
    min_angle : float
        Smallest angle in degrees; every corner of the input must be at least this wide.
    max_area : float
        Largest triangle area.
    max_steiner : int
        Most points Triangle may add (its ``S`` switch): the work and memory it takes are bounded by it.

    Returns
    -------
    points : (n, 2) array
        The input vertices first, in order, then the added ones.
    triangles : (m, 3) int array
    on_segment : (n,) int array
        For a point added on an input segment, that segment's row in ``segments``; -1 for the input
        vertices and the points inside.
    capped : bool
        Triangle stopped at ``max_steiner`` added points, leaving the mesh short of the bounds.

    An angle may still be below ``min_angle`` if the repair passes run out of points or passes (never seen
    on fuzzed outlines); the caller measures the result.
    """
    n_in = len(vertices)
    q, a = _switch_number(min_angle), _switch_number(max_area)
    data = {"vertices": vertices, "segments": segments, "segment_markers": np.arange(len(segments)) + 2}
    if holes is not None and len(holes):
        data["holes"] = holes
    out = tr.triangulate(data, f"pq{q}a{a}QS{int(max_steiner)}")
    for _ in range(_REPAIR_PASSES):
        v, t = np.asarray(out["vertices"], dtype=float), np.asarray(out["triangles"], dtype=np.int64)
        left = int(max_steiner) - (len(v) - n_in)
        bad = triangle_min_angles(v, t) < min_angle - 1e-6
        if not bad.any() or left <= 0:
            break
        # Triangle spares these on purpose (their shortest edge joins points it put at equal distances from
        # an input corner); in a refinement pass a bound of half their area makes it split them
        d1, d2 = v[t[:, 1]] - v[t[:, 0]], v[t[:, 2]] - v[t[:, 0]]
        bound = np.where(bad, 0.25 * np.abs(d1[:, 0] * d2[:, 1] - d1[:, 1] * d2[:, 0]), -1.0)
        out = tr.triangulate({"vertices": v, "triangles": t, "segments": out["segments"],
                              "segment_markers": out["segment_markers"], "triangle_max_area": bound},
                             f"rpq{q}a{a}aQS{left}")
    v, t = np.asarray(out["vertices"], dtype=float), np.asarray(out["triangles"], dtype=np.int64)
    on_segment = np.full(len(v), -1, dtype=np.int64)
    sub = np.asarray(out["segments"], dtype=np.int64)
    marker = np.asarray(out["segment_markers"], dtype=np.int64).ravel() - 2
    ours = marker >= 0  # every input segment carries its row + 2; Triangle's own markers are 0 and 1
    on_segment[sub[ours, 0]] = marker[ours]
    on_segment[sub[ours, 1]] = marker[ours]
    on_segment[:n_in] = -1
    return v, t, on_segment, len(v) - n_in >= int(max_steiner)


def to_given_coordinates(v: np.ndarray, tri: np.ndarray, on_segment: np.ndarray, segs: np.ndarray,
                         given: np.ndarray, scale: float, centre: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """A triangulation of the unit-size copy of a polygon (:func:`quality_triangulation`'s vertices ``v``,
    triangles ``tri`` and the input segment each vertex lies on, or -1) in the polygon's own coordinates:
    scaled by ``scale`` and moved by ``centre``, the input vertices ``given`` exactly as given (Triangle keeps
    them first), boundary points put onto the given segments, unused vertices dropped, every triangle
    counter-clockwise. Returns ``(points, triangles)``."""
    pts = v * scale + centre
    pts[:len(given)] = given
    k = np.flatnonzero(on_segment >= 0)
    i, j = segs[on_segment[k], 0], segs[on_segment[k], 1]
    ua, ub = v[i], v[j]
    t = np.einsum("ij,ij->i", v[k] - ua, ub - ua) / np.einsum("ij,ij->i", ub - ua, ub - ua)
    pts[k] = given[i] + t[:, None] * (given[j] - given[i])
    used = np.flatnonzero(np.bincount(tri.ravel(), minlength=len(pts)))
    if len(used) != len(pts):  # vertices left outside (never expected with 'p')
        remap = -np.ones(len(pts), dtype=np.int64)
        remap[used] = np.arange(len(used))
        pts, tri = pts[used], remap[tri]
    d1, d2 = pts[tri[:, 1]] - pts[tri[:, 0]], pts[tri[:, 2]] - pts[tri[:, 0]]
    cw = d1[:, 0] * d2[:, 1] - d1[:, 1] * d2[:, 0] < 0
    tri[cw] = tri[cw][:, ::-1]
    return pts, tri
