"""The fit benchmark (course.bench.fit): its camera problem, its rows and table, its options; never its timings.
Every run here is ``--fast`` (tiny fits): the rows must be well formed, the numbers are not the course's."""
import argparse
import json
import math

import pytest
import torch

from course import inverse as fit
from course.bench import BENCHES, cli
from course.bench import fit as fb

@pytest.fixture(autouse=True)
def one_thread():
    """One torch thread while a test fits (steadier on a shared machine), restored afterwards."""
    threads = torch.get_num_threads()
    torch.set_num_threads(1)
    yield
    torch.set_num_threads(threads)


KEYS = {"application", "method", "steps", "seconds", "metric", "unit", "start", "final", "target", "better", "met"}


def check_rows(rows):
    for r in rows:
        assert set(r) == KEYS, r
        assert isinstance(r["steps"], int) and r["steps"] > 0 and r["seconds"] >= 0
        assert math.isfinite(r["start"]) and math.isfinite(r["final"]) and r["better"] in ("higher", "lower")
        assert r["met"] == (r["final"] >= r["target"] if r["better"] == "higher" else r["final"] <= r["target"])


def test_registered():
    assert BENCHES["fit"] is fb and fb.REPEAT == 1 and fb.DESCRIPTION


def test_cli_fast_camera_rows_every_method(tmp_path, capsys):
    out = tmp_path / "fit.json"
    assert cli(["fit", "--fast", "--only", "camera", "--threads", "1", "--json", str(out)]) == 0
    rows = json.loads(out.read_text())
    check_rows(rows)
    textured = ["soft, render() reference, defaults", "soft, render() reference, one start"]
    assert [r["method"] for r in rows] == [m for m in list(fit.CAMERA_METHODS) + textured for _ in range(2)]
    assert [r["metric"] for r in rows[:2]] == ["rotation error", "centre error"]
    flat = len(fit.CAMERA_METHODS) * 2
    assert all(r["start"] == pytest.approx(30.0, abs=1e-6) for r in rows[:flat:2])   # camera_problem: 30° off
    # the textured start: orbited 45° about x by look_at, which keeps the camera upright: 39° of rotation
    assert all(r["start"] == pytest.approx(39.06, abs=0.01) for r in rows[flat::2])
    assert all(r["steps"] == 5 for r in rows)
    hard = [r for r in rows if r["method"] == "hard"]                       # autograd alone: the pose never moves
    assert all(r["final"] == pytest.approx(r["start"]) for r in hard)
    assert rows[0]["target"] == 2.0 and rows[0]["better"] == "lower"
    printed = capsys.readouterr().out
    assert "| application | method | steps |" in printed and printed.count("| camera |") == len(rows)


def test_fast_mesh_views_and_texture_rows():
    lines = []
    rows = fb.bench_fit(["mesh", "views", "texture"], fast=True, out=lines.append)
    check_rows(rows)
    mesh = [r for r in rows if r["application"] == "mesh"]
    metrics = ("held-out IoU", "self-intersections", "Chamfer (of the diagonal)", "normal consistency")
    assert [(r["method"], r["metric"]) for r in mesh] == [
        (m, metric) for m in ("soft", "soft, smoothness=0", "soft, large steps") for metric in metrics]
    assert mesh[0]["start"] == mesh[4]["start"] == mesh[8]["start"]         # one seed, one start
    assert mesh[1]["start"] == 0 and mesh[1]["unit"] == "pairs"             # the start sphere is embedded
    assert mesh[2]["unit"] == "%" and mesh[2]["start"] > 1 and 0 < mesh[3]["start"] <= 1
    assert all(0 <= r["final"] <= 1 for r in rows if r["metric"] == "held-out IoU")
    assert [r["method"] for r in rows if r["application"] == "views"] == ["ring (fixed)", "learned views"]
    texture = [r for r in rows if r["application"] == "texture"]
    assert [r["method"] for r in texture] == ["texture, checker target", "vertex colours, checker target",
                                              "vertex colours, vertex-coloured target"]
    assert all(r["unit"] == "dB" and r["final"] > r["start"] for r in texture)
    assert not [line for line in lines if line.startswith("note:")]
    assert lines[-1].startswith("| application")


def test_fast_starts_rows():
    rows = fb.bench_fit(["starts"], fast=True, out=lambda line: None)
    check_rows(rows)
    assert [r["method"] for r in rows[::2]] == list(fb.START_VARIANTS)
    assert all(r["unit"] == "deg" and r["start"] >= 0 for r in rows[::2])
    assert all(r["unit"] == "of 2" and 0 <= r["final"] <= 2 for r in rows[1::2])             # --fast: two starts


def test_fast_images_rows_and_picture(tmp_path):
    """The mesh from images: five fits, five metrics each, each fit's start its own (the hull, or the sphere);
    --figure writes the README's picture (two rows of three)."""
    lines = []
    rows = fb.bench_fit(["images"], fast=True, out=lines.append, figure=str(tmp_path / "fit.png"))
    check_rows(rows)
    metrics = ("held-out IoU", "held-out PSNR", "self-intersections", "Chamfer (of the diagonal)", "normal consistency")
    assert [(r["method"], r["metric"]) for r in rows] == [(label, m) for label, _ in fb.IMAGE_FITS for m in metrics]
    hull = [r["start"] for r in rows if r["metric"] == "Chamfer (of the diagonal)"]
    assert hull[0] == hull[1] == hull[2] == hull[4] == hull[5] != hull[3]   # the sphere starts elsewhere
    assert rows[0]["target"] == 0.96 and all(r["steps"] <= 3 for r in rows)
    from PIL import Image
    with Image.open(tmp_path / "fit.png") as im:
        assert im.size[0] > im.size[1] > 0
    assert f"wrote {tmp_path / 'fit.png'}" in lines


def test_table_and_options():
    rows = [dict(application="camera", method="soft", steps=150, seconds=2.5, metric="rotation error", unit="deg",
                 start=30.0, final=0.97, target=2.0, better="lower", met=True),
            dict(application="mesh", method="soft", steps=300, seconds=40.0, metric="held-out IoU", unit="",
                 start=0.66, final=0.89, target=0.9, better="higher", met=False)]
    table = fb.format_table(rows).splitlines()
    assert table[2] == "| camera | soft | 150 | 2.5 | rotation error | 30.00 deg | 0.97 deg | ≤ 2.00 deg | yes |"
    assert table[3] == "| mesh | soft | 300 | 40.0 | held-out IoU | 0.660 | 0.890 | ≥ 0.900 | no |"
    assert fb._applications("mesh, camera") == ["mesh", "camera"]
    with pytest.raises(argparse.ArgumentTypeError, match="unknown application"):
        fb._applications("mesh,teapots")
    with pytest.raises(ValueError, match="unknown application"):
        fb.bench_fit(["teapots"])


def test_fast_batch_rows():
    """A camera batch against its views one by one, side by side: per renderer a time row (ms, one by one ->
    batched) and a speed-up row; the numbers are the machine's, only their form is checked."""
    rows = fb.bench_fit(["batch"], fast=True, out=lambda line: None)
    check_rows(rows)
    labels = ("soft silhouettes + gradient", "soft colours + gradient", "exact image + colour gradient",
              "Reynolds gradient")
    assert [r["method"] for r in rows] == [f"{label}, 4 views at 16²" for label in labels for _ in range(2)]
    for timed, ratio in zip(rows[::2], rows[1::2]):
        assert (timed["unit"], ratio["unit"], timed["steps"], ratio["start"]) == ("ms", "x", 4, 1.0)
        assert timed["target"] == timed["start"] and ratio["final"] == pytest.approx(timed["start"] / timed["final"])
