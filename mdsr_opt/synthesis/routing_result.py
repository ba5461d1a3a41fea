"""The result of muscle routing (:func:`~mdsr_opt.synthesis.routing.route_muscles`): the routed muscles
with their figures (:class:`MuscleStats`), the units dropped on the way (:class:`DroppedUnit`) and the
whole answer (:class:`RoutingResult`)."""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field, replace

import networkx as nx
import numpy as np
from numpy.typing import ArrayLike

from ..body.muscles import Muscle
from ..core.results import format_value, to_jsonable
from .fabrication import Fabrication
from .routing_symmetry import Reflection

__all__ = ["MuscleStats", "DroppedUnit", "RoutingResult", "largest_turn"]


@dataclass(frozen=True)
class MuscleStats:
    """Figures of one routed muscle.

    Attributes
    ----------
    name : str
        The muscle's name.
    n_edges : int
        Number of mesh edges along the path.
    rest_length, target_length : float
        Path length at rest and in the target.
    contraction : float
        ``1 - target_length / rest_length``: the contraction that would make the whole cable match the
        target (a first guess for the design stage).
    mean_weight : float
        Mean relative contraction ``w`` of the path's edges.
    nonuniformity : float
        Variance of those weights (the paper's nonuniformity coefficient; 0 = perfectly uniform).
    turning_angle : float
        Total absolute turning of the path at rest, radians (0 = straight).
    turning_angle_target : float
        The same in the target configuration.
    max_turn : float
        The largest turn at any single node, at rest, radians (the tortuosity rule bounds it).
    """

    name: str
    n_edges: int
    rest_length: float
    target_length: float
    contraction: float
    mean_weight: float
    nonuniformity: float
    turning_angle: float
    turning_angle_target: float
    max_turn: float = 0.0

    def to_dict(self) -> dict:
        """The figures as a JSON-ready dict."""
        return to_jsonable(asdict(self))


@dataclass(frozen=True)
class DroppedUnit:
    """A unit that is not a muscle of the result as it stood, and why.

    Attributes
    ----------
    nodes : tuple of int
        Its path when it was spliced, dropped or cut.
    rest_length : float
        Its rest length then.
    reason : str
        ``"spliced into ..."``, ``"dropped: ..."`` or ``"cut by max_muscles ..."``.
    """

    nodes: tuple
    rest_length: float
    reason: str

    def to_dict(self) -> dict:
        """The figures as a JSON-ready dict."""
        return to_jsonable(asdict(self))


@dataclass(frozen=True, eq=False)
class RoutingResult:
    """Muscles routed for a target, with their figures.

    Iterating, ``len`` and indexing act on :attr:`muscles`, so ``for m in route_muscles(...)`` works.
    Two results compare equal only if they are the same object (``eq=False``: the graph and the dict
    have no meaningful ``==``); compare ``[m.nodes for m in result]`` instead.

    Attributes
    ----------
    muscles : tuple of Muscle
        The routed muscles, strongest first (by ``sum w * l0`` over their edges). Each path starts at the
        end whose rest coordinates are lexicographically smaller.
    stats : tuple of MuscleStats
        One entry per muscle, same order.
    graph : networkx.Graph
        The contraction graph (see :func:`contraction_graph`). The routing passes a function that builds it,
        called on first access (a search on 16k nodes does not need the networkx graph: it took a third of a
        second to build); a graph given is kept as it is.
    seeds : tuple of (int, int)
        The seed edges, most contracted first.
    n_units : int
        Units left when growth stopped, before ``min_length``/``max_muscles`` selection.
    params : dict
        The knobs used (``K_a``, ``K_b``, ``K_h``, ``n_seeds``, ``max_muscles``, ``min_length``,
        ``min_contraction``, ``max_turn``, ``seed_threshold``, ``symmetry``, ``compression_ratio``).
    dropped : tuple of DroppedUnit
        Fragments shorter than ``min_length`` (spliced or dropped), muscles cut by ``max_muscles`` and, in a
        design's result, muscles the design took out (idle: "dropped after the design: ...").
    reflection : Reflection or None
        The mirror symmetry the muscles were routed with (None: not symmetric, or switched off).
    n_regions : int
        Contracted regions that were seeded.
    fabrication : Fabrication or None
        The channel, wall and fixtures the ropes were routed for, every field set (None: a result saved
        before routing knew them).
    fixture_radius : float or None
        The end fixtures' radius the ropes fit with: the ``anchor_radius`` to design with (smaller than
        ``fabrication.fixture_radius`` when the fixtures were shrunk to keep ropes).
    notes : tuple of str
        The resolutions that made the ropes buildable (ends moved inward, ropes dropped and why, fixtures
        shrunk), one sentence each (see :mod:`mdsr_opt.synthesis.routing_fixtures`).
    """

    muscles: tuple[Muscle, ...]
    stats: tuple[MuscleStats, ...]
    graph: nx.Graph
    seeds: tuple[tuple[int, int], ...] = ()
    n_units: int = 0
    params: dict = field(default_factory=dict)
    dropped: tuple = ()
    reflection: Reflection | None = None
    n_regions: int = 0
    fabrication: Fabrication | None = None
    fixture_radius: float | None = None
    notes: tuple = ()

    def __iter__(self):
        return iter(self.muscles)

    def __len__(self) -> int:
        return len(self.muscles)

    def __getitem__(self, i):
        return self.muscles[i]

    def __repr__(self) -> str:
        names = [m.name for m in self.muscles]
        return (f"RoutingResult({len(self.muscles)} muscle(s) {format_value(names)}, edges "
                f"{format_value([s.n_edges for s in self.stats])}, contractions "
                f"{format_value([round(s.contraction, 4) for s in self.stats])}, n_units={self.n_units}, "
                f"seeds={len(self.seeds)}, graph={self.graph.number_of_nodes()} nodes)")

    def to_dict(self) -> dict:
        """Muscles, their figures, seeds, unit count and knobs as a JSON-ready dict (the graph is left out:
        :func:`contraction_graph` rebuilds it from the mesh and the target)."""
        return to_jsonable({"muscles": list(self.muscles), "stats": [s.to_dict() for s in self.stats],
                            "seeds": list(self.seeds), "n_units": self.n_units, "params": dict(self.params),
                            "dropped": [asdict(d) for d in self.dropped],
                            "fabrication": None if self.fabrication is None else self.fabrication.to_dict(),
                            "fixture_radius": self.fixture_radius, "notes": list(self.notes)})

    def table(self) -> str:
        """The stats as a plain-text table, one row per muscle under a header row, laid out as the other
        results' tables (:meth:`~mdsr_opt.synthesis.results.DesignResult.muscle_table`): lengths L0 (rest)
        and L (target) in the mesh's units, turning angles in radians (total) and degrees (largest turn)."""
        w = max([6] + [len(s.name) for s in self.stats])
        head = (f"{'muscle':<{w}} {'edges':>5} {'L0':>9} {'L':>9} {'contr.':>7} {'mean w':>8} "
                f"{'var w':>9} {'turn':>7} {'max':>5}")
        rows = [head]
        for s in self.stats:
            rows.append(f"{s.name:<{w}} {s.n_edges:>5d} {s.rest_length:>9.4g} {s.target_length:>9.4g} "
                        f"{s.contraction:>7.3f} {s.mean_weight:>8.4f} {s.nonuniformity:>9.2e} "
                        f"{s.turning_angle:>7.3f} {math.degrees(s.max_turn):>5.1f}")
        return "\n".join(rows)

    def keeping(self, kept, dropped) -> RoutingResult:
        """A copy with only the muscles ``kept`` after a design (their stats alike), each muscle the design
        took out (``dropped``: :class:`~mdsr_opt.synthesis.acceptance.DroppedMuscle` s, or anything with
        ``nodes`` and ``reason``) added to :attr:`dropped` with its reason: the routing of a result then names
        the muscles the result has, fresh or loaded."""
        paths = {tuple(m.nodes) for m in kept}
        pairs = [(m, st) for m, st in zip(self.muscles, self.stats) if tuple(m.nodes) in paths]
        out = tuple(DroppedUnit(tuple(d.nodes), float(st.rest_length), f"dropped after the design: {d.reason}")
                    for d in dropped for m, st in zip(self.muscles, self.stats) if tuple(m.nodes) == tuple(d.nodes))
        return self.replaced(muscles=tuple(m for m, _ in pairs), stats=tuple(st for _, st in pairs),
                             dropped=tuple(self.dropped) + out)

    def replaced(self, **changes) -> RoutingResult:
        """A copy with ``changes`` (as :func:`dataclasses.replace`), its graph still unbuilt if it was."""
        return replace(self, **{"graph": self.__dict__["_graph"], **changes})


def _get_graph(self) -> nx.Graph:
    g = self.__dict__["_graph"]
    if not isinstance(g, nx.Graph):  # a builder: the graph is made on first access
        g = g()
        self.__dict__["_graph"] = g
    return g


def _set_graph(self, value) -> None:
    if not (isinstance(value, nx.Graph) or callable(value)):
        raise TypeError(f"graph must be a networkx.Graph or a function building one, got {type(value).__name__}")
    self.__dict__["_graph"] = value


# the field ``graph`` set by the dataclass's __init__ through this property: a graph, or a function building it
RoutingResult.graph = property(_get_graph, _set_graph, doc="The contraction graph (built on first access).")


def largest_turn(x: ArrayLike, path) -> float:
    """The largest turning angle (radians) at any interior node of ``path`` in configuration ``x``.

    Example
    -------
    >>> round(math.degrees(largest_turn([[0, 0], [1, 0], [2, 1]], [0, 1, 2])), 6)
    45.0
    """
    x = np.asarray(x, dtype=float)
    d = np.diff(x[list(path)], axis=0)
    if len(d) < 2:
        return 0.0
    a, b = d[:-1], d[1:]
    c = (a * b).sum(axis=1) / (np.linalg.norm(a, axis=1) * np.linalg.norm(b, axis=1))
    return float(np.arccos(np.clip(c, -1.0, 1.0)).max())
