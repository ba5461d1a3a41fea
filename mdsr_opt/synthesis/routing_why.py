"""Why routing seeded no muscle unit: the filters between the contracted edges and the seeds, with counts.

:func:`~mdsr_opt.synthesis.routing.route_muscles` seeds its units on edges that pass, in turn, the buildable
band (both nodes at the fabrication's clearance inside the outline and the holes), the seed threshold
(``seed_threshold`` times the reference contraction) and the compression filter (the contraction above
``compression_ratio`` times the largest principal stretch of the triangles beside the edge:
:func:`beside_stretch`). When no unit is seeded, :func:`no_seed_message` says which of them removed the
contracted edges, how many each, and the value of the knob that would keep some.
"""

from __future__ import annotations

import math

import numpy as np

from .fabrication import MIN_INSET_FRACTION, body_depth, boundary_distance

__all__ = ["beside_stretch", "compression_dominated", "no_feasible_message", "no_seed_message", "no_muscle_message"]

#: The contraction the message counts edges above, as the user reads a target ("8 edges contract > 5 %").
NOTABLE_CONTRACTION = 0.05


def beside_stretch(mesh, x: np.ndarray) -> np.ndarray:
    """Per edge, the largest principal stretch minus one (``sigma_1 - 1``) of the triangles beside it in ``x``."""
    sv = np.linalg.svd(mesh.deformation_gradients(x), compute_uv=False)
    stretch = sv[:, 0] - 1.0
    T = mesh.triangles
    s_edge = np.full(len(mesh.edges), -np.inf)
    for j in range(3):
        np.maximum.at(s_edge, mesh.edge_rows(T[:, j], T[:, (j + 1) % 3]), stretch)
    return s_edge


def compression_dominated(mesh, x: np.ndarray, w: np.ndarray, ratio: float = 1.0) -> np.ndarray:
    """Edges whose contraction exceeds ``ratio`` times the largest principal stretch (``sigma_1 - 1``) of the
    triangles beside them: compression, not the sideways (Poisson) response of a stretched region."""
    return w > ratio * beside_stretch(mesh, x)


def _pct(v: float) -> str:
    return f"{100 * v:.3g} %"


def no_feasible_message(w: np.ndarray, contracts: bool, fab, clearance: float, *, min_contraction: float,
                        rest_rtol: float) -> str:
    """The sentence a user reads when no edge may carry a rope at all: none inside the buildable band contracts
    (``contracts``: some edge contracts by more than ``min_contraction``; ``fab``: the fabrication, every field
    set, None without one), the target only stretches the body (no ``w`` above ``rest_rtol``), or no edge
    contracts by more than ``min_contraction``."""
    w_top = float(w.max())
    if fab is not None and contracts:
        return (f"no edge at least {clearance:.4g} inside the outline and the holes (the channel's half width "
                f"{0.5 * fab.channel_diameter:.4g} plus its wall {fab.wall:.4g}, at least min_inset_fraction "
                f"{fab.min_inset_fraction:g} of the body's size) contracts by more than min_contraction="
                f"{min_contraction:g}; no muscles routed")
    if w_top <= rest_rtol:
        return (f"no edge contracts (largest relative stretch {-float(w.min()):.3g}): the target only stretches the "
                "body and a cable cannot push; no muscles routed")
    return (f"no edge contracts by more than min_contraction={min_contraction:g} (largest contraction {w_top:.3g}); "
            "lower min_contraction to route such weak contractions. Elongated edges cannot carry a muscle (a cable "
            "cannot push); no muscles routed")


def no_muscle_message(reasons) -> str:
    """The one sentence ``mdsr run`` (a failed case) and :func:`~mdsr_opt.synthesis.pipeline.design_pipeline`
    (its ValueError) give when routing laid no muscle on a target: ``routing found no muscle on the target
    (<reasons>)``, ``reasons`` the routing's warnings (its :class:`~mdsr_opt.synthesis.routing.RoutingWarning`
    messages, which give the values that would work), else the question every such target raises."""
    why = "; ".join(str(r) for r in reasons if str(r).strip()) or \
        "muscles can only contract: does the target shorten any edge?"
    return f"routing found no muscle on the target ({why})"


def _finer_mesh(mesh, out: np.ndarray, clearance: float) -> str:
    """The hint that a finer mesh gives the contracted edges ``out`` (outside the buildable band) edges inside it,
    when it does: the body is deeper than the band's inset, and some of them reach within one of their lengths
    of the band (a node at least ``clearance`` minus the edge's length inside), so a finer mesh has whole edges
    there; empty otherwise."""
    R = body_depth(mesh)
    if R <= clearance * (1 + 1e-9):
        return ""  # the band is empty: no mesh has an edge in it
    dist, E = boundary_distance(mesh), mesh.edges
    reach = out & (np.maximum(dist[E[:, 0]], dist[E[:, 1]]) >= clearance - mesh.edge_lengths)
    if not reach.any():
        return ""
    h_mean, h_max = float(mesh.edge_lengths.mean()), 0.5 * (R - clearance)
    if h_mean > h_max:
        return (f"; {int(reach.sum())} of those reach within an edge of the band: a finer mesh (mean edge length at "
                f"most {h_max:.3g}, now {h_mean:.4g}; the body is {R:.4g} deep) gives them edges inside it")
    # the mesh is already as fine as the band asks (its edges fit in it): no finer mesh to suggest. Edges with a
    # node on the outline or a hole stay outside at any mesh and inset; the others need a thinner inset.
    wall = out & (np.minimum(dist[E[:, 0]], dist[E[:, 1]]) <= 1e-9 * R)
    head = (f"; {int(reach.sum())} of those reach within an edge of the band, on a mesh already finer than the band "
            f"asks (mean edge length {h_mean:.4g}, at most {h_max:.3g})")
    if wall.sum() == out.sum():
        return head + (": each has a node on the outline or a hole, where no rope lies at any mesh or inset")
    return head + (f": {int((out & ~wall).sum())} lie off the walls but nearer than {clearance:.4g}, where a smaller "
                   "channel_diameter or wall (or min_inset_fraction, whichever sets that inset) lets ropes reach them")


def no_seed_message(mesh, x: np.ndarray, w: np.ndarray, contracted: np.ndarray, admissible: np.ndarray | None,
                    threshold: float, eligible: np.ndarray | None, *, min_contraction: float,
                    seed_threshold: float, compression_ratio: float, clearance: float | None,
                    min_inset_fraction: float | None = None) -> str:
    """The sentence a user reads when routing seeded no unit: which filter removed the contracted edges.

    Parameters
    ----------
    mesh, x : the rest mesh and the target.
    w : (E,) ndarray
        Each edge's relative contraction.
    contracted : (E,) bool ndarray
        The edges contracting by more than ``min_contraction``.
    admissible : (E,) bool ndarray or None
        The buildable band (None: no fabrication, every edge).
    threshold : float
        The seed threshold (a contraction).
    eligible : (E,) bool ndarray or None
        The compression filter's verdict (None: not applied).
    min_contraction, seed_threshold, compression_ratio : the knobs, quoted in the message.
    clearance : float or None
        The band's inset (None: no fabrication).
    min_inset_fraction : float, optional
        The fabrication's least inset as a fraction of the body's diameter, quoted in the message (default
        :data:`~mdsr_opt.synthesis.fabrication.MIN_INSET_FRACTION`).
    """
    n_c = int(contracted.sum())
    notable = int((w > NOTABLE_CONTRACTION).sum())
    head = (f"no muscle unit could be seeded: {n_c} edge(s) contract by more than min_contraction="
            f"{min_contraction:g} (the largest {_pct(float(w.max()))}"
            + (f", {notable} by more than {_pct(NOTABLE_CONTRACTION)}" if notable else "") + ")")
    parts = []
    left = contracted.copy()
    if admissible is not None:
        out = left & ~admissible
        if out.any():
            frac = MIN_INSET_FRACTION if min_inset_fraction is None else min_inset_fraction
            parts.append(f"{int(out.sum())} lie outside the buildable band (a node closer than {clearance:.4g} to "
                         f"the outline or a hole: half the channel plus its wall, at least min_inset_fraction "
                         f"{frac:g} of the body's size)"
                         + (f", {int((out & (w > NOTABLE_CONTRACTION)).sum())} of those contracting by more than "
                            f"{_pct(NOTABLE_CONTRACTION)}" if notable else "") + _finer_mesh(mesh, out, clearance))
        left &= admissible
    if not left.any() and not parts:  # nothing contracts: the head says it all
        return head + "; no muscles routed"
    if not left.any():
        return (head + "; but " + parts[0] + ", so none is left: a smaller channel_diameter or wall, or a finer "
                "mesh, gives the ropes room nearer the outline; no muscles routed")
    below = left & (w < threshold)
    if below.any():
        parts.append(f"{int(below.sum())} of the rest contract less than the seed threshold {_pct(threshold)} "
                     f"(seed_threshold={seed_threshold:g} times the reference contraction)")
    strong = left & ~below
    hint = ""
    if eligible is not None and strong.any():
        cut = strong & ~eligible
        if cut.any():
            s = beside_stretch(mesh, x)[cut]
            ratios = np.where(s > 0, w[cut] / np.where(s > 0, s, 1.0), np.inf)
            top = float(ratios.max())  # the largest compression_ratio that keeps one of them
            suggest = math.floor(20.0 * top * (1 - 1e-9)) / 20.0
            if suggest <= 0:
                suggest = float(f"{0.9 * top:.2g}")
            kept = int((ratios > suggest).sum())
            everything = " all" if not (strong & eligible).any() else ""
            parts.append(f"the compression_ratio filter ({compression_ratio:g}) removed{everything} "
                         f"{int(cut.sum())} of the {int(strong.sum())} above it (an edge seeds only where it "
                         f"contracts by more than compression_ratio times the largest principal stretch beside "
                         f"it: compression, not the sideways response to a stretch)")
            if suggest < compression_ratio:
                half = int((ratios > 0.5).sum())
                hint = (f"; try compression_ratio={suggest:g} or lower (it keeps {kept} of them"
                        + (f", 0.5 keeps {half}" if suggest > 0.5 and half > kept else "") + ")")
    if not parts or eligible is not None and (strong & eligible).any():
        parts.append(f"{int((strong if eligible is None else strong & eligible).sum())} passed every filter but "
                     f"no path within max_turn could be cut from them")
    return head + "; of them " + "; ".join(parts) + hint + "; no muscles routed"
