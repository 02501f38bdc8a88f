"""Inputs to tensors: ``as_tensor`` and the checks every renderer module validates its inputs with.

Public functions accept numpy arrays, lists or tensors and return tensors that keep the input's dtype
(float32 by default, float64 everywhere supported) and device. ``as_tensor`` does the conversion once, at
the top of a function; the checks below raise an error that names the argument and says what is wrong, so a
user reads "K must have shape (3, 3), got (3, 4)" or "width must be a positive integer, got 8.5", not an
error from deep inside torch (or, worse, a silently wrong image).

The rules they enforce, the same in every module:

* ``dtype`` arguments are ``None`` or a floating ``torch.dtype`` (a string such as ``"float"`` is refused:
  ``TypeError``); ``device`` arguments are ``None``, a ``torch.device`` or a device string.
* Arrays of numbers hold real numbers (complex is refused: ``TypeError``); ``_check_shape`` and
  ``_check_finite`` refuse a wrong shape or NaN / inf (``ValueError``).
* Counts and sizes (``_check_count``: resolution, samples, subdivisions, width, height, ...) are Python or
  numpy integers, never bools and never floats, not even 2.0 (``ValueError``).
* Scalars (``_check_real``: near, far, radius, bias, ...) are real numbers, not bools or strings, finite
  unless infinity is allowed, in the stated range (``ValueError``).
* Face and other vertex indices (``_as_faces``) are integers, never floats (even integral ones: a float
  index is a bug upstream, and rounding it would hide the bug), within range (``TypeError`` for the dtype,
  ``ValueError`` for shape and range).
* Flags (``_check_flag``) are bools (numpy bools too), so ``cull_backfaces="no"`` is not silently true.
"""
from __future__ import annotations

import math
import numbers
import operator

import numpy as np
import torch

__all__ = ["as_tensor"]


def _check_dtype(dtype, name: str = "dtype"):
    """``dtype`` unchanged when it is None or a floating torch.dtype; else a TypeError naming ``name``."""
    if dtype is None:
        return None
    if not isinstance(dtype, torch.dtype):
        raise TypeError(f"{name} must be a torch.dtype such as torch.float32 or torch.float64, got {dtype!r}")
    if not dtype.is_floating_point:
        raise TypeError(f"{name} must be a floating torch.dtype such as torch.float32 or torch.float64, "
                        f"got {dtype}")
    return dtype


def _check_device(device, name: str = "device"):
    """``device`` as a torch.device (None stays None); a TypeError naming ``name`` when it is not one."""
    if device is None or isinstance(device, torch.device):
        return device
    try:
        return torch.device(device)
    except (RuntimeError, TypeError, ValueError) as err:
        raise TypeError(f"{name} must be a torch.device or a device string such as 'cpu' or 'cuda', "
                        f"got {device!r}") from err


def as_tensor(x, *, dtype=None, device=None, name: str = "input") -> torch.Tensor:
    """Turn ``x`` (tensor, numpy array, list) into a floating tensor, keeping a float dtype it already has.

    dtype: None (keep a float dtype; integers and bools become torch's default dtype) or a floating
    torch.dtype; device: None (keep) or a device. Raises TypeError naming ``name`` for something that is not
    an array of real numbers, and naming ``dtype`` / ``device`` for a wrong dtype or device.
    """
    dtype = _check_dtype(dtype)
    device = _check_device(device)
    if isinstance(x, torch.Tensor):
        t = x
    else:
        try:
            t = torch.as_tensor(x, dtype=dtype)                             # no float32 round trip
        except Exception as err:  # a ragged list, a string, ...
            raise TypeError(f"{name} must be a tensor or array of numbers, got {type(x).__name__}") from err
    if t.is_complex():
        raise TypeError(f"{name} must hold real numbers, got dtype {t.dtype}")
    if dtype is not None:
        t = t.to(dtype)
    elif not t.is_floating_point():
        t = t.to(torch.get_default_dtype())
    if device is not None:
        t = t.to(device)
    return t


def _shape_str(shape: tuple) -> str:
    """``(3,)``, ``(N, 3)``: a shape as Python writes it, None shown as N."""
    parts = ["N" if s is None else str(s) for s in shape]
    return "(" + ", ".join(parts) + ("," if len(parts) == 1 else "") + ")"


def _check_shape(x: torch.Tensor, shape: tuple, name: str) -> None:
    """Raise a ValueError naming ``name`` unless ``x.shape`` matches ``shape`` (None matches any size) and
    ``x`` is finite."""
    ok = x.dim() == len(shape) and all(s is None or s == d for s, d in zip(shape, x.shape))
    if not ok:
        raise ValueError(f"{name} must have shape {_shape_str(shape)}, got {tuple(x.shape)}")
    _check_finite(x, name)


def _check_finite(x: torch.Tensor, name: str, *, allow_inf: bool = False) -> None:
    """Raise a ValueError naming ``name`` where ``x`` holds NaN (or, unless ``allow_inf``, ±inf)."""
    if not x.is_floating_point():
        return
    x = x.detach()
    bad = torch.isnan(x) if allow_inf else ~torch.isfinite(x)
    if bool(bad.any()):
        raise ValueError(f"{name} contains NaN" + ("" if allow_inf else " or inf"))


def unit_scale(v: torch.Tensor, dim: int = -1) -> torch.Tensor:
    """v times the power of two that brings its largest |component| along ``dim`` into [0.5, 1) (detached; 1 for
    a zero vector). A power of two scales every later product, sum and square root exactly, so a direction
    computed from the result has the very bits it would have from v, unless v's squares overflow (|v| beyond
    ~1e154 in float64, ~1e19 in float32) or underflow, which they then no longer do."""
    _, e = torch.frexp(v.detach().abs().amax(dim, keepdim=True))
    return v * torch.ldexp(torch.ones_like(v.detach()), -e)


def unit(v: torch.Tensor, dim: int = -1) -> torch.Tensor:
    """``v / |v|`` along ``dim`` at any magnitude, bit for bit ``v / v.norm()`` wherever that one neither
    overflows nor underflows (``unit_scale``): a direction of norm 1e160 gave inf (and every shadow test after
    it failed), 1e-200 gave 0 ("a zero vector"). The gradient is that of v / |v|. A zero vector gives NaN:
    callers refuse it first (``_is_zero``)."""
    s = unit_scale(v, dim)
    return s / s.norm(dim=dim, keepdim=True)


def _is_zero(v: torch.Tensor) -> bool:
    """Whether every component of v is 0 (not ``v.norm() == 0``, which is also true of 1e-200)."""
    return not bool((v.detach() != 0).any())


def _check_count(value, name: str, *, minimum: int = 1, hint: str = "") -> int:
    """``value`` as a Python int >= ``minimum``: an int, numpy integer or integer 0-d tensor, never a bool
    and never a float (not even 2.0). Raises a ValueError naming ``name`` otherwise (``hint``: a few words
    after "must be a positive integer", such as " (texels per side)")."""
    what = "a positive integer" if minimum == 1 else (
        "a non-negative integer" if minimum == 0 else f"an integer >= {minimum}")
    what += hint
    if isinstance(value, (bool, np.bool_)) or (isinstance(value, torch.Tensor) and value.dtype == torch.bool):
        raise ValueError(f"{name} must be {what}, got the bool {value!r}")
    try:
        v = operator.index(value)
    except TypeError:
        raise ValueError(f"{name} must be {what}, got {value!r}") from None
    if v < minimum:
        raise ValueError(f"{name} must be {what}, got {v}")
    return int(v)


def _check_real(value, name: str, *, low=None, high=None, low_open: bool = False, high_open: bool = False,
                allow_inf: bool = False) -> float:
    """``value`` as a float: a real number (int, float, numpy scalar or one-element tensor), never a bool
    or a string, finite unless ``allow_inf``, in [low, high] (open ends with ``low_open`` / ``high_open``;
    None: unbounded). Raises a ValueError naming ``name`` otherwise."""
    if isinstance(value, torch.Tensor):
        if value.numel() != 1 or value.dtype == torch.bool or value.is_complex():
            raise ValueError(f"{name} must be a real number, got a tensor of shape {tuple(value.shape)} "
                             f"and dtype {value.dtype}")
        value = value.detach().reshape(()).item()
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, numbers.Real):
        raise ValueError(f"{name} must be a real number, got {value!r}")
    v = float(value)
    if math.isnan(v) or (math.isinf(v) and not allow_inf):
        raise ValueError(f"{name} must be a finite number, got {v}")
    if low is not None and (v < low or (low_open and v == low)):
        raise ValueError(f"{name} must be {'>' if low_open else '>='} {low:g}, got {v:g}")
    if high is not None and (v > high or (high_open and v == high)):
        raise ValueError(f"{name} must be {'<' if high_open else '<='} {high:g}, got {v:g}")
    return v


def _check_flag(value, name: str) -> bool:
    """``value`` as a bool: True / False (numpy bools too, and the integers 0 and 1); a ValueError naming
    ``name`` for anything else, so that a string such as "no" is never silently true."""
    if isinstance(value, (bool, np.bool_)):
        return bool(value)
    if isinstance(value, numbers.Integral) and value in (0, 1):
        return bool(value)
    raise ValueError(f"{name} must be True or False, got {value!r}")


def _as_index(x, name: str, *, device=None) -> torch.Tensor:
    """An int64 tensor of indices from a tensor, numpy array or list of integers. A float (even 2.0), bool or
    complex array is refused with a TypeError naming ``name``: an index must never be rounded."""
    if isinstance(x, torch.Tensor):
        t = x
    else:
        try:
            readonly = isinstance(x, np.ndarray) and not x.flags.writeable
            t = torch.as_tensor(np.array(x) if readonly else x)             # torch cannot share read-only memory
        except Exception as err:
            raise TypeError(f"{name} must be a tensor or array of integer indices, got {type(x).__name__}") \
                from err
    if t.dtype == torch.bool or t.is_floating_point() or t.is_complex():
        raise TypeError(f"{name} must hold integer indices, got dtype {t.dtype} (convert with .long() only if "
                        "every value is a whole number)")
    return t.to(device=device if device is not None else t.device, dtype=torch.int64)


def _as_faces(faces, name: str = "faces", *, num_verts: int | None = None, device=None,
              holder: str = "the mesh has {} vertices") -> torch.Tensor:
    """Faces (F, 3) int64 from integer indices, checked: dtype (TypeError), shape and range (ValueError),
    each message naming ``name``. ``num_verts``: the number of vertices the indices must stay below
    (``holder`` says what has them, in the message)."""
    f = _as_index(faces, name, device=device)
    if f.dim() != 2 or f.shape[1] != 3:
        raise ValueError(f"{name} must have shape (F, 3), got {tuple(f.shape)}")
    if f.numel():
        lo, hi = int(f.min()), int(f.max())
        if lo < 0:
            raise ValueError(f"{name} holds a negative vertex index ({lo})")
        if num_verts is not None and hi >= num_verts:
            raise ValueError(f"{name} index vertex {hi} but {holder.format(num_verts)}")
    return f
