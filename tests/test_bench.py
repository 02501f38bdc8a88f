"""The benchmark runs and measures what it says; the OpenGL oracle agrees with the rasterizer."""
import json
import subprocess
import sys

import pytest
import torch

from course.bench.raster import SCENES, _OpenGL, bench_raster, format_table, scene
from course.raster import rasterize


def test_standard_scenes_are_the_documented_ones():
    faces = {name: scene(name)[0].num_faces for name in SCENES}
    assert faces == {"S1": 20480, "S2": 327680, "S3": 20480, "S4": 1280}
    mesh, cam = scene("S3")
    assert (cam.width, cam.height) == (1024, 1024) and torch.allclose(cam.eye, torch.tensor([0.0, 0.0, 3.0]))


def test_bench_raster_reports_rows(capsys):
    rows = bench_raster(["S4"], repeat=1, memory=False)
    assert [(r["scene"], r["cull"]) for r in rows] == [("S4", False), ("S4", True)]
    assert all(r["ms"] > 0 and r["mtri_s"] > 0 for r in rows)
    assert "S4" in capsys.readouterr().out
    assert "OpenGL" not in format_table(rows)


def test_bench_command_runs_a_benchmark_with_its_own_options(tmp_path, capsys):
    from course.bench import BENCHES, cli
    out = tmp_path / "rows.json"
    assert cli(["raster", "--scenes", "S4", "--repeat", "1", "--no-memory", "--json", str(out)]) == 0
    rows = json.loads(out.read_text())
    assert [(r["scene"], r["cull"]) for r in rows] == [("S4", False), ("S4", True)]
    for name, module in BENCHES.items():                                   # every benchmark is complete
        assert module.DESCRIPTION and callable(module.add_arguments) and callable(module.run), name
    with pytest.raises(SystemExit):                                         # raster's options are its own
        cli(["skips", "--scenes", "S4"])
    assert "unrecognized arguments: --scenes" in capsys.readouterr().err


def test_cli_usage_and_unknown_command():
    out = subprocess.run([sys.executable, "-m", "course"], capture_output=True, text=True)
    assert out.returncode == 2 and "render" in out.stdout and "bench" in out.stdout
    out = subprocess.run([sys.executable, "-m", "course", "paint"], capture_output=True, text=True)
    assert out.returncode == 2 and "unknown command 'paint'" in out.stderr


def opengl():
    try:
        return _OpenGL()
    except Exception as err:                                                # no moderngl or no EGL driver
        pytest.skip(f"OpenGL not available: {err}")


@pytest.mark.parametrize("cull", [False, True])
def test_opengl_picks_the_same_faces(cull):
    """An external oracle: a real OpenGL implementation sees the same face at almost every pixel (the
    rest lie on triangle edges, where GL's sub-pixel snapping may decide differently)."""
    gl = opengl()
    mesh, cam = scene("S4")
    gl.prepare(mesh, cam, cull)
    ours = rasterize(mesh, cam, cull_backfaces=cull).face_id
    theirs = gl.face_ids()
    assert (ours == theirs).double().mean() > 0.999
    assert torch.equal(ours >= 0, theirs >= 0) or (ours >= 0).ne(theirs >= 0).sum() < 20


def test_bench_skips_are_exact(capsys):
    from course.bench.skips import bench_skips
    rows = bench_skips(repeat=1)
    assert len(rows) == 4
    assert all(r["max_diff"] == 0.0 for r in rows), rows                    # every skip leaves the image as is


def test_bench_precision_reports_float32_against_float64(capsys):
    from course.bench.precision import bench_precision
    rows = bench_precision(["teapot", "moved-1e5"], repeat=1)
    assert [r["scene"] for r in rows] == ["teapot", "moved-1e5"]
    assert all(r["ms32"] > 0 and r["ms64"] > 0 and r["same"] > 0.99 for r in rows)
    assert all(0 < r["depth_p50"] <= r["depth_p99"] <= r["depth_max"] < 1e-4 for r in rows)
    assert "moved-1e5" in capsys.readouterr().out


def test_bench_aa_rows_and_plot(tmp_path):
    """The antialiasing bench on a tiny scene: every method, supersampling converging, adaptive equal to
    full supersampling on flat colours, the exact method its own reference; the plot is written."""
    import torch
    from course.bench.aa import measure, plot_pareto
    from course.camera import Camera
    from course.models import icosphere
    mesh = icosphere(1)
    cam = Camera.look_at((0.3, 0.4, 3.0), (0.0, 0.0, 0.0), fov_y=40.0, width=24, height=20)
    colors = torch.rand(mesh.faces.shape[0], 3, generator=torch.Generator().manual_seed(0))
    rows = measure("tiny", repeat=1, scene=(mesh, cam, colors))
    by = {r["method"]: r for r in rows}
    assert {"none", "exact", "ss 2x2", "ss 8x8", "ss-jit 4x4", "adaptive 4x4", "adaptive-jit 8x8"} <= set(by)
    assert by["exact"]["rmse"] == 0 and all(r["ms"] > 0 for r in rows)
    assert by["ss 8x8"]["rmse"] < by["ss 2x2"]["rmse"] < by["none"]["rmse"]
    for k in (2, 4, 8):
        assert by[f"adaptive {k}x{k}"]["rmse"] == by[f"ss {k}x{k}"]["rmse"]
    plot_pareto(rows, tmp_path / "pareto.png")
    assert (tmp_path / "pareto.png").stat().st_size > 1000
