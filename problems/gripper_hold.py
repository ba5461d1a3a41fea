"""Gripper holding an object: the C-shaped ring of gripper.py closes on a free disk; is it held?

Two muscles along the inner rim (its upper and lower half), contracted by ``HOLD``, close the jaws on a disk
of radius ``DISK`` that nothing else supports: the target's solves move it (``FreeDisk``) until the
contacts' net force on it vanishes, as a disk held in the air would settle. The case then reports whether
the grip holds it at Coulomb friction ``FRICTION`` and the load it resists in each direction (``grip`` in
``summary.json``, a word in the summary's design cell): issue 35's gripper that grips.

Every solve with the disk is a contact solve (IPOPT with the gap of each candidate node-segment pair as a
constraint) and the design of a case with obstacles is derivative-free, so the scene's default mesh is the
coarse one (about 150 nodes): a few seconds, where the gripper's medium mesh takes about 40 s of solves.
``--resolution medium`` runs it finer.

Material: the body's material of ``gripper.py``, ``NeoHookean(E=1.0, nu=0.4)`` in plane strain (E = 1).

Run ``python problems/gripper_hold.py --out out/gripper_hold`` or ``mdsr run gripper_hold --out out/gripper_hold``.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from mdsr_opt.scenes.library import load_problem_module
from mdsr_opt.scenes.obstacles import FreeDisk
from mdsr_opt.scenes.runscene import run_main
from mdsr_opt.scenes.scene import Case, Scene, resolve_resolution
from mdsr_opt.scenes.select import boundary_path

gripper = load_problem_module(Path(__file__).with_name("gripper.py"))

HOLD, DISK, FRICTION = 0.3, 1.2, 0.5   # the muscles' contraction, the disk's radius, Coulomb's mu


def inner_muscles(mesh):
    """Two muscles along the inner rim, the upper and the lower half: contracted, they close the jaws."""
    ri, half = gripper.R0 - gripper.WIDTH / 2, gripper.OPENING / 2

    def rim(a0, a1):
        return ri * np.array([np.cos(a0), np.sin(a0)]), ri * np.array([np.cos(a1), np.sin(a1)])

    return (boundary_path(mesh, *rim(half + 0.08, np.pi - 0.12), via=ri * np.array([0.0, 1.0]), name="upper"),
            boundary_path(mesh, *rim(np.pi + 0.12, 2 * np.pi - half - 0.08), via=ri * np.array([0.0, -1.0]),
                          name="lower"))


def build(resolution="coarse") -> Scene:
    """The scene: case ``hold`` (internal driving of the two inner-rim muscles, jaws closed on a free disk,
    with its grip report)."""
    mesh, material = gripper.body(resolution)
    cases = (Case("hold", contractions=[HOLD, HOLD], muscles=inner_muscles(mesh), obstacles=(FreeDisk((0.0, 0.0),
                  DISK),), friction=FRICTION, description=f"two inner-rim muscles contracted by {HOLD:.0%} close "
                  f"the jaws on a free disk of radius {DISK}: held at friction {FRICTION}?"),)
    return Scene(
        name="gripper_hold", title="Gripper holding a disk: the C's inner-rim muscles close its jaws on a free disk",
        description=__doc__.split("\n\n")[1].replace("\n", " "), mesh=mesh, material=material, cases=cases,
        resolution=resolve_resolution(resolution), source=__file__)


if __name__ == "__main__":
    raise SystemExit(run_main(build))
