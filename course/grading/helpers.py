"""The helpers checks are written with: compare results, split points between cases, recognise mistakes.

``compare`` says how a result differs ("shape (3,) expected, got (1, 3)", "dtype float64 in, float32 out"),
``require`` turns that into a ``Fail``, and ``grade_parts`` splits a task's points between basic and stress
cases. ``_diagnose`` is ``compare`` plus the typical mistakes of a task, each written as the wrong result it
gives; ``_call`` runs the student's function on copies of the inputs, ``_ref`` imports the package's
reference when a check runs (so a fresh import is a fresh reference), and ``summarize_exception`` turns
what the student's code raised into one line that points at the student's own line.

The lecture modules (``lecture01`` ...) import from here and from ``registry``; nothing here imports them.
"""
from __future__ import annotations

import importlib
import math
import os
import re
import sysconfig
import traceback

import numpy as np
import torch

__all__ = ["Fail", "require", "generator", "grade_parts", "to_tensor", "compare", "summarize_exception"]


# ------------------------------------------------------------------------- helpers for writing checks

class Fail(Exception):
    """A check found a problem; the message is what the student reads."""


def require(message: str | None) -> None:
    """Raise ``Fail(message)`` unless ``message`` is None: ``require(compare(got, expected))``."""
    if message:
        raise Fail(message)


def generator(seed: int) -> torch.Generator:
    """A seeded CPU generator, so every check sees the same random inputs on every run."""
    return torch.Generator().manual_seed(seed)


_NUMBER = re.compile(r"[-+]?(?:\d+\.?\d*|\.\d+)(?:e[-+]?\d+)?")     # 3, -0.25, 1e-4 in a message


def grade_parts(*parts) -> tuple[int, str]:
    """Run ``(points, label, fn)`` parts; ``fn()`` passes by returning, fails by raising ``Fail``.

    An exception from the student's code fails that part only, with a one-line summary. A student who has
    not started (``NotImplementedError``) or whose code hangs stops the whole check (see ``run_check``).
    A diagnosis is said once per task: a second case failing with the same explanation, up to its numbers
    ("shape (4,) expected, got ()" and "shape (3,) expected, got ()"), adds nothing to the message.
    """
    earned, messages, seen = 0, [], set()
    for points, label, fn in parts:
        try:
            fn()
            earned += points
            continue
        except Fail as failure:
            message = str(failure)
            explanation = message.split(": ", 1)[-1]                      # "{case}: {explanation}"
        except NotImplementedError as exc:
            if _not_attempted(exc):
                raise
            explanation = summarize_exception(exc)
            message = f"{label}: {explanation}"
        except Exception as exc:                                           # the student's code raised
            explanation = summarize_exception(exc)
            message = f"{label}: {explanation}"
        key = _NUMBER.sub("#", explanation)                              # the same mistake is said once,
        if key not in seen:                                               # whatever the case's numbers
            seen.add(key)
            messages.append(message)
    return earned, "; ".join(messages)


def to_tensor(x, name: str = "result") -> torch.Tensor:
    """A student's result as a plain, detached tensor (numpy arrays accepted); ``Fail`` with a readable reason."""
    if x is None:
        raise Fail(f"{name} is None: did you forget to return it?")
    if isinstance(x, torch.Tensor):
        return x.as_subclass(torch.Tensor).detach() if type(x) is not torch.Tensor else x.detach()
    if isinstance(x, np.ndarray):
        if x.dtype == object:
            raise Fail(f"{name}: a numpy array of Python objects; return numbers")
        return torch.from_numpy(np.array(x, copy=True))
    if isinstance(x, (tuple, list)):
        raise Fail(f"{name}: expected a tensor, got a {type(x).__name__} of {len(x)} "
                   f"(stack it into one tensor{' or return fewer values' if isinstance(x, tuple) else ''})")
    raise Fail(f"{name}: expected a tensor or numpy array, got {type(x).__name__}")


def _shape(shape) -> str:
    return "(" + ", ".join(map(str, shape)) + ("," if len(shape) == 1 else "") + ")"


def _dtype(t: torch.Tensor) -> str:
    return str(t.dtype).replace("torch.", "")


def _index(flat: int, shape) -> str:
    idx = np.unravel_index(flat, tuple(shape)) if len(shape) else ()
    return str(int(idx[0])) if len(shape) == 1 else _shape([int(i) for i in idx])


def _num(v) -> str:
    v = float(v)
    return f"{v:.4g}" if math.isfinite(v) else str(v)


def _fmt(x) -> str:
    """A small tensor as a short list, for messages: [0, 0, 1.571]."""
    x = torch.as_tensor(x)
    if x.dim() == 0:
        return _num(x)
    return "[" + ", ".join(_fmt(row) for row in x) + "]"


def compare(got, expected, *, name: str = "result", atol: float | None = None, rtol: float | None = None,
            check_dtype: bool = True) -> str | None:
    """None when ``got`` matches ``expected``, else one line saying how it differs: type, shape, dtype,
    NaN/inf, or the largest error with its index. ``got`` may be a numpy array or a tensor. The default
    tolerance follows ``expected``'s dtype: 1e-4 (float32), 1e-9 (float64); booleans and integers must match
    exactly."""
    expected = expected.detach() if isinstance(expected, torch.Tensor) else torch.as_tensor(expected)
    try:
        got = to_tensor(got, name)
    except Fail as failure:
        return str(failure)
    if tuple(got.shape) != tuple(expected.shape):
        return f"{name}: shape {_shape(expected.shape)} expected, got {_shape(got.shape)}"
    if check_dtype and got.dtype != expected.dtype:
        if expected.is_floating_point() and got.is_floating_point():
            return f"{name}: dtype {_dtype(expected)} in, {_dtype(got)} out (keep the input's dtype)"
        return f"{name}: dtype {_dtype(expected)} expected, got {_dtype(got)}"
    got = got.to(expected.device)
    if not expected.is_floating_point():
        return _compare_exact(got, expected, name)
    return _compare_float(got.to(torch.float64), expected.to(torch.float64), name, expected.dtype, atol, rtol)


def _compare_exact(got, expected, name) -> str | None:
    if expected.dtype == torch.bool and got.dtype != torch.bool:
        got = got != 0
    if got.is_floating_point() and not expected.is_floating_point():
        got = got.round().to(expected.dtype)
    wrong = (got != expected).flatten()
    if not wrong.any():
        return None
    first = int(wrong.nonzero()[0])
    g, e = got.flatten()[first].item(), expected.flatten()[first].item()
    return (f"{name}: {int(wrong.sum())} of {wrong.numel()} values differ (first at index "
            f"{_index(first, expected.shape)}: got {g}, expected {e})")


def _compare_float(g, e, name, dtype, atol, rtol) -> str | None:
    low = dtype in (torch.float16, torch.bfloat16, torch.float32)
    atol = (1e-4 if low else 1e-9) if atol is None else atol
    rtol = (1e-4 if low else 1e-9) if rtol is None else rtol
    for what, bad_got, bad_exp in (("NaN", g.isnan(), e.isnan()), ("inf", g.isinf(), e.isinf())):
        extra = (bad_got & ~bad_exp).flatten()
        if extra.any():
            first = int(extra.nonzero()[0])
            return (f"{name}: {what} at {int(extra.sum())} of {extra.numel()} entries "
                    f"(first at index {_index(first, e.shape)})")
    same = (g == e) | (g.isnan() & e.isnan())                              # equal infs and NaNs match
    err = torch.where(same, torch.zeros_like(g), (g - e).abs()).nan_to_num(nan=math.inf)
    excess = (err - (atol + rtol * e.abs().nan_to_num(posinf=0.0))).flatten()
    if not (excess > 0).any():
        return None
    first = int(torch.where(excess > 0, err.flatten(), -1.0).argmax())
    as_float32 = bool((g == g.to(torch.float32).to(torch.float64)).all())  # every value rounded to float32
    plain = bool((g * 1024 == (g * 1024).round()).all())                # 0, 1, 0.5, ...: no evidence
    lost = not low and as_float32 and not plain and float(err.max()) < 1e-3
    hint = " (float64 in: compute in float64)" if lost else ""
    return (f"{name}: wrong values at {int((excess > 0).sum())} of {excess.numel()} entries; largest error "
            f"{_num(err.flatten()[first])} at index {_index(first, e.shape)} (got {_num(g.flatten()[first])}, "
            f"expected {_num(e.flatten()[first])}){hint}")


def _close(got, expected, tol: float = 1e-4) -> bool:
    """Loose float comparison used to recognise a typical mistake (not for scoring)."""
    try:
        g, e = to_tensor(got).to(torch.float64), torch.as_tensor(expected).to(torch.float64)
    except Fail:
        return False
    return g.shape == e.shape and bool(torch.allclose(g, e, atol=tol, rtol=tol))


def _unpack(out, names: tuple[str, ...], fn: str):
    """A student's tuple result, or ``Fail`` naming what was expected: "look_at should return (R, t)"."""
    want = "(" + ", ".join(names) + ")"
    if not isinstance(out, (tuple, list)):
        raise Fail(f"{fn} should return a tuple {want}, got {type(out).__name__}")
    if len(out) != len(names):
        raise Fail(f"{fn} should return {len(names)} values {want}, got {len(out)}")
    return [to_tensor(value, f"{fn} {name}") for value, name in zip(out, names)]


_LIBRARY_DIRS = tuple({os.path.realpath(p) for key, p in sysconfig.get_paths().items()
                       if key in ("stdlib", "platstdlib", "purelib", "platlib")}
                      | {os.path.dirname(os.path.dirname(os.path.realpath(__file__)))})   # course/


def _match(got, variants, tol: float = 1e-6) -> str | None:
    """The explanation of the first ``(alternative, explanation)`` in ``variants`` whose alternative has
    ``got``'s shape and is close to it (a typical mistake recognised by the wrong result it gives), else None."""
    for alternative, explanation in variants:
        if alternative is not None and got.shape == alternative.shape and _close(got, alternative, tol):
            return explanation
    return None


def _is_library(filename: str) -> bool:
    return os.path.realpath(filename).startswith(_LIBRARY_DIRS) or filename.startswith("<frozen")


def _frames(exc: BaseException) -> list[tuple[str, int, str, str, bool]]:
    """(file, line number, function, line, in a library?) of each frame of ``exc``'s traceback; for an exception
    raised in the student's process (``remote.RemoteError``), the frames that process reported."""
    remote = getattr(exc, "remote_frames", None)
    if remote:
        return [(str(f[0]), int(f[1]), str(f[2]), str(f[3]), bool(f[4])) for f in remote]
    return [(f.filename, f.lineno, f.name, f.line or "", _is_library(f.filename))
            for f in traceback.extract_tb(exc.__traceback__)]


def _student_frame(exc: BaseException):
    """The innermost traceback frame in the student's code (not the package, torch or the standard library)."""
    frames = [f for f in _frames(exc) if not f[4]]
    return frames[-1] if frames else None


def _not_attempted(exc: BaseException) -> bool:
    """True for the exercise's own ``raise NotImplementedError()``, not one from deep inside a library."""
    frames = _frames(exc)
    if not frames or frames[-1][4]:
        return False
    return "NotImplementedError" in (frames[-1][3] or "NotImplementedError")


def summarize_exception(exc: BaseException) -> str:
    """One line: ``ValueError: shapes do not match (line 3 in rodrigues: `return K @ w`)``."""
    text = " ".join(str(exc).split())
    text = re.sub(r"0x[0-9a-fA-F]+", "0x…", text)                           # no memory addresses in outputs
    text = f"{type(exc).__name__}: {text[:200]}" if text else type(exc).__name__
    frame = _student_frame(exc)
    if frame is not None and frame[3]:
        text += f" (line {frame[1]} in {frame[2]}: `{frame[3].strip()[:80]}`)"
    return text


def _ref(module: str, name: str):
    """A reference implementation, imported when a check runs (so a fresh import is a fresh reference)."""
    try:
        return getattr(importlib.import_module(module), name)
    except (ImportError, AttributeError) as err:
        raise RuntimeError(f"grader error: reference {module}.{name} is not available ({err})") from None


# ------------------------------------------------------------------------- typical mistakes, recognised

def _diagnose(got, expected, name: str, variants=(), *, check_dtype: bool = False, **tol) -> str | None:
    """``compare``, and when it fails, the first ``(alternative, explanation)`` that ``got`` matches instead."""
    message = compare(got, expected, name=name, check_dtype=check_dtype, **tol)
    if message is None:
        return None
    for alternative, explanation in variants:
        if _close(got, alternative) and not _close(expected, alternative):
            return f"{name}: {explanation}"
    return message


def _call(impl, *args):
    """Call the student's function on copies, so an in-place edit can't change the reference's inputs."""
    return impl(*(a.clone() if isinstance(a, torch.Tensor) else a for a in args))
