"""Truth generators: each variant differs from the inference model the way it says."""

import numpy as np
import pytest

from pymc_vcc.physics.simulate import VCCSimulator
from pymc_vcc.physics.unit import load_unit
from pymc_vcc.studies.truths import (
    DRIFT,
    FINE_VOLUMES,
    VARIANTS,
    WEAR,
    WEARING,
    generate_truth,
    record_again,
    worn_parameters,
)

CHARGE = 1.4


@pytest.fixture(scope="module")
def truths():
    return {v: generate_truth(v, seed=7, charge=CHARGE) for v in VARIANTS}


def test_each_variant_differs_as_it_says(truths):
    model, unit = truths["model"], load_unit()
    assert model.n_volumes == 10 and not model.lags and not model.biases
    assert all(t.n_volumes in FINE_VOLUMES for v, t in truths.items() if v != "model")
    # a finer condenser holds its pressure differently: far beyond the noise (0.5 %)
    pd_gap = abs(float(truths["fine"].observed["PD"].mean() - model.observed["PD"].mean()))
    assert pd_gap > 5e3
    assert all(5.0 <= tau <= 30.0 for tau in truths["lag"].lags.values())
    assert abs(truths["bias"].biases["TD"]) <= 0.5
    assert abs(truths["bias"].biases["PD"]) <= 0.01 * float(model.observed["PD"].max())
    logged = truths["inputs"].inputs["T_ambient"].values - model.inputs["T_ambient"].values
    assert 0 < np.abs(logged).max() <= 0.5 + 0.5 / 3
    drifted = truths["drift"].parameters
    for spec in unit.parameters:
        if spec.id != "M0" and spec.low < spec.nominal * (1 - DRIFT):
            assert abs(drifted[spec.id] / spec.nominal - 1) <= (spec.tolerance or DRIFT) + 1e-12
    lengths = [spec for spec in unit.parameters if spec.tolerance is not None]
    assert lengths and all(  # a length does not drift: it is off within its stated tolerance
        abs(drifted[spec.id] / spec.nominal - 1) <= spec.tolerance for spec in lengths
    )
    assert drifted != {spec.id: spec.nominal for spec in unit.parameters}
    everything = truths["all"]
    assert everything.lags and everything.biases
    assert all(t.charge == CHARGE for t in truths.values())


def test_a_record_starts_from_the_steady_state_at_its_first_inputs():
    """Settled 600 s or 1200 s: the same first outputs (steady); unsettled: a start-up."""
    runs = {
        s: VCCSimulator(t_window=(0.0, 100.0), solver="cvode", settle=s)({"M0": 1.5})
        for s in (0.0, 600.0, 1200.0)
    }
    for name, tol in (("TD", 0.05), ("PD", 2e3), ("TS", 0.05)):
        first = {s: float(run[name].values[0]) for s, run in runs.items()}
        assert first[600.0] == pytest.approx(first[1200.0], abs=tol)
        assert abs(first[0.0] - first[600.0]) > 10 * tol
    assert runs[600.0]["time"].values[0] == 0.0
    with pytest.raises(ValueError, match="unknown truth variant"):
        generate_truth("wet", seed=1)


@pytest.mark.slow
def test_a_second_round_draws_the_model_error_at_the_first_posterior():
    from pymc_vcc.execution.executors import make_executor
    from pymc_vcc.studies.unit_log import calibrate_record

    truth = generate_truth("fine", seed=3, charge=CHARGE, t_end=400.0)
    with make_executor("processes", 2) as executor:
        tree = calibrate_record(
            truth.observed, truth.inputs, executor, draws=16, error_draws=12, rounds=2, seed=1
        )
        with pytest.raises(ValueError, match="rounds"):
            calibrate_record(truth.observed, truth.inputs, executor, rounds=0)
    stats = tree["sample_stats"]
    assert int(stats["error_rounds"]) == 2 and int(stats["error_draws"]) >= 10
    smc = int(stats["simulations"].sum())
    assert int(stats["n_simulations"]) >= smc + 2 * 3 * 12  # both rounds' model-error draws
    assert 0.9 <= float(tree["posterior"]["M0"].mean()) <= 2.2


def test_a_later_record_keeps_the_units_sensors_and_logger():
    """Months later the same sensors read: the same lags, biases and constant input errors,
    only the noise is new."""
    first = generate_truth("all", seed=8, charge=CHARGE, t_end=300.0)
    later = record_again(first, 9, first.parameters)
    assert later.n_volumes == first.n_volumes and later.parameters == first.parameters
    assert later.observed["time"].values[-1] == 300.0
    assert later.lags == first.lags and later.biases == first.biases
    assert later.input_offsets == first.input_offsets and first.input_offsets
    assert not np.array_equal(later.observed["TD"].values, first.observed["TD"].values)
    fresh = generate_truth("all", seed=9, charge=CHARGE, t_end=300.0, parameters=first.parameters)
    assert fresh.biases != first.biases
    longer = record_again(first, 9, first.parameters, seconds=420.0)
    assert longer.observed["time"].values[-1] == 420.0 and longer.biases == first.biases
    assert longer.input_offsets == first.input_offsets
    # another day: the profile from 120 s on, whose compressor starts at 65 Hz, not 55 Hz
    elsewhere = record_again(first, 9, first.parameters, seconds=300.0, start=120.0)
    assert elsewhere.observed["time"].values[-1] == 300.0 and elsewhere.lags == first.lags
    logged = 0.02  # the logger's relative error on a speed is within 1 % + 1/3 %
    assert float(first.inputs["compressor_speed"][0]) == pytest.approx(55.0, rel=logged)
    assert float(elsewhere.inputs["compressor_speed"][0]) == pytest.approx(65.0, rel=logged)


def test_a_month_of_wear_moves_the_wearing_parameters_a_little_and_nothing_else():
    unit = load_unit()
    healthy = {spec.id: spec.nominal for spec in unit.parameters} | {"M0": 1.5}
    worn = [worn_parameters(unit, healthy, np.random.default_rng(k)) for k in range(200)]
    for pid, value in healthy.items():
        ratios = np.array([w[pid] for w in worn]) / value
        if pid in WEARING:  # spread over the whole ±WEAR, never beyond
            assert np.all(np.abs(ratios - 1) <= WEAR) and np.ptp(ratios) > 1.8 * WEAR, pid
        else:
            assert np.all(ratios == 1), pid
    again = worn_parameters(unit, healthy, np.random.default_rng(0))
    assert again == worn[0]
