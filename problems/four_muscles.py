"""Four-muscle experiment: the humanoid figure with four muscles, contracted by 20, 30, 40 and 50 %.

The paper checks its internal-driving model against a prototype on three bodies driven by one, two and
four independent muscle units, each contracted by 20 %, 30 %, 40 % and 50 % of its rest length (its
Figure 9 and Table 3). This scene is the four-muscle group: the humanoid figure of ``humanoid.py`` with
a muscle along the top of each arm and along the outer side of each leg, all contracted alike (the arms
curl up, the legs bow out). Each case is the forward (internal-driving) solve at one contraction; the
design must then recover the four contractions from the shape alone, and routing on the shape is
compared with the true muscles.

The shapes are drawn by the mdsr_opt authors from the paper's descriptions (it gives no geometry); they
are not the paper's meshes.

Material: the body's material of ``humanoid.py``, ``NeoHookean(E=1.0, nu=0.4)`` in plane strain, in units
where E = 1 (E scales forces and energies only: drag- and stroke-driven shapes do not depend on it). Plane
strain at nu = 0.4 is the law the library's results were made and checked with, kept so they stay comparable;
a cast silicone robot is a thin, nearly incompressible sheet (``NeoHookean(1.0, 0.5, plane="stress")`` or
``silicone(...)``), which moves no node of these cases by more than 0.8 % of the largest motion (default
resolution).

Run ``python problems/four_muscles.py --out out/four_muscles`` or ``mdsr run four_muscles --out out/four_muscles``.
"""

from __future__ import annotations

from pathlib import Path

from mdsr_opt.scenes.scene import Animation, Case, Scene, resolve_resolution
from mdsr_opt.scenes.select import boundary_path
from mdsr_opt.scenes.library import load_problem_module
from mdsr_opt.scenes.runscene import run_main

LEVELS = (0.2, 0.3, 0.4, 0.5)

humanoid = load_problem_module(Path(__file__).with_name("humanoid.py"))


def build(resolution="medium") -> Scene:
    """The four-muscle experiment: cases ``a20`` ... ``a50`` (internal driving, the muscles given)."""
    mesh, material = humanoid.body(resolution)
    muscles = (
        boundary_path(mesh, (-1.05, 3.3), (-3.45, 3.2), via=(-2.2, 3.25), name="left arm"),
        boundary_path(mesh, (1.05, 3.3), (3.45, 3.2), via=(2.2, 3.25), name="right arm"),
        boundary_path(mesh, (-1.0, -2.9), (-1.0, -0.3), via=(-1.0, -1.5), name="left leg"),
        boundary_path(mesh, (1.0, -2.9), (1.0, -0.3), via=(1.0, -1.5), name="right leg"),
    )
    cases = tuple(Case(f"a{round(100 * a)}", contractions=[a] * 4, description=f"all four muscles contracted by {a:.0%}")
                  for a in LEVELS)
    return Scene(
        name="four_muscles", title="Four-muscle experiment (paper Figure 9, column C): 20-50 % contraction",
        description=__doc__.split("\n\n")[1].replace("\n", " "), mesh=mesh, material=material, cases=cases,
        muscles=muscles, regions={m.name.replace(" ", "_"): list(m.nodes) for m in muscles},
        design_options={"method": "flattened", "a_max": 0.6, "muscle_model": "cable"},
        animations=(Animation("sweep", (("rest", 0.0), ("a50", 1.0), ("rest", 0.0)), frames_per_step=6),),
        expected={"n_muscles": 4, "contractions": {c.name: c.contractions.tolist() for c in cases}},
        resolution=resolve_resolution(resolution), source=__file__)


if __name__ == "__main__":
    raise SystemExit(run_main(build))
