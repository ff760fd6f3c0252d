"""Local identifiability (pymc_vcc.inference.identifiability) against exact Fisher information."""

from dataclasses import dataclass
from typing import ClassVar

import numpy as np
import pytest
import xarray as xr

from pymc_vcc.execution.options import RunOptions
from pymc_vcc.inference.identifiability import identifiability
from pymc_vcc.inference.noise import SensorNoise
from pymc_vcc.physics.simulate import VCCSimulator
from pymc_vcc.studies.identify import IdentifyResult

N_TIME = 120
PLACE = np.linspace(0.0, 1.0, N_TIME)


@dataclass(frozen=True)
class Product:
    """Two temperatures (K): ``T1 = 300 + a·b·(1 + t)`` sees only the product ``a·b``,
    ``T2 = 280 + c·sin(6t)`` sees ``c``; ``d`` changes nothing. ``fail_above`` fails runs
    with a larger ``d``."""

    fail_above: float = np.inf
    parameter_names: ClassVar[tuple[str, ...]] = ("a", "b", "c", "d")
    output_names: ClassVar[tuple[str, ...]] = ("T1", "T2")
    bounds: ClassVar[dict[str, tuple[float, float]]] = {
        "a": (0.5, 1.5),
        "b": (0.5, 1.5),
        "c": (-2.0, 2.0),
        "d": (0.0, 1.0),
    }

    def __call__(self, theta, rng) -> xr.Dataset:
        rows = {
            "T1": 300.0 + theta["a"] * theta["b"] * (1.0 + PLACE),
            "T2": 280.0 + theta["c"] * np.sin(6.0 * PLACE),
        }
        failed = theta["d"] > self.fail_above
        return xr.Dataset(
            {name: ("time", row, {"units": "K"}) for name, row in rows.items()},
            attrs={"status": "failed" if failed else "ok", "failure_reason": "too large d"},
        )


PRIOR_SD = {name: (hi - lo) / np.sqrt(12.0) for name, (lo, hi) in Product.bounds.items()}
AT = {"a": 1.2, "b": 0.8, "c": 0.5, "d": 0.5}


def exact_information(noise_sd: float, correlation: float = 0.0) -> np.ndarray:
    """Jᵀ Σ⁻¹ J in prior-sd units, Σ the AR(1) covariance of each output's errors."""
    slopes = np.zeros((2 * N_TIME, 4))
    slopes[:N_TIME, 0] = AT["b"] * (1.0 + PLACE) * PRIOR_SD["a"]
    slopes[:N_TIME, 1] = AT["a"] * (1.0 + PLACE) * PRIOR_SD["b"]
    slopes[N_TIME:, 2] = np.sin(6.0 * PLACE) * PRIOR_SD["c"]
    lags = np.abs(np.subtract.outer(np.arange(N_TIME), np.arange(N_TIME)))
    one = noise_sd**2 * correlation**lags
    covariance = np.block([[one, np.zeros_like(one)], [np.zeros_like(one), one]])
    return slopes.T @ np.linalg.solve(covariance, slopes)


@pytest.mark.parametrize("correlation", [0.0, 0.6])
def test_information_is_the_exact_fisher_information(correlation):
    noise = SensorNoise(temperature=0.2, correlation=correlation)
    found = identifiability(Product(), noise, at=AT, run=RunOptions(executor="serial"))
    np.testing.assert_allclose(found.information, exact_information(0.2, correlation), rtol=1e-6)
    assert found.simulations == 9 and not found.failed


def test_student_t_errors_carry_less_information():
    gaussian = identifiability(
        Product(), SensorNoise(temperature=0.2), at=AT, run=RunOptions(executor="serial")
    )
    heavy = identifiability(
        Product(), SensorNoise(temperature=0.2, dof=4.0), at=AT, run=RunOptions(executor="serial")
    )
    np.testing.assert_allclose(heavy.information, gaussian.information * 5.0 / 7.0, rtol=1e-12)


def test_directions_name_the_product_and_the_inert_parameter():
    found = identifiability(
        Product(), SensorNoise(temperature=0.2), at=AT, run=RunOptions(executor="serial")
    )
    weak = found.not_identified()
    assert len(weak) == 2 and all(d.sd_ratio == pytest.approx(1.0, abs=1e-9) for d in weak)
    # a·b fixed: a relative move δa/a needs b to move by -δa/a; in prior sds, the unit axis
    ridge = np.array([AT["a"] / PRIOR_SD["a"], -AT["b"] / PRIOR_SD["b"]])
    for direction in weak:  # both lie in the span of d and the ridge (they share sd ratio 1)
        a, b, c, _ = (direction.loadings[name] for name in Product.parameter_names)
        assert c == pytest.approx(0.0, abs=1e-9)
        assert a * ridge[1] - b * ridge[0] == pytest.approx(0.0, abs=1e-6)
    ratios = found.sd_ratio
    assert ratios["d"] == pytest.approx(1.0) and ratios["c"] < 0.05
    assert found.conditional_sd_ratio["a"] < 0.1 < 0.5 < ratios["a"]  # alone known, jointly not
    described = weak[0].describe()
    assert described.startswith("1: +") and "c" not in described.split()
    assert "c" not in weak[0].summary()["loadings"]  # JSON keeps the loadings that matter
    assert "2 of 4 directions not identified" in str(found)


def test_confounding_is_the_fitted_shift_a_held_parameter_causes():
    found = identifiability(
        Product(), SensorNoise(temperature=0.2), at=AT, run=RunOptions(executor="serial")
    )
    table = found.confounding(["a", "c"])
    assert list(table.index) == ["b", "d"] and list(table.columns) == ["a", "c"]
    # a·b is what T1 sees: a true b one prior sd above the held value reads as a higher a
    expected = AT["a"] / AT["b"] * PRIOR_SD["b"]
    assert table.loc["b", "a"] == pytest.approx(expected, rel=1e-3)
    assert table.loc["b", "c"] == pytest.approx(0.0, abs=1e-9)
    assert table.loc["d"].abs().max() == pytest.approx(0.0, abs=1e-9)
    with pytest.raises(ValueError, match="were not examined"):
        found.confounding(["e"])
    printed = IdentifyResult(found, 1.0, 0.0, fit=("a", "c")).format_table()
    assert "Fitting a, c: the shift of each estimate" in printed
    assert printed.splitlines()[-2].split()[0] == "b"  # the largest pull on a first


def test_a_failed_perturbation_is_reported_not_raised():
    found = identifiability(
        Product(fail_above=0.52),
        SensorNoise(temperature=0.2),
        at=AT,
        run=RunOptions(executor="serial"),
    )
    assert set(found.failed) == {"d"} and "too large d" in found.failed["d"]
    assert np.isnan(found.sd_ratio["d"]) and found.sd_ratio["c"] < 0.05
    assert "failed: d" in str(found)


def test_steps_stay_inside_the_bounds():
    at_edge = {**AT, "c": 2.0}
    found = identifiability(
        Product(), SensorNoise(temperature=0.2), at=at_edge, run=RunOptions(executor="serial")
    )
    np.testing.assert_allclose(found.information, exact_information(0.2), rtol=1e-6)


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"parameters": ["a", "x"]}, r"parameters \['x'\] are not the simulator's"),
        ({"step": 0.0}, "step must be positive"),
        ({"at": {**AT, "c": 3.0}}, r"at\['c'\] = 3.0 lies outside"),
        ({"prior_sd": {"a": -1.0}}, r"prior_sd\['a'\] must be positive"),
    ],
)
def test_bad_input_is_refused_in_one_line(kwargs, message):
    with pytest.raises(ValueError, match=message):
        identifiability(
            Product(), SensorNoise(), **{"at": AT, **kwargs}, run=RunOptions(executor="serial")
        )


@dataclass(frozen=True)
class Idle:
    """A compressor's electrical power (W) that reads zero whatever ``a``."""

    parameter_names: ClassVar[tuple[str, ...]] = ("a",)
    output_names: ClassVar[tuple[str, ...]] = ("W_comp",)
    bounds: ClassVar[dict[str, tuple[float, float]]] = {"a": (0.0, 1.0)}

    def __call__(self, theta, rng) -> xr.Dataset:
        power = theta["a"] * np.zeros(N_TIME)
        return xr.Dataset({"W_comp": ("time", power, {"units": "W"})}, attrs={"status": "ok"})


def test_a_zero_noise_scale_is_refused():
    with pytest.raises(ValueError, match="sensor noise of output 'W_comp' is zero"):
        identifiability(Idle(), SensorNoise.typical(), run=RunOptions(executor="serial"))


def test_a_failed_point_is_refused():
    with pytest.raises(RuntimeError, match="the simulation at the point failed: too large d"):
        identifiability(
            Product(fail_above=0.1), SensorNoise(), at=AT, run=RunOptions(executor="serial")
        )


def test_split_unit_compressor_losses_trade_off_and_fans_speeds_are_inert():
    """Only the loss heat reaching the gas, CF_POW·φ(CF_PREF), reaches the nine outputs; the
    fans' speeds reach none; the charge is sharply identified."""
    simulator = VCCSimulator(
        t_window=(0.0, 300.0), parameters=["M0", "CF_POW", "CF_PREF", "FO_SPEED"], solver="cvode"
    )
    found = identifiability(simulator, SensorNoise.typical(), run=RunOptions(executor="serial"))
    weak = found.not_identified()
    assert len(weak) == 2
    fan, losses = weak
    assert fan.sd_ratio == 1.0 and fan.loadings["FO_SPEED"] == pytest.approx(1.0)
    assert losses.loadings["CF_POW"] * losses.loadings["CF_PREF"] < 0
    assert abs(losses.loadings["M0"]) < 0.05
    assert found.sd_ratio["M0"] < 0.01


def test_identify_command_writes_the_table_and_names_the_unidentified(tmp_path, capsys):
    import json

    from pymc_vcc.cli import main

    code = main(
        [
            "identify",
            "--parameters", "M0", "CF_POW", "CF_PREF", "FI_SPEED", "L_LIQ",
            "--at", "M0=1.4", "FO_FLOW=0.5",
            "--t-end", "200",
            "--fit", "M0", "CF_POW",
            "--executor", "serial",
            "--solver", "cvode",
            "--out", str(tmp_path),
            "--json",
        ]
    )  # fmt: skip
    assert code == 0
    summary = json.loads(capsys.readouterr().out.strip().splitlines()[-1])
    pull = summary["confounding"]
    assert next(iter(pull)) == "L_LIQ"  # the liquid line's refrigerant reads as charge
    assert pull["L_LIQ"]["M0"] < -0.005
    assert pull["FI_SPEED"] == {"M0": 0.0, "CF_POW": 0.0}  # an inert fan speed pulls nothing
    # only the loss heat CF_POW·φ(CF_PREF) is seen: more of it through CF_PREF reads as CF_POW
    assert pull["CF_PREF"]["CF_POW"] > 0.05
    assert summary["at"]["M0"] == 1.4 and summary["n_simulations"] == 11
    assert summary["prior_sd"]["L_LIQ"] == pytest.approx(0.05 * 20.0 / np.sqrt(3.0))  # ±5 %
    assert summary["sd_ratio"]["FI_SPEED"] == 1.0 and summary["sd_ratio"]["M0"] < 0.01
    assert len(summary["not_identified"]) == 2
    table = (tmp_path / "identifiability.csv").read_text().splitlines()
    assert table[0] == ",at,prior_sd,sd_ratio,conditional_sd_ratio" and len(table) == 6


def test_identify_refuses_to_fit_a_parameter_it_does_not_examine():
    from pymc_vcc.studies import identify_study

    with pytest.raises(ValueError, match=r"fitted parameter\(s\) \['CF_LEV'\] are not among"):
        identify_study(parameters=["M0", "CF_VOL"], fit=["CF_LEV"])


def test_identify_command_refuses_a_bad_point(capsys):
    from pymc_vcc.cli import main

    with pytest.raises(SystemExit) as exit_info:
        main(["identify", "--at", "M0:1.4"])
    assert exit_info.value.code == 2
    assert "must be NAME=VALUE with a number, got 'M0:1.4'" in capsys.readouterr().err


def test_logging_compressor_power_separates_its_loss_factors():
    """The electrical power sees CF_POW alone, so with it the losses' direction is informed."""
    from pymc_vcc.physics.cycles import OUTPUT_IDS

    simulator = VCCSimulator(
        t_window=(0.0, 300.0),
        parameters=["M0", "CF_POW", "CF_PREF"],
        outputs=[*OUTPUT_IDS, "W_comp"],
        solver="cvode",
    )
    found = identifiability(simulator, SensorNoise.typical(), run=RunOptions(executor="serial"))
    assert not found.not_identified()
    assert found.sd_ratio["CF_POW"] < 0.05 and found.sd_ratio["CF_PREF"] < 0.5
