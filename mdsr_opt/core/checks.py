"""Argument checks shared by every stage: arrays of the right shape, positive numbers, indices."""

from __future__ import annotations

import numbers
import numpy as np
from numpy.typing import ArrayLike

__all__ = ['as_float_array', 'as_index_array', 'positive_float', 'positive_int']


def as_float_array(value: ArrayLike, name: str, shape: tuple[int | None, ...] | None = None) -> np.ndarray:
    """Return ``value`` as a finite float array, raising ``TypeError``/``ValueError`` naming ``name``."""
    try:
        arr = np.asarray(value)
    except Exception as exc:  # pragma: no cover - exotic inputs
        raise TypeError(f"{name} must be array-like of numbers: {exc}") from None
    if arr.dtype == object or not (np.issubdtype(arr.dtype, np.number) or arr.dtype == bool):
        raise TypeError(f"{name} must be an array of numbers, got dtype {arr.dtype}")
    if np.issubdtype(arr.dtype, np.complexfloating):
        raise TypeError(f"{name} must be real, got complex values")
    arr = arr.astype(float)
    if shape is not None:
        _check_shape(arr, shape, name)
    if not np.all(np.isfinite(arr)):
        bad = np.argwhere(~np.isfinite(arr))
        raise ValueError(f"{name} contains NaN or inf (first at index {tuple(int(i) for i in bad[0])})")
    return arr


def as_index_array(value: ArrayLike, name: str, n: int | None = None,
                   shape: tuple[int | None, ...] | None = None) -> np.ndarray:
    """Return ``value`` as an int64 array of node indices, each in ``[0, n)`` when ``n`` is given."""
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


def _check_shape(arr: np.ndarray, shape: tuple[int | None, ...], name: str) -> None:
    want = "(" + ", ".join("k" if s is None else str(s) for s in shape) + ")"
    if arr.ndim != len(shape) or any(s is not None and s != a for s, a in zip(shape, arr.shape)):
        raise ValueError(f"{name} must have shape {want}, got {arr.shape}")


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


def positive_int(value, name: str) -> int:
    """An integer >= 1 (not a bool, not a float that happens to be whole)."""
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, numbers.Integral):
        raise TypeError(f"{name} must be an integer, got {type(value).__name__} {value!r}")
    if value < 1:
        raise ValueError(f"{name} must be a positive integer, got {value}")
    return int(value)
