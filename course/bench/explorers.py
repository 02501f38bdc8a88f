"""The explorers' benchmark: ``python -m course bench explorers [--only NAME ...]``.

Every lecture explorer of ``course.viz.explorers`` redrawn as a slider moves: its ``draw_*`` function called
with each control at its lowest and highest value in turn (the others at their defaults), and the figure
rendered to a PNG as the notebook's inline backend does (Agg, at the explorers' ``FIGURE_SCALE`` times the
default resolution, the figure closed each time). ``first`` is the first call at the defaults, which also computes what the explorer keeps (a fit's
snapshots, a landscape); ``median`` and ``max`` are over the slider moves after that, each move timed
``--repeat`` times. Explorers marked ``live`` redraw while a slider is dragged (they should stay under
200 ms); the others redraw when it is released, their controls greyed out meanwhile.
"""
from __future__ import annotations

import io
import statistics
import time

__all__ = ["slider_moves", "measure", "bench_explorers", "add_arguments", "run"]

REPEAT = 3
DESCRIPTION = "the lecture explorers' redraw time as a slider moves (median and worst over the sliders' ends)"
BUDGET_MS = 200.0


def slider_moves(controls: dict) -> list[dict]:
    """Each control moved in turn, the others left at their defaults: a slider to its lowest and its highest
    value, a checkbox flipped, a drop-down to each of its other options."""
    moves = []
    for name, spec in controls.items():
        if isinstance(spec, bool):
            ends = [not spec]
        elif isinstance(spec, list):
            ends = spec[1:]
        else:
            ends = [spec[0], spec[1]]
        moves += [{name: v} for v in ends]
    return moves


def _redraw(draw, values, dpi):
    import matplotlib.pyplot as plt
    start = time.perf_counter()
    out = draw(**values)
    fig = plt.gcf()
    fig.savefig(io.BytesIO(), format="png", dpi=dpi, bbox_inches="tight")   # what the inline backend does
    elapsed = 1000 * (time.perf_counter() - start)
    plt.close("all")
    return elapsed, out


def measure(repeat: int = REPEAT, only=None) -> list[dict]:
    """Rows: explorer, live, first (ms), median (ms), max (ms), moves, and the line of its defaults."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from ..viz.explorers import EXPLORERS, FIGURE_SCALE
    dpi = FIGURE_SCALE * plt.rcParams["figure.dpi"]
    rows = []
    for name, (_, draw, controls, live) in EXPLORERS.items():
        if only and not any(word.lower() in name.lower() for word in only):
            continue
        first, out = _redraw(draw, {}, dpi)
        moves = slider_moves(controls)
        for values in moves:                                                # fills what each value keeps
            _redraw(draw, values, dpi)
        times = [_redraw(draw, values, dpi)[0] for values in moves for _ in range(repeat)]
        rows.append(dict(explorer=name, live=live, first=first, median=statistics.median(times), max=max(times),
                         moves=len(moves), line=out["line"]))
    return rows


def bench_explorers(repeat: int = REPEAT, only=None) -> list[dict]:
    rows = measure(repeat, only)
    print(f"redraw: draw_* and its PNG (Agg, tight bounding box); median and max over each control's ends, "
          f"{repeat} runs each; budget {BUDGET_MS:.0f} ms for live explorers")
    print(f"{'explorer':<24} {'redraws':>8} {'first ms':>9} {'median ms':>10} {'max ms':>8}  verdict")
    for r in rows:
        verdict = ("ok" if r["max"] < BUDGET_MS else "over budget") if r["live"] else "on release, greyed out"
        print(f"{r['explorer']:<24} {'live' if r['live'] else 'release':>8} {r['first']:>9.0f} {r['median']:>10.0f} "
              f"{r['max']:>8.0f}  {verdict}")
    return rows


def add_arguments(parser) -> None:
    parser.add_argument("--only", nargs="+", default=None,
                        help="explorers whose name contains one of these words (e.g. 03 soft)")


def run(args) -> list[dict]:
    return bench_explorers(args.repeat, args.only)
