"""Hyperelastic materials as scalar energy densities ``Psi(F)`` (per unit rest area, times thickness).

Each material is a frozen dataclass with validated parameters. ``psi(F, params)`` works on a 2x2 CasADi
SX/MX matrix or on numpy arrays of shape (..., 2, 2); stresses and tangents come from automatic
differentiation in :mod:`mdsr_opt.mechanics.model`. ``params`` is the numeric parameter vector the symbolic model
takes at solve time, so one built model serves any stiffness.
"""

from __future__ import annotations

from dataclasses import dataclass

import casadi as ca
import numpy as np

from ..core.checks import positive_float

__all__ = ["NeoHookean", "LinearElastic", "Material"]


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
    def psi_expr(F, params):
        """Energy density for a 2x2 symbolic ``F`` and symbolic ``params = [mu, lam]``."""
        J = F[0, 0] * F[1, 1] - F[0, 1] * F[1, 0]
        lnJ = ca.log(J)
        return params[0] / 2 * (ca.sumsqr(F) - 2) - params[0] * lnJ + params[1] / 2 * lnJ ** 2

    def psi(self, F, params=None):
        """``Psi(F)`` (times thickness) for a CasADi 2x2 matrix or a numpy array (..., 2, 2).

        Returns ``inf`` (numpy) where ``J <= 0``.
        """
        p = self.params if params is None else params
        if _is_symbolic(F):
            return self.psi_expr(F, p)
        F = np.asarray(F, dtype=float)
        J = F[..., 0, 0] * F[..., 1, 1] - F[..., 0, 1] * F[..., 1, 0]
        with np.errstate(divide="ignore", invalid="ignore"):
            lnJ = np.where(J > 0, np.log(np.where(J > 0, J, 1.0)), np.nan)
            out = p[0] / 2 * (np.sum(F ** 2, axis=(-2, -1)) - 2) - p[0] * lnJ + p[1] / 2 * lnJ ** 2
        out = np.where(J > 0, out, np.inf)
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
    def psi_expr(F, params):
        e00, e11 = F[0, 0] - 1, F[1, 1] - 1
        e01 = (F[0, 1] + F[1, 0]) / 2
        tr = e00 + e11
        return params[0] * (e00 ** 2 + e11 ** 2 + 2 * e01 ** 2) + params[1] / 2 * tr ** 2

    def psi(self, F, params=None):
        p = self.params if params is None else params
        if _is_symbolic(F):
            return self.psi_expr(F, p)
        F = np.asarray(F, dtype=float)
        eps = 0.5 * (F + np.swapaxes(F, -1, -2)) - np.eye(2)
        tr = eps[..., 0, 0] + eps[..., 1, 1]
        out = p[0] * np.sum(eps ** 2, axis=(-2, -1)) + p[1] / 2 * tr ** 2
        return float(out) if out.ndim == 0 else out


Material = NeoHookean | LinearElastic
