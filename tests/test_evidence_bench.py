"""The work-precision bench on the two-mass oscillator scene: quick sweep through the CLI."""

import csv
from pathlib import Path

import pytest

from master.cli import main
from master.evidence.bench import PROFILES, Config, Row, configurations, figure, pareto, speedup

SCENE = Path(__file__).resolve().parents[1] / "docs" / "evidence" / "oscillator" / "oscillator.ssd"


def test_quick_bench_through_the_cli(tmp_path, capsys):
    assert main(["bench", str(SCENE), "--quick", "--repeats", "1", "--out", str(tmp_path)]) == 0
    out = capsys.readouterr().out
    assert "speed-up" in out
    rows = list(csv.DictReader(open(tmp_path / "oscillator-quick.csv")))
    assert len(rows) == len(configurations(PROFILES["oscillator"], quick=True))
    assert (tmp_path / "oscillator-quick.png").stat().st_size > 10_000
    stable = [r for r in rows if r["stable"] == "True"]
    unstable = [r for r in rows if r["stable"] == "False"]
    assert unstable and unstable[0]["macro_step_s"] == "0.5"  # kept in the table, marked
    # the linear analysis agrees: spectral radius of the macro-step map above 1 only there
    assert float(unstable[0]["rho_linear"]) > 1.0
    assert all(float(r["rho_linear"]) < 1.0 for r in stable)
    assert any(r["pareto"] == "True" for r in stable)
    for r in stable:
        # coupling errors of these steps: between 1e-4 and 5 % of the variables' range
        assert 1e-4 < float(r["error_max"]) < 0.05
        assert float(r["wall_time_s"]) > 0


def _row(t: float, e: float, stable: bool = True) -> Row:
    return Row(Config("x", 1), t, [t], e, e, "v", stable, "finished")


def test_pareto_front_and_speedup():
    base = _row(1.0, 0.1)
    rows = [base, _row(0.5, 0.2), _row(0.3, 0.05), _row(0.2, 0.5), _row(0.1, 1e-3, stable=False)]
    rows[2] = Row(Config("y", 2), 0.3, [0.3], 0.05, 0.05, "v", True, "finished")
    assert [(r.wall_time, r.error) for r in pareto(rows)] == [(0.2, 0.5), (0.3, 0.05)]
    b, best = speedup(rows, base.config)
    assert b is base and best.wall_time == pytest.approx(0.3)


def crowded_tick_labels(axis) -> list[tuple[str, str]]:
    """The pairs of shown tick labels (major and minor) of a drawn axis closer than half a label's
    height (they overlap or touch)."""
    ticks = axis.get_majorticklabels() + axis.get_minorticklabels()
    boxes = [(t.get_text(), t.get_window_extent()) for t in ticks if t.get_visible() and t.get_text()]
    pad = [box.padded(box.height / 4) for _, box in boxes]
    return [
        (boxes[i][0], boxes[j][0])
        for i in range(len(boxes))
        for j in range(i + 1, len(boxes))
        if pad[i].overlaps(pad[j])
    ]


def test_the_plot_labels_wall_times_within_a_decade_apart():
    """The hydraulic scene's quick sweep spans 4 ms to 75 ms: matplotlib's labels of the minor
    ticks there ("3x10^-2", "4x10^-2") ran into each other; 1, 2, 5 per decade do not."""
    rows = [
        _row(t, e) for t, e in ((0.0038, 0.1), (0.016, 0.04), (0.03, 0.02), (0.053, 0.04), (0.0755, 1e-3))
    ]
    fig = figure(rows, "work-precision")
    fig.canvas.draw()
    for axis in (fig.axes[0].xaxis, fig.axes[0].yaxis):
        shown = [t.get_text() for t in axis.get_majorticklabels() if t.get_visible() and t.get_text()]
        assert len(shown) >= 3 and crowded_tick_labels(axis) == [], shown


def test_bench_works_on_any_scene_and_writes_under_results(tmp_path, capsys, monkeypatch):
    """A scene without a profile: a sweep derived from the scenario (its macro step and orders),
    written to results/bench-SCENE/ under the current folder (never into tracked files), named."""
    scene = Path(__file__).resolve().parent / "scenarios" / "step_force.ssd"
    monkeypatch.chdir(tmp_path)
    assert main(["bench", str(scene), "--quick", "--repeats", "1"]) == 0
    out = capsys.readouterr().out
    assert "wrote results/bench-step_force/" in out
    rows = list(csv.DictReader(open(tmp_path / "results" / "bench-step_force" / "step_force-quick.csv")))
    steps = sorted(float(r["macro_step_s"]) for r in rows)
    assert len(rows) == 4 and steps[-1] == pytest.approx(8 * steps[0])  # 2 H and H / 4 around its H
    # a smaller macro step gives a smaller coupling error (first order in H at order 0)
    by_step = {float(r["macro_step_s"]): float(r["error_max"]) for r in rows if r["order"] == "0"}
    assert by_step[min(by_step)] < by_step[max(by_step)]


def test_bench_names_a_bad_scenario_in_one_line(tmp_path, capsys):
    assert main(["bench", str(tmp_path / "nothing.ssd")]) == 1
    err = capsys.readouterr().err
    assert err.startswith("error:") and "nothing.ssd" in err and len(err.strip().splitlines()) == 1
