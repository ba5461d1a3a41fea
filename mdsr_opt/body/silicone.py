"""Presets of casting silicones as thin sheets (plane stress, incompressible), with the data they come from.

:func:`silicone` gives a :class:`~mdsr_opt.body.material.Yeoh` sheet (or the Neo-Hookean sheet of the same
small-strain shear modulus) of a named silicone. Constants are in pascals (SI): with lengths in metres,
energies are in joules and rope tensions in newtons (any other length unit ``L`` gives ``Pa L^3`` and
``Pa L^2``).

Sources
-------
* Ecoflex 00-30, Ecoflex 00-50, Dragon Skin 10 Medium, Dragon Skin 20, Dragon Skin 30 (Smooth-On): Yeoh
  constants fitted here to the uniaxial tensile curves of the Soft Robotics Materials Database,
  L. Marechal, P. Balland, L. Lindenroth, F. Petrou, C. Kontovounisios and F. Bello, "Toward a common
  framework and database of materials for soft robotics", Soft Robotics 8(3), 284-297 (2021),
  doi:10.1089/soro.2019.0115; data files ``Tensile-Tests-Data/<name>.csv`` of
  github.com/LucMarechal/Soft-Robotics-Materials-Database (commit 0f67d88995fe), columns "Engineering
  Strain" and "Engineering Stress (MPa)": ASTM D412 dumbbells 3 x 6 mm, 33 mm long, pulled at 450 mm/min,
  strain derived from the crosshead displacement (the files' headers). The fit: the twelve rows at 25, 50,
  ..., 300 % strain (t = 1.1, 2.2, ..., 13.2 s; tests/test_materials.py lists them), linear least squares
  on the relative error of the incompressible uniaxial nominal stress ``2 (l - l^-2)(C1 + 2 C2 x +
  3 C3 x^2)``, ``x = l^2 + 2/l - 3``, constants rounded to three significant figures. They stay within
  5.5 % of the measured stress from 50 to 300 % strain; at 25 % they exceed it by up to 8.1 % (Ecoflex
  00-30 7.4 %, Dragon Skin 20 8.1 %) and at 11 % by 8-21 %. The small-strain end is the least certain part
  of these tests (crosshead strain includes the grips' settling; the Ecoflex files start with a negative
  stress at 4 % strain), so the small-strain moduli ``E = 6 C1`` (45, 62, 131, 370, 553 kPa) are
  extrapolations.
  ``C3 < 0`` in every fit: the laws' uniaxial stress stops rising at 326-334 % strain (Dragon Skin) and
  424-432 % (Ecoflex), outside the data; do not stretch these presets past 300 %. They are independent
  fits of the paper's data, not the coefficients its authors fitted. A cast part differs from a test
  specimen with mixing, degassing, cure and age: measure the batch a robot is made of where it matters.
* Sylgard 184 (Dow): Young's modulus 1.32 MPa, the low end of the 1.32-2.97 MPa that I. D. Johnston
  et al., "Mechanical characterization of bulk Sylgard 184 for microfluidics and microengineering",
  J. Micromech. Microeng. 24(3), 035017 (2014), doi:10.1088/0960-1317/24/3/035017, report for curing
  temperatures from 25 to 200 C (abstract), the cooler the cure the softer (as R. Moucka et al., Sci. Rep.
  2021, doi:10.1038/s41598-021-98694-2, sum it up). A Neo-Hookean sheet (``C1 = E/6``, ``C2 = C3 = 0``);
  cured hot, Sylgard 184 is up to 2.25 times stiffer.

Example
-------
>>> m = silicone("ecoflex-00-30", thickness=2e-3)
>>> m.kind.startswith("yeoh"), round(m.E / 1e3, 1)   # small-strain Young's modulus, kPa
(True, 44.9)
"""

from __future__ import annotations

from ..core.checks import did_you_mean
from .material import NeoHookean, Yeoh

__all__ = ["silicone", "SILICONES"]

#: name -> (C1, C2, C3) in Pa (see the module's sources: fits to Marechal et al. 2021, Johnston et al. 2014)
SILICONES: dict[str, tuple[float, float, float]] = {
    "ecoflex-00-30": (7.48e3, 164.0, -3.38),
    "ecoflex-00-50": (10.3e3, 324.0, -5.98),
    "dragon-skin-10": (21.8e3, 2.71e3, -73.8),
    "dragon-skin-20": (61.7e3, 6.83e3, -183.0),
    "dragon-skin-30": (92.2e3, 7.86e3, -212.0),
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
        With ``stress_unit="Pa"``: tensions of a body in known length units are then reported in newtons.

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
        hint = did_you_mean(key, SILICONES, cutoff=0.5)
        raise ValueError(f"unknown silicone {name!r}{hint}; known: {', '.join(SILICONES)}")
    if law not in _LAWS:
        raise ValueError(f"law must be one of {', '.join(_LAWS)}, got {law!r}")
    C1, C2, C3 = SILICONES[key]
    if law == "neo-hookean":
        return NeoHookean(E=6.0 * C1, nu=0.5, thickness=thickness, plane="stress", stress_unit="Pa")
    return Yeoh(C1, C2, C3, thickness, stress_unit="Pa")
