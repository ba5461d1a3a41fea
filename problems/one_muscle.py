"""One-muscle experiment: the tentacle body with one muscle, contracted by 20, 30, 40 and 50 %.

The paper checks its internal-driving model against a prototype on three bodies driven by one, two and
four independent muscle units, each contracted by 20 %, 30 %, 40 % and 50 % of its rest length (its
Figure 9 and Table 3). This scene is the one-muscle group: the tapered finger of ``tentacle.py`` with one
muscle along its lower side, from the base to where the rounded tip begins. Each case is the forward
(internal-driving) solve at one contraction; the design must then recover that contraction from the
shape alone, a problem with a known answer, and routing on the shape is compared with the true muscle.

The shapes are drawn by the mdsr_opt authors from the paper's descriptions (it gives no geometry); they
are not the paper's meshes.

Material: the body's material of ``tentacle.py``, ``NeoHookean(E=1.0, nu=0.4)`` in plane strain, in units
where E = 1 (E scales forces and energies only: drag- and stroke-driven shapes do not depend on it). Plane
strain at nu = 0.4 is the law the library's results were made and checked with, kept so they stay comparable;
a cast silicone robot is a thin, nearly incompressible sheet (``NeoHookean(1.0, 0.5, plane="stress")`` or
``silicone(...)``), which moves no node of these cases by more than 1.2 % of the largest motion (default
resolution).

Run ``python problems/one_muscle.py --out out/one_muscle`` or ``mdsr run one_muscle --out out/one_muscle``.
"""

from __future__ import annotations

from pathlib import Path

from mdsr_opt.scenes.scene import Animation, Case, Scene, resolve_resolution
from mdsr_opt.scenes.select import boundary_path
from mdsr_opt.scenes.library import load_problem_module
from mdsr_opt.scenes.runscene import run_main

LEVELS = (0.2, 0.3, 0.4, 0.5)

tentacle = load_problem_module(Path(__file__).with_name("tentacle.py"))


def build(resolution="medium") -> Scene:
    """The one-muscle experiment: cases ``a20`` ... ``a50`` (internal driving, the muscle given)."""
    mesh, material = tentacle.body(resolution)
    L = tentacle.LENGTH
    lower = boundary_path(mesh, (0.0, -0.6), (L, -float(tentacle.half_width(L))), via=(L / 2, -0.5),
                          name="lower")
    cases = tuple(Case(f"a{round(100 * a)}", contractions=[a], description=f"the muscle contracted by {a:.0%}")
                  for a in LEVELS)
    return Scene(
        name="one_muscle", title="One-muscle experiment (paper Figure 9, column A): 20-50 % contraction",
        description=__doc__.split("\n\n")[1].replace("\n", " "), mesh=mesh, material=material, cases=cases,
        muscles=(lower,), regions={"muscle": list(lower.nodes)},
        design_options={"method": "flattened", "a_max": 0.6, "muscle_model": "cable"},
        animations=(Animation("sweep", (("rest", 0.0), ("a50", 1.0), ("rest", 0.0)), frames_per_step=6),),
        expected={"n_muscles": 1, "contractions": {c.name: c.contractions.tolist() for c in cases}},
        resolution=resolve_resolution(resolution), source=__file__)


if __name__ == "__main__":
    raise SystemExit(run_main(build))
