"""The linear co-simulation model against mathematics: solver stability limits, exact solution,
convergence order of polynomial extrapolation."""

import numpy as np
import pytest

from master.evidence import linear
from master.evidence.linear import LinearComponent, LinearScheme, largest_stable_step, step_matrix
from master.evidence.oscillator import SET_A, SET_A_V1_10, SET_A_X1_10, SET_A_Z0, split_scheme


def test_oscillator_exact_solution_matches_published_values():
    z = SET_A.exact(10.0, SET_A_Z0)[0]
    assert z[0] == pytest.approx(SET_A_X1_10, rel=1e-12)
    assert z[1] == pytest.approx(SET_A_V1_10, rel=1e-12)


def _dahlquist(solver: int, lam: float = -1.0) -> LinearScheme:
    c = LinearComponent(
        "d", np.array([[lam]]), np.zeros((1, 0)), np.eye(1), np.zeros((1, 0)), (), ("x",), solver=solver
    )
    return LinearScheme((c,), ())


@pytest.mark.parametrize(
    "solver, limit",
    [(linear.EULER, 2.0), (linear.AB2, 1.0), (linear.AB3, 6.0 / 11.0), (linear.RK4, 2.785)],
)
def test_solver_stability_limits_on_negative_real_axis(solver, limit):
    h = largest_stable_step(_dahlquist(solver), 1e-3, 10.0, rel_tol=1e-5)
    assert h == pytest.approx(limit, rel=1e-3)


@pytest.mark.parametrize("solver", [linear.SI_EULER, linear.SI_MIDPOINT])
def test_semi_implicit_solvers_stable_far_past_explicit_limit(solver):
    g = step_matrix(_dahlquist(solver, lam=-1e4), 1.0)  # z = -1e4
    assert np.max(np.abs(np.linalg.eigvals(g))) < 1.0


def _max_error(scheme, n_steps, t_end):
    """Max |x1 - exact| over the macro points of the scheme started on the exact solution."""
    h = t_end / n_steps
    g = step_matrix(scheme, h)
    lay = linear._Layout(scheme)
    z = np.zeros(lay.size)
    z[0] = 1.0
    past = SET_A.exact(-h * np.arange(scheme.order + 1), SET_A_Z0)
    z[lay.samples["mass1"]] = past[:, :2].ravel()  # x1, v1 at t_0 - i h
    z[lay.samples["mass2"]] = past[:, 2:].ravel()  # x2, v2
    exact = SET_A.exact(np.linspace(0.0, t_end, n_steps + 1), SET_A_Z0)[:, 0]
    err = 0.0
    for i in range(1, n_steps + 1):
        z = g @ z
        err = max(err, abs(z[0] - exact[i]))
    return err


@pytest.mark.parametrize("order", [0, 1, 2, 3])
def test_polynomial_extrapolation_converges_with_order_k_plus_1(order):
    errs = [_max_error(split_scheme(order=order, inputs="polynomial"), n, 10.0) for n in (200, 400)]
    observed = np.log2(errs[0] / errs[1])
    assert observed == pytest.approx(order + 1, abs=0.2)


@pytest.mark.parametrize(
    "split, order, solvers, ratios, first",
    [
        ("displacement", 3, (3, 5), (1, 20), ()),
        ("force", 2, (3, 1), (1, 5), ()),
        ("force", 1, (2, 6), (3, 1), ()),
        ("force", 2, (3, 1), (1, 5), ("mass2", "mass1")),  # Gauss-Seidel, either order
        ("force", 3, (3, 6), (1, 20), ("mass1", "mass2")),
    ],
)
def test_linear_model_reproduces_the_runtime(split, order, solvers, ratios, first):
    """The runtime on the msd FMUs and the linear model of its scheme agree to round-off, so the
    spectral radius of the model's macro-step map is the stability criterion of the runtime."""
    import dataclasses
    from fractions import Fraction

    from master.api import run
    from master.evidence.oscillator import scene

    h = Fraction(1, 20)
    sc = scene(
        split=split, macro_step=h, order=order, solvers=solvers, step_ratios=ratios, stop_time=Fraction(5)
    )
    if first:
        sc = dataclasses.replace(sc, coupling="gauss-seidel", order=first)
    data = run(sc).data
    lin = dataclasses.replace(
        split_scheme(order=order, solvers=solvers, step_ratios=ratios, split=split), first=first
    )
    z = linear.simulate(lin, {"mass1": SET_A_Z0[:2], "mass2": SET_A_Z0[2:]}, float(h), 100)
    for i, name in enumerate(("mass1.x", "mass1.v", "mass2.x", "mass2.v")):
        assert np.max(np.abs(data[name] - z[:, i])) < 1e-12


def test_monolithic_matrix_of_the_split_is_the_oscillator():
    for split in ("force", "displacement"):
        a = linear.monolithic_matrix(split_scheme(SET_A, split=split))
        assert np.allclose(a, SET_A.matrix())


def _windowed() -> LinearScheme:
    """Two-mass oscillator with a stiff coupling spring (cc = 100 N/m), displacement split, RK4,
    order 1, held inputs: its stability has windows (unstable, stable again, ...) as H grows."""
    import dataclasses

    return split_scheme(dataclasses.replace(SET_A, cc=100.0), split="displacement", order=1)


def test_largest_stable_step_is_the_first_crossing_of_a_scan_with_windows():
    scheme = _windowed()
    hs = np.linspace(0.01, 0.5, 500)  # an independent dense eigenvalue scan
    grows = [not linear.is_stable(scheme, h) for h in hs]
    first = int(np.argmax(grows))
    assert 0 < first and not all(grows[first:]), "the scan must show a window (unstable, then stable)"
    h = largest_stable_step(scheme, 0.01, 3.0, rel_tol=1e-4)
    assert hs[first - 1] <= h < hs[first]
    assert linear.is_stable(scheme, h) and not linear.is_stable(scheme, h * (1 + 2e-4))


def test_largest_stable_step_does_not_jump_over_a_narrow_window():
    # from 0.2 s (stable, between windows) the first crossing is at 0.2213 s: unstable up to
    # 0.2532 s (rho 1.125 at 0.245 s), stable again until 0.2893 s
    scheme = _windowed()
    assert linear.spectral_radius(scheme, 0.245) > 1.1 and linear.is_stable(scheme, 0.27)
    assert largest_stable_step(scheme, 0.2, 3.0) == pytest.approx(0.2213, abs=2e-4)


@pytest.mark.parametrize("order", [0, 1, 2, 3])
@pytest.mark.parametrize("solvers", [(4, 4), (3, 1)])
def test_linear_model_reproduces_the_runtime_with_interpolated_inputs_at_ratio_4(order, solvers):
    """mass2 interpolates its inputs at step ratio 4: the runtime gives it one doStep per macro
    step with its inputs as polynomials and four solver steps inside; the model, one component
    with substeps 4 and polynomial inputs, agrees to round-off. `linearize` models it so too."""
    from fractions import Fraction

    from master.api import run
    from master.evidence.oscillator import scene
    from master.evidence.stability import linearize

    h = Fraction(1, 20)
    sc = scene(split="force", macro_step=h, order=order, solvers=solvers, step_ratios=(1, 4),
               interpolate=(False, True), substeps=1, stop_time=Fraction(5))  # fmt: skip
    data = run(sc).data
    lin = split_scheme(
        order=order, solvers=solvers, substeps=(1, 4), inputs=("hold", "polynomial"), split="force"
    )
    z = linear.simulate(lin, {"mass1": SET_A_Z0[:2], "mass2": SET_A_Z0[2:]}, float(h), 100)
    for i, name in enumerate(("mass1.x", "mass1.v", "mass2.x", "mass2.v")):
        assert np.max(np.abs(data[name] - z[:, i])) < 1e-12
    mass2 = linearize(sc).components[1]
    assert (mass2.step_ratio, mass2.substeps, mass2.input_mode) == (1, 4, "polynomial")
