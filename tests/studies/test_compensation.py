"""A later record's model error, drawn where the commissioning calibration left the model."""

import numpy as np
import pytest
from scipy.special import logit

from pymc_vcc.inference.error_model import SensorAccuracy
from pymc_vcc.physics.simulate import VCCSimulator
from pymc_vcc.physics.unit import load_unit
from pymc_vcc.studies.record_budget import (
    FIXED_SPREAD,
    Commissioning,
    ErrorPair,
    compensate,
    fixed_spread,
    held_inputs,
)
from pymc_vcc.studies.truths import generate_truth
from pymc_vcc.studies.unit_log import SETTLE

NAMES = ["M0", "CF_LEV", "HTC_CA", "FO_FLOW"]


@pytest.fixture(scope="module")
def record():
    truth = generate_truth("model", seed=3, charge=1.5, t_end=600.0)
    unit = load_unit()
    model = VCCSimulator(
        unit, held_inputs(truth.inputs), t_window=(0.0, 600.0), parameters=NAMES, settle=SETTLE
    )
    return unit, model, truth.observed


def _draws(unit, model, centre, rng, n):
    """Units off the model in their held parameters and sensors, as commissioned at ``centre``."""
    theta = dict(zip(NAMES, map(float, centre), strict=True))
    held = fixed_spread(unit, NAMES, FIXED_SPREAD)
    return [
        {
            "theta": theta,
            "theta_c": theta,
            "fixed": {pid: float(rng.uniform(lo, hi)) for pid, (lo, hi) in held.items()},
            "input_errors": {},
            "lags": np.zeros(len(model.output_names)),
            "fineness": 0.0,
            "biases": rng.uniform(-1.0, 1.0, len(model.output_names)),
        }
        for _ in range(n)
    ]


@pytest.mark.slow
def test_a_compensation_moves_the_commissionings_parameters_inside_their_bounds(record):
    """Each draw's model moves by what the commissioning calibration would absorb of its unit:
    only the commissioning's parameters (a fault parameter of the later record stays), inside
    their bounds, differently for different units, the same unit by the same move of the
    bounds' logits wherever its later parameters lie; a unit whose commissioning run fails gets
    no compensation and fails."""
    from pymc_vcc.execution.executors import make_executor

    unit, model, observed = record
    rng = np.random.default_rng(1)
    centre = np.array([unit.parameter_spec(n).nominal for n in NAMES])
    centre[0] = 1.5
    posterior = centre * (1.0 + 0.01 * rng.standard_normal((64, len(NAMES))))
    commissioning = Commissioning(model, observed, posterior)
    draws = _draws(unit, model, centre, rng, 14)
    for draw in draws:
        draw["theta"] = {**draw["theta"], "DP_RESTR": 5000.0}
    draws[0]["theta_c"] = {**draws[0]["theta_c"], "M0": -1.0}  # cannot run
    # the unit of draws[1] once more, its later condenser HTC near the bound
    draws[2] = {**draws[1], "theta": {**draws[1]["theta"], "HTC_CA": 11.0}}
    with make_executor("processes", 2) as executor:
        compensate(draws, commissioning, executor, SensorAccuracy())
    assert draws[0]["model_theta"] is None
    shifts = []
    for draw in draws[1:]:
        moved = draw["model_theta"]
        assert set(moved) == {*NAMES, "DP_RESTR"} and moved["DP_RESTR"] == 5000.0
        for name in NAMES:
            spec = unit.parameter_spec(name)
            assert spec.low <= moved[name] <= spec.high
        shifts.append([moved[n] - draw["theta"][n] for n in NAMES])
    spread = np.std(shifts, axis=0) / [
        unit.parameter_spec(n).high - unit.parameter_spec(n).low for n in NAMES
    ]
    assert np.all(spread > 1e-4)  # each parameter moves, by unit
    # the same unit's move is the same in the bounds' logits: smaller near a bound
    low, high = unit.parameter_spec("HTC_CA").low, unit.parameter_spec("HTC_CA").high
    logit_moves = [
        logit((d["model_theta"]["HTC_CA"] - low) / (high - low))
        - logit((d["theta"]["HTC_CA"] - low) / (high - low))
        for d in draws[1:3]
    ]
    assert logit_moves[0] == pytest.approx(logit_moves[1], rel=1e-9)
    moves = [abs(d["model_theta"]["HTC_CA"] - d["theta"]["HTC_CA"]) for d in draws[1:3]]
    assert moves[1] < 0.5 * moves[0]


def test_a_draws_sensor_biases_shift_the_unit_by_their_share_of_the_bound(record):
    unit, model, observed = record
    accuracy = SensorAccuracy()
    pair = ErrorPair(model, unit, observed["time"].values, accuracy)
    draw = _draws(unit, model, [1.5, 1.0, 60.0, 0.8], np.random.default_rng(2), 1)[0]
    draw["fixed"] = {}
    shares = np.zeros(len(model.output_names))
    shares[model.output_names.index("TD")] = 1.0
    shares[model.output_names.index("PD")] = -0.5
    unbiased, _ = pair({**draw, "biases": np.zeros_like(shares)})
    biased, _ = pair({**draw, "biases": shares})
    shift = biased - unbiased
    td, pd = model.output_names.index("TD"), model.output_names.index("PD")
    assert shift[td] == pytest.approx(np.full(shift.shape[1], accuracy.temperature))  # K
    relative, _ = accuracy.bias_bound("Pa")
    np.testing.assert_allclose(shift[pd], -0.5 * relative * unbiased[pd], rtol=1e-12)
    others = [j for j in range(len(shares)) if j not in (td, pd)]
    assert np.all(shift[others] == 0.0)
