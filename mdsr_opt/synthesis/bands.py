"""How far a designed stroke can be trusted: its band under the uncertainties of the fabrication
(:func:`stroke_bands`).

A stroke is designed for a model: end fixtures of exactly ``anchor_radius``, a Poisson's ratio known
exactly, one mesh. None of these is exact in a workshop, and the stroke moves with each (on a strip bent
by one muscle, from 0.94 to 0.78 as the fixture radius goes from 0.1 to 0.25). The band makes the design
again, from the designed contractions, with each quantity moved to either side and reports where the
stroke goes:

- the fixture size: ``anchor_radius`` +- ``radius_tol`` (default :data:`RADIUS_RTOL` of the radius);
- the material: ``nu`` +- ``nu_tol`` (default :data:`NU_TOL`; kept inside ``(-1, 0.5)``, said when cut);
- the mesh: the same design on the mesh refined once, every triangle split into four at its edges'
  midpoints (:func:`refine_mesh`). Any mesh can be refined so, whether it was made from an outline or
  read from a file; the outline's polygon stays the same, every muscle keeps its path (its edges are
  split) and the target is carried to the new nodes along the edges. Above ``max_refined_nodes`` this
  part is left out, and the band says so. It is the discretisation error of the rope as laid out; a rope
  drawn as waypoints and snapped to the edges of *another* mesh of the body follows another zig-zag path
  (its rest length differs by a few per cent on coarse meshes) and takes another stroke: compare strokes
  of ropes of the same rest length, or design on the mesh that matches the channel.

Each source gives a deviation below and above the nominal stroke (the smallest and largest change among
its designs, and 0); the band adds the sources' deviations (a worst case, not a statistical interval).
A design of the band that fails contributes nothing and is named in ``notes``: a band is never narrower
in silence.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass, field

import numpy as np

from ..body.checks import check_target_shape
from ..body.mesh import Mesh
from ..body.muscles import Muscle
from ..core.checks import positive_float, positive_int
from ..core.errors import LayoutError
from ..mechanics.anchors import check_anchor_radius
from ..core.quantities import point_band
from ..core.results import compact_repr, to_jsonable
from ..plot.style import muscle_label

__all__ = ["RADIUS_RTOL", "NU_TOL", "MAX_REFINED_NODES", "NU_CAP", "BAND_MAX_ITER", "StrokeBands", "refine_mesh",
           "stroke_bands"]

#: the default tolerance of the fixture size, relative to ``anchor_radius``
RADIUS_RTOL = 0.25
#: the default tolerance of Poisson's ratio (absolute)
NU_TOL = 0.05
#: the refined mesh's largest node count: above it the mesh part of the band is left out
MAX_REFINED_NODES = 20000
#: the largest Poisson's ratio a band's material takes (0.5 is incompressible, outside the models)
NU_CAP = 0.49
#: the optimiser's iterations a band's design may take (it starts at the designed contractions; one that
#: needs more is left out of the band, and named in its notes), unless ``max_iter`` is given
BAND_MAX_ITER = 100


@dataclass(eq=False)
class StrokeBands:
    """Per muscle, the designed stroke and its band under the fabrication's uncertainties.

    Attributes
    ----------
    names : tuple of str
        The muscles (their names, or ``"M<k+1>"``: :func:`mdsr_opt.plot.style.muscle_label`).
    nominal : (m,) ndarray
        The designed strokes (a length).
    band : (m, 2) ndarray
        ``(low, high)`` per muscle; ``low <= nominal <= high``.
    contributions : dict of str to (m, 2) ndarray
        Per source (``"anchor_radius"``, ``"nu"``, ``"mesh"``), the deviation below (<= 0) and above (>= 0)
        the nominal stroke.
    values : dict of str to list
        Per source, the values its designs took (radii, Poisson's ratios, the refined node count).
    notes : tuple of str
        What the band left out and why (a failed design, a cut tolerance, no refinement).
    time : float
        Seconds spent.
    """

    names: tuple
    nominal: np.ndarray
    band: np.ndarray
    contributions: dict = field(default_factory=dict)
    values: dict = field(default_factory=dict)
    notes: tuple = ()
    time: float = 0.0

    def __repr__(self) -> str:
        return compact_repr(self, ("names", "nominal", "band", "notes"))

    @property
    def low(self) -> np.ndarray:
        return self.band[:, 0]

    @property
    def high(self) -> np.ndarray:
        return self.band[:, 1]

    def table(self) -> str:
        """One line per muscle: nominal stroke, band, each source's deviations; then the notes."""
        src = list(self.contributions)
        head = f"{'muscle':<10} {'stroke':>10} {'low':>10} {'high':>10}" + "".join(f" {s:>22}" for s in src)
        rows = [head]
        for i, n in enumerate(self.names):
            rows.append(f"{n:<10} {self.nominal[i]:>10.4g} {self.band[i, 0]:>10.4g} {self.band[i, 1]:>10.4g}"
                        + "".join(f" {f'{self.contributions[s][i, 0]:+.3g} / {self.contributions[s][i, 1]:+.3g}':>22}"
                                  for s in src))
        rows.append("strokes, bands and deviations in the mesh's length units")
        rows += [f"note: {n}" for n in self.notes]
        return "\n".join(rows)

    def to_dict(self) -> dict:
        """Every field, JSON-ready."""
        return to_jsonable({"names": list(self.names), "nominal": self.nominal, "band": self.band,
                            "contributions": self.contributions, "values": self.values, "notes": list(self.notes),
                            "time": self.time})


def refine_mesh(mesh: Mesh) -> tuple[Mesh, np.ndarray]:
    """``mesh`` refined once: every triangle split into four at its edges' midpoints.

    Returns the refined mesh (the old nodes first, in their order, then one node per row of
    ``mesh.edges``) and the ``(k, 2)`` array of the edges (old node pairs) whose midpoints are the new nodes
    ``n, n + 1, ...``. The outline and the holes are the same polygons; angles are kept.
    """
    if not isinstance(mesh, Mesh):
        raise TypeError(f"mesh must be a Mesh, got {type(mesh).__name__}")
    n, e = mesh.n_nodes, mesh.edges
    P = mesh.points
    mid = {(int(a), int(b)): n + k for k, (a, b) in enumerate(e)}

    def m(a, b):
        return mid[(a, b) if a < b else (b, a)]

    tris = []
    for a, b, c in mesh.triangles.tolist():
        ab, bc, ca = m(a, b), m(b, c), m(c, a)
        tris += [(a, ab, ca), (ab, b, bc), (ca, bc, c), (ab, bc, ca)]
    pts = np.vstack([P, 0.5 * (P[e[:, 0]] + P[e[:, 1]])])
    return Mesh(pts, np.asarray(tris, dtype=np.int64)), np.asarray(e)


def _refined(mesh: Mesh, muscles, target, held=None):
    """The refined mesh, the muscles along it (every edge split at its midpoint), the target on it and the
    held nodes on it (``held`` and the midpoints of the edges between two held nodes; None stays None)."""
    fine, e = refine_mesh(mesh)
    n = mesh.n_nodes
    index = {(int(a), int(b)): n + k for k, (a, b) in enumerate(e)}
    mus = []
    for mu in muscles:
        path = [int(mu.nodes[0])]
        for a, b in zip(mu.nodes[:-1], mu.nodes[1:]):
            path += [index[(min(a, b), max(a, b))], int(b)]
        mus.append(Muscle(tuple(path), name=mu.name))
    y = np.asarray(target, dtype=float)
    if held is not None:
        both = np.isin(e, np.asarray(held)).all(axis=1)
        held = np.concatenate([np.asarray(held, dtype=np.int64), n + np.flatnonzero(both)])
    return fine, mus, np.vstack([y, 0.5 * (y[e[:, 0]] + y[e[:, 1]])]), held


def stroke_bands(source, material=None, muscles=None, target=None, design=None, *, radius_tol: float | None = None,
                 nu_tol: float = NU_TOL, refine: bool = True, max_refined_nodes: int = MAX_REFINED_NODES,
                 **design_options) -> StrokeBands:
    """Every designed stroke's band under the fixture size, Poisson's ratio and one mesh refinement.

    See the module docstring for the sources and how they combine.

    Parameters
    ----------
    source : PipelineResult or Mesh
        A pipeline's result (its mesh, material, muscles, target and design are used; give nothing else
        positionally), or the mesh of ``material, muscles, target, design``.
    material, muscles, target : the body's material, the layout and the target the design was made for.
    design : DesignResult
        The design (its method, ``a_max``, muscle model, stiffness and ``anchor_radius`` are those of the
        band's designs, which start from its contractions).
    radius_tol : float, optional
        The fixture size's tolerance (a length; default :data:`RADIUS_RTOL` times ``anchor_radius``).
    nu_tol : float, default :data:`NU_TOL`
    refine : bool, default True
        Include the mesh refinement (False: left out, and a note says so).
    max_refined_nodes : int, default :data:`MAX_REFINED_NODES`
    **design_options
        Other keywords of :func:`~mdsr_opt.synthesis.contractions.design_contractions` (``tol``,
        ``options``...), as given to the design; ``max_iter`` defaults to :data:`BAND_MAX_ITER`.

    Returns
    -------
    StrokeBands
        The caller may store ``band`` in ``design.stroke_band`` (the pipeline and ``mdsr run`` do), where
        the stroke table, the fabrication CSV and the design figure show it.

    Example
    -------
    >>> from mdsr_opt import Mesh, Muscle, NeoHookean, solve_internal
    >>> from mdsr_opt.synthesis.contractions import design_contractions
    >>> mesh, mat, mus = Mesh.rectangle(4.0, 1.0, 16, 4), NeoHookean(1.0, 0.3), [Muscle(range(1, 16))]
    >>> target = solve_internal(mesh, mat, mus, [0.15]).x
    >>> b = stroke_bands(mesh, mat, mus, target, design_contractions(mesh, mat, mus, target))
    >>> bool(b.low[0] <= b.nominal[0] <= b.high[0]), sorted(b.contributions)
    (True, ['anchor_radius', 'mesh', 'nu'])
    """
    import time

    from .contractions import design_contractions
    from .results import MuscleWarning

    t0 = time.perf_counter()
    if material is None and muscles is None and target is None and design is None:
        try:
            mesh, material, muscles, target, design = (source.mesh, source.material, source.muscles,
                                                       source.target, source.design)
        except AttributeError:
            raise TypeError("give a PipelineResult, or the mesh, material, muscles, target and design") from None
    else:
        mesh = source
    if not isinstance(mesh, Mesh):
        raise TypeError(f"mesh must be a Mesh, got {type(mesh).__name__}")
    target = check_target_shape(mesh, target)  # the check of every entry point that takes a target
    mus = tuple(muscles)
    a0 = np.asarray(design.contractions, dtype=float)
    s0 = np.asarray(design.stroke, dtype=float)
    if len(a0) != len(mus) or len(s0) != len(mus):
        raise ValueError(f"the design has {len(a0)} contraction(s) and {len(s0)} stroke(s) for {len(mus)} "
                         "muscle(s): give the muscles it was made for")
    nu_tol = positive_float(nu_tol, "nu_tol", allow_zero=True)
    max_refined_nodes = positive_int(max_refined_nodes, "max_refined_nodes")
    if not isinstance(refine, (bool, np.bool_)):
        raise TypeError(f"refine must be True or False, got {type(refine).__name__}")
    r0 = float(design.anchor_radius)
    r_tol = RADIUS_RTOL * r0 if radius_tol is None else positive_float(radius_tol, "radius_tol", allow_zero=True)
    opts = {k: v for k, v in design_options.items() if k not in ("initial_guess", "anchor_radius")}
    opts.update(method=design.method, a_max=design.a_max, muscle_model=design.muscle_model,
                stiffness=design.stiffness)
    opts.setdefault("max_iter", BAND_MAX_ITER)
    notes: list[str] = []

    def strokes(what, msh, mat, ms, y, radius):
        """The strokes of the design again on these inputs, or None (with a note) when it fails."""
        try:
            check_anchor_radius(msh, radius)
        except ValueError as exc:  # the radius plus its tolerance is too large for this body
            notes.append(f"{what}: {exc}; left out")
            return None
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore", MuscleWarning)
                res = design_contractions(msh, mat, ms, y, anchor_radius=radius, initial_guess=a0, **opts)
        except (RuntimeError, LayoutError) as exc:  # a solver failed hard, or the patches refused the layout
            notes.append(f"{what}: design refused or failed ({exc}); left out")
            return None
        if not res.success:
            notes.append(f"{what}: design failed ({res.status}); left out")
            return None
        return np.asarray(res.stroke, dtype=float)

    runs: dict[str, list] = {"anchor_radius": [], "nu": [], "mesh": []}
    values: dict[str, list] = {"anchor_radius": [], "nu": [], "mesh": []}
    if r_tol == 0:
        notes.append("anchor_radius: no tolerance (radius 0 and no radius_tol): no fixture-size part")
    else:
        for r in (max(r0 - r_tol, 0.0), r0 + r_tol):
            values["anchor_radius"].append(r)
            runs["anchor_radius"].append(strokes(f"anchor_radius {r:.4g}", mesh, material, mus, target, r))
    nu = float(material.nu)
    for v in (nu - nu_tol, nu + nu_tol):
        w = min(max(v, -0.99), NU_CAP)
        if w != v:
            notes.append(f"nu {v:.3g} is outside the models' range: {w:.3g} used")
        if w == nu:
            continue
        values["nu"].append(w)
        runs["nu"].append(strokes(f"nu {w:.3g}", mesh, type(material)(material.E, w, material.thickness), mus,
                                  target, r0))
    if not refine:
        notes.append("mesh: refinement left out (refine=False)")
    elif mesh.n_nodes + len(mesh.edges) > max_refined_nodes:
        notes.append(f"mesh: refinement left out (the refined mesh would have {mesh.n_nodes + len(mesh.edges)} "
                     f"nodes, more than max_refined_nodes {max_refined_nodes})")
    else:
        fine, fmus, fy, fheld = _refined(mesh, mus, target, opts.get("held"))
        values["mesh"].append(fine.n_nodes)
        if fheld is not None:  # the same clamp on the refined body
            opts["held"] = fheld
        runs["mesh"].append(strokes(f"mesh refined to {fine.n_nodes} nodes", fine, material, fmus, fy, r0))
    contributions = {}
    for src, got in runs.items():
        dev = [s - s0 for s in got if s is not None]
        if not values[src]:
            continue
        stack = np.vstack(dev + [np.zeros_like(s0)])
        contributions[src] = np.column_stack([stack.min(axis=0), stack.max(axis=0)])
    down = sum((c[:, 0] for c in contributions.values()), np.zeros_like(s0))
    up = sum((c[:, 1] for c in contributions.values()), np.zeros_like(s0))
    names = tuple(muscle_label(mu, i) for i, mu in enumerate(mus))
    sat = np.asarray(getattr(design, "saturated", np.zeros(len(s0), dtype=bool)), dtype=bool).reshape(-1)
    for i in np.flatnonzero(sat if sat.shape == s0.shape else np.zeros(len(s0), dtype=bool)):
        if point_band(s0[i] + down[i], s0[i] + up[i], True):  # a point: the bound, not a certainty
            notes.append(f"{names[i]}: saturated (at its bound) in the design and in every design of the band: "
                         "its stroke is the bound's (a_max, or its fixtures' cap, times its rest length), so its "
                         "band is that point; the uncertainty is in the shape reached, not in the stroke")
    return StrokeBands(names=names, nominal=s0.copy(), band=np.column_stack([s0 + down, s0 + up]),
                       contributions=contributions, values=values, notes=tuple(notes), time=time.perf_counter() - t0)
