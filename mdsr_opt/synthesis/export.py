"""Fabrication files: the body and its muscle channels at true scale, and the muscle table.

:func:`export_fabrication` writes, for any design (a :class:`~mdsr_opt.synthesis.poses_result.PosesResult`, a
:class:`~mdsr_opt.synthesis.results.DesignResult` or a mapping of pose names to DesignResults):

``<name>.svg``
    The body outline, its holes and every muscle channel at true scale: the centre line along the muscle's
    mesh edges, the channel drawn ``channel_width`` wide (the fabrication's ``channel_diameter``) and around
    it its wall band (``channel_width + 2 wall`` wide, class ``wall``). The ``viewBox`` is in the body's
    length unit and the ``width``/``height`` attributes state the physical size, so a printer or laser cutter
    reproduces it 1:1. Both ends of every channel carry their fixture: a circle of the fixture's radius
    (the design's ``anchor_radius``, class ``end``) and one of that radius plus the wall (class
    ``end-wall``); ends closer than that radius share one plate, drawn once in black (class ``end shared``,
    ``data-muscles`` naming its muscles; :func:`~mdsr_opt.synthesis.export_dxf.fixture_plates`); each muscle
    is labelled with its name beside its channel, in its colour as in every figure. A place where the layout cannot be moulded
    (:func:`~mdsr_opt.synthesis.fabrication.rope_conflicts`: a channel or fixture outside the body, channels or
    fixtures of different muscles closer than a wall, ropes that cross) carries a red ring (class ``conflict``,
    group ``conflicts``) and the caption, wrapped to the drawing's width, says it.
``<name>.dxf``
    The same geometry as DXF R12 (ASCII; ``$INSUNITS`` set to the unit): layers ``BODY`` (outer outline,
    a closed POLYLINE), ``HOLES``, ``MUSCLES`` (one open POLYLINE per muscle, its vertices the muscle's
    nodes at rest, its width the channel width), ``WALLS`` (the same polylines as wide as the channel and
    its two walls, and the fixtures' circles of radius fixture + wall), ``ENDS`` (the fixtures' circles; a
    shared plate once, as a closed polyline where its ends lie apart),
    ``LABELS`` (text) and ``CONFLICTS`` (a circle where the layout cannot be moulded, as the SVG's red rings).
``<name>_muscles.csv``
    One row per muscle: rest length, end points, and per pose the stroke, the commanded contraction, the
    achieved one (``stroke / rest length``) and the tension it needs;
    last, when the design carries them (``stroke_band``, :func:`~mdsr_opt.synthesis.bands.stroke_bands`),
    each pose's stroke band (``stroke <pose> low``, ``stroke <pose> high``). Above the header, comment lines
    (``#``, e.g. ``pandas.read_csv(path, comment="#")``) say what the drawings say: ``# FAILED DESIGN:
    <reason>, do not build`` and ``# NOT MOULDABLE as laid out (<k> place(s)): <each place>``.

Every number is in the body's length unit ``units`` (one of :data:`UNITS`; default the design's own
``units``, a scene's, else "body units": a drawing whose unit is not known says so and is never labelled
mm), and every column header says it. Tensions are in newtons when the material's ``stress_unit`` (the
silicone presets: Pa) and the length unit are known, else in units of ``E * thickness * length``
(:func:`~mdsr_opt.core.quantities.tension_unit`). Input is checked completely before anything is written, and each
file is written atomically, so bad input leaves nothing behind. A layout that cannot be moulded is still
written, with a :class:`~mdsr_opt.synthesis.fabrication.FabricationWarning` naming the muscles, the distance and
the clearance required. A design that failed, that the acceptance rule rejects (a PipelineResult's
``far_from_target``: the case ``mdsr run`` fails), or whose stroke would stretch a rope, is refused unless
``allow_failed=True``, and then every file says ``FAILED DESIGN: <reason>, do not build``
(:mod:`~mdsr_opt.synthesis.export_checks`). Files of the same name already in the folder are replaced
(``mdsr run`` refuses a folder with files in it unless ``--overwrite``; here give another ``out`` or ``name``). The channel, wall and fixtures drawn are those the layout was
routed with unless told otherwise.
"""

from __future__ import annotations

import csv
import io as _stdio
import math
import os
from dataclasses import dataclass
import re
import textwrap
from pathlib import Path
from typing import Mapping, Sequence

import numpy as np

from ..body.fingerprint import check_same_mesh
from ..body.io import atomic_path
from ..body.mesh import Mesh
from ..body.polygons import polygon_area
from ..body.muscles import Muscle, check_muscles
from ..core.checks import check_stem
from ..core.quantities import LENGTH_UNITS, length_unit, tension_unit
from ..core.results import compact_repr, to_jsonable
from ..mechanics.anchors import body_size
from ..plot.style import layout_colors, muscle_label, muscle_name
from .export_checks import failed_mark, not_mouldable
from .export_dxf import dxf_text, fixture_plates, label_points
from .fabrication import warn_conflicts
from .poses_result import PosesResult

__all__ = ["UNITS", "check_units", "FabricationData", "fabrication_data", "fabrication_files", "export_fabrication"]

#: Known length units and their size in metres.
UNITS = LENGTH_UNITS

#: the longer side, in px, of an SVG drawn in body units (no unit, so not to scale): a size a browser or a
#: viewer shows (at one px per unit a body a few units across would be a few px wide); its caption says the scale
SVG_SIDE_PX = 600.0


def check_units(units) -> str:
    """``units`` if it is a known length unit (:data:`UNITS`); TypeError/ValueError naming the choices."""
    if not isinstance(units, str):
        raise TypeError(f"units must be a string (one of {', '.join(UNITS)}), got {type(units).__name__}")
    if units not in UNITS:
        raise ValueError(f"unknown units {units!r}: expected one of {', '.join(UNITS)}")
    return units


@dataclass(eq=False)
class FabricationData:
    """Everything the fabrication files contain, checked (see :func:`fabrication_data`)."""

    outline: np.ndarray           # (k, 2) outer boundary, counter-clockwise
    holes: list                   # list of (k, 2)
    muscles: tuple                # Muscle
    paths: list                   # (len, 2) rest polylines
    rest_lengths: np.ndarray      # (m,)
    pose_names: tuple
    contractions: np.ndarray      # (P, m)
    strokes: np.ndarray           # (P, m)
    tensions: np.ndarray          # (P, m), NaN where unknown
    end_radius: float
    channel_width: float
    units: str | None             # None: body units (not known)
    wall: float = 0.0
    stroke_bands: np.ndarray | None = None  # (P, m, 2) low/high stroke per pose and muscle; None: not computed
    tension_unit: str = "units of E*t*length"  # the unit of ``tensions`` (N when known)
    conflicts: tuple = ()         # fabrication.Conflict: where the layout cannot be moulded (marked in the SVG)
    failure: str = ""             # why this is no design to build ("": it is; export_checks.design_failure)

    def __repr__(self) -> str:
        return compact_repr(self, ("units", "pose_names"), extra={
            "n_muscles": len(self.muscles), "n_holes": len(self.holes), "outline": self.outline,
            "strokes": self.strokes, "channel_width": self.channel_width})

    def to_dict(self) -> dict:
        """Every field, JSON-ready (arrays as nested lists, NaN as None, muscles as ``{nodes, name}``)."""
        return {f: to_jsonable(getattr(self, f)) for f in self.__dataclass_fields__}


def _from_design(d, muscles, mesh, what="the design"):
    a = np.asarray(d.contractions, dtype=float).reshape(-1)
    if len(a) != len(muscles):
        raise ValueError(f"{what} has {len(a)} contraction(s) for {len(muscles)} muscle(s)")
    L0 = np.array([m.rest_length(mesh) for m in muscles])
    _check_rest_lengths(getattr(d, "rest_lengths", None), L0, muscles, what)
    st = getattr(d, "stroke", None)
    st = a * L0 if st is None or np.size(st) != len(a) else np.asarray(st, dtype=float).reshape(-1)
    tn = getattr(d, "tension", None)
    tn = np.full(len(a), np.nan) if tn is None or np.size(tn) != len(a) else np.asarray(tn, float).reshape(-1)
    return a, st, tn, getattr(d, "anchor_radius", None)


def _check_rest_lengths(recorded, L0, muscles, what) -> None:
    """The rest lengths a result recorded must be those of ``muscles`` on this mesh (another mesh, or
    another layout of as many muscles, would pair its strokes with the wrong lengths)."""
    if recorded is None or np.size(recorded) != len(L0):
        return
    rec = np.asarray(recorded, dtype=float).reshape(-1)
    off = np.flatnonzero(np.isfinite(rec) & ~np.isclose(rec, L0, rtol=1e-7, atol=0.0))
    if len(off):
        i = int(off[0])
        raise ValueError(f"{what} was made with muscle {muscle_label(muscles[i], i)!r} of rest length {rec[i]:.6g}; on this "
                         f"mesh with these muscles it is {L0[i]:.6g}: give the mesh and the muscles the design "
                         "was made with")


def _known(design, name: str):
    """The design's own ``units`` or ``stress_unit`` (None when it records none)."""
    from .pipeline import PipelineResult

    if isinstance(design, PipelineResult):
        return getattr(design.design, name, None) or getattr(design.material, name, None)
    items = list(design.values()) if isinstance(design, Mapping) else [design]
    return next((v for v in (getattr(d, name, None) for d in items) if isinstance(v, str) and v), None)


def _check_design_type(design, muscles) -> None:
    """TypeError naming ``design`` when it is none of the results :func:`fabrication_data` reads."""
    from .pipeline import PipelineResult

    kinds = ("a PosesResult (design_poses), a PipelineResult (design_pipeline), a DesignResult "
             "(design_contractions), a mapping of pose name to DesignResult, or None with muscles=... (the "
             "layout alone)")
    if design is None:
        if muscles is None:
            raise TypeError(f"design is None and no muscles are given: design must be {kinds}")
        return
    if isinstance(design, (PosesResult, PipelineResult)):
        return
    if isinstance(design, Mapping):
        bad = [k for k, d in design.items() if not hasattr(d, "contractions")]
        if bad:
            raise TypeError(f"design is a mapping whose value for {bad[0]!r} is a {type(design[bad[0]]).__name__}, "
                            f"not a DesignResult: design must be {kinds}")
        return
    if not hasattr(design, "contractions"):
        raise TypeError(f"design must be {kinds}, got {type(design).__name__}")


def fabrication_data(mesh: Mesh, design=None, *, muscles: Sequence[Muscle] | None = None, units: str | None = None,
                     channel_width: float | None = None, fabrication=None, material=None,
                     failure: str = "") -> FabricationData:
    """Collect and check the geometry and per-pose figures of a design (writes nothing).

    Parameters
    ----------
    mesh : Mesh
        The body at rest, in length unit ``units``.
    design : PosesResult, PipelineResult, DesignResult, mapping of pose name -> DesignResult, or None
        None: the layout alone (no strokes).
    muscles : the layout; required unless ``design`` knows its own (a PosesResult, a PipelineResult, or any
        result with a ``muscles`` attribute), which it then replaces.
    units : one of :data:`UNITS`, optional
        Default: the design's (``design.units``, a scene's ``units`` or ``design_pipeline(units=...)``), else
        None: "body units" (the drawing says so; a DXF carries no unit). A unit other than the design's is
        refused.
    channel_width : float, optional
        Drawn width of a channel (length units); default the fabrication's ``channel_diameter``.
    fabrication : Fabrication or dict of its fields, optional
        Channel, wall and fixtures (:class:`~mdsr_opt.synthesis.fabrication.Fabrication`); default: the one
        the layout was routed with (a PipelineResult's, a PosesResult's), else the defaults for this body;
        one stating other sizes than the routed one is refused. The fixtures' radius is the design's
        ``anchor_radius`` when it has one.
    material : optional
        The body's material, for the unit of the tensions (its ``stress_unit``) when the design does not
        record it (a PosesResult records it since ``design_poses`` was given ``units``); with a known length
        unit, tensions are then in N.
    failure : str, optional
        Why the design is not to be built beyond what it records itself (a gait whose schedule failed);
        the result's ``failure`` joins it with :func:`~mdsr_opt.synthesis.export_checks.design_failure` and
        :func:`~mdsr_opt.synthesis.export_checks.impossible_strokes` ("" when the design may be built).
    """
    from .export_checks import check_same_fabrication, design_failure, impossible_strokes, routed_fabrication
    from .fabrication import Fabrication, check_fabrication, check_sizes_fit, rope_conflicts
    from .pipeline import PipelineResult

    known = _known(design, "units")
    if units is None:
        units = known
    elif known is not None and check_units(units) != known:
        raise ValueError(f"units={units!r}, but the design was made in {known}: the mesh's coordinates are in "
                         f"{known} (leave units out, or give units={known!r})")
    units = None if units is None else check_units(units)
    t_unit, t_factor = tension_unit(_known(design, "stress_unit") or getattr(material, "stress_unit", None), units)
    if not isinstance(failure, str):
        raise TypeError(f"failure must be a string (why the design is not to be built), got {type(failure).__name__}")
    routed = routed_fabrication(design)
    check_same_fabrication(fabrication, routed)
    fabrication = routed if fabrication is None and routed is not None else fabrication
    fab = check_fabrication(fabrication)
    if fab is False:  # routed without a fabrication: the defaults' channel, wall and fixtures are drawn
        fab = Fabrication()
    if not isinstance(mesh, Mesh):
        raise TypeError(f"mesh must be a Mesh, got {type(mesh).__name__}")
    _check_design_type(design, muscles)
    size = body_size(mesh) if isinstance(design, PosesResult) else None  # its poses judged as mdsr run's
    failure = "; ".join(w for w in (design_failure(design, size), failure.strip()) if w)
    if isinstance(design, PipelineResult):  # the design with the muscles it was made for
        design, muscles = design.design, design.muscles if muscles is None else muscles
    elif muscles is None and not isinstance(design, (PosesResult, Mapping)):
        muscles = getattr(design, "muscles", None)  # a result that records its muscles
    if isinstance(design, PosesResult):
        if design.states.shape[1] != mesh.n_nodes:
            raise ValueError(f"the design is of a mesh with {design.states.shape[1]} nodes, not this one "
                             f"({mesh.n_nodes})")
        check_same_mesh(mesh, design.rest_mesh, "the layout")
        mus = list(design.muscles) if muscles is None else check_muscles(mesh, muscles)
        _check_rest_lengths(design.rest_lengths, np.array([mu.rest_length(mesh) for mu in mus]), mus, "the layout")
        names, A, S, T = design.names, design.contractions, design.strokes, design.tensions
        radius, bands = design.anchor_radius, None
    else:
        if muscles is None:
            raise ValueError("give the muscles of the design (muscles=...): a DesignResult or a mapping of them "
                             "does not record its muscles (a PipelineResult and a PosesResult do)")
        if design is None:
            items = {}
        elif isinstance(design, Mapping):
            items = dict(design)
        elif hasattr(design, "contractions"):
            items = {"design": design}
        else:
            raise TypeError("design must be a PosesResult, a PipelineResult, a DesignResult, a mapping of pose "
                            f"name to DesignResult or None, got {type(design).__name__}")
        what = {k: "the design" if len(items) == 1 else f"the design of {k!r}" for k in items}
        for k, d in items.items():  # the body first: muscles checked on another body would mislead
            check_same_mesh(mesh, getattr(d, "rest_mesh", None), what[k])
        mus = check_muscles(mesh, muscles)
        rows = {k: _from_design(d, mus, mesh, what[k]) for k, d in items.items()}
        bands = [np.asarray(getattr(d, "stroke_band", ()), dtype=float).reshape(-1, 2) for d in items.values()]
        bands = np.array([b if len(b) == len(mus) else np.full((len(mus), 2), np.nan) for b in bands])
        names = tuple(str(k) for k in rows)
        m = len(mus)
        A = np.array([r[0] for r in rows.values()]).reshape(len(rows), m)
        S = np.array([r[1] for r in rows.values()]).reshape(len(rows), m)
        T = np.array([r[2] for r in rows.values()]).reshape(len(rows), m)
        radius = next((r[3] for r in rows.values() if r[3] is not None), None)
    if not mus:
        raise ValueError("the design has no muscles: nothing to fabricate")
    # every channel is labelled: an unnamed muscle is called M<k> (its place in the layout, from 1), as in
    # every figure (mdsr_opt.plot.style.muscle_name)
    mus = [mu if mu.name else Muscle(mu.nodes, name=muscle_name(i)) for i, mu in enumerate(mus)]
    h = float(mesh.edge_lengths.mean())
    fab = fab.for_body(mesh)
    if channel_width is None:
        channel_width = fab.channel_diameter if fab.channel_diameter > 0 else 0.2 * h
    if (isinstance(channel_width, bool) or not isinstance(channel_width, (int, float))
            or not math.isfinite(channel_width) or channel_width <= 0):
        raise ValueError(f"channel_width must be a positive length, got {channel_width!r}")
    end_radius = (float(radius) if radius is not None and math.isfinite(radius) and radius > 0
                  else fab.fixture_radius if fab.fixture_radius > 0 else 0.4 * h)
    check_sizes_fit(mesh, float(channel_width), fab.wall, end_radius)
    loops = [mesh.points[np.asarray(lp)] for lp in mesh.boundary_loops]
    areas = [polygon_area(p) for p in loops]
    k = int(np.argmax(np.abs(areas)))
    outline = loops[k] if areas[k] > 0 else loops[k][::-1]
    holes = [p for i, p in enumerate(loops) if i != k]
    P = mesh.points
    fd = FabricationData(outline=outline, holes=holes, muscles=tuple(mus),
                         paths=[P[list(mu.nodes)] for mu in mus],
                         rest_lengths=np.array([mu.rest_length(mesh) for mu in mus]), pose_names=tuple(names),
                         contractions=np.asarray(A, float), strokes=np.asarray(S, float),
                         tensions=t_factor * np.asarray(T, float), tension_unit=t_unit,
                         # the end patches' radius, when the design has one (NaN: none; 0: points)
                         end_radius=end_radius,
                         conflicts=tuple(rope_conflicts(mesh, mus, fab, fixture_radius=end_radius,
                                                        channel_width=float(channel_width))),
                         channel_width=float(channel_width), units=units, wall=float(fab.wall),
                         stroke_bands=bands if bands is not None and np.isfinite(bands).any() else None)
    fd.failure = "; ".join(w for w in (failure, *impossible_strokes(fd)) if w)  # a rope that would stretch too
    return fd


# ---------------------------------------------------------------------------------------------- writers
#: Characters XML 1.0 does not allow in a document (C0 controls but tab, line feed and carriage return;
#: lone surrogates; U+FFFE and U+FFFF): names are checked at the door, and these never reach the SVG anyway.
_NOT_XML = re.compile("[\x00-\x08\x0b\x0c\x0e-\x1f\ud800-\udfff\ufffe\uffff]")


#: The stroke of a fixture plate that several muscles share (each muscle's own plate is in its colour)
SHARED_PLATE = "#000000"


def escape(text) -> str:
    """``text`` as XML character data or an attribute value: ``& < > " '`` as entities, any character XML
    does not allow replaced by U+FFFD (so the SVG always parses)."""
    t = str(text).replace("&", "&amp;").replace("<", "&lt;").replace(">", "&gt;")
    return _NOT_XML.sub("\ufffd", t.replace('"', "&quot;").replace("'", "&#x27;"))


def _svg_text(fd: FabricationData, title: str) -> str:
    allp = np.vstack([fd.outline] + fd.holes)
    lo, hi = allp.min(0), allp.max(0)
    size = float((hi - lo).max())
    pad = 0.05 * size + fd.end_radius + fd.wall
    W, H = float(hi[0] - lo[0] + 2 * pad), float(hi[1] - lo[1] + 2 * pad)
    u = length_unit(fd.units)
    scale, phys = (1.0, u) if u in ("mm", "cm", "in") else (UNITS[u] / 1e-3, "mm") if u in UNITS else (1.0, "")
    drawn = ""
    if not phys:  # body units have no physical size: a drawable one (1 body unit = 1 px would be a speck)
        scale, phys = SVG_SIDE_PX / max(W, H), "px"
        drawn = f" (not to scale: drawn at {scale:.4g} px per body unit)"

    def xy(p):
        return f"{p[0] - lo[0] + pad:.9g},{hi[1] - p[1] + pad:.9g}"

    lw = 0.002 * size
    fs = 0.035 * size
    shared = sum(len({i for i, _ in held}) > 1 for held, _ in fixture_plates(fd.paths, fd.end_radius))
    caption = (f"{title}: {len(fd.muscles)} muscle channel(s) {fd.channel_width:.4g} wide with walls of "
               f"{fd.wall:.4g}; circles: end fixtures (radius {fd.end_radius:.4g}) and their walls"
               + (f" (black: {shared} plate(s) that muscles ending closer than a radius share)" if shared else "")
               + f"; units: {u}{drawn}")
    if fd.failure:  # first, in the title and the caption: no one builds it by mistake
        title, caption = f"{failed_mark(fd.failure)}. {title}", f"{failed_mark(fd.failure)}. {caption}"
    if fd.conflicts:
        caption += ". " + not_mouldable(fd.conflicts, "red rings")
    fc = fs * 0.8
    # the caption wrapped to the drawing's width (a sans-serif character is at most ~0.6 em wide on average),
    # on lines below the drawing, which grows by as many lines
    lines = textwrap.wrap(caption, max(20, int((W - 0.6 * pad) / (0.6 * fc)))) or [""]
    y0 = H - pad * 0.3
    H += 1.25 * fc * (len(lines) - 1)
    out = ['<?xml version="1.0" encoding="UTF-8"?>',
           f'<svg xmlns="http://www.w3.org/2000/svg" version="1.1" width="{W * scale:.9g}{phys}" '
           f'height="{H * scale:.9g}{phys}" viewBox="0 0 {W:.9g} {H:.9g}">',
           f"<title>{escape(title)} ({'true scale, ' if fd.units else ''}units: {u})</title>",
           '<g id="body" fill="none" stroke="#000000" stroke-width="%.6g">' % lw]
    for i, loop in enumerate([fd.outline] + fd.holes):
        pts = " ".join(xy(p) for p in loop)
        kind = "outline" if i == 0 else f"hole{i - 1}"
        out.append(f'<polygon id="{kind}" class="{"outline" if i == 0 else "hole"}" points="{pts}"/>')
    out.append("</g>")
    out.append('<g id="muscles" fill="none" stroke-linecap="round" stroke-linejoin="round">')
    colors = layout_colors(fd.muscles)  # the figures' colours (plot.style)
    for i, (mu, path) in enumerate(zip(fd.muscles, fd.paths)):
        c = colors[i]
        pts = " ".join(xy(p) for p in path)
        if fd.wall > 0:
            out.append(f'<polyline class="wall" points="{pts}" stroke="{c}" stroke-opacity="0.12" '
                       f'stroke-width="{fd.channel_width + 2 * fd.wall:.9g}"/>')
        out.append(f'<polyline class="channel" points="{pts}" stroke="{c}" stroke-opacity="0.35" '
                   f'stroke-width="{fd.channel_width:.9g}"/>')
        out.append(f'<polyline class="muscle" id="{escape(mu.name)}" points="{pts}" stroke="{c}" '
                   f'stroke-width="{lw:.6g}" data-rest-length="{fd.rest_lengths[i]:.9g}" data-units="{u}"/>')
    out.append("</g>")
    out.append(f'<g id="ends" fill="none" stroke-width="{lw:.6g}">')
    # each fixture plate once: a muscle's own in its colour, one that ends closer than a fixture's radius
    # share (one rigid part) as one outline in black, naming the muscles it holds
    walls = fixture_plates(fd.paths, fd.end_radius, fd.wall)
    for (held, shape), (_, wall) in zip(fixture_plates(fd.paths, fd.end_radius), walls):
        shared = len({i for i, _ in held}) > 1
        c = SHARED_PLATE if shared else colors[held[0][0]]
        attrs = (f'class="end shared" data-muscles="{" ".join(escape(fd.muscles[i].name) for i, _ in held)}" '
                 if shared else 'class="end" ')
        for kind, outline, r, dash in (("", shape, fd.end_radius, ""),
                                       ("-wall", wall, fd.end_radius + fd.wall, f' stroke-dasharray="{2 * lw:.6g}"')):
            if kind and fd.wall <= 0:
                continue
            a = attrs.replace('class="end', f'class="end{kind}')
            if len(outline) == 1:
                x, y = xy(outline[0]).split(",")
                out.append(f'<circle {a}cx="{x}" cy="{y}" r="{r:.9g}" stroke="{c}"{dash}/>')
            else:
                out.append(f'<polygon {a}points="{" ".join(xy(q) for q in outline)}" stroke="{c}"{dash}/>')
    out.append("</g>")
    out.append(f'<g id="labels" font-family="sans-serif" font-size="{fs:.6g}" text-anchor="middle" '
               'dominant-baseline="central">')
    # each name centred on its point, beside its channel and clear of the other channels and names
    for i, (mu, p) in enumerate(zip(fd.muscles, label_points(fd.paths, 1.2 * fs))):
        x, y = xy(p).split(",")
        out.append(f'<text class="label" x="{x}" y="{y}" fill="{colors[i]}">{escape(mu.name)}</text>')
    out.append("</g>")
    if fd.conflicts:  # where the layout cannot be moulded: a red ring, its sentence as the ring's title
        out.append(f'<g id="conflicts" fill="none" stroke="#d00000" stroke-width="{2 * lw:.6g}">')
        for cf in fd.conflicts:
            x, y = xy(cf.at).split(",")
            names = " ".join(escape(fd.muscles[i].name) for i in cf.muscles)
            out.append(f'<circle class="conflict {cf.kind}" cx="{x}" cy="{y}" '
                       f'r="{max(fd.end_radius, fd.channel_width) + fd.wall:.9g}" data-muscles="{names}" '
                       f'data-distance="{cf.distance:.9g}" data-required="{cf.required:.9g}">'
                       f"<title>{escape(cf.message)}</title></circle>")
        out.append("</g>")
    if fd.failure:  # across the drawing, in red: a print of it cannot be taken for a design to build
        out.append(f'<text id="failed" x="{W / 2:.6g}" y="{(H - 1.25 * fc * (len(lines) - 1)) / 2:.6g}" '
                   f'font-family="sans-serif" font-weight="bold" font-size="{min(0.12 * size, W / 20):.6g}" '
                   'fill="#d00000" fill-opacity="0.55" text-anchor="middle" dominant-baseline="central">'
                   "FAILED DESIGN: DO NOT BUILD</text>")
    out.append(f'<text class="caption" x="{pad * 0.3:.6g}" y="{y0:.6g}" font-family="sans-serif" '
               f'font-size="{fc:.6g}"{FAILED_FILL if fd.failure else ""}>' + "".join(
                   f'<tspan x="{pad * 0.3:.6g}" dy="{0 if k == 0 else 1.25 * fc:.6g}">{escape(t)}</tspan>'
                   for k, t in enumerate(lines)) + "</text>")
    out.append("</svg>")
    return "\n".join(out) + "\n"


#: the caption of a failed design is drawn in this colour (its first sentence says why it failed)
FAILED_FILL = ' fill="#d00000"'


def _csv_text(fd: FabricationData) -> str:
    u, tu = length_unit(fd.units), fd.tension_unit
    head = ["muscle", "edges", f"rest length [{u}]", f"start x [{u}]", f"start y [{u}]", f"end x [{u}]",
            f"end y [{u}]"]
    for p in fd.pose_names:
        # the commanded contraction beside the achieved one (the stroke's): a slack or stretched rope shows
        head += [f"stroke {p} [{u}]", f"contraction {p} [1]", f"achieved {p} [1]", f"tension {p} [{tu}]"]
    if fd.pose_names:
        head += [f"max stroke [{u}]", f"max tension [{tu}]"]
    if fd.stroke_bands is not None:  # the strokes' uncertainty bands (synthesis.bands), last
        head += [f"stroke {p} {e} [{u}]" for p in fd.pose_names for e in ("low", "high")]
    buf = _stdio.StringIO()
    if fd.failure:  # a first line no one misses (a spreadsheet shows it above the table)
        buf.write(f"# {failed_mark(fd.failure)}\n")
    if fd.conflicts:  # as the SVG's caption and the DXF's CONFLICTS layer say it
        buf.write(f"# {not_mouldable(fd.conflicts)}\n")
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(head)

    def num(v):
        return "" if not np.isfinite(v) else f"{v:.9g}"

    for i, (mu, path) in enumerate(zip(fd.muscles, fd.paths)):
        row = [mu.name, len(mu.nodes) - 1, num(fd.rest_lengths[i]), num(path[0, 0]), num(path[0, 1]),
               num(path[-1, 0]), num(path[-1, 1])]
        for k in range(len(fd.pose_names)):
            achieved = fd.strokes[k, i] / fd.rest_lengths[i] if fd.rest_lengths[i] > 0 else np.nan
            row += [num(fd.strokes[k, i]), num(fd.contractions[k, i]), num(achieved), num(fd.tensions[k, i])]
        if fd.pose_names:
            t = fd.tensions[:, i]
            row += [num(fd.strokes[:, i].max()), num(np.nanmax(t)) if np.isfinite(t).any() else ""]
        if fd.stroke_bands is not None:
            row += [num(v) for k in range(len(fd.pose_names)) for v in fd.stroke_bands[k, i]]
        w.writerow(row)
    return buf.getvalue()


def fabrication_files(out, name: str) -> dict[str, Path]:
    """The files :func:`export_fabrication` writes for ``name`` into the folder ``out``:
    ``{"svg": out/<name>.svg, "dxf": out/<name>.dxf, "csv": out/<name>_muscles.csv}``."""
    folder = Path(out)
    return {"svg": folder / f"{name}.svg", "dxf": folder / f"{name}.dxf", "csv": folder / f"{name}_muscles.csv"}


def export_fabrication(mesh: Mesh, design, out, *, muscles: Sequence[Muscle] | None = None, units: str | None = None,
                       name: str = "robot", channel_width: float | None = None, fabrication=None,
                       material=None, allow_failed: bool = False, failure: str = "") -> dict[str, str]:
    """Write the fabrication files of a design: SVG and DXF at true scale, and the muscle CSV.

    Parameters
    ----------
    mesh : Mesh
        The body at rest; its coordinates are lengths in ``units``.
    design : PosesResult, PipelineResult, DesignResult, mapping of pose name -> DesignResult, or None (layout
        only)
    out : str or path-like
        Output folder (created).
    muscles : the layout (required unless ``design`` knows its own: a PosesResult, a PipelineResult).
    units : one of :data:`UNITS`, optional: the unit of every number written. Default: the design's own
        (a scene's ``units``, ``design_pipeline(units=...)``), else "body units" (said in every file; a DXF
        without a unit), never an invented mm. A unit other than the design's is refused.
    name : file stem: ``<name>.svg``, ``<name>.dxf``, ``<name>_muscles.csv``.
    channel_width : drawn channel width, length units (default the fabrication's ``channel_diameter``).
    fabrication : Fabrication or dict of its fields (default: the one the layout was routed with, a
        PipelineResult's or a PosesResult's, else the defaults for the body): the channels' walls and the
        end fixtures drawn. One stating other sizes than the routed one is refused.
    material : optional: the body's material, for the tensions' unit when the design does not record it
        (:func:`fabrication_data`).
    allow_failed : bool, default False
        Write the files of a design that is not to be built (it failed, the acceptance rule rejects it: a
        PipelineResult's ``far_from_target``, or a muscle's stroke would stretch its rope:
        :mod:`~mdsr_opt.synthesis.export_checks`); every file then says ``FAILED DESIGN: <reason>, do not
        build`` (the SVG's title and caption, a DXF text, the CSV's first line) and a warning says so.
    failure : str, optional
        Why the design is not to be built beyond what it records (a gait whose schedule failed): it is then
        a failed design as above.

    Returns
    -------
    dict
        ``{"svg": path, "dxf": path, "csv": path}``. Files of those names already in ``out`` are replaced
        (each atomically), without a warning: unlike ``mdsr run``, which refuses a folder with files in it
        unless ``--overwrite``.

    Raises
    ------
    TypeError, ValueError
        Unknown units, a design of another mesh (:func:`~mdsr_opt.body.fingerprint.check_same_mesh`) or of
        other muscles, missing muscles, a name that is no plain file stem
        (:func:`~mdsr_opt.core.checks.check_stem`), ``out`` naming an existing file, a channel, wall or
        fixture too large for the body, a fabrication other than the routed one, a failed or not accepted
        design (``far_from_target``) without ``allow_failed``: before anything is written.

    Warns
    -----
    FabricationWarning
        Where the layout cannot be moulded (:func:`~mdsr_opt.synthesis.fabrication.rope_conflicts`: a channel or
        fixture outside the body, channels or fixtures of different muscles closer than a wall, ropes that
        cross), naming the muscles, the distance and the clearance required; every file marks those places
        (the SVG's red rings and caption, the DXF's ``CONFLICTS`` layer, the CSV's ``# NOT MOULDABLE`` line).
    """
    check_stem(name, "name")  # no path separator, no control character: before anything is written
    try:
        folder = Path(out)
    except TypeError:
        raise TypeError(f"out must be a folder path (str or path-like), got {type(out).__name__}") from None
    if folder.exists() and not folder.is_dir():
        raise ValueError(f"out {os.fspath(out)!r} is an existing file, not a folder: give a folder for the "
                         "fabrication files")
    if not isinstance(allow_failed, (bool, np.bool_)):
        raise TypeError(f"allow_failed must be True or False, got {type(allow_failed).__name__}")
    fd = fabrication_data(mesh, design, muscles=muscles, units=units, channel_width=channel_width,
                          fabrication=fabrication, material=material, failure=failure)
    if fd.failure and not allow_failed:
        raise ValueError(f"export_fabrication ({name}): {fd.failure}: its files would describe a robot that "
                         "does not do what was asked. Give allow_failed=True to write them anyway, marked "
                         "'FAILED DESIGN ... do not build'")
    if fd.failure:
        import warnings

        warnings.warn(f"export_fabrication ({name}): {failed_mark(fd.failure)}; every file says so",
                      UserWarning, stacklevel=2)
    warn_conflicts(fd.conflicts, f"export_fabrication ({name})")
    svg = _svg_text(fd, name)
    dxf = dxf_text(fd)
    table = _csv_text(fd)
    paths = fabrication_files(out, name)
    Path(out).mkdir(parents=True, exist_ok=True)
    with atomic_path(paths["svg"]) as tmp:
        Path(tmp).write_text(svg, encoding="utf-8")  # as its XML declaration says, on every platform
    with atomic_path(paths["dxf"]) as tmp:
        Path(tmp).write_text(dxf, encoding="ascii")
    with atomic_path(paths["csv"]) as tmp:
        Path(tmp).write_text(table, encoding="utf-8")
    return {k: os.fspath(v) for k, v in paths.items()}
