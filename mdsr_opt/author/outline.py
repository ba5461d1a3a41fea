"""Outlines for the authoring page: polygons (with holes) from JSON or SVG text.

JSON: ``{"outline": [[x, y], ...], "holes": [[[x, y], ...], ...]}`` or a bare list of points.
SVG: every ``<polygon>``, ``<polyline>``, ``<rect>`` and straight-segment ``<path>`` (commands M, L, H, V,
Z, absolute or relative) is a polygon; the largest is the outline, the others are holes. SVG's y axis
points down, so y is negated (the drawing appears upright). Curves and ``transform`` attributes are
refused with a message saying so.
"""

from __future__ import annotations

import json
import re
import xml.etree.ElementTree as ET

import numpy as np

from ..body.polygons import check_polygon, polygon_area

__all__ = ["parse_outline", "MAX_POINTS"]

#: Most vertices an outline file may hold (all polygons together).
MAX_POINTS = 20000

_NUM = r"[-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?"


def parse_outline(filename: str, text: str) -> tuple[np.ndarray, list[np.ndarray]]:
    """Read an outline and holes from a ``.json`` or ``.svg`` file's text.

    Returns
    -------
    outline : (k, 2) ndarray, counter-clockwise; holes : list of (k_i, 2) ndarrays.

    Raises
    ------
    ValueError
        Unknown file type, malformed text, fewer than 3 points, too many points, non-finite numbers, a
        polygon that crosses itself (the message names which), unsupported SVG features.
    """
    name = str(filename or "").lower()
    if name.endswith(".json"):
        polys = _from_json(text)
    elif name.endswith(".svg"):
        polys = _from_svg(text)
    else:
        raise ValueError(f"an outline file ends in .json or .svg, not {filename!r}")
    if not polys:
        raise ValueError(f"{filename}: holds no polygon")
    if sum(len(p) for p in polys) > MAX_POINTS:
        raise ValueError(f"{filename}: more than {MAX_POINTS} points")
    return check_outline(polys[0], polys[1:], where=filename)


def check_outline(outline, holes=(), where: str = "outline") -> tuple[np.ndarray, list[np.ndarray]]:
    """Check an outline and holes as polygons (finite, simple) and order them: the outline is the
    polygon with the largest area when it came from an SVG file (the caller passes that one first)."""
    polys = [np.asarray(outline, dtype=float)] + [np.asarray(h, dtype=float) for h in holes]
    for i, p in enumerate(polys):
        what = "outline" if i == 0 else f"hole {i}"
        if p.ndim != 2 or p.shape[1:] != (2,):
            raise ValueError(f"{where}: {what}: expected a list of [x, y] points")
        if not np.all(np.isfinite(p)):
            raise ValueError(f"{where}: {what}: coordinates must be finite numbers")
    checked = []
    for i, p in enumerate(polys):
        what = "outline" if i == 0 else f"hole {i}"
        try:
            checked.append(check_polygon(p, what))
        except ValueError as exc:
            raise ValueError(f"{where}: {exc}") from None
    return checked[0], checked[1:]


def _from_json(text: str) -> list[np.ndarray]:
    try:
        data = json.loads(text)
    except json.JSONDecodeError as exc:
        raise ValueError(f"outline file is not valid JSON: {exc}") from None
    if isinstance(data, dict):
        unknown = set(data) - {"outline", "holes"}
        if unknown:
            raise ValueError(f"outline JSON: unknown field {sorted(unknown)[0]!r} (allowed: outline, holes)")
        if "outline" not in data:
            raise ValueError("outline JSON: missing field 'outline'")
        outline, holes = data["outline"], data.get("holes", [])
        if not isinstance(holes, list):
            raise ValueError("outline JSON: 'holes' must be a list of polygons")
    elif isinstance(data, list):
        outline, holes = data, []
    else:
        raise ValueError("outline JSON: expected {\"outline\": [[x, y], ...], \"holes\": [...]} or a list of points")
    return [_points(outline, "outline")] + [_points(h, f"holes[{i}]") for i, h in enumerate(holes)]


def _points(v, what: str) -> np.ndarray:
    if not isinstance(v, list) or not all(isinstance(p, list) and len(p) == 2 for p in v):
        raise ValueError(f"outline JSON: {what} must be a list of [x, y] points")
    for p in v:
        for c in p:
            if isinstance(c, bool) or not isinstance(c, (int, float)):
                raise ValueError(f"outline JSON: {what}: {c!r} is not a number")
    return np.asarray(v, dtype=float).reshape(-1, 2)


def _from_svg(text: str) -> list[np.ndarray]:
    if "<!ENTITY" in text or "<!DOCTYPE" in text:
        raise ValueError("SVG outline: DOCTYPE and ENTITY declarations are not accepted")
    try:
        root = ET.fromstring(text)
    except ET.ParseError as exc:
        raise ValueError(f"SVG outline is not valid XML: {exc}") from None
    polys = []
    for el in root.iter():
        tag = el.tag.rsplit("}", 1)[-1]
        if tag not in ("polygon", "polyline", "rect", "path"):
            if tag in ("circle", "ellipse", "line"):
                raise ValueError(f"SVG outline: <{tag}> is not supported (use polygon, rect or a straight path)")
            continue
        if "transform" in el.attrib:
            raise ValueError(f"SVG outline: <{tag}> has a transform attribute, which is not supported "
                             "(apply the transforms to the points first)")
        if tag in ("polygon", "polyline"):
            nums = [float(v) for v in re.findall(_NUM, el.get("points", ""))]
            if len(nums) % 2:
                raise ValueError(f"SVG outline: <{tag}> points has an odd count of numbers")
            polys.append(np.asarray(nums, dtype=float).reshape(-1, 2))
        elif tag == "rect":
            try:
                x, y = float(el.get("x", 0)), float(el.get("y", 0))
                w, h = float(el.get("width")), float(el.get("height"))
            except (TypeError, ValueError):
                raise ValueError("SVG outline: <rect> needs numeric x, y, width and height") from None
            polys.append(np.array([[x, y], [x + w, y], [x + w, y + h], [x, y + h]]))
        else:
            polys.extend(_path(el.get("d", "")))
    polys = [p * [1.0, -1.0] for p in polys if len(p)]
    polys.sort(key=lambda p: -abs(polygon_area(p)) if len(p) >= 3 else 0.0)
    return polys


def _path(d: str) -> list[np.ndarray]:
    tokens = re.findall(rf"[A-Za-z]|{_NUM}", d)
    out, cur = [], []
    pos = np.zeros(2)
    start = np.zeros(2)
    cmd = None
    i = 0
    while i < len(tokens):
        t = tokens[i]
        if t.isalpha():
            cmd = t
            i += 1
            if cmd in "Zz":
                if cur:
                    out.append(np.array(cur))
                cur, pos = [], start.copy()
                continue
            if cmd not in "MmLlHhVv":
                raise ValueError(f"SVG outline: path command {cmd!r} (a curve or arc) is not supported; "
                                 "only straight segments M, L, H, V, Z")
            continue
        if cmd is None:
            raise ValueError("SVG outline: a path must start with a command (M)")
        rel = cmd.islower()
        c = cmd.upper()
        n = 1 if c in "HV" else 2
        if i + n > len(tokens) or any(tok.isalpha() for tok in tokens[i:i + n]):
            raise ValueError(f"SVG outline: path command {cmd!r} is missing a number")
        vals = [float(v) for v in tokens[i:i + n]]
        i += n
        if c == "H":
            new = np.array([vals[0] + (pos[0] if rel else 0.0), pos[1]])
        elif c == "V":
            new = np.array([pos[0], vals[0] + (pos[1] if rel else 0.0)])
        else:
            new = np.array(vals) + (pos if rel else 0.0)
        if c == "M":
            if cur:
                out.append(np.array(cur))
            cur, start = [new], new.copy()
            cmd = "l" if rel else "L"  # further pairs after M are line-tos
        else:
            cur.append(new)
        pos = new
    if cur:
        out.append(np.array(cur))
    return out
