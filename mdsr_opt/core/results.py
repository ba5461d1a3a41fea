"""Conventions shared by the result objects: a short ``repr``, a JSON-ready ``to_dict`` and ``save``/``load``.

Result objects hold arrays of thousands of numbers; a dataclass's own ``repr`` prints all of them. The
helpers here give every result the same manners:

- :func:`compact_repr` writes ``Name(field=value, ...)`` with short 1-D numeric arrays (at most
  :data:`MAX_VALUES`: one value per muscle) as their values, like lists, other arrays as
  ``array(shape, dtype)``, long sequences as their length and floats to four significant digits;
- :func:`to_jsonable` turns arrays, numpy scalars, tuples, dataclasses and non-finite floats into what
  :func:`json.dumps` accepts (NaN and infinities become ``None``);
- :func:`save_fields` / :func:`load_fields` write a result holding states as one ``.npz`` file: every array
  field exactly (dtype and bits), the other fields as JSON metadata with a format tag, so that
  ``load(save(r))`` equals ``r`` and a damaged or foreign file is refused with a ``ValueError`` naming it.

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
import json
import math
import os
import tempfile
import zipfile
import zlib
from typing import Any, Callable, Mapping, Sequence

import numpy as np

from .errors import InputError

__all__ = ["compact_repr", "format_value", "one_line", "MAX_REPR", "WHY_CHARS", "to_jsonable", "plain", "save_npz", "load_npz",
           "save_fields", "load_fields"]

#: Longest ``repr`` a result object prints (one line).
MAX_REPR = 200

#: Longest reason a failed result's ``repr`` gives (:func:`compact_repr`'s ``why``).
WHY_CHARS = 90


class _Shown(str):
    """A field's text :func:`compact_repr` shows as it is (not cut to a value's 40 characters)."""

#: A 1-D numeric array of at most this many values (one per muscle, say) prints its values, a longer one
#: its shape: ``contractions=[0.1, 0.2, ...]`` for up to 16 muscles, ``x=array((54,), float64)`` for a state.
MAX_VALUES = 16


def one_line(text: Any, limit: int) -> str:
    """``text`` on one line and at most ``limit`` characters, cut cleanly: at a word, never inside brackets
    (an unclosed one is dropped with what follows it), with ``...`` where it was cut.

    >>> one_line("rejected (the boundary crosses itself) at load 0.5", 30)
    'rejected...'
    """
    text = " ".join(str(text).split())
    if len(text) <= limit:
        return text
    cut = text[:limit - 3]
    if " " in cut:
        cut = cut[:cut.rfind(" ")]
    while cut.count("(") > cut.count(")"):  # the last unclosed bracket and what follows it
        cut = cut[:cut.rfind("(")]
    return cut.rstrip(" ;:,(") + "..."


def format_value(value: Any, *, max_items: int = 6, max_chars: int = 60) -> str:
    """A short text for one field's value (see the module docstring)."""
    if isinstance(value, np.ndarray):
        if value.ndim == 1 and value.size <= MAX_VALUES and value.dtype.kind in "biuf":
            # per-muscle figures (contractions, strokes...): their values, as a list prints them
            return "[" + ", ".join(format_value(v) for v in value.tolist()) + "]"
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
        if 0 < len(value) <= MAX_VALUES and all(isinstance(v, (int, float, np.number)) and not isinstance(v, bool)
                                                for v in value):  # numbers, one per muscle: as an array
            inner = ", ".join(format_value(v) for v in value)
            return f"({inner}{',' if len(value) == 1 else ''})" if isinstance(value, tuple) else f"[{inner}]"
        if len(value) <= max_items and all(isinstance(v, (int, float, str, bool, np.number)) for v in value):
            inner = ", ".join(format_value(v) for v in value)
            text = f"({inner}{',' if len(value) == 1 else ''})" if isinstance(value, tuple) else f"[{inner}]"
            if len(text) <= max_chars:
                return text
        return f"<{len(value)} items>"
    text = repr(value)
    return text if len(text) <= max_chars else f"<{type(value).__name__}>"


def compact_repr(obj: Any, fields: Sequence[str], *, extra: Mapping[str, Any] | None = None, why: str = "",
                 why_name: str = "why", max_chars: int = MAX_REPR) -> str:
    """``TypeName(field=value, ...)`` over ``fields`` (then ``why``, then ``extra`` name/value pairs) with
    :func:`format_value`, one line of at most ``max_chars`` characters (the fields that do not fit are
    left out and ``...`` says so). ``why``: why the result is no success ("" when it is one), shown as
    ``<why_name>='...'`` on one line of at most :data:`WHY_CHARS` characters (:func:`one_line`), right after
    the ``success`` item (else after ``fields``), so that it is never the part left out."""
    items = [(name, getattr(obj, name)) for name in fields] + list((extra or {}).items())
    head, parts = f"{type(obj).__name__}(", []
    if str(why or "").strip():
        names = [name for name, _ in items]
        at = names.index("success") + 1 if "success" in names else len(fields)
        shown = _Shown(repr(one_line(why, WHY_CHARS)))
        items.insert(at, (why_name, shown))
    for name, value in items:
        text = (f"{name}={value}" if isinstance(value, _Shown) else
                f"{name}={format_value(value, max_chars=40)}").replace("\n", " ")
        if len(head) + len(", ".join(parts + [text])) + len(", ...)") > max_chars:
            parts.append("...")
            break
        parts.append(text)
    return head + ", ".join(parts) + ")"


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


# ---------------------------------------------------------------------------------------------- save / load
def plain(value: Any) -> Any:
    """``value`` as JSON types, exactly: numpy scalars as Python numbers, tuples as lists, dataclasses as
    dicts of their fields; NaN and infinities are KEPT (the metadata of :func:`save_npz` is read back by
    Python's :mod:`json`, which writes and reads them), arrays as nested lists."""
    if dataclasses.is_dataclass(value) and not isinstance(value, type):
        return {f.name: plain(getattr(value, f.name)) for f in dataclasses.fields(value)}
    if isinstance(value, dict):
        return {str(k): plain(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [plain(v) for v in value]
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, (bool, np.bool_)):
        return bool(value)
    if isinstance(value, (int, np.integer)):
        return int(value)
    if isinstance(value, (float, np.floating)):
        return float(value)
    return value


def save_npz(path: str | os.PathLike, kind: str, arrays: Mapping[str, np.ndarray], meta: Mapping) -> str:
    """Write ``arrays`` (exactly) and ``meta`` (:func:`plain`, as JSON) into one ``.npz`` file, atomically.
    ``path`` must end in ``.npz`` (a ``ValueError`` suggests one otherwise, e.g. ``out/design.npz`` for a folder).

    The file carries the format tag ``mdsr_opt.<kind>/1``; :func:`load_npz` checks it. Returns the path.
    """
    path = os.fspath(path)
    if not path.endswith(".npz"):
        stem, ext = os.path.splitext(path)
        like = os.path.join(path, f"{kind}.npz") if os.path.isdir(path) or not ext else stem + ".npz"
        raise ValueError(f"a {kind} result is saved as one .npz file: give a file name ending in .npz, e.g. "
                         f"{like!r} (got {path!r}; only a PipelineResult, which holds meshes too, is saved into "
                         "a folder)")
    if os.path.isdir(path):
        raise InputError(f"cannot write {path}: it is a folder")
    text = json.dumps({"format": f"mdsr_opt.{kind}/1", "arrays": sorted(arrays), "fields": plain(dict(meta))})
    payload = {f"a:{k}": np.asarray(v) for k, v in arrays.items()}
    for k, v in payload.items():
        if v.dtype.hasobject:
            raise TypeError(f"array field {k[2:]!r} holds Python objects; it cannot be saved exactly")
    folder = os.path.dirname(os.path.abspath(path))
    os.makedirs(folder, exist_ok=True)
    fd, tmp = tempfile.mkstemp(suffix=".npz", prefix=".tmp-", dir=folder)
    try:
        with os.fdopen(fd, "wb") as fh:
            np.savez(fh, __meta__=np.array(text), **payload)
        os.replace(tmp, path)
    finally:
        if os.path.lexists(tmp):
            os.remove(tmp)
    return path


def load_npz(path: str | os.PathLike, kind: str) -> tuple[dict, dict]:
    """The ``(arrays, meta)`` written by :func:`save_npz` with format ``mdsr_opt.<kind>/1``.

    Raises
    ------
    FileNotFoundError
        No such file.
    ValueError
        The file (named) is not a ``.npz`` written by :func:`save_npz`, is damaged (truncated, a bad
        checksum, an array missing), or holds another kind of result.
    """
    path = os.fspath(path)
    if not os.path.exists(path):
        raise FileNotFoundError(f"no such {kind} result file: {path}")
    if os.path.isdir(path):
        raise ValueError(f"{path} is a folder, not a {kind} result file: give the .npz file that save() wrote")
    try:
        loaded = np.load(path, allow_pickle=False)
        if not isinstance(loaded, np.lib.npyio.NpzFile):
            raise ValueError("a single .npy array, not an .npz archive")
        with loaded as z:
            if "__meta__" not in z.files:
                raise ValueError("no mdsr_opt metadata in the archive")
            head = json.loads(str(z["__meta__"][()]))
            if not isinstance(head, dict):
                raise ValueError("the metadata is not a JSON object")
            fmt = head.get("format")
            if fmt != f"mdsr_opt.{kind}/1":
                raise _Foreign(f"{path} is not a mdsr_opt {kind} result (format {fmt!r})")
            arrays = {name: z[f"a:{name}"] for name in head["arrays"]}
            meta = head["fields"]
    except _Foreign as exc:
        raise ValueError(str(exc)) from None
    except (OSError, ValueError, EOFError, KeyError, TypeError, zipfile.BadZipFile, zlib.error,
            RecursionError) as exc:  # RecursionError: metadata nested deeper than the JSON parser's stack
        raise ValueError(f"{path} is damaged or not a mdsr_opt {kind} result file: {exc}") from None
    if not isinstance(meta, dict):
        raise ValueError(f"{path} is damaged: its fields are not a JSON object")
    return arrays, meta


class _Foreign(Exception):
    pass


def save_fields(obj: Any, path: str | os.PathLike, kind: str, *, skip: Sequence[str] = (),
                extra_arrays: Mapping[str, np.ndarray] | None = None) -> str:
    """Save a dataclass result with :func:`save_npz`: array fields as arrays, the others as metadata.

    ``skip`` names fields left out (in memory only); ``extra_arrays`` are arrays stored under their own
    names (the class's ``load`` turns them back into fields). Returns the path."""
    arrays, meta = dict(extra_arrays or {}), {}
    for f in dataclasses.fields(obj):
        if f.name in skip:
            continue
        value = getattr(obj, f.name)
        if isinstance(value, np.ndarray):
            arrays[f.name] = value
        else:
            meta[f.name] = value
    return save_npz(path, kind, arrays, meta)


def load_fields(cls: type, path: str | os.PathLike, kind: str, *,
                convert: Mapping[str, Callable[[Any], Any]] | None = None,
                extra: Callable[[dict, dict], dict] | None = None) -> Any:
    """Read a result written by :func:`save_fields` back into ``cls``.

    ``convert`` maps a field name to a function turning its stored value back (tuples, nested
    dataclasses); ``extra(arrays, fields)`` may rebuild fields from ``extra_arrays``. Every failure to
    rebuild (a field missing, of the wrong kind) is a ``ValueError`` naming the file and the field.
    """
    arrays, meta = load_npz(path, kind)
    path = os.fspath(path)
    fields = {**meta, **arrays}
    names = {f.name for f in dataclasses.fields(cls)}
    name = "?"
    try:
        if extra is not None:
            fields = extra(arrays, fields)
        fields = {k: v for k, v in fields.items() if k in names}
        required = [f.name for f in dataclasses.fields(cls) if f.init and f.default is dataclasses.MISSING
                    and f.default_factory is dataclasses.MISSING]
        missing = [k for k in required if k not in fields]
        if missing:
            raise ValueError(f"field {missing[0]!r} is missing")
        for name, fn in (convert or {}).items():
            if name in fields and fields[name] is not None:
                fields[name] = fn(fields[name])
        name = "?"
        return cls(**fields)
    except (TypeError, ValueError, KeyError, IndexError, AttributeError) as exc:
        where = f" (field {name!r})" if name != "?" else ""
        raise ValueError(f"{path} is damaged{where}: {exc}") from None
