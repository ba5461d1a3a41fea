"""The design as the ``mdsr author`` page shows it: per-muscle lengths, strokes and tensions, the difference, and
what ``mdsr run`` says of the design (its acceptance)."""

from __future__ import annotations

import math

import numpy as np

from ..mechanics.anchors import body_size
from ..synthesis.acceptance import IDLE_CONTRACTION, difference_failure, idle_mask, rest_difference
from .contact import route_notes

__all__ = ["design_summary"]


def design_summary(session) -> dict:
    """The design of ``session`` (a :class:`~mdsr_opt.author.session.Session`) as the page shows it: per-muscle
    contraction, achieved contraction, stroke, tension, difference and what ``mdsr run`` says of it."""
    res = session.design
    target = session.target
    xd = res.x_aligned
    rows = []
    for i, m in enumerate(session.muscles):
        nodes = np.asarray(m.nodes)
        L0 = _path_length(session.mesh.points[nodes])
        Lt = _path_length(target[nodes])
        Ld = _path_length(xd[nodes])
        row = {"name": m.name, "contraction": float(res.contractions[i]), "rest_length": L0,
               "target_length": Lt, "driven_length": Ld, "achieved_geometric": 1.0 - Ld / L0,
               "stroke_geometric": L0 - Ld}
        for k in ("achieved", "stroke", "tension"):  # per-muscle fields of newer results, when present
            v = getattr(res, k, None)
            if v is not None:
                try:
                    row[k] = float(np.asarray(v, dtype=float).reshape(-1)[i])
                except (TypeError, ValueError, IndexError):
                    pass
        rows.append(row)
    dist = np.linalg.norm(xd - target, axis=1)
    return {"method": res.method, "success": bool(res.success), "status": str(res.status),
            "contractions": [float(a) for a in res.contractions], "difference": _num(res.difference),
            "relative_difference": _num(res.difference / body_size(session.mesh)),  # as `mdsr run`
            "x_aligned": xd.tolist(), "node_distance": dist.tolist(), "muscles": rows,
            # a design clamped at nodes (a case with obstacles) is shown where it stands, not aligned
            "held": getattr(res, "held", None) is not None,
            "muscle_model": getattr(res, "muscle_model", None), "params": _jsonable(session.design_params),
            "saturated": [m.name for m, sat in zip(session.muscles, res.saturated) if sat],
            "dropped": [d.to_dict() for d in session.dropped],
            # idle muscles the design kept (the design without them failed), as mdsr run's "idle ... kept"
            "idle_kept": _idle_kept(session, res),
            # what `mdsr run` says of this design: "" (within the scene's max_difference) or why it fails
            "acceptance": difference_failure(res.difference, body_size(session.mesh),
                                             *[session.acceptance[k] for k in ("max_difference",) if k in session.acceptance],
                                             units=session.units or None,
                                             rest_difference=rest_difference(session.mesh, target)),
            # what the obstacles changed and how the design met them, as mdsr run says
            "notes": list(getattr(session, "design_notes", [])) + route_notes(session),
            "layout": [{"name": m.name, "nodes": [int(v) for v in m.nodes]} for m in session.muscles]}


def _idle_kept(session, res) -> list:
    thr = float(session.acceptance.get("idle_contraction", IDLE_CONTRACTION))
    if thr <= 0 or not res.success:
        return []
    idle = idle_mask(res, thr)
    return [m.name for m, i in zip(session.muscles, idle) if i]


def _num(v):
    v = float(v)
    return v if math.isfinite(v) else None


def _path_length(p: np.ndarray) -> float:
    return float(np.linalg.norm(np.diff(p, axis=0), axis=1).sum())


def _jsonable(d: dict) -> dict:
    return {k: (v if isinstance(v, (str, int, float, bool, type(None))) else str(v)) for k, v in d.items()}
