"""What a workshop can build: the rope's channel, the wall around it and the end fixtures (:class:`Fabrication`).

A rope runs in a moulded channel of diameter ``channel_diameter`` with a ``wall`` of material around it, and
ends on a fixture (a bead, a knot, a washer plate) of radius ``fixture_radius``. A rope node is admissible
when it lies at least :meth:`Fabrication.clearance` inside the outline and every hole: the larger of half the
channel plus the wall and ``min_inset_fraction`` of the body's diameter (default :data:`MIN_INSET_FRACTION`,
2 %; a slender body needs less, see :class:`Fabrication`); an end fixture fits
when its disk of radius ``fixture_radius + wall`` lies inside the body. ``fixture_radius`` is what the
design calls ``anchor_radius`` (the rigid end patch is the fixture). The routing may shrink the fixtures down
to ``min_fixture_radius`` to keep a muscle (see :mod:`mdsr_opt.synthesis.routing_fixtures`). Ropes of different
muscles need ``channel_diameter + wall`` between their centre lines and must not cross; their fixtures need
``2 fixture_radius + wall`` between centres. The routing keeps all this; :func:`rope_conflicts` finds where a
layout (muscles a user gives, a layout merged from several poses) breaks it, and the design and the export
warn with a :class:`FabricationWarning`.

Defaults: fractions of the body's size, not millimetres
-------------------------------------------------------
Every length is in the body's own unit. A field left None takes a default that is a fraction of the body's
diameter ``D`` (:func:`~mdsr_opt.mechanics.anchors.body_size`): channel 1 % of ``D``, wall 1 %, fixture
radius 4 % (:data:`~mdsr_opt.mechanics.anchors.ANCHOR_FRACTION`, the design's default ``anchor_radius``),
smallest fixture 1.5 %. For the cast silicone bodies these tools are made for (50 to 200 mm across; 100 mm
typical) that is a 1 mm core pin for a 0.3-0.5 mm braided line, a 1 mm wall, an 8 mm washer or bead and a
3 mm knot at the smallest -- what a workshop uses. They are fractions and not millimetres converted to the
scene's ``units`` because a scene's unit is often nominal: the library's bodies are 4 "mm" strips that
stand for any size, and 1 mm channels would not fit in them at all, while a body given in metres or inches
gets the same proportions. A workshop with its own parts gives them in the body's unit
(``Fabrication(channel_diameter=1.2, wall=1.5, fixture_radius=3.0)`` for a body in mm, or the scene file's
``[fabrication]`` table).

Example
-------
>>> from mdsr_opt import Mesh
>>> mesh = Mesh.rectangle(100.0, 60.0, 20, 12)               # a 100 x 60 mm plate (diameter 116.6 mm)
>>> fab = Fabrication().for_body(mesh)
>>> round(fab.channel_diameter, 3), round(fab.wall, 3), round(fab.fixture_radius, 3)
(1.166, 1.166, 4.665)
>>> round(Fabrication(channel_diameter=2.0, wall=2.0).clearance(mesh), 3)   # 2/2 + 2 = 3 > 2 % of 116.6
3.0
"""

from __future__ import annotations

import math
import numbers
from dataclasses import asdict, dataclass, fields, replace
from typing import Mapping

import numpy as np

from ..core.errors import LayoutError
from ..mechanics.anchors import ANCHOR_FRACTION, MAX_ANCHOR_FRACTION, body_size

__all__ = ["Fabrication", "CHANNEL_FRACTION", "WALL_FRACTION", "MIN_FIXTURE_FRACTION", "MIN_INSET_FRACTION",
           "boundary_distance", "segment_insets", "deepest_edge", "body_depth", "no_band_message", "check_fabrication",
           "admissible_edges", "FabricationWarning",
           "Conflict", "rope_conflicts", "warn_conflicts", "check_sizes_fit",
           "pair_conflicts", "check_channel_fits"]

#: Default channel diameter, as a fraction of the body's diameter.
CHANNEL_FRACTION = 0.01
#: Default wall around a channel or a fixture, as a fraction of the body's diameter.
WALL_FRACTION = 0.01
#: Default smallest fixture the routing may shrink an end to, as a fraction of the body's diameter.
MIN_FIXTURE_FRACTION = 0.015
#: Every rope node lies at least this fraction of the body's diameter inside the outline and the holes: the
#: default of :attr:`Fabrication.min_inset_fraction`.
MIN_INSET_FRACTION = 0.02


class FabricationWarning(UserWarning):
    """A rope that cannot be moulded as laid out: its channel or fixture reaches outside the body, or comes
    closer to another rope's channel or fixture than a wall (:func:`rope_conflicts`)."""


@dataclass(frozen=True)
class Fabrication:
    """The channel, wall and end fixtures a workshop builds the robot with (lengths in the body's unit).

    Parameters
    ----------
    channel_diameter : float, optional
        Diameter of the moulded channel a rope runs in (>= 0); default 1 % of the body's diameter.
    wall : float, optional
        Least material around a channel and around a fixture (>= 0); default 1 % of the diameter.
    fixture_radius : float, optional
        Radius of the fixture (bead, knot, plate) at each rope end, which is the design's ``anchor_radius``
        (>= 0); default 4 % of the diameter.
    min_fixture_radius : float, optional
        The smallest fixture the routing may shrink the ends to when the full size does not fit (>= 0, at
        most ``fixture_radius``); default 1.5 % of the diameter, or ``fixture_radius`` if that is smaller.
        Give ``min_fixture_radius = fixture_radius`` to forbid shrinking.
    min_inset_fraction : float, optional
        The least inset of a routed rope node as a fraction of the body's diameter, a fraction in
        ``[0, 0.5)`` and not a length: a rope node lies at least the larger of ``channel_diameter / 2 + wall``
        and ``min_inset_fraction`` times the diameter inside the outline and every hole. Default
        :data:`MIN_INSET_FRACTION` (2 %), which keeps a rope off the outline when the channel and wall are
        small beside the body. A body thinner than about twice that fraction of its length (a slender
        tentacle) has no room for it: give a smaller fraction, or 0 to let the channel and wall alone decide.

    Raises
    ------
    TypeError, ValueError
        A field that is not a real number, negative or not finite (the message names it),
        ``min_fixture_radius > fixture_radius``, or ``min_inset_fraction >= 0.5`` (no body is that deep).
    """

    channel_diameter: float | None = None
    wall: float | None = None
    fixture_radius: float | None = None
    min_fixture_radius: float | None = None
    min_inset_fraction: float | None = None

    def __post_init__(self):
        for f in fields(self):
            v = getattr(self, f.name)
            if v is None:
                continue
            what = "a fraction" if f.name == "min_inset_fraction" else "a length"
            if isinstance(v, bool) or not isinstance(v, numbers.Real):
                raise TypeError(f"Fabrication: {f.name} must be {what} (a real number), got {type(v).__name__}")
            if not math.isfinite(float(v)) or float(v) < 0:
                raise ValueError(f"Fabrication: {f.name} must be a finite {what[2:]} >= 0, got {v!r}")
            object.__setattr__(self, f.name, float(v))
        if self.min_inset_fraction is not None and self.min_inset_fraction >= 0.5:
            raise ValueError(f"Fabrication: min_inset_fraction must be below 0.5 (a fraction of the body's diameter: "
                             f"no point of a body lies half its diameter inside it), got {self.min_inset_fraction:g}")
        if (self.fixture_radius is not None and self.min_fixture_radius is not None
                and self.min_fixture_radius > self.fixture_radius):
            raise ValueError(f"Fabrication: min_fixture_radius {self.min_fixture_radius:g} is larger than "
                             f"fixture_radius {self.fixture_radius:g}")

    def for_body(self, mesh) -> "Fabrication":
        """This spec with every field set: the defaults (fractions of ``mesh``'s diameter) for those left None.

        Raises :class:`~mdsr_opt.core.errors.LayoutError` (a ``ValueError``) for a fixture at least half the
        body's size (it would hold most of it)."""
        D = body_size(mesh)
        r = ANCHOR_FRACTION * D if self.fixture_radius is None else self.fixture_radius
        if r >= MAX_ANCHOR_FRACTION * D:
            raise LayoutError(f"Fabrication: fixture_radius {r:g} is at least half the body's size ({D:.3g}): a "
                              "muscle's end fixture would hold most of the body")
        r_min = min(r, MIN_FIXTURE_FRACTION * D) if self.min_fixture_radius is None else self.min_fixture_radius
        return Fabrication(channel_diameter=CHANNEL_FRACTION * D if self.channel_diameter is None
                           else self.channel_diameter, wall=WALL_FRACTION * D if self.wall is None else self.wall,
                           fixture_radius=r, min_fixture_radius=r_min,
                           min_inset_fraction=MIN_INSET_FRACTION if self.min_inset_fraction is None
                           else self.min_inset_fraction)

    def clearance(self, mesh) -> float:
        """How far inside the outline and the holes every rope node lies: the larger of ``channel_diameter / 2
        + wall`` and ``min_inset_fraction`` (default :data:`MIN_INSET_FRACTION`) of the body's diameter."""
        f = self.for_body(mesh)
        return max(0.5 * f.channel_diameter + f.wall, f.min_inset_fraction * body_size(mesh))

    def to_dict(self) -> dict:
        """The fields as a JSON-ready dict (None: the default)."""
        return asdict(self)


def check_fabrication(fabrication, anchor_radius=None) -> Fabrication | bool:
    """``fabrication`` as a :class:`Fabrication`: one, a mapping of its fields (a scene file's
    ``[fabrication]`` table), or None (all defaults); False (no fabrication: the routing search alone) is
    returned as it is. ``anchor_radius``, when given, is the fixture radius if
    the spec leaves it open; a spec that states another one is refused (the two name one thing)."""
    if fabrication is False or isinstance(fabrication, np.bool_) and not fabrication:
        return False  # the routing search alone (route_muscles), passed on as given
    if fabrication is None:
        fab = Fabrication()
    elif isinstance(fabrication, Fabrication):
        fab = fabrication
    elif isinstance(fabrication, Mapping):
        unknown = sorted(set(map(str, fabrication)) - {f.name for f in fields(Fabrication)})
        if unknown:
            raise ValueError(f"fabrication: unknown field(s) {', '.join(unknown)}; expected "
                             f"{', '.join(f.name for f in fields(Fabrication))}")
        fab = Fabrication(**dict(fabrication))
    else:
        raise TypeError(f"fabrication must be a Fabrication, a dict of its fields, None (the defaults) or False "
                        f"(route_muscles: the search alone), got "
                        f"{type(fabrication).__name__}")
    if anchor_radius is not None:
        if fab.fixture_radius is None:
            fab = replace(fab, fixture_radius=float(anchor_radius))
            if fab.min_fixture_radius is not None and fab.min_fixture_radius > fab.fixture_radius:
                fab = replace(fab, min_fixture_radius=fab.fixture_radius)
        elif not math.isclose(fab.fixture_radius, float(anchor_radius), rel_tol=1e-12, abs_tol=0.0):
            raise ValueError(f"anchor_radius {float(anchor_radius):g} and fabrication.fixture_radius "
                             f"{fab.fixture_radius:g} differ: they are one thing (the end fixture's radius); "
                             "give one of them")
    return fab


def boundary_distance(mesh) -> np.ndarray:
    """Each node's distance at rest from the body's boundary (the outline and every hole), read-only and cached
    on the mesh; boundary nodes have 0."""
    cache = mesh.__dict__
    if "_boundary_distance" not in cache:
        import shapely

        d = shapely.distance(shapely.points(mesh.points), _boundary_lines(mesh))
        d[mesh.boundary_nodes] = 0.0
        d.flags.writeable = False
        cache["_boundary_distance"] = d
    return cache["_boundary_distance"]


def _boundary_at(mesh, at) -> str:
    """The words for the boundary loop of ``mesh`` at rest nearest the point ``at``: ``"the outline"``, or
    ``"the edge of the hole around (x, y)"`` (its nodes' mean: holes are not numbered alike everywhere)."""
    from shapely.geometry import LineString, Point

    P, loops = mesh.points, mesh.boundary_loops
    d = [LineString(np.vstack([P[lp], P[lp[:1]]])).distance(Point(at)) for lp in loops]
    k = int(np.argmin(d))
    if k == 0:
        return "the outline"
    c = P[loops[k]].mean(axis=0)
    return f"the edge of the hole around ({c[0]:.4g}, {c[1]:.4g})"


def _boundary_lines(mesh):
    """The body's boundary at rest (the outline and every hole) as one shapely MultiLineString, cached on the
    mesh."""
    cache = mesh.__dict__
    if "_boundary_lines" not in cache:
        from shapely.geometry import MultiLineString

        P = mesh.points
        cache["_boundary_lines"] = MultiLineString([np.vstack([P[lp], P[lp[:1]]]) for lp in mesh.boundary_loops])
    return cache["_boundary_lines"]


def segment_insets(mesh, edges: np.ndarray) -> np.ndarray:
    """The distance at rest of each segment ``edges`` (k, 2 node ids) from the body's boundary: at most its
    nodes' :func:`boundary_distance`, less where the segment passes a reflex corner of the outline or a hole."""
    import shapely

    E = np.asarray(edges, dtype=np.int64).reshape(-1, 2)
    if not len(E):
        return np.zeros(0)
    P = mesh.points
    return shapely.distance(shapely.linestrings(P[E.reshape(-1)].reshape(-1, 2, 2)), _boundary_lines(mesh))


def body_depth(mesh) -> float:
    """The radius of the largest disk inside the body at rest (outline minus holes), cached on the mesh (the
    pipeline's door and each of its routings ask for it)."""
    cache = mesh.__dict__
    if "_body_depth" not in cache:
        import shapely
        from shapely.geometry import Polygon

        P = mesh.points
        loops = mesh.boundary_loops
        poly = Polygon(P[loops[0]], [P[lp] for lp in loops[1:]])
        if not poly.is_valid:
            poly = poly.buffer(0)
        cache["_body_depth"] = float(shapely.maximum_inscribed_circle(poly, 1e-4 * body_size(mesh)).length)
    return cache["_body_depth"]


def admissible_edges(mesh, fab: Fabrication, clearance: float) -> np.ndarray:
    """The edges a rope may run on: the whole edge at least ``clearance`` inside the outline and every hole (its
    nodes, and the segment between them where it passes a reflex corner: :func:`segment_insets`).

    Only whole mesh edges far enough inside are used (no band refined, no route offset inward): the rope
    then lies exactly on the nodes the design and the fabrication files use, and the rule is exact on the
    mesh -- every rope node has its clearance, which an offset route or a refined band would have to
    re-establish after moving nodes. The price is a mesh fine enough to have edges inside; one that has none
    is refused here with a :class:`~mdsr_opt.core.errors.LayoutError` (a ``ValueError``: a layout this body and
    mesh cannot hold, which ``mdsr run`` reports as the case's failure) naming the cause and the numbers that
    would work (:func:`no_band_message`). Ropes routed elsewhere and moved into the band are snapped onto
    these edges (:mod:`~mdsr_opt.synthesis.routing_band`)."""
    dist = boundary_distance(mesh)
    tol = 1e-12 * float(dist.max() if len(dist) else 0.0)
    ok = dist >= clearance - tol
    E = mesh.edges
    adm = ok[E[:, 0]] & ok[E[:, 1]]
    # a point of an edge lies within half its length of a node: only edges that near the clearance can dip below it
    near = np.flatnonzero(adm & (np.minimum(dist[E[:, 0]], dist[E[:, 1]]) - 0.5 * mesh.edge_lengths < clearance))
    adm[near[segment_insets(mesh, E[near]) < clearance - tol]] = False
    if adm.any():
        return adm
    raise LayoutError(no_band_message(mesh, fab, clearance))


def deepest_edge(mesh) -> float:
    """How deep inside the body at rest the deepest mesh edge lies (its nodes and the segment between them:
    :func:`segment_insets`): the largest clearance at which :func:`admissible_edges` finds an edge; 0 for a
    mesh with every edge touching the boundary."""
    dist = boundary_distance(mesh)
    E = mesh.edges
    d = np.minimum(dist[E[:, 0]], dist[E[:, 1]])  # a segment lies no deeper than its nodes: read the deepest first
    order = np.argsort(-d, kind="stable")
    best = 0.0
    for start in range(0, len(order), 256):
        chunk = order[start:start + 256]
        chunk = chunk[d[chunk] > best]
        if not len(chunk):
            break
        best = max(best, float(segment_insets(mesh, E[chunk]).max()))
    return best


def _at_most(v: float) -> float:
    """``v`` rounded down to three significant digits (a value to quote that still satisfies ``<= v``)."""
    if v <= 0:
        return 0.0
    step = 10.0 ** (math.floor(math.log10(v)) - 2)
    return math.floor(v / step * (1 + 1e-12)) * step


def no_band_message(mesh, fab: Fabrication, clearance: float) -> str:
    """Why no mesh edge lies ``clearance`` inside the body (:func:`admissible_edges` found none) and what would
    work: the real cause first -- a body not deep enough for the inset (no finer mesh helps: the channel, the
    wall or ``min_inset_fraction`` must shrink) or a mesh too coarse for it -- with the values that fit."""
    f = fab.for_body(mesh)
    D = body_size(mesh)
    need = 0.5 * f.channel_diameter + f.wall
    floor = f.min_inset_fraction * D
    R = body_depth(mesh)
    fits = deepest_edge(mesh)  # the largest clearance this mesh admits
    h = float(mesh.edge_lengths.mean())
    why = (f"the larger of channel_diameter {f.channel_diameter:.4g} / 2 + wall {f.wall:.4g} = {need:.4g} and "
           f"min_inset_fraction {f.min_inset_fraction:g} of the body's diameter {D:.4g} = {floor:.4g}")
    if clearance > max(need, floor) * (1 + 1e-9):
        why += f"; here routed deeper, at an inset of {clearance:.4g}"
    # on this mesh every term above ``fits`` must come down to it (together)
    here = []
    if fits > 0:  # a mesh with every edge on the boundary holds nothing at any size
        if floor > fits:
            here.append(f"min_inset_fraction at most {_at_most(fits / D):.3g}")
        if need > fits:
            here.append(f"channel_diameter / 2 + wall at most {_at_most(fits):.4g}")
        if clearance > max(need, floor, fits) * (1 + 1e-9):
            here.append(f"an inset at most {_at_most(fits):.4g}")
    asks = ("the channel and its wall ask" if need >= max(floor, clearance) * (1 - 1e-12) else
            "min_inset_fraction asks" if floor >= clearance * (1 - 1e-12) else "asked")
    on_mesh = f"on this mesh (its deepest edge lies {fits:.4g} inside): " + " and ".join(here) if here else ""
    finer = f"a finer mesh, mean edge length at most {_at_most((R - clearance) / 2):.3g} (now {h:.4g})"
    if R <= clearance * (1 + 1e-9):
        head = (f"the body is too thin for the inset {asks}: every rope node must lie at least {clearance:.4g} "
                f"inside the outline and the holes ({why}), but the body is only {R:.4g} deep at its deepest point "
                f"(its largest inscribed circle's radius), so no finer mesh helps. ")
        ways = [on_mesh] if on_mesh else [(f"a finer mesh, with channel_diameter / 2 + wall and min_inset_fraction "
                                           f"times the diameter below the body's depth {R:.4g}")]
    else:
        head = (f"the mesh is too coarse to hold a rope at its inset: every rope node must lie at least "
                f"{clearance:.4g} inside the outline and the holes ({why}); the body is {R:.4g} deep at its deepest "
                f"point, but no mesh edge lies that deep, its two nodes and the segment between them (the deepest: "
                f"{fits:.4g}; mean edge length {h:.4g}). ")
        ways = [finer] + ([on_mesh] if on_mesh else [])
    return head + "Would work: " + "; or ".join(ways)


@dataclass(frozen=True)
class Conflict:
    """One reason a layout cannot be moulded in one layer (:func:`rope_conflicts`).

    Attributes
    ----------
    kind : str
        ``"inset"`` (a channel closer to the outline or a hole than its half width plus the wall),
        ``"fixture-inset"`` (an end fixture with its wall reaching outside the body), ``"ropes"`` (two channels
        closer than a channel width plus a wall), ``"crossing"`` (two ropes that cross or touch),
        ``"fixtures"`` (two fixtures closer than their radii plus a wall) or ``"fixture-channel"`` (a fixture
        closer to another rope's channel than its radius, half the channel and a wall).
    muscles : tuple of int
        The muscle(s) concerned (indices in the layout).
    distance : float
        The smallest inset or centre-to-centre distance found (length unit of the mesh).
    required : float
        What moulding needs there.
    at : tuple of float
        Where (a point of the body at rest), for marking the drawing.
    message : str
        The sentence a user reads: the muscles' names, the distance and the required clearance.
    """

    kind: str
    muscles: tuple
    distance: float
    required: float
    at: tuple
    message: str


def _name(muscles, i) -> str:
    return getattr(muscles[i], "name", None) or f"M{i + 1}"


def rope_conflicts(mesh, muscles, fab: Fabrication, *, fixture_radius: float | None = None,
                   channel_width: float | None = None) -> list:
    """Every place where a layout cannot be moulded in one layer, as :class:`Conflict` s (empty: it can).

    A channel of width ``c`` with its wall ``w`` needs every point of the rope (its nodes and the segments
    between them) at least ``c / 2 + w`` inside the outline and the holes (and ``fab.min_inset_fraction`` of the
    body's size, as the routing keeps); an end fixture of radius ``r`` needs ``r + w``. Two ropes need their centre lines ``c + w`` apart (one wall between the two
    channels) and must not cross; two fixtures need their centres ``2 r + w`` apart, and a fixture needs
    ``r + c / 2 + w`` from another rope's centre line. Two ends closer than ``r`` share one fixture plate (the
    design holds them as one rigid part): the two ropes meet there, and are checked outside that plate and
    its wall.

    Parameters
    ----------
    mesh : Mesh
        The body at rest.
    muscles : sequence of Muscle (or node sequences)
    fab : Fabrication
        The channel, wall and fixtures (fields left None take the body's defaults).
    fixture_radius : float, optional
        The ends' radius (the design's ``anchor_radius``); default ``fab.fixture_radius``.
    channel_width : float, optional
        The channel's width; default ``fab.channel_diameter``.
    """
    import shapely
    from shapely.geometry import LineString, Point
    from shapely.ops import nearest_points

    f = fab.for_body(mesh)
    c = f.channel_diameter if channel_width is None else float(channel_width)
    r = f.fixture_radius if fixture_radius is None else float(fixture_radius)
    w = f.wall
    P = mesh.points
    D = body_size(mesh)
    tol = 1e-9 * D
    dist = boundary_distance(mesh)
    paths = [np.asarray(list(getattr(m, "nodes", m)), dtype=np.int64) for m in muscles]
    out = []
    inset_need = max(0.5 * c + w, f.min_inset_fraction * D)
    for i, p in enumerate(paths):
        k = int(p[np.argmin(dist[p])])
        at, d_in, where = P[k], float(dist[k]), ""
        if len(p) > 1 and d_in >= inset_need - tol:  # its nodes are deep enough: is every segment?
            seg = segment_insets(mesh, np.column_stack([p[:-1], p[1:]]))
            j = int(np.argmin(seg))
            if seg[j] < d_in:
                line = LineString(P[p[j:j + 2]])
                at = np.asarray(shapely.shortest_line(line, _boundary_lines(mesh)).coords[0])
                d_in = float(seg[j])
                where = f" (between two of its nodes, near ({at[0]:.4g}, {at[1]:.4g}))"
        if d_in < inset_need - tol:
            on = f" (it runs on {_boundary_at(mesh, at)})" if d_in <= tol else ""
            out.append(Conflict("inset", (i,), d_in, inset_need, tuple(map(float, at)),
                                f"muscle {_name(muscles, i)}: its channel is not mouldable: its smallest inset from "
                                f"the outline or a hole is {d_in:.4g}{on}{where}, a channel {c:.4g} wide with a "
                                f"wall {w:.4g} needs {inset_need:.4g}"))
        for e in (p[0], p[-1]):
            if r > 0 and dist[e] < r + w - tol:
                out.append(Conflict("fixture-inset", (i,), float(dist[e]), r + w, tuple(map(float, P[e])),
                                    f"muscle {_name(muscles, i)}: its end fixture at ({P[e][0]:.4g}, {P[e][1]:.4g}) "
                                    f"reaches outside the body: its centre is {dist[e]:.4g} inside, a fixture of "
                                    f"radius {r:.4g} with a wall {w:.4g} needs {r + w:.4g}"))
                break
    lines = [LineString(P[p]) if len(p) > 1 else Point(P[p[0]]) for p in paths]
    for i in range(len(paths)):
        for j in range(i + 1, len(paths)):
            a, b = lines[i], lines[j]
            pair = f"muscles {_name(muscles, i)} and {_name(muscles, j)}"
            ends_i, ends_j = (paths[i][0], paths[i][-1]), (paths[j][0], paths[j][-1])
            # ends closer than a fixture's radius share one plate (the design holds them as one rigid part):
            # their ropes meet in it, and only outside it (and its wall) do the channels need their clearance
            shared = [(ea, eb) for ea in ends_i for eb in ends_j if r > 0 and np.linalg.norm(P[ea] - P[eb]) < r]
            if shared:
                zone = shapely.union_all([Point(P[e]).buffer(r + w, 32) for pr in shared for e in pr])
                a, b = a.difference(zone), b.difference(zone)
                if a.is_empty or b.is_empty:
                    continue
            d = float(a.distance(b))
            if d <= tol:
                x = a.intersection(b)
                q = shapely.get_coordinates(x)[0] if not x.is_empty else P[paths[i][0]]
                out.append(Conflict("crossing", (i, j), 0.0, c + w, tuple(map(float, q)),
                                    f"{pair} cross or touch at ({q[0]:.4g}, {q[1]:.4g}): two ropes that cross cannot "
                                    f"be moulded in one layer (their centre lines need {c + w:.4g} between them)"))
            elif d < c + w - tol:
                qa, qb = nearest_points(a, b)
                q = 0.5 * (np.asarray(qa.coords[0]) + np.asarray(qb.coords[0]))
                out.append(Conflict("ropes", (i, j), d, c + w, tuple(map(float, q)),
                                    f"{pair}: their channels overlap: centre lines {d:.4g} apart near "
                                    f"({q[0]:.4g}, {q[1]:.4g}), two channels {c:.4g} wide with a wall {w:.4g} "
                                    f"between them need {c + w:.4g}"))
            if r <= 0:
                continue
            own_i, own_j = {e for e, _ in shared}, {e for _, e in shared}
            pairs = [(float(np.linalg.norm(P[ea] - P[eb])), ea, eb) for ea in ends_i for eb in ends_j
                     if ea not in own_i and eb not in own_j]
            dd, ea, eb = min(pairs) if pairs else (np.inf, None, None)
            if dd < 2 * r + w - tol:
                q = 0.5 * (P[ea] + P[eb])
                out.append(Conflict("fixtures", (i, j), dd, 2 * r + w, tuple(map(float, q)),
                                    f"{pair}: their end fixtures overlap: centres {dd:.4g} apart near "
                                    f"({q[0]:.4g}, {q[1]:.4g}), two fixtures of radius {r:.4g} with a wall "
                                    f"{w:.4g} between them need {2 * r + w:.4g}"))
                continue
            for (own, ends, other, k) in ((i, ends_i, b, j), (j, ends_j, a, i)):
                ends = [e for e in ends if e not in own_i | own_j]
                if not ends:
                    continue
                de, e = min((float(other.distance(Point(P[e]))), e) for e in ends)
                need = r + 0.5 * c + w
                if de < need - tol:
                    out.append(Conflict("fixture-channel", (own, k), de, need, tuple(map(float, P[e])),
                                        f"{pair}: the end fixture of {_name(muscles, own)} at ({P[e][0]:.4g}, "
                                        f"{P[e][1]:.4g}) overlaps the channel of {_name(muscles, k)}: {de:.4g} from "
                                        f"its centre line, a fixture of radius {r:.4g}, half the channel "
                                        f"{0.5 * c:.4g} and a wall {w:.4g} need {need:.4g}"))
                    break
    return out


def pair_conflicts(mesh, kept, cand, fab: Fabrication, fixture_radius: float) -> tuple[list, float]:
    """The conflicts of rope ``cand`` with rope ``kept`` (:func:`rope_conflicts` between the two, not their
    insets), and the fraction of ``cand``'s nodes closer to ``kept`` than a channel and a wall (``fab`` with every
    field set); ``([], 0.0)`` when the two can be moulded side by side."""
    import shapely
    from shapely.geometry import LineString

    found = [c for c in rope_conflicts(mesh, [kept, cand], fab, fixture_radius=fixture_radius) if len(c.muscles) == 2]
    if not found:
        return found, 0.0
    P = mesh.points
    line = LineString(P[list(getattr(kept, "nodes", kept))])
    d = shapely.distance(shapely.points(P[list(getattr(cand, "nodes", cand))]), line)
    return found, float(np.mean(d < fab.channel_diameter + fab.wall))


def warn_conflicts(conflicts, where: str, stacklevel: int = 3) -> None:
    """One :class:`FabricationWarning` listing ``conflicts`` (nothing when there are none)."""
    if not conflicts:
        return
    import warnings

    warnings.warn(f"{where}: {len(conflicts)} place(s) cannot be moulded as laid out: "
                  + "; ".join(cf.message for cf in conflicts), FabricationWarning, stacklevel=stacklevel)


def check_sizes_fit(mesh, channel_width: float, wall: float, fixture_radius: float) -> None:
    """ValueError when a channel of width ``channel_width`` with its ``wall``, or a fixture of radius
    ``fixture_radius`` with its wall, cannot fit anywhere in the body (deeper than :func:`body_depth`); the
    message gives the body's size and the largest channel the body admits."""
    R = body_depth(mesh)
    ext = np.ptp(mesh.points, axis=0)
    body = f"the body is {ext[0]:.4g} x {ext[1]:.4g} and {R:.4g} deep at its deepest point (largest inscribed radius)"
    if 0.5 * channel_width + wall > R:
        most = 2.0 * (R - wall)
        raise ValueError(f"channel_width {channel_width:.4g} with walls of {wall:.4g} does not fit in the body: "
                         f"{body}, so half the channel plus the wall must be at most {R:.4g} (channel_width at "
                         + (f"most {most:.4g} with this wall)" if most > 0 else f"any size needs a wall below {R:.4g})"))
    if fixture_radius + wall > R:
        raise ValueError(f"the end fixtures (radius {fixture_radius:.4g}) with their wall {wall:.4g} do not fit in "
                         f"the body: {body}, so fixture radius plus wall must be at most {R:.4g}")


def check_channel_fits(mesh, fabrication, *, routed: bool = True, where: str = "fabrication") -> None:
    """:class:`~mdsr_opt.core.errors.LayoutError` (a ``ValueError``), before any work, when no rope's channel with
    its wall fits anywhere in the body.

    A rope node needs ``channel_diameter / 2 + wall`` of body on every side (to the outline and each hole),
    so a body whose largest inscribed circle (:func:`body_depth`) is smaller holds no rope at all: no mesh
    refinement helps. The message names the channel, the wall and the largest channel the body admits with
    that wall. ``fabrication`` is anything :func:`check_fabrication` takes (False: no channel, nothing to
    check). With ``routed=False`` (muscles the user lays, designed as given) only sizes the spec states are
    checked: the defaults (fractions of the body's diameter) are the routing's, and a given rope that does
    not fit them is warned about (:func:`rope_conflicts`), not refused.
    """
    fab = check_fabrication(fabrication)
    if fab is False or not routed and fab.channel_diameter is None and fab.wall is None:
        return
    f = fab.for_body(mesh)
    need = 0.5 * f.channel_diameter + f.wall
    # a node that deep: the largest inscribed circle is no smaller (the routing reads these distances anyway,
    # and the circle itself is then not needed)
    if need <= float(boundary_distance(mesh).max()):
        return
    R = body_depth(mesh)
    if need <= R * (1.0 + 1e-9):
        return
    ext = np.ptp(mesh.points, axis=0)
    said = [f"{n} the default {frac:.0%} of the body's diameter" for n, frac in
            (("channel_diameter", CHANNEL_FRACTION), ("wall", WALL_FRACTION)) if getattr(fab, n) is None]
    default = f" ({'; '.join(said)})" if said else ""
    most = 2.0 * (R - f.wall)
    admits = (f"the largest channel_diameter this body admits with this wall is {most:.4g}" if most > 0 else
              f"no channel fits with this wall: the wall must be below {R:.4g}")
    raise LayoutError(f"{where}: channel_diameter {f.channel_diameter:.4g} with a wall {f.wall:.4g}{default} does "
                      f"not fit in the body: a rope needs channel_diameter / 2 + wall = {need:.4g} of material to the "
                      f"outline and the holes on every side, but the body ({ext[0]:.4g} x {ext[1]:.4g}) is only "
                      f"{R:.4g} deep at its deepest point (its largest inscribed circle's radius); {admits}")
