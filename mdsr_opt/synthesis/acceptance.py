"""What a design must show before it counts as one: no idle muscle, and a shape close enough to the target.

An optimiser that converges has found the best contractions for the layout it was given; that is not yet a
robot. Two outcomes used to pass unnoticed:

- an *idle* muscle, designed to a contraction below :data:`IDLE_CONTRACTION`, or a rope slack at the
  designed state (no tension): a rope a workshop would mould, thread and fix for nothing. It is not always harmless: a rope held at its rest length stops the
  body from stretching along it, and the bound ``a >= 0`` keeps the design from paying it out, so the
  layout without it can only reach the target as closely or closer. :func:`design_active` drops it and
  designs again, and says so (:class:`DroppedMuscle`); when every muscle is idle the design does not move
  the body and is no success.
- a difference to the target larger than a stated fraction of the body's size: :data:`MAX_DIFFERENCE`,
  the default bound of :func:`difference_failure`, with which ``mdsr run`` fails a case. The size is the
  body's diameter at rest (:func:`~mdsr_opt.mechanics.anchors.body_size`), which does not change when the
  body is rotated (the bounding-box diagonal ``mesh.size`` of a square grows by 41 % turned 45 degrees).
- a design that barely moves the body: a target close to the rest shape is within that fraction of the size
  even when every muscle does nothing, so :func:`difference_failure` also compares the design's difference
  with the rest shape's (the "do nothing" design) and fails a design that covers less than
  :data:`MIN_PROGRESS` of the way from rest to the target.

A muscle at ``a_max`` is flagged by the design itself
(:attr:`~mdsr_opt.synthesis.results.DesignResult.saturated` and a
:class:`~mdsr_opt.synthesis.results.MuscleWarning`).
"""

from __future__ import annotations

import logging
import math
import numbers
import warnings
from dataclasses import asdict, dataclass
from typing import Sequence

import numpy as np

from ..body.muscles import Muscle
from ..core.checks import positive_float
from ..core.quantities import percent_beside
from ..core.results import to_jsonable
from ..mechanics.align import difference, node_weights
from ..plot.style import muscle_label, muscle_name

_LOG = logging.getLogger(__name__)

__all__ = ["A_MAX", "IDLE_CONTRACTION", "MAX_DIFFERENCE", "MIN_PROGRESS", "BANDS", "AcceptanceWarning", "DroppedMuscle",
           "design_active", "idle_mask", "as_good", "difference_failure", "rest_difference", "check_idle_contraction", "check_max_difference"]

#: a designed contraction below this (a fraction of the rope's rest length) leaves the muscle idle
IDLE_CONTRACTION = 1e-3

#: the largest contraction a design gives a muscle unless told otherwise (``design_contractions``' ``a_max``):
#: a muscle at it is ``saturated``, and an idle threshold must lie below it (the same number as that default:
#: tests/test_door_fractions.py checks it)
A_MAX = 0.6

#: the largest difference to the target, as a fraction of the body's size (its diameter at rest,
#: :func:`~mdsr_opt.mechanics.anchors.body_size`), with which a case of ``mdsr run`` is a success
MAX_DIFFERENCE = 0.05

#: the least fraction of the rest shape's difference to the target a design must remove (``1 - D / D_rest``)
#: to count as moving the body towards it (:func:`difference_failure`): a bar against designs that do next to
#: nothing, not a measure of quality (that is ``max_difference``)
MIN_PROGRESS = 0.1

#: a target nearer the rest shape than this fraction of the size is "the rest shape": no progress is asked
REST_TOLERANCE = 1e-3

#: a target nearer the rest shape than this fraction of the size (after alignment) is nearly a rigid motion of it:
#: :func:`difference_failure` says so when a design makes no progress towards it
NEAR_RIGID = 0.01


class AcceptanceWarning(UserWarning):
    """A design found and verified (``success``) that lies farther from its target than ``mdsr run`` accepts
    (:func:`difference_failure` with :data:`MAX_DIFFERENCE` and :data:`MIN_PROGRESS`): a stable state, but not
    the shape asked for."""

#: whether ``mdsr run`` and the scene runner compute every stroke's uncertainty band unless told
#: (:func:`~mdsr_opt.synthesis.bands.stroke_bands`: four to five more designs per case, 3-6 times the
#: design's own time on the library's coarse scenes; ``--bands`` or a scene's ``[acceptance] bands = true``)
BANDS = False


@dataclass(frozen=True)
class DroppedMuscle:
    """A muscle taken out of a layout after its design, and why.

    Attributes
    ----------
    name : str
        Its name (or ``"M<k+1>"``, its place ``k`` in the layout given, when unnamed:
        :func:`mdsr_opt.plot.style.muscle_label`).
    nodes : tuple of int
        Its path.
    contraction : float
        The contraction it was designed to before it was dropped.
    reason : str
    """

    name: str
    nodes: tuple
    contraction: float
    reason: str

    def to_dict(self) -> dict:
        """The fields, JSON-ready."""
        return to_jsonable(asdict(self))


def check_idle_contraction(value, name: str = "idle_contraction", a_max=None) -> float:
    """``value`` as a contraction threshold in ``[0, 1)`` (0: drop nothing), below the design's ``a_max``
    when that is given (at or above it every muscle would be idle); TypeError/ValueError naming ``name``
    otherwise."""
    v = positive_float(value, name, allow_zero=True)
    if v >= 1.0:
        raise ValueError(f"{name} must lie in [0, 1) (a fraction of the rope's rest length), got {v:g}")
    if a_max is not None and v > 0 and isinstance(a_max, numbers.Real) and not isinstance(a_max, bool) \
            and v >= a_max:
        raise ValueError(f"{name} ({v:g}) must lie below a_max ({a_max:g}), the most a design contracts a "
                         f"muscle: every muscle would count as idle (the threshold is {100 * IDLE_CONTRACTION:g} % "
                         "by default)")
    return v


def check_max_difference(value, name: str = "max_difference") -> float:
    """``value`` as a fraction of the body's size in ``(0, 1]`` (``inf``: no bound); TypeError/ValueError
    naming ``name`` otherwise. A value above 1 (a difference larger than the body) is refused as a percent
    typed by mistake: 5 would turn the acceptance off, where 0.05 was meant."""
    if isinstance(value, (int, float)) and not isinstance(value, bool) and value == math.inf:
        return math.inf
    v = positive_float(value, name)
    if v > 1.0:
        raise ValueError(f"{name} is a fraction of the body's size (0.05 = 5 %), got {v:g}: a difference "
                         f"larger than the body accepts any design; give {v / 100:g} for {v:g} %, or inf for "
                         "no bound")
    return v


def rest_difference(mesh, target, design_options: dict | None = None) -> float:
    """The rest shape's difference to ``target`` (the "do nothing" design, :func:`difference_failure`'s
    ``rest_difference``), with the weights a design made with ``design_options`` measures by: their ``weights``,
    else :func:`~mdsr_opt.mechanics.align.node_weights` with their ``interior_weight`` (default 0.5)."""
    opts = design_options or {}
    w = opts.get("weights")
    w = node_weights(mesh, opts.get("interior_weight", 0.5)) if w is None else np.asarray(w, dtype=float)
    return float(difference(mesh.points, target, w))


def difference_failure(difference: float, size: float, max_difference: float = MAX_DIFFERENCE,
                       units: str | None = None, rest_difference: float | None = None,
                       min_progress: float = MIN_PROGRESS, n_anchors: int | None = None) -> str:
    """Why a design's ``difference`` (a length) to its target fails, or ``""`` when it passes.

    ``size`` is the body's size, a length: its diameter at rest (:func:`~mdsr_opt.mechanics.anchors.body_size`,
    the same however the body is turned) wherever ``mdsr run`` and the design tools judge a design.
    It fails when it is above ``max_difference * size``, and, given ``rest_difference`` (the rest shape's
    difference to the same target, with the same weights), when it removes less than ``min_progress`` of it:
    ``difference > (1 - min_progress) * rest_difference``; a target within :data:`REST_TOLERANCE` of the
    size of the rest shape asks for no progress. Lengths are quoted in ``units`` (default ``"body units"``).

    Why a design makes no progress is said as the numbers allow: a target within :data:`NEAR_RIGID` of the
    size of the rest shape after alignment is nearly a rigid motion of it, and with ``n_anchors == 1`` (the
    number of anchor nodes, when known) that is why: the body turns freely about its one anchor node, the
    drags turn it and leave the muscles little to do (anchor a region); else "the muscles barely move the
    body".

    Example
    -------
    >>> difference_failure(0.01, 1.0)
    ''
    >>> difference_failure(0.12, 2.0, 0.05, units="mm")
    'difference 0.12 mm is 6.00 % of the size 2 mm, more than max_difference 5 %'
    >>> difference_failure(0.043, 1.0, rest_difference=0.045)[:40]
    'the design removes 4 % of the rest shape'
    >>> difference_failure(0.9034, 100.0, rest_difference=1.0)[:42]   # 9.66 %: not "10 %", the threshold
    'the design removes 9.7 % of the rest shape'
    """
    from ..plot.style import unit_label

    d, u = float(difference), unit_label(units)
    if not math.isfinite(d):
        return "its difference is not finite (no shape to compare)"
    if d > max_difference * size:
        return (f"difference {d:.3g} {u} is {percent_beside(d / size, max_difference, 2)} % of the size {size:.3g} {u}, more than "
                f"max_difference {100 * max_difference:g} %")
    if rest_difference is None:
        return ""
    d0 = float(rest_difference)
    if not math.isfinite(d0) or d0 <= REST_TOLERANCE * size or d <= (1.0 - min_progress) * d0:
        return ""
    head = (f"the design removes {percent_beside(1.0 - d / d0, min_progress)} % of the rest shape's difference {d0:.3g} {u} "
            f"to the target (difference {d:.3g} {u}), less than min_progress {100 * min_progress:g} %: ")
    rigid = f"{100 * d0 / size:.2g} % of the size {size:.3g} {u}"
    one = n_anchors == 1
    if one and d0 < NEAR_RIGID * size:
        return head + (f"the anchors are a single node, about which the body turns freely, so the drags turn it "
                       f"nearly rigidly (the target differs from the rest shape by {rigid} after alignment) and leave "
                       "the muscles little to do: anchor a region of several nodes (a larger radius or box)")
    if d0 < NEAR_RIGID * size:
        return head + (f"the muscles barely move the body, and the target is nearly a rigid motion of the rest "
                       f"shape (it differs by {rigid} after alignment): do the anchors hold the body?")
    return head + "the muscles barely move the body" + (" (the anchors are a single node, about which it turns "
                                                         "freely)" if one else "")


def design_active(mesh, material, muscles: Sequence[Muscle], target, *, idle_contraction: float = IDLE_CONTRACTION,
                  drop_slack: bool | None = None, **design_options):
    """:func:`~mdsr_opt.synthesis.contractions.design_contractions`, then every idle muscle (designed
    contraction below ``idle_contraction``, or a rope slack at the designed state) dropped from the layout
    and the design made again on the others (started from their contractions and, unless ``warm_start`` says
    otherwise, from the state just designed), until no muscle is idle.

    A slack rope carries no tension at the designed state: its length constraint is inactive there, so the
    layout without it has the same equilibrium, and a workshop would build and drive it for nothing.

    Parameters
    ----------
    mesh, material, muscles, target : as for ``design_contractions``.
    idle_contraction : float in [0, 1), default :data:`IDLE_CONTRACTION`
        The threshold (0 and ``drop_slack=False``: keep every muscle).
    drop_slack : bool, optional
        Also drop the ropes the design reports ``slack`` (no tension); default: when ``idle_contraction > 0``.
        Only exact cables (``muscle_model="cable"``, the default) count: a spring under compression pushes.
    **design_options
        Keywords of ``design_contractions``.

    Returns
    -------
    design : DesignResult
        The design of the muscles kept. Its ``status`` names what was dropped. When every muscle is idle,
        nothing is dropped and ``success`` is False (the design does not move the body). A design without the
        idle muscles whose optimiser stopped short (an evaluation cap, say) is a success when it is verified,
        rejected for nothing and no farther from the target than the design with them (to :data:`IDLE_RTOL`);
        when it fails otherwise, the design with them is returned, its ``status`` saying so, and a
        :class:`~mdsr_opt.synthesis.results.MuscleWarning` names the idle muscles kept.
    muscles : tuple of Muscle
        The muscles kept (those of ``design``).
    dropped : tuple of DroppedMuscle

    Only the warnings of the design returned are issued (a
    :class:`~mdsr_opt.synthesis.results.MuscleWarning` for a saturated muscle, for instance).
    """
    from .contractions import design_contractions

    thr = check_idle_contraction(idle_contraction, a_max=design_options.get("a_max", A_MAX))
    drop_slack = (thr > 0 if drop_slack is None else bool(drop_slack)) and \
        design_options.get("muscle_model", "cable") == "cable"
    # unnamed muscles are named by their place in the layout given (M1, M2, ...), so that a muscle keeps its
    # name in the design made again without the idle ones
    mus = tuple(Muscle(mu.nodes, name=muscle_name(i)) if isinstance(mu, Muscle) and not mu.name else mu
                for i, mu in enumerate(muscles))
    where = np.arange(len(mus))
    opts = dict(design_options)
    dropped: list[DroppedMuscle] = []
    dropping = thr > 0 or drop_slack
    deferred = dict(opts)
    if dropping and opts.get("verify", True):
        # a design with idle muscles (some, not all) is made again without them: its own verification, a
        # forward solve from rest, is left out; the design kept is verified as always
        def defer(r):
            idle = idle_mask(r, thr, drop_slack)
            return "idle muscle(s) to drop first" if idle.any() and not idle.all() else ""
        deferred["skip_verification"] = defer
    res, caught = _designed(design_contractions, mesh, material, mus, target, deferred)
    asked = opts  # the options of the design res (without the deferral)
    while res.success and dropping:
        a = np.asarray(res.contractions, dtype=float)
        idle = idle_mask(res, thr, drop_slack)
        if not idle.any():
            break
        if idle.all():
            res.success = False
            high = thr > IDLE_CONTRACTION and np.nanmax(a, initial=0.0) >= IDLE_CONTRACTION
            res.status += (f"; every muscle is idle (contractions {', '.join(f'{v:.3g}' for v in a)} below "
                           f"idle_contraction {thr:g}): the design does not move the body"
                           + (f" by more than that threshold, above the default {IDLE_CONTRACTION:g}: lower it "
                              "to keep these muscles" if high else ""))
            break
        keep = np.flatnonzero(~idle)
        gone = [DroppedMuscle(name=muscle_label(mu, where[i]), nodes=tuple(int(n) for n in mu.nodes),
                              contraction=float(a[i]), reason=f"idle: designed contraction {a[i]:.3g} below "
                              f"idle_contraction {thr:g}" if a[i] < thr else f"idle: slack at the designed "
                              f"state (contraction {a[i]:.3g}, no tension): it does not pull")
                for i, mu in enumerate(mus) if idle[i]]
        more = {"initial_guess": a[keep]}
        if opts.get("warm_start", True) in (True, "target") and np.isfinite(res.x).all():
            # the state just designed is near an equilibrium without the idle muscles (exactly one when
            # they were slack): the warm start's forward solve starts there rather than from the target
            more["warm_start"] = res.x
        _LOG.info("design: idle muscle(s) %s left out; designing again with the %d kept",
                  ", ".join(g.name for g in gone), len(keep))
        again, caught_again = _designed(design_contractions, mesh, material, tuple(mus[i] for i in keep), target,
                                        dict(deferred, **more))
        names = ", ".join(g.name for g in gone)
        if not again.success and as_good(again, res):
            # the optimiser stopped short (its evaluation cap, say) no farther from the target than the design
            # with the idle muscles, a success: the layout without them does as well, verified, with fewer ropes
            again.success = True
            again.status += (f"; a success all the same: verified, at a difference {again.difference:.4g} no larger "
                             f"than the design with {names} ({res.difference:.4g}, to {100 * IDLE_RTOL:g} %)")
        if not again.success:
            why = again.status
            if res.verification is None and asked.get("verify", True):
                # the design with them was left unverified: made again, verified, to be returned
                res, caught = _designed(design_contractions, mesh, material, mus, target, asked)
            res.status += f"; idle muscle(s) {names} kept: the design without them failed ({why})"
            from .results import MuscleWarning

            caught.append(warnings.WarningMessage(
                MuscleWarning(f"idle muscle(s) {names} kept in the layout (contraction below idle_contraction "
                              f"{thr:g}, or a slack rope): the design without them failed ({why}); they may be "
                              "left out of the build"), MuscleWarning, __file__, 0))
            break
        dropped += gone
        again.status += f"; idle muscle(s) {names} dropped and the design made again"
        if getattr(res, "fallback", "") and not again.fallback:  # how the layout with them was designed
            again.status += f" (the layout with them: {res.fallback})"
        res, caught, mus, where = again, caught_again, tuple(mus[i] for i in keep), where[keep]
        asked = dict(opts, **more)
    for w in caught:
        warnings.warn_explicit(w.message, w.category, w.filename, w.lineno)
    return res, mus, tuple(dropped)


#: how much larger than the design with its idle muscles the design without them may end and still be its
#: optimum when its optimiser stopped short of its own tolerance (:func:`design_active`)
IDLE_RTOL = 1e-3


def as_good(again, res) -> bool:
    """The design ``again`` (without the idle muscles of the successful ``res``), though its optimiser did not
    report success, is verified, rejected for nothing else and ends no farther from the target than ``res``
    (to :data:`IDLE_RTOL`): :func:`design_active` and :func:`~mdsr_opt.synthesis.poses.design_poses` then
    count it a success."""
    v = getattr(again, "verification", None)
    d, d0 = float(again.difference), float(res.difference)
    return bool(res.success and v is not None and v.passed and "rejected" not in again.status
                and math.isfinite(d) and d <= d0 * (1.0 + IDLE_RTOL) + 1e-300)


def idle_mask(res, thr: float, drop_slack: bool = True) -> np.ndarray:
    """The idle muscles of the design ``res`` (as :func:`design_active` drops them): contraction below ``thr``,
    or (with ``drop_slack``) rope slack."""
    a = np.asarray(res.contractions, dtype=float)
    slack = np.asarray(getattr(res, "slack", ()), dtype=bool).reshape(-1)
    slack = slack if drop_slack and slack.shape == a.shape else np.zeros(a.shape, dtype=bool)
    return (np.isfinite(a) & (a < thr)) | slack


def _designed(design_contractions, mesh, material, mus, target, opts):
    """One design and the warnings it issued (held back: only the design kept issues them; the caller's
    filters still apply, so a warning turned into an error raises here)."""
    with warnings.catch_warnings(record=True) as caught:
        res = design_contractions(mesh, material, mus, target, **opts)
    return res, list(caught)
