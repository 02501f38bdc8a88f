"""The grader's boundary (course/grading/remote.py, worker.py, sandbox.py, reading.py): plain data across the pipe
and nothing else, autograd through it both ways, time limits enforced from outside, every process ended.

One worker (a real process, as the grader starts it) serves most tests; those that end it start their own.
"""
import math
import os
import signal
import time

import numpy as np
import pytest
import torch

from course import Camera, Mesh
from course.grading import remote
from course.grading.reading import reaches_reference
from course.grading.registry import run_check
from course.grading.sandbox import Isolation, Worker, end_processes

pytestmark = pytest.mark.timeout(300)


def roundtrip(value, trusted=True):
    tree, buffers, _ = remote.encode(value)
    return remote.decode(tree, buffers, trusted=trusted)[0]


# ------------------------------------------------------------------------------------------- the format

def test_plain_values_come_back_as_they_were():
    values = [None, True, 0, -7, 2 ** 70, 1.5, math.inf, -math.inf, 3 + 4j, "text", b"\x00\xff", [1, (2, 3)],
              {"a": 1, 2: [None]}, torch.Size([2, 3]), slice(1, None, 2), Ellipsis, torch.float64,
              torch.device("cpu"), np.float64(2.5), np.int32(-3), np.array([[1, 2]], dtype=np.uint8)]
    for value in values:
        back = roundtrip(value)
        assert type(back) is type(value), value
        if isinstance(value, np.ndarray):
            assert back.dtype == value.dtype and np.array_equal(back, value)
        else:
            assert back == value
    assert math.isnan(roundtrip(math.nan))


@pytest.mark.parametrize("dtype", [torch.float16, torch.bfloat16, torch.float32, torch.float64, torch.complex64,
                                   torch.complex128, torch.uint8, torch.int8, torch.int16, torch.int32, torch.int64,
                                   torch.bool])
def test_tensors_keep_dtype_shape_and_bits(dtype):
    g = torch.Generator().manual_seed(1)
    t = (torch.randn(3, 4, generator=g, dtype=torch.float64) * 100).to(dtype)
    for value in (t, t.T, t[:, 1], torch.empty(0, 5, dtype=dtype)):      # views and empties too
        back = roundtrip(value)
        assert back.dtype == dtype and back.shape == value.shape and torch.equal(back, value)
        assert back.is_contiguous() and not back.requires_grad


def test_a_generator_travels_as_its_state_and_records_as_their_fields():
    g = torch.Generator().manual_seed(5)
    back = roundtrip(g)
    assert torch.equal(torch.rand(4, generator=back), torch.rand(4, generator=g))
    mesh = Mesh(torch.rand(4, 3, dtype=torch.float64), torch.tensor([[0, 1, 2], [0, 2, 3]]))
    camera = Camera.look_at((0, 0, 3), (0, 0, 0), fov_y=40, width=8, height=6)
    back = roundtrip({"mesh": mesh, "camera": camera})
    assert isinstance(back["mesh"], Mesh) and torch.equal(back["mesh"].verts, mesh.verts)
    assert isinstance(back["camera"], Camera) and torch.equal(back["camera"].K, camera.K)


def test_nothing_that_runs_comes_through():
    class Sneaky:                                                         # a student's class
        def __reduce__(self):
            return (os.system, ("echo pwned",))

    class Liar(torch.Tensor):
        def __eq__(self, other):
            return True
    assert roundtrip(Sneaky()) == remote.Opaque("test_nothing_that_runs_comes_through.<locals>.Sneaky")
    assert type(roundtrip(torch.zeros(2).as_subclass(Liar))) is torch.Tensor
    assert isinstance(roundtrip(np.array([object()], dtype=object)), remote.Opaque)
    assert isinstance(roundtrip((x for x in ())), remote.Opaque)
    record = {"$": "record", "module": "course.not_imported_anywhere", "qualname": "X", "f": {"a": 1}}
    back = remote.decode(record, [], trusted=True)[0]
    assert type(back).__name__ == "SimpleNamespace" and back.a == 1       # never imported on the grader's side
    with pytest.raises(ValueError, match="plain data"):
        remote.decode({"$": "ndarray", "dtype": "|O", "shape": [1], "b": 0}, [b"x" * 8])
    with pytest.raises(ValueError, match="not a value"):
        remote.decode({"$": "pickle", "b": 0}, [b""])


def test_deep_and_huge_values_are_refused(monkeypatch):
    deep = []
    for _ in range(remote.MAX_DEPTH + 5):
        deep = [deep]
    with pytest.raises(ValueError, match="nested"):
        remote.encode(deep)
    monkeypatch.setattr(remote, "MAX_MESSAGE", 1000)
    with pytest.raises(ValueError, match="too large"):
        remote.encode(torch.zeros(1000))


def test_an_exception_is_rebuilt_with_its_builtin_class_and_the_students_frames():
    class MyError(ValueError):
        pass
    try:
        raise MyError("bad input")
    except MyError as exc:
        record = remote.exception_record(exc, lambda filename: False)
    rebuilt = remote.rebuild_exception(record)
    assert isinstance(rebuilt, ValueError) and type(rebuilt).__name__ == "MyError" and str(rebuilt) == "bad input"
    assert rebuilt.remote_frames[-1][3] == 'raise MyError("bad input")'
    for name in ("SystemExit", "KeyboardInterrupt", "GeneratorExit"):   # never stop the grader
        assert isinstance(remote.rebuild_exception({"type": name, "bases": [name, "BaseException"]}), Exception)


# ------------------------------------------------------------------------------------------ a real worker

@pytest.fixture(scope="module")
def worker():
    w = Worker(Isolation())
    w.start()
    assert w.run_cell(DEFINITIONS, 60) == ("ok", "")
    yield w
    w.end()


DEFINITIONS = """\
import math, time, torch
def scale(x, k=2.0):
    return (x * k).sin()
def numpy_and_tuple(n):
    import numpy
    return numpy.arange(n), (n, [n * 0.5])
def fit(render, target, pose0, steps):
    pose = pose0.detach().clone().requires_grad_(True)
    opt = torch.optim.Adam([pose], lr=0.1)
    for _ in range(steps):
        opt.zero_grad()
        loss = ((render(pose) - target) ** 2).mean()
        loss.backward()
        opt.step()
    return pose.detach()
def train(model, opt, x, y, loss_fn):
    opt.zero_grad()
    loss = loss_fn(model(x), y)
    loss.backward()
    opt.step()
    return float(loss)
def sneaky_optimizer(model, opt, x, y, loss_fn):
    opt.load_state_dict({})
class Odd(ValueError):
    pass
def raises(kind):
    if kind == "odd":
        raise Odd("an odd value")
    if kind == "exit":
        raise SystemExit(3)
    raise NotImplementedError()
def hangs(*args):
    while True:
        try:
            time.sleep(0.01)
        except:
            pass
def dies(*args):
    import os
    os._exit(5)
def remember(x):
    global seen
    seen = x
    return x
"""


def test_calls_send_plain_data_and_bring_back_plain_data(worker):
    x = torch.tensor([0.5, -1.0], dtype=torch.float64)
    assert torch.equal(worker.function("scale")(x, k=3.0), (x * 3.0).sin())
    array, (n, half) = worker.function("numpy_and_tuple")(4)
    assert isinstance(array, np.ndarray) and list(array) == [0, 1, 2, 3] and n == 4 and half == [2.0]
    assert worker.function("nothing_here") == "nothing_here is not defined (did its cell run without errors?)"
    assert worker.function("math").startswith("math is not a function")
    x.zero_()                                                             # the worker has its own copy
    assert worker.function("remember")(torch.ones(2)).sum() == 2


def test_autograd_runs_where_the_code_lives_both_ways(worker):
    x = torch.tensor([0.3, 1.2, -0.7], dtype=torch.float64, requires_grad=True)
    y = worker.function("scale")(x, k=2.0)
    assert y.requires_grad
    (got,) = torch.autograd.grad((y * torch.arange(3.0, dtype=torch.float64)).sum(), x)
    assert torch.allclose(got, 2 * torch.cos(2 * x.detach()) * torch.arange(3.0, dtype=torch.float64), atol=0,
                          rtol=1e-15)
    calls = []

    def render(pose):                                                    # the grader's, called back from the worker
        calls.append(pose.detach().clone())
        return torch.stack([pose[0] ** 2, pose[1] * 3.0])
    target = torch.tensor([4.0, 3.0], dtype=torch.float64)
    pose = worker.function("fit")(render, target, torch.tensor([1.0, 0.0], dtype=torch.float64), 150)
    assert len(calls) == 150 and torch.allclose(pose, torch.tensor([2.0, 1.0], dtype=torch.float64), atol=1e-2)


def test_the_graders_model_and_optimizer_step_in_the_grader(worker):
    import copy
    torch.manual_seed(0)
    model = torch.nn.Linear(3, 2).double()
    twin = copy.deepcopy(model)
    opt, twin_opt = torch.optim.SGD(model.parameters(), lr=0.5), torch.optim.SGD(twin.parameters(), lr=0.5)
    x, y = torch.randn(5, 3, dtype=torch.float64), torch.randn(5, 2, dtype=torch.float64)
    mse = torch.nn.functional.mse_loss
    twin_opt.zero_grad()
    want = mse(twin(x), y)
    want.backward()
    twin_opt.step()
    got = worker.function("train")(model, opt, x, y, mse)                 # forward, loss, backward: here
    assert isinstance(got, float) and got == float(want.detach())
    assert torch.equal(model.weight, twin.weight) and torch.equal(model.bias, twin.bias)
    with pytest.raises(AttributeError, match="offers zero_grad, step"):
        worker.function("sneaky_optimizer")(model, opt, x, y, mse)


def test_exceptions_keep_their_class_and_never_stop_the_grader(worker):
    with pytest.raises(ValueError, match="an odd value") as caught:
        worker.function("raises")("odd")
    assert type(caught.value).__name__ == "Odd"
    with pytest.raises(remote.RemoteError) as caught:
        worker.function("raises")("exit")
    assert type(caught.value).__name__ == "SystemExit" and not isinstance(caught.value, SystemExit)
    result = run_check("1.1", worker.function("raises"))
    assert result.points == 0 and result.message.startswith("not attempted yet")   # the student's own raise


def test_reading_the_reference_rule_in_the_graders_process():
    cells = ["import course.camera as cam\nfrom course.camera import look_at as reference",
             "def helper(e, t, u):\n    return reference(e, t, u)",
             "def look_at(eye, target, up):\n    return helper(eye, target, up)",
             "def rodrigues(w):\n    return cam.axis_angle_to_matrix(w)",
             "def world_to_camera(points, R, t):\n    return points @ R.T + t"]
    assert reaches_reference(cells, "look_at", "course.camera", "look_at")            # through a helper
    assert reaches_reference(cells, "rodrigues", "course.camera", "axis_angle_to_matrix")
    assert not reaches_reference(cells, "world_to_camera", "course.camera", "world_to_camera")
    own = ["from course.camera import look_at", "def look_at(eye, target, up):\n    return eye"]
    assert not reaches_reference(own, "look_at", "course.camera", "look_at")          # rebound: the student's own
    method = ["from course.mesh import Mesh", "def vertex_normals(v, f):\n    return Mesh(v, f).vertex_normals()"]
    assert reaches_reference(method, "vertex_normals", "course.mesh", "Mesh.vertex_normals")


# -------------------------------------------------------------------------- limits, from outside the worker

def test_a_hang_is_cut_off_from_outside_and_a_death_is_reported():
    w = Worker(Isolation())
    w.start()
    try:
        assert w.run_cell(DEFINITIONS, 60) == ("ok", "")
        start = time.monotonic()
        result = run_check("1.3", w.function("hangs"), timeout=2)
        assert result.points == 0 and result.message.startswith("stopped after 2 s")
        assert time.monotonic() - start < 10 and w.endpoint.broken and not w.alive
    finally:
        w.end()
    w = Worker(Isolation())
    w.start()
    try:
        w.run_cell(DEFINITIONS, 60)
        result = run_check("1.3", w.function("dies"), timeout=5)
        assert result.points == 0 and "the process running the notebook died" in result.message
        assert w.exit_note() == "exit code 5"
    finally:
        w.end()


def test_cells_are_interrupted_and_a_cell_deaf_to_interrupts_ends_the_worker():
    w = Worker(Isolation())
    w.start()
    try:
        assert w.run_cell("while True:\n    pass", 1) == ("timeout", "stopped after 1 s")
        assert w.run_cell("x = 1", 5) == ("ok", "")                        # the worker carries on
        deaf = "import signal\nsignal.signal(signal.SIGINT, signal.SIG_IGN)\nwhile True:\n    pass"
        status, why = w.run_cell(deaf, 1)
        assert status == "ended" and "did not stop when interrupted" in why and not w.alive
    finally:
        w.end()


def test_memory_and_processes_are_limited_and_every_process_is_ended(tmp_path):
    w = Worker(Isolation(memory_gb=4))
    w.start()
    pid = w.process.pid
    try:
        status, why = w.run_cell("import torch\nhuge = torch.ones(2 * 2**30)", 30)        # 8 GB
        assert status == "error" and ("memory" in why.lower() or "alloc" in why.lower()), why
        flag = tmp_path / "alive"
        daemon = (f"import os, time\nif os.fork() == 0:\n    os.setsid()\n    if os.fork() == 0:\n"
                  f"        for _ in range(600):\n            open({str(flag)!r}, 'w').write(str(os.getpid()))\n"
                  f"            time.sleep(0.05)\n    os._exit(0)\nos.wait()\n"
                  f"for _ in range(5):\n    if os.fork() == 0:\n        time.sleep(600)\n        os._exit(0)")
        assert w.run_cell(daemon, 30)[0] == "ok"
        for _ in range(100):
            if flag.exists():
                break
            time.sleep(0.05)
        left = int(flag.read_text())
    finally:
        w.end()
    assert w.process.returncode is not None
    assert not running(pid) and not running(left)
    end_processes(pid, "no-such-marker")                                 # nothing left: returns at once


def running(pid: int) -> bool:
    """Alive and not a zombie (a killed orphan waits for whoever adopted it to reap it)."""
    try:
        stat = open(f"/proc/{pid}/stat").read()
    except OSError:
        return False
    return stat[stat.rindex(")") + 2] not in "ZX"


def test_a_user_that_does_not_exist_or_is_root_is_refused():
    with pytest.raises(ValueError, match="there is no user"):
        Worker(Isolation(user="no-such-student-here"))
    with pytest.raises(ValueError, match="must not run as root"):
        Worker(Isolation(user="root"))


def test_check_does_nothing_in_the_worker(monkeypatch, capsys):
    from course.grading import check
    monkeypatch.setenv("COURSE_GRADING_WORKER", "1")
    result = check("1.1", lambda w: 1 / 0)
    assert result.message == "checked by the grader" and capsys.readouterr().out == ""
    assert signal.getsignal(signal.SIGINT) is not None


def test_a_grader_started_in_the_background_still_interrupts_cells():
    """A shell without job control starts background commands with SIGINT ignored, and a child inherits that: the
    worker takes the interrupt back, so a hanging cell is interrupted, not its worker ended (found when the suite
    itself was started with `&`)."""
    previous = signal.signal(signal.SIGINT, signal.SIG_IGN)               # as `grade ... &` from a script
    try:
        w = Worker(Isolation())
        w.start()
    finally:
        signal.signal(signal.SIGINT, previous)
    try:
        assert w.run_cell("while True:\n    pass", 1) == ("timeout", "stopped after 1 s")
        assert w.run_cell("x = 2", 5) == ("ok", "")
    finally:
        w.end()
