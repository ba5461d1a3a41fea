"""A scene's one end-fixture size.

The ``[fabrication]`` table's ``fixture_radius`` and the ``[design]`` table's ``anchor_radius`` name one
thing: the radius of the fixture (bead, knot, plate) at each rope end, which the design models as a rigid
anchor patch (:mod:`mdsr_opt.synthesis.fabrication`). A scene states it in either place, or in both with one
value (:func:`fixture_radius_conflict` refuses two values); :func:`scene_fixture_radius` is the size the
consumers of a scene take for muscles it gives -- the target of an internal case, the designs of given muscles
(:func:`~mdsr_opt.scenes.cases.case_anchor_radius`, whose radii a gait of given muscles takes), the
animations of the scene's muscles and the virtual prototype. Routed ropes keep the size they were fitted to
(the routing may shrink the stated size). A case's own ``anchor_radius`` (its muscles' fixtures, e.g.
routed ropes whose fixtures had to shrink) lies between the stated ``min_fixture_radius`` and
``fixture_radius``: the routing shrinks fixtures, it never grows them.
"""

from __future__ import annotations

import math
from typing import Mapping

__all__ = ["stated_fabrication_of", "stated_fixture_radii", "scene_fixture_radius", "fixture_radius_conflict"]


def stated_fabrication_of(routing_options: Mapping | None):
    """The fabrication that routing options state (``routing_options["fabrication"]``: a Fabrication or a dict
    of its fields), or None (none stated, or ``False``: routed without one)."""
    fab = (routing_options or {}).get("fabrication")
    return None if fab is None or fab is False else fab


def stated_fixture_radii(routing_options: Mapping | None) -> tuple[float | None, float | None]:
    """``(fixture_radius, min_fixture_radius)`` as the scene's fabrication (:func:`stated_fabrication_of`)
    states them; None where it states none."""
    fab = stated_fabrication_of(routing_options)
    if fab is None:
        return None, None
    get = fab.get if isinstance(fab, Mapping) else (lambda k: getattr(fab, k, None))
    r, r_min = get("fixture_radius"), get("min_fixture_radius")
    return (None if r is None else float(r)), (None if r_min is None else float(r_min))


def scene_fixture_radius(scene) -> float | None:
    """The scene's end-fixture radius: its design ``anchor_radius``, else its fabrication's ``fixture_radius``
    (the same size, :func:`fixture_radius_conflict`), else None (the default,
    :func:`~mdsr_opt.mechanics.anchors.default_anchor_radius`)."""
    r = (getattr(scene, "design_options", None) or {}).get("anchor_radius")
    if r is not None:
        return float(r)
    return stated_fixture_radii(getattr(scene, "routing_options", None))[0]


def _same(a: float, b: float) -> bool:
    return math.isclose(a, b, rel_tol=1e-12, abs_tol=0.0)


def fixture_radius_conflict(design_radius, routing_options, case_radii: Mapping,
                            names: Mapping) -> tuple[str, str] | None:
    """Where a scene states two end-fixture sizes: ``(field, message)``, or None when it states one.

    ``design_radius`` is the design's ``anchor_radius`` (or None), ``routing_options`` holds the fabrication,
    ``case_radii`` maps a case's key to its own ``anchor_radius``. ``names`` spells the fields in the
    caller's words: ``"design"``, ``"fixture"``, ``"min"`` and ``"case"`` (a format string with ``{}`` for the
    case's key). Refused: a design ``anchor_radius`` other than the fabrication's ``fixture_radius``; a case's
    radius above the stated ``fixture_radius`` or below the stated ``min_fixture_radius``.
    """
    r_fab, r_min = stated_fixture_radii(routing_options)
    if design_radius is not None and r_fab is not None and not _same(float(design_radius), r_fab):
        return names["design"], (f"{float(design_radius):g} differs from {names['fixture']} {r_fab:g}: they are one "
                                 "size (the radius of the rope ends' fixtures, which the design calls anchor_radius); "
                                 "give one of them, or the same value in both")
    for key, rc in case_radii.items():
        if rc is None:
            continue
        rc = float(rc)
        if r_fab is not None and rc > r_fab and not _same(rc, r_fab):
            return names["case"].format(key), (f"{rc:g} is larger than {names['fixture']} {r_fab:g}: a case's own "
                                               "fixtures are the scene's, or smaller where the routing had to "
                                               f"shrink them (down to {names['min']}), never larger")
        if r_min is not None and rc < r_min and not _same(rc, r_min):
            return names["case"].format(key), (f"{rc:g} is smaller than {names['min']} {r_min:g}, the smallest "
                                               "fixture the fabrication allows")
    return None
