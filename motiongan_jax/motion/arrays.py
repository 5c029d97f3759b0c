"""Array arguments checked at the boundary of the measures (motion.gait, evaluation.metrics): a wrong
rank or shape, an empty array or a NaN/inf raises ValueError naming the argument and the problem."""

from __future__ import annotations

import math

import numpy as np


def float_array(x, name: str, ndim: int, shape: tuple | None = None, min_len: int = 1) -> np.ndarray:
    """`x` as float64 of rank `ndim`; `shape` entries that are not None must match; the leading
    axis needs at least `min_len` entries; every value must be finite."""
    try:
        a = np.asarray(x, dtype=np.float64)
    except (TypeError, ValueError) as e:
        raise ValueError(f"{name}: not convertible to a float array ({e})") from None
    if a.ndim != ndim:
        raise ValueError(f"{name}: expected rank {ndim}, got shape {a.shape}")
    if shape is not None:
        for axis, want in enumerate(shape):
            if want is not None and a.shape[axis] != want:
                raise ValueError(f"{name}: axis {axis} must have size {want}, got shape {a.shape}")
    if a.size == 0:
        raise ValueError(f"{name}: empty array (shape {a.shape})")
    if a.shape[0] < min_len:
        raise ValueError(f"{name}: needs at least {min_len} entries along axis 0, got shape {a.shape}")
    if not np.all(np.isfinite(a)):
        raise ValueError(f"{name}: contains NaN or inf")
    return a


def int_array(x, name: str, ndim: int) -> np.ndarray:
    """`x` as int64 of rank `ndim`, non-empty; floats are accepted only if integer-valued."""
    a = np.asarray(x)
    if a.ndim != ndim:
        raise ValueError(f"{name}: expected rank {ndim}, got shape {a.shape}")
    if a.size == 0:
        raise ValueError(f"{name}: empty array (shape {a.shape})")
    if np.issubdtype(a.dtype, np.floating):
        if not np.all(np.isfinite(a)):
            raise ValueError(f"{name}: contains NaN or inf")
        if not np.all(a == np.round(a)):
            raise ValueError(f"{name}: expected integer values")
    elif not (np.issubdtype(a.dtype, np.integer) or a.dtype == bool):
        raise ValueError(f"{name}: expected integers, got dtype {a.dtype}")
    return a.astype(np.int64)


def same_len(a: np.ndarray, name_a: str, b: np.ndarray, name_b: str) -> None:
    if a.shape[0] != b.shape[0]:
        raise ValueError(f"{name_b}: length {b.shape[0]} does not match {name_a} ({a.shape[0]})")


def positive(value: float, name: str, allow_zero: bool = False) -> float:
    v = float(value)
    if not math.isfinite(v) or v < 0 or (v == 0 and not allow_zero):
        raise ValueError(f"{name}: must be {'>= 0' if allow_zero else '> 0'} and finite, got {value}")
    return v


def count(value: int, name: str, minimum: int) -> int:
    if isinstance(value, bool) or int(value) != value or value < minimum:
        raise ValueError(f"{name}: must be an integer >= {minimum}, got {value}")
    return int(value)
