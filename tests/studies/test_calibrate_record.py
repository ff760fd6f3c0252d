"""A record's calibration: whose coils made it, and the sampler under its error budget."""

import warnings

import numpy as np
import pytest
import xarray as xr

from pymc_vcc.execution.executors import make_executor
from pymc_vcc.studies import unit_log
from pymc_vcc.studies.truths import generate_truth
from pymc_vcc.studies.unit_log import REJECTION_MAIN, REJECTION_PILOT, calibrate_record


@pytest.fixture(scope="module")
def truth():
    return generate_truth("model", seed=5, charge=1.4, t_end=400.0)


def test_unknown_coils_or_method_are_refused_before_any_simulation(truth):
    for wrong, message in (({"coils": "coarse"}, "coils 'coarse': allowed are"),
                           ({"method": "mcmc"}, "method 'mcmc': allowed are")):  # fmt: skip
        with pytest.raises(ValueError, match=message):
            calibrate_record(truth.observed, truth.inputs, None, **wrong)


@pytest.mark.slow
@pytest.mark.parametrize("method", ["likelihood", "rejection"])
def test_the_models_own_data_is_calibrated_without_a_coil_offset(truth, method):
    """``coils="model"``: no offset runs, no unit charge beside the model's, two runs per
    model-error draw, the likelihood's posterior refined under the sensors alone; every
    simulation counted, by either sampler."""
    with make_executor("processes", 2) as executor:
        tree = calibrate_record(
            truth.observed,
            truth.inputs,
            executor,
            draws=16,
            error_draws=12,
            coils="model",
            method=method,
            seed=3,
        )
    stats = tree["sample_stats"]
    assert "M0_model" not in tree["posterior"] and "coil_offset_kg" not in stats
    predictive = min(24, tree["posterior"]["M0"].size)
    fixed = 2 * 12 + predictive  # the model-error draws and the predictive check
    if method == "likelihood":  # the SMC under the model's error, then the exact stage's fits
        exact = int(stats["exact_simulations"])
        sampled = int(stats["simulations"].sum() + stats["resumed_simulations"].sum())
        assert exact > 0 and int(stats["n_simulations"]) == sampled + exact + fixed
    else:  # no exact stage; the main phase runs to its end
        assert int(stats["exact_simulations"]) == 0
        sampled = 16 * (REJECTION_PILOT + REJECTION_MAIN)
        assert int(stats["n_simulations"]) == sampled + fixed
    charge = tree["posterior"]["M0"]
    assert 0.9 <= float(charge.min()) < float(charge.max()) <= 2.2  # accuracy: the benchmark
    # the record travels with its posterior: a later analysis can read it again
    assert tree["observed_data"].to_dataset().equals(truth.observed)
    assert tree["constant_data"].to_dataset().equals(truth.inputs)


def test_a_later_record_takes_a_prior_or_a_commissioning_posterior_not_both():
    import xarray as xr

    from pymc_vcc.physics.unit import load_unit
    from pymc_vcc.studies.unit_log import box_prior

    prior = box_prior(load_unit(), ["M0"])
    with pytest.raises(ValueError, match="a prior or a commissioning posterior, not both"):
        calibrate_record(None, None, None, prior=prior, commissioning=xr.DataTree())  # type: ignore[arg-type]


def _checked(seed: int, misfits: list[bool], p_values: list[float]) -> xr.DataTree:
    """A calibration's tree as far as its attempts are judged: the check per output."""
    outputs = ["TS", "TE"][: len(misfits)]
    stats = xr.Dataset(
        {
            "ppc_z_mean": ("output", np.zeros(len(outputs))),
            "ppc_p_value": ("output", p_values),
            "ppc_misfit": ("output", np.array(misfits, dtype=float)),
            "n_simulations": 100 + seed,
        },
        coords={"output": outputs},
    )
    return xr.DataTree.from_dict({"posterior": xr.Dataset({"seed": seed}), "sample_stats": stats})


def _attempts_of(monkeypatch, checks):
    """Make each calibration of seed k return ``checks[k]`` (misfits, p-values), warning when
    a sensor is missed; return the seeds calibrated."""
    seeds = []

    def calibrate_once(observed, inputs, executor, *, seed, **options):
        seeds.append(seed)
        misfits, p_values = checks[seed]
        if any(misfits):
            warnings.warn(f"seed {seed} misses a sensor", stacklevel=2)
        return _checked(seed, misfits, p_values)

    monkeypatch.setattr(unit_log, "calibrate_once", calibrate_once)
    return seeds


def test_a_failed_predictive_check_calibrates_again_from_the_next_seed(monkeypatch):
    seeds = _attempts_of(
        monkeypatch, {5: ([True, False], [0.001, 0.5]), 6: ([False, False], [0.2, 0.4])}
    )
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        tree = calibrate_record(None, None, None, attempts=3, seed=5)
    assert seeds == [5, 6]  # stops at the first that reproduces every sensor
    assert int(tree["posterior"]["seed"]) == 6
    assert int(tree["sample_stats"]["check_attempts"]) == 2
    assert int(tree["sample_stats"]["n_simulations"]) == 105 + 106
    assert not [w for w in caught if "misses a sensor" in str(w.message)]


def test_when_every_attempt_fails_the_best_check_is_kept_with_its_warning(monkeypatch):
    seeds = _attempts_of(
        monkeypatch,
        {
            0: ([True, True], [0.001, 0.002]),
            1: ([True, False], [0.003, 0.5]),
            2: ([True, False], [0.004, 0.5]),
        },
    )
    with pytest.warns(UserWarning, match="seed 2 misses a sensor") as caught:
        tree = calibrate_record(None, None, None, attempts=3)
    assert seeds == [0, 1, 2]
    assert int(tree["posterior"]["seed"]) == 2  # one misfit, and the larger smallest p-value
    assert len([w for w in caught if "misses a sensor" in str(w.message)]) == 1


def test_one_attempt_keeps_a_failed_check_and_none_is_refused(monkeypatch):
    seeds = _attempts_of(monkeypatch, {0: ([True], [0.001])})
    with pytest.warns(UserWarning, match="misses a sensor"):
        tree = calibrate_record(None, None, None)
    assert seeds == [0] and int(tree["sample_stats"]["check_attempts"]) == 1
    with pytest.raises(ValueError, match="attempts must be at least 1, got 0"):
        calibrate_record(None, None, None, attempts=0)


def test_a_later_records_model_error_is_drawn_mostly_at_the_unit_as_commissioned(
    truth, monkeypatch
):
    """The model-error draws of a later record hold each fault with about
    ERROR_FAULT_PROBABILITY (a healthy unit's error shapes the budget), not with the SMC
    reference's REFERENCE_FAULT_PROBABILITY."""
    from pymc_vcc.physics.unit import load_unit
    from pymc_vcc.studies.faults import (
        ERROR_FAULT_PROBABILITY,
        FAULTS,
        REFERENCE_FAULT_PROBABILITY,
    )

    class Drawn(Exception):
        pass

    def capture(model, observed, prior, executor, rng, *, thetas, **options):
        raise Drawn(dict(zip(prior.names, thetas.T, strict=True)))

    monkeypatch.setattr(unit_log, "error_budget", capture)
    unit = load_unit()
    rng = np.random.default_rng(0)
    posterior = xr.Dataset(
        {
            spec.id: (("chain", "draw"), spec.nominal * (1 + 0.01 * rng.standard_normal((1, 64))))
            for spec in unit.parameters
        }
    )
    commissioning = xr.DataTree.from_dict({"posterior": posterior})
    with pytest.raises(Drawn) as drawn, warnings.catch_warnings():
        warnings.simplefilter("ignore")  # the commissioning holds no record: said apart
        calibrate_record(
            truth.observed, truth.inputs, None, commissioning=commissioning, coils="model",
            error_draws=2000,
        )  # fmt: skip
    draws = drawn.value.args[0]
    for fault in FAULTS:
        if fault.relative:  # the calibration parameters' faults: read against commissioning
            continue
        beyond = float(np.mean(draws[fault.parameters[0]] >= fault.threshold))
        assert beyond < 2 * ERROR_FAULT_PROBABILITY < REFERENCE_FAULT_PROBABILITY, fault.name
        assert beyond > ERROR_FAULT_PROBABILITY / 4, fault.name  # the faults are still drawn


def test_a_later_round_draws_half_its_model_error_where_the_first_round_did():
    """A later record's second round draws its model error half at the first round's draws
    (the unit as commissioned, mostly) and half at the first round's posterior; a first
    round draws at one set alone."""
    rng = np.random.default_rng(0)
    first, posterior = np.zeros((40, 3)), np.ones((30, 3))
    mixed = unit_log._error_thetas(first, posterior, 11, rng)
    assert mixed.shape == (11, 3)
    assert (mixed[:, 0] == 0).sum() == 5 and (mixed[:, 0] == 1).sum() == 6
    assert (unit_log._error_thetas(first, first, 11, rng) == 0).all()
    assert (unit_log._error_thetas(None, posterior, 11, rng) == 1).all()
    assert unit_log._error_thetas(first, None, 11, rng) is None


ROUND_CHARGE = 1.4  # kg: every draw of the stand-in rounds' posteriors


def _stand_in_rounds(monkeypatch, budget, warn=None):
    """Calibrations whose error budget is ``budget``, whose sampler returns a posterior of
    ``ROUND_CHARGE`` alone (calling ``warn(particles)`` first) and whose check passes."""

    def sample(method, model, observed, budget, prior, particles, *rest):
        if warn is not None:
            warn(particles)
        posterior = xr.Dataset({"M0": (("chain", "draw"), np.full((1, particles), ROUND_CHARGE))})
        return xr.DataTree.from_dict({"posterior": posterior, "sample_stats": xr.Dataset()}), 0

    def check(tree, model, budget, executor, rng):
        return {name: dict.fromkeys(unit_log.PPC_KEYS, 0.0) for name in budget.outputs}, 0

    monkeypatch.setattr(unit_log, "error_budget", budget)
    monkeypatch.setattr(unit_log, "_sample", sample)
    monkeypatch.setattr(unit_log, "_predictive_check", check)


def test_a_first_records_second_round_draws_half_its_model_error_over_the_box(truth, monkeypatch):
    """A first record calibrated in two rounds: the first round's model error is drawn over
    the prior (the budget draws it), the second's half at the first round's posterior and half
    over the prior again (at the posterior alone, the budget was too narrow for the unit: every
    such commissioning failed its predictive check)."""
    from types import SimpleNamespace

    from pymc_vcc.physics.unit import load_unit

    drawn = []

    def budget(model, observed, prior, executor, rng, *, thetas, **options):
        drawn.append(thetas)
        return SimpleNamespace(n_draws=12, n_failed=0, outputs=list(observed.data_vars))

    _stand_in_rounds(monkeypatch, budget)
    prior = unit_log.box_prior(load_unit(), ["M0"])
    calibrate_record(
        truth.observed, truth.inputs, None, prior=prior, draws=96, error_draws=40, rounds=2,
        coils="model", method="rejection",
    )  # fmt: skip
    assert drawn[0] is None  # over the prior, by the budget
    second = drawn[1][:, 0]
    assert len(second) == 40 and (second == ROUND_CHARGE).sum() == 20
    low, high = prior.bounds["M0"]
    box = second[second != ROUND_CHARGE]
    assert ((low <= box) & (box <= high)).all() and box.std() > 0.2 * (high - low)


def test_only_the_last_rounds_posterior_quality_is_reported(truth, monkeypatch):
    """A scouting round's posterior only places the next round's model error: its posterior
    quality warnings are not shown (its 48 particles at the small budget hold an ESS of 24 by
    design), the last round's are, and other warnings of either round too."""
    from types import SimpleNamespace

    from pymc_vcc.inference.pymc.smc import PosteriorQualityWarning
    from pymc_vcc.physics.unit import load_unit

    def budget(model, observed, prior, executor, rng, **options):
        return SimpleNamespace(n_draws=12, n_failed=0, outputs=list(observed.data_vars))

    def warn(particles):
        warnings.warn(f"{particles} particles: few", PosteriorQualityWarning, stacklevel=2)
        warnings.warn(f"{particles} particles: other", UserWarning, stacklevel=2)

    _stand_in_rounds(monkeypatch, budget, warn)
    prior = unit_log.box_prior(load_unit(), ["M0"])
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        calibrate_record(
            truth.observed, truth.inputs, None, prior=prior, draws=96, rounds=2,
            coils="model", method="rejection",
        )  # fmt: skip
    shown = {str(w.message) for w in caught}
    assert shown == {"48 particles: other", "96 particles: few", "96 particles: other"}
