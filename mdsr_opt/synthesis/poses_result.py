"""The result of :func:`~mdsr_opt.synthesis.poses.design_poses`: one muscle layout for several poses, each
pose's design on it, the overall verdict (:attr:`PosesResult.success`) and the per-pose one
(:attr:`PosesResult.pose_success`), saved and read back as JSON (``mdsr_opt.poses/2``)."""

from __future__ import annotations

import json
import math
import os
from dataclasses import dataclass, field

import numpy as np

from ..body.muscles import Muscle
from ..core.results import MAX_REPR, WHY_CHARS, one_line
from ..plot.style import muscle_label
from .acceptance import DroppedMuscle
from .fabrication import Fabrication

__all__ = ["PosesResult", "FORMAT"]

#: The tag :meth:`PosesResult.save` writes. ``/1`` files (before the overall ``success``) stored the per-pose
#: verdicts under ``success``; they are refused by name, not read as something else.
FORMAT = "mdsr_opt.poses/2"


@dataclass(eq=False)
class PosesResult:
    """One muscle layout for several poses and each pose's design on it.

    ``success`` is the verdict on the whole result, as :class:`~mdsr_opt.synthesis.pipeline.PipelineResult`'s
    is on one design: every pose designed and the layout mouldable. ``pose_success`` says which poses were
    designed.

    Attributes
    ----------
    names : tuple of str
        The poses, in order.
    muscles : tuple of Muscle
        The shared layout.
    rest_lengths : (m,) ndarray
        Rest length of every shared muscle (length units of the mesh).
    sources : tuple of tuple of str
        For every shared muscle, the poses whose own routing produced it (first: the one it was taken from).
    contractions, strokes, tensions : (P, m) ndarrays
        Per pose and muscle: the designed contraction, the stroke (length taken in, ``a L0`` where the design
        gives no ``stroke``) and the rope tension (NaN where the design gives none).
    differences : (P,) ndarray
        Difference index (weighted RMS node distance, a length) each pose reaches on the shared layout.
    pose_success : (P,) bool ndarray
        Each pose's design succeeded (converged, verified, moving the body towards its target); the whole
        result's verdict is :attr:`success`.
    status : tuple of str
    states : (P, n, 2) ndarray
        Each pose's designed state (aligned to rest).
    separate_differences : (P,) ndarray
        For comparison: the difference each pose reaches with its own separately routed layout (NaN when not
        compared).
    separate_n_muscles : (P,) int ndarray
        How many muscles each separate layout has (their sum: what the separate layouts need in total).
    engaged : (P, m) bool ndarray
        The muscle pulls in that pose (its path shortens in the target); a released muscle's rope is left at
        its path length in the designed state, at zero tension: a negative stroke where that path is longer
        than at rest (paid out), a positive one where the designed shape, which misses the target, shortens it
        (slack taken up).
    anchor_radius : float or None
        Radius of the rigid end patches used by the designs.
    muscle_model : str
    max_muscles : int or None
        The budget asked for.
    times : dict
        Seconds: ``routing``, ``shared`` (designs on the shared layout), ``separate``, ``total``.
    designs : dict of str to DesignResult
        The full per-pose designs (in memory only; empty after :meth:`load`).
    rest_mesh : dict or None
        The fingerprint of the mesh the layout was made on (:func:`~mdsr_opt.body.fingerprint.mesh_fingerprint`),
        saved with it; :func:`~mdsr_opt.synthesis.gait.gait_schedule` and
        :func:`~mdsr_opt.synthesis.export.export_fabrication` refuse another mesh (None: not recorded, not checked).
    rest_differences : (P,) ndarray or None
        The rest shape's difference to each pose's target (the "do nothing" design, with the designs'
        weights): a pose whose design removes less than
        :data:`~mdsr_opt.synthesis.acceptance.MIN_PROGRESS` of it is not a success
        (:func:`~mdsr_opt.synthesis.acceptance.difference_failure`); None: not recorded.
    units : str or None
        The mesh's length unit (``design_poses(units=...)``, a scene's ``units``): strokes and differences are
        in it. None: body units.
    stress_unit : str or None
        The material's stress unit (a silicone preset's ``"Pa"``): with ``units``, tables and fabrication
        files give tensions in N (:func:`~mdsr_opt.synthesis.export.export_fabrication`).
    problems : tuple of str
        Why the layout itself is no success (ropes kept for different poses that cannot be moulded in one
        layer); empty when none. :attr:`success` is False when there is any.
    fabrication : Fabrication or None
        The channel, wall and fixtures the layout was routed with, every field set (None: routed without
        one); :func:`~mdsr_opt.synthesis.export.export_fabrication` draws it.
    notes : tuple of str
        What was resolved to make the shared layout mouldable, one sentence each (as a routing's ``notes``):
        a pose's rope merged into another pose's it runs along, shortened to its part clear of the stronger
        ropes' channels and fixtures, or dropped; the fixtures made smaller than the fabrication's
        ``fixture_radius`` so that every rope keeps them; a muscle that pulls in no pose dropped (or kept, when
        the poses designed without it failed). Empty when nothing was.
    dropped : tuple of DroppedMuscle
        The muscles taken out of the layout because no pose uses them: released in every pose, or designed
        below ``idle_contraction`` (or slack) wherever engaged (``contraction``: its largest over the poses).
    """

    names: tuple
    muscles: tuple
    rest_lengths: np.ndarray
    sources: tuple
    contractions: np.ndarray
    strokes: np.ndarray
    tensions: np.ndarray
    differences: np.ndarray
    pose_success: np.ndarray
    status: tuple
    states: np.ndarray
    separate_differences: np.ndarray
    separate_n_muscles: np.ndarray
    engaged: np.ndarray | None = None
    anchor_radius: float | None = None
    muscle_model: str = "cable"
    max_muscles: int | None = None
    times: dict = field(default_factory=dict)
    designs: dict = field(default_factory=dict, repr=False)
    rest_mesh: dict | None = None
    rest_differences: np.ndarray | None = None
    units: str | None = None
    stress_unit: str | None = None
    problems: tuple = ()
    fabrication: Fabrication | None = None
    notes: tuple = ()
    dropped: tuple = ()

    @property
    def n_muscles(self) -> int:
        return len(self.muscles)

    @property
    def success(self) -> bool:
        """The whole result is a success: every pose designed (:attr:`pose_success`: converged, verified,
        moving the body towards its target) and the layout mouldable (no ``problems``)."""
        return bool(np.all(self.pose_success)) and not self.problems

    def index(self, name: str) -> int:
        """Position of pose ``name`` (ValueError naming the poses otherwise)."""
        if name not in self.names:
            raise ValueError(f"unknown pose {name!r} (poses: {', '.join(self.names)})")
        return self.names.index(name)

    def __repr__(self) -> str:
        per = ", ".join(f"{n}: {d:.3g}" + ("" if not np.isfinite(s) else f" (sep. {s:.3g})")
                        for n, d, s in zip(self.names, self.differences, self.separate_differences))
        if len(per) > 90:  # many poses: the range, not one figure per pose (one short line)
            per = f"{np.nanmin(self.differences):.3g}..{np.nanmax(self.differences):.3g}"
        sep = int(self.separate_n_muscles.sum())
        head = (f"PosesResult({len(self.names)} poses, {self.n_muscles} shared muscles (separate layouts: {sep}), "
                f"difference {per}, success={self.success}")
        tail = ", layout NOT mouldable)" if self.problems else ")"
        room = MAX_REPR - len(head) - len(tail) - len(", why=''")  # one line, as every result's repr
        why = "" if self.success else f", why={one_line(self.reason, max(min(room, WHY_CHARS), 30))!r}"
        return head + why + tail

    @property
    def reason(self) -> str:
        """Why the result is no success, in one phrase ("" when it is one): each failed pose's status, then
        the layout's :attr:`problems` (its ``repr`` shows it as ``why=...``)."""
        return "; ".join([f"pose {n}: {' '.join(str(s).split())}" for n, s, ok in
                          zip(self.names, self.status, self.pose_success) if not ok] + [str(p) for p in self.problems])

    def table(self) -> str:
        """Per pose: difference on the shared layout and on its own, and the strokes."""
        head = f"{'pose':<14} {'shared D':>10} {'own D':>10} {'own m':>5}  strokes " + \
            f"({', '.join(muscle_label(m, i) for i, m in enumerate(self.muscles))})"
        rows = [head, "-" * len(head)]
        for k, n in enumerate(self.names):
            own = self.separate_differences[k]
            own = f"{own:>10.4g}" if np.isfinite(own) else f"{'-':>10}"  # not compared, or no own layout
            rows.append(f"{n:<14} {self.differences[k]:>10.4g} {own} "
                        f"{int(self.separate_n_muscles[k]):>5d}  " + " ".join(f"{s:.4g}" for s in self.strokes[k]))
        u = f"in {self.units}" if self.units else "in the mesh's length units"
        rows.append(f"D (weighted RMS node distance) and strokes {u}")
        rows += [f"NOT a success: {p}" for p in self.problems]
        if self.dropped:  # said, as the notes say it: a rope no pose uses is not in the layout
            rows.append(f"dropped, no pose uses it: {', '.join(d.name for d in self.dropped)}")
        return "\n".join(rows)

    def to_dict(self) -> dict:
        """JSON-friendly (NaN as None); :meth:`from_dict` inverts it."""
        def fin(a):
            a = np.asarray(a, dtype=float)
            return np.where(np.isfinite(a), a, np.nan).astype(object).tolist() if a.ndim else float(a)

        def nan_none(v):
            if isinstance(v, list):
                return [nan_none(u) for u in v]
            return None if isinstance(v, float) and not math.isfinite(v) else v

        return {"names": list(self.names),
                "muscles": [{"name": m.name, "nodes": list(m.nodes)} for m in self.muscles],
                "rest_lengths": nan_none(fin(self.rest_lengths)), "sources": [list(s) for s in self.sources],
                "contractions": nan_none(fin(self.contractions)), "strokes": nan_none(fin(self.strokes)),
                "tensions": nan_none(fin(self.tensions)), "differences": nan_none(fin(self.differences)),
                "success": self.success, "pose_success": [bool(s) for s in self.pose_success],
                "status": list(self.status),
                "states": np.asarray(self.states, dtype=float).tolist(),
                "separate_differences": nan_none(fin(self.separate_differences)),
                "separate_n_muscles": [int(v) for v in self.separate_n_muscles],
                "engaged": np.asarray(self.engaged, dtype=bool).tolist(),
                "anchor_radius": self.anchor_radius, "muscle_model": self.muscle_model,
                "max_muscles": self.max_muscles, "times": {k: float(v) for k, v in self.times.items()},
                "rest_mesh": self.rest_mesh,
                "rest_differences": None if self.rest_differences is None else nan_none(fin(self.rest_differences)),
                "units": self.units, "stress_unit": self.stress_unit, "problems": list(self.problems),
                "fabrication": None if self.fabrication is None else self.fabrication.to_dict(),
                "notes": list(self.notes), "dropped": [d.to_dict() for d in self.dropped]}

    @classmethod
    def from_dict(cls, d: dict) -> "PosesResult":
        def arr(v, dtype=float):
            return np.array([[np.nan if u is None else u for u in r] if isinstance(r, list) else
                             (np.nan if r is None else r) for r in v], dtype=dtype)

        m = len(d["muscles"])
        P = len(d["names"])
        return cls(names=tuple(d["names"]),
                   muscles=tuple(Muscle(x["nodes"], name=x["name"]) for x in d["muscles"]),
                   rest_lengths=arr(d["rest_lengths"]), sources=tuple(tuple(s) for s in d["sources"]),
                   contractions=arr(d["contractions"]).reshape(P, m), strokes=arr(d["strokes"]).reshape(P, m),
                   tensions=arr(d["tensions"]).reshape(P, m), differences=arr(d["differences"]),
                   pose_success=np.array(d["pose_success"], dtype=bool), status=tuple(d["status"]),
                   states=np.array(d["states"], dtype=float), separate_differences=arr(d["separate_differences"]),
                   separate_n_muscles=np.array(d["separate_n_muscles"], dtype=int),
                   engaged=np.array(d["engaged"], dtype=bool).reshape(P, m),
                   anchor_radius=d.get("anchor_radius"), muscle_model=d.get("muscle_model", "cable"),
                   max_muscles=d.get("max_muscles"), times=dict(d.get("times", {})), rest_mesh=d.get("rest_mesh"),
                   rest_differences=None if d.get("rest_differences") is None else arr(d["rest_differences"]),
                   units=d.get("units"), stress_unit=d.get("stress_unit"), problems=tuple(d.get("problems", ())),
                   fabrication=None if d.get("fabrication") is None else Fabrication(**d["fabrication"]),
                   notes=tuple(map(str, d.get("notes", ()))),
                   dropped=tuple(DroppedMuscle(name=str(g["name"]), nodes=tuple(int(n) for n in g["nodes"]),
                                               contraction=float(g["contraction"]), reason=str(g["reason"]))
                                 for g in d.get("dropped", ())))

    def save(self, path) -> str:
        """Write :meth:`to_dict` as JSON (atomically), tagged :data:`FORMAT`. Returns the path.
        An existing file of that name is replaced, without a warning (``mdsr run`` refuses to without
        ``--overwrite``)."""
        from ..body.io import write_json

        return write_json(path, {"format": FORMAT, **self.to_dict()})

    @classmethod
    def load(cls, path) -> "PosesResult":
        """Read a result written by :meth:`save`.

        Raises
        ------
        FileNotFoundError
            No such file.
        ValueError
            The file (named) is not valid JSON, not a poses result, written in the older format
            ``mdsr_opt.poses/1``, or damaged (a field missing or of the wrong shape).
        """
        from ..body.io import read_json

        try:
            data = read_json(path)
        except (UnicodeDecodeError, json.JSONDecodeError) as exc:
            raise ValueError(f"{os.fspath(path)} is damaged: not valid JSON ({exc})") from None
        fmt = data.get("format", FORMAT) if isinstance(data, dict) else None
        if fmt == "mdsr_opt.poses/1":
            raise ValueError(f"{os.fspath(path)} is a poses result in the older format {fmt} (its 'success' is the "
                             f"per-pose list that {FORMAT} calls 'pose_success'): make the layout again with "
                             "design_poses, or the gait with mdsr run")
        if fmt != FORMAT or "names" not in data:
            raise ValueError(f"{os.fspath(path)} is not a mdsr_opt poses result (format {fmt!r})")
        try:
            return cls.from_dict(data)
        except KeyError as exc:
            raise ValueError(f"{os.fspath(path)} is damaged: field {exc.args[0]!r} is missing") from None
        except (TypeError, ValueError, AttributeError, IndexError) as exc:
            raise ValueError(f"{os.fspath(path)} is damaged: {exc}") from None
