"""Fault diagnosis: intensities relative to commissioning, the verdict's rules, the report."""

import numpy as np
import pytest

from pymc_vcc.studies.diagnose import FAULTS, NAMED, Fault, verdict


def test_intensity_is_relative_to_commissioning_or_the_fault_parameter_itself():
    draws = {"M0": np.array([1.8, 1.5]), "HTC_CA": np.array([40.0, 50.0]),
             "FO_FLOW": np.array([0.6, 0.3]), "P_NCG": np.array([2e4, 6e4])}  # fmt: skip
    commissioned = {"M0": 2.0, "HTC_CA": 50.0, "FO_FLOW": 0.5}
    by_name = {fault.name: fault for fault in FAULTS}
    under = by_name["undercharge"].intensity(draws, commissioned)
    assert under == pytest.approx([0.10, 0.25])
    assert by_name["overcharge"].intensity(draws, commissioned) == pytest.approx([-0.10, -0.25])
    # the larger of the two moves of the condenser's air side
    fouling = by_name["condenser fouling or low outdoor airflow"].intensity(draws, commissioned)
    assert fouling == pytest.approx([0.2, 0.4])
    assert by_name["non-condensable gas"].intensity(draws, commissioned) == pytest.approx(
        [2e4, 6e4]
    )
    rising = Fault("x", ("M0",), +1, 0.1)
    assert rising.intensity(draws, commissioned) == pytest.approx([-0.1, -0.25])


def test_every_standard_fault_is_diagnosed_from_a_parameter_of_the_cycle():
    from pymc_vcc.physics.unit import load_unit

    unit = load_unit()
    known = set(unit.parameters.ids) | set(unit.faults.ids)
    assert {pid for fault in FAULTS for pid in fault.parameters} <= known
    for fault in FAULTS:
        if not fault.relative:  # a fault parameter: a healthy unit has 0
            assert all(unit.faults[pid].nominal == 0.0 for pid in fault.parameters)
            assert all(fault.threshold < unit.faults[pid].high for pid in fault.parameters)


def test_verdict_names_one_several_none_or_the_pair_it_cannot_separate():
    quiet = dict.fromkeys(("a", "b", "c"), 0.01)
    assert verdict(quiet) == ("no fault", [])
    assert verdict(quiet | {"b": NAMED}) == ("b", [])
    text, pairs = verdict(quiet | {"a": 0.95, "c": 0.99})
    assert text == "several: a, c" and pairs == []
    text, pairs = verdict(quiet | {"a": 0.55, "c": 0.45})  # together likely, neither alone
    assert pairs == [("a", "c")] and "not distinguishable" in text
    text, pairs = verdict(quiet | {"a": 0.6})
    assert pairs == [] and text == "no fault named; possible: a"
