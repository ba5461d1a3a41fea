"""Hyperelastic materials as scalar energy densities ``Psi(F)`` (per unit rest area, times thickness).

Each material is a frozen dataclass with validated parameters. Its law is stated once, in
:meth:`~NeoHookean.density`: an expression in the entries of ``F - I`` and the numbers ``(mu, lam)`` built
from arithmetic alone (and a ``log1p`` the caller passes), so the same lines evaluate numpy arrays and
CasADi symbols. Everything else derives from it:

* :meth:`~NeoHookean.psi_expr` (CasADi, symbolic parameters): the symbolic energy model
  (:mod:`mdsr_opt.mechanics.model`), whose stresses and tangents CasADi differentiates -- the reference;
* :meth:`~NeoHookean.psi` (numpy, any batch shape) and the vectorised energy of
  :class:`~mdsr_opt.mechanics.newton.NewtonEnergy`;
* the closed-form first Piola stress, tangent ``dP/dF`` and its derivative along a direction
  (:meth:`~NeoHookean.stress_tangent`, :meth:`~NeoHookean.tangent_derivative`), which the numeric energy
  model, the Newton backend and the design's numpy callbacks evaluate for speed; tests check them against
  CasADi's derivatives of :meth:`~NeoHookean.psi_expr` and against finite differences.

``params`` is the numeric parameter vector ``[mu t, lam t]`` the models take at solve time, so one built
model serves any stiffness. A material of another kind needs only ``kind``, ``params`` and ``psi_expr``:
the models then evaluate it symbolically.
"""

from __future__ import annotations

from dataclasses import dataclass

import casadi as ca
import numpy as np

from ..core.checks import positive_float

__all__ = ["NeoHookean", "LinearElastic", "Material", "numeric_law"]


def _lame(E: float, nu: float) -> tuple[float, float]:
    return E / (2.0 * (1.0 + nu)), E * nu / ((1.0 + nu) * (1.0 - 2.0 * nu))


def _check_E_nu(E, nu):
    E = positive_float(E, "E (Young's modulus)")
    if isinstance(nu, bool) or not isinstance(nu, (int, float, np.floating, np.integer)):
        raise TypeError(f"nu (Poisson's ratio) must be a real number, got {type(nu).__name__}")
    nu = float(nu)
    if not np.isfinite(nu) or not -1.0 < nu < 0.5:
        raise ValueError(f"nu (Poisson's ratio) must lie in (-1, 0.5), got {nu}")
    return E, nu


def _is_symbolic(F) -> bool:
    return isinstance(F, (ca.SX, ca.MX, ca.DM))


@dataclass(frozen=True)
class _Isotropic:
    """Validated ``E``, ``nu``, ``thickness`` and the Lame parameters shared by the isotropic materials."""

    E: float
    nu: float
    thickness: float = 1.0

    def __post_init__(self):
        E, nu = _check_E_nu(self.E, self.nu)
        object.__setattr__(self, "E", E)
        object.__setattr__(self, "nu", nu)
        object.__setattr__(self, "thickness", positive_float(self.thickness, "thickness"))

    @property
    def mu(self) -> float:
        return _lame(self.E, self.nu)[0]

    @property
    def lam(self) -> float:
        return _lame(self.E, self.nu)[1]

    @property
    def params(self) -> np.ndarray:
        """Numeric parameters ``[mu * t, lam * t]`` fed to the symbolic model."""
        mu, lam = _lame(self.E, self.nu)
        return np.array([mu * self.thickness, lam * self.thickness])


@dataclass(frozen=True)
class NeoHookean(_Isotropic):
    """Compressible 2D Neo-Hookean material.

    ``Psi(F) = mu/2 (tr F^T F - 2) - mu ln J + lam/2 (ln J)^2``, ``mu = E / (2 (1 + nu))``,
    ``lam = E nu / ((1 + nu)(1 - 2 nu))``; the element energy is ``thickness * area * Psi``.

    Example
    -------
    >>> import numpy as np
    >>> NeoHookean(E=1.0, nu=0.3).psi(np.eye(2))
    0.0
    """

    kind = "neo-hookean"
    #: the energy does not change under a rigid rotation of the body (frame indifference)
    rotation_invariant = True

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
    def psi_expr(F, params):
        """Energy density for a 2x2 symbolic ``F`` and symbolic ``params = [mu, lam]``."""
        return NeoHookean.density(F[0, 0] - 1, F[0, 1], F[1, 0], F[1, 1] - 1, params[0], params[1], ca.log1p)

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

    def psi(self, F, params=None):
        """``Psi(F)`` (times thickness) for a CasADi 2x2 matrix or a numpy array (..., 2, 2).

        Returns ``inf`` (numpy) where ``J <= 0``.
        """
        p = self.params if params is None else params
        if _is_symbolic(F):
            return self.psi_expr(F, p)
        F = np.asarray(F, dtype=float)
        a, b, c, d = F[..., 0, 0] - 1, F[..., 0, 1], F[..., 1, 0], F[..., 1, 1] - 1
        with np.errstate(divide="ignore", invalid="ignore"):
            out = self.density(a, b, c, d, p[0], p[1])
        out = np.where(a + d + (a * d - b * c) > -1, out, np.inf)
        return float(out) if out.ndim == 0 else out


@dataclass(frozen=True)
class LinearElastic(_Isotropic):
    """Small-strain (geometrically linear) isotropic elasticity, for scenes with small strains.

    ``Psi = mu eps:eps + lam/2 (tr eps)^2`` with ``eps = (F + F^T)/2 - I``. Not rotation invariant:
    use it only where rotations stay small (the fidelity helper decides).
    """

    kind = "linear"
    rotation_invariant = False

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


def numeric_law(material) -> bool:
    """Whether ``material`` states its law in closed form (``density``, ``stress_tangent`` and
    ``tangent_derivative``, None for a constant tangent), so that the energy models can evaluate it in
    vectorised numpy."""
    return all(callable(getattr(material, k, None)) for k in ("density", "stress_tangent")) and (
        hasattr(material, "tangent_derivative"))


Material = NeoHookean | LinearElastic
