"""Muscle routing: the contraction graph of a target shape and the best-first muscle search.

Given the rest mesh and a target configuration (typically the result of external driving), every mesh edge
gets a weight, its relative contraction ``w = (l0 - l) / l0`` (positive: the edge shortens, negative: it
stretches). :func:`contraction_graph` returns these as a networkx graph. :func:`route_muscles` lays
muscle units along strongly and uniformly contracted, smooth chains of edges:

1. **Regions and seeds.** A contracted region is a connected set of nodes touched by edges contracted by
   at least ``seed_threshold * w_ref`` (``w_ref``: the contraction reached by the most contracted edges
   of total rest length four mean edge lengths; one short edge at a corner would dominate ``w_max``),
   counting only compression: an edge whose contraction is smaller than the largest principal stretch
   of the triangles beside it is the sideways (Poisson) response of a stretched region, which a cable
   cannot produce. Each region is seeded on its own with its ``n_seeds`` most contracted edges (a global
   top-n would put every seed in the most contracted region), but an island nearer than :data:`SEED_SPACING`
   times the body's diameter (through the body) to a region holding ten times its contraction is not seeded;
   a seed nearer than the spacing to a unit already made starts none.
2. **First units.** Each connected component of the seed edges is cut into simple paths, straightest
   continuation first, every turn within ``max_turn`` and every edge passing the same gate ``g <= 1`` as
   growth (below), so no seed joins edges that contract very differently; each path is a muscle unit.
3. **Growth and splicing.** Units grow from their endpoints by a best-first (A*-like) search. A step adds
   a contracted edge ``e`` at an endpoint ``N`` (or joins another unit's endpoint through ``e``) and costs

   ``g = K_a * g_a + K_b * (1 - cos(theta))``,

   where ``g_a`` is the nonuniformity of the step: the largest squared relative deviation of a joined
   part's mean contraction from the mean of the grown unit, ``max_p ((mean_p - mean) / mean)**2`` over
   the parts (the unit, the edge, and the other unit when splicing), and ``theta`` the turn taken (for a
   splice, the larger of the two turns at the joint). A step is allowed only if ``g <= 1`` and no turn
   exceeds ``max_turn`` (the tortuosity rule, which seed paths obey too). Of all allowed steps the one
   with the smallest ``f = g + K_h * h`` is taken, ``h`` being the shortest-path length along mesh edges
   (rest lengths, in mean edge lengths) from the new endpoint to the nearest endpoint of another unit.
   Joining another unit's endpoint splices the two (fewer, longer muscles). Growth ends when no step is
   allowed.
4. **Fragments and selection.** Units shorter than ``min_length`` are spliced into a neighbouring unit
   end (within the tortuosity limit, and ``K_a * share * g_a <= 1`` with ``share`` the fragment's share
   of the joined edges) or dropped; the result's ``dropped`` records each with the reason.
   The rest are ranked by the contraction they capture (``sum w * l0``), twins of stronger ones dropped (within
   the spacing over half their length: :mod:`~mdsr_opt.synthesis.routing_spacing`), at most ``max_muscles`` kept.
5. **Symmetry.** When the body is mirror-symmetric and the target contracts mirrored edges alike,
   every step is taken together with its mirror image (:mod:`mdsr_opt.synthesis.routing_symmetry`), so the
   muscles are mirror pairs or their own mirror images, node for node.

Channels inside the body (``fabrication``, :class:`~mdsr_opt.synthesis.fabrication.Fabrication`): a rope runs in a
moulded channel with a wall around it, so only edges whose two nodes lie at least ``channel_diameter / 2 + wall``
(and ``min_inset_fraction``, 2 %, of the body's diameter) inside the outline and every hole can carry one. The search
runs on those edges only, rather than offsetting routes inward or refining a band along the boundary: the rule is then
exact on the mesh (every rope node has its clearance, on the very nodes the design and the fabrication files use),
costs nothing, and changes no node; a body or mesh with no such edge is refused (a LayoutError) naming the cause and
the values that would work. Where the contraction is strongest next to the outline, the band's jagged edge and its
necks beside holes break such ropes into fragments; :func:`route_for_design` then also routes on every contracted edge and snaps the ropes
into the band (``band="offset"``, :mod:`mdsr_opt.synthesis.routing_band`). The routed ropes are then fitted to their
end fixtures (:mod:`mdsr_opt.synthesis.routing_fixtures`), each resolution a sentence of ``result.notes``.
``fabrication=False`` is the search alone, on every edge.

A cable cannot push: an edge with ``w <= min_contraction`` (every elongated or unchanged edge) is never
part of a muscle, neither as a seed nor by growth. A target that only stretches the body, contracts
nothing by more than ``min_contraction``, or equals the rest shape (every edge length within a relative
``1e-8``, up to a rigid motion) gives no muscles and a :class:`RoutingWarning` saying which.

Why ``g_a`` is a relative mismatch (a change made for the paper's Figure 6)
-----------------------------------------------------------------------------
An earlier version took ``g_a = Var(w over the grown unit) / w_max**2``. The weights along a chain of
contracted edges vary smoothly and lie in ``(0, w_max]``, so that variance stays below about
``0.03 w_max**2`` for any unit: ``K_a * g_a`` reached the gate ``g <= 1`` only for ``K_a`` of about 30 to
100, and below that ``K_a`` changed nothing (measured with that cost: tentacle/curl, tentacle/s_curve,
gripper/close and humanoid/raise_arms routed identically for every ``K_a`` in 0.1 .. 10). Growth runs until no step is allowed, so ``K_a`` acts only through the gate, never
through the order. The relative mismatch is dimensionless and of order one: an edge that contracts half
as much as the unit costs ``0.25 K_a``. ``K_a`` then states how alike the parts of a muscle must be
(within ``1/sqrt(K_a)`` of the mean at zero turn), and over ``K_a`` = 1 .. 30 a smaller value splices more
units into fewer, longer muscles, as the paper reports. The paper's own ``g_a`` is the rise of the
variance; a rise can be negative (an edge near the mean lowers the variance) and lets the variance creep
over many steps, so it is not used.

Deviations from the paper (and from the project's design notes), on purpose:

* ``g_a`` as above.
* ``h`` is the shortest-path length along mesh edges, not the Manhattan distance. The paper takes the
  Manhattan distance because a muscle follows the lattice edges, so its length is closer to that than
  to the straight-line distance. On a triangle mesh the length along mesh edges is exactly that path
  length, and unlike a Manhattan distance (which depends on the x and y axes) it does not change when
  the body is rotated: rotating mesh and target together gives the same muscles.
* The tortuosity is a rule (``max_turn``) besides a cost: the paper wants smooth muscles; a rope that turns
  sharply at a node rubs and cuts the silicone.

The search lives in :mod:`mdsr_opt.synthesis.routing_search` (:class:`~mdsr_opt.synthesis.routing_search.Router`), the
mirror symmetry in :mod:`mdsr_opt.synthesis.routing_symmetry`, the quality table in :mod:`mdsr_opt.studies.routing_quality`.

Determinism: ties are broken by rest geometry (edge midpoints, node coordinates), never by node index,
and weights are compared on a grid of ``1e-9``, so the ~1e-16 round-off of a rigid motion of the target
changes the order of two weights only if they straddle a grid boundary (in practice never; the tests
check several motions). Relabelling the nodes or moving the target rigidly gives the same muscles.

Example
-------
>>> import numpy as np
>>> from mdsr_opt import Mesh
>>> from mdsr_opt.synthesis.routing import route_muscles
>>> mesh = Mesh.rectangle(4.0, 1.0, nx=16, ny=4)
>>> target = mesh.points * [0.8, 1.0]          # shorten along x by 20 %
>>> result = route_muscles(mesh, target)
>>> len(result) > 0 and all(s.turning_angle == 0.0 for s in result.stats)
True
"""

from __future__ import annotations

import functools
import math
import warnings
from dataclasses import replace

import networkx as nx
import numpy as np
from numpy.typing import ArrayLike

from ..core.checks import check_int, positive_float
from ..core.errors import LayoutError
from ..body.checks import check_mesh, check_target_shape
from ..body.mesh import Mesh
from ..body.muscles import Muscle
from ..mechanics.anchors import ANCHOR_FRACTION, body_size
from ..plot.style import muscle_name
from .fabrication import Fabrication, admissible_edges, check_channel_fits, check_fabrication
from .routing_band import snap_into_band
from .routing_fixtures import FixtureFit, fit_fixtures, fitting_notes, shared_plates
from .routing_memo import memoised, shared_work
from .routing_result import DroppedUnit, MuscleStats, RoutingResult, largest_turn
from .routing_search import Router
from .routing_symmetry import find_reflections, weights_are_symmetric
from .routing_spacing import parallel_twins
from .routing_why import compression_dominated, no_feasible_message, no_seed_message

__all__ = [
    "contraction_graph",
    "edge_weights",
    "route_muscles",
    "RoutingWarning",
    "route_for_design",
]

#: Seed paths start no nearer than this fraction of the body's diameter to a unit made before them (the
#: default anchor patch radius, :data:`~mdsr_opt.mechanics.anchors.ANCHOR_FRACTION`): a length, so a finer
#: mesh, whose most contracted edges lie in more parallel rows a cell apart, does not get more parallel
#: muscles (a 4 x 1 strip: 3 muscles at 2.4k nodes, 5 at 4.3k, 8 at 17k without it).
SEED_SPACING = ANCHOR_FRACTION

#: :func:`route_for_design` keeps the ropes snapped into the band (``band="offset"``) when they shorten in the
#: target by more than this factor times the ropes searched inside it.
OFFSET_GAIN = 1.2

#: Weights are compared as integers on this grid (rigid-motion round-off is ~1e-16).
_QUANTUM = 1e-9
#: A target whose every edge length matches its rest length within this relative tolerance
#: (``|l - l0| <= _REST_RTOL * l0``, i.e. ``|w| <= _REST_RTOL``) counts as the rest shape.
_REST_RTOL = 1e-8


class RoutingWarning(UserWarning):
    """Routing found nothing to do (rest-shape or elongation-only target) or dropped every unit."""


# ---------------------------------------------------------------------------------------------- input
def edge_weights(mesh: Mesh, target: ArrayLike) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Rest lengths, target lengths and relative contractions of ``mesh.edges``.

    Parameters
    ----------
    mesh : Mesh
        The rest mesh.
    target : array_like, shape (n, 2)
        Target node positions; must be finite and must not invert any triangle.

    Returns
    -------
    l0, l, w : ndarray, shape (k,)
        Rest length, target length and ``w = (l0 - l) / l0`` of each row of ``mesh.edges``. ``l0`` is
        the mesh's cached ``edge_lengths`` and read-only (copy it to modify); ``l`` and ``w`` are new
        arrays, so changing them affects nothing else.

    Example
    -------
    >>> from mdsr_opt import Mesh
    >>> mesh = Mesh.rectangle(1.0, 1.0, 1, 1, pattern="right")
    >>> l0, l, w = edge_weights(mesh, mesh.points * [0.5, 1.0])
    >>> float(w.max())
    0.5
    """
    mesh = check_mesh(mesh)
    return _weights(mesh, check_target_shape(mesh, target))


def _weights(mesh: Mesh, x: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    e = mesh.edges
    l0 = mesh.edge_lengths
    l = np.linalg.norm(x[e[:, 1]] - x[e[:, 0]], axis=1)
    return l0, l, (l0 - l) / l0


def contraction_graph(mesh: Mesh, target: ArrayLike) -> nx.Graph:
    """The contraction graph of ``target`` over the rest ``mesh``.

    Parameters
    ----------
    mesh : Mesh
        The rest mesh.
    target : array_like, shape (n, 2)
        Target node positions (e.g. an external-driving equilibrium). Finite, no inverted triangle.

    Returns
    -------
    networkx.Graph
        One node per mesh node (attributes ``rest`` and ``target``: coordinate tuples) and one edge per
        mesh edge with attributes ``rest_length``, ``target_length`` and ``weight`` =
        ``(rest_length - target_length) / rest_length`` (positive: contraction, negative: elongation).
        ``graph.graph`` holds ``w_max`` and ``w_min``. Note that weights can be negative, so the graph is
        not meant for networkx shortest-path routines.

    Raises
    ------
    TypeError
        ``mesh`` is not a :class:`~mdsr_opt.Mesh` or ``target`` is not numeric.
    ValueError
        ``target`` has the wrong shape, contains NaN/inf, or inverts a triangle.

    Example
    -------
    >>> from mdsr_opt import Mesh
    >>> mesh = Mesh.rectangle(2.0, 1.0, 2, 1)
    >>> G = contraction_graph(mesh, mesh.points * [0.9, 1.0])
    >>> round(G.edges[0, 1]["weight"], 6)
    0.1
    """
    mesh = check_mesh(mesh)
    x = check_target_shape(mesh, target)
    return _graph(mesh, x, *_weights(mesh, x))


def _graph(mesh: Mesh, x: np.ndarray, l0: np.ndarray, l: np.ndarray, w: np.ndarray) -> nx.Graph:
    G = nx.Graph(w_max=float(w.max()), w_min=float(w.min()))
    G.add_nodes_from((i, {"rest": tuple(p), "target": tuple(q)})
                     for i, (p, q) in enumerate(zip(mesh.points.tolist(), x.tolist())))
    G.add_edges_from((a, b, {"rest_length": r, "target_length": t, "weight": c})
                     for (a, b), r, t, c in zip(mesh.edges.tolist(), l0.tolist(), l.tolist(), w.tolist()))
    return G


def route_muscles(mesh: Mesh, target: ArrayLike, *, K_a: float = 4.0, K_b: float = 4.0, K_h: float = 0.1,
                  n_seeds: int = 8, max_muscles: int | None = None, min_length: float | None = None,
                  min_contraction: float = 1e-3, max_turn: float = 45.0, seed_threshold: float = 0.6,
                  symmetry: str | bool = "auto", fabrication: Fabrication | dict | bool | None = None,
                  compression_ratio: float = 1.0, inset: float | None = None, band: str = "edges") -> RoutingResult:
    """Route muscle units along contracted, uniform, smooth chains of mesh edges.

    One search with the knobs given (by default the paper's, on the admissible edges), so each knob acts as
    documented and studies of the search reproduce. :func:`~mdsr_opt.design_pipeline` and ``mdsr run`` route with
    :func:`route_for_design`, which routes again (deeper, with ``K_a = 1``, snapped into the band) when this loses
    ropes: for the pipeline's layout call ``route_for_design(mesh, target)``; design with its ``fixture_radius``.

    Parameters
    ----------
    mesh : Mesh
        The rest mesh.
    target : array_like, shape (n, 2)
        Target node positions (e.g. an external-driving equilibrium); finite, no inverted triangle.
    K_a : float, default 4
        Weight of nonuniformity ``g_a``, the largest squared relative deviation of a joined part's mean
        contraction from the grown unit's mean (see the module docstring). A step is allowed only if
        ``K_a * g_a + K_b * (1 - cos(theta)) <= 1``; at zero turn an edge may join a unit whose mean
        contraction it matches within ``1/sqrt(K_a)``. Smaller: fewer, longer muscles (more splicing);
        larger: more, shorter, more uniform ones.
    K_b : float, default 4
        Weight of tortuosity ``1 - cos(theta)`` of the turn taken.
    K_h : float, default 0.1
        Weight of the heuristic (shortest-path length along mesh edges to the nearest other unit's
        endpoint, in mean edge lengths) in the best-first order.
    n_seeds : int, default 8
        Seed edges per contracted region: the region's ``n_seeds`` most contracted edges.
    max_muscles : int, optional
        Keep at most this many muscles (the strongest by ``sum w * l0``; mirror pairs are kept or cut
        together); default: all. Cut muscles are listed in ``result.dropped``.
    min_length : float, optional
        Fragments with a smaller rest length are spliced into a neighbouring unit or dropped (the reason
        is in ``result.dropped``); default: twice the mean rest edge length.
    min_contraction : float, default 1e-3
        Only edges with ``w > min_contraction`` are used (a cable cannot push).
    max_turn : float, default 45
        Tortuosity rule, degrees: no muscle turns by more than this at any node (seed paths, growth steps
        and splice joints alike; ``band="offset"``: up to :data:`~mdsr_opt.synthesis.routing_band.SNAP_TURN`).
    seed_threshold : float, default 0.6
        Contracted regions are the connected sets of edges with ``w >= seed_threshold * w_ref`` (islands
        beside far stronger ones aside); each gets its own seeds. ``w_ref``: the largest contraction reached
        by edges of total rest length four mean edge lengths (so one short edge at a corner cannot set it).
    symmetry : {"auto", True, False}, default "auto"
        Route mirrored pairs of muscles when the body is mirror-symmetric (``find_reflections``) and
        mirrored edges contract alike (within ``1e-6 * max|w|``). ``True`` requires that and raises
        otherwise; ``False`` never does it.
    fabrication : Fabrication or dict of its fields, optional
        The channel, wall and end fixtures (:class:`~mdsr_opt.synthesis.fabrication.Fabrication`; default:
        its defaults for this body). Ropes run only on edges whose two nodes lie at least the larger of
        ``channel_diameter / 2 + wall`` and ``min_inset_fraction`` times the diameter inside the outline and holes,
        and the routed ropes are fitted to their end fixtures (:func:`~mdsr_opt.synthesis.routing_fixtures.fit_fixtures`:
        ends moved inward, stubs and joined ropes dropped, fixtures shrunk), each step recorded in
        ``result.notes``; ``result.fixture_radius`` is the fixture radius to design with (``anchor_radius``).
        ``False``: the search alone, on every edge of the contraction graph (ropes may lie on the outline;
        for studies of the search, not for a robot to build).
    inset : float, optional
        Lay every rope node at least this far inside the outline and the holes, when that is more than the
        fabrication's clearance (half the channel plus the wall, at least ``min_inset_fraction`` of the body's
        size): a deeper route on which end fixtures fit (:func:`route_for_design` tries ``min_fixture_radius + wall`` when
        ropes were lost for lack of room at their ends). Ignored with ``fabrication=False``.
    band : {"edges", "offset", "offset+long"}, default "edges"
        How ropes keep their clearance (ignored with ``fabrication=False``). ``"edges"``: the search runs on
        the admissible edges only. ``"offset"``: the search runs on every contracted edge and each rope is
        moved into the band (the body shrunk by the clearance) and snapped to admissible edges, cut where the
        band has a gap (:mod:`~mdsr_opt.synthesis.routing_band`); ``"offset+long"``: also a search at ``K_a = 1``.
    compression_ratio : float in (0, 1], default 1
        An edge seeds a region only if its contraction exceeds ``compression_ratio`` times the largest
        principal stretch of the triangles beside it. 1: compression dominates (the default; the sideways
        Poisson response of a stretched region, at most ``nu`` times its stretch, seeds nothing). Around a
        hole drawn shut (an eye, a mouth) the hoop contraction a ring-shaped rope makes comes with a
        radial stretch of about the same size, so no edge there passes 1; about 0.5 admits it while still
        rejecting the Poisson response of a material with ``nu`` below 0.5.

    Returns
    -------
    RoutingResult
        Iterable of :class:`~mdsr_opt.Muscle`; ``.stats`` per muscle, ``.dropped`` the fragments and cut
        muscles with the reason, ``.graph`` the contraction graph, ``.reflection`` the symmetry used.

    Raises
    ------
    TypeError
        ``mesh`` is not a Mesh, a knob has the wrong type, or ``target`` is not numeric.
    ValueError
        ``target`` has the wrong shape, contains NaN/inf or inverts a triangle; a knob is out of range. A
        :class:`~mdsr_opt.core.errors.LayoutError` (a ``ValueError``; ``mdsr run`` fails the case) for what this
        body, mesh and target cannot hold: ``symmetry=True`` for a body or target that is not mirror-symmetric;
        a channel with its wall deeper than the body; no edge far enough inside (a body too thin for the inset,
        or a mesh too coarse): the message names the cause and the values that would work.

    Warns
    -----
    RoutingWarning
        The target equals the rest shape (every edge length within a relative ``1e-8``, up to a rigid
        motion), only stretches the body, contracts no edge by more than ``min_contraction``, or every
        unit is shorter than ``min_length``. The message says which; the result is then empty.

    Example
    -------
    >>> import numpy as np
    >>> from mdsr_opt import Mesh
    >>> mesh = Mesh.rectangle(4.0, 1.0, nx=16, ny=4)
    >>> X = mesh.points
    >>> R, phi = 3.0, (X[:, 0] - 2.0) / 3.0            # bend the strip about the centre line y = 0.5
    >>> r = R - (X[:, 1] - 0.5)                          # the top side (y = 1) is on the inside
    >>> target = np.column_stack([r * np.sin(phi), R - r * np.cos(phi)])
    >>> result = route_muscles(mesh, target)
    >>> bool(np.all(X[list(result[0].nodes), 1] > 0.5))  # the muscle runs on the concave side
    True
    """
    mesh = check_mesh(mesh)
    K_a = positive_float(K_a, "K_a", allow_zero=True)
    K_b = positive_float(K_b, "K_b", allow_zero=True)
    K_h = positive_float(K_h, "K_h", allow_zero=True)
    n_seeds = check_int(n_seeds, "n_seeds", 1)
    if max_muscles is not None:
        max_muscles = check_int(max_muscles, "max_muscles", 1)
    ell = float(mesh.edge_lengths.mean())
    min_length = 2.0 * ell if min_length is None else positive_float(min_length, "min_length", allow_zero=True)
    min_contraction = positive_float(min_contraction, "min_contraction", allow_zero=True)
    if min_contraction >= 1.0:
        raise ValueError("min_contraction must be < 1 (a fraction of the rest length), "
                         f"got {min_contraction}")
    max_turn = positive_float(max_turn, "max_turn", allow_zero=True)
    if max_turn > 180.0:
        raise ValueError(f"max_turn must be <= 180 degrees, got {max_turn}")
    seed_threshold = positive_float(seed_threshold, "seed_threshold")
    compression_ratio = positive_float(compression_ratio, "compression_ratio")
    if compression_ratio > 1.0:
        raise ValueError(f"compression_ratio must be in (0, 1] (a fraction of the largest principal stretch "
                         f"beside an edge), got {compression_ratio}")
    if seed_threshold > 1.0:
        raise ValueError(f"seed_threshold must be in (0, 1] (a fraction of the largest contraction), "
                         f"got {seed_threshold}")
    if symmetry not in ("auto", True, False):
        raise ValueError(f"symmetry must be 'auto', True or False, got {symmetry!r}")
    if band not in ("edges", "offset", "offset+long"):
        raise ValueError(f"band must be 'edges', 'offset' or 'offset+long', got {band!r}")
    fab = check_fabrication(fabrication)
    if fab is False and band != "edges":
        raise ValueError(f"band={band!r} snaps ropes into the buildable band, which fabrication=False has none of")
    if fab is False:
        fab, clearance, adm_edges = None, 0.0, None
    else:
        check_channel_fits(mesh, fab)  # a channel with its wall deeper than the body: no mesh can hold it
        fab = fab.for_body(mesh)
        clearance = fab.clearance(mesh)
        if inset is not None:
            clearance = max(clearance, positive_float(inset, "inset", allow_zero=True))
        # the routings of one body at one clearance share their band (routing_memo: deeper and band routings)
        adm_edges = memoised(("admissible", id(mesh), fab, clearance), lambda: admissible_edges(mesh, fab, clearance))
    params = dict(K_a=K_a, K_b=K_b, K_h=K_h, n_seeds=n_seeds, max_muscles=max_muscles,
                  min_length=min_length, min_contraction=min_contraction, max_turn=max_turn,
                  seed_threshold=seed_threshold, symmetry=symmetry, compression_ratio=compression_ratio,
                  inset=None if inset is None else float(inset), band=band)

    x = memoised(("target", id(mesh), target.dtype.str, target.shape, target.tobytes()), lambda: check_target_shape(
        mesh, target)) if isinstance(target, np.ndarray) else check_target_shape(mesh, target)  # checked once per scope
    l0, l, w = _weights(mesh, x)
    # built when a caller asks for result.graph (the search needs no networkx graph); a partial of a module
    # function, so that a result still pickles (a run's jobs send it to worker processes)
    graph = functools.partial(_graph, mesh, x, l0, l, w)

    def empty(msg: str) -> RoutingResult:
        warnings.warn(msg, RoutingWarning, stacklevel=3)
        return RoutingResult((), (), graph, (), 0, params, fabrication=fab,
                             fixture_radius=None if fab is None else fab.fixture_radius)

    w_abs = float(np.abs(w).max())
    if w_abs <= _REST_RTOL:
        return empty(f"target equals the rest shape within tolerance (up to a rigid motion): no edge "
                     f"length changes by more than {_REST_RTOL:g} of its rest length (largest "
                     f"|w| = {w_abs:.3g}), so there is nothing for a muscle to do; no muscles routed")
    reflection = None
    if symmetry is not False:
        reflection = next((m for m in memoised(("mirrors", id(mesh)), lambda: find_reflections(mesh))
                           if weights_are_symmetric(w, m)), None)
        if symmetry is True and reflection is None:
            raise LayoutError("symmetry=True but the body is not mirror-symmetric or the target does not "
                              "contract mirrored edges alike")
    wq = np.rint(w / _QUANTUM).astype(np.int64)
    if reflection is not None:  # exact symmetry of the quantised weights (floor of the pair's mean)
        wq = (wq + wq[reflection.edge_map]) // 2
    floor_q = int(round(min_contraction / _QUANTUM))
    turn_limit = (1.0 - math.cos(math.radians(max_turn))) + 1e-12
    offset = band != "edges" and adm_edges is not None
    # one search per set of inputs (routing_memo): the band routing pools the search an earlier one ran
    same = (id(mesh), wq.tobytes(), reflection is None, K_b, K_h, floor_q, ell, turn_limit, seed_threshold, compression_ratio,
            n_seeds, min_length)
    key = same + (K_a, None if adm_edges is None else adm_edges.tobytes())
    router = memoised(("router",) + key, lambda: Router(mesh, wq, K_a, K_b, K_h, floor_q, ell, turn_limit,
                                                         reflection, adm_edges))
    if not router.feasible.any():
        return empty(no_feasible_message(w, bool((wq > floor_q).any()), fab, clearance,
                                         min_contraction=min_contraction, rest_rtol=_REST_RTOL))
    compressed = memoised(("compressed", id(mesh), hash(x.tobytes()), compression_ratio),
                          lambda: compression_dominated(mesh, x, w, compression_ratio))
    knobs = dict(seed_threshold=seed_threshold, compressed=compressed, n_seeds=n_seeds,
                 spacing=SEED_SPACING * body_size(mesh), min_length=min_length)
    regions, seeds, dropped = memoised(("search",) + key, lambda: router.search(**knobs))
    dropped = [DroppedUnit(*d) for d in dropped]

    E = mesh.edges
    units = [U for U in router.units if U.alive]
    pieces = [(U.uid, list(U.path)) for U in units]
    if offset:  # the search on every contracted edge, its ropes moved into the band, pooled with the above
        free_paths = []
        for k_a in sorted({K_a, min(K_a, 1.0)} if band == "offset+long" else {K_a}):
            free = Router(mesh, wq, k_a, K_b, K_h, floor_q, ell, turn_limit, reflection)
            free.search(**knobs)
            free_paths += [list(U.path) for U in free.units if U.alive]
        snapped = snap_into_band(mesh, free_paths, adm_edges, free.feasible, clearance, turn_limit)
        pieces += [(-1 - i, p) for i, (_, p) in enumerate(snapped)]  # no mirror partner among the search's units
    found, laid = [], set()
    for uid, path in pieces:
        if tuple(router.XL[path[-1]]) < tuple(router.XL[path[0]]):
            path.reverse()
        if tuple(path) in laid or laid.add(tuple(path)):  # pooled searches and snapping can lay a rope twice
            continue
        ks = [router.edge_id(a, b) for a, b in zip(path[:-1], path[1:])]
        strength = sum(router.wql[k] * l0[k] for k in ks)
        found.append([-strength, tuple(router.XL[path[0]]), tuple(router.XL[path[-1]]), path, ks, uid])
    found.sort(key=lambda t: t[:3])
    # the spacing holds for the grown ropes too: a rope beside stronger ones is their twin (routing_spacing)
    twins = parallel_twins(mesh, [f[3] for f in found], max(knobs["spacing"], fab.channel_diameter + fab.wall
                           if fab else 0.0), [f[5] for f in found], None if reflection is None else router.mirror_uid)
    dropped += [DroppedUnit(tuple(found[i][3]), float(l0[found[i][4]].sum()), why) for i, why in twins.items()]
    found = [f for i, f in enumerate(found) if i not in twins]
    fit = (FixtureFit(tuple((i, tuple(f[3])) for i, f in enumerate(found)), None, (), ()) if fab is None
           else fit_fixtures(mesh, [f[3] for f in found], fab))
    for i, why in fit.dropped:
        L = float(sum(l0[k] for k in found[i][4]))
        dropped.append(DroppedUnit(tuple(found[i][3]), L, f"dropped: {why}"))
    refit = []
    for i, path in fit.kept:
        path = list(path)
        if tuple(router.XL[path[-1]]) < tuple(router.XL[path[0]]):
            path.reverse()
        ks = [router.edge_id(a, b) for a, b in zip(path[:-1], path[1:])]
        strength = sum(router.wql[k] * l0[k] for k in ks)
        refit.append([-strength, tuple(router.XL[path[0]]), tuple(router.XL[path[-1]]), path, ks, found[i][5]])
    found = sorted(refit, key=lambda t: t[:3])
    extra = dict(fabrication=fab, fixture_radius=fit.radius, notes=fit.notes)
    if max_muscles is not None:
        kept, taken = [], set()
        for f in found:
            if f[5] in taken:
                continue
            orbit = [f] + [g for g in found if reflection is not None and g[5] != f[5] and f[5] >= 0
                           and g[5] == router.mirror_uid[f[5]]]
            if len(kept) + len(orbit) <= max_muscles:
                kept += orbit
            else:
                for g in orbit:
                    L = float(sum(l0[k] for k in g[4]))
                    dropped.append(DroppedUnit(tuple(g[3]), L, f"cut by max_muscles={max_muscles} (weaker "
                                                                  "than the muscles kept; mirror pairs kept whole)"))
            taken.update(g[5] for g in orbit)
        found = sorted(kept, key=lambda t: t[:3])
    if fab is not None:  # the end plates the ropes kept share (after the max_muscles cut)
        extra["notes"] = fit.notes + shared_plates(mesh.points, [f[3] for f in found], fit.radius)
    seed_edges = tuple((int(E[k, 0]), int(E[k, 1])) for k in seeds)
    if not found:
        inside = "" if fab is None else (
            f"; the ropes lie at least {clearance:.4g} inside the body, and on a mesh this coarse (mean edge length "
            f"{ell:.4g}) few edges there form a unit: a finer mesh gives them room")
        why = no_seed_message(mesh, x, w, wq > floor_q, adm_edges, router.threshold_q * _QUANTUM, router.eligible,
                              min_contraction=min_contraction, seed_threshold=seed_threshold,
                              compression_ratio=compression_ratio, clearance=None if fab is None else clearance,
                              min_inset_fraction=None if fab is None else fab.min_inset_fraction) \
            if not units and not dropped \
            else (f"all {len(units) + len(dropped)} muscle unit(s) are shorter than min_length={min_length:.4g}; "
                  f"no muscles routed (lower min_length, K_a or K_b{inside})") if not fit.notes else (
               "no routed rope keeps room for its end fixtures: " + "; ".join(fit.notes)
               + " (give a smaller fixture_radius or min_fixture_radius, or a finer mesh)")
        warnings.warn(why, RoutingWarning, stacklevel=2)
        return RoutingResult((), (), graph, seed_edges, len(units), params, tuple(dropped), reflection,
                             len(regions), **extra)

    muscles, stats = [], []
    for i, (_, _, _, path, ks, _) in enumerate(found):
        m = Muscle(path, name=muscle_name(i))  # M1, M2, ...: the name every figure and drawing uses
        wk = w[ks]
        L0, L = m.length(mesh.points), m.length(x)
        muscles.append(m)
        stats.append(MuscleStats(name=m.name, n_edges=len(ks), rest_length=L0, target_length=L,
                                 contraction=1.0 - L / L0, mean_weight=float(wk.mean()),
                                 nonuniformity=float(wk.var()), turning_angle=m.turning_angle(mesh.points),
                                 turning_angle_target=m.turning_angle(x),
                                 max_turn=largest_turn(mesh.points, path)))
    return RoutingResult(tuple(muscles), tuple(stats), graph, seed_edges, len(units), params, tuple(dropped),
                         reflection, len(regions), **extra)


def route_for_design(mesh: Mesh, target: ArrayLike, **options) -> RoutingResult:
    """:func:`route_muscles` as the pipeline routes (:func:`~mdsr_opt.design_pipeline`, ``mdsr run``). Ropes
    dropped or cut for their fixtures: route again deeper inside with the smallest fixtures (kept if it keeps
    more ropes, or ropes that shorten :data:`OFFSET_GAIN` times more); no rope kept with the default ``K_a``
    (4): again with ``K_a = 1``; ropes still lost inside the band: route on every contracted edge and snap
    into the band (``band="offset"``, kept when its ropes capture :data:`OFFSET_GAIN` times more contraction).
    Each change is said first in ``result.notes``; a ``K_a`` or ``band`` given, or ``fabrication=False``, is
    used as given; the kept routing's warnings are re-emitted.

    Example
    -------
    >>> from mdsr_opt import Mesh
    >>> mesh = Mesh.rectangle(4.0, 1.0, 32, 8)
    >>> len(route_for_design(mesh, mesh.points * [0.8, 1.0])) >= 1
    True
    """
    with shared_work():  # the routings below share their mirrors, compressed edges and searches (routing_memo)
        rr, caught = _routed_for_design(mesh, target, options)
    for w in caught:
        warnings.warn_explicit(w.message, w.category, w.filename, w.lineno)
    return rr


def _routed_for_design(mesh: Mesh, target: ArrayLike, options: dict):
    def attempt(opts, first=False):
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            try:
                rr = route_muscles(mesh, target, **opts)
            except LayoutError:  # a fallback (deeper inside, say) this body cannot hold: the routing before it stays
                if first:
                    raise
                return None, []
        return rr, caught

    rr, caught = attempt(options, first=True)
    fab = check_fabrication(options.get("fabrication"))
    if fab is not False and options.get("inset") is None and fitting_notes(mesh.points, rr):
        # ropes were dropped or shortened for their end fixtures: route deeper inside, where the smallest
        # fixture fits at any rope node, and keep that routing if it keeps more ropes
        f = fab.for_body(mesh)
        deep, caught_deep = attempt(dict(options, inset=f.min_fixture_radius + f.wall,
                                         fabrication=replace(f, fixture_radius=f.min_fixture_radius)))
        if deep is not None and (len(deep) > len(rr) or _captured(deep) > OFFSET_GAIN * _captured(rr)):
            note = (f"{len(rr)} rope(s) kept at the fabrication's clearance, shortening by {_captured(rr):.4g} in the "
                    f"target; routed again with every rope node {f.min_fixture_radius + f.wall:.4g} inside the body, "
                    f"fixtures shrunk from radius {f.fixture_radius:.4g} to the smallest, {f.min_fixture_radius:.4g}: "
                    f"{len(deep)} kept, shortening by {_captured(deep):.4g}")
            rr, caught = deep.replaced(notes=(note,) + deep.notes), caught_deep
    if not len(rr) and "K_a" not in options and options.get("fabrication") is not False:
        again, caught2 = attempt(dict(options, K_a=1.0))
        if again is not None and len(again):
            why = "; ".join(fitting_notes(mesh.points, rr)) or "; ".join(str(w.message) for w in caught)
            note = f"no rope routed with K_a=4 was kept ({why}): routed again with K_a=1 (fewer, longer ropes)"
            rr, caught = again.replaced(notes=(note,) + again.notes), caught2
    if fab is not False and options.get("band") is None and (fitting_notes(mesh.points, rr) or not len(rr)):
        # ropes lost inside the band (fragments along its jagged edge, gaps at necks beside holes): route on
        # every contracted edge and snap the ropes into the band (routing_band); kept when its ropes capture
        # clearly more of the target's contraction than the best routing inside the band above
        opts = dict(options, band="offset" if "K_a" in options else "offset+long")
        if rr.params.get("inset") is not None:
            opts["inset"], opts["fabrication"] = rr.params["inset"], replace(
                fab.for_body(mesh), fixture_radius=fab.for_body(mesh).min_fixture_radius)
        snapped, caught_snapped = attempt(opts)
        if snapped is not None and _captured(snapped) > OFFSET_GAIN * _captured(rr):
            depth, r0 = snapped.params["inset"] or snapped.fabrication.clearance(mesh), fab.for_body(mesh).fixture_radius
            small = "" if opts.get("inset") is None else f", fixtures shrunk from radius {r0:.4g} to the smallest, {snapped.fixture_radius:.4g}"
            note = (f"ropes routed on every contracted edge and snapped into the band at least {depth:.4g} inside the body{small}: "
                    f"they shorten by {_captured(snapped):.4g} in the target, the ropes searched inside the band by {_captured(rr):.4g}")
            rr, caught = snapped.replaced(notes=(note,) + snapped.notes), caught_snapped
    return rr, caught


def _captured(rr: RoutingResult) -> float:
    """How much the ropes of a routing shorten in its target, summed (rest minus target length)."""
    return float(sum(st.rest_length - st.target_length for st in rr.stats))
