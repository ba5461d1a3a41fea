"""Plane-stress laws of a thin hyperelastic sheet, written as energies of ``a = tr F'F`` and ``J = det F``.

A sheet of rest thickness ``t`` loaded in its plane is in plane stress: the out-of-plane stretch ``l3`` takes
the value that makes the normal stress vanish, so ``l3`` is a function of the in-plane deformation ``F``
(2 x 2). For an isotropic law it depends on ``J`` only, and the energy per unit rest volume is a function
``W(a, J)`` of two invariants of ``F``:

* incompressible (``l3 = 1/J``): ``I1 = a + J^-2``, ``I2 = J^2 + a J^-2`` and
  ``W = (mu - k)/2 P(I1 - 3) + k/2 (I2 - 3)`` with ``P(x) = x + r2 x^2 + r3 x^3``: Neo-Hookean
  (``k = 0``, ``P(x) = x``), Mooney-Rivlin (``k = 2 C01``, ``mu = 2 (C10 + C01)``) and Yeoh
  (``k = 0``, ``mu = 2 C1``, ``r2 = C2/C1``, ``r3 = C3/C1``): :class:`IncompressibleLaw`;
* compressible Neo-Hookean (``mu``, ``lam`` the 3-D Lame constants): ``s = ln l3`` solves
  ``mu (e^2s - 1) + lam (ln J + s) = 0`` (the normal stress ``mu (l3 - 1/l3) + lam ln(J l3)/l3`` times
  ``l3``), and ``W = mu/2 (a + l3^2 - 3) - mu ln(J l3) + lam/2 ln^2(J l3)``: :class:`CompressibleNeoHookeanLaw`.

The two parameters ``(mu, k)`` or ``(mu, lam)`` are the model's material parameters (times the thickness);
shape constants such as Yeoh's ratios belong to the law itself. Each law states its energy once, in
:meth:`~InvariantLaw.density` (entries of ``F - I``; numpy arrays or CasADi symbols), and its partial
derivatives in ``(a, J)`` up to third order in :meth:`~InvariantLaw.partials`; the first Piola stress
``P = 2 W_a F + W_J K`` (``K = J F^-T``, the cofactor, linear in ``F``), its tangent and the tangent's
derivative follow from them by the chain rule, the same for every law. Tests check them against CasADi's
derivatives of :meth:`~InvariantLaw.density`, finite differences and the closed-form uniaxial and
equibiaxial stresses.
"""

from __future__ import annotations

import casadi as ca
import numpy as np

__all__ = ["InvariantLaw", "IncompressibleLaw", "CompressibleNeoHookeanLaw", "log_stretch"]

#: Newton iterations of the out-of-plane stretch in the symbolic energy: from the start below they reach
#: round-off for ``J`` in [0.05, 20] and every ``nu`` in [0, 0.5) (at most 7), so that CasADi's derivatives
#: of the iterate are those of the root
SYMBOLIC_ITERATIONS = 8

# dK_ij / dF_kl of the cofactor K = [[F11, -F10], [-F01, F00]] (constant)
_DK = np.zeros((2, 2, 2, 2))
_DK[0, 0, 1, 1] = _DK[1, 1, 0, 0] = 1.0
_DK[0, 1, 1, 0] = _DK[1, 0, 0, 1] = -1.0


def _symbolic(*xs) -> bool:
    return any(isinstance(x, (ca.SX, ca.MX, ca.DM)) for x in xs)


def _cof(F):
    """The cofactor ``K = J F^-T`` of (2, 2, ...) arrays."""
    return np.stack([np.stack([F[1, 1], -F[1, 0]]), np.stack([-F[0, 1], F[0, 0]])])


def _outer(X, Y):
    """``X_ij Y_kl`` of (2, 2, m) arrays: (2, 2, 2, 2, m)."""
    return X[:, :, None, None] * Y[None, None]


def log_stretch(lnJ, mu, lam, iterations: int | None = None):
    """``s = ln l3``, the log of the out-of-plane stretch of a compressible Neo-Hookean sheet in plane stress.

    Newton's method on ``f(s) = mu (e^2s - 1) + lam (ln J + s)``, convex and increasing for ``lam >= 0``,
    from the small-strain root ``s0 = -lam ln J / (2 mu + lam)``, where ``f(s0) = mu (e^2s0 - 1 - 2 s0) >= 0``:
    the iterates fall monotonically to the root. Numpy arrays iterate until the step is round-off (at most
    60 times); CasADi symbols take ``iterations`` (default :data:`SYMBOLIC_ITERATIONS`) steps.
    """
    symbolic = _symbolic(lnJ, mu, lam)
    exp = ca.exp if symbolic else np.exp
    s = -lam * lnJ / (2 * mu + lam)
    n = (SYMBOLIC_ITERATIONS if iterations is None else iterations) if symbolic else (
        60 if iterations is None else iterations)
    for _ in range(n):
        u = exp(2 * s)
        step = (mu * (u - 1) + lam * (lnJ + s)) / (2 * mu * u + lam)
        s = s - step
        if not symbolic and iterations is None:
            with np.errstate(invalid="ignore"):
                if not np.any(np.abs(step) > 4e-16 * (1.0 + np.abs(s))):
                    break
    return s


class InvariantLaw:
    """A plane-stress law ``W(a, J)``: the generic stress, tangent and tangent derivative from the law's
    :meth:`partials`. Subclasses give :meth:`density` and :meth:`partials`."""

    def density(self, a, b, c, d, mu, lam, log1p=np.log1p):
        """``W`` at ``F = I + [[a, b], [c, d]]`` (numpy arrays or CasADi symbols); not finite where ``J <= 0``."""
        raise NotImplementedError

    def partials(self, a, J, mu, lam):
        """``(W_a, W_J, W_aa, W_aJ, W_JJ, W_aaa, W_aaJ, W_aJJ, W_JJJ)`` at invariants ``a``, ``J`` (arrays)."""
        raise NotImplementedError

    def stretch3(self, J, mu, lam):
        """The out-of-plane stretch ``l3`` at in-plane area ratio ``J`` (numpy arrays)."""
        raise NotImplementedError

    def _invariants(self, F):
        a = (F * F).sum(axis=(0, 1))
        J = F[0, 0] * F[1, 1] - F[0, 1] * F[1, 0]
        return a, J, _cof(F)

    def stress_tangent(self, F, mu, lam, tangent: bool = True):
        """First Piola stress ``P`` (2, 2, m) and, with ``tangent``, ``A[i, j, k, l] = dP_ij / dF_kl``
        (2, 2, 2, 2, m) of deformation gradients ``F`` (2, 2, m), elements last:
        ``P = 2 W_a F + W_J K``, ``A = 2 W_a d_ik d_jl + 4 W_aa F (x) F + 2 W_aJ (F (x) K + K (x) F)
        + W_JJ K (x) K + W_J dK/dF``."""
        a, J, K = self._invariants(F)
        Wa, WJ, Waa, WaJ, WJJ, *_ = self.partials(a, J, mu, lam)
        P = 2 * Wa * F + WJ * K
        if not tangent:
            return P, None
        A = 4 * Waa * _outer(F, F) + 2 * WaJ * (_outer(F, K) + _outer(K, F)) + WJJ * _outer(K, K)
        A += WJ * _DK[..., None]
        for i in range(2):
            for j in range(2):
                A[i, j, i, j] += 2 * Wa
        return P, A

    def tangent_derivative(self, F, dF, mu, lam):
        """The derivative of the tangent of :meth:`stress_tangent` along ``dF`` (both (2, 2, m)):
        (2, 2, 2, 2, m)."""
        a, J, K = self._invariants(F)
        Wa, WJ, Waa, WaJ, WJJ, Waaa, WaaJ, WaJJ, WJJJ = self.partials(a, J, mu, lam)
        da = 2 * (F * dF).sum(axis=(0, 1))
        dJ = (K * dF).sum(axis=(0, 1))
        dK = _cof(dF)
        dWa, dWJ = Waa * da + WaJ * dJ, WaJ * da + WJJ * dJ
        dWaa, dWaJ, dWJJ = Waaa * da + WaaJ * dJ, WaaJ * da + WaJJ * dJ, WaJJ * da + WJJJ * dJ
        dA = 4 * dWaa * _outer(F, F) + 4 * Waa * (_outer(dF, F) + _outer(F, dF))
        dA += 2 * dWaJ * (_outer(F, K) + _outer(K, F))
        dA += 2 * WaJ * (_outer(dF, K) + _outer(F, dK) + _outer(dK, F) + _outer(K, dF))
        dA += dWJJ * _outer(K, K) + WJJ * (_outer(dK, K) + _outer(K, dK)) + dWJ * _DK[..., None]
        for i in range(2):
            for j in range(2):
                dA[i, j, i, j] += 2 * dWa
        return dA


class IncompressibleLaw(InvariantLaw):
    """``W = (mu - k)/2 P(I1 - 3) + k/2 (I2 - 3)``, ``l3 = 1/J``, ``P(x) = x + r2 x^2 + r3 x^3`` (the model's
    parameters ``(mu, k)``: the small-strain shear modulus and, for Mooney-Rivlin, ``2 C01``; times the
    thickness).

    Parameters
    ----------
    ratios : (r2, r3)
        Yeoh's ``C2/C1`` and ``C3/C1`` (zero for Neo-Hookean and Mooney-Rivlin).
    mooney : bool
        Whether the second parameter ``k`` weighs ``I2`` (Mooney-Rivlin); otherwise it is ignored (``k = 0``).
    """

    def __init__(self, ratios=(0.0, 0.0), mooney: bool = False):
        self.r2, self.r3 = (float(r) for r in ratios)
        self.mooney = bool(mooney)

    def density(self, a, b, c, d, mu, lam, log1p=np.log1p):
        """``W`` in ``F - I`` without cancellation at rest: ``I1 - 3 = (a - d)^2 + (b + c)^2 + e^2 (3 + 2 e)
        / J^2`` and ``I2 - 3 = (I1 - 3)/J^2 + (e (2 + e))^3 / J^4`` with ``e = J - 1``; ``J^-2`` as
        ``exp(-2 ln J)``, so an inverted triangle has no finite energy."""
        exp = ca.exp if _symbolic(a, b, c, d, mu, lam) else np.exp
        e = a + d + (a * d - b * c)
        iJ2 = exp(-2 * log1p(e))
        x = (a - d) ** 2 + (b + c) ** 2 + e * e * (3 + 2 * e) * iJ2
        k = lam if self.mooney else 0.0
        W = (mu - k) / 2 * (x + self.r2 * x ** 2 + self.r3 * x ** 3)
        if self.mooney:
            W = W + k / 2 * (x * iJ2 + (e * (2 + e)) ** 3 * iJ2 * iJ2)
        return W

    def stretch3(self, J, mu, lam):
        return 1.0 / np.asarray(J, dtype=float)

    def partials(self, a, J, mu, lam):
        k2 = lam if self.mooney else 0.0
        x = a + J ** -2 - 3.0
        c = (mu - k2) / 2
        P1 = c * (1 + 2 * self.r2 * x + 3 * self.r3 * x * x)
        P2 = c * (2 * self.r2 + 6 * self.r3 * x)
        P3 = c * 6 * self.r3 + 0 * x
        xJ, xJJ, xJJJ = -2 * J ** -3, 6 * J ** -4, -24 * J ** -5
        k = k2 / 2
        return (P1 + k * J ** -2, P1 * xJ + k * (2 * J - 2 * a * J ** -3), P2, P2 * xJ + k * (-2 * J ** -3),
                P2 * xJ ** 2 + P1 * xJJ + k * (2 + 6 * a * J ** -4), P3, P3 * xJ,
                P3 * xJ ** 2 + P2 * xJJ + k * 6 * J ** -4,
                P3 * xJ ** 3 + 3 * P2 * xJ * xJJ + P1 * xJJJ + k * (-24 * a * J ** -5))


class CompressibleNeoHookeanLaw(InvariantLaw):
    """``W = mu/2 (a - 2) + h(J)`` with ``h(J) = mu/2 (l3^2 - 1) - mu ln(J l3) + lam/2 ln^2(J l3)`` at the
    out-of-plane stretch of :func:`log_stretch` (``mu``, ``lam`` the 3-D Lame constants times the thickness).

    Implicit differentiation of the stretch's equation (with ``u = l3^2``, ``D = 2 mu u + lam``): ``h' =
    -mu u / J`` (the envelope theorem), ``h'' = mu u (2 mu u + 3 lam) / (D J^2)`` and ``h''' = mu/J^3 (-2 lam u
    (N' D - 2 mu N) / D^3 - 2 N / D)``, ``N = u (2 mu u + 3 lam)``, ``N' = 4 mu u + 3 lam``.
    """

    def density(self, a, b, c, d, mu, lam, log1p=np.log1p):
        """``W`` in ``F - I``: ``mu/2 |F - I|^2 + mu (tr(F - I) - ln J) + mu/2 (e^2s - 1 - 2 s) + lam/2 q^2``
        with ``q = ln J + s``; not finite where ``J <= 0``."""
        symbolic = _symbolic(a, b, c, d, mu, lam)
        expm1 = ca.expm1 if symbolic else np.expm1
        lnJ = log1p(a + d + (a * d - b * c))
        s = log_stretch(lnJ, mu, lam)
        q = lnJ + s
        return (mu / 2 * (a * a + b * b + c * c + d * d) + mu * ((a + d) - lnJ)
                + mu / 2 * (expm1(2 * s) - 2 * s) + lam / 2 * q * q)

    def stretch3(self, J, mu, lam):
        with np.errstate(invalid="ignore", divide="ignore"):
            return np.exp(log_stretch(np.log(np.asarray(J, dtype=float)), mu, lam))

    def partials(self, a, J, mu, lam):
        with np.errstate(invalid="ignore", divide="ignore"):
            u = np.exp(2 * log_stretch(np.log(J), mu, lam))
        D = 2 * mu * u + lam
        N = u * (2 * mu * u + 3 * lam)
        h1 = -mu * u / J
        h2 = mu * N / (D * J * J)
        h3 = mu / J ** 3 * (-2 * lam * u * ((4 * mu * u + 3 * lam) * D - 2 * mu * N) / D ** 3 - 2 * N / D)
        z = 0 * J
        return mu / 2 + z, h1, z, z, h2, z, z, z, h3
