"""Reading and checking scene values: the field-naming reader of scene files and the checks of a
scene's routing and design options (also used for scenes built in Python)."""

from __future__ import annotations

import inspect
import json
import math
import sys
from pathlib import Path
from typing import Mapping, Sequence
import numpy as np

from ..core.checks import check_int, did_you_mean, integer_range
from ..core.errors import InputError

__all__ = ['check_scene_options', 'contact_options', 'SceneFileError']


def check_scene_options(options, kind: str, label: str = "") -> dict:
    """Check a scene's ``routing_options`` (``kind="routing"``) or ``design_options`` (``"design"``): every
    key a keyword of :func:`~mdsr_opt.synthesis.routing.route_muscles` /
    :func:`~mdsr_opt.synthesis.contractions.design_contractions`, every value in its range, solver
    ``options`` known to the solver. Returns a checked copy.

    Raises ``SceneFileError`` (a ValueError) or ``TypeError`` naming ``label`` and the field.
    """
    if kind not in ("routing", "design"):
        raise ValueError(f"kind must be 'routing' or 'design', got {kind!r}")
    r = Reader(label or "scene")
    if not isinstance(options, Mapping):
        r.fail(f"{kind}_options", f"expected a dict, got {tname(options)}", TypeError)
    arrays = {k: options[k] for k in ("initial_guess", "initial", "weights") if kind == "design" and k in options}
    rest = {k: v for k, v in options.items() if k not in arrays}
    if "initial" in arrays:  # the first contractions' older spelling
        arrays.setdefault("initial_guess", arrays.pop("initial"))
    # per-problem arrays (initial, weights) are checked by design_contractions against the muscles and mesh
    return {**scene_options(r, rest, kind), **arrays}


class SceneFileError(InputError):
    """A scene file is malformed; the message names the file and the field."""


class Reader:
    """Field-path-aware checks for one scene file."""

    def __init__(self, path: Path):
        self.path = path
        self.label = path.name if isinstance(path, Path) else str(path)

    def fail(self, where: str, msg: str, kind: type = SceneFileError):
        err = kind(f"{self.label}: {where}: {msg}")
        raise err

    def keys(self, d, allowed: Sequence[str], where: str, required: Sequence[str] = ()) -> dict:
        if not isinstance(d, Mapping):
            self.fail(where, f"expected a table/object, got {tname(d)}", TypeError)
        for k in d:
            if k not in allowed:
                hint = did_you_mean(k, allowed) or f" (allowed: {', '.join(allowed)})"
                self.fail(_join(where, k), f"unknown field{hint}")
        for k in required:
            if k not in d:
                self.fail(_join(where, k), "missing (required)")
        return dict(d)

    def number(self, v, where: str, positive: bool = False) -> float:
        if isinstance(v, bool) or not isinstance(v, (int, float)):
            self.fail(where, f"expected a number, got {tname(v)}", TypeError)
        v = float(v)
        if not math.isfinite(v):
            self.fail(where, f"must be finite, got {v}")
        if positive and v <= 0:
            self.fail(where, f"must be > 0, got {v}")
        return v

    def integer(self, v, where: str, lo: int | None = 1, hi: int | None = None) -> int:
        """:func:`~mdsr_opt.core.checks.check_int`, its failures reported at ``where`` in the file."""
        try:
            return check_int(v, where, lo, hi)
        except TypeError:
            self.fail(where, f"expected an integer, got {v!r}", TypeError)
        except ValueError:
            self.fail(where, f"must be {integer_range(lo, hi)}, got {v}")

    def string(self, v, where: str) -> str:
        if not isinstance(v, str) or not v:
            self.fail(where, f"expected a non-empty string, got {tname(v)}", TypeError)
        return v

    def point(self, v, where: str) -> np.ndarray:
        if not isinstance(v, (list, tuple)) or len(v) != 2:
            self.fail(where, f"expected a point [x, y], got {v!r}", TypeError if not isinstance(v, (list, tuple))
                      else SceneFileError)
        return np.array([self.number(c, f"{where}[{i}]") for i, c in enumerate(v)])

    def points(self, v, where: str, at_least: int = 1) -> np.ndarray:
        if not isinstance(v, (list, tuple)):
            self.fail(where, f"expected a list of points [[x, y], ...], got {tname(v)}", TypeError)
        if len(v) < at_least:
            self.fail(where, f"needs at least {at_least} point(s), got {len(v)}")
        return np.array([self.point(p, f"{where}[{i}]") for i, p in enumerate(v)]).reshape(-1, 2)


def _join(where: str, key) -> str:
    return f"{where}.{key}" if where else str(key)


def tname(v) -> str:
    return "a list" if isinstance(v, list) else "a table" if isinstance(v, Mapping) else type(v).__name__


#: The deepest nesting of tables and lists a scene file may have (a scene needs five or so).
MAX_DEPTH = 64
#: The largest scene file read, in bytes (a big body belongs in a mesh file, ``body.mesh``).
MAX_BYTES = 64 * 2 ** 20


def read_file(path: Path) -> dict:
    """The parsed TOML or JSON scene file: a dict, at most :data:`MAX_BYTES` large and :data:`MAX_DEPTH`
    deep (``SceneFileError`` naming the file otherwise, never a ``RecursionError``)."""
    suffix = path.suffix.lower()
    if suffix not in (".json", ".toml"):
        raise SceneFileError(f"{path.name}: a scene file ends in .toml or .json, not {suffix or 'nothing'}")
    size = path.stat().st_size
    if size > MAX_BYTES:
        raise SceneFileError(f"{path.name}: the scene file is {size / 2 ** 20:.1f} MB, more than the "
                             f"{MAX_BYTES // 2 ** 20} MB a scene file may have (give a large body as a mesh file, "
                             "body.mesh)")
    text = path.read_bytes()
    too_deep = SceneFileError(f"{path.name}: tables and lists are nested more than {MAX_DEPTH} deep; a scene "
                              "file needs only a few levels")
    if suffix == ".json":
        try:
            data = json.loads(text.decode("utf-8"))
        except (UnicodeDecodeError, json.JSONDecodeError) as exc:
            raise SceneFileError(f"{path.name}: not valid JSON: {exc}") from None
        except RecursionError:  # nested deeper than the parser's stack
            raise too_deep from None
    else:
        if sys.version_info >= (3, 11):
            import tomllib
        else:  # pragma: no cover - Python 3.10
            import tomli as tomllib
        try:
            data = tomllib.loads(text.decode("utf-8"))
        except (UnicodeDecodeError, tomllib.TOMLDecodeError) as exc:
            raise SceneFileError(f"{path.name}: not valid TOML: {exc}") from None
        except RecursionError:
            raise too_deep from None
    if not isinstance(data, dict):
        raise SceneFileError(f"{path.name}: the top level must be a table/object, got {tname(data)}")
    if _depth_exceeds(data, MAX_DEPTH):  # parsed, but deeper than any later walk of it should go
        raise too_deep
    return data


def _depth_exceeds(data, limit: int) -> bool:
    """Do the nested dicts and lists of ``data`` go more than ``limit`` levels deep? (No recursion.)"""
    stack = [(data, 1)]
    while stack:
        v, d = stack.pop()
        if d > limit:
            return True
        if isinstance(v, Mapping):
            stack.extend((u, d + 1) for u in v.values() if isinstance(u, (Mapping, list)))
        elif isinstance(v, list):
            stack.extend((u, d + 1) for u in v if isinstance(u, (Mapping, list)))
    return False


def scene_options(r: Reader, spec, where: str) -> dict:
    from ..synthesis.contractions import design_contractions
    from ..synthesis.routing import route_muscles

    fn = route_muscles if where == "routing" else design_contractions
    allowed = [p.name for p in inspect.signature(fn).parameters.values() if p.kind == p.KEYWORD_ONLY]
    if where == "design":
        allowed = [a for a in allowed if a not in ("initial_guess", "weights")]
    opts = r.keys(spec, allowed, where)
    checks = _ROUTING_CHECKS if where == "routing" else _DESIGN_CHECKS
    for k, v in opts.items():
        if k not in checks:  # a keyword added to the function later must get its check here (a test says so)
            r.fail(f"{where}.{k}", "is a keyword this version cannot check in a scene file; set it in Python")
        opts[k] = checks[k](r, v, f"{where}.{k}")
    if where == "design" and "options" in opts:
        opts["options"] = _solver_options(r, opts["options"], opts)
    if where == "design" and opts.get("contact") and opts.get("method", "derivative-free") != "derivative-free":
        r.fail(f"{where}.method", f"contact = true is designed by method = \"derivative-free\", or with no method (a "
               f"gradient design without contact, checked with it); the other methods solve equations without "
               f"contact rows, got {opts['method']!r}")
    if where == "design" and "contact_gap" in opts and not opts.get("contact"):
        r.fail(f"{where}.contact_gap", "is the gap of self-contact: set contact = true too")
    return opts


def _real(lo: float, hi: float, lo_open: bool = False, hi_open: bool = False, what: str = ""):
    def check(r: Reader, v, where: str) -> float:
        x = r.number(v, where)
        if x < lo or x > hi or (lo_open and x == lo) or (hi_open and x == hi):
            rng = f"{'(' if lo_open else '['}{lo:g}, {hi:g}{')' if hi_open else ']'}"
            r.fail(where, f"must lie in {rng}{what}, got {x:g}")
        return x
    return check


def _positive(allow_zero: bool = False):
    def check(r: Reader, v, where: str) -> float:
        x = r.number(v, where)
        if x < 0 or (x == 0 and not allow_zero):
            r.fail(where, f"must be {'>= 0' if allow_zero else '> 0'}, got {x:g}")
        return x
    return check


def _integer(minimum: int = 1):
    def check(r: Reader, v, where: str) -> int:
        return r.integer(v, where, minimum)
    return check


def _choice(*choices: str):
    def check(r: Reader, v, where: str) -> str:
        if v not in choices:
            r.fail(where, f"must be one of {', '.join(map(repr, choices))}, got {v!r}",
                   SceneFileError if isinstance(v, str) else TypeError)
        return v
    return check


def _boolean(r: Reader, v, where: str) -> bool:
    if not isinstance(v, bool):
        r.fail(where, f"expected true or false, got {v!r}", TypeError)
    return v


def _table(r: Reader, v, where: str) -> dict:
    if not isinstance(v, Mapping):
        r.fail(where, f"expected a table of solver options, got {tname(v)}", TypeError)
    return dict(v)


def _boolean_or(*choices: str):
    """True, false or one of ``choices``."""
    def check(r: Reader, v, where: str):
        if not (isinstance(v, bool) or v in choices):
            r.fail(where, f"must be {', '.join(map(repr, choices))}, true or false, got {v!r}",
                   TypeError if not isinstance(v, str) else SceneFileError)
        return v
    return check


_symmetry = _boolean_or("auto")


def fabrication_table(r: Reader, v, where: str):
    """A scene's fabrication: a table of :class:`~mdsr_opt.synthesis.fabrication.Fabrication`'s fields (or
    one, or False: the routing search alone); kept as a plain table of the fields given (the scene file
    the page saves writes it back)."""
    from dataclasses import fields as dc_fields

    from ..synthesis.fabrication import Fabrication

    if v is False or isinstance(v, np.bool_) and not v:
        return False
    if isinstance(v, Fabrication):
        v = {k: x for k, x in v.to_dict().items() if x is not None}
    names = [f.name for f in dc_fields(Fabrication)]
    table = r.keys(v, names, where)
    out = {k: _positive(allow_zero=True)(r, x, f"{where}.{k}") for k, x in table.items()}
    try:
        Fabrication(**out)
    except (TypeError, ValueError) as exc:
        r.fail(where, str(exc).replace("Fabrication: ", ""))
    return out


#: Scene-file checks of ``[design]`` (the ranges design_contractions enforces) and ``[routing]``.
_DESIGN_CHECKS = {
    "method": _choice("flattened", "nested", "derivative-free"),
    "a_max": _real(0.0, 1.0, lo_open=True, hi_open=True, what=" (a fraction of the rest length)"),
    "interior_weight": _real(0.3, 0.7),
    "muscle_model": _choice("springs", "cable"),
    "stiffness": _positive(),
    "tol": _positive(),
    "max_iter": _integer(1),
    "hessian": _choice("exact", "gauss-newton"),
    "scaling": _choice("auto", "size"),
    "warm_start": _boolean_or("target", "rest"),
    "outer": _choice("nelder-mead", "powell"),
    "options": _table,
    "inner_tol": _positive(),
    "verify": _boolean,
    "gap_rtol": _positive(),
    "derivatives": _choice("numeric", "assembled", "casadi"),
    # a length; its bound against the body's size is checked where the mesh is known (Scene)
    "anchor_radius": _positive(allow_zero=True),
    # self-contact of the boundary, in the target solves, the design and the animations (a length: the gap)
    "contact": _boolean,
    "contact_gap": _positive(),
}


def contact_options(design_options) -> dict:
    """The contact keywords (``contact``, ``contact_gap``) of a scene's ``design_options`` for the solves of
    :func:`~mdsr_opt.solve_external` and :func:`~mdsr_opt.solve_internal`: ``{}`` without contact."""
    if not design_options.get("contact"):
        return {}
    return {"contact": True, "contact_gap": design_options.get("contact_gap")}


_ROUTING_CHECKS = {
    "K_a": _positive(allow_zero=True),
    "K_b": _positive(allow_zero=True),
    "K_h": _positive(allow_zero=True),
    "n_seeds": _integer(1),
    "max_muscles": _integer(1),
    "min_length": _positive(allow_zero=True),
    "min_contraction": _real(0.0, 1.0, hi_open=True, what=" (a fraction of the rest length)"),
    "max_turn": _real(0.0, 180.0, what=" (degrees)"),
    "seed_threshold": _real(0.0, 1.0, lo_open=True, what=" (a fraction of the largest contraction)"),
    "compression_ratio": _real(0.0, 1.0, lo_open=True, what=" (a fraction of the largest principal stretch)"),
    "inset": _positive(allow_zero=True),
    "symmetry": _symmetry,
    "fabrication": fabrication_table,
}


def _solver_options(r: Reader, options: dict, design: dict) -> dict:
    """``[design.options]``: IPOPT's options (flattened, without the ``ipopt.`` prefix) or scipy's
    ``minimize`` options (nested: L-BFGS-B; derivative-free: Nelder-Mead or Powell), each checked against
    the solver (:func:`~mdsr_opt.synthesis.contractions.check_design_options`)."""
    from ..synthesis.contractions import check_design_options

    for k, v in options.items():
        try:
            check_design_options({k: v}, design.get("method", "flattened"), design.get("outer", "nelder-mead"))
        except (ValueError, TypeError) as exc:
            r.fail(f"design.options.{k}", str(exc))
    return options
