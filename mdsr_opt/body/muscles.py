"""Muscle units: cables routed along chains of mesh edges.

A :class:`Muscle` is a simple path of mesh nodes ``(v0, ..., vk)``; consecutive nodes must share a mesh
edge. A contraction ``a`` in ``[0, 1)`` shortens the muscle to ``(1 - a)`` of its rest length.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Sequence

import numpy as np
from numpy.typing import ArrayLike

from ..core.checks import as_float_array, as_index_array, check_label

__all__ = ["Muscle", "check_muscles", "check_contractions", "check_distinct_ropes", "default_muscle_name",
           "label_of", "muscle_name_clash", "check_muscle_names"]


def default_muscle_name(i: int) -> str:
    """The name of an unnamed muscle ``i`` (0-based place in its layout): ``"M1"``, ``"M2"``... (every
    figure, file, table and message uses it: :func:`mdsr_opt.plot.style.muscle_name`)."""
    return f"M{int(i) + 1}"


def label_of(muscles, i: int) -> str:
    """The label of the ``i``-th of ``muscles`` (Muscles or node lists): its name, else ``M<i+1>``."""
    m = muscles[i]
    return m.label(i) if isinstance(m, Muscle) else default_muscle_name(i)


@dataclass(frozen=True)
class Muscle:
    """A muscle unit along mesh edges.

    Parameters
    ----------
    nodes : sequence of int
        The path ``v0 ... vk`` (at least two nodes, no node twice).
    name : str, optional
        A label used in reports, figures and fabrication files: no control characters or line breaks
        (:func:`~mdsr_opt.core.checks.check_label`).

    Example
    -------
    >>> from mdsr_opt import Mesh, Muscle
    >>> mesh = Mesh.rectangle(2.0, 1.0, 2, 1, pattern="right")
    >>> Muscle([0, 1, 2]).rest_length(mesh)
    2.0
    """

    nodes: tuple[int, ...]
    name: str | None = field(default=None, compare=False)

    def __post_init__(self):
        if isinstance(self.nodes, Muscle):
            raise TypeError(f"Muscle() takes a path of node indices, got a Muscle ({self.nodes.name or 'unnamed'}, "
                            f"nodes {list(self.nodes.nodes)[:6]}{'...' if len(self.nodes.nodes) > 6 else ''}): "
                            "edge_path() and boundary_path() return a Muscle already: use it as it is, or "
                            "Muscle(m.nodes, name=...) for a renamed copy")
        if isinstance(self.nodes, (str, bytes, dict)) or not hasattr(self.nodes, "__iter__"):
            raise TypeError(f"Muscle() takes a path of node indices (a list, tuple or integer array of at least two), "
                            f"got {type(self.nodes).__name__} {self.nodes!r:.60}")
        arr = as_index_array(list(self.nodes) if not isinstance(self.nodes, np.ndarray) else self.nodes,
                             "muscle nodes", shape=(None,))
        if len(arr) < 2:
            raise ValueError(f"muscle {self._label()} needs at least two nodes, got {len(arr)}")
        if len(np.unique(arr)) != len(arr):
            vals, counts = np.unique(arr, return_counts=True)
            raise ValueError(f"muscle {self._label()} repeats node {int(vals[counts > 1][0])}: "
                             "a muscle is a simple path")
        object.__setattr__(self, "nodes", tuple(int(v) for v in arr))
        if self.name is not None:  # it labels the muscle in SVG, DXF and CSV files
            check_label(self.name, "muscle name")

    def _label(self) -> str:
        return repr(self.name) if self.name else "path"

    def label(self, i: int) -> str:
        """The muscle's name, else :func:`default_muscle_name` ``(i)``, ``i`` its place in the layout."""
        return str(self.name) if self.name else default_muscle_name(i)

    @property
    def segments(self) -> np.ndarray:
        """Consecutive node pairs (k, 2)."""
        v = np.asarray(self.nodes, dtype=np.int64)
        return np.column_stack([v[:-1], v[1:]])

    @property
    def edges(self) -> frozenset:
        """The mesh edges it runs along, each as ``(smaller node, larger node)``: its path regardless of
        direction."""
        return frozenset((min(a, b), max(a, b)) for a, b in zip(self.nodes[:-1], self.nodes[1:]))

    def check_on(self, mesh) -> None:
        """Raise ``ValueError`` unless every node is in ``mesh`` and every segment is a mesh edge."""
        v = np.asarray(self.nodes)
        if v.max() >= mesh.n_nodes:
            raise ValueError(f"muscle {self._label()} has node {int(v.max())} out of range [0, {mesh.n_nodes})")
        seg = self.segments
        off = np.flatnonzero(mesh.edge_rows(seg[:, 0], seg[:, 1]) < 0)
        if len(off):
            a, b = (int(v) for v in seg[off[0]])
            raise ValueError(f"muscle {self._label()} leaves the mesh: segment ({a}, {b}) is not a mesh edge")

    def segment_lengths(self, x: ArrayLike) -> np.ndarray:
        x = np.asarray(x, dtype=float)
        s = self.segments
        return np.linalg.norm(x[s[:, 1]] - x[s[:, 0]], axis=1)

    def length(self, x: ArrayLike) -> float:
        """Length of the path in configuration ``x`` (n, 2)."""
        return float(self.segment_lengths(x).sum())

    def rest_length(self, mesh) -> float:
        return self.length(mesh.points)

    def turning_angle(self, x: ArrayLike) -> float:
        """Total absolute turning angle (radians) along the path in configuration ``x``."""
        x = np.asarray(x, dtype=float)
        d = np.diff(x[list(self.nodes)], axis=0)
        if len(d) < 2:
            return 0.0
        ang = np.arctan2(d[:, 1], d[:, 0])
        turn = np.diff(ang)
        turn = (turn + np.pi) % (2 * np.pi) - np.pi
        return float(np.abs(turn).sum())


def check_muscles(mesh, muscles: Sequence[Muscle], what: str = "muscles") -> list[Muscle]:
    """Validate a list of muscles against ``mesh``; accept plain node lists too. Two muscles of the list
    with one label (:func:`check_muscle_names`) are refused; ``what`` names the list in that message."""
    if isinstance(muscles, Muscle):
        muscles = [muscles]
    out = []
    for i, m in enumerate(muscles):
        if not isinstance(m, Muscle):
            if isinstance(m, (str, bytes)) or not hasattr(m, "__len__"):
                raise TypeError(f"muscles[{i}] must be a Muscle or a sequence of node indices, got {type(m).__name__}")
            m = Muscle(tuple(m) if not isinstance(m, np.ndarray) else m)
        m.check_on(mesh)
        out.append(m)
    check_muscle_names(out, what)
    return out


def muscle_name_clash(muscles) -> tuple[str, int, int] | None:
    """The first label two of ``muscles`` (one layout) share: ``(label, first index, second index)``, or None.
    An unnamed muscle is called by its place (``M1``, ``M2`` ...: every table, figure and file does), so a
    muscle named ``"M2"`` clashes with an unnamed second one; a node list is an unnamed muscle."""
    seen: dict[str, int] = {}
    for i, m in enumerate(muscles):
        label = m.label(i) if isinstance(m, Muscle) else default_muscle_name(i)
        if label in seen:
            return label, seen[label], i
        seen[label] = i
    return None


def check_muscle_names(muscles, what: str = "muscles") -> None:
    """Raise ``ValueError`` when two of ``muscles`` have one label (:func:`muscle_name_clash`), naming the
    label and both places in ``what`` (the list's name): every table, figure and file names a muscle by its
    label, so two would read as one."""
    clash = muscle_name_clash(muscles)
    if clash:
        raise ValueError(f"muscle name {clash[0]!r} is used twice ({what}[{clash[1]}] and {what}[{clash[2]}]): "
                         "every table, figure and file names a muscle by it")


def check_distinct_ropes(muscles: Sequence[Muscle]) -> None:
    """Raise ``ValueError`` when two muscles run along the same path (either direction). As exact cables
    they are one length constraint twice: the tighter rope holds, the other hangs slack, and the solvers'
    linear systems are singular. (Dummy springs along one path are springs in parallel: allowed.)"""
    seen: dict = {}
    for i, m in enumerate(muscles):
        j = seen.setdefault(m.edges, i)
        if j != i:
            raise ValueError(f"muscles {j} and {i} run along the same path: as cable ropes they are one length "
                             f"constraint twice (the tighter holds, the other hangs slack); give it once")


def check_contractions(contractions: ArrayLike, n_muscles: int, a_max: float = 1.0) -> np.ndarray:
    """Contractions as a float vector, one per muscle, each in ``[0, a_max)`` with ``a_max <= 1``."""
    a = np.atleast_1d(as_float_array(contractions, "contractions"))  # strings, bools, None: TypeError
    if a.ndim != 1:
        raise ValueError(f"contractions must have shape (k,), got {a.shape}")
    if len(a) != n_muscles:
        raise ValueError(f"contractions must have one value per muscle ({n_muscles}), got {len(a)}")
    bad = (a < 0) | (a >= a_max)
    if bad.any():
        i = int(np.argmax(bad))
        raise ValueError(f"contractions[{i}] = {a[i]} is outside [0, {a_max:g})")
    return a
