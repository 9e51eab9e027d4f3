"""Error measures on trajectories with known differences."""

import numpy as np
import pytest

from master.evidence.errors import Trajectory, compare


def test_scaled_max_and_end_errors():
    t = np.linspace(0.0, 1.0, 11)
    ref = Trajectory(t, {"a": np.sin(t), "b": 10.0 * t, "c": np.full_like(t, 5.0)})
    res = Trajectory(t, {"a": np.sin(t) + 0.01 * t, "b": 10.0 * t + 0.5, "c": np.full_like(t, 5.25)})
    rep = compare(res, ref)
    assert rep.max_error["a"] == pytest.approx(0.01 / np.sin(1.0))
    assert rep.max_error["b"] == pytest.approx(0.05)  # 0.5 over a range of 10
    assert rep.max_error["c"] == pytest.approx(0.25)  # constant reference: range taken as 1
    assert rep.end_error["a"] == pytest.approx(0.01 / np.sin(1.0))
    assert rep.worst_max == pytest.approx(0.25) and rep.worst_max_variable == "c"
    assert rep.n_times == 11


def test_grids_are_compared_at_shared_times_only():
    tr = np.linspace(0.0, 2.0, 201)
    ref = Trajectory(tr, {"y": tr**2})
    t = np.linspace(0.0, 2.0, 5)
    rep = compare(Trajectory(t, {"y": t**2 + 0.04}), ref)
    assert rep.worst_max == pytest.approx(0.01)  # 0.04 over a range of 4
    assert rep.n_times == 5
    fine = np.linspace(0.0, 2.0, 401)  # finer result: only the reference's times count
    rep = compare(Trajectory(fine, {"y": fine**2 + np.where(np.arange(401) % 2, 1.0, 0.0)}), ref)
    assert rep.worst_max == 0.0 and rep.n_times == 201
    with pytest.raises(ValueError, match="share no time"):
        compare(Trajectory(t + 0.123, {"y": t}), ref)


def test_non_finite_result_is_infinite_error():
    t = np.linspace(0.0, 1.0, 3)
    rep = compare(Trajectory(t, {"y": np.array([0.0, np.nan, 1.0])}), Trajectory(t, {"y": t}))
    assert rep.worst_max == np.inf and rep.worst_end == np.inf


def test_missing_variable_is_named():
    t = np.linspace(0.0, 1.0, 3)
    with pytest.raises(ValueError, match="'z' missing in the result"):
        compare(Trajectory(t, {"y": t}), Trajectory(t, {"y": t, "z": t}), ["z"])
    with pytest.raises(ValueError, match="3 values for 2 times"):
        Trajectory(t[:2], {"y": t})
