"""The DXF drawing of the fabrication files (:func:`dxf_text`, written by
:func:`~mdsr_opt.synthesis.export.export_fabrication`): body, holes, channels, walls, fixtures and labels as DXF R12."""

from __future__ import annotations

import math

import numpy as np

from ..plot.style import dxf_color, label_slots

__all__ = ["dxf_text", "label_at", "label_points", "fixture_plates"]

_DXF_INSUNITS = {"in": 1, "mm": 4, "cm": 5, "m": 6, "um": 13}


def label_at(path: np.ndarray, offset: float) -> tuple[np.ndarray, np.ndarray]:
    """A label point beside the middle of a polyline, and the text direction."""
    i = max(1, len(path) // 2)
    a, b = path[i - 1], path[i]
    d = (b - a) / (np.linalg.norm(b - a) or 1.0)
    return (a + b) / 2 + offset * np.array([-d[1], d[0]]), d


def label_points(paths, offset: float) -> list[np.ndarray]:
    """A label point per polyline of ``paths``: beside it, ``offset`` away at a third, half or two thirds of
    its nodes, on either side, wherever it lies farthest from every other polyline and from the labels
    placed before it (so no name sits on another muscle or on another name, as two opposed ropes' labels
    did at their middles)."""
    out: list[np.ndarray] = []
    for j, path in enumerate(paths):
        path = np.asarray(path, dtype=float)
        others = [np.asarray(p, dtype=float) for k, p in enumerate(paths) if k != j]
        best, score = None, -np.inf
        for frac in (0.5, 1 / 3, 2 / 3):
            i = min(max(1, int(round(frac * len(path)))), len(path) - 1)
            a, b = path[i - 1], path[i]
            d = (b - a) / (np.linalg.norm(b - a) or 1.0)
            for side in (1.0, -1.0):
                q = (a + b) / 2 + side * offset * np.array([-d[1], d[0]])
                near = [np.linalg.norm(o - q, axis=1).min() for o in others + [np.array(out)] if len(o)]
                s = min(near, default=np.inf)
                if s > score + 1e-9 * offset:
                    best, score = q, s
                if score >= 2.0 * offset:  # clear of everything: the first such place
                    break
            if score >= 2.0 * offset:
                break
        out.append(best)
    return out


def fixture_plates(paths, radius: float, grow: float = 0.0) -> list[tuple[tuple, np.ndarray]]:
    """The end fixtures of the muscles whose rest polylines are ``paths``, each plate once: ends closer than
    ``radius`` share one plate (:func:`~mdsr_opt.synthesis.fabrication.rope_conflicts`; the design holds them
    as one rigid part), so they are one outline, not two overlapping circles.

    Returns per plate ``(ends, outline)``: ``ends`` the ``(muscle, 0 or -1)`` pairs it holds, ``outline``
    the (k, 2) closed boundary of the union of discs of radius ``radius + grow`` (``grow``: the wall) about
    those ends, or a (1, 2) array (its centre) when it is one disc (one end, or ends at one point)."""
    ends = [(i, k, np.asarray(p[k], dtype=float)) for i, p in enumerate(paths) for k in (0, -1)]
    n = len(ends)
    group = list(range(n))

    def root(a):
        while group[a] != a:
            group[a] = group[group[a]]
            a = group[a]
        return a

    if radius > 0:
        for a in range(n):
            for b in range(a + 1, n):
                if ends[a][0] != ends[b][0] and np.linalg.norm(ends[a][2] - ends[b][2]) < radius:
                    group[root(a)] = root(b)
    out = []
    for g in dict.fromkeys(root(a) for a in range(n)):
        members = [e for a, e in enumerate(ends) if root(a) == g]
        pts = np.array([e[2] for e in members])
        held = tuple((i, k) for i, k, _ in members)
        if np.ptp(pts, axis=0).max() <= 1e-9 * max(radius, 1e-300):
            out.append((held, pts[:1]))
            continue
        from shapely.geometry import Point
        from shapely.ops import unary_union

        shape = unary_union([Point(*q).buffer(radius + grow, 64) for q in pts])
        out.append((held, np.asarray(shape.exterior.coords)[:-1]))
    return out


#: DXF layers: name and ACI colour (7 white/black, 1 red, 5 blue, 3 green)
_DXF_LAYERS = (("BODY", 7), ("HOLES", 7), ("MUSCLES", 1), ("WALLS", 8), ("ENDS", 5), ("LABELS", 3),
               ("CONFLICTS", 1))


def _dxf_number(v: float) -> str:
    """A finite number as DXF wants it: fixed point (no exponent), every digit of its shortest
    round-tripping form (``5.619e-09`` is ``0.000000005619``)."""
    v = float(v)
    if not math.isfinite(v):
        raise ValueError(f"a DXF coordinate must be finite, got {v}")
    s = np.format_float_positional(v, trim="0")
    return "0.0" if s in ("-0.0", "0.0") else s


def _dxf_string(text: str) -> str:
    """A DXF string value: one line (control characters become spaces), ASCII, other characters as the
    ``\\U+XXXX`` escapes that DXF readers decode (AutoCAD; ezdxf's ``decode_dxf_unicode``), a backslash
    and a caret too (``^J`` is a caret code); ``%`` as ``%%%``, since ``%%`` starts a TEXT's control codes
    (``%%u`` underlines); a character beyond U+FFFF becomes ``?``. At most 255 characters, as R12's TEXT
    takes (whole characters: an escape is never cut); the SVG and the CSV keep the name as it is."""
    out = []
    for ch in str(text):
        o = ord(ch)
        if o < 32 or o == 127:
            out.append(" ")
        elif ch == "%":  # "%%%" is a literal percent sign ("%%u" would toggle underlining)
            out.append("%%%")
        elif o < 127 and ch not in "\\^":  # ^ starts a caret code (^J: a line feed)
            out.append(ch)
        elif o <= 0xFFFF and not 0xD800 <= o <= 0xDFFF:
            out.append(f"\\U+{o:04X}")
        else:  # beyond four hex digits (an emoji, say) or a lone surrogate: no escape holds it
            out.append("?")
    n, keep = 0, 0
    for piece in out:
        if n + len(piece) > 255:
            break
        n, keep = n + len(piece), keep + 1
    return "".join(out[:keep])


def dxf_text(fd) -> str:
    """The DXF file of a :class:`~mdsr_opt.synthesis.export.FabricationData` (R12, ASCII): written directly, as a sequence of group code / value lines.

    R12 (AC1009) is the version every CAD program, laser cutter and CAM tool reads; its 2-D ``POLYLINE``
    carries the channel width (groups 40/41). R12 has no unit variable: ``$INSUNITS`` (R2000's) is
    written for the readers that honour it (ezdxf, QCAD/LibreCAD); AutoCAD reports it as unknown and
    ignores it, as it does any header variable newer than the file. The SVG and the CSV state the unit
    as well. It is written here, not through ezdxf, whose import alone costs more than the whole
    export."""
    lines: list[str] = []

    def g(code: int, value) -> None:
        lines.append(f"{code:>3}")
        lines.append(value if isinstance(value, str) else str(value))

    def xy(p) -> None:
        g(10, _dxf_number(p[0]))
        g(20, _dxf_number(p[1]))
        g(30, "0.0")

    def polyline(points, layer: str, closed: bool, width: float = 0.0, color: int | None = None) -> None:
        g(0, "POLYLINE")
        g(8, layer)
        if color is not None:
            g(62, color)
        g(66, 1)  # vertices follow
        xy((0.0, 0.0))
        g(70, 1 if closed else 0)
        if width > 0:
            g(40, _dxf_number(width))
            g(41, _dxf_number(width))
        for p in points:
            g(0, "VERTEX")
            g(8, layer)
            xy(p)
        g(0, "SEQEND")
        g(8, layer)

    size = float(np.ptp(fd.outline, axis=0).max())
    labels = label_points(fd.paths, 0.05 * size)
    # the drawing's extents: the outline, the channels at their width, the end circles, the labels' points
    reach = max(fd.end_radius, 0.5 * fd.channel_width) + fd.wall
    near = np.vstack([fd.outline] + [p - reach for p in fd.paths] + [p + reach for p in fd.paths]
                     + [np.vstack(labels) + [0.0, 0.035 * size]])
    lo, hi = near.min(axis=0), near.max(axis=0)
    g(0, "SECTION")
    g(2, "HEADER")
    g(9, "$ACADVER")
    g(1, "AC1009")
    g(9, "$INSUNITS")
    g(70, _DXF_INSUNITS.get(fd.units, 0))  # 0: unitless
    g(9, "$MEASUREMENT")
    g(70, 0 if fd.units == "in" else 1)
    g(9, "$EXTMIN")
    xy(lo)
    g(9, "$EXTMAX")
    xy(hi)
    g(0, "ENDSEC")
    g(0, "SECTION")
    g(2, "TABLES")
    g(0, "TABLE")
    g(2, "LTYPE")
    g(70, 1)
    g(0, "LTYPE")
    g(2, "CONTINUOUS")
    g(70, 0)
    g(3, "Solid line")
    g(72, 65)
    g(73, 0)
    g(40, "0.0")
    g(0, "ENDTAB")
    g(0, "TABLE")
    g(2, "LAYER")
    g(70, len(_DXF_LAYERS) + 1)
    for name, color in (("0", 7),) + _DXF_LAYERS:
        g(0, "LAYER")
        g(2, name)
        g(70, 0)
        g(62, color)
        g(6, "CONTINUOUS")
    g(0, "ENDTAB")
    g(0, "TABLE")
    g(2, "STYLE")
    g(70, 1)
    g(0, "STYLE")
    g(2, "STANDARD")
    g(70, 0)
    g(40, "0.0")
    g(41, "1.0")
    g(50, "0.0")
    g(71, 0)
    g(42, "2.5")
    g(3, "txt")
    g(4, "")
    g(0, "ENDTAB")
    g(0, "ENDSEC")
    g(0, "SECTION")
    g(2, "ENTITIES")
    polyline(fd.outline, "BODY", closed=True)
    for h in fd.holes:
        polyline(h, "HOLES", closed=True)
    slots = label_slots([mu.name for mu in fd.muscles])  # the figures' colour of each muscle (plot.style)
    for i, (mu, path, q) in enumerate(zip(fd.muscles, fd.paths, labels)):
        # each muscle's entities in the ACI colour nearest its figure colour (plot.style.dxf_color of its
        # name's colour slot, as the figures and the SVG colour it)
        aci = dxf_color(slots[i])
        if fd.wall > 0:
            polyline(path, "WALLS", closed=False, width=fd.channel_width + 2 * fd.wall)
        polyline(path, "MUSCLES", closed=False, width=fd.channel_width, color=aci)
        g(0, "TEXT")
        g(8, "LABELS")
        g(62, aci)
        xy(q)
        g(40, _dxf_number(0.035 * size))
        g(1, _dxf_string(mu.name))
    # each fixture plate once (ends closer than a fixture's radius share one: one outline, in the ENDS
    # layer's colour; a muscle's own plate in its colour), and its wall
    walls = fixture_plates(fd.paths, fd.end_radius, fd.wall)
    for (held, shape), (_, wall) in zip(fixture_plates(fd.paths, fd.end_radius), walls):
        own = len({i for i, _ in held}) == 1
        for layer, outline, r in (("ENDS", shape, fd.end_radius), ("WALLS", wall, fd.end_radius + fd.wall)):
            if layer == "WALLS" and fd.wall <= 0:
                continue
            color = dxf_color(slots[held[0][0]]) if own and layer == "ENDS" else None
            if len(outline) == 1:
                g(0, "CIRCLE")
                g(8, layer)
                if color is not None:
                    g(62, color)
                xy(outline[0])
                g(40, _dxf_number(r))
            else:
                polyline(outline, layer, closed=True, color=color)
    for cf in getattr(fd, "conflicts", ()):  # where the layout cannot be moulded: a circle, as the SVG's red ring
        g(0, "CIRCLE")
        g(8, "CONFLICTS")
        xy(cf.at)
        g(40, _dxf_number(max(fd.end_radius, fd.channel_width) + fd.wall))
    if getattr(fd, "failure", ""):  # a failed design: said in red below the drawing, in lines R12 takes
        import textwrap

        from .export_checks import failed_mark

        for k, line in enumerate(textwrap.wrap(failed_mark(fd.failure), 200)):
            g(0, "TEXT")
            g(8, "CONFLICTS")
            xy((lo[0], lo[1] - (k + 1) * 0.05 * size))
            g(40, _dxf_number(0.035 * size))
            g(1, _dxf_string(line))
    g(0, "ENDSEC")
    g(0, "EOF")
    return "\n".join(lines) + "\n"
