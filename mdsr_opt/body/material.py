"""Hyperelastic materials of a sheet: energy densities ``Psi(F)`` per unit rest area (times the thickness).

Each material is a frozen dataclass with validated parameters and a law, stated once in
:meth:`~NeoHookean.density`: an expression in the entries of ``F - I`` and two numbers ``(mu, lam)``, built
from arithmetic (and a ``log1p`` the caller passes), so the same lines evaluate numpy arrays and CasADi
symbols. Everything else derives from it:

* :meth:`~NeoHookean.psi_expr` (CasADi, symbolic parameters): the symbolic energy model
  (:mod:`mdsr_opt.mechanics.model`), whose stresses and tangents CasADi differentiates -- the reference;
* :meth:`~NeoHookean.psi` (numpy, any batch shape) and the vectorised energy of
  :class:`~mdsr_opt.mechanics.newton.NewtonEnergy`;
* the closed-form first Piola stress, tangent ``dP/dF`` and its derivative along a direction
  (:meth:`~NeoHookean.stress_tangent`, :meth:`~NeoHookean.tangent_derivative`), which the numeric energy
  model, the Newton backend and the design's numpy callbacks evaluate for speed; tests check them against
  CasADi's derivatives of :meth:`~NeoHookean.psi_expr` and against finite differences.

Planes. A body long out of its plane (an extrusion) is in plane strain: ``plane="strain"``, the 2-D law of
the 3-D one at zero out-of-plane strain, whose small-strain in-plane moduli are ``E / (1 - nu^2)`` and
``nu / (1 - nu)`` (:attr:`~NeoHookean.plane_moduli`). A thin sheet (a cast silicone robot) is in plane
stress: ``plane="stress"``, the out-of-plane stretch free (:mod:`mdsr_opt.body.planestress`), in-plane
moduli ``E`` and ``nu``; incompressible (``nu = 0.5``) in closed form. Plane strain is the default, the law
of the library's scenes before plane stress existed. :class:`Yeoh` and :class:`MooneyRivlin` are
incompressible sheets; :func:`~mdsr_opt.body.silicone.silicone` makes presets of casting silicones.

``params`` is the numeric parameter vector the models take at solve time (two numbers: the small-strain
shear modulus times the thickness, then a second modulus times the thickness, see each class), so one
built model serves any stiffness; ``kind`` names the law (and its shape constants), so models are made once
per kind. A material of another kind needs only ``kind``, ``params`` and ``psi_expr``: the models then
evaluate it symbolically.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from functools import cached_property
import numbers

import casadi as ca
import numpy as np

from ..core.checks import positive_float
from ..core.quantities import check_stress_unit
from .planestress import CompressibleNeoHookeanLaw, IncompressibleLaw

__all__ = ["NeoHookean", "LinearElastic", "Yeoh", "MooneyRivlin", "Material", "numeric_law", "material_dict",
           "material_from_dict"]

#: the two planes of a 2-D body
PLANES = ("strain", "stress")


def _lame(E: float, nu: float) -> tuple[float, float]:
    if nu == 0.5:
        return E / 3.0, np.inf
    return E / (2.0 * (1.0 + nu)), E * nu / ((1.0 + nu) * (1.0 - 2.0 * nu))


def _check_plane(plane) -> str:
    if not isinstance(plane, str):
        raise TypeError(f"plane must be 'strain' or 'stress', got {type(plane).__name__}")
    if plane not in PLANES:
        raise ValueError(f"plane must be 'strain' (a body long out of its plane) or 'stress' (a thin sheet), "
                         f"got {plane!r}")
    return plane


def _real(v, name: str) -> float:
    if isinstance(v, bool) or not isinstance(v, numbers.Real):
        raise TypeError(f"{name} must be a real number, got {type(v).__name__}")
    v = float(v)
    if not np.isfinite(v):
        raise ValueError(f"{name} must be finite, got {v}")
    return v


def _check_E_nu(E, nu, lo=-1.0, lo_closed=False, hi_closed=False, why=""):
    E = positive_float(E, "E (Young's modulus)")
    if isinstance(nu, bool) or not isinstance(nu, (int, float, np.floating, np.integer)):
        raise TypeError(f"nu (Poisson's ratio) must be a real number, got {type(nu).__name__}")
    nu = float(nu)
    if not np.isfinite(nu) or not ((lo <= nu if lo_closed else lo < nu) and (nu <= 0.5 if hi_closed else nu < 0.5)):
        rng = f"{'[' if lo_closed else '('}{lo:g}, 0.5{']' if hi_closed else ')'}"
        raise ValueError(f"nu (Poisson's ratio) must lie in {rng}{why}, got {nu}")
    return E, nu


def _is_symbolic(F) -> bool:
    return isinstance(F, (ca.SX, ca.MX, ca.DM))


class _Law:
    """The door of a material to its law (``self.law``): density, stress, tangent, ``psi_expr`` and ``psi``."""

    #: the energy does not change under a rigid rotation of the body (frame indifference)
    rotation_invariant = True

    def density(self, a, b, c, d, mu, lam, log1p=np.log1p):
        """``Psi`` at ``F = I + [[a, b], [c, d]]`` (numpy arrays or CasADi symbols; ``log1p`` of their kind),
        ``(mu, lam)`` the two entries of :attr:`params`. Not finite where ``J <= 0``."""
        return self.law.density(a, b, c, d, mu, lam, log1p)

    def stress_tangent(self, F, mu, lam, tangent: bool = True):
        """Closed-form first Piola stress ``P = dPsi/dF`` (2, 2, m) and, with ``tangent``, ``A[i, j, k, l] =
        dP_ij / dF_kl`` (2, 2, 2, 2, m) of deformation gradients ``F`` (2, 2, m), elements last."""
        return self.law.stress_tangent(F, mu, lam, tangent)

    def tangent_derivative(self, F, dF, mu, lam):
        """The derivative of the tangent of :meth:`stress_tangent` along ``dF`` (both (2, 2, m)):
        (2, 2, 2, 2, m)."""
        return self.law.tangent_derivative(F, dF, mu, lam)

    def psi_expr(self, F, params):
        """Energy density for a 2x2 symbolic ``F`` and symbolic ``params`` (two entries)."""
        return self.law.density(F[0, 0] - 1, F[0, 1], F[1, 0], F[1, 1] - 1, params[0], params[1], ca.log1p)

    def stretch3(self, F):
        """The out-of-plane stretch (thickness ratio) at deformation gradients ``F`` (..., 2, 2): 1 in plane
        strain, ``1/J`` for an incompressible sheet, the stretch of zero normal stress for a compressible one;
        ``nan`` where ``J <= 0``."""
        F = np.asarray(F, dtype=float)
        J = F[..., 0, 0] * F[..., 1, 1] - F[..., 0, 1] * F[..., 1, 0]
        with np.errstate(divide="ignore", invalid="ignore"):
            out = np.where(J > 0, self.law.stretch3(np.where(J > 0, J, 1.0), *self.params), np.nan)
        return float(out) if out.ndim == 0 else out

    def psi(self, F, params=None):
        """``Psi(F)`` (times thickness) for a CasADi 2x2 matrix or a numpy array (..., 2, 2).

        Returns ``inf`` (numpy) where ``J <= 0``.
        """
        p = self.params if params is None else params
        if _is_symbolic(F):
            return self.psi_expr(F, p)
        F = np.asarray(F, dtype=float)
        a, b, c, d = F[..., 0, 0] - 1, F[..., 0, 1], F[..., 1, 0], F[..., 1, 1] - 1
        with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
            out = self.law.density(a, b, c, d, p[0], p[1])
        out = np.where(a + d + (a * d - b * c) > -1, out, np.inf)
        return float(out) if out.ndim == 0 else out


class _PlaneStrainNeoHookean:
    """``Psi(F) = mu/2 (tr F^T F - 2) - mu ln J + lam/2 (ln J)^2`` (the plane-strain law)."""

    @staticmethod
    def stretch3(J, mu, lam):
        return np.ones_like(np.asarray(J, dtype=float))

    @staticmethod
    def density(a, b, c, d, mu, lam, log1p=np.log1p):
        """``Psi`` at ``F = I + [[a, b], [c, d]]`` (numpy arrays or CasADi symbols; ``log1p`` of their kind).

        Written in ``F - I`` (``tr F'F - 2 = |F - I|^2 + 2 tr(F - I)``, ``ln J = log1p(J - 1)``): no
        cancellation of O(1) terms, so a state at rest has an energy of round-off squared, not of round-off.
        Not finite where ``J <= 0``.
        """
        lnJ = log1p(a + d + (a * d - b * c))
        return mu / 2 * (a * a + b * b + c * c + d * d) + mu * ((a + d) - lnJ) + lam / 2 * lnJ ** 2

    @staticmethod
    def stress_tangent(F, mu, lam, tangent: bool = True):
        """Closed-form first Piola stress ``P = dPsi/dF`` (2, 2, m) and, with ``tangent``, ``A[i, j, k, l] =
        dP_ij / dF_kl`` (2, 2, 2, 2, m) of deformation gradients ``F`` (2, 2, m), elements last.

        With ``G = F^-T``: ``P = mu F + (lam ln J - mu) G`` and ``A_ijkl = mu d_ik d_jl + (mu - lam ln J)
        G_il G_kj + lam G_ij G_kl``.
        """
        f00, f01, f10, f11 = F[0, 0], F[0, 1], F[1, 0], F[1, 1]
        J = f00 * f11 - f01 * f10
        lnJ = np.log(J)
        iJ = 1.0 / J
        G = np.stack([np.stack([f11 * iJ, -f10 * iJ]), np.stack([-f01 * iJ, f00 * iJ])])  # F^-T
        P = mu * F + (lam * lnJ - mu) * G
        if not tangent:
            return P, None
        A = lam * (G[:, :, None, None] * G[None, None])
        A += (mu - lam * lnJ) * (G[:, None, None, :] * np.swapaxes(G, 0, 1)[None, :, :, None])
        for i in range(2):
            for j in range(2):
                A[i, j, i, j] += mu
        return P, A

    @staticmethod
    def tangent_derivative(F, dF, mu, lam):
        """The derivative of the tangent ``A`` of :meth:`stress_tangent` along ``dF`` (both (2, 2, m)):
        ``-lam (G:dF) G_il G_kj + (mu - lam ln J)(dG_il G_kj + G_il dG_kj) + lam (dG_ij G_kl + G_ij dG_kl)``
        with ``dG = -G dF' G``; (2, 2, 2, 2, m)."""
        f00, f01, f10, f11 = F[0, 0], F[0, 1], F[1, 0], F[1, 1]
        J = f00 * f11 - f01 * f10
        iJ = 1.0 / J
        G = np.stack([np.stack([f11 * iJ, -f10 * iJ]), np.stack([-f01 * iJ, f00 * iJ])])  # F^-T
        GT = np.swapaxes(G, 0, 1)
        dG = -np.einsum("iam,bam,blm->ilm", G, dF, G)
        dGT = np.swapaxes(dG, 0, 1)
        tr = (G * dF).sum(axis=(0, 1))  # d ln J
        c1 = mu - lam * np.log(J)
        GG = G[:, None, None, :] * GT[None, :, :, None]  # G_il G_kj
        dA = lam * (dG[:, :, None, None] * G[None, None] + G[:, :, None, None] * dG[None, None])
        dA += c1 * (dG[:, None, None, :] * GT[None, :, :, None] + G[:, None, None, :] * dGT[None, :, :, None])
        dA -= lam * tr * GG
        return dA



_NH_STRAIN = _PlaneStrainNeoHookean()
_NH_STRESS = CompressibleNeoHookeanLaw()
_INCOMPRESSIBLE = IncompressibleLaw()  # Neo-Hookean (k ignored) ...
_MOONEY = IncompressibleLaw(mooney=True)  # ... and Mooney-Rivlin sheets


@dataclass(frozen=True)
class _Isotropic:
    """Validated ``E``, ``nu``, ``thickness``, ``plane`` and the Lame parameters of the isotropic materials."""

    E: float
    nu: float
    thickness: float = 1.0
    plane: str = "strain"
    #: the unit of ``E`` (:data:`~mdsr_opt.core.quantities.STRESS_UNITS`, ``"Pa"``...), None: dimensionless
    stress_unit: str | None = field(default=None, compare=False)

    #: whether ``nu = 0.5`` (incompressible) is allowed in plane stress
    _stress_incompressible = True
    #: the lowest ``nu`` of a plane-stress body, and whether it is included
    _stress_nu_min = (-1.0, False)

    def __post_init__(self):
        plane = _check_plane(self.plane)
        if plane == "stress":
            lo, closed = self._stress_nu_min
            why = "" if lo == -1.0 else " for a plane-stress Neo-Hookean sheet (its out-of-plane stretch has no " \
                                        "solution under strong compression at nu < 0)"
            E, nu = _check_E_nu(self.E, self.nu, lo, closed, self._stress_incompressible, why)
        else:
            E, nu = _check_E_nu(self.E, self.nu, why=" in plane strain (nu = 0.5, incompressible, needs "
                                                     "plane='stress')")
        object.__setattr__(self, "E", E)
        object.__setattr__(self, "nu", nu)
        object.__setattr__(self, "thickness", positive_float(self.thickness, "thickness"))
        object.__setattr__(self, "stress_unit", check_stress_unit(self.stress_unit))

    @property
    def mu(self) -> float:
        """The shear modulus ``E / (2 (1 + nu))``."""
        return _lame(self.E, self.nu)[0]

    @property
    def lam(self) -> float:
        """The 3-D Lame constant ``E nu / ((1 + nu)(1 - 2 nu))`` (``inf`` at ``nu = 0.5``)."""
        return _lame(self.E, self.nu)[1]

    @property
    def plane_moduli(self) -> tuple[float, float]:
        """The small-strain in-plane Young's modulus and Poisson's ratio: ``(E, nu)`` in plane stress,
        ``(E / (1 - nu^2), nu / (1 - nu))`` in plane strain."""
        if self.plane == "stress":
            return self.E, self.nu
        return self.E / (1.0 - self.nu ** 2), self.nu / (1.0 - self.nu)


@dataclass(frozen=True)
class NeoHookean(_Law, _Isotropic):
    """Compressible Neo-Hookean material in plane strain or plane stress.

    ``mu = E / (2 (1 + nu))``, ``lam = E nu / ((1 + nu)(1 - 2 nu))``; the element energy is
    ``thickness * area * Psi``.

    * ``plane="strain"`` (default): ``Psi(F) = mu/2 (tr F^T F - 2) - mu ln J + lam/2 (ln J)^2``, the 3-D law at
      zero out-of-plane strain: a body long out of its plane. ``nu`` in (-1, 0.5).
    * ``plane="stress"``: a thin sheet, its out-of-plane stretch ``l3`` free
      (:class:`~mdsr_opt.body.planestress.CompressibleNeoHookeanLaw`): ``Psi = mu/2 (tr F^T F + l3^2 - 3) -
      mu ln(J l3) + lam/2 ln^2(J l3)`` at the ``l3`` where the normal stress vanishes. ``nu`` in [0, 0.5];
      at ``nu = 0.5`` incompressible in closed form, ``l3 = 1/J`` and ``Psi = mu/2 (tr F^T F + J^-2 - 3)``,
      ``mu = E/3``. Cast silicones have ``nu`` of 0.49-0.5.

    ``params`` is ``[mu t, lam t]`` (``[mu t, 0]`` when incompressible).

    Example
    -------
    >>> import numpy as np
    >>> NeoHookean(E=1.0, nu=0.3).psi(np.eye(2))
    0.0
    >>> round(NeoHookean(E=3.0, nu=0.5, plane="stress").psi(np.diag([2.0, 1.0])), 6)  # mu/2 (4 + 1 + 1/4 - 3)
    1.125
    """

    _stress_nu_min = (0.0, True)

    @property
    def kind(self) -> str:
        """``"neo-hookean"`` (plane strain), ``"neo-hookean-plane-stress"`` or
        ``"neo-hookean-plane-stress-incompressible"``."""
        if self.plane == "strain":
            return "neo-hookean"
        return "neo-hookean-plane-stress" + ("-incompressible" if self.nu == 0.5 else "")

    @property
    def law(self):
        """The law's closed forms (see :mod:`mdsr_opt.body.planestress`)."""
        if self.plane == "strain":
            return _NH_STRAIN
        return _INCOMPRESSIBLE if self.nu == 0.5 else _NH_STRESS

    @property
    def params(self) -> np.ndarray:
        """Numeric parameters ``[mu t, lam t]`` (``[mu t, 0]`` when incompressible) fed to the models."""
        mu, lam = _lame(self.E, self.nu)
        return np.array([mu * self.thickness, 0.0 if self.nu == 0.5 else lam * self.thickness])

@dataclass(frozen=True)
class LinearElastic(_Isotropic):
    """Small-strain (geometrically linear) isotropic elasticity, for scenes with small strains.

    ``Psi = mu eps:eps + lam/2 (tr eps)^2`` with ``eps = (F + F^T)/2 - I``. Not rotation invariant:
    use it only where rotations stay small (the fidelity helper decides). In plane stress (``nu`` up to
    0.5) ``lam`` is the in-plane ``E nu / (1 - nu^2)``; in plane strain (default) the 3-D Lame constant.
    """

    kind = "linear"
    rotation_invariant = False

    @property
    def params(self) -> np.ndarray:
        """Numeric parameters ``[mu t, lam t]``; in plane stress the in-plane ``lam`` is
        ``2 mu lam / (lam + 2 mu) = E nu / (1 - nu^2)``."""
        mu, lam = _lame(self.E, self.nu)
        if self.plane == "stress":
            lam = self.E * self.nu / (1.0 - self.nu ** 2)
        return np.array([mu * self.thickness, lam * self.thickness])

    @staticmethod
    def density(a, b, c, d, mu, lam, log1p=None):
        """``Psi`` at ``F = I + [[a, b], [c, d]]`` (numpy arrays or CasADi symbols; ``log1p`` unused)."""
        s = 0.5 * (b + c)
        return mu * (a * a + d * d + 2 * s * s) + lam / 2 * (a + d) ** 2

    @staticmethod
    def psi_expr(F, params):
        return LinearElastic.density(F[0, 0] - 1, F[0, 1], F[1, 0], F[1, 1] - 1, params[0], params[1])

    @staticmethod
    def stress_tangent(F, mu, lam, tangent: bool = True):
        """As :meth:`NeoHookean.stress_tangent`: ``P = 2 mu eps + lam tr(eps) I`` and the constant tangent
        (2, 2, 2, 2, 1)."""
        tr = F[0, 0] + F[1, 1] - 2.0
        s = 0.5 * (F[0, 1] + F[1, 0])
        P = np.stack([np.stack([2 * mu * (F[0, 0] - 1.0) + lam * tr, 2 * mu * s]),
                      np.stack([2 * mu * s, 2 * mu * (F[1, 1] - 1.0) + lam * tr])])
        if not tangent:
            return P, None
        I2 = np.eye(2)
        C = (mu * (np.einsum("ik,jl->ijkl", I2, I2) + np.einsum("il,jk->ijkl", I2, I2))
             + lam * np.einsum("ij,kl->ijkl", I2, I2))
        return P, C[..., None]

    #: the tangent is constant: no derivative
    tangent_derivative = None

    def psi(self, F, params=None):
        p = self.params if params is None else params
        if _is_symbolic(F):
            return self.psi_expr(F, p)
        F = np.asarray(F, dtype=float)
        out = self.density(F[..., 0, 0] - 1, F[..., 0, 1], F[..., 1, 0], F[..., 1, 1] - 1, p[0], p[1])
        return float(out) if out.ndim == 0 else out


def _scaled(v: float, factor: float) -> float:
    return float(v) * factor


@dataclass(frozen=True)
class Yeoh(_Law):
    """Incompressible Yeoh sheet in plane stress: ``Psi = C1 x + C2 x^2 + C3 x^3``, ``x = tr F^T F + J^-2 - 3``
    (``I1 - 3`` at the out-of-plane stretch ``1/J``), per unit rest volume (SI: Pa); the element energy is
    ``thickness * area * Psi``.

    The law of filled silicones, whose stiffness rises with stretch (Yeoh, Rubber Chem. Technol. 66, 754,
    1993). ``C1 > 0`` is half the small-strain shear modulus (``mu = 2 C1``, ``E = 6 C1``, ``nu = 0.5``);
    ``C2`` and ``C3`` may be negative, as fits often give them: such a law softens past the stretches it was
    fitted to. ``params`` is ``[2 C1 t, 0]``; ``C2/C1`` and ``C3/C1`` are part of the law (its ``kind``).

    Example
    -------
    >>> import numpy as np
    >>> m = Yeoh(C1=1.0, C2=0.5)
    >>> round(m.psi(np.diag([2.0, 1.0])), 6)  # x = 2.25: 2.25 + 0.5 * 2.25^2
    4.78125
    """

    C1: float
    C2: float = 0.0
    C3: float = 0.0
    thickness: float = 1.0
    #: the unit of the constants (``"Pa"`` for the silicone presets), None: dimensionless
    stress_unit: str | None = field(default=None, compare=False)

    nu = 0.5
    plane = "stress"

    def __post_init__(self):
        object.__setattr__(self, "C1", positive_float(self.C1, "C1 (Yeoh)"))
        object.__setattr__(self, "C2", _real(self.C2, "C2 (Yeoh)"))
        object.__setattr__(self, "C3", _real(self.C3, "C3 (Yeoh)"))
        object.__setattr__(self, "thickness", positive_float(self.thickness, "thickness"))
        object.__setattr__(self, "stress_unit", check_stress_unit(self.stress_unit))

    @property
    def mu(self) -> float:
        """The small-strain shear modulus ``2 C1``."""
        return 2.0 * self.C1

    @property
    def E(self) -> float:
        """The small-strain Young's modulus ``6 C1``."""
        return 6.0 * self.C1

    lam = np.inf
    plane_moduli = property(lambda self: (self.E, 0.5), doc="Small-strain ``(E, nu)`` in the plane.")

    @property
    def kind(self) -> str:
        """``"yeoh(C2/C1, C3/C1)"``: the law with its shape."""
        return f"yeoh({self.C2 / self.C1!r}, {self.C3 / self.C1!r})"

    @cached_property
    def law(self):
        return IncompressibleLaw((self.C2 / self.C1, self.C3 / self.C1))

    @property
    def params(self) -> np.ndarray:
        """Numeric parameters ``[2 C1 t, 0]``."""
        return np.array([2.0 * self.C1 * self.thickness, 0.0])

    def scaled(self, factor: float, thickness: float) -> "Yeoh":
        """The same law with every constant times ``factor`` and the given thickness."""
        return Yeoh(_scaled(self.C1, factor), _scaled(self.C2, factor), _scaled(self.C3, factor), thickness)


@dataclass(frozen=True)
class MooneyRivlin(_Law):
    """Incompressible Mooney-Rivlin sheet in plane stress: ``Psi = C10 (I1 - 3) + C01 (I2 - 3)`` with
    ``I1 = tr F^T F + J^-2`` and ``I2 = J^2 + J^-2 tr F^T F`` (the out-of-plane stretch ``1/J``), per unit
    rest volume (SI: Pa).

    ``mu = 2 (C10 + C01) > 0`` is the small-strain shear modulus (``E = 3 mu``, ``nu = 0.5``); a negative
    constant, as some fits give, can lose stability at large stretch. ``params`` is ``[mu t, 2 C01 t]``.
    """

    C10: float
    C01: float = 0.0
    thickness: float = 1.0
    #: the unit of the constants (``"Pa"``...), None: dimensionless
    stress_unit: str | None = field(default=None, compare=False)

    nu = 0.5
    plane = "stress"
    kind = "mooney-rivlin"
    lam = np.inf
    law = _MOONEY

    def __post_init__(self):
        c10, c01 = _real(self.C10, "C10 (Mooney-Rivlin)"), _real(self.C01, "C01 (Mooney-Rivlin)")
        if not c10 + c01 > 0:
            raise ValueError(f"C10 + C01 (half the shear modulus) must be > 0, got {c10} + {c01}")
        object.__setattr__(self, "C10", c10)
        object.__setattr__(self, "C01", c01)
        object.__setattr__(self, "thickness", positive_float(self.thickness, "thickness"))
        object.__setattr__(self, "stress_unit", check_stress_unit(self.stress_unit))

    @property
    def mu(self) -> float:
        """The small-strain shear modulus ``2 (C10 + C01)``."""
        return 2.0 * (self.C10 + self.C01)

    @property
    def E(self) -> float:
        """The small-strain Young's modulus ``6 (C10 + C01)``."""
        return 3.0 * self.mu

    plane_moduli = property(lambda self: (self.E, 0.5), doc="Small-strain ``(E, nu)`` in the plane.")

    @property
    def params(self) -> np.ndarray:
        """Numeric parameters ``[2 (C10 + C01) t, 2 C01 t]``."""
        return np.array([self.mu * self.thickness, 2.0 * self.C01 * self.thickness])

    def scaled(self, factor: float, thickness: float) -> "MooneyRivlin":
        """The same law with both constants times ``factor`` and the given thickness."""
        return MooneyRivlin(_scaled(self.C10, factor), _scaled(self.C01, factor), thickness)


def numeric_law(material) -> bool:
    """Whether ``material`` states its law in closed form (``density``, ``stress_tangent`` and
    ``tangent_derivative``, None for a constant tangent), so that the energy models can evaluate it in
    vectorised numpy."""
    return all(callable(getattr(material, k, None)) for k in ("density", "stress_tangent")) and (
        hasattr(material, "tangent_derivative"))


Material = NeoHookean | LinearElastic | Yeoh | MooneyRivlin


def material_dict(material) -> dict:
    """A JSON-ready record of a material: ``kind``, ``E``, ``nu``, ``thickness`` (small-strain values for the
    incompressible laws), ``plane`` and the law's own constants; :func:`material_from_dict` reads it back."""
    out = {"kind": material.kind, "E": float(material.E), "nu": float(material.nu),
           "thickness": float(material.thickness), "plane": getattr(material, "plane", "strain")}
    if getattr(material, "stress_unit", None):
        out["stress_unit"] = material.stress_unit
    if isinstance(material, Yeoh):
        out.update(C1=material.C1, C2=material.C2, C3=material.C3)
    elif isinstance(material, MooneyRivlin):
        out.update(C10=material.C10, C01=material.C01)
    return out


def material_from_dict(data: dict):
    """The material of a :func:`material_dict` record (or of an older one: ``kind``, ``E``, ``nu``,
    ``thickness``, plane strain). Raises ValueError for an unknown kind."""
    if not isinstance(data, dict):
        raise TypeError(f"a material record must be a dict, got {type(data).__name__}")
    kind = data.get("kind")
    if not isinstance(kind, str):
        raise ValueError(f"a material record needs a kind, got {kind!r}")
    t = data.get("thickness", 1.0)
    su = data.get("stress_unit")
    if kind.startswith("yeoh"):
        return Yeoh(data["C1"], data.get("C2", 0.0), data.get("C3", 0.0), t, stress_unit=su)
    if kind == MooneyRivlin.kind:
        return MooneyRivlin(data["C10"], data.get("C01", 0.0), t, stress_unit=su)
    plane = data.get("plane", "stress" if "plane-stress" in kind else "strain")
    if kind.startswith("neo-hookean"):
        return NeoHookean(data["E"], data["nu"], t, plane, stress_unit=su)
    if kind == LinearElastic.kind:
        return LinearElastic(data["E"], data["nu"], t, plane, stress_unit=su)
    raise ValueError(f"unknown material kind {kind!r} (known: neo-hookean[-plane-stress[-incompressible]], "
                     f"linear, yeoh(...), mooney-rivlin)")
