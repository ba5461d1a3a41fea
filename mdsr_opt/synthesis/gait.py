"""Gait schedules: the strokes of every muscle over a cyclic sequence of poses on one shared layout.

:func:`gait_schedule` takes a :class:`~mdsr_opt.synthesis.poses_result.PosesResult` (one layout, every pose's strokes) and a
sequence of its poses, interpolates the strokes linearly between them and solves every frame forward. The
schedule is written as a CSV actuation schedule in length units (:meth:`GaitSchedule.write_csv`), drawn as
a chart (:func:`mdsr_opt.plot.design.plot_schedule`) and replayed as a GIF (:func:`save_gait_animation`). :func:`run_gait` is
the scene runner's hook: layout, schedule, chart, GIF and fabrication files of a scene's :class:`Gait`.
"""

from __future__ import annotations

import csv
import os
import warnings
from dataclasses import dataclass, field
from typing import Mapping, Sequence

import numpy as np

from ..core.guards import interruptible
from ..body.fingerprint import check_same_mesh, mesh_fingerprint
from ..body.mesh import Mesh
from ..body.muscles import Muscle
from ..core.checks import check_options, keyword_names, positive_float, positive_int
from ..core.quantities import BODY_UNITS, length_unit
from ..core.results import compact_repr, load_fields, save_fields, to_jsonable
from ..mechanics.anchors import body_size
from .acceptance import MAX_DIFFERENCE, check_max_difference, difference_failure
from .layouts import check_budget
from .poses_result import PosesResult

__all__ = ["Gait", "GaitSchedule", "GaitWarning", "gait_schedule", "save_gait_animation",
           "warm_start_state", "ZERO_STROKE"]

#: A stroke within this fraction of its rope's rest length of zero is zero: the rope held at its rest length (in
#: the frame's solve at contraction 0, able to pull), not paid out. Round-off leaves a pose's zero stroke at about
#: -1e-16 of the length; at the same 1e-9 :func:`~mdsr_opt.synthesis.poses.design_poses` counts a path as shortening.
ZERO_STROKE = 1e-9


class GaitWarning(UserWarning):
    """A keyframe of a gait schedule does not reach its pose (:attr:`GaitSchedule.reasons` says why)."""


# ---------------------------------------------------------------------------------------------- gait
def warm_start_state(mesh: Mesh, x) -> np.ndarray | None:
    """A solved state ``x`` (aligned to rest, as the solvers return it) moved rigidly so that the solver's
    three gauge coordinates (:func:`~mdsr_opt.mechanics.equilibrium.gauge_coordinates`) have their rest
    values: a first guess for a nearby solve (``initial_guess=``). None when no rigid motion does it or
    ``x`` inverts an element. The same as :func:`~mdsr_opt.mechanics.equilibrium.in_gauge_frame`, which
    :func:`~mdsr_opt.solve_internal` now applies to any state given as ``initial_guess`` itself.

    A frame of an animation started from its neighbour's state this way takes 4-9 iterations where the
    default start needs 3-40 (and 473 at a 50 % contraction that load stepping from rest found hard).
    """
    from ..mechanics.equilibrium import in_gauge_frame

    return in_gauge_frame(mesh, np.asarray(x, dtype=float).reshape(-1, 2))


def _frames(value, name: str = "frames_per_step") -> int:
    return positive_int(value, name)


@dataclass(frozen=True)
class Gait:
    """A cyclic sequence of a scene's poses played on one shared layout (the scene-file ``[gait]`` block).

    Parameters
    ----------
    name : str
        Output folder name (``out/<name>/``).
    sequence : tuple of str
        Case names in order; ``"rest"`` means every stroke zero. With ``cyclic`` the first pose closes the
        cycle. Every case named (except ``"rest"``) is a pose of the shared layout.
    frames_per_step : int
        Frames from one pose to the next (the next excluded); total ``steps * frames_per_step + 1``.
    max_muscles : int, optional
        The shared layout's muscle budget.
    step_time : float
        Seconds from one pose to the next (the schedule's time axis).
    cyclic : bool
    fps : float
        Frames per second of the GIF.
    """

    name: str
    sequence: tuple
    frames_per_step: int = 6
    max_muscles: int | None = None
    step_time: float = 1.0
    cyclic: bool = True
    fps: float = 8.0

    def __post_init__(self):
        if not isinstance(self.name, str) or not self.name or not all(c.isalnum() or c in "_-" for c in self.name):
            raise ValueError(f"gait name must be letters, digits, '_' and '-', got {self.name!r}")
        seq = tuple(str(s) for s in self.sequence)
        if not seq:
            raise ValueError(f"gait {self.name!r}: the pose sequence is empty")
        if all(s == "rest" for s in seq):
            raise ValueError(f"gait {self.name!r}: names no pose other than 'rest'")
        if len(seq) < 2 and not self.cyclic:
            raise ValueError(f"gait {self.name!r}: a non-cyclic gait needs at least two poses")
        object.__setattr__(self, "sequence", seq)
        object.__setattr__(self, "frames_per_step", _frames(self.frames_per_step))
        check_budget(self.max_muscles)
        positive_float(self.step_time, f"gait {self.name!r}: step_time")  # a string or bool: TypeError
        positive_float(self.fps, f"gait {self.name!r}: fps")

    @property
    def poses(self) -> tuple[str, ...]:
        """The poses named (no repeats, no ``"rest"``)."""
        return tuple(dict.fromkeys(s for s in self.sequence if s != "rest"))

    def __repr__(self) -> str:
        return compact_repr(self, ("name", "sequence", "frames_per_step", "max_muscles", "step_time", "cyclic",
                                   "fps"))

    def to_dict(self) -> dict:
        """The settings, JSON-ready (the scene-file ``[gait]`` block's keys)."""
        return {f: to_jsonable(getattr(self, f)) for f in self.__dataclass_fields__}


@dataclass(eq=False)
class GaitSchedule:
    """The strokes of every muscle over a gait, and the forward-solved states.

    Attributes
    ----------
    sequence : tuple of str
        The keyframe poses in order (the cycle closed: last = first when cyclic).
    frames_per_step : int
    times : (F,) ndarray
        Seconds (``step_time`` per step).
    keyframes : (K,) int ndarray
        Frame index of every keyframe.
    labels : tuple of str
        Per frame, the pose or ``"a->b 2/5"``.
    muscle_names : tuple of str
    rest_lengths : (m,) ndarray
    strokes : (F, m) ndarray
        Commanded strokes (length taken in by each muscle; linear between the designed poses).
    achieved : (F, m) ndarray
        Strokes the forward solve achieved (NaN when the solver gives none).
    tensions : (F, m) ndarray
    states : (F, n, 2) ndarray
    frame_success : (F,) bool ndarray
        Per frame, its forward solve succeeded.
    status : tuple of str
    units : str
        The length unit of every stroke (``"body units"`` when the mesh's is not known).
    rest_mesh : dict or None
        The fingerprint of the mesh the schedule was solved on (:func:`~mdsr_opt.body.fingerprint.mesh_fingerprint`);
        :func:`save_gait_animation` refuses another mesh (None: not recorded, not checked).
    keyframe_differences : (K,) ndarray
        Per keyframe, the difference (a length) its pose reaches on the layout (0 for ``"rest"``).
    reached : (K,) bool ndarray
        Per keyframe, its pose was reached: the pose's design succeeded, its difference passes
        :func:`~mdsr_opt.synthesis.acceptance.difference_failure` (within ``max_difference`` of the body's
        size, and removing at least :data:`~mdsr_opt.synthesis.acceptance.MIN_PROGRESS` of the rest shape's
        difference to the pose) and the keyframe's frame solved.
    max_difference : float
        That bound, a fraction of the body's size.
    reasons : tuple of str
        Per keyframe, why its pose was not reached ("" when it was).
    success : bool (property)
        The whole schedule's verdict: every frame solved and every keyframe's pose reached.
    """

    sequence: tuple
    frames_per_step: int
    times: np.ndarray
    keyframes: np.ndarray
    labels: tuple
    muscle_names: tuple
    rest_lengths: np.ndarray
    strokes: np.ndarray
    achieved: np.ndarray
    tensions: np.ndarray
    states: np.ndarray
    frame_success: np.ndarray
    status: tuple
    units: str = BODY_UNITS
    rest_mesh: dict | None = None
    keyframe_differences: np.ndarray = field(default_factory=lambda: np.zeros(0))
    reached: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=bool))
    max_difference: float = float("nan")
    reasons: tuple = ()

    @property
    def n_frames(self) -> int:
        return len(self.times)

    @property
    def success(self) -> bool:
        """Every frame solved and every keyframe's pose reached (``frame_success``, ``reached``)."""
        return bool(np.all(self.frame_success) and np.all(self.reached))

    @property
    def unreached(self) -> tuple[str, ...]:
        """The poses of the keyframes not reached (no repeats)."""
        return tuple(dict.fromkeys(self.sequence[k] for k in np.flatnonzero(~np.asarray(self.reached, bool))))

    @property
    def contractions(self) -> np.ndarray:
        return self.strokes / self.rest_lengths

    def __repr__(self) -> str:
        seq = " -> ".join(self.sequence)
        if len(seq) > 60:
            seq = f"{len(self.sequence)} keyframes"
        top = float(np.nanmax(self.strokes)) if np.isfinite(self.strokes).any() else float("nan")
        return (f"GaitSchedule({seq}, {self.n_frames} frames, {len(self.muscle_names)} "
                f"muscles, max stroke {top:.4g} {self.units}, {self.outcome()})")

    def outcome(self) -> str:
        """One phrase: the frames solved, or, when a keyframe's pose was not reached, the frames solved and
        reaching their pose and the poses never reached."""
        solved = np.asarray(self.frame_success, bool).copy()
        if not self.unreached:
            return f"{int(solved.sum())}/{self.n_frames} frames solved"
        kf = np.asarray(self.keyframes, dtype=int)
        solved[kf[~np.asarray(self.reached, bool)]] = False
        why, d = {}, {}
        for k in np.flatnonzero(~np.asarray(self.reached, bool)):
            p = self.sequence[k]
            d.setdefault(p, self.keyframe_differences[k])
            why.setdefault(p, self.reasons[k] if k < len(self.reasons) and self.reasons[k] else
                           f"max_difference {100 * self.max_difference:g} % of the size")
        return (f"{int(solved.sum())}/{self.n_frames} frames solved and reaching their pose; pose(s) "
                + ", ".join(f"{p} (difference {v:.3g} {self.units})" for p, v in d.items()) + " NOT reached ("
                + "; ".join(f"{p}: {r}" for p, r in why.items()) + ")")

    def to_dict(self) -> dict:
        """Every field, JSON-ready (arrays as nested lists, NaN as None)."""
        return {f: to_jsonable(getattr(self, f)) for f in self.__dataclass_fields__}

    def save(self, path: str | os.PathLike) -> str:
        """Write the schedule, states included, as one ``.npz`` file (arrays exactly); returns the path.
        :meth:`load` reads it back; :meth:`write_csv` writes the actuation table instead.
        An existing file of that name is replaced, without a warning (``mdsr run`` refuses to without
        ``--overwrite``)."""
        return save_fields(self, path, "gait_schedule")

    @classmethod
    def load(cls, path: str | os.PathLike) -> "GaitSchedule":
        """Read a schedule written by :meth:`save` (ValueError naming a damaged or foreign file).

        A file written before the per-frame verdicts were named ``frame_success`` (its ``success`` the
        per-frame array) is read too: that array becomes ``frame_success``."""
        return load_fields(cls, path, "gait_schedule",
                           convert={k: tuple for k in ("sequence", "labels", "muscle_names", "status", "reasons")},
                           extra=_older_frame_success)

    def write_csv(self, path) -> str:
        """The actuation schedule: one row per frame, strokes in ``units`` (atomically). Returns the path."""
        from ..body.io import atomic_path

        u = self.units
        head = ["frame", "time [s]", "pose"] + [f"{n} stroke [{u}]" for n in self.muscle_names] + \
            [f"{n} achieved [{u}]" for n in self.muscle_names] + ["solved"]
        with atomic_path(path) as tmp:
            with open(tmp, "w", newline="") as fh:
                w = csv.writer(fh)
                w.writerow(head)
                for k in range(self.n_frames):
                    w.writerow([k, f"{self.times[k]:.6g}", self.labels[k]]
                               + [f"{v:.9g}" for v in self.strokes[k]]
                               + ["" if not np.isfinite(v) else f"{v:.9g}" for v in self.achieved[k]]
                               + [int(self.frame_success[k])])
        return os.fspath(path)


@interruptible()
def gait_schedule(mesh: Mesh, material, layout: PosesResult, sequence: Sequence[str], *, frames_per_step: int = 6,
                  cyclic: bool = True, step_time: float = 1.0, units: str | None = None,
                  solve_options: Mapping | None = None, max_difference: float | None = None) -> GaitSchedule:
    """The strokes of every muscle over a cyclic sequence of poses, every frame solved forward.

    Keyframes take the designed strokes of their pose (``"rest"``: all zero). Between two keyframes the
    pulling part of every stroke (``max(stroke, 0)``) is interpolated linearly over ``frames_per_step``
    frames; a muscle that does not pull in a frame is released as far as either neighbouring pose needs
    (``min(s_i, s_{i+1}, 0)``: the servo pays the rope out first, so the body can stretch along it). Each
    frame is a forward internal-driving solve (:func:`~mdsr_opt.solve_internal` with the pulling muscles, the
    layout's muscle model and anchor radius, warm-started from the previous frame (:func:`warm_start_state`),
    else from rest); frames with equal strokes (a gait goes out and back) are solved once, and a frame in
    which no muscle pulls is the rest shape exactly. A stroke within :data:`ZERO_STROKE` of its rope's length of
    zero is zero: in a frame where another muscle pulls, that rope is held at its rest length (solved with
    contraction 0), as the pose's design held it. A released rope whose path in the solved frame is longer than
    the rope paid out would be taut: that frame is reported as failed.

    Parameters
    ----------
    mesh, material : the body of ``layout``.
    layout : PosesResult from :func:`design_poses`.
    sequence : pose names (or ``"rest"``), at least one.
    frames_per_step : int >= 1
    cyclic : bool
        Close the cycle: the first keyframe is repeated at the end.
    step_time : float
        Seconds per step.
    units : str, optional
        The mesh's length unit, written into the schedule (see :data:`mdsr_opt.synthesis.export.UNITS`);
        None (the default): the layout's (``design_poses(units=...)``), else "body units": no unit is invented.
    solve_options : dict, optional
        Extra keywords for :func:`~mdsr_opt.solve_internal` (``backend``...); ``tol`` defaults to 1e-10, the
        tolerance of the design's own forward solves (at the solver's default 1e-8 the cable's nearly slack
        ropes, strokes of ~1e-3 of their length, leave residuals of ~1e-4 that the solve rejects).
    max_difference : float, optional
        A keyframe's pose is reached when its design succeeded, its difference passes
        :func:`~mdsr_opt.synthesis.acceptance.difference_failure` (at most this fraction of the body's size,
        default :data:`~mdsr_opt.synthesis.acceptance.MAX_DIFFERENCE`, and removing at least
        :data:`~mdsr_opt.synthesis.acceptance.MIN_PROGRESS` of the rest shape's difference to the pose) and
        its frame solved (``reached``, ``reasons``; the summary names the poses not reached, and a
        :class:`GaitWarning` says why).

    Returns
    -------
    GaitSchedule
        ``n_frames = steps * frames_per_step + 1``; a failed frame solve is reported in ``frame_success`` and
        ``status``.
    """
    from ..mechanics.equilibrium import solve_internal
    from .export import check_units

    if not isinstance(layout, PosesResult):
        raise TypeError(f"layout must be a PosesResult (from design_poses), got {type(layout).__name__}")
    if not isinstance(mesh, Mesh):
        raise TypeError(f"mesh must be a Mesh, got {type(mesh).__name__}")
    if layout.states.shape[1] != mesh.n_nodes:
        raise ValueError(f"mesh is not the body of this layout: the layout's states have {layout.states.shape[1]} "
                         f"nodes, the mesh {mesh.n_nodes}")
    check_same_mesh(mesh, layout.rest_mesh, "the layout")
    fps_ = _frames(frames_per_step)
    units = check_units(units) if units is not None else length_unit(layout.units)  # none: "body units"
    if isinstance(sequence, str) or not isinstance(sequence, Sequence):
        raise TypeError(f"sequence must be a list of pose names, got {type(sequence).__name__}")
    seq = [str(s) for s in sequence]
    if not seq:
        raise ValueError("the gait's pose sequence is empty")
    for s in seq:
        if s != "rest":
            layout.index(s)
    positive_float(step_time, "step_time")
    max_difference = MAX_DIFFERENCE if max_difference is None else check_max_difference(max_difference)
    if cyclic:
        seq = seq + [seq[0]]
    if len(seq) < 2:
        raise ValueError("a non-cyclic gait needs at least two poses")
    # checked at the door (a misspelt key named with the nearest); the layout's model, fixtures and the warm
    # start are the schedule's own
    own = {"muscle_model", "anchor_radius", "initial_guess"}
    opts = {"tol": 1e-10, **check_options(solve_options, set(keyword_names(solve_internal)) - own,
                                          "solve_options")}  # the design's own forward tolerance
    m = layout.n_muscles
    key = [np.zeros(m) if s == "rest" else layout.strokes[layout.index(s)] for s in seq]
    S, labels, kf = [], [], []
    for i in range(len(seq) - 1):
        kf.append(len(S))
        lo, hi = key[i], key[i + 1]
        for j in range(fps_):
            if j == 0:
                S.append(lo.copy())
                labels.append(seq[i])
                continue
            pull = np.maximum(lo, 0) + (np.maximum(hi, 0) - np.maximum(lo, 0)) * j / fps_
            S.append(np.where(pull > 0, pull, np.minimum(np.minimum(lo, hi), 0.0)))
            labels.append(f"{seq[i]}->{seq[i + 1]} {j}/{fps_}")
    kf.append(len(S))
    S.append(key[-1].copy())
    labels.append(seq[-1])
    S = np.array(S)
    L0 = layout.rest_lengths
    S[np.abs(S) <= ZERO_STROKE * L0] = 0.0  # round-off about zero: a held rope, not a paid-out one
    F = len(S)
    ach, ten = np.full((F, m), np.nan), np.full((F, m), np.nan)
    states, ok, status = [], np.zeros(F, bool), []
    x_prev = None
    solved: dict[bytes, tuple] = {}
    for k in range(F):
        # the muscles solved: those that pull and, when any does, those held at their rest length
        on = np.flatnonzero(S[k] >= 0) if (S[k] > 0).any() else np.empty(0, dtype=int)
        key = np.round(S[k], 12).tobytes()  # a gait goes out and back: equal strokes are solved once
        if key in solved:
            x, ok[k], msg, ach_on, ten_on = solved[key]
            ach[k, on], ten[k, on] = ach_on, ten_on
        elif not len(on):  # nothing pulls: the rest shape, exactly
            x, ok[k], msg = mesh.points.copy(), True, "rest (no muscle pulls)"
        else:
            args = (mesh, material, [layout.muscles[i] for i in on], np.clip(S[k, on] / L0[on], 0.0, 0.999))
            kw = dict(muscle_model=layout.muscle_model, anchor_radius=layout.anchor_radius, **opts)
            # warm start from the previous frame's state (moved to the solver's gauge), else from the
            # default start (the predictor from rest), which is also the fallback
            guess = warm_start_state(mesh, x_prev) if x_prev is not None else None
            r = solve_internal(*args, initial_guess=guess, **kw) if guess is not None else None
            if r is None or not r.success:
                r = solve_internal(*args, **kw)
            x, ok[k], msg = np.asarray(r.x, dtype=float), bool(r.success), str(r.status)
            st, tn = getattr(r, "stroke", None), getattr(r, "tension", None)
            ach[k, on] = st if st is not None and np.size(st) == len(on) else np.nan
            ten[k, on] = tn if tn is not None and np.size(tn) == len(on) else np.nan
            solved[key] = (x, ok[k], msg, ach[k, on].copy(), ten[k, on].copy())
        x_prev = x if ok[k] else None
        off = np.setdiff1d(np.arange(m), on)
        if len(off):  # released ropes: their length is L0 - stroke; the body's path must not exceed it
            Lx = np.array([layout.muscles[i].length(x) for i in off])
            ach[k, off], ten[k, off] = L0[off] - Lx, 0.0
            over = Lx - (L0[off] - S[k, off])
            if (over > 1e-6 * L0[off]).any():
                i = int(np.argmax(over))
                ok[k] = False
                msg += (f"; released muscle {layout.muscles[off[i]].name} would be taut (its path exceeds the paid-out "
                        f"rope by {over[i]:.3g} {units})")
        states.append(x)
        status.append(msg)
    # a keyframe reaches its pose when the pose's design succeeded on the layout, passes the acceptance
    # rule (within max_difference, and removing a part of the rest shape's difference) and its frame solved
    kd = np.array([0.0 if s == "rest" else float(layout.differences[layout.index(s)]) for s in seq])
    reasons = [_unreached(layout, s, kd[i], body_size(mesh), max_difference, units, bool(ok[kf[i]]))
               for i, s in enumerate(seq)]
    reached = np.array([not r for r in reasons], dtype=bool)
    why = dict.fromkeys(f"{s}: {r}" + (f" ({layout.status[layout.index(s)]})" if r.endswith("failed") else "")
                        for s, r in zip(seq, reasons) if r)  # a failed design: its status says why
    if why:
        warnings.warn("gait_schedule: pose(s) NOT reached by the shared layout: " + "; ".join(why), GaitWarning,
                      stacklevel=3)
    return GaitSchedule(sequence=tuple(seq), frames_per_step=fps_, times=np.arange(F) * float(step_time) / fps_,
                        keyframes=np.array(kf), labels=tuple(labels),
                        muscle_names=tuple(mu.name for mu in layout.muscles), rest_lengths=L0.copy(), strokes=S,
                        achieved=ach, tensions=ten, states=np.array(states), frame_success=ok, status=tuple(status),
                        units=units, rest_mesh=mesh_fingerprint(mesh), keyframe_differences=kd, reached=reached,
                        max_difference=float(max_difference), reasons=tuple(reasons))


def _unreached(layout: PosesResult, pose: str, diff: float, size: float, max_difference: float, units: str,
               solved: bool) -> str:
    """Why a keyframe of ``pose`` does not reach it ("" when it does, and for ``"rest"``)."""
    k = None if pose == "rest" else layout.index(pose)
    if k is not None and not layout.pose_success[k]:
        return "its design on the shared layout failed"
    if not solved:
        return "its frame did not solve"
    rest = float("nan") if k is None or layout.rest_differences is None else float(layout.rest_differences[k])
    why = "" if k is None else difference_failure(diff, size, max_difference, units,
                                                  rest_difference=rest if np.isfinite(rest) else None)
    return why


def save_gait_animation(mesh: Mesh, schedule: GaitSchedule, muscles: Sequence[Muscle], path, title: str = "",
                        fps: float = 8.0) -> str:
    """Replay a schedule on its shared layout as a GIF (:func:`mdsr_opt.plot.scenes.save_animation`); ``mesh`` must be
    the body the schedule was solved on. An existing
    file of that name is replaced, without a warning (``mdsr run`` refuses to without ``--overwrite``)."""
    from ..plot.scenes import save_animation

    if not isinstance(mesh, Mesh):
        raise TypeError(f"mesh must be a Mesh, got {type(mesh).__name__}")
    if schedule.states.shape[1:] != (mesh.n_nodes, 2):
        raise ValueError(f"mesh is not the body of this schedule: its states have {schedule.states.shape[1]} "
                         f"nodes, the mesh {mesh.n_nodes}")
    check_same_mesh(mesh, schedule.rest_mesh, "the gait schedule")

    top = float(np.nanmax(schedule.contractions)) or 1.0
    titles = [f"{title} {schedule.labels[k]} (t = {schedule.times[k]:.2f} s)".strip() for k in range(schedule.n_frames)]
    return save_animation(mesh, list(schedule.states), path, muscles=list(muscles),
                          activations=np.clip(schedule.contractions / top, 0, 1), titles=titles, fps=fps,
                          units=schedule.units)


def _older_frame_success(arrays: dict, fields: dict) -> dict:
    """``fields`` with an older file's per-frame ``success`` array named ``frame_success``."""
    old = arrays.get("success")
    if "frame_success" not in fields and old is not None and np.ndim(old) == 1:
        fields = {**fields, "frame_success": np.asarray(old, bool)}
    return fields
