"""Solves in dimensionless units: a body scaled to a reference size and unit stiffness, results mapped back.

Every equilibrium (and design) is solved on the body's *unit* copy: lengths divided by ``L``, the power of
two that brings the body's size ``S`` (``mesh.size``, the rest bounding box's diagonal) within a factor
``sqrt 2`` of :data:`REFERENCE_SIZE`, and Young's modulus and thickness by the powers of two nearest them,
so that the copy's stiffness ``E t`` is within a factor 2 of 1. Energies are then in units of ``E t S^2``
(up to a fixed factor), forces (rope tensions, multipliers) of ``E t S`` and stiffnesses (Hessians) of
``E t``. The same problem in metres or micrometres, at ``E = 1e-9`` or ``1e9``, is one dimensionless
problem (up to a factor below 2 in size and stiffness), so every tolerance and threshold of the solvers
(IPOPT's, the tolerance contract's of :mod:`~mdsr_opt.mechanics.residual`, step limits, patch radii,
stability pivots) means the same in any units. Scaling by powers of two is exact in floating point: the
copy's geometry is the body's to the last bit (which nodes an anchor patch takes, which coordinates pin the
gauge), and mapping results back (:class:`Units`) rounds nothing.

Example
-------
>>> from mdsr_opt import Mesh, NeoHookean
>>> u = Units(Mesh.rectangle(4e-3, 1e-3, 8, 2), NeoHookean(1e6, 0.3, thickness=1e-3))   # SI units
>>> u.length == 2.0 ** -10, u.stiffness == 2.0 ** 20 * 2.0 ** -10, round(u.unit_mesh.size, 6)
(True, True, 4.22206)
>>> u.unit_material.E, u.unit_material.thickness
(0.95367431640625, 1.024)
>>> Units(Mesh.rectangle(4.0, 1.0, 8, 2), NeoHookean(1.0, 0.3)).identity   # already in these units
True
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from ..core.quantities import tension_unit

__all__ = ["Units", "unit_mesh", "unit_material", "power_of_two"]

#: the key of a mesh's unit copy in its ``__dict__`` (a ``*_cache`` key: left out of pickles, made again)
_UNIT_KEY = "_unit_mesh_cache"


def power_of_two(v: float) -> float:
    """The power of two ``2^k`` with ``v / 2^k`` in ``[sqrt(1/2), sqrt(2))`` (decided on the mantissa, so
    ``power_of_two(v / power_of_two(v)) == 1`` exactly)."""
    m, e = math.frexp(float(v))  # v = m 2^e, m in [1/2, 1)
    return math.ldexp(1.0, e if m >= math.sqrt(0.5) else e - 1)


#: the size of a unit body: its copy's size lies within a factor ``sqrt 2`` of it. Any fixed value makes
#: the solves independent of units; this one is the regime the solvers' heuristics were tuned and measured
#: in (the 4 x 1 strips of the tests and benchmarks at E = 1, whose copies are themselves). Solved at unit
#: size instead, the cable's slack ropes end farther from their lengths (IPOPT's barrier parameter is
#: absolute, the energy 16x smaller): 40 random 2-3 rope strips and L-shapes took 1,039 IPOPT iterations
#: against 791 (size 4), 801 (size 8) and 823 (size 16); the muscle scenes (sizes 6-11), 733 at size 4
#: against 729 at their own
REFERENCE_SIZE = 4.0


def length_unit(mesh) -> float:
    """The power of two that lengths are divided by: the copy's size is within ``sqrt 2`` of
    :data:`REFERENCE_SIZE`."""
    return power_of_two(mesh.size / REFERENCE_SIZE)


def unit_mesh(mesh):
    """The mesh scaled by ``1 / length_unit(mesh)`` (cached on the mesh; the mesh itself when that power
    is 1)."""
    L = length_unit(mesh)
    if L == 1.0:
        return mesh
    d = mesh.__dict__
    um = d.get(_UNIT_KEY)
    if um is None:
        um = d[_UNIT_KEY] = mesh.with_points(np.asarray(mesh.points, dtype=float) / L)
    return um


def _stiffness_units(material) -> tuple[float, float]:
    """The powers of two ``E`` and the thickness are divided by (1 for a material that is no dataclass,
    which cannot be copied with other numbers)."""
    if not dataclasses.is_dataclass(material):
        return 1.0, 1.0
    return power_of_two(material.E), power_of_two(material.thickness)


def unit_material(material):
    """The material with ``E`` and ``thickness`` divided by their nearest powers of two (the same kind and
    Poisson's ratio; the material itself when both powers are 1). A material stated by other constants
    (Yeoh, Mooney-Rivlin) scales them all by its ``scaled(factor, thickness)``."""
    e, t = _stiffness_units(material)
    if e == 1.0 and t == 1.0:
        return material
    if callable(getattr(material, "scaled", None)):
        return material.scaled(1.0 / e, material.thickness / t)
    return dataclasses.replace(material, E=material.E / e, thickness=material.thickness / t)


class Units:
    """The scales of a body, powers of two: ``length`` (about its size ``S``), ``stiffness`` (about ``E t``),
    ``force`` (``stiffness * length``) and ``energy`` (``force * length``), with the unit copies of its mesh
    and material and maps of results back.

    ``identity`` is True when the body is its own unit copy (nothing to map)."""

    def __init__(self, mesh, material):
        self.mesh, self.material = mesh, material
        self.unit_mesh = unit_mesh(mesh)
        self.unit_material = unit_material(material)
        self.identity = self.unit_mesh is mesh and self.unit_material is material
        self.length = length_unit(mesh)
        e, t = _stiffness_units(material)
        self.stiffness = e * t
        self.force = self.stiffness * self.length
        self.energy = self.force * self.length

    def __repr__(self) -> str:
        return f"Units(length={self.length:g}, stiffness={self.stiffness:g})"

    # ------------------------------------------------------------------ in
    def to_unit(self, x):
        """A length (a float) or an array of lengths in unit lengths; None stays None."""
        if x is None:
            return None
        return float(x) / self.length if np.ndim(x) == 0 else np.asarray(x, dtype=float) / self.length

    def state_in(self, x_start):
        """A flattened or (n, 2) state in unit lengths (the same shape)."""
        return np.asarray(x_start, dtype=float) / self.length

    # ------------------------------------------------------------------ out
    def stability_out(self, chk):
        """A :class:`~mdsr_opt.mechanics.stability.StabilityCheck` of the unit problem with its curvature in
        the user's units of the Hessian (``E t``)."""
        if chk is not None and chk.curvature is not None and not self.identity:
            chk = dataclasses.replace(chk, curvature=float(chk.curvature) * self.stiffness)
        return chk

    def equilibrium_out(self, res):
        """An :class:`~mdsr_opt.mechanics.result.EquilibriumResult` of the unit problem in the user's units
        (in place; returned). ``residual``, ``min_J``, contractions and rotations have no units; the contact
        report's forces are in ``E * t * length``, as rope tensions, and say so (``force_unit``)."""
        if res.contact is not None:
            res.contact["force_unit"] = tension_unit(getattr(self.material, "stress_unit", None), None)[0]
        if self.identity:
            return res
        L = self.length
        res.x = res.x * L
        res.energy = float(res.energy) * self.energy
        res.elastic_energy = float(res.elastic_energy) * self.energy
        if res.translation is not None:
            res.translation = np.asarray(res.translation) * L
        if res.stability is not None and res.stability.get("curvature") is not None:
            res.stability = dict(res.stability, curvature=float(res.stability["curvature"]) * self.stiffness)
        for name, scale in (("stroke", L), ("rest_lengths", L), ("tension", self.force)):
            v = getattr(res, name)
            if v is not None:
                setattr(res, name, np.asarray(v, dtype=float) * scale)
        if res.anchor_radius is not None:
            res.anchor_radius = float(res.anchor_radius) * L
        return res
