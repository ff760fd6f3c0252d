"""A record's calibration: whose coils made it, and the sampler under its error budget."""

import pytest

from pymc_vcc.execution.executors import make_executor
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
