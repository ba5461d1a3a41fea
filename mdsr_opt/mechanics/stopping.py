"""The iteration callback that stops a CasADi NLP solver at its next iteration when Ctrl-C was pressed (or a
stop was requested) inside :func:`~mdsr_opt.core.guards.interruptible`.

CasADi calls an NLP solver's ``iteration_callback`` once per iteration (IPOPT, sqpmethod and Uno alike); a
nonzero answer stops the solver (IPOPT: ``User_Requested_Stop``), and the surrounding
:func:`~mdsr_opt.core.guards.interruptible` block then raises the :class:`KeyboardInterrupt`. Its inputs are
declared empty, which CasADi accepts for any NLP, so one callback serves every solver of the process and
nothing is copied for it.

Example
-------
>>> import casadi as ca
>>> x = ca.MX.sym("x")
>>> opts = with_stop_callback({"ipopt.print_level": 0, "ipopt.sb": "yes", "print_time": False})
>>> solver = ca.nlpsol("s", "ipopt", {"x": x, "f": (x - 1) ** 2}, opts)
>>> float(solver(x0=0)["x"])
1.0
"""

from __future__ import annotations

import casadi as ca
import numpy as np

from ..core.guards import stop_requested

__all__ = ["stop_callback", "with_stop_callback"]

_CALLBACK: list = []  # the process's one callback (a CasADi Callback must stay referenced while in use)


class _StopCallback(ca.Callback):
    """``iteration_callback`` of an NLP solver: 1 (stop) when :func:`~mdsr_opt.core.guards.stop_requested`."""

    def __init__(self):
        ca.Callback.__init__(self)
        self.construct("stop_on_interrupt", {})

    def get_n_in(self):
        return ca.nlpsol_n_out()

    def get_n_out(self):
        return 1

    def get_name_in(self, i):
        return ca.nlpsol_out(i)

    def get_sparsity_in(self, i):
        return ca.Sparsity(0, 0)  # empty: CasADi skips the check against the NLP's sizes

    def get_sparsity_out(self, i):
        return ca.Sparsity.scalar()

    def has_eval_buffer(self):
        return True

    def eval_buffer(self, arg, res):
        np.frombuffer(res[0], dtype=np.float64)[0] = 1.0 if stop_requested() else 0.0
        return 0


def stop_callback() -> ca.Function:
    """The process's stopping iteration callback (made on first use)."""
    if not _CALLBACK:
        _CALLBACK.append(_StopCallback())
    return _CALLBACK[0]


def with_stop_callback(opts: dict) -> dict:
    """``opts`` (CasADi ``nlpsol`` options) with :func:`stop_callback` as the ``iteration_callback``, unless
    the caller gave one (theirs is kept: the solve then stops on Ctrl-C by CasADi's own check)."""
    out = dict(opts)
    out.setdefault("iteration_callback", stop_callback())
    return out
