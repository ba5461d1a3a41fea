"""Conventions shared by the result objects: a short ``repr`` and a JSON-ready ``to_dict``.

Result objects hold arrays of thousands of numbers; a dataclass's own ``repr`` prints all of them. The
helpers here give every result the same manners:

- :func:`compact_repr` writes ``Name(field=value, ...)`` with arrays as ``array(shape, dtype)``, long
  sequences as their length and floats to four significant digits;
- :func:`to_jsonable` turns arrays, numpy scalars, tuples, dataclasses and non-finite floats into what
  :func:`json.dumps` accepts (NaN and infinities become ``None``).

Example
-------
>>> import numpy as np
>>> from dataclasses import dataclass
>>> @dataclass
... class R:
...     x: np.ndarray
...     error: float
>>> compact_repr(R(np.zeros((500, 2)), 1.234567e-9), ("x", "error"))
'R(x=array((500, 2), float64), error=1.235e-09)'
>>> to_jsonable({"x": np.arange(3), "e": float("nan"), "t": (1, np.float64(2.5))})
{'x': [0, 1, 2], 'e': None, 't': [1, 2.5]}
"""

from __future__ import annotations

import dataclasses
import math
from typing import Any, Sequence

import numpy as np

__all__ = ["compact_repr", "format_value", "to_jsonable"]


def format_value(value: Any, *, max_items: int = 6, max_chars: int = 60) -> str:
    """A short text for one field's value (see the module docstring)."""
    if isinstance(value, np.ndarray):
        if value.size <= max_items and value.ndim <= 1:
            return np.array2string(value, precision=4, separator=", ")
        return f"array({tuple(value.shape)}, {value.dtype})"
    if isinstance(value, (bool, np.bool_)):
        return repr(bool(value))
    if isinstance(value, (float, np.floating)):
        return f"{float(value):.4g}"
    if isinstance(value, (int, np.integer)):
        return str(int(value))
    if isinstance(value, str):
        text = repr(value)
        return text if len(text) <= max_chars else text[: max_chars - 4] + "...'"
    if isinstance(value, dict):
        return f"{{{len(value)} keys}}" if len(repr(value)) > max_chars else repr(value)
    if isinstance(value, (list, tuple)):
        if len(value) <= max_items and all(isinstance(v, (int, float, str, bool, np.number)) for v in value):
            inner = ", ".join(format_value(v) for v in value)
            text = f"({inner}{',' if len(value) == 1 else ''})" if isinstance(value, tuple) else f"[{inner}]"
            if len(text) <= max_chars:
                return text
        return f"<{len(value)} items>"
    text = repr(value)
    return text if len(text) <= max_chars else f"<{type(value).__name__}>"


def compact_repr(obj: Any, fields: Sequence[str]) -> str:
    """``TypeName(field=value, ...)`` over ``fields`` with :func:`format_value`."""
    parts = ", ".join(f"{name}={format_value(getattr(obj, name))}" for name in fields)
    return f"{type(obj).__name__}({parts})"


def to_jsonable(value: Any) -> Any:
    """``value`` with arrays, numpy scalars, tuples and dataclasses made JSON-ready; NaN and inf become None."""
    if dataclasses.is_dataclass(value) and not isinstance(value, type):
        to_dict = getattr(value, "to_dict", None)
        if callable(to_dict):
            return to_jsonable(to_dict())
        return {f.name: to_jsonable(getattr(value, f.name)) for f in dataclasses.fields(value)}
    if isinstance(value, dict):
        return {str(k): to_jsonable(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [to_jsonable(v) for v in value]
    if isinstance(value, np.ndarray):
        return to_jsonable(value.tolist())
    if isinstance(value, (bool, np.bool_)):
        return bool(value)
    if isinstance(value, (int, np.integer)):
        return int(value)
    if isinstance(value, (float, np.floating)):
        v = float(value)
        return v if math.isfinite(v) else None
    return value
