"""One visual language for every figure and drawing the package writes.

This module is the one place that owns

- muscle names and colours: muscle ``i`` (0-based, its place in the layout) is called
  :func:`muscle_name` ``(i)`` (``"M1"``, ``"M2"``, ...) unless it carries a name of its own
  (:func:`muscle_label`), and is drawn in :func:`muscle_color` ``(i)`` in design figures, Figure 6,
  schedules, animations and the fabrication SVG and DXF alike (a numbered name ``M<k>`` is always
  colour ``k``, so one name is one colour also where a muscle is drawn without the muscles numbered before
  it; another name takes the first colour no muscle of the same figure takes: :func:`label_colors`);
- the colours of bodies (driven, target, rest outline) and of measured contours;
- colour scales (:func:`symmetric_limits` and :func:`shared_limits` give panels meant to be compared one
  scale) and colour bars the height of their axes (:func:`add_colorbar`);
- axis labels with quantity and unit (:func:`axis_label`, :func:`label_coordinates`): the scene's length
  unit where known, else ``"body units"``;
- how a contraction or stroke is quoted: commanded and achieved side by side (:func:`commanded_achieved`);
- the file formats figures are written in (:func:`figure_formats`): PNG, and with the vector option a PDF
  or SVG beside it (:func:`mdsr_opt.plot.common.save_figure`), and the files so written (:func:`figure_paths`).

It imports only matplotlib's colour helpers and the muscles' default name (:mod:`mdsr_opt.body.muscles`), so every
stage at or above ``plot`` can use it.
"""

from __future__ import annotations

import os
import re

import numpy as np

from ..body.muscles import default_muscle_name

__all__ = ["MUSCLE_COLORS", "REGION_COLORS", "BODY", "TARGET", "LIGHT", "REST_LINE", "CONTOUR", "CONTOUR_EDGE", "ENERGY_CMAP",
           "CONTRACTION_CMAP", "DISTANCE_CMAP", "BODY_UNITS", "VECTOR_FORMATS", "muscle_name", "muscle_label",
           "muscle_color", "muscle_colors", "muscle_slot", "name_color", "muscle_color_of", "label_slots",
           "label_colors", "layout_colors", "dxf_color", "unit_label", "axis_label", "label_coordinates",
           "energy_label", "symmetric_limits", "shared_limits", "add_colorbar", "commanded_achieved", "figure_formats",
           "figure_paths"]

#: Muscle colours by place in the layout (muscle ``i`` is ``MUSCLE_COLORS[i % 20]``): saturated, apart from
#: the bodies' blues and greys, and told apart from one another (matplotlib's tab10 without its grey, red
#: first as the fabrication drawings always had it; then ten darker or stronger ones, so a layout of up to
#: 20 muscles, as the face's 13, has no colour twice).
MUSCLE_COLORS = ("#d62728", "#1f77b4", "#2ca02c", "#ff7f0e", "#9467bd", "#8c564b", "#e377c2", "#17becf",
                 "#bcbd22", "#393b79", "#8b0000", "#ffd700", "#006400", "#b8860b", "#4b0082", "#ff1493",
                 "#008080", "#808000", "#ff00ff", "#5f9ea0")

#: AutoCAD colour index nearest to each of :data:`MUSCLE_COLORS` (DXF entities carry an ACI colour)
_ACI = (1, 5, 3, 30, 200, 34, 221, 4, 50, 170, 16, 2, 96, 42, 192, 230, 134, 56, 6, 132)

#: Named node regions (a scene's rest figure): ColorBrewer's Dark2, drawn as squares, so that a region is
#: never taken for a muscle of the same colour
REGION_COLORS = ("#1b9e77", "#d95f02", "#7570b3", "#e7298a", "#66a61e", "#e6ab02", "#a6761d", "#666666")

#: A driven (simulated) body: face and edge colour
BODY = {"face": "#8fb3d9", "edge": "#335577"}
#: A target shape, drawn under the driven body
TARGET = {"face": "#cccccc", "edge": "#999999"}
#: A body drawn as the background of other marks (rest mesh, routed muscles)
LIGHT = {"face": "#dde6f0", "edge": "#9aaabb"}
#: The rest outline behind a deformed body
REST_LINE = "#aaaaaa"
#: A measured contour over a photograph: bright cyan on a black rim, visible on grey, white and black
CONTOUR = "#00e5ff"
CONTOUR_EDGE = "#000000"

#: Colour maps: energy density (sequential), relative contraction (diverging, centred on 0: red shortens,
#: blue stretches), distance to a contour (sequential, light = near)
ENERGY_CMAP = "viridis"
CONTRACTION_CMAP = "coolwarm"
DISTANCE_CMAP = "magma_r"

#: The length unit named on axes when the coordinates carry none
BODY_UNITS = "body units"

#: File formats a figure may be written in beside its PNG
VECTOR_FORMATS = ("pdf", "svg")


def muscle_name(i: int) -> str:
    """The name of muscle ``i`` (0-based place in its layout) in every figure and file: ``"M1"``, ``"M2"``..."""
    return default_muscle_name(i)


def muscle_label(muscle, i: int) -> str:
    """The label of ``muscle``, the ``i``-th (0-based) of its layout: its own ``name`` when it has one, else
    :func:`muscle_name` ``(i)``."""
    name = getattr(muscle, "name", None)
    return str(name) if name else muscle_name(i)


def muscle_color(i: int) -> str:
    """The colour (``#rrggbb``) of muscle ``i`` (0-based place in its layout) in every figure and drawing."""
    return MUSCLE_COLORS[int(i) % len(MUSCLE_COLORS)]


def muscle_colors(n: int) -> list[str]:
    """The colours of muscles ``0 .. n-1``."""
    return [muscle_color(i) for i in range(int(n))]


#: a muscle's default name, ``M<k>`` (:func:`muscle_name`)
_NUMBERED = re.compile(r"M([1-9][0-9]*)")


def muscle_slot(label: str, i: int) -> int:
    """The colour slot of a muscle labelled ``label``, the ``i``-th (0-based) of what is drawn: ``k - 1`` for
    a numbered name ``M<k>`` (so muscle ``M3`` keeps its colour in a figure that shows it alone or first,
    as a case of a scene whose muscles are numbered scene-wide), else ``i``."""
    m = _NUMBERED.fullmatch(str(label))
    return int(m.group(1)) - 1 if m else int(i)


def name_color(label: str, i: int) -> str:
    """The colour of the muscle labelled ``label``, ``i``-th of what is drawn: :func:`muscle_color` of its
    :func:`muscle_slot`. Every figure, animation and drawing colours muscles by it (or by
    :func:`muscle_color_of`), so one name is one colour everywhere."""
    return muscle_color(muscle_slot(label, i))


def muscle_color_of(muscle, i: int) -> str:
    """The colour of ``muscle``, the ``i``-th (0-based) of what is drawn: :func:`name_color` of its
    :func:`muscle_label`."""
    return name_color(muscle_label(muscle, i), i)


def label_slots(labels) -> list[int]:
    """The colour slots of the muscles labelled ``labels``, drawn together: a numbered name ``M<k>`` takes
    slot ``k - 1`` (:func:`muscle_slot`), every other name the lowest slot no muscle of the set takes, in
    order, so no two muscles of one figure share a colour unless two are numbered alike."""
    labels = [str(n) for n in labels]
    fixed = [muscle_slot(n, -1) for n in labels]
    used = {s for s in fixed if s >= 0}
    out, free = [], 0
    for s in fixed:
        if s < 0:
            while free in used:
                free += 1
            s = free
            used.add(s)
        out.append(s)
    return out


def label_colors(labels) -> list[str]:
    """The colours of the muscles labelled ``labels``, drawn together (:func:`label_slots`)."""
    return [muscle_color(s) for s in label_slots(labels)]


def layout_colors(muscles) -> list[str]:
    """The colours of ``muscles`` drawn together: :func:`label_colors` of their :func:`muscle_label`."""
    return label_colors([muscle_label(m, i) for i, m in enumerate(muscles)])


def dxf_color(i: int) -> int:
    """The AutoCAD colour index (ACI) standing for :func:`muscle_color` ``(i)`` in DXF files (``i`` a colour
    slot: :func:`muscle_slot`)."""
    return _ACI[int(i) % len(_ACI)]


def unit_label(units: str | None) -> str:
    """``units``, or :data:`BODY_UNITS` when there are none."""
    return str(units) if units else BODY_UNITS


def axis_label(quantity: str, units: str | None = None) -> str:
    """``"quantity (unit)"``: an axis label with its unit (:func:`unit_label`); ``units="1"`` for a ratio
    gives ``"quantity (-)"``."""
    u = "-" if units == "1" else unit_label(units)
    return f"{quantity} ({u})"


def energy_label(stress_unit: str | None = None, units: str | None = None) -> str:
    """The colour bar label of a strain energy map: ``Psi`` times the sheet's thickness, an energy per rest
    area, in ``stress_unit`` times the length ``units`` (``"Pa·mm"``) when the material states its stress
    unit, else in units of ``E*t``."""
    if stress_unit:
        return axis_label("strain energy per area", f"{stress_unit}·{unit_label(units)}")
    return "strain energy per area (units of E*t)"


def label_coordinates(ax, units: str | None = None) -> None:
    """Label a drawing's axes as coordinates ``x``, ``y`` in ``units`` (:func:`axis_label`)."""
    ax.set_xlabel(axis_label("x", units), fontsize=8)
    ax.set_ylabel(axis_label("y", units), fontsize=8)


def symmetric_limits(*values, floor: float = 1e-12) -> tuple[float, float]:
    """``(-m, m)`` with ``m`` the largest magnitude of all ``values`` (finite ones): one diverging colour
    scale, centred on 0, for every panel drawn with it."""
    m = 0.0
    for v in values:
        a = np.abs(np.asarray(v, dtype=float))
        a = a[np.isfinite(a)]
        if a.size:
            m = max(m, float(a.max()))
    m = m if m > floor else 1.0
    return -m, m


def shared_limits(*values) -> tuple[float, float]:
    """``(lo, hi)`` over all ``values`` (finite ones): one sequential colour scale for every panel."""
    lo, hi = np.inf, -np.inf
    for v in values:
        a = np.asarray(v, dtype=float)
        a = a[np.isfinite(a)]
        if a.size:
            lo, hi = min(lo, float(a.min())), max(hi, float(a.max()))
    if not np.isfinite(lo):
        return 0.0, 1.0
    return (lo, hi) if hi > lo else (lo, lo + 1.0)


def add_colorbar(ax, mappable, label: str | None = None, *, pad: float = 0.02, width: float = 0.035):
    """A colour bar beside ``ax``, exactly the height of the axes' drawn box (also with an equal aspect
    ratio, where ``fig.colorbar(ax=...)`` spans the whole figure height); returns the colorbar.

    ``pad`` and ``width`` are fractions of the axes' width (the bar keeps at least 0.08 inch)."""
    fig = ax.figure
    w_in = ax.get_position().width * fig.get_size_inches()[0]
    width = max(width, 0.08 / max(w_in, 1e-9))
    cax = ax.inset_axes([1.0 + pad, 0.0, width, 1.0])
    cb = fig.colorbar(mappable, cax=cax)
    if label:
        cb.set_label(label, fontsize=8)
    cb.ax.tick_params(labelsize=7)
    return cb


def commanded_achieved(commanded, achieved=None, names=None, fmt: str = ".3f") -> str:
    """``"M1 0.150 -> 0.148, M2 ..."``: per muscle the commanded value, then the achieved one (``nan`` when
    unknown); only the commanded value when no achieved values are given. ``names`` default to
    :func:`muscle_name`."""
    c = np.asarray(commanded, dtype=float).ravel()
    a = None if achieved is None else np.asarray(achieved, dtype=float).ravel()
    if a is not None and a.size != c.size:
        a = None
    names = [muscle_name(i) for i in range(c.size)] if names is None else list(names)
    def num(v):  # a value that rounds to zero reads 0.00, never -0.00
        t = f"{v:{fmt}}"
        return t[1:] if t.startswith("-") and float(t) == 0.0 else t

    parts = []
    for i, v in enumerate(c):
        s = f"{names[i]} {num(v)}" if np.isfinite(v) else f"{names[i]} nan"
        if a is not None:
            s += f" \u2192 {num(a[i])}" if np.isfinite(a[i]) else " \u2192 nan"
        parts.append(s)
    return ", ".join(parts)


def figure_formats(vector=None) -> tuple[str, ...]:
    """The formats written beside each PNG for the vector option ``vector``: ``None``/``False`` none,
    ``True`` ``("pdf",)``, a format name (``"pdf"``, ``"svg"``) or a sequence of them as given.

    Raises
    ------
    ValueError
        A format other than :data:`VECTOR_FORMATS`.
    """
    if vector is None or vector is False:
        return ()
    if vector is True:
        return ("pdf",)
    items = (vector,) if isinstance(vector, str) else tuple(vector)
    out = []
    for f in items:
        if not isinstance(f, str) or f.lower().lstrip(".") not in VECTOR_FORMATS:
            raise ValueError(f"vector figure format must be one of {', '.join(VECTOR_FORMATS)}, got {f!r}")
        f = f.lower().lstrip(".")
        if f not in out:
            out.append(f)
    return tuple(out)


def figure_paths(path, vector=None) -> list[str]:
    """Every file :func:`mdsr_opt.plot.common.save_figure` writes for ``path`` and ``vector``: ``path``, then
    one per vector format with the same stem (``design.png`` and ``vector=True``: ``design.png``,
    ``design.pdf``)."""
    path = os.fspath(path)
    stem, ext = os.path.splitext(path)
    return [path] + [f"{stem}.{f}" for f in figure_formats(vector) if f != ext.lower().lstrip(".")]
