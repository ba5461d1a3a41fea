"""A design with contact and no method named: a gradient design without the contacts, checked with them,
made again by the derivative-free method with them only when it touches (the rule and why:
:mod:`~mdsr_opt.synthesis.contactdesign`). :func:`design_gradient_first` is the route;
:func:`~mdsr_opt.synthesis.contractions.design_contractions` takes it, passing itself as ``design`` (the designs
the route makes are its designs by a named method)."""

from __future__ import annotations

import logging
import time
import warnings

import numpy as np

from ..body.checks import check_target_shape
from ..mechanics.align import align
from ..mechanics.equilibrium import check_held
from .contactdesign import contact_words, gradient_method, target_touches, untouched
from .verify import verify_design

_LOG = logging.getLogger("mdsr_opt.synthesis.contractions")


def design_gradient_first(design, mesh, material, muscles, target, clock0: float, common: dict, flat: dict,
                          search: dict, contact_kw: dict, ckw: dict, verify_tol: float):
    """A design with contact and no method named (:mod:`~mdsr_opt.synthesis.contactdesign`): by the gradient
    method without the contacts (``common`` and the flattened NLP's ``flat`` keywords), kept when
    :func:`~mdsr_opt.synthesis.contactdesign.untouched` finds that it touches nothing and it passes its
    verification with the contacts; else made again by the derivative-free method with the contacts
    (``search``: its ``tol``, ``max_iter``, ``outer``, ``options``), started from its contractions.

    ``design`` is :func:`~mdsr_opt.synthesis.contractions.design_contractions`; ``contact_kw`` its contact
    keywords as given, ``ckw`` them checked on the unit body
    (:func:`~mdsr_opt.synthesis.contactdesign.check_design_contact`, at the door); ``verify_tol`` the
    tightest equilibrium tolerance of the check. Returns the
    :class:`~mdsr_opt.synthesis.results.DesignResult`, its ``contact_route`` saying which route."""
    gm, what = gradient_method(common["held"]), contact_words(ckw)
    hold = check_held(mesh, common["held"], None)  # the muscles are checked with it by the design below
    pressed = target_touches(mesh, check_target_shape(mesh, target), ckw, hold)
    if pressed:  # a shape the contact forces make: searched with them from the start, as when named
        _LOG.info("design: %s: by method derivative-free with %s", pressed, what)
        res = design(mesh, material, muscles, target, method="derivative-free", **common, **search,
                                  **contact_kw)
        res.contact_route = f"by method 'derivative-free' with {what}: {pressed}"
        res.status += f"; designed {res.contact_route}"
        return res
    skip, skipped = common["skip_verification"], []
    if skip is not None:  # whether the caller discarded the gradient design (its verification left out)
        def noted(r):
            why = skip(r)
            skipped.append(bool(why))
            return why
        common = dict(common, skip_verification=noted)
    _LOG.info("design: by method %s without %s, then checked with them", gm, what)
    with warnings.catch_warnings(record=True) as caught:  # issued only when this design is the answer
        warnings.simplefilter("always")
        first = design(mesh, material, muscles, target, method=gm, **common, **flat)
    why = "" if first.success else f"failed ({first.status})"
    tol, verify = min(common["inner_tol"], verify_tol), common["verify"]
    if not why:
        _ok, why, fx, gap = untouched(mesh, material, muscles, first, ckw, tol=tol, gap_rtol=common["gap_rtol"])
    if not why and ckw.get("obstacles") and first.held is None:
        # the free body's state moved rigidly into the obstacles' frame (the gauge the contact solve holds)
        al = align(first.x, fx)
        R = first.rotation @ al.R.T
        first.x, first.rotation, first.translation = al.apply(first.x), R, first.translation - R @ al.t
    if not why and verify and not (skipped and skipped[-1]):
        v = verify_design(mesh, material, muscles, first, target, weights=common["weights"],
                          gap_rtol=common["gap_rtol"], tol=tol, start="design" if verify == "design" else "rest",
                          held=first.held, **ckw)
        if v.passed:
            first.verification = v
        else:
            why = f"fails its verification with them ({v.message})"
    if not why:
        for w in caught:
            warnings.warn_explicit(w.message, w.category, w.filename, w.lineno)
        first.contact_route = (f"by method {gm!r} without {what}, then checked with them: untouched (the forward "
                               f"solve with them from rest at these contractions has no contact force and lands on "
                               f"the design's state, within {gap:.3g})"
                               + ("; verified with them" if first.verification is not None and verify else ""))
        first.status += f"; designed {first.contact_route}"
        first.time = time.perf_counter() - clock0
        first.solve_time = first.time - first.build_time
        _LOG.info("design: the %s design touches nothing with %s: kept", gm, what)
        return first
    a = np.asarray(first.contractions, dtype=float)
    start = np.clip(a, 0.0, common["a_max"]) if a.shape == (len(first.rest_lengths),) and np.isfinite(a).all() \
        else common["initial_guess"]
    _LOG.info("design: %s; designing by method derivative-free with %s, from the %s design's contractions",
              why, what, gm)
    res = design(mesh, material, muscles, target, method="derivative-free",
                              **dict(common, initial_guess=start), **search, **contact_kw)
    res.contact_route = (f"by method 'derivative-free' with {what}, started from the contractions of the {gm} "
                         f"design without them, which {why}")
    res.status += f"; designed {res.contact_route}"
    res.count_in([first], clock0)
    return res
