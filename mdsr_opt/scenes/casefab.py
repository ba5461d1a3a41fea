"""A case's fabrication files under ``mdsr run``, for a scene that states its fabrication.

A scene whose ``[fabrication]`` table (or ``routing.fabrication``) gives the channel, wall and fixtures a
workshop builds with gets, beside each designed case's figures, the case's SVG, DXF and muscle CSV
(:func:`~mdsr_opt.synthesis.export.export_fabrication`), drawn with those sizes; a case whose design failed
gets them marked ``FAILED DESIGN: <reason>, do not build``. A scene that states none gets none (its
``[gait]`` folder still holds the gait's).
"""

from __future__ import annotations

import os
import warnings
from pathlib import Path

from .fixtures import stated_fabrication_of

__all__ = ["stated_fabrication", "fixture_wall", "write_case_fabrication"]


def stated_fabrication(scene):
    """The fabrication the scene states (a Fabrication or a dict of its fields), or None (none stated, or
    ``False``: routed without one)."""
    return stated_fabrication_of(getattr(scene, "routing_options", None))


def fixture_wall(scene) -> float:
    """The wall (a length) the scene's designs keep between a rope's two end fixtures: its ``[fabrication]``
    ``wall``, else the default fabrication's for its body
    (:data:`~mdsr_opt.synthesis.fabrication.WALL_FRACTION` of the diameter)."""
    from ..synthesis.fabrication import Fabrication, check_fabrication

    return (check_fabrication(stated_fabrication(scene)) or Fabrication()).for_body(scene.mesh).wall


def write_case_fabrication(scene, run, folder) -> list[str]:
    """Write ``<scene>_<case>.svg``, ``.dxf`` and ``_muscles.csv`` of ``run`` (a designed case) into
    ``folder`` with the scene's stated fabrication and ``units`` (marked FAILED when the case failed, its
    design or its acceptance); the paths, or [] when the scene states no fabrication or the case has no
    design or no muscle."""
    from ..synthesis.export import export_fabrication
    from ..synthesis.fabrication import FabricationWarning

    fab = stated_fabrication(scene)
    if fab is None or run.design is None or run.setup is None or not len(run.setup.muscles):
        return []
    with warnings.catch_warnings():  # a layout the scene gives that cannot be moulded: the case reports it
        warnings.simplefilter("ignore", FabricationWarning)
        files = export_fabrication(scene.mesh, run.design, Path(folder), muscles=run.setup.muscles,
                                   units=scene.units, name=f"{scene.name}_{run.setup.case.name}",
                                   fabrication=fab, material=scene.material, allow_failed=True,
                                   failure="" if run.report.success else f"the case failed ({run.report.message})")
    return [os.fspath(f) for f in files.values()]
