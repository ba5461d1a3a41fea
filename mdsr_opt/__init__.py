"""mdsr_opt: kinematic modelling and computational design of muscle-driven soft robots.

Data flows one way: mesh -> scene -> equilibrium -> target -> contraction graph -> muscles -> design ->
evaluation. The names a user calls are here, listed in ``__init__.pyi`` and imported lazily from the module
that owns each (``lazy_loader``), so ``import mdsr_opt`` stays cheap and does not touch numpy, CasADi or
matplotlib; everything else is imported from its module (``mdsr_opt.<stage>.<module>``). The command line is
:mod:`mdsr_opt.cli.main`.
"""

from __future__ import annotations

import lazy_loader

__version__ = "0.1.0"

__getattr__, _, _names = lazy_loader.attach_stub(__name__, __file__)
__all__ = [*_names, "__version__"]


def __dir__() -> list[str]:
    return list(__all__)
