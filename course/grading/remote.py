"""Calls across a process boundary in plain data: how the grader calls a student's function it never runs itself.

The grader (the trusted side) and the worker that runs a student's notebook (``worker.py``) are two processes joined
by a pair of pipes, each holding an ``Endpoint``. Either side can call a function that lives on the other: the
arguments go out as plain data, the function runs where it lives, and its result comes back as plain data. Nothing
that crosses can carry code: the format (``encode`` / ``decode``) is a JSON tree plus raw buffers, and knows

    None, bool, int, float, complex, str, bytes        as themselves
    list, tuple, dict, torch.Size, slice               rebuilt from their items
    torch.Tensor, numpy arrays and numpy scalars       dtype, shape and the raw bytes (numeric dtypes only)
    torch.dtype, torch.device, torch.Generator         by name, by name, by its state
    a course record (a Mesh, a Camera, a grading       its class's name and its fields; rebuilt only as a class
      helper's plain object)                           already imported on the receiving side, never by importing
    a callable, an optimizer                           a handle: the receiver gets a proxy whose calls come back
                                                       to run where the object lives
    anything else                                      an ``Opaque`` that carries only its type's name

so a result the student's code returns is, on the grader's side, tensors and numbers and nothing that runs. Nothing
is unpickled. A message larger than ``MAX_MESSAGE`` bytes or nested deeper than ``MAX_DEPTH`` is refused.

**Autograd across the pipe.** A check may ask whether a gradient reaches the inputs (``out.requires_grad``,
``torch.autograd.grad(out, inputs)``), and a student's function may call back a render function of the grader's
and backpropagate through it (task 10.3) or step the grader's optimizer (13.4). A call made while autograd records
goes through ``_Bridge``, a ``torch.autograd.Function``: on the far side the tensors that required a gradient
become leaves, the function runs, and its graph is kept under a number; the outputs that require a gradient come
back attached to the ``_Bridge`` node, whose backward sends the incoming gradients over, lets the far side run its
own backward (which accumulates into its own leaves: the grader's parameters), and returns the leaves' gradients.
So the gradient a check reads is computed by the code that computed the value, as in one process.

**Time.** ``Endpoint.deadline`` (a ``time.monotonic()`` value) bounds every wait for the other side: when it passes,
``CheckTimeout`` is raised in the grader, which then ends the worker from outside (``sandbox.py``); a student's
``except:`` cannot swallow it, since it never reaches the student's process. ``PeerGone`` is raised when the other
side has died (its pipe closed).

What stays true whatever the student's process does: the grader decodes only the data above, calls only the
objects it exported itself, and computes every expected value and every comparison in its own process.
"""
from __future__ import annotations

import builtins
import dataclasses
import itertools
import json
import math
import os
import re
import select
import struct
import sys
import time
import traceback
import types

import numpy as np
import torch

from .registry import CheckTimeout, PeerGone

__all__ = ["Endpoint", "RemoteFunction", "RemoteError", "PeerGone", "Opaque", "encode", "decode", "MAX_MESSAGE",
           "MAX_DEPTH", "exception_record", "rebuild_exception"]

MAX_MESSAGE = 1 << 30            # bytes in one message (a 128 M-entry float64 tensor): more is refused
MAX_DEPTH = 60                   # nesting of lists, tuples, dicts and records
_HEADER = struct.Struct("<Q")    # every frame: its length, then its bytes

_DTYPES = {str(d).replace("torch.", ""): d for d in (
    torch.float16, torch.bfloat16, torch.float32, torch.float64, torch.complex64, torch.complex128, torch.uint8,
    torch.int8, torch.int16, torch.int32, torch.int64, torch.bool)}
_NUMPY_KINDS = set("biufc")      # bool, signed, unsigned, float, complex: numpy dtypes that carry no objects

# methods a proxy may call on an object of the grader's that is not a plain function; anything else is refused
_METHODS = {torch.optim.Optimizer: ("zero_grad", "step"),
            torch.nn.Module: ("__call__", "forward", "zero_grad", "train", "eval")}


class RemoteError(Exception):
    """An exception raised on the other side, rebuilt here: its class name and message, and the frames of the
    other side's traceback (``remote_frames``) so that messages can point at the student's line."""
    remote_frames: list = []
    remote_not_attempted = False


@dataclasses.dataclass(frozen=True)
class Opaque:
    """A value of a type the format does not carry (a generator, an object of the student's class): its type's
    name only."""
    type_name: str

    def __repr__(self):
        return f"<{self.type_name} object>"


# ------------------------------------------------------------------------------------------ the format

def _tensor_bytes(t: torch.Tensor) -> bytes:
    t = t.detach().resolve_conj().resolve_neg()
    if t.layout != torch.strided:
        t = t.to_dense()
    t = t.to("cpu").contiguous()
    if t.dtype == torch.bfloat16:
        t = t.view(torch.int16)
    return t.numpy().tobytes() if t.numel() else b""


def _tensor_from(data: bytes, dtype: torch.dtype, shape) -> torch.Tensor:
    if not math.prod(shape):
        return torch.empty(shape, dtype=dtype)
    flat = torch.frombuffer(bytearray(data), dtype=torch.uint8)
    expected = math.prod(shape) * torch.empty((), dtype=dtype).element_size()
    if flat.numel() != expected:
        raise ValueError(f"a tensor of shape {tuple(shape)} and dtype {dtype} needs {expected} bytes, got "
                         f"{flat.numel()}")
    return flat.view(dtype).reshape(shape).clone()


def _is_record(value) -> bool:
    """A plain object of the course's own (a dataclass or an object with a ``__dict__``) sent field by field."""
    cls = type(value)
    module = getattr(cls, "__module__", "") or ""
    return ((module == "course" or module.startswith("course.")) and not callable(value)
            and (dataclasses.is_dataclass(value) or hasattr(value, "__dict__")))


def _exportable(value):
    """(kind, methods) for an object that is sent as a handle, else None."""
    for cls, methods in _METHODS.items():
        if isinstance(value, cls):
            return "object", methods
    if callable(value) and not isinstance(value, type):
        return "function", ("__call__",)
    return None


class _Encoder:
    """One message's tree: ``tensors`` lists every tensor met, in order (their bytes become buffers)."""

    def __init__(self, endpoint: "Endpoint | None"):
        self.endpoint, self.buffers, self.tensors, self.size = endpoint, [], [], 0

    def buffer(self, data: bytes) -> int:
        self.size += len(data)
        if self.size > MAX_MESSAGE:
            raise ValueError(f"a message over {MAX_MESSAGE >> 20} MB: the result is too large to send")
        self.buffers.append(data)
        return len(self.buffers) - 1

    def encode(self, value, depth: int = 0):
        if depth > MAX_DEPTH:
            raise ValueError(f"a value nested more than {MAX_DEPTH} levels deep")
        if value is None or type(value) in (bool, str):
            return value
        if isinstance(value, str):
            return str(value)
        if isinstance(value, int) and not isinstance(value, bool):
            value = int(value)
            return value if abs(value) < 2 ** 63 else {"$": "bigint", "v": str(value)}
        if isinstance(value, float) and not isinstance(value, np.generic):
            value = float(value)
            return value if math.isfinite(value) else {"$": "float", "v": repr(value)}
        if type(value) is complex:
            return {"$": "complex", "re": self.encode(value.real), "im": self.encode(value.imag)}
        if isinstance(value, torch.Tensor):
            t = value.as_subclass(torch.Tensor) if type(value) is not torch.Tensor else value
            if str(t.dtype).replace("torch.", "") not in _DTYPES:
                return {"$": "opaque", "type": f"tensor of dtype {t.dtype}"}
            if t.numel() * t.element_size() + self.size > MAX_MESSAGE:          # refused before it is copied
                raise ValueError(f"a message over {MAX_MESSAGE >> 20} MB: the result is too large to send")
            self.tensors.append(t)
            return {"$": "tensor", "i": len(self.tensors) - 1, "dtype": str(t.dtype).replace("torch.", ""),
                    "shape": list(t.shape), "b": self.buffer(_tensor_bytes(t)), "grad": bool(t.requires_grad)}
        if isinstance(value, np.ndarray) or isinstance(value, np.generic):
            array = np.asarray(value)
            if array.dtype.kind not in _NUMPY_KINDS:
                return {"$": "opaque", "type": f"numpy array of {array.dtype}"}
            kind = "ndarray" if isinstance(value, np.ndarray) else "npscalar"
            return {"$": kind, "dtype": array.dtype.str, "shape": list(array.shape),
                    "b": self.buffer(np.ascontiguousarray(array).tobytes())}
        if isinstance(value, torch.Size):
            return {"$": "size", "v": [int(n) for n in value]}
        if type(value) in (list, tuple):
            items = [self.encode(v, depth + 1) for v in value]
            return items if type(value) is list else {"$": "tuple", "v": items}
        if type(value) is dict:
            return {"$": "dict", "k": [self.encode(k, depth + 1) for k in value],
                    "v": [self.encode(v, depth + 1) for v in value.values()]}
        if type(value) is bytes:
            return {"$": "bytes", "b": self.buffer(value)}
        if isinstance(value, torch.dtype):
            return {"$": "dtype", "v": str(value).replace("torch.", "")}
        if isinstance(value, torch.device):
            return {"$": "device", "v": str(value)}
        if isinstance(value, torch.Generator):
            return {"$": "generator", "b": self.buffer(_tensor_bytes(value.get_state()))}
        if type(value) is slice:
            return {"$": "slice", "v": [self.encode(v, depth + 1) for v in (value.start, value.stop, value.step)]}
        if value is Ellipsis:
            return {"$": "ellipsis"}
        if isinstance(value, Opaque):
            return {"$": "opaque", "type": value.type_name}
        if isinstance(value, (RemoteFunction, RemoteObject)) and value._endpoint is self.endpoint:
            return {"$": "yours", "h": value._handle}                     # a proxy going home: its own object
        if _is_record(value):
            cls = type(value)
            fields = (value.__dict__ if hasattr(value, "__dict__")
                      else {f.name: getattr(value, f.name) for f in dataclasses.fields(value)})
            return {"$": "record", "module": cls.__module__, "qualname": cls.__qualname__,
                    "f": {str(k): self.encode(v, depth + 1) for k, v in fields.items()}}
        exported = _exportable(value) if self.endpoint is not None else None
        if exported:
            kind, methods = exported
            handle = self.endpoint.export(value, methods)
            return {"$": kind, "h": handle, "name": _name_of(value), "methods": list(methods)}
        return {"$": "opaque", "type": _name_of(type(value))}


def _name_of(value) -> str:
    name = getattr(value, "__qualname__", None) or getattr(value, "__name__", None) or type(value).__name__
    return re.sub(r"[^\w.<>]", "_", str(name))[:80]


class _Decoder:
    """Rebuilds a tree; ``trusted`` (the grader's side) rebuilds records only of classes already imported."""

    def __init__(self, endpoint: "Endpoint | None", buffers: list, trusted: bool):
        self.endpoint, self.buffers, self.trusted, self.tensors = endpoint, buffers, trusted, {}

    def decode(self, node, depth: int = 0):
        if depth > MAX_DEPTH:
            raise ValueError(f"a value nested more than {MAX_DEPTH} levels deep")
        if node is None or isinstance(node, (bool, int, float, str)):
            return node
        if isinstance(node, list):
            return [self.decode(v, depth + 1) for v in node]
        if not isinstance(node, dict):
            raise ValueError(f"not a value of the format: {type(node).__name__}")
        kind = node.get("$")
        if kind == "tensor":
            dtype = _DTYPES[node["dtype"]]
            shape = [int(n) for n in node["shape"]]
            if dtype == torch.bfloat16:
                t = _tensor_from(self.buffers[node["b"]], torch.int16, shape).view(torch.bfloat16)
            else:
                t = _tensor_from(self.buffers[node["b"]], dtype, shape)
            self.tensors[int(node["i"])] = (t, bool(node.get("grad")))
            return t
        if kind in ("ndarray", "npscalar"):
            dtype = np.dtype(node["dtype"])
            if dtype.kind not in _NUMPY_KINDS:
                raise ValueError(f"numpy dtype {dtype} is not plain data")
            array = np.frombuffer(self.buffers[node["b"]], dtype=dtype).reshape(node["shape"]).copy()
            return array if kind == "ndarray" else array[()]
        if kind == "tuple":
            return tuple(self.decode(v, depth + 1) for v in node["v"])
        if kind == "dict":
            return {self._key(self.decode(k, depth + 1)): self.decode(v, depth + 1)
                    for k, v in zip(node["k"], node["v"])}
        if kind == "size":
            return torch.Size([int(n) for n in node["v"]])
        if kind == "bigint":
            return int(node["v"])
        if kind == "float":
            return float(node["v"])
        if kind == "complex":
            return complex(float(self.decode(node["re"])), float(self.decode(node["im"])))
        if kind == "bytes":
            return bytes(self.buffers[node["b"]])
        if kind == "dtype":
            return _DTYPES[node["v"]]
        if kind == "device":
            return torch.device(str(node["v"]))
        if kind == "generator":
            g = torch.Generator()
            g.set_state(_tensor_from(self.buffers[node["b"]], torch.uint8, [len(self.buffers[node["b"]])]))
            return g
        if kind == "slice":
            return slice(*(self.decode(v, depth + 1) for v in node["v"]))
        if kind == "ellipsis":
            return Ellipsis
        if kind == "opaque":
            return Opaque(str(node["type"])[:120])
        if kind == "yours":
            return self.endpoint.exported(int(node["h"]))
        if kind == "record":
            return self._record(node, depth)
        if kind in ("function", "object"):
            methods = tuple(str(m) for m in node.get("methods", ()))
            cls = RemoteFunction if kind == "function" else RemoteObject
            return cls(self.endpoint, int(node["h"]), str(node.get("name", "?"))[:80], methods)
        raise ValueError(f"not a value of the format: {kind!r}")

    @staticmethod
    def _key(key):
        if isinstance(key, (list, dict, torch.Tensor, np.ndarray)):
            raise ValueError("a dict key that is not hashable plain data")
        return key

    def _record(self, node, depth):
        module, qualname = str(node["module"]), str(node["qualname"])
        fields = {str(k): self.decode(v, depth + 1) for k, v in node["f"].items()}
        cls = None
        if module == "course" or module.startswith("course."):
            source = sys.modules.get(module)
            if source is None and not self.trusted:
                import importlib
                source = importlib.import_module(module)
            cls = source
            for part in qualname.split("."):
                cls = getattr(cls, part, None) if cls is not None else None
        if not isinstance(cls, type) or cls.__module__ != module:
            return types.SimpleNamespace(**fields)                        # a class this side does not have
        obj = cls.__new__(cls)
        for name, value in fields.items():
            object.__setattr__(obj, name, value)                          # frozen dataclasses too
        return obj


def encode(value, endpoint: "Endpoint | None" = None) -> tuple[object, list, list]:
    """(tree, buffers, tensors met in order) of ``value``; callables become handles of ``endpoint``."""
    encoder = _Encoder(endpoint)
    tree = encoder.encode(value)
    return tree, encoder.buffers, encoder.tensors


def decode(tree, buffers: list, endpoint: "Endpoint | None" = None, trusted: bool = True):
    """The value of ``tree``; returns (value, {tensor index: (tensor, required a gradient)})."""
    decoder = _Decoder(endpoint, buffers, trusted)
    return decoder.decode(tree), decoder.tensors


# ------------------------------------------------------------------------------------------ exceptions

def exception_record(exc: BaseException, is_library) -> dict:
    """What is sent for an exception: its class's name, the builtin exceptions it derives from, its message, and
    the frames of its traceback (file, line number, function, line, whether the file is a library's)."""
    frames = [[f.filename, f.lineno, f.name, (f.line or "")[:200], bool(is_library(f.filename))]
              for f in traceback.extract_tb(exc.__traceback__)][-30:]
    frames = getattr(exc, "remote_frames", None) or frames
    bases = [c.__name__ for c in type(exc).__mro__ if getattr(builtins, c.__name__, None) is c]
    return {"type": re.sub(r"\W", "_", type(exc).__name__)[:80], "bases": bases, "message": str(exc)[:2000], "frames": frames}


def rebuild_exception(record: dict) -> RemoteError:
    """A ``RemoteError`` whose class is named like the original and derives from the first builtin ``Exception``
    class the original derived from (so ``except ValueError`` in a check catches a student's ValueError).
    ``SystemExit`` and ``KeyboardInterrupt`` raised by the student's code arrive as plain errors."""
    base = Exception
    for name in record.get("bases", ()):
        cls = getattr(builtins, str(name), None)
        if isinstance(cls, type) and issubclass(cls, Exception):
            base = cls
            break
    name = re.sub(r"\W", "_", str(record.get("type", "Error")).rsplit(".", 1)[-1])[:80] or "Error"
    cls = type(name, (RemoteError, base) if base is not Exception else (RemoteError,), {"__module__": "remote"})
    try:
        exc = cls(str(record.get("message", "")))
    except Exception:                                                     # a base whose constructor differs
        exc = RemoteError(str(record.get("message", "")))
    exc.remote_frames = [tuple(f) for f in record.get("frames", [])][:30]
    return exc


# ------------------------------------------------------------------------------------------ the endpoint

class Endpoint:
    """One side of the pipe pair. ``trusted``: the grader's side (decodes records only of classes it has imported).

    ``call`` runs a function of the other side and serves the other side's requests while it waits (a call
    can call back); ``serve`` answers one request. ``handlers`` maps extra request names to functions
    ``handler(message) -> value`` (the worker's "run a cell", "look up a function", ...)."""

    def __init__(self, rfd: int, wfd: int, *, trusted: bool, handlers: dict | None = None):
        self.rfd, self.wfd, self.trusted = rfd, wfd, trusted
        self.handlers = dict(handlers or {})
        self.deadline: float | None = None
        self.gone: str | None = None           # why the other side is gone, once it is
        self.broken = False                    # a wait ran past the deadline: the other side is mid-request
        self.broken_frame = False              # ... and part of a message was read: the stream is out of step
        self._objects: dict[int, tuple[object, tuple]] = {}
        self._graphs: dict[int, tuple[list, list]] = {}
        self._ids = itertools.count(1)

    # -- exports and graphs kept for the other side
    def export(self, value, methods) -> int:
        for handle, (obj, _) in self._objects.items():
            if obj is value:
                return handle
        handle = next(self._ids)
        self._objects[handle] = (value, tuple(methods))
        return handle

    def exported(self, handle: int):
        if handle not in self._objects:
            raise ValueError(f"no object {handle} here")
        return self._objects[handle][0]

    def forget(self) -> None:
        """Drop every object and graph kept for the other side (between tasks)."""
        self._objects.clear()
        self._graphs.clear()

    # -- frames on the pipe
    def _remaining(self) -> float | None:
        if self.deadline is None:
            return None
        left = self.deadline - time.monotonic()
        if left <= 0:
            self.broken = True
            raise CheckTimeout(self.deadline)
        return left

    def _wait(self, fd: int, writing: bool) -> None:
        while True:
            left = self._remaining()
            ready = select.select([], [fd], [], left) if writing else select.select([fd], [], [], left)
            if ready[1 if writing else 0]:
                return

    def _write(self, data: bytes) -> None:
        view = memoryview(data)
        while view:
            self._wait(self.wfd, writing=True)
            try:
                n = os.write(self.wfd, view[:1 << 20])
            except (BrokenPipeError, OSError) as err:
                self.gone = self.gone or f"the other process closed its pipe ({err.__class__.__name__})"
                raise PeerGone(self.gone) from None
            view = view[n:]

    def _read(self, n: int) -> bytes:
        chunks, got = [], 0
        while got < n:
            self._wait(self.rfd, writing=False)
            try:
                chunk = os.read(self.rfd, min(n - got, 1 << 20))
            except OSError as err:
                chunk, self.gone = b"", f"reading from the other process failed ({err.__class__.__name__})"
            if not chunk:
                self.gone = self.gone or "the other process ended"
                raise PeerGone(self.gone)
            chunks.append(chunk)
            got += len(chunk)
            self.broken_frame = True                                       # until the whole message is read
        return b"".join(chunks)

    def send(self, message: dict, buffers=()) -> None:
        head = json.dumps(dict(message, nbuf=len(buffers)), allow_nan=False).encode("utf-8")
        parts = [_HEADER.pack(len(head)), head]
        for b in buffers:
            parts += [_HEADER.pack(len(b)), bytes(b)]
        self._write(b"".join(parts))

    def receive(self) -> tuple[dict, list]:
        total = 0

        def frame() -> bytes:
            nonlocal total
            (n,) = _HEADER.unpack(self._read(_HEADER.size))
            total += n
            if total > MAX_MESSAGE:
                self.gone = f"the other process sent a message over {MAX_MESSAGE >> 20} MB"
                raise PeerGone(self.gone)
            return self._read(n)
        try:
            message = json.loads(frame().decode("utf-8"))
        except (UnicodeDecodeError, ValueError):
            message = None
        if not isinstance(message, dict) or not isinstance(message.get("nbuf", 0), int):
            self.gone = "the other process sent something that is not a message"
            raise PeerGone(self.gone)
        buffers = [frame() for _ in range(message.get("nbuf", 0))]
        self.broken_frame = False
        return message, buffers

    # -- requests
    def request(self, message: dict, buffers=()):
        """Send a request and wait for its answer, serving the other side's requests meanwhile; returns
        (answer message, its buffers), or raises the other side's exception rebuilt."""
        self.send(message, buffers)
        return self.request_pending()

    def request_pending(self):
        """Wait for the answer to the request sent last (``request`` without sending it again)."""
        while True:
            reply, reply_buffers = self.receive()
            op = reply.get("op")
            if op == "return":
                return reply, reply_buffers
            if op == "raise":
                raise rebuild_exception(reply.get("exc", {}))
            self.serve(reply, reply_buffers)

    def call(self, handle: int, method: str | None, args: tuple, kwargs: dict):
        """``object(*args, **kwargs)`` (or its ``method``) on the other side; with autograd through ``_Bridge``."""
        if torch.is_grad_enabled():
            anchor = torch.zeros((), requires_grad=True)                  # lets outputs require a gradient
            box: dict = {}
            tree, buffers, tensors = encode((args, kwargs), self)
            inputs = [t for t in tensors if t.requires_grad]
            *outputs, _ = _Bridge.apply(self, handle, method, tree, buffers, box, anchor, *inputs)
            return _swap(box["value"], dict(zip(box["order"], outputs)))
        tree, buffers, _ = encode((args, kwargs), self)
        reply, reply_buffers = self.request({"op": "call", "h": handle, "m": method, "a": tree, "grad": False},
                                            buffers)
        value, _ = decode(reply["v"], reply_buffers, self, self.trusted)
        return value

    def serve(self, message: dict, buffers: list) -> None:
        """Answer one request of the other side (a call, a backward, or one of ``handlers``)."""
        op = message.get("op")
        try:
            if op == "call":
                reply, reply_buffers = self._serve_call(message, buffers)
            elif op == "backward":
                reply, reply_buffers = self._serve_backward(message, buffers)
            elif op == "release":
                for gid in message.get("graphs", []):
                    self._graphs.pop(int(gid), None)
                return                                                    # no answer
            elif op in self.handlers:
                value = self.handlers[op](message)
                tree, reply_buffers, _ = encode(value, self)
                reply = {"op": "return", "v": tree}
            else:
                raise ValueError(f"unknown request {op!r}")
        except (CheckTimeout, PeerGone):
            raise
        except BaseException as exc:                                      # the code that ran raised
            from .helpers import _is_library
            self.send({"op": "raise", "exc": exception_record(exc, _is_library)})
            return
        self.send(reply, reply_buffers)

    def _serve_call(self, message, buffers):
        handle, method = int(message["h"]), message.get("m")
        if handle not in self._objects:
            raise ValueError(f"no object {handle} here")
        target, methods = self._objects[handle]
        method = method or "__call__"
        if method not in methods:
            raise AttributeError(f"{_name_of(target)} offers only {', '.join(methods)}, not {method}")
        if method != "__call__":
            target = getattr(target, method)
        (args, kwargs), tensors = decode(message["a"], buffers, self, self.trusted)
        leaves = []
        grad = bool(message.get("grad"))
        for index in sorted(tensors):
            t, wanted = tensors[index]
            if wanted and grad and (t.is_floating_point() or t.is_complex()):
                t.requires_grad_(True)
                leaves.append(t)
        with torch.set_grad_enabled(grad):
            result = target(*args, **kwargs)
        tree, reply_buffers, outputs = encode(result, self)
        reply = {"op": "return", "v": tree}
        if grad and any(o.requires_grad for o in outputs):
            gid = next(self._ids)
            self._graphs[gid] = (leaves, outputs)
            reply["graph"] = gid
        return reply, reply_buffers

    def _serve_backward(self, message, buffers):
        leaves, outputs = self._graphs[int(message["graph"])]
        grads, _ = decode(message["g"], buffers, self, self.trusted)
        pairs = [(o, g) for o, g in zip(outputs, grads) if g is not None and o.requires_grad]
        for leaf in leaves:
            leaf.grad = None
        if pairs:
            torch.autograd.backward([o for o, _ in pairs], [g.to(o.dtype) for o, g in pairs], retain_graph=True)
        tree, reply_buffers, _ = encode([leaf.grad for leaf in leaves], self)
        return {"op": "return", "v": tree}, reply_buffers


def _swap(value, mapping):
    """``value`` with each tensor whose id is a key of ``mapping`` replaced by its value (``_Bridge``'s outputs)."""
    if isinstance(value, torch.Tensor):
        return mapping.get(id(value), value)
    if type(value) in (list, tuple):
        return type(value)(_swap(v, mapping) for v in value)
    if type(value) is dict:
        return {k: _swap(v, mapping) for k, v in value.items()}
    if isinstance(value, types.SimpleNamespace) or _is_record(value):
        for name, field in vars(value).items():
            object.__setattr__(value, name, _swap(field, mapping))
    return value


class _Bridge(torch.autograd.Function):
    """A remote call as one autograd node: forward makes the call, backward sends the gradients over."""

    @staticmethod
    def forward(ctx, endpoint, handle, method, tree, buffers, box, anchor, *inputs):
        reply, reply_buffers = endpoint.request({"op": "call", "h": handle, "m": method, "a": tree, "grad": True},
                                                buffers)
        value, tensors = decode(reply["v"], reply_buffers, endpoint, endpoint.trusted)
        outputs = [tensors[i][0] for i in sorted(tensors)]
        wanted = [tensors[i][1] and (o.is_floating_point() or o.is_complex()) for i, o in zip(sorted(tensors), outputs)]
        box["value"], box["order"] = value, [id(o) for o in outputs]
        ctx.endpoint, ctx.graph, ctx.wanted, ctx.n_inputs = endpoint, reply.get("graph"), wanted, len(inputs)
        padding = torch.zeros(())                                         # forward returns at least one tensor
        ctx.mark_non_differentiable(padding, *[o for o, w in zip(outputs, wanted) if not w])
        return tuple(outputs) + (padding,)

    @staticmethod
    def backward(ctx, *grads):
        none = (None,) * 7
        if ctx.graph is None:
            return none + (None,) * ctx.n_inputs
        sent = [g if w else None for g, w in zip(grads[:-1], ctx.wanted)]
        tree, buffers, _ = encode(sent, ctx.endpoint)
        reply, reply_buffers = ctx.endpoint.request({"op": "backward", "graph": ctx.graph, "g": tree}, buffers)
        leaf_grads, _ = decode(reply["v"], reply_buffers, ctx.endpoint, ctx.endpoint.trusted)
        leaf_grads = list(leaf_grads)[:ctx.n_inputs]
        return none + tuple(leaf_grads) + (None,) * (ctx.n_inputs - len(leaf_grads))


# ------------------------------------------------------------------------------------------ proxies

class RemoteFunction:
    """A function that lives on the other side: calling it sends the arguments over and waits for the result.

    On the grader's side ``reaches(module, qualname)`` asks the other side whether the function's code can reach a
    package function (``registry.calls_reference``, which needs the live function)."""

    def __init__(self, endpoint: Endpoint, handle: int, name: str, methods=("__call__",)):
        self._endpoint, self._handle, self.__name__, self._methods = endpoint, handle, name, tuple(methods)
        self.__qualname__ = name

    def __call__(self, *args, **kwargs):
        return self._endpoint.call(self._handle, None, args, kwargs)

    def __getattr__(self, name):
        if name.startswith("_") or name not in self.__dict__.get("_methods", ()):
            raise AttributeError(f"{self.__dict__.get('__name__', 'the object')} has no attribute {name!r} here "
                                 f"(it lives in another process, which offers {', '.join(self._methods)})")
        return lambda *args, **kwargs: self._endpoint.call(self._handle, name, args, kwargs)

    def time_limit(self, fn, seconds):
        """``fn()`` with every wait for the other side bounded: past ``seconds`` from now, ``CheckTimeout`` (the
        grader then ends the other process: ``Endpoint.broken`` is set). ``registry.run_check`` uses it in place
        of its in-process time limit."""
        if not seconds or seconds <= 0:
            return fn()
        previous, self._endpoint.deadline = self._endpoint.deadline, time.monotonic() + seconds
        try:
            return fn()
        finally:
            self._endpoint.deadline = previous

    def reaches(self, module: str, qualname: str) -> bool:
        """Whether the function can reach ``module.qualname``: as the grader reads its source
        (``static_reaches``, set by the grader: ``reading.reaches_reference``), or as the other side reads the live
        function (``registry.calls_reference`` there)."""
        static = self.__dict__.get("static_reaches")
        if static is not None and static(module, qualname):
            return True
        reply, buffers = self._endpoint.request({"op": "reaches", "h": self._handle, "module": module,
                                                 "qualname": qualname})
        value, _ = decode(reply["v"], buffers, self._endpoint, self._endpoint.trusted)
        return bool(value) if isinstance(value, bool) else False

    def __repr__(self):
        return f"<function {self.__name__} in another process>"


class RemoteObject(RemoteFunction):
    """An object of the other side that offers a few methods (an optimizer's ``zero_grad`` and ``step``)."""

    def __repr__(self):
        return f"<{self.__name__} in another process, offering {', '.join(self._methods)}>"
