"""The physics over the Table III box, small: laws, ranges, stillness, charge observability.

``scripts/probe_physics.py`` runs the same probes at full size (200 draws, every 0.1 kg step
on the rating point and the built-in profile); the figures are in models/README.md.
"""

import numpy as np
import pytest

from pymc_vcc.physics.probes import (
    OSCILLATION_LIMIT,
    box_probe,
    charge_observability,
    check_draw,
    noise_sd,
    rated_inputs,
    separation,
)
from pymc_vcc.physics.simulate import simulate
from pymc_vcc.physics.unit import load_unit


@pytest.fixture(scope="module")
def unit():
    return load_unit()


def test_noise_in_engineering_terms():
    assert noise_sd("TD", 350.0) == 0.3
    assert noise_sd("PC", 27e5) == pytest.approx(13.5e3)
    assert noise_sd("MDOT", 0.02) == pytest.approx(2e-4)
    run = simulate(t_end=20.0)
    assert separation(run, run) == dict.fromkeys(separation(run, run), 0.0)


def test_air_ranges_follow_the_box(unit):
    ranges = unit.cycle_model.box_ranges(unit)
    assert ranges["V_air_out"] == (0.5, 1.5) and ranges["V_air_in"] == (0.1, 0.8)
    assert ranges["W_fans"] == (100.0, 1000.0)


def test_a_dozen_box_draws_hold_every_law(unit):
    reports = box_probe(12, seed=7, unit=unit)
    failed = [r for r in reports if not r.holds]
    assert not failed, failed
    assert all(r.oscillation < 1e-3 and r.mass_error < 1e-4 for r in reports)


@pytest.mark.parametrize("draw", [82, 181])
def test_no_limit_cycle_at_high_two_phase_htc(unit, draw):
    """Box draws (seed 0) whose coil cell holding the dew point, between a two-phase HTC 6-12
    times the vapour one, cycled at N = 10 (PC peak-to-peak 7.6e-3 and 0.13) are still."""
    theta = unit.parameters.sample_uniform(draw + 1, np.random.default_rng(0))[draw]
    report = check_draw(unit, theta)
    assert report.holds and report.oscillation < OSCILLATION_LIMIT, report


def test_charge_held_through_a_violent_start_up(unit):
    """The box draw whose start-up lost most charge with the C¹ density fillet (3.5e-4 at
    12 s, as a condenser cell stepped through the bubble-line band) holds it to 1e-4."""
    theta = unit.parameters.sample_uniform(65, np.random.default_rng(0))[64]
    run = simulate(unit, theta, rated_inputs(unit, 60.0), diagnostics=True)
    assert run.attrs["status"] == "ok" and run.attrs["mass_error"] < 1e-4


def test_charge_stays_observable_when_the_tank_fills(unit):
    """Above 1.6 kg the excess charge sits in the suction tank: each 0.1 kg step must still
    move an output by more than two noise standard deviations at the rating point."""
    rows = charge_observability([1.6, 1.7, 1.8, 1.9, 2.0, 2.1, 2.2], unit)
    moved = np.array([row[3] for row in rows])
    assert np.all(moved > 2.0), rows
