"""The benchmark runs and measures what it says; the OpenGL oracle agrees with the rasterizer."""
import json
import math
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


@pytest.fixture
def no_cold_start(monkeypatch):
    """The raster and ray-tracing benchmarks end with the kernels' cold start, which compiles every kernel in a
    fresh process (15-20 s): measured once, for one kernel, in ``test_cold_start_compiles_then_loads``."""
    lines = []
    for module in ("raster", "raytrace"):
        monkeypatch.setattr(f"course.bench.{module}.cold_start_line", lambda out=print: lines.append(out) or None)
    return lines


def test_cold_start_compiles_then_loads():
    from course import kernels
    from course.bench.kernels import cold_start
    if not kernels.available():
        pytest.skip("Numba is not installed")
    times = cold_start(only=["screen"])
    assert set(times["compile"]) == set(times["load"]) == {"import_s", "screen"}
    assert times["load"]["screen"] < times["compile"]["screen"]          # a cache hit beats compiling


def test_bench_raster_reports_rows(capsys, no_cold_start):
    rows = bench_raster(["S4"], repeat=1, memory=False)
    assert len(no_cold_start) == 1                                        # it ends with the cold-start line
    assert [(r["scene"], r["cull"]) for r in rows] == [("S4", False), ("S4", True)]
    assert all(r["ms"] > 0 and r["mtri_s"] > 0 for r in rows)
    assert "S4" in capsys.readouterr().out
    assert "OpenGL" not in format_table(rows)


def test_bench_command_runs_a_benchmark_with_its_own_options(tmp_path, capsys, no_cold_start):
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


def test_bench_raytrace_tiny_scene_agrees_with_brute_force(capsys):
    """The ray-tracing bench on a tiny scene: every kind of ray, the BVH agreeing with brute force on the
    subset; Embree (when installed) side by side, otherwise skipped with a message."""
    from course.bench.raytrace import _embree, brute_force, format_table, measure
    from course.camera import Camera
    from course.models import icosphere
    mesh = icosphere(1)
    cam = Camera.look_at((0.3, 0.4, 3.0), (0.0, 0.0, 0.0), fov_y=40.0, width=64, height=48)
    embree, msg = _embree()
    rows = measure("tiny", repeat=1, scale=0.5, n_incoherent=256, brute_pairs=4096, embree=embree,
                   scene_override=(mesh, cam))
    assert [r["kind"] for r in rows] == ["build", "primary", "shadow", "incoherent"]
    assert all(r["ms"] > 0 for r in rows)
    assert rows[1]["rays"] == 32 * 24 and rows[3]["rays"] == 256
    assert all(r["agree"] == 1.0 and r["speedup"] > 0 for r in rows[1:]), rows
    if embree is None:
        assert "embreex" in msg
    else:
        assert all(r["ratio"] > 0 for r in rows)
        o = torch.tensor([[0.13, 0.07, 3.0], [5.0, 5.0, 5.0]])
        d = torch.tensor([[0.0, 0.0, -1.0], [1.0, 0.0, 0.0]])
        ids = embree.trace(embree.build(mesh), o, d)                       # Embree: same face, and a miss
        assert list(ids) == brute_force(o, d, mesh.verts[mesh.faces]).tolist()
    assert "incoherent" in format_table(rows)


def test_bench_raytrace_thin_scene_and_skip_message(capsys, monkeypatch, no_cold_start):
    from course.bench import raytrace
    mesh, cam = raytrace.thin_scene(n_thin=50, n_flat=4, size=16)
    assert mesh.num_faces == 54
    monkeypatch.setattr(raytrace, "_Embree", lambda: (_ for _ in ()).throw(ImportError("no embreex")))
    monkeypatch.setattr(raytrace, "scene", lambda name, dtype=torch.float32: (mesh, cam))
    rows = raytrace.bench_raytrace(["thin"], repeat=1, scale=1.0, n_incoherent=64, brute_pairs=2048,
                                   vs_embree=True)
    out = capsys.readouterr().out
    assert "--vs embree skipped" in out and "pip install embreex" in out
    assert {r["kind"] for r in rows} == {"build", "primary", "shadow", "incoherent"}


def test_bench_shadows_rows_and_plot(tmp_path, capsys):
    """Shadow maps converge to the ray-traced shadow as the resolution grows; N shadow rays and N shadow maps
    approach the area-light reference; the plot is written."""
    from course.bench.shadows import bench_shadows
    rows = bench_shadows(resolutions=(64, 256), size=32, repeat=1, samples=(1, 4), area_points=64,
                         reference_samples=64, area_resolution=64, plot=str(tmp_path / "p.png"))
    hard = {(r["method"], r["param"]): r for r in rows if r["case"] == "hard"}
    assert hard[("ray traced", 1)]["error"] == 0
    assert hard[("map pcf1", 256)]["error"] < hard[("map pcf1", 64)]["error"] < 0.2
    assert ("map pcf3", 64) in hard
    area = {(r["method"], r["param"]): r for r in rows if r["case"] == "area"}
    assert area[("shadow rays", 4)]["error"] < area[("shadow rays", 1)]["error"]
    assert area[("shadow maps 64", 4)]["error"] < area[("shadow maps 64", 1)]["error"]
    assert all(r["ms"] > 0 for r in rows)
    assert (tmp_path / "p.png").stat().st_size > 1000
    assert "teapot" in capsys.readouterr().out


def _scaling_rows(embree: bool):
    """Synthetic bench_raytrace rows: brute force linear in the faces, the BVH logarithmic."""
    rows = []
    for name, faces in (("S4", 1280), ("S1", 20480), ("S2", 327680)):
        rows.append(dict(scene=name, faces=faces, kind="build", rays=0, ms=5.0, embree_ms=1.0 if embree else None))
        for kind, rays in (("primary", 1000), ("shadow", 800), ("incoherent", 500)):
            ms = rays * 1e-3 * math.log2(faces)                              # µs per ray = log2(faces)
            rows.append(dict(scene=name, faces=faces, kind=kind, rays=rays, ms=ms, brute_ms_per_ray=faces * 1e-6,
                             embree_ms=ms / 4 if embree else None))
    return rows


@pytest.mark.parametrize("embree", [False, True])
def test_bench_raytrace_scaling_plot_from_rows(tmp_path, embree):
    """plot_scaling draws time per ray against faces on log axes from the bench's rows, without running it."""
    import matplotlib.pyplot as plt
    from course.bench.raytrace import plot_scaling
    fig = plot_scaling(_scaling_rows(embree), tmp_path / "scaling.png")
    try:
        ax = fig.axes[0]
        lines = {ln.get_label(): ln for ln in ax.get_lines()}
        expected = {"brute force, primary", "brute force, incoherent", "BVH, primary", "BVH, incoherent",
                    "∝ faces"} | ({"Embree, primary", "Embree, incoherent"} if embree else set())
        assert set(lines) == expected
        assert ax.get_xscale() == ax.get_yscale() == "log"
        assert list(lines["BVH, primary"].get_xdata()) == [1280, 20480, 327680]          # sorted by faces
        assert lines["brute force, incoherent"].get_ydata() == pytest.approx([1.28, 20.48, 327.68])   # µs
        assert lines["BVH, incoherent"].get_ydata() == pytest.approx([math.log2(f) for f in (1280, 20480, 327680)])
        assert list(lines["∝ faces"].get_ydata()) == pytest.approx(lines["brute force, primary"].get_ydata())
        assert (tmp_path / "scaling.png").stat().st_size > 1000
    finally:
        plt.close(fig)


def test_bench_raytrace_scaling_plot_rejects_rows_without_rays():
    from course.bench.raytrace import plot_scaling
    with pytest.raises(ValueError, match="no primary or incoherent rows"):
        plot_scaling([dict(scene="S4", faces=1280, kind="build", rays=0, ms=3.0)])


def test_bench_penumbra_rows_bias_and_plot(tmp_path, capsys):
    """The penumbra bench on a tiny configuration: every estimator a row; the exact one is its own reference,
    autograd through shadow rays is biased by exactly 1 with no spread, edge sampling is close; the plot."""
    from course.bench import penumbra
    configs = (("shadow_rays", "S=8", dict(samples=8)), ("edge_sampling", "S=8 M=64", dict(samples=8, edge_samples=64)),
               ("finite_differences", "S=8 h=1e-2", dict(samples=8, step=1e-2)), ("vsm", "2x2 R=16",
                                                                                  dict(grid=2, resolution=16)))
    rows = penumbra.measure(scenes=("square",), seeds=2, n=3, repeat=1, configs=configs)
    assert [r["method"] for r in rows] == ["exact", "shadow_rays", "edge_sampling", "finite_differences", "vsm"]
    assert rows[0]["error"] == 0 and rows[1]["bias"] == 1.0 and rows[1]["spread"] == 0.0
    assert rows[2]["error"] < 0.5 and all(r["ms"] > 0 for r in rows)
    penumbra.plot_pareto(rows, tmp_path / "p.png")
    assert (tmp_path / "p.png").stat().st_size > 0


def test_bench_representations_fast_rows(capsys):
    """The three fits' smoke run: a row per fit and the hull, shares of each row's error that sum to at most 1."""
    from course.bench import representations
    rows = representations.bench_representations(fast=True)
    assert [r["fit"] for r in rows][1:] == [label for label, _, _ in representations.FITS]
    for r in rows:
        shares = sum(r[f"share_{name}"] for name, _ in representations.SHARES)
        assert 0 < r["psnr"] < 100 and 0 <= shares <= 1 + 1e-12
    assert rows[0]["inside_pixels"] > 0                                 # the gap under the lid, seen from above
    assert "lid gap" in capsys.readouterr().out


def test_bench_splats_rows(capsys):
    from course.bench import splats
    rows = splats.bench_splats(counts=(40,), sizes=(12,), repeat=1)
    assert len(rows) == 1 and rows[0]["count"] == 40 and rows[0]["forward_ms"] > 0 and rows[0]["mesh_ms"] > 0
    assert "img/s" in capsys.readouterr().out


@pytest.mark.skipif(not torch.cuda.is_available(), reason="needs a CUDA device")
def test_bench_splats_on_cuda_draws_the_cpus_image(capsys):
    from course.bench import splats
    rows = splats.bench_splats(counts=(200,), sizes=(32,), repeat=1, device="cuda")
    assert rows[0]["device"].startswith("cuda") and rows[0]["cpu_diff"] < 1e-12
