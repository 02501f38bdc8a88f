"""The gradient benchmark (course.bench.gradients): its scenes, rows and error metric; never its timings."""
import json
import math

import pytest
import torch

from course.bench import BENCHES, cli
from course.bench import gradients as gb


def test_error_metric_relative_cosine_and_absolute():
    ref = torch.tensor([[3.0, 0.0, 4.0]], dtype=torch.float64)
    e = gb.gradient_error((ref.clone(),), (ref,))
    assert e["rel"] == 0 and e["cos"] == pytest.approx(1.0) and not e["abs"]
    e = gb.gradient_error((2 * ref,), (ref,))                               # twice as long, same direction
    assert e["rel"] == pytest.approx(1.0) and e["cos"] == pytest.approx(1.0)
    e = gb.gradient_error((-ref,), (ref,))
    assert e["rel"] == pytest.approx(2.0) and e["cos"] == pytest.approx(-1.0)
    zero = torch.zeros(1, 3, dtype=torch.float64)                          # g* = 0: the absolute error
    e = gb.gradient_error((torch.tensor([[0.0, 3.0, 4.0]]),), (zero,))
    assert e["abs"] and e["rel"] == pytest.approx(5.0) and math.isnan(e["cos"])
    # several parameters: the worst relative error; each block scaled, so a huge one does not drown the rest
    big, small = torch.tensor([1e6, 0.0]), torch.tensor([0.0, 1.0])
    e = gb.gradient_error((big, -small), (big, small))
    assert e["rel"] == pytest.approx(2.0) and e["cos"] == pytest.approx(0.0, abs=1e-12)
    # a mask keeps only the compared entries (finite differences on a subset: NaN elsewhere)
    g = torch.tensor([[1.0, 2.0, 3.0], [math.nan] * 3], dtype=torch.float64)
    r = torch.tensor([[1.0, 2.0, 3.0], [5.0, 5.0, 5.0]], dtype=torch.float64)
    mask = torch.tensor([[True] * 3, [False] * 3])
    assert gb.gradient_error((g,), (r,), (mask,))["rel"] == 0


def test_scenes_are_float64_front_facing_and_the_weights_are_what_they_say():
    for name in ("triangle", "triangles", "spheres", "pose"):
        sc = gb.make_scene(name)
        assert sc["mesh"].verts.dtype == torch.float64 and sc["camera"].dtype == torch.float64
    sc = gb.make_scene("triangles")
    xy, _ = sc["camera"].project(sc["mesh"].verts)
    a, b, c = (xy[sc["mesh"].faces[:, k]] for k in range(3))
    cross = (b[:, 0] - a[:, 0]) * (c[:, 1] - a[:, 1]) - (b[:, 1] - a[:, 1]) * (c[:, 0] - a[:, 0])
    assert (cross < 0).all()                                                # counter-clockwise on screen (y down)
    assert gb.make_scene("pose")["wrt"] == ("R", "t", "focal")
    w = gb.weights_for(sc, "L2")
    assert w.shape == (32, 32, 3) and w.abs().sum() > 0                     # the moved mesh changes the image
    assert torch.equal(gb.weights_for(sc, "random"), gb.weights_for(sc, "random"))   # seeded
    with pytest.raises(ValueError, match="unknown scene"):
        gb.make_scene("S9")


def test_measure_scene_rows_and_errors_on_one_triangle():
    sc = gb.make_scene("triangle")
    specs = gb.method_specs(steps={torch.float64: (1e-6,), torch.float32: (1e-3,)}, samples=(200,),
                            sigmas=(1e-4,), orders=(1,), warp_samples=(64,))
    rows = gb.measure_scene(sc, "random", specs, repeat=1)
    by = {(r["family"], r["param"]): r for r in rows}
    assert [r["method"] for r in rows] == ["exact", "reynolds", "edge_sampling", "reparameterization",
                                           "reparameterization", "finite_differences", "finite_differences",
                                           "soft", "nmr"]
    assert by[("exact", "")]["rel"] == 0 and by[("exact", "")]["x_exact"] == 1
    assert by[("reynolds", "order 1")]["rel"] < 1e-12                       # exact for flat colours
    assert by[("FD float64", "h=1e-06")]["rel"] < 1e-5
    assert by[("FD float32", "h=1e-03")]["dtype"] == "float32"
    assert 0 < by[("edge sampling", "200 smp")]["rel"] < 1                  # noisy but an estimate
    assert 0 < by[("reparameterization", "64 spp")]["rel"] < 1 and by[("reparameterization", "64 spp")]["cos"] > 0.5
    assert 0 < by[("reparam. (harmonic)", "64 spp")]["rel"] < 2                # the 1/r warp beside it
    for r in rows:
        assert r["ms"] > 0 and math.isfinite(r["rel"]) and -1 <= r["cos"] <= 1 + 1e-12 and not r["abs"]


def test_finite_differences_on_a_big_mesh_use_a_seeded_subset_and_say_so():
    sc = gb.make_scene("S4-64")
    specs = [s for s in gb.method_specs(steps={torch.float64: (1e-6,)}) if s["method"] in ("exact",
                                                                                         "finite_differences")]
    rows = gb.measure_scene(sc, "random", specs, repeat=1, fd_vertices=2)
    fd = rows[1]
    assert fd["note"] == "2 of 642 vertices" and fd["rel"] < 1e-4 and fd["cos"] > 0.999999


def test_pose_row_gradient_wrt_camera():
    sc = gb.make_scene("pose")
    specs = [s for s in gb.method_specs(orders=(1,)) if s["method"] in ("exact", "reynolds")]
    rows = gb.measure_scene(sc, "L2", specs, repeat=1)
    assert rows[1]["rel"] < 1e-9


def test_affine_scene_needs_order_2(capsys):
    """Vertex colours affine on screen: Reynolds with 2 points per piece is exact, with 1 it is not."""
    assert gb._model_missing("affine") is None
    rows = gb.bench_gradients(["affine"], weights=["random"], repeat=1, samples=(100,), sigmas=(),
                              steps={torch.float64: (1e-6,)}, fd_vertices=2, plot=None)
    reyn = {r["param"]: r["rel"] for r in rows if r["method"] == "reynolds"}
    assert reyn["order 2"] < 1e-10 < 1e-5 < reyn["order 1"]
    assert "vertex colours" in capsys.readouterr().out


def test_plot_pareto_on_synthetic_rows(tmp_path):
    rows = []
    for scene in ("a", "b"):
        rows.append(dict(scene=scene, weights="random", method="exact", family="exact", param="", ms=10.0, rel=0.0))
        for k, n in enumerate((100, 1000)):
            rows.append(dict(scene=scene, weights="random", method="edge_sampling", family="edge sampling",
                             param=f"{n} smp", ms=5.0 * (k + 1), rel=0.1 / (k + 1)))
        rows.append(dict(scene=scene, weights="random", method="reynolds", family="reynolds", param="order 1",
                         ms=3.0, rel=0.0))                                 # exact: drawn at the floor
    path = tmp_path / "p.png"
    fig = gb.plot_pareto(rows, str(path))
    assert path.stat().st_size > 0 and len([a for a in fig.axes if a.has_data()]) == 2
    with pytest.raises(ValueError):
        gb.plot_pareto([])


def test_the_command_is_registered_and_writes_rows(tmp_path, capsys):
    assert BENCHES["gradients"] is gb
    out = tmp_path / "rows.json"
    assert cli(["gradients", "--scenes", "triangle", "--weights", "random", "--samples", "100", "--sigmas", "1e-4",
                "--repeat", "1", "--plot", "", "--json", str(out)]) == 0
    rows = json.loads(out.read_text())
    assert {r["scene"] for r in rows} == {"triangle"} and rows[0]["method"] == "exact"
    text = capsys.readouterr().out
    assert "× exact" in text and "rel L2" in text


def test_vs_mitsuba_skips_or_runs_without_failing_the_rest(capsys):
    """Without Mitsuba (or without a working LLVM for it) the bench says why and runs the rest."""
    pytest.importorskip("matplotlib")
    rows = gb.bench_gradients(["triangle"], weights=["random"], repeat=1, samples=(100,), sigmas=(1e-4,),
                              steps={torch.float64: (1e-6,)}, plot=None, vs="mitsuba", mitsuba_spp=(4,))
    out = capsys.readouterr().out
    assert any(r["method"] == "exact" for r in rows)
    mitsuba = [r for r in rows if r["method"] == "mitsuba"]
    if mitsuba:
        assert "agree to Monte Carlo noise" in out and mitsuba[0]["cos"] > 0.9
    else:
        assert "--vs mitsuba: skipped" in out or "DISAGREE" in out
