"""Argument checks shared by every stage: arrays of the right shape, positive numbers, indices, node lists,
names and file stems."""

from __future__ import annotations

import difflib
import inspect
import math
import numbers
import unicodedata
from collections.abc import Callable, Iterable, Mapping
import numpy as np
from numpy.typing import ArrayLike

__all__ = ['as_float_array', 'as_index_array', 'node_indices', 'positive_float', 'positive_int', 'check_int',
           'integer_range', 'check_label', 'check_stem', 'check_options', 'keyword_names', 'did_you_mean', 'unknown_key_hint']


def as_float_array(value: ArrayLike, name: str, shape: tuple[int | None, ...] | None = None) -> np.ndarray:
    """Return ``value`` as a finite float array, raising ``TypeError``/``ValueError`` naming ``name``.

    Real numbers only: strings (``"0.2"``), booleans (``True`` would read as 1), None, complex numbers and
    object arrays are refused with a ``TypeError`` naming the first bad element and its type, never
    converted."""
    found = _first_non_real(value)
    if found is not None:
        where, bad = found
        raise TypeError(f"{name}{where} must be a real number, got {type(bad).__name__} {bad!r}")
    try:
        arr = np.asarray(value)
    except Exception as exc:  # pragma: no cover - exotic inputs
        raise TypeError(f"{name} must be array-like of numbers: {exc}") from None
    if arr.dtype == object or arr.dtype == bool or not np.issubdtype(arr.dtype, np.number):
        kind = "booleans" if arr.dtype == bool else f"dtype {arr.dtype}"
        raise TypeError(f"{name} must be an array of real numbers, got {kind}")
    if np.issubdtype(arr.dtype, np.complexfloating):
        raise TypeError(f"{name} must be real, got complex values")
    arr = arr.astype(float)
    if shape is not None:
        _check_shape(arr, shape, name)
    if not np.all(np.isfinite(arr)):
        bad = np.argwhere(~np.isfinite(arr))
        raise ValueError(f"{name} contains NaN or inf (first at index {tuple(int(i) for i in bad[0])})")
    return arr


def _first_non_real(value) -> tuple[str, object] | None:
    """The index (``"[2][0]"``, ``""`` for a scalar) and value of the first element of the nested lists,
    tuples or object array ``value`` that is not a real number (a string, bool, None, complex ...), else
    None. Numeric numpy arrays are left to the dtype check."""
    stack: list[tuple[str, object]] = [("", value)]
    while stack:
        where, v = stack.pop()
        if isinstance(v, (list, tuple)) or (isinstance(v, np.ndarray) and v.dtype == object):
            items = list(v) if not isinstance(v, np.ndarray) or v.ndim else [v.item()]
            stack.extend((f"{where}[{i}]", e) for i, e in reversed(list(enumerate(items))))
        elif isinstance(v, np.ndarray):
            continue
        elif isinstance(v, (bool, np.bool_)) or not isinstance(v, numbers.Real):
            return where, v
    return None


def as_index_array(value: ArrayLike, name: str, n: int | None = None,
                   shape: tuple[int | None, ...] | None = None) -> np.ndarray:
    """Return ``value`` as an int64 array of node indices, each in ``[0, n)`` when ``n`` is given.

    Integers only: a float array is refused even when every value is whole (``16.0``; a float index is
    usually a computed position, and ``16.9`` must never become 16), and so are booleans, also inside a
    list (``[True, 3]`` would read as ``[1, 3]``)."""
    if isinstance(value, (list, tuple)) and _holds_bool(value):
        raise TypeError(f"{name} must hold integer node indices, got a boolean")
    arr = np.asarray(value)
    if arr.size == 0:
        arr = arr.astype(np.int64)
    if arr.dtype == bool or not np.issubdtype(arr.dtype, np.integer):
        if np.issubdtype(arr.dtype, np.floating) and arr.size and np.all(np.isfinite(arr)) \
                and np.all(arr == np.round(arr)):
            raise TypeError(f"{name} must hold integers, got dtype {arr.dtype} (cast with .astype(int))")
        raise TypeError(f"{name} must hold integer node indices, got dtype {arr.dtype}")
    arr = arr.astype(np.int64)
    if shape is not None:
        _check_shape(arr, shape, name)
    if n is not None and arr.size:
        lo, hi = int(arr.min()), int(arr.max())
        if lo < 0 or hi >= n:
            bad = lo if lo < 0 else hi
            raise ValueError(f"{name} has node index {bad} out of range [0, {n})")
    return arr


def _holds_bool(value) -> bool:
    """Is there a bool (Python or numpy) anywhere in the nested lists/tuples ``value``?"""
    stack = [value]
    while stack:
        v = stack.pop()
        if isinstance(v, (list, tuple)):
            stack.extend(v)
        elif isinstance(v, (bool, np.bool_)):
            return True
    return False


def _first_non_integer(value):
    """The first boolean or float of a flat list or array (a non-whole one first for arrays), else None."""
    if isinstance(value, (list, tuple)):
        return next((v for v in value if isinstance(v, (bool, np.bool_, float, np.floating))), None)
    if isinstance(value, np.ndarray) and value.size:
        flat = value.reshape(-1)
        if flat.dtype == bool:
            return flat[0]
        if np.issubdtype(flat.dtype, np.floating):
            off = flat[~np.isfinite(flat) | (flat % 1 != 0)]
            return off[0] if len(off) else flat[0]
    return None


def node_indices(value, name: str, n: int | None = None) -> np.ndarray:
    """The one check of a list of node indices (anchors, drag nodes, a rigid drag's nodes): a 1-D int64
    array of integers, each in ``[0, n)`` when ``n`` is given, none named twice. A scalar integer is a list
    of one. A float is refused even when it is whole (``16.0``: a float index is usually a computed
    position, and ``16.9`` must never become 16); so are booleans and NaN.

    Raises
    ------
    TypeError
        Not integers (floats, booleans, strings); the message names the first bad value.
    ValueError
        Not one-dimensional, an index out of range, or a node named twice (the message names it).
    """
    if isinstance(value, (numbers.Integral, np.integer)) and not isinstance(value, (bool, np.bool_)):
        value = [value]
    bad = _first_non_integer(value)
    if isinstance(bad, (bool, np.bool_)):
        raise TypeError(f"{name}: node index {bool(bad)!r} is a boolean, not an integer")
    if bad is not None:
        whole = bool(np.isfinite(bad) and float(bad).is_integer())
        raise TypeError(f"{name}: node index {float(bad)!r} is not an integer" + (
            " (a float: node indices must be integers, cast with int())" if whole else ""))
    arr = as_index_array(value, name, n=n, shape=(None,))
    if len(arr) > 1:
        srt = np.sort(arr)
        dup = srt[1:][srt[1:] == srt[:-1]]
        if len(dup):
            raise ValueError(f"{name}: node {int(dup[0])} is repeated (give each node once)")
    return arr


#: Unicode categories refused in names that go into files: control characters (NUL, ESC, line feed, tab ...),
#: lone surrogates (not encodable as UTF-8) and the line and paragraph separators.
_BAD_CATEGORIES = ("Cc", "Cs", "Zl", "Zp")


def check_label(value, what: str) -> str:
    """A name written into files (a muscle's label in SVG, DXF and CSV; a pose's column): a string without
    control characters, lone surrogates or line breaks. Markup characters (``<``, ``&``, quotes) are allowed:
    the writers escape them.

    Raises ``TypeError`` for a non-string, ``ValueError`` naming the first bad character and its position.
    """
    if not isinstance(value, str):
        raise TypeError(f"{what} must be a string, got {type(value).__name__}")
    for i, ch in enumerate(value):
        if unicodedata.category(ch) in _BAD_CATEGORIES:
            raise ValueError(f"{what} {value!r} holds the control character U+{ord(ch):04X} at position {i}: "
                             "names go into files (SVG, DXF, CSV) and may hold no control characters or line "
                             "breaks")
    return value


#: Characters no file name may hold on some supported system (Windows refuses these).
_STEM_FORBIDDEN = '/\\<>:"|?*'


def check_stem(value, what: str = "name") -> str:
    """A file stem (``<stem>.svg``): a non-empty :func:`check_label` string with no path separator and no
    character a Windows file name refuses (``/ \\ < > : " | ? *``), not starting with a dot."""
    check_label(value, what)
    bad = next((c for c in value if c in _STEM_FORBIDDEN), None)
    if not value or value.startswith(".") or bad is not None:
        why = f"holds {bad!r}" if bad is not None else "is empty" if not value else "starts with a dot"
        raise ValueError(f"{what} must be a plain file stem (no folder, no path separator), got {value!r}: it {why}")
    return value


def _check_shape(arr: np.ndarray, shape: tuple[int | None, ...], name: str) -> None:
    want = "(" + ", ".join("k" if s is None else str(s) for s in shape) + ")"
    if arr.ndim != len(shape) or any(s is not None and s != a for s, a in zip(shape, arr.shape)):
        raise ValueError(f"{name} must have shape {want}, got {arr.shape}{_what_given(arr)}")


def _what_given(arr: np.ndarray) -> str:
    """What a value of the wrong shape was, beside its shape: a single number, or a short list's values."""
    if arr.ndim == 0:
        return f" (a single value, {arr.item()!r})"
    if arr.ndim == 1 and 0 < arr.size <= 4:
        return f" (the values {arr.tolist()})"
    return ""


def positive_float(value, name: str, allow_zero: bool = False) -> float:
    """A finite real scalar > 0 (or >= 0 with ``allow_zero``)."""
    if isinstance(value, bool) or not isinstance(value, numbers.Real):
        raise TypeError(f"{name} must be a real number, got {type(value).__name__}")
    v = float(value)
    if not np.isfinite(v):
        raise ValueError(f"{name} must be finite, got {v}")
    if v < 0 or (v == 0 and not allow_zero):
        raise ValueError(f"{name} must be {'>= 0' if allow_zero else '> 0'}, got {v}")
    return v


def friction_coefficient(value, name: str = "friction") -> float:
    """Coulomb's friction coefficient: a finite real number >= 0; ``ValueError`` naming ``name`` otherwise (a
    non-number too)."""
    if isinstance(value, bool) or not isinstance(value, numbers.Real) or not math.isfinite(float(value)) \
            or value < 0:
        raise ValueError(f"{name} must be a number >= 0 (Coulomb's coefficient), got {value!r}")
    return float(value)


def integer_range(lo: int | None = None, hi: int | None = None) -> str:
    """The words for an integer in ``[lo, hi]`` (either end open when None): ``"an integer >= 0"``,
    ``"an integer in 1..8"``, ...; the messages of :func:`check_int`."""
    if lo is None and hi is None:
        return "an integer"
    if hi is None:
        return f"an integer >= {lo}"
    return f"an integer <= {hi}" if lo is None else f"an integer in {lo}..{hi}"


def check_int(value, name: str, lo: int | None = None, hi: int | None = None) -> int:
    """The one check of an integer argument: a Python or numpy integer (not a bool, not a float that happens
    to be whole) within ``[lo, hi]`` (either end open when None), as an ``int``.

    Raises ``TypeError`` for a value that is not an integer, ``ValueError`` for one out of range, both naming
    ``name``.

    Example
    -------
    >>> check_int(3, "n_seeds", 1)
    3
    >>> check_int(0, "n_seeds", 1)
    Traceback (most recent call last):
    ...
    ValueError: n_seeds must be an integer >= 1, got 0
    """
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, numbers.Integral):
        raise TypeError(f"{name} must be an integer, got {type(value).__name__} {value!r}")
    v = int(value)
    if (lo is not None and v < lo) or (hi is not None and v > hi):
        raise ValueError(f"{name} must be {integer_range(lo, hi)}, got {v}")
    return v


def positive_int(value, name: str) -> int:
    """An integer >= 1 (not a bool, not a float that happens to be whole): :func:`check_int` worded for
    counts (``"must be a positive integer"``)."""
    v = check_int(value, name)
    if v < 1:
        raise ValueError(f"{name} must be a positive integer, got {v}")
    return v


def keyword_names(func: Callable) -> tuple[str, ...]:
    """The keyword-only parameters of ``func`` (those an ``options`` dict passed on as ``**options`` may
    name)."""
    return tuple(p.name for p in inspect.signature(func).parameters.values() if p.kind == p.KEYWORD_ONLY)


def did_you_mean(word, choices: Iterable[str], cutoff: float = 0.6) -> str:
    """``" (did you mean 'gecko'?)"`` naming the choice nearest to ``word`` (by :func:`difflib.get_close_matches`
    with ``cutoff``), or ``""`` when none is near: the one spelling of a near miss in every message."""
    close = difflib.get_close_matches(str(word), list(choices), n=1, cutoff=cutoff)
    return f" (did you mean {close[0]!r}?)" if close else ""


def unknown_key_hint(key, allowed: Iterable[str]) -> str:
    """The words after "unknown key": ``" (did you mean 'max_muscles'?)"`` for a near miss, else the list of
    the keys allowed."""
    allowed = sorted(allowed)
    return did_you_mean(key, allowed) or f" (allowed: {', '.join(allowed)})"


def check_options(options, allowed: Iterable[str], name: str) -> dict:
    """An options dict (``routing_options``, ``design_options`` ...) as a new ``dict``, None as ``{}``, checked
    before any work: a mapping whose keys are all in ``allowed``.

    Raises ``TypeError`` for a value that is not a mapping or a key that is not a string, ``ValueError`` for
    an unknown key, naming it with the nearest allowed key (``did you mean 'max_muscles'?``).
    """
    if options is None:
        return {}
    if not isinstance(options, Mapping):
        raise TypeError(f"{name} must be a dict, got {type(options).__name__}")
    allowed = set(allowed)
    for k in options:
        if not isinstance(k, str):
            raise TypeError(f"{name}: keys must be strings, got {type(k).__name__} {k!r}")
        if k not in allowed:
            raise ValueError(f"{name}: unknown key {k!r}{unknown_key_hint(k, allowed)}")
    return dict(options)
