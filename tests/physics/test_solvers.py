"""The two ODE solvers: exact on a linear test problem, failures returned not raised, and the same
cycle outputs on the Fig. 4 profile at nominal and over draws from the Table III box."""

import time
from dataclasses import replace

import numpy as np
import pytest
from numba import carray, cfunc, njit
from scipy.linalg import expm

from pymc_vcc.physics.cycles import OUTPUT_IDS
from pymc_vcc.physics.failures import FailureKind
from pymc_vcc.physics.integration.segments import make_solver
from pymc_vcc.physics.integration.solver import (
    CVODE,
    DIFFERENCING_TOLERANCE_SCALE,
    METHODS,
    RADAU,
    Solver,
    get_solver,
)
from pymc_vcc.physics.integration.sundials import (
    JAC_SIGNATURE,
    RHS_SIGNATURE,
    Callbacks,
    dense_matrix_data,
    vector_data,
)
from pymc_vcc.physics.simulate import VCCSimulator, simulate
from pymc_vcc.physics.unit import load_unit

# a stiff linear system y' = A y (time constants 0.01 s to 10 s), exact solution expm(A t) y0
A = np.array([[-100.0, 1.0, 0.0], [0.0, -1.0, 0.5], [0.0, 0.0, -0.1]])
Y0 = np.array([1.0, 2.0, 3.0])


@njit
def _linear(a, limit, y, dydt):
    """y' = A y while y[0] < limit; beyond it y[0]' = 1 and the rest is not finite (a property
    that left its table). Returns whether dydt is finite."""
    for i in range(3):
        dydt[i] = a[i, 0] * y[0] + a[i, 1] * y[1] + a[i, 2] * y[2] if y[0] < limit else np.nan
    if limit < np.inf:
        dydt[0] = 1.0
    return bool(np.isfinite(dydt).all())


@cfunc(RHS_SIGNATURE)
def _linear_c(t, y_vector, dydt_vector, user_data):
    data = carray(user_data, (10,), np.float64)
    ok = _linear(
        data[:9].reshape((3, 3)), data[9], vector_data(y_vector, 3), vector_data(dydt_vector, 3)
    )
    return 0 if ok else 1


@cfunc(JAC_SIGNATURE)
def _linear_jac_c(t, y_vector, f_vector, matrix, user_data, tmp1, tmp2, tmp3):
    a = carray(user_data, (9,), np.float64).reshape((3, 3))
    dense_matrix_data(matrix, 3)[:, :] = a.T  # row j holds column j
    return 0


class Linear:
    """The linear system as both solvers take it (a SegmentModel); past ``limit`` its
    right-hand side is not finite."""

    def __init__(self, limit=np.inf):
        self.data = np.append(A.ravel(), limit)
        self.bad_rhs = 0
        self.u = np.zeros(0)  # no inputs

    def rhs(self, y, dydt):
        return _linear(A, self.data[9], y, dydt)

    def jac(self, y, f):
        return A.copy()

    def c_callbacks(self):
        return Callbacks(_linear_c.address, _linear_jac_c.address, self.data.ctypes.data, self)


TIGHT = {"radau": (1e-6, 1e-9), "cvode": (1e-7, 1e-11)}
"""(rtol, atol) per method on the linear problem: BDF at a tenth of the rtol, as by default."""


def _solver(method):
    rtol, atol = TIGHT[method]
    solver = replace(get_solver(method), rtol=rtol, max_step=5.0)
    return make_solver(solver, atol=np.full(3, atol), wall_limit=10.0)


@pytest.mark.parametrize("method", METHODS)
def test_linear_problem_matches_the_matrix_exponential(method):
    solver = _solver(method)
    t_out = np.linspace(0.5, 20.0, 40)
    states = np.full((t_out.size, 3), np.nan)
    linear = Linear()
    y_end, failure = solver.integrate(
        linear, Y0, 0.0, 20.0, t_out, states, time.perf_counter() + 10.0
    )
    assert failure is None
    exact = np.array([expm(A * t) @ Y0 for t in t_out])
    np.testing.assert_allclose(states, exact, rtol=1e-4, atol=1e-6)
    np.testing.assert_allclose(y_end, exact[-1], rtol=1e-4, atol=1e-6)
    counters = solver.counters
    assert counters.n_rhs > 0 and counters.n_jac > 0 and counters.n_steps > 0
    assert counters.bad_rhs == 0
    # a second segment continues from the first, counters add up
    n_rhs, n_steps = counters.n_rhs, counters.n_steps
    later = np.full((1, 3), np.nan)
    _, failure = solver.integrate(
        linear, y_end, 20.0, 30.0, np.array([30.0]), later, time.perf_counter() + 10
    )
    assert failure is None and solver.counters.n_rhs > n_rhs and solver.counters.n_steps > n_steps
    np.testing.assert_allclose(later[0], expm(A * 30.0) @ Y0, rtol=1e-4, atol=1e-6)


@pytest.mark.parametrize("method", METHODS)
def test_failures_come_back_with_their_kind(method, capfd):
    t_out = np.array([1.0, 2.0])
    late = np.full((2, 3), np.nan)
    _, failure = _solver(method).integrate(
        Linear(), Y0, 0.0, 2.0, t_out, late, time.perf_counter() - 1.0
    )
    assert failure is not None and failure.kind == FailureKind.TIME_LIMIT
    assert "wall-clock limit" in failure.detail and np.isnan(late).all()

    states = np.full((2, 3), np.nan)
    solver = _solver(method)
    _, failure = solver.integrate(
        Linear(limit=1.5), Y0, 0.0, 2.0, t_out, states, time.perf_counter() + 10.0
    )
    assert failure is not None and failure.kind in (FailureKind.SOLVER, FailureKind.NON_FINITE)
    assert np.isnan(states).all()  # y[0] passes 1.5 at t = 0.5
    if method == "cvode":  # CVODE retried shorter steps and then named what failed
        assert "RHSFUNC" in failure.detail, failure.detail
    assert capfd.readouterr() == ("", "")  # nothing on screen


def test_unknown_method_names_the_choices():
    with pytest.raises(ValueError, match=r"one of \['radau', 'cvode'\], got 'rk4'"):
        get_solver("rk4")
    with pytest.raises(ValueError, match=r"one of \['radau', 'cvode'\], got 'rk4'"):
        replace(RADAU, method="rk4")


def test_a_name_stands_for_its_methods_default_and_a_solver_for_itself():
    assert get_solver() is RADAU and get_solver("radau") is RADAU
    assert get_solver("cvode") is CVODE
    tight = replace(CVODE, rtol=1e-7)
    assert get_solver(tight) is tight
    with pytest.raises(TypeError, match="a method name or a Solver"):
        get_solver(3)  # type: ignore[arg-type]
    assert get_solver("cvode", rtol=1e-7) == tight and get_solver(tight, rtol=1e-5) == CVODE
    with pytest.raises(ValueError, match=r"unknown solver field\(s\) \['atol'\]; allowed are"):
        get_solver("radau", atol=1.0)


@pytest.mark.parametrize("name", ["rtol", "atol_pressure", "atol_enthalpy", "max_step"])
@pytest.mark.parametrize("value", [0.0, -1.0, float("inf"), float("nan"), True, "1e-4"])
def test_solver_values_must_be_finite_positive_numbers(name, value):
    with pytest.raises(ValueError, match=f"solver {name}: expected a"):
        replace(RADAU, **{name: value})


def test_scaled_scales_rtol_and_every_atol_alone():
    tight = RADAU.scaled(DIFFERENCING_TOLERANCE_SCALE)
    for name in ("rtol", "atol_pressure", "atol_enthalpy", "atol_temperature", "atol_integral"):
        assert getattr(tight, name) == pytest.approx(0.1 * getattr(RADAU, name))
    assert (tight.method, tight.max_step) == (RADAU.method, RADAU.max_step)
    with pytest.raises(ValueError, match="tolerance scale must be positive, got 0"):
        RADAU.scaled(0)


def test_a_solver_reads_as_its_method_at_the_default_and_in_full_otherwise():
    assert (str(RADAU), str(CVODE)) == ("radau", "cvode")
    assert str(replace(CVODE, rtol=1e-7)) == (
        "cvode (rtol=1e-07, atol_pressure=0.2, atol_enthalpy=0.05, atol_temperature=0.0001, "
        "atol_integral=1e-06, max_step=60)"
    )
    assert Solver("radau", 1e-4, 20.0, 5.0, 0.01, 1e-4, 60.0) == RADAU


def test_simulate_runs_the_solver_it_is_given():
    by_name = simulate(t_end=60.0, solver="cvode")
    tight = replace(CVODE, rtol=1e-7)
    by_value = simulate(t_end=60.0, solver=tight)
    assert by_name.attrs["solver"] == "cvode" and by_value.attrs["solver"] == str(tight)
    assert by_value.attrs["n_rhs"] > by_name.attrs["n_rhs"]  # tighter: more work
    assert simulate(t_end=60.0, solver=CVODE).equals(by_name)


def _outputs(run):
    return np.column_stack([run[name].values for name in OUTPUT_IDS])


def _difference(a, b):
    """Largest difference of each output, relative to that output's largest magnitude."""
    return np.abs(_outputs(a) - _outputs(b)).max(axis=0) / np.abs(_outputs(a)).max(axis=0)


def test_solvers_agree_on_the_fig4_profile_at_nominal():
    # a generous wall-clock limit: the test must not depend on how busy the machine is
    runs = [simulate(solver=method, max_wall_time=600.0) for method in METHODS]
    assert all(run.attrs["status"] == "ok" for run in runs), [r.attrs for r in runs]
    # measured: 6e-5 at most; each solver is within ~1e-4 of an rtol 1e-8 reference
    assert _difference(*runs).max() < 5e-4


@pytest.mark.slow
def test_solvers_agree_over_box_draws():
    """50 draws, 1060 s: both solve the same draws; all draws but one agree to 4 % of each
    output's largest magnitude, 90 % of them to 0.1 %. (Measured: median 1.5e-4, 90th
    percentile 3.6e-4, second worst 2.7e-3.)"""
    unit = load_unit()
    simulators = [
        VCCSimulator(unit, t_window=(0.0, 1060.0), solver=method, max_wall_time=600.0)
        for method in METHODS
    ]
    differences = []
    for theta in unit.parameters.sample_uniform(50, np.random.default_rng(7)):
        radau, cvode = (simulator(theta) for simulator in simulators)
        assert radau.attrs["status"] == cvode.attrs["status"], (theta, cvode.attrs)
        if radau.attrs["status"] == "ok":
            differences.append(_difference(radau, cvode).max())
    assert len(differences) >= 45
    # the one exception, draw 16, differs by 11 % over ~240 s: against an rtol 1e-7 reference
    # (Radau, tolerances / 1000, max step 5 s) Radau at its default tolerances is 11 % off and
    # CVODE 3.9 %, so there the reference solver needs tighter tolerances (open in issue 15)
    assert sorted(differences)[-2] < 4e-2
    assert np.quantile(differences, 0.9) < 1e-3


def test_a_scikit_sundae_built_otherwise_is_refused_by_name(monkeypatch):
    """CVODE is called through ctypes with the memory layout of a 32-bit-index SUNDIALS 7:
    another build would corrupt memory, so it is refused before anything is loaded."""
    from sksundae import _cy_common

    from pymc_vcc.physics.integration import sundials

    monkeypatch.setattr(_cy_common, "SUNDIALS_INT_TYPE", "long int")
    with pytest.raises(ImportError, match=r"SUNDIALS_INT_TYPE = 'int'.*built with 'long int'"):
        sundials._library_folder()
