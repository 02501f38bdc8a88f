"""Inputs to tensors: ``as_tensor`` and the generic shape check every renderer module validates with.

Public functions accept numpy arrays, lists or tensors and return tensors that keep the input's dtype
(float32 by default, float64 everywhere supported) and device. ``as_tensor`` does the conversion once, at
the top of a function; ``_check_shape`` raises a ``ValueError`` naming the argument when its shape is
wrong or it holds NaN / inf, so a user reads "K must have shape (3, 3), got (3, 4)", not an error from
deep inside torch.
"""
from __future__ import annotations

import torch

__all__ = ["as_tensor"]


def as_tensor(x, *, dtype=None, device=None, name: str = "input") -> torch.Tensor:
    """Turn ``x`` (tensor, numpy array, list) into a floating tensor, keeping a float dtype it already has."""
    if isinstance(x, torch.Tensor):
        t = x
    else:
        try:
            t = torch.as_tensor(x, dtype=dtype)                             # no float32 round trip
        except Exception as err:  # a ragged list, a string, ...
            raise TypeError(f"{name} must be a tensor or array of numbers, got {type(x).__name__}") from err
    if dtype is not None:
        t = t.to(dtype)
    elif not t.is_floating_point():
        t = t.to(torch.get_default_dtype())
    if device is not None:
        t = t.to(device)
    return t


def _check_shape(x: torch.Tensor, shape: tuple, name: str) -> None:
    """Raise a ValueError naming ``name`` unless ``x.shape`` matches ``shape`` (None matches any size)."""
    ok = x.dim() == len(shape) and all(s is None or s == d for s, d in zip(shape, x.shape))
    if not ok:
        want = "(" + ", ".join("N" if s is None else str(s) for s in shape) + ")"
        raise ValueError(f"{name} must have shape {want}, got {tuple(x.shape)}")
    if not torch.isfinite(x).all():
        raise ValueError(f"{name} contains NaN or inf")
