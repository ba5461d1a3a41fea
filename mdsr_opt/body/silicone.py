"""Presets of casting silicones as thin sheets (plane stress, incompressible), with the data they come from.

:func:`silicone` gives a :class:`~mdsr_opt.body.material.Yeoh` sheet (or the Neo-Hookean sheet of the same
small-strain shear modulus) of a named silicone. Constants are in pascals (SI): with lengths in metres,
energies are in joules and rope tensions in newtons (any other length unit ``L`` gives ``Pa L^3`` and
``Pa L^2``).

Sources
-------
* Ecoflex 00-30, Ecoflex 00-50, Dragon Skin 10 (Medium), Dragon Skin 20, Dragon Skin 30 (Smooth-On): Yeoh
  constants fitted here (linear least squares on the relative error of the incompressible uniaxial
  nominal stress ``2 (l - l^-2)(C1 + 2 C2 x + 3 C3 x^2)``, ``x = l^2 + 2/l - 3``) to the ASTM D412 tensile
  tests of L. Marechal, P. Balland, L. Lindenroth, F. Petrou, C. Kontovounisios and F. Bello, "Toward a
  common framework and database of materials for soft robotics", Soft Robotics 8(3), 284-297 (2021) (the
  Soft Robotics Materials Database, Open Database License): engineering strains 25-300 %, where the fits
  stay within 5 % of the measured stress. Below 25 % the crosshead-derived strains of those tests include
  the grips' settling, and the fits exceed the measured stress by 8-20 % at 11 % strain. Smooth-On's
  technical bulletins state higher 100 % moduli (Ecoflex 00-30: 10 psi, 69 kPa, against 30 kPa measured;
  Dragon Skin 30: 86 psi, 593 kPa, against 437 kPa): a cast part can differ from these by tens of per cent
  with mixing, degassing, cure and age, so measure the batch a robot is made of where it matters.
  ``C3 < 0`` in every fit: past about 400 % strain the laws soften, outside the data.
* Sylgard 184 (Dow, 10:1): Young's modulus 1.32 MPa cured at room temperature (25 C), rising to 2.97 MPa
  cured at 200 C: I. D. Johnston, D. K. McCluskey, C. K. L. Tan and M. C. Tracey, "Mechanical
  characterization of bulk Sylgard 184 for microfluidics and microengineering", J. Micromech. Microeng.
  24, 035017 (2014). A Neo-Hookean sheet (``C1 = E/6``, ``C2 = C3 = 0``).

Example
-------
>>> m = silicone("ecoflex-00-30", thickness=2e-3)
>>> m.kind.startswith("yeoh"), round(m.E / 1e3, 1)   # small-strain Young's modulus, kPa
(True, 44.8)
"""

from __future__ import annotations

from .material import NeoHookean, Yeoh

__all__ = ["silicone", "SILICONES"]

#: name -> (C1, C2, C3) in Pa (see the module's sources)
SILICONES: dict[str, tuple[float, float, float]] = {
    "ecoflex-00-30": (7.47e3, 168.0, -3.6),
    "ecoflex-00-50": (10.30e3, 329.0, -6.1),
    "dragon-skin-10": (21.7e3, 2.75e3, -74.9),
    "dragon-skin-20": (61.4e3, 6.96e3, -187.0),
    "dragon-skin-30": (91.9e3, 8.01e3, -216.0),
    "sylgard-184": (1.32e6 / 6.0, 0.0, 0.0),
}

_LAWS = ("yeoh", "neo-hookean")


def _key(name: str) -> str:
    return "-".join(name.strip().lower().replace("_", " ").replace("-", " ").split())


def silicone(name: str, thickness: float = 1.0, law: str = "yeoh"):
    """A sheet of a casting silicone (plane stress, incompressible).

    Parameters
    ----------
    name : str
        One of :data:`SILICONES` (case, spaces and underscores do not matter: ``"Dragon Skin 30"``).
    thickness : float
        The sheet's rest thickness, in the units of the mesh.
    law : {"yeoh", "neo-hookean"}
        The fitted Yeoh law, or the Neo-Hookean sheet of the same small-strain shear modulus ``2 C1``
        (:class:`~mdsr_opt.body.material.NeoHookean` with ``nu = 0.5``, ``plane="stress"``).

    Returns
    -------
    Yeoh or NeoHookean

    Raises
    ------
    ValueError
        An unknown name (the message lists the known ones) or law.
    TypeError
        A name that is not a string.
    """
    if not isinstance(name, str):
        raise TypeError(f"the silicone's name must be a string, got {type(name).__name__}")
    key = _key(name)
    if key not in SILICONES:
        raise ValueError(f"unknown silicone {name!r}; known: {', '.join(SILICONES)}")
    if law not in _LAWS:
        raise ValueError(f"law must be one of {', '.join(_LAWS)}, got {law!r}")
    C1, C2, C3 = SILICONES[key]
    if law == "neo-hookean":
        return NeoHookean(E=6.0 * C1, nu=0.5, thickness=thickness, plane="stress")
    return Yeoh(C1, C2, C3, thickness)
