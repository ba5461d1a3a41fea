"""The units a user reads beside a length or a rope's tension.

A body's coordinates are lengths in a unit (a scene's ``units``: :data:`LENGTH_UNITS`) or in none ("body
units"); a material's constants are stresses in a unit (``stress_unit``: :data:`STRESS_UNITS`, the
silicone presets' pascals) or in none (the dimensionless library materials, ``E = 1``). A rope's tension is
a stress times the sheet's thickness times a length: in newtons when both units are known
(:func:`tension_unit`; ``Pa x mm^2 = 1e-6 N``), else in "units of E*t*length".

Example
-------
>>> tension_unit("Pa", "mm")
('N', 1e-06)
>>> tension_unit(None, "mm")
('units of E*t*mm', 1.0)
>>> length_unit(None)
'body units'
"""

from __future__ import annotations

__all__ = ["LENGTH_UNITS", "STRESS_UNITS", "BODY_UNITS", "check_length_unit", "check_stress_unit", "length_unit",
           "tension_unit", "contact_in_unit", "percent_beside", "POINT_BAND_RTOL", "point_band", "band_text"]

#: Known length units and their size in metres.
LENGTH_UNITS = {"mm": 1e-3, "cm": 1e-2, "m": 1.0, "um": 1e-6, "in": 0.0254}

#: Known stress units and their size in pascals.
STRESS_UNITS = {"Pa": 1.0, "kPa": 1e3, "MPa": 1e6}

#: A length whose unit is not known
BODY_UNITS = "body units"


def check_length_unit(value) -> str | None:
    """``value`` if it is None or a known length unit (:data:`LENGTH_UNITS`); TypeError/ValueError naming
    them."""
    if value is None:
        return None
    if not isinstance(value, str):
        raise TypeError(f"units must be a string (one of {', '.join(LENGTH_UNITS)}), got {type(value).__name__}")
    if value not in LENGTH_UNITS:
        raise ValueError(f"unknown units {value!r}: expected one of {', '.join(LENGTH_UNITS)}")
    return value


def check_stress_unit(value) -> str | None:
    """``value`` if it is None or a known stress unit (:data:`STRESS_UNITS`); ValueError naming them."""
    if value is None or (isinstance(value, str) and value in STRESS_UNITS):
        return value
    raise ValueError(f"unknown stress_unit {value!r}: expected None (dimensionless) or one of "
                     f"{', '.join(STRESS_UNITS)}")


def length_unit(units: str | None) -> str:
    """The unit a length is read in: ``units``, or :data:`BODY_UNITS` when there is none."""
    return str(units) if units else BODY_UNITS


def tension_unit(stress_unit: str | None, units: str | None) -> tuple[str, float]:
    """``(label, factor)``: a tension computed in the material's and the body's units (``E * t * length``)
    times ``factor`` is in ``label``: ``("N", ...)`` when both units are known (:data:`STRESS_UNITS`,
    :data:`LENGTH_UNITS`), else ``("units of E*t*<length unit>", 1.0)``."""
    if stress_unit in STRESS_UNITS and units in LENGTH_UNITS:
        return "N", STRESS_UNITS[stress_unit] * LENGTH_UNITS[units] ** 2
    return f"units of E*t*{units if units else 'length'}", 1.0


def contact_in_unit(report: dict | None, stress_unit: str | None, units: str | None) -> dict | None:
    """A contact report (``EquilibriumResult.contact``: forces in ``E * t * length``) with its forces in the
    unit rope tensions are given in (:func:`tension_unit`: newtons when ``stress_unit`` and ``units`` are
    known) and that unit in ``force_unit``; a copy (None stays None)."""
    if report is None:
        return None
    label, factor = tension_unit(stress_unit, units)
    if report.get("force_unit") == label:
        return dict(report)
    if report.get("force_unit", tension_unit(stress_unit, None)[0]) != tension_unit(stress_unit, None)[0]:
        raise ValueError(f"the contact report is in {report['force_unit']!r}, not in units of E*t*length")

    def scaled(v):
        return [scaled(u) for u in v] if isinstance(v, (list, tuple)) else float(v) * factor

    out = dict(report, force_unit=label)
    for key in ("node_forces", "obstacle_forces", "total_force"):
        if key in out:
            out[key] = scaled(out[key])
    out["pairs"] = [dict(p, force=None if p["force"] is None else float(p["force"]) * factor)
                    for p in report.get("pairs", [])]
    if isinstance(report.get("friction"), dict):
        fr = dict(report["friction"])
        for key in ("tangential", "normal"):
            if key in fr:
                fr[key] = scaled(fr[key])
        out["friction"] = fr
    return out


def percent_beside(value: float, threshold: float, digits: int = 0, most: int = 6) -> str:
    """The fraction ``value`` as a percentage (the number, without ``%``) with ``digits`` decimals, or as many
    more (up to ``most``) as it takes to print it on the same side of the fraction ``threshold`` as it lies:
    a message comparing the two never shows a value equal to the threshold, or across it.

    Example
    -------
    >>> percent_beside(0.0966, 0.1), percent_beside(0.0996, 0.1), percent_beside(0.5, 0.1)
    ('9.7', '9.96', '50')
    >>> percent_beside(0.05004, 0.05, 2), percent_beside(0.1, 0.1)
    ('5.004', '10')
    """
    v, t = 100.0 * float(value), 100.0 * float(threshold)
    side = (v > t) - (v < t)
    for d in range(int(digits), max(int(most), int(digits)) + 1):
        text = f"{v:.{d}f}"
        shown = float(text)
        if (shown > t) - (shown < t) == side:
            return text
    return text


#: a stroke band narrower than this (relative to the stroke) of a muscle at its bound is that bound, a point
POINT_BAND_RTOL = 1e-6


def point_band(low: float, high: float, at_bound: bool) -> bool:
    """A stroke band ``[low, high]`` of a muscle ``at_bound`` (saturated) that is its bound: a point (within
    :data:`POINT_BAND_RTOL`), not a certain stroke."""
    return bool(at_bound) and high - low <= POINT_BAND_RTOL * max(abs(low), 1e-300)


def band_text(low: float, high: float, at_bound: bool = False, digits: int = 4) -> str:
    """A stroke band as read beside its stroke: ``"[low, high]"`` (``digits`` significant digits), or
    ``"(its bound)"`` for a saturated muscle's point band (:func:`point_band`).

    >>> band_text(1.0, 1.25), band_text(3.0, 3.0, at_bound=True)
    ('[1, 1.25]', '(its bound)')
    """
    return "(its bound)" if point_band(low, high, at_bound) else f"[{low:.{digits}g}, {high:.{digits}g}]"
