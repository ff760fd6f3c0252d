"""Fault diagnosis: intensities relative to commissioning, the verdict's rules, the report."""

import numpy as np
import pytest

from pymc_vcc.studies.diagnose import NAMED, verdict
from pymc_vcc.studies.faults import FAULTS


def test_intensity_is_relative_to_commissioning_or_the_fault_parameter_itself():
    draws = {"M0": np.array([1.8, 1.5]), "P_NCG": np.array([2e4, 6e4])}
    commissioned = {"M0": np.array([2.0, 2.0])}
    by_name = {fault.name: fault for fault in FAULTS}
    under = by_name["undercharge"].intensity(draws, commissioned)
    assert under == pytest.approx([0.10, 0.25])
    assert by_name["overcharge"].intensity(draws, commissioned) == pytest.approx([-0.10, -0.25])
    assert by_name["non-condensable gas"].intensity(draws, commissioned) == pytest.approx(
        [2e4, 6e4]
    )


def test_fouling_and_low_outdoor_airflow_are_one_drop_of_the_condensers_conductance():
    """The data see the condenser's air-side conductance, not its HTC and its airflow apart:
    the fault's intensity is that conductance's drop, which either lowers, less than in
    proportion (ε-NTU)."""
    from pymc_vcc.physics.unit import load_unit
    from pymc_vcc.studies.faults import coil_conductance

    unit = load_unit()
    htc, flow = unit.parameters["HTC_CA"].nominal, unit.parameters["FO_FLOW"].nominal
    healthy = {"HTC_CA": np.array([htc] * 3), "FO_FLOW": np.array([flow] * 3)}
    faulty = {"HTC_CA": np.array([htc, 0.6 * htc, htc]),
              "FO_FLOW": np.array([flow, flow, 0.6 * flow])}  # fmt: skip
    conductance = coil_conductance("condenser", unit, healthy)
    assert 100.0 < conductance[0] < 1e5 and np.ptp(conductance) == 0.0  # W/K
    fault = {f.name: f for f in FAULTS}["condenser fouling or low outdoor airflow"]
    drops = fault.intensity(faulty, healthy, unit)
    assert drops[0] == pytest.approx(0.0, abs=1e-12)
    assert 0.0 < drops[1] < 0.4 and 0.0 < drops[2] < 0.4
    with pytest.raises(ValueError, match="measured on the unit"):
        fault.intensity(faulty, healthy)


def test_every_standard_fault_is_diagnosed_from_a_parameter_of_the_cycle():
    from pymc_vcc.physics.unit import load_unit

    unit = load_unit()
    known = set(unit.parameters.ids) | set(unit.faults.ids)
    assert {pid for fault in FAULTS for pid in fault.parameters} <= known
    for fault in FAULTS:
        if not fault.relative:  # a fault parameter: a healthy unit has 0
            assert all(unit.faults[pid].nominal == 0.0 for pid in fault.parameters)
            assert all(fault.threshold < unit.faults[pid].high for pid in fault.parameters)


def test_the_prior_holds_a_healthy_unit_likelier_than_any_fault():
    """From a commissioning posterior (the model's charge sampled, the unit's beside it), the
    later record's prior puts the charge at the model's, the healthy unit's fault parameters
    far below their thresholds, and each fault beyond its threshold at most its prior
    probability."""
    import xarray as xr

    from pymc_vcc.physics.unit import load_unit
    from pymc_vcc.studies.faults import FAULT_PROBABILITY
    from pymc_vcc.studies.unit_log import later_prior

    unit = load_unit()
    rng = np.random.default_rng(0)
    nominal = {spec.id: spec.nominal for spec in unit.parameters}
    draws = {pid: value * (1 + 0.01 * rng.standard_normal(200)) for pid, value in nominal.items()}
    draws["M0_model"] = draws["M0"] + 0.05
    posterior = xr.Dataset({pid: (("chain", "draw"), v[None]) for pid, v in draws.items()})
    prior = later_prior(xr.DataTree.from_dict({"posterior": posterior}), unit, 0.03, 1)
    sample = prior.sample(20_000, rng)
    column = {name: sample[:, i] for i, name in enumerate(prior.names)}
    assert np.median(column["M0"]) == pytest.approx(nominal["M0"] + 0.05, abs=0.01)
    commissioned = {pid: np.full(len(sample), value) for pid, value in nominal.items()}
    commissioned["M0"] = commissioned["M0"] + 0.05
    for fault in FAULTS:
        beyond = fault.intensity(column, commissioned, unit) >= fault.threshold
        assert np.mean(beyond) <= FAULT_PROBABILITY, fault.name
        if not fault.relative:
            assert np.median(column[fault.parameters[0]]) < fault.threshold / 10, fault.name


def _posterior(draws):
    import xarray as xr

    dataset = xr.Dataset(
        {pid: (("chain", "draw"), np.asarray(v)[None]) for pid, v in draws.items()}
    )
    return xr.DataTree.from_dict({"posterior": dataset})


def test_a_commissioning_posterior_without_the_moved_parameters_is_refused_in_one_line():
    from pymc_vcc.physics.unit import load_unit
    from pymc_vcc.studies.unit_log import later_prior

    with pytest.raises(ValueError, match=r"lacks \['FI_FLOW'\]; calibrate the healthy unit") as e:
        draws = {"M0": 1.5, "HTC_CA": 40.0, "FO_FLOW": 1.0, "HTC_EA": 40.0}  # no FI_FLOW
        later_prior(_posterior({pid: [v] * 8 for pid, v in draws.items()}), load_unit(), 0.03, 0)
    assert "\n" not in str(e.value)


def test_the_leak_alarm_is_the_undercharge_beyond_its_fraction_paired_with_commissioning():
    """Each later draw against a commissioning draw, the loss read with the model's form
    error: a charge 15 % below every commissioning draw sounds the alarm at 0.9 unless the
    form error reads it a third short (P = Φ(0.05 / (0.15 × 0.15)) = 0.987), 5 % below never,
    and against a commissioning posterior spread ±19 % a later charge at its mean sounds it
    about as often as the commissioning draws lie 11 % or more above it (about a fifth: not 0,
    as against the mean alone)."""
    from scipy.stats import norm

    from pymc_vcc.physics.unit import load_unit
    from pymc_vcc.studies.faults import MODEL_FORM
    from pymc_vcc.studies.unit_log import leak_alarm

    unit = load_unit()
    pinned = _posterior({"M0": [1.6] * 100})
    alarm = leak_alarm(_posterior({"M0": [1.6 * 0.85] * 4000}), pinned, unit, 0.9, 0)
    assert alarm == pytest.approx(norm.cdf(0.05 / (0.15 * MODEL_FORM)), abs=1e-9)
    assert leak_alarm(_posterior({"M0": [1.6 * 0.95] * 400}), pinned, unit, 0.9, 0) < 1e-9
    commissioned = np.linspace(1.3, 1.9, 101)
    alarm = leak_alarm(_posterior({"M0": [1.6] * 4000}), _posterior({"M0": commissioned}), unit,
                       0.9, 0)  # fmt: skip
    assert alarm == pytest.approx(np.mean(commissioned >= 1.6 / 0.9), abs=0.04)
    assert alarm > 0.15


def test_the_model_form_spreads_each_intensity_in_proportion_and_zero_leaves_it():
    """Each draw times 1 + N(0, spread²): a fault read at 0.3 for sure spreads to sd 0.3 ×
    spread around 0.3; a reading of 0 stays 0; spread 0 is the model's reading; a negative or
    not finite spread is refused in one line."""
    from pymc_vcc.studies.faults import with_model_form

    read = {"a": np.full(20000, 0.3), "b": np.zeros(20000)}
    spread = with_model_form(read, 0, 0.15)
    assert spread["a"].mean() == pytest.approx(0.3, abs=0.002)
    assert spread["a"].std() == pytest.approx(0.3 * 0.15, rel=0.03)
    assert np.all(spread["b"] == 0.0)
    assert np.array_equal(with_model_form(read, 0, 0.0)["a"], read["a"])
    for bad in (-0.1, float("nan")):
        with pytest.raises(ValueError, match="model form spread") as e:
            with_model_form(read, 0, bad)
        assert "\n" not in str(e.value)


def test_a_faults_probability_integrates_the_form_error_out_as_its_draws_would():
    """beyond_probability is the mean, over many form-error draws, of the share of spread
    draws beyond the threshold (draws above, near and below it, at 0 and negative), without
    their noise; spread 0 is the share of the model's own draws beyond it."""
    from pymc_vcc.studies.faults import beyond_probability, with_model_form

    rng = np.random.default_rng(1)
    read = np.concatenate([rng.normal(0.24, 0.03, 60), np.zeros(20), [-0.1, 0.1, 0.5]])
    exact = beyond_probability(read, 0.2, 0.15)
    drawn = [np.mean(with_model_form({"a": read}, seed, 0.15)["a"] >= 0.2) for seed in range(4000)]
    assert exact == pytest.approx(np.mean(drawn), abs=4 * np.std(drawn) / np.sqrt(len(drawn)))
    assert 0.4 < exact < 0.8 and np.std(drawn) > 0.02  # near a threshold, the draws' noise
    assert beyond_probability(read, 0.2, 0.0) == np.mean(read >= 0.2)
    assert beyond_probability(np.zeros(5), 0.2) == 0.0
    with pytest.raises(ValueError, match="model form spread"):
        beyond_probability(read, 0.2, -0.1)


def test_the_model_form_needed_is_the_conformal_quantile_of_each_cases_spread():
    """A case the model covers alone needs 0; one read at 0.2 ± 0.01 for 0.3 needs
    sqrt((0.1/1.96)² − 0.01²)/0.2 = 0.25; of 39 cases needing 0 and that one, the 95 %
    quantile (rank ⌈41 × 0.95⌉ = 39) is 0, of 18 and two such cases (rank 20 of 20) 0.25;
    five cases cannot vouch for 99 % (rank 6 of 5: infinite); healthy cases are not counted."""
    from pymc_vcc.studies.fault_benchmark import model_form_needed

    def case(mean, sd, truth):
        return {"fault": "x", "model_mean": mean, "model_sd": sd, "true_intensity": truth}

    good, bad = case(0.3, 0.02, 0.31), case(0.2, 0.01, 0.3)
    healthy = {"fault": None}
    assert model_form_needed([good] * 39 + [bad, healthy]) == 0.0
    needed = np.sqrt((0.1 / 1.959964) ** 2 - 0.01**2) / 0.2
    assert model_form_needed([good] * 18 + [bad] * 2) == pytest.approx(needed)
    assert model_form_needed([good] * 5, coverage=0.99) == float("inf")


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


def test_a_lower_naming_probability_names_a_fault_nearer_its_threshold():
    """At 0.7 a fault at 0.75 is named and a pair at 0.4 and 0.35 is not distinguishable; at
    0.9 both are less sure ("possible", "no fault")."""
    quiet = dict.fromkeys(("a", "b", "c"), 0.01)
    assert verdict(quiet | {"a": 0.75}, named=0.7) == ("a", [])
    assert verdict(quiet | {"a": 0.75}, named=0.9) == ("no fault named; possible: a", [])
    assert verdict(quiet | {"a": 0.4, "b": 0.35}, named=0.7)[1] == [("a", "b")]
    assert verdict(quiet | {"a": 0.4, "b": 0.35}, named=0.9) == ("no fault", [])


def test_a_fault_no_other_rivals_is_named_as_likely_from_the_likely_probability():
    """Likely at 0.5: a sole fault at 0.6 is named as likely, not at 0.45, not beside a rival at
    0.2 (nor a pair, neither sure); a fault at 0.9 is named for sure; off, it is only possible."""
    from pymc_vcc.studies.diagnose import LIKELY_PREFIX, RIVAL

    quiet = dict.fromkeys(("a", "b", "c"), 0.01)
    assert verdict(quiet | {"a": 0.6}, likely=0.5) == (LIKELY_PREFIX + "a", [])
    assert verdict(quiet | {"c": 0.5}, likely=0.5) == (LIKELY_PREFIX + "c", [])
    assert verdict(quiet | {"a": 0.45}, likely=0.5) == ("no fault", [])
    rivalled = quiet | {"a": 0.6, "b": RIVAL}
    assert verdict(rivalled, likely=0.5) == ("no fault named; possible: a", [])
    assert verdict(quiet | {"a": 0.6, "b": 0.19}, likely=0.5)[0] == LIKELY_PREFIX + "a"
    assert verdict(quiet | {"a": 0.75, "b": 0.15}, likely=0.5)[0] == LIKELY_PREFIX + "a"
    assert verdict(quiet | {"a": 0.75, "b": 0.15}, likely=None)[1] == [("a", "b")]
    assert verdict(quiet | {"a": 0.95}, likely=0.5) == ("a", [])
    assert verdict(quiet | {"a": 0.6}, likely=None) == ("no fault named; possible: a", [])
    assert verdict(quiet | {"a": 0.6}, named=0.7, likely=0.7) == ("no fault named; possible: a", [])


def test_a_likely_probability_outside_its_range_is_refused_through_the_cli(tmp_path, capsys):
    from pymc_vcc.cli import main

    for likely, named in (("0.4", "0.9"), ("0.95", "0.9"), ("0.8", "0.75")):
        code = main(["diagnose", "no-such.csv", "--prior", "none", "--likely", likely,
                     "--named", named, "--out", str(tmp_path / "d")])  # fmt: skip
        err = capsys.readouterr().err.strip()
        assert code != 0 and f"likely probability must lie in [0.5, {named}]" in err
        assert f"got {float(likely)}" in err
        assert len(err.splitlines()) == 1 and not (tmp_path / "d").exists()
    code = main(["diagnose", "no-such.csv", "--prior", "none", "--likely", "OFF", "--named", "0.3"])
    assert code != 0 and "naming probability must lie" in capsys.readouterr().err  # off parsed
    with pytest.raises(SystemExit) as exit_info:
        main(["diagnose", "no-such.csv", "--prior", "none", "--likely", "often"])
    assert exit_info.value.code != 0
    assert "--likely: must be a number or 'off', got 'often'" in capsys.readouterr().err


def test_a_naming_probability_outside_its_range_is_refused_through_the_cli(tmp_path, capsys):
    from pymc_vcc.cli import main

    for named in ("0.4", "1"):
        code = main(["diagnose", "no-such.csv", "--prior", "none", "--named", named,
                     "--out", str(tmp_path / "d")])  # fmt: skip
        err = capsys.readouterr().err.strip()
        assert code != 0 and f"naming probability must lie in [0.5, 1), got {float(named)}" in err
        assert len(err.splitlines()) == 1 and not (tmp_path / "d").exists()


def test_a_commissioning_the_model_missed_is_named_in_the_report():
    """The outputs whose predictive check failed at commissioning are read from its tree and
    stated under the report (none for a tree written without a check)."""
    import xarray as xr

    from pymc_vcc.studies.diagnose import Diagnosis, commissioning_misfits

    draws = {"M0": [1.5] * 8}
    assert commissioning_misfits(_posterior(draws)) == []
    outputs = ["TD", "PD", "TS"]
    checks = {
        "ppc_z_mean": [0.1, 4.0, -3.0],
        "ppc_p_value": [0.6, 1e-5, 2e-4],
        "ppc_misfit": [0.0, 1.0, 1.0],
    }
    stats = xr.Dataset({k: ("output", v) for k, v in checks.items()}, coords={"output": outputs})
    tree = xr.DataTree.from_dict(
        {"posterior": _posterior(draws)["posterior"].to_dataset(), "sample_stats": stats}
    )
    assert commissioning_misfits(tree) == ["PD", "TS"]
    diagnosis = Diagnosis(
        tree,
        {f.name: np.zeros(8) for f in FAULTS},
        {f.name: 0.0 for f in FAULTS},
        "no fault",
        commissioned={"M0": 1.5},
        unreproduced=["PD", "TS"],
    )
    assert "could not reproduce PD, TS" in diagnosis.format_table().splitlines()[-1]
    assert "form error" not in diagnosis.format_table()  # the model's reading alone
    diagnosis.model_form = 0.15
    assert "the model's form error: ±15 % of each intensity" in diagnosis.format_table()
    assert diagnosis.summary()["commissioning_unreproduced"] == ["PD", "TS"]
    assert "cost at the rating point: not read (every run failed)" in diagnosis.format_table()
    diagnosis.rating = {"capacity": np.array([-0.10, -0.12]), "COP": np.array([-0.05, -0.07])}
    diagnosis.rating_failed = 1
    line = "what the faults cost at the rating point: capacity -11.0 % (-11.9 to -10.1), COP -6.0"
    assert line in diagnosis.format_table() and "1 draw(s) failed" in diagnosis.format_table()
    assert diagnosis.summary()["rating_change"]["COP"]["mean"] == pytest.approx(-0.06)
    assert "(the model's error there included, ±1.2 points, 1 sd)" in diagnosis.format_table()
    first = "verdict: no fault (a fault is named at P(fault) >= 0.9)"
    assert diagnosis.format_table().splitlines()[0] == first
    diagnosis.likely = 0.6
    assert diagnosis.format_table().splitlines()[0] == (
        "verdict: no fault (a fault is named at P(fault) >= 0.9, or as likely at >= 0.6 when no "
        "other reaches 0.2)"
    )
    assert diagnosis.summary()["likely_at"] == 0.6


def test_the_cost_at_the_rating_point_is_spread_by_the_models_error_there():
    """Each draw copied and moved by N(0, s²): the mean kept, the variances added."""
    from pymc_vcc.studies.diagnose import RATING_COPIES, RATING_FORM, with_rating_form

    read = {"COP": np.random.default_rng(1).normal(-0.05, 0.01, 2000)}
    spread = with_rating_form(read, 0)["COP"]
    assert spread.size == 2000 * RATING_COPIES
    assert spread.mean() == pytest.approx(-0.05, abs=5e-4)
    assert spread.std() == pytest.approx(np.hypot(0.01, RATING_FORM), rel=0.03)
    assert np.array_equal(
        with_rating_form(read, 0, 0.0)["COP"], np.repeat(read["COP"], RATING_COPIES)
    )


def test_cases_are_scored_in_yuill_and_brauns_categories():
    from pymc_vcc.studies.fault_benchmark import score

    gas, fouling = "non-condensable gas", "condenser fouling or low outdoor airflow"
    assert score(None, "no fault") == "correct"
    assert score(None, "no fault named; possible: undercharge") == "correct"
    assert score(None, gas) == "false alarm"
    assert score(None, f"{gas} / {fouling}: not distinguishable with these sensors") == (
        "false alarm"
    )
    assert score(gas, gas) == "correct diagnosis"
    assert score(gas, fouling) == "misdiagnosis"
    assert score(gas, f"several: {fouling}, {gas}") == "misdiagnosis"
    assert score(gas, "no fault") == "missed detection"
    assert score(gas, f"{gas} / {fouling}: not distinguishable with these sensors") == (
        "no response"
    )


def test_two_faults_at_once_are_correct_only_when_both_are_named():
    from pymc_vcc.studies.fault_benchmark import score

    gas, short, leak = "non-condensable gas", "undercharge", "compressor valve leakage"
    both = [short, gas]
    assert score(both, f"several: {gas}, {short}") == "correct diagnosis"  # in any order
    assert score(tuple(both), short) == "partial diagnosis"
    assert score(both, gas) == "partial diagnosis"
    assert score(both, leak) == "misdiagnosis"
    assert score(both, f"several: {short}, {leak}") == "misdiagnosis"  # one right, one wrong
    assert score(both, "no fault") == "missed detection"
    assert score(both, f"no fault named; possible: {gas}") == "no response"
    assert score(both, f"{short} / {gas}: not distinguishable with these sensors") == (
        "no response"
    )


def test_rows_are_scored_again_at_another_naming_probability():
    """A gas at 0.8 and a healthy record reading gas at 0.6: at 0.9 a possible gas (no
    response) and no alarm; at 0.75 the gas named; at 0.5 a false alarm as well."""
    from pymc_vcc.studies.fault_benchmark import rescored

    gas = "non-condensable gas"
    rows = [
        {"fault": gas, "probabilities": {gas: 0.8}, "verdict": "", "score": ""},
        {"fault": None, "probabilities": {gas: 0.6}, "verdict": "", "score": ""},
    ]
    scores = {p: [r["score"] for r in rescored(rows, p)] for p in (0.9, 0.75, 0.5)}
    assert scores == {
        0.9: ["no response", "correct"],
        0.75: ["correct diagnosis", "correct"],
        0.5: ["correct diagnosis", "false alarm"],
    }
    assert rows[0]["score"] == ""  # the rows themselves are left as they were


def test_rows_are_scored_again_with_a_likely_fault_named():
    """A gas at 0.8 with nothing else near: possible at 0.9 (no response), named as likely at
    0.5 (correct); a healthy record reading gas at 0.6 is then a false alarm, and a valve leak
    read as likely gas a misdiagnosis."""
    from pymc_vcc.studies.fault_benchmark import rescored

    gas, leak = "non-condensable gas", "compressor valve leakage"
    quiet = {leak: 0.01}
    rows = [
        {"fault": gas, "probabilities": quiet | {gas: 0.8}},
        {"fault": None, "probabilities": quiet | {gas: 0.6}},
        {"fault": leak, "probabilities": quiet | {gas: 0.6}},
    ]
    assert [r["score"] for r in rescored(rows, 0.9)] == ["no response", "correct", "no response"]
    likely = rescored(rows, 0.9, likely=0.5)
    assert [r["verdict"] for r in likely] == [f"likely: {gas}"] * 3
    assert [r["score"] for r in likely] == ["correct diagnosis", "false alarm", "misdiagnosis"]


def test_rows_are_scored_again_at_another_form_error_from_the_models_reads():
    """A gas read 60-70 kPa by the model (threshold 50): at form error 0 every draw is beyond
    it, named; at 0.6 its probability falls under 0.9, possible; rows without the reads are
    refused in one line."""
    from pymc_vcc.studies.fault_benchmark import rescored

    gas = "non-condensable gas"
    row = {"fault": gas, "probabilities": {gas: 0.0}, "model_reads": {gas: [60e3, 65e3, 70e3]}}
    (sharp,) = rescored([row], 0.9, model_form=0.0)
    assert sharp["probabilities"][gas] == 1.0 and sharp["score"] == "correct diagnosis"
    (wide,) = rescored([row], 0.9, model_form=0.6)
    assert 0.5 < wide["probabilities"][gas] < 0.9 and wide["score"] == "no response"
    assert rescored([row], 0.9)[0]["probabilities"][gas] == 0.0  # the row's own
    with pytest.raises(ValueError, match="keep no model_reads"):
        rescored([{"fault": gas, "probabilities": {}}], 0.9, model_form=0.1)


def test_unbiased_naming_moves_each_reading_onto_its_truth_and_keeps_its_width():
    """A 100 kPa gas (threshold 50) read 20-40 kPa: moved onto 100 ± 10 kPa it is beyond 50
    for sure, named; read 40-160 kPa for 60 kPa, moved onto 0-120, 2 of 3 draws are beyond
    (P 2/3 without form error), named at 0.6, not at 0.7 nor 0.9; healthy cases are not
    counted, rows without the reads are refused."""
    from pymc_vcc.studies.fault_benchmark import unbiased_naming

    gas = "non-condensable gas"

    def case(reads, truth):
        return {"fault": gas, "true_intensity": truth, "model_reads": {gas: reads}}

    narrow, wide = case([20e3, 30e3, 40e3], 100e3), case([40e3, 100e3, 160e3], 60e3)
    assert unbiased_naming([narrow, wide, {"fault": None}], 0.9) == 0.5
    assert unbiased_naming([narrow], 0.9, model_form=0.0) == 1.0
    assert unbiased_naming([wide], 0.6, model_form=0.0) == 1.0
    assert unbiased_naming([wide], 0.7, model_form=0.0) == 0.0
    with pytest.raises(ValueError, match="keep no model_reads"):
        unbiased_naming([{"fault": gas}], 0.9)


def test_correct_diagnosis_is_scored_by_the_faults_size_in_thresholds():
    from pymc_vcc.studies.fault_benchmark import correct_by_size

    def row(fault, intensity, score):
        return {"fault": fault, "true_intensity": intensity, "score": score}

    rows = [
        row(None, 0.0, "false alarm"),  # no fault: in no band
        row("liquid-line restriction", 80e3, "no response"),  # 1.6 thresholds
        row("liquid-line restriction", 150e3, "correct diagnosis"),  # 3
        row("undercharge", 0.15, "correct diagnosis"),  # 1.5
        row("undercharge", 0.2, "missed detection"),  # 2
        row("overcharge", 0.3, "correct diagnosis"),  # 3
        row("overcharge", 0.05, "correct diagnosis"),  # below its threshold: in no band
    ]
    assert correct_by_size(rows) == [(1.0, 1.75, 2, 0.5), (1.75, float("inf"), 3, 2 / 3)]
    low, high, cases, share = correct_by_size(rows, (1.0, 1.55, 2.5))[1]
    assert (low, high, cases, share) == (1.55, 2.5, 2, 0.0)
    assert np.isnan(correct_by_size(rows[:1])[0][3])  # no faulted case
    with pytest.raises(ValueError, match="band edges must increase"):
        correct_by_size(rows, (1.75, 1.0))


def test_correct_diagnosis_is_scored_by_what_the_fault_costs():
    """Bands of the larger drop of capacity and COP at the rating point; rows without the
    true cost, with a failed one, or without a fault are in no band."""
    from pymc_vcc.studies.fault_benchmark import (
        FaultBenchmarkResult,
        correct_by_cost,
        cost_band,
        rating_drop,
        summarise_cases,
    )

    def row(fault, capacity, cop, score):
        rating = {"capacity": {"true": capacity}, "COP": {"true": cop}}
        return {"fault": fault, "true_intensity": 0.3, "score": score, "rating": rating,
                "simulations": 1, "seconds": 1.0, "probabilities": {"undercharge": 0.0},
                "severity_error": 0.1, "covered": True, "model_mean": 0.3,
                "model_sd": 0.01}  # fmt: skip

    leak, gas = "compressor valve leakage", "non-condensable gas"
    rows = [
        row(gas, 0.01, -0.02, "no response"),  # costs 2 % of the COP
        row(gas, 0.02, 0.01, "correct diagnosis"),  # both rose: a drop of -1 %
        row(leak, -0.07, -0.03, "correct diagnosis"),  # 7 % of the capacity
        row(leak, -0.16, -0.11, "correct diagnosis"),
        row(leak, -0.12, -0.08, "no response"),
        row(None, -0.20, -0.20, "false alarm"),  # no fault
        row(leak, float("nan"), -0.2, "correct diagnosis"),  # the truth's run failed
    ]
    assert rating_drop(rows[0]["rating"]) == pytest.approx(0.02)
    assert rating_drop(rows[1]["rating"]) == pytest.approx(-0.01)
    inf = float("inf")
    assert correct_by_cost(rows) == [(-inf, 0.05, 2, 0.5), (0.05, 0.1, 1, 1.0), (0.1, inf, 2, 0.5)]
    assert [cost_band(low, high) for low, high, *_ in correct_by_cost(rows)] == [
        "under 5 %", "5-10 %", "10 % or more"
    ]  # fmt: skip
    assert correct_by_cost([*rows, {"fault": leak, "score": "no response"}])[0][2] == 2
    table = summarise_cases(rows)
    assert table["by_cost"] == correct_by_cost(rows)
    printed = FaultBenchmarkResult(rows, table).format_table()
    assert "by what the fault costs at the rating point: 0.50 of 2 at under 5 %; 1.00 of 1" in (
        printed
    )
    without = [{k: v for k, v in r.items() if k != "rating"} for r in rows]
    assert summarise_cases(without)["by_cost"] is None
    assert "costs" not in FaultBenchmarkResult(without, summarise_cases(without)).format_table()


def test_rows_written_before_rows_kept_the_cost_get_it_computed_again():
    """From the unit's seed and the case: a valve leak of 25 % costs a tenth or more of the
    rating (11-17 % on 29 benchmark units); the unit as it was, its wear only (under 1 %); a
    row that keeps its cost is left as it is."""
    from pymc_vcc.studies.fault_benchmark import rating_drop, with_true_rating_change

    def row(case):
        return {"case": case, "unit_seed": 9300, "variant": "all", "score": "correct"}

    kept = row("None: {}") | {"rating": {"capacity": {"true": 0.5}, "COP": {"true": 0.5}}}
    rows = [row("None: {}"), row('compressor valve leakage: {"F_LEAK": 0.25}'), kept]
    healthy, leaking, again = with_true_rating_change(rows)
    assert abs(rating_drop(healthy["rating"])) < 0.01
    assert rating_drop(leaking["rating"]) > 0.10
    assert again is kept and leaking["score"] == "correct" and "rating" not in rows[1]
    with pytest.raises(ValueError, match="unknown case"):
        with_true_rating_change([row('undercharge: {"M0": -0.4}')])


def test_score_table_counts_rates_among_healthy_and_faulted_cases():
    from pymc_vcc.studies.fault_benchmark import summarise_cases

    gas = "non-condensable gas"
    rows = [
        {"fault": None, "score": "false alarm", "simulations": 100, "seconds": 1.0},
        {"fault": None, "score": "correct", "simulations": 100, "seconds": 1.0},
        {"fault": gas, "score": "correct diagnosis", "severity_error": 0.1, "covered": True,
         "simulations": 200, "seconds": 3.0},
        {"fault": gas, "score": "missed detection", "severity_error": 0.5, "covered": False,
         "simulations": 200, "seconds": 5.0},
    ]  # fmt: skip
    for row, p_leak in zip(rows, [0.6, 0.1, 0.0, 0.0], strict=True):
        row |= {"true_intensity": 0.0, "probabilities": {"undercharge": p_leak}}
        row |= {"model_mean": 0.0, "model_sd": 0.0} if row["fault"] is None else {}
    rows[2] |= {"model_mean": 0.1, "model_sd": 0.05}  # covers 0 alone
    rows[3] |= {"model_mean": 0.2, "model_sd": 0.0}  # needs 1 / 1.96
    leaks = [  # the leak alarm: the undercharge's probability above 0.5, per loss
        {"fault": "undercharge", "score": "correct diagnosis", "severity_error": 0.1,
         "covered": True, "simulations": 200, "seconds": 3.0, "true_intensity": loss,
         "probabilities": {"undercharge": p}, "model_mean": loss, "model_sd": 0.01}
        for loss, p in ((0.19999999999999996, 0.99), (0.20000000000000007, 0.4), (0.3, 1.0))
    ]  # fmt: skip
    with_leaks = summarise_cases(rows + leaks)
    assert with_leaks["leak_false_alarm_rate"] == 0.5
    assert with_leaks["leak_detection"] == [(0.2, 0.5), (0.3, 1.0)]
    table = summarise_cases(rows)
    assert table["false_alarm_rate"] == 0.5 and table["correct_rate"] == 0.5
    assert table["missed_rate"] == 0.5 and table["misdiagnosis_rate"] == 0.0
    assert table["median_severity_error"] == pytest.approx(0.3)
    assert table["intensity_coverage"] == 0.5 and table["simulations"] == 150
    assert table["model_form_needed"] == float("inf")  # two cases cannot vouch for 95 %
    assert summarise_cases(rows * 10)["model_form_needed"] == pytest.approx(1 / 1.959964)
    assert table["by_fault"][gas] == {
        "cases": 2, "correct": 0.5, "severity_error": pytest.approx(0.3), "covered": 0.5
    }  # fmt: skip
    assert table["pairs"] is None
    assert table["rating"] is None  # rows written before the rating point was read


def test_the_rating_point_change_is_scored_against_the_true_units():
    """The median error of the rating-point reading and the share of true changes inside its
    interval; a reading whose runs all failed does not cover, a truth that failed is left out."""
    from pymc_vcc.studies.fault_benchmark import FaultBenchmarkResult, summarise_cases

    def read(true, mean, low, high):
        return {
            "true": true,
            "mean": mean,
            "low": low,
            "high": high,
            "covered": low <= true <= high,
        }

    failed = {"true": -0.1, "mean": None, "low": None, "high": None, "covered": False}
    ratings = [
        {"capacity": read(-0.10, -0.12, -0.15, -0.09), "COP": read(-0.05, -0.06, -0.08, -0.04)},
        {"capacity": read(0.00, 0.01, -0.01, 0.02), "COP": read(-0.02, 0.00, -0.01, 0.01)},
        {"capacity": failed, "COP": read(float("nan"), 0.0, -0.01, 0.01)},
    ]
    rows = [
        {"fault": None, "score": "correct", "simulations": 1, "seconds": 1.0, "rating": rating,
         "true_intensity": 0.0, "probabilities": {"undercharge": 0.0}}
        for rating in ratings
    ]  # fmt: skip
    table = summarise_cases(rows)
    assert table["rating"]["capacity"] == {
        "cases": 3, "median_error": pytest.approx(0.015), "coverage": pytest.approx(2 / 3)
    }  # fmt: skip
    assert table["rating"]["COP"] == {
        "cases": 2, "median_error": pytest.approx(0.015), "coverage": 0.5
    }  # fmt: skip
    printed = FaultBenchmarkResult(rows, table).format_table()
    assert "capacity error (median) 1.5 points of the rating, inside its 95 % interval 0.67" in (
        printed
    )


def test_two_faults_at_once_are_scored_apart_from_the_cases_of_one():
    from pymc_vcc.studies.fault_benchmark import FaultBenchmarkResult, summarise_cases

    gas, short = "non-condensable gas", "undercharge"

    def read(error, covered):
        return {"severity_error": error, "covered": covered}

    one = {
        "fault": gas,
        "score": "correct diagnosis",
        "severity_error": 0.1,
        "covered": True,
        "true_intensity": 100e3,
        "model_mean": 100e3,
        "model_sd": 1e3,
    }
    pairs = [
        {"fault": [short, gas], "score": "correct diagnosis", "true_intensity": 0.0,
         "faults_read": {short: read(0.1, True), gas: read(0.2, True)}},
        {"fault": [short, gas], "score": "partial diagnosis", "true_intensity": 0.0,
         "faults_read": {short: read(0.3, True), gas: read(0.9, False)}},
    ]  # fmt: skip
    rows = [one, *pairs]
    for row in rows:
        row |= {"simulations": 100, "seconds": 1.0, "probabilities": {"undercharge": 0.0}}
    table = summarise_cases(rows)
    # the cases of one fault are scored as if the pairs were not there
    assert table["correct_rate"] == 1.0 and table["by_size"][1][2] == 1
    assert table["median_severity_error"] == pytest.approx(0.1)
    assert table["pairs"] == {
        "cases": 2, "correct diagnosis": 0.5, "partial diagnosis": 0.5, "misdiagnosis": 0.0,
        "missed detection": 0.0, "no response": 0.0,
        "median_severity_error": pytest.approx(0.25), "intensity_coverage": 0.75,
    }  # fmt: skip
    printed = FaultBenchmarkResult(rows, table).format_table()
    assert "cases: 3 (0 without a fault, 2 with two at once)" in printed
    assert "two faults at once (2 cases): both named 0.50, one of them alone 0.50" in printed
    assert "intensities inside their 95 % intervals 0.75" in printed


@pytest.mark.slow
def test_fault_benchmark_commissions_diagnoses_and_resumes(tmp_path):
    """One unit, healthy and with non-condensable gas, at the smoke budget; run again, it
    recomputes nothing (the rows and the commissioning posterior are kept)."""
    from pymc_vcc.studies import StudySettings
    from pymc_vcc.studies.fault_benchmark import LATER_SECONDS, fault_benchmark
    from pymc_vcc.studies.faults import MODEL_FORM

    gas, leak = "non-condensable gas", "compressor valve leakage"
    cases = [(None, {}), (gas, {"P_NCG": 150e3}), ((gas, leak), {"P_NCG": 150e3, "F_LEAK": 0.3})]
    settings = StudySettings(budget="smoke", out=tmp_path / "faults", n_workers=2)
    first = fault_benchmark(settings, "model", 1, cases)
    assert [r["fault"] for r in first.runs] == [None, gas, [gas, leak]]
    pair = first.runs[2]  # two faults at once: each one's reading against its truth
    assert pair["faults_read"][leak]["true_intensity"] == pytest.approx(0.3)
    assert pair["faults_read"][gas]["true_intensity"] == 150e3
    assert "two faults at once (1 case): both named" in first.format_table()
    gas = first.runs[1]
    assert gas["true_intensity"] == 150e3 and gas["later_seconds"] == LATER_SECONDS
    assert gas["later_start"] == 0.0
    for row in first.runs:  # what the faults cost at the rating point, truly and as read
        for read in row["rating"].values():
            assert np.isfinite(read["true"]) and read["low"] <= read["mean"] <= read["high"]
            assert read["model_sd"] >= 0  # the model's own reading, to measure its error
    wear = first.runs[0]["rating"]  # no fault: the wear of what faults move costs little
    assert abs(wear["capacity"]["true"]) < 0.05 and abs(wear["COP"]["true"]) < 0.05
    assert "what the faults cost at the rating point: capacity" in first.format_table()
    assert gas["intensity_low"] <= gas["intensity_mean"] <= gas["intensity_high"]
    # the row keeps the model's own reading too, from which the form error is measured
    assert gas["model_form"] == MODEL_FORM and gas["model_sd"] > 0
    reads = gas["model_reads"]  # and every fault's reading, to score at another form error
    assert set(reads) == {f.name for f in FAULTS} and len(reads[gas["fault"]]) > 1
    assert gas["score"] in ("correct diagnosis", "misdiagnosis", "missed detection", "no response")
    printed = first.format_table()  # the 150 kPa gas is three thresholds: scored apart
    assert f"{float(gas['score'] == 'correct diagnosis'):.2f} of 1 at 1.75 times or more" in printed
    assert "1-1.75 times" not in printed  # no case in that band
    kept = list((tmp_path / "faults" / "checkpoints").glob("validate-faults-unit-*.nc"))
    assert len(kept) == 1
    again = fault_benchmark(
        StudySettings(budget="smoke", out=tmp_path / "faults", n_workers=2, resume=True),
        "model",
        1,
        cases,
    )
    assert again.runs == first.runs and again.wall_seconds < 30


def test_a_resumed_fault_benchmark_reuses_only_the_rows_of_its_rounds_and_length(
    tmp_path, monkeypatch
):
    import json

    from pymc_vcc.studies import StudySettings
    from pymc_vcc.studies import fault_benchmark as benchmark

    class Commissioning(Exception):
        pass

    def commissioned(*args):
        raise Commissioning

    monkeypatch.setattr(benchmark, "_commissioned", commissioned)
    cases = [(None, {})]
    rows = tmp_path / "checkpoints" / f"{benchmark.RUNS_CHECKPOINT}.jsonl"
    rows.parent.mkdir()
    row = {
        "unit_seed": 0, "case": benchmark.case_label(cases[0]), "budget": "smoke",
        "rounds": 1, "method": "likelihood", "fault": None, "true_intensity": 0.0,
        "verdict": "no fault", "score": "correct", "simulations": 10, "seconds": 1.0,
        "probabilities": {fault.name: 0.0 for fault in FAULTS},
    }  # fmt: skip
    rows.write_text(json.dumps(row) + "\n")
    settings = StudySettings(budget="smoke", out=tmp_path, n_workers=1, resume=True)
    kept = benchmark.fault_benchmark(settings, "all", 1, cases, rounds=1)
    assert [r["rounds"] for r in kept.runs] == [1]
    with pytest.raises(Commissioning):  # two rounds: its row is not that of one
        benchmark.fault_benchmark(settings, "all", 1, cases, rounds=2)
    # a row written before rows kept their length is of the commissioning record's 1060 s
    assert benchmark.fault_benchmark(settings, "all", 1, cases, rounds=1, later_seconds=1060.0)
    with pytest.raises(Commissioning):
        benchmark.fault_benchmark(settings, "all", 1, cases, rounds=1, later_seconds=2120.0)
    with pytest.raises(Commissioning):  # a row written before rows kept their start began at 0
        benchmark.fault_benchmark(settings, "all", 1, cases, rounds=1, later_start=1060.0)
    with pytest.raises(Commissioning):  # ... and logged the nine outputs, MDOT among them
        benchmark.fault_benchmark(settings, "all", 1, cases, rounds=1, outputs=["PD", "PE"])
    with pytest.raises(Commissioning):  # ... and was commissioned on 1060 s
        benchmark.fault_benchmark(settings, "all", 1, cases, rounds=1, commission_seconds=2120.0)
    with pytest.raises(Commissioning):  # ... in one round
        benchmark.fault_benchmark(settings, "all", 1, cases, rounds=1, commission_rounds=2)


def test_a_longer_commissioning_logs_the_same_unit_longer_and_is_kept_apart(tmp_path):
    """The commissioning record of ``commission_seconds``: the unit, its sensors and its logger
    as in the healthy record, logged from the profile's start for longer, with new noise; its
    posterior is kept under its own name (and its number of rounds), so a resumed run never
    takes another length's or another number of rounds'."""
    import xarray as xr

    from pymc_vcc.studies import StudySettings
    from pymc_vcc.studies import fault_benchmark as benchmark
    from pymc_vcc.studies.truths import RECORD_SECONDS

    healthy = benchmark._logging(benchmark.benchmark_unit("all", 3), ["PD", "TE"])
    assert benchmark._commissioning_record(healthy, 3, RECORD_SECONDS) is healthy
    longer = benchmark._commissioning_record(healthy, 3, 1500.0)
    assert float(longer.observed["time"].values[-1]) == 1500.0
    assert list(longer.observed.data_vars) == ["PD", "TE"]
    for kept in ("charge", "parameters", "n_volumes", "lags", "biases", "input_offsets"):
        assert getattr(longer, kept) == getattr(healthy, kept), kept
    first = longer.observed.sel(time=slice(None, RECORD_SECONDS))
    difference = first["PD"].values - healthy.observed["PD"].values
    assert 0 < np.abs(difference).max() < 0.1 * float(healthy.observed["PD"].mean())  # noise
    log = tmp_path / "validate-faults.jsonl"
    name = f"validate-faults-unit-3-all-{healthy.charge:.4f}kg-small-without-"
    name += "-".join(n for n in benchmark.OUTPUT_IDS if n not in ("PD", "TE")) + "-1500s"
    for rounds, suffix in ((1, ""), (2, "-2rounds")):
        kept = xr.DataTree(xr.Dataset({"rounds": float(rounds)}))
        kept.to_netcdf(tmp_path / f"{name}{suffix}.nc", engine="h5netcdf")
    settings = StudySettings()
    for rounds in (1, 2):
        tree = benchmark._commissioned(longer, 3, None, settings, "small", "finer", log, rounds)
        assert float(tree["rounds"]) == rounds


def test_a_case_moves_the_healthy_unit_and_knows_its_true_intensity():
    from pymc_vcc.physics.unit import load_unit
    from pymc_vcc.studies.fault_benchmark import CASES, _faulted

    unit = load_unit()
    healthy = {spec.id: spec.nominal for spec in unit.parameters} | {"M0": 1.5}
    worn = healthy | {"HTC_CA": healthy["HTC_CA"] * 1.02, "FI_FLOW": healthy["FI_FLOW"] * 0.97}
    before = {pid: np.array([value]) for pid, value in healthy.items()}
    relative = [f for f in FAULTS if f.relative]
    for case in CASES:
        moved, intensities = _faulted(unit, healthy, worn, case)
        fault, changes = case
        if isinstance(fault, tuple):  # two faults at once: each as it is alone
            assert len(fault) == 2 and set(intensities) == set(fault)
            moves = {f.name: f.parameters for f in FAULTS}
            for name in fault:
                alone = {pid: c for pid, c in changes.items() if pid in moves[name]}
                assert intensities[name] == pytest.approx(
                    _faulted(unit, healthy, worn, (name, alone))[1][name]
                )
                assert intensities[name] > {f.name: f.threshold for f in FAULTS}[name]
            continue
        if fault is None:  # the unit as it was, or changes at most half a fault's threshold,
            # still below three quarters of it with a month's wear
            assert intensities == {} and set(changes) <= set(healthy)
            unworn, _ = _faulted(unit, healthy, healthy, case)
            for state, share in ((unworn, 0.5), (moved, 0.75)):
                after = {pid: np.array([value]) for pid, value in state.items()}
                for f in relative:
                    assert f.intensity(after, before, unit)[0] <= share * f.threshold + 1e-12, case
            continue
        intensity = intensities[fault]
        threshold = {f.name: f.threshold for f in FAULTS}[fault]
        assert intensity > threshold  # every case lies beyond its fault's detection threshold
        if fault == "undercharge":
            assert moved["M0"] == pytest.approx(1.5 * (1 + changes["M0"]))
            assert intensity == pytest.approx(-changes["M0"])
        if "HTC_CA" in changes:  # the fault acts on the worn coil; read against commissioning
            assert moved["HTC_CA"] == pytest.approx(worn["HTC_CA"] * (1 + changes["HTC_CA"]))


def test_a_fault_probability_outside_zero_one_is_refused_before_any_work():
    from pymc_vcc.studies.diagnose import diagnose

    with pytest.raises(ValueError, match=r"fault probability must lie in \(0, 1\), got 0.0"):
        diagnose(None, None, None, None, fault_probability=0.0)  # type: ignore[arg-type]


def test_a_negative_model_form_is_refused_through_the_cli_before_any_work(tmp_path, capsys):
    from pymc_vcc.cli import main

    code = main(["diagnose", "no-such.csv", "--prior", "none", "--model-form", "-0.1",
                 "--out", str(tmp_path / "d")])  # fmt: skip
    err = capsys.readouterr().err.strip()
    assert code != 0 and "model form spread must be a finite fraction >= 0, got -0.1" in err
    assert len(err.splitlines()) == 1 and not (tmp_path / "d").exists()


def test_a_unit_heating_is_refused_in_one_line_before_any_work():
    """The standard faults name the coils of a unit cooling (the condenser outdoors)."""
    from pymc_vcc.physics.unit import HEAT_PUMP_UNIT, load_unit
    from pymc_vcc.studies.diagnose import diagnose

    with pytest.raises(ValueError, match=r"faults of a unit cooling .* is 'heat-pump-heating'"):
        diagnose(None, None, None, None, unit=load_unit(HEAT_PUMP_UNIT))  # type: ignore[arg-type]


def test_the_rating_point_reads_what_the_faults_cost(monkeypatch):
    """Capacity and COP at the rating inputs, a later draw against itself with its faults
    undone (what they move at its paired commissioning draw): the same unit costs nothing
    (the same simulation), and so does a compressor whose power factor drifted (no fault moves
    it); 40 % less indoor airflow costs capacity and COP (−18 % and −12 % on the nominal unit),
    non-condensable gas costs COP (about 1 % at 120 kPa) more than capacity; a draw whose run
    fails is left out and counted."""
    import pymc_vcc.studies.diagnose as diagnose_module
    from pymc_vcc.physics.unit import load_unit
    from pymc_vcc.studies.diagnose import rating_change

    unit = load_unit()
    flow = unit.parameter_spec("FI_FLOW").nominal
    power = unit.parameter_spec("CF_POW").nominal
    commissioned = _posterior({"M0": [1.6] * 4, "FI_FLOW": [flow] * 4})["posterior"]
    same, failed = rating_change({"M0": np.full(3, 1.6), "FI_FLOW": np.full(3, flow)},
                                 commissioned, unit, 0)  # fmt: skip
    assert failed == 0 and set(same) == {"capacity", "COP"}
    assert np.abs(same["capacity"]).max() < 1e-9 and np.abs(same["COP"]).max() < 1e-9
    drifted, _ = rating_change(
        {"M0": np.full(2, 1.6), "FI_FLOW": np.full(2, flow), "CF_POW": np.full(2, 1.1 * power)},
        commissioned,
        unit,
        0,
    )
    assert np.abs(drifted["COP"]).max() < 1e-9
    clogged, _ = rating_change({"M0": np.full(2, 1.6), "FI_FLOW": np.full(2, 0.6 * flow)},
                               commissioned, unit, 0)  # fmt: skip
    assert -0.25 < clogged["capacity"].mean() < -0.12 and clogged["COP"].mean() < -0.06
    gas, _ = rating_change(
        {"M0": np.full(2, 1.6), "FI_FLOW": np.full(2, flow), "P_NCG": np.full(2, 120e3)},
        commissioned,
        unit,
        0,
    )
    assert abs(gas["capacity"].mean()) < 0.01 and gas["COP"].mean() < -0.005
    assert gas["COP"].mean() < -2 * abs(gas["capacity"].mean())  # the compressor's work rises
    real = diagnose_module.operating_point
    calls = iter(range(100))

    def failing_first(*args, **kwargs):
        point = real(*args, **kwargs)
        return point | {"status": "failed"} if next(calls) == 0 else point

    monkeypatch.setattr(diagnose_module, "operating_point", failing_first)
    kept, failed = rating_change({"M0": np.full(3, 1.6), "FI_FLOW": np.full(3, flow)},
                                 commissioned, unit, 0)  # fmt: skip
    assert failed == 1 and len(kept["COP"]) == 2
