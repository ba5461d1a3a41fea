"""Two-muscle experiment: the gripper body with two muscles, contracted by 20, 30, 40 and 50 %.

The paper checks its internal-driving model against a prototype on three bodies driven by one, two and
four independent muscle units, each contracted by 20 %, 30 %, 40 % and 50 % of its rest length (its
Figure 9 and Table 3). This scene is the two-muscle group: the C-shaped ring of ``gripper.py`` with two
muscles along its outer rim, one on the upper and one on the lower half, both contracted alike: the
gripper opens. (Muscles on the inner rim would close it, but at 20 % the jaws already meet, and the model
has no contact: beyond that they would pass through each other.) Each case
is the forward (internal-driving) solve at one contraction; the design must then recover the two
contractions from the shape alone, and routing on the shape is compared with the true muscles.

The shapes are drawn by the mdsr_opt authors from the paper's descriptions (it gives no geometry); they
are not the paper's meshes.

Material: the body's material of ``gripper.py``, ``NeoHookean(E=1.0, nu=0.4)`` in plane strain, in units where
E = 1 (E scales forces and energies only: drag- and stroke-driven shapes do not depend on it). Plane strain at
nu = 0.4 is the law the library's results were made and checked with, kept so they stay comparable; a cast
silicone robot is a thin, nearly incompressible sheet (``NeoHookean(1.0, 0.5, plane="stress")`` or
``silicone(...)``), which moves no node of these cases by more than 0.9 % of the largest motion (default
resolution).

Run ``python problems/two_muscles.py --out out/two_muscles`` or ``mdsr run two_muscles --out out/two_muscles``.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from mdsr_opt.scenes.scene import Animation, Case, Scene, resolve_resolution
from mdsr_opt.scenes.select import boundary_path
from mdsr_opt.scenes.library import load_problem_module
from mdsr_opt.scenes.runscene import run_main

LEVELS = (0.2, 0.3, 0.4, 0.5)

gripper = load_problem_module(Path(__file__).with_name("gripper.py"))


def build(resolution="medium") -> Scene:
    """The two-muscle experiment: cases ``a20`` ... ``a50`` (internal driving, the muscles given)."""
    mesh, material = gripper.body(resolution)
    ro = gripper.R0 + gripper.WIDTH / 2
    half = gripper.OPENING / 2

    def rim(a0, a1):
        return ro * np.array([np.cos(a0), np.sin(a0)]), ro * np.array([np.cos(a1), np.sin(a1)])

    upper = boundary_path(mesh, *rim(half + 0.08, np.pi - 0.12), via=ro * np.array([0.0, 1.0]), name="upper")
    lower = boundary_path(mesh, *rim(np.pi + 0.12, 2 * np.pi - half - 0.08), via=ro * np.array([0.0, -1.0]),
                          name="lower")
    cases = tuple(Case(f"a{round(100 * a)}", contractions=[a, a], description=f"both muscles contracted by {a:.0%}")
                  for a in LEVELS)
    return Scene(
        name="two_muscles", title="Two-muscle experiment (paper Figure 9, column B): 20-50 % contraction",
        description=__doc__.split("\n\n")[1].replace("\n", " "), mesh=mesh, material=material, cases=cases,
        muscles=(upper, lower), regions={"upper": list(upper.nodes), "lower": list(lower.nodes)},
        design_options={"method": "flattened", "a_max": 0.6, "muscle_model": "cable"},
        animations=(Animation("sweep", (("rest", 0.0), ("a50", 1.0), ("rest", 0.0)), frames_per_step=6),),
        expected={"n_muscles": 2, "contractions": {c.name: c.contractions.tolist() for c in cases}},
        resolution=resolve_resolution(resolution), source=__file__)


if __name__ == "__main__":
    raise SystemExit(run_main(build))
