"""Units that are not the model: truth generators for data the inference model did not make.

A real unit differs from the 10-volume model that calibrates it. Each *variant* draws a unit
and its sensors that differ the way real ones do, simulates it from its steady state at the
record's first inputs, and returns what a data logger would record: the outputs as its sensors
read them and the inputs as they were measured.

* ``model``: the inference model itself, typical white sensor noise (the idealised case);
* ``fine``: the unit discretised finer, 20, 25 or 30 volumes per coil (model-form error);
  every variant below has such coils too, as every real unit has, and adds one more way
  a real unit differs:
* ``lag``: each sensor a first-order lag of 5-30 s (a strap-on pipe sensor);
* ``bias``: each sensor off by a constant within its accuracy class (±0.5 K, ±1 % of the
  pressure reading, ±2 % of the mass flow);
* ``inputs``: the logged inputs off the true ones (ambient and indoor ±0.5 K, speed ±1 %,
  valve ±2 % of the reading, each a constant per record plus noise per input step);
* ``drift``: every parameter but the charge moved by up to ±15 % from nominal (fouling,
  airflow, valve and compressor wear), inside the unit's bounds; the lengths, which do not
  drift, off within the tolerance the unit states for them;
* ``all``: all of the above at once.

Every variant adds the typical white sensor noise of
:meth:`~pymc_vcc.inference.noise.SensorNoise.typical`; charges are drawn uniformly from
:data:`CHARGE_RANGE` unless given.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field

import numpy as np
import xarray as xr

from pymc_vcc.inference.error_model import SensorAccuracy, lagged
from pymc_vcc.inference.noise import SensorNoise
from pymc_vcc.physics.inputs import CALIBRATION_SECONDS, builtin_inputs, window
from pymc_vcc.physics.integration.solver import Solver
from pymc_vcc.physics.simulate import VCCSimulator
from pymc_vcc.physics.unit import Unit, load_unit

VARIANTS: tuple[str, ...] = ("model", "fine", "lag", "bias", "inputs", "drift", "all")
"""The truth generators, in the order the benchmark reports them."""

CHARGE_RANGE = (1.0, 2.1)  # kg
FINE_VOLUMES = (20, 25, 30)  # volumes per coil of a finer unit
LAG_RANGE = (5.0, 30.0)  # s, first-order sensor time constant
DRIFT = 0.15  # largest relative change of a non-charge parameter
WEAR = 0.03
"""Largest relative change of each :data:`WEARING` parameter between a unit's commissioning and
a record a month later."""
WEARING: tuple[str, ...] = ("HTC_CA", "HTC_EA", "FO_FLOW", "FI_FLOW", "CF_LEV", "CF_VOL")
"""The parameters a unit's use moves between two records: the coils' air sides (fouling), the
fans' flows (filters, belts), the valve's and the compressor's flow factors (wear)."""
SETTLE = 600.0  # s at the first inputs before the record starts
RECORD_SECONDS = CALIBRATION_SECONDS
"""Length of a generated record, s: the paper's calibration window of the built-in profile."""
ACCURACY = SensorAccuracy()
"""Bounds of the sensors' constant errors and of the inputs' logging errors: the typical
accuracy classes (±0.5 K, ±1 % of a pressure, ±2 % of a flow; inputs ±0.5 K, ±1 % speed,
±2 % valve)."""


@dataclass(frozen=True)
class Truth:
    """One generated record and what made it.

    Attributes:
        variant: the generator (:data:`VARIANTS`).
        observed: the outputs as the sensors read them (SI, ``units`` attrs).
        inputs: the inputs as they were logged (the model is run on these).
        charge: the true charge, kg.
        parameters: every parameter of the true unit (id -> value, SI).
        n_volumes: volumes per coil of the true unit.
        lags: sensor time constants, s (output -> τ; empty without lags).
        biases: sensor offsets in SI units (output -> offset; empty without biases).
        input_offsets: the logged inputs' constant errors (input -> K or fraction; empty
            when the inputs are logged exactly).
    """

    variant: str
    observed: xr.Dataset
    inputs: xr.Dataset
    charge: float
    parameters: dict[str, float]
    n_volumes: int
    lags: dict[str, float] = field(default_factory=dict)
    biases: dict[str, float] = field(default_factory=dict)
    input_offsets: dict[str, float] = field(default_factory=dict)

    @property
    def seconds(self) -> float:
        """Length of the record, s."""
        return float(self.observed["time"].values[-1])


def _uniform(rng: np.random.Generator, bound: float) -> float:
    return float(rng.uniform(-bound, bound))


def drifted_parameters(
    unit: Unit, rng: np.random.Generator, drift: float = DRIFT
) -> dict[str, float]:
    """Every parameter but the charge at nominal × U(1 − drift, 1 + drift), inside its bounds;
    one the unit states a tolerance for (a length) does not drift: it is off within that."""
    moved = {}
    for spec in unit.parameters:
        if spec.id == "M0":
            continue
        value = spec.nominal * (1.0 + _uniform(rng, spec.tolerance or drift))
        moved[spec.id] = float(np.clip(value, spec.low, spec.high))
    return moved


def worn_parameters(
    unit: Unit, parameters: Mapping[str, float], rng: np.random.Generator, wear: float = WEAR
) -> dict[str, float]:
    """``parameters`` a month of use later: each :data:`WEARING` one × U(1 − wear, 1 + wear),
    inside its bounds; the rest as they were."""
    worn = dict(parameters)
    for pid in WEARING:
        spec = unit.parameter_spec(pid)
        value = parameters[pid] * (1.0 + _uniform(rng, wear))
        worn[pid] = float(np.clip(value, spec.low, spec.high))
    return worn


def record_again(
    earlier: Truth,
    seed: int | np.random.SeedSequence,
    parameters: Mapping[str, float],
    seconds: float | None = None,
    start: float = 0.0,
) -> Truth:
    """The unit of ``earlier`` recorded again with ``parameters`` (the charge among them) for
    ``seconds`` (None: as long as ``earlier``), over the built-in input profile from ``start``
    s on (0: the operating points ``earlier`` saw; later: others, as on another day's
    weather): its coils, sensors and logger as they were, its noise new (drawn from
    ``seed``)."""
    length = earlier.seconds if seconds is None else seconds
    return generate_truth(
        earlier.variant,
        seed,
        inputs=window(builtin_inputs(), start + length, start),
        charge=parameters["M0"],
        t_end=length,
        parameters=parameters,
        n_volumes=earlier.n_volumes,
        sensors=earlier,
    )


def logged_inputs(
    inputs: xr.Dataset,
    rng: np.random.Generator,
    offsets: Mapping[str, float] | None = None,
) -> tuple[xr.Dataset, dict[str, float]]:
    """The inputs as a logger reads them, and each input's constant error: drawn within its
    accuracy (or the given ``offsets``, the same logger's), plus an error of a third of that
    accuracy per held step."""
    rows = inputs["time"].size
    constant, errors = {}, {}
    for name, (_, bound) in ACCURACY.inputs.items():
        constant[name] = _uniform(rng, bound) if offsets is None else offsets[name]
        errors[name] = constant[name] + rng.uniform(-bound / 3, bound / 3, rows)
    return ACCURACY.shift_inputs(inputs, errors), constant


def generate_truth(
    variant: str,
    seed: int | np.random.SeedSequence,
    *,
    unit: Unit | None = None,
    inputs: xr.Dataset | None = None,
    charge: float | None = None,
    t_end: float = RECORD_SECONDS,
    parameters: Mapping[str, float] | None = None,
    n_volumes: int | None = None,
    solver: str | Solver = "cvode",
    sensors: Truth | None = None,
) -> Truth:
    """Draw a true unit of ``variant`` and the record its logger would write.

    Args:
        variant: one of :data:`VARIANTS`.
        seed: the record's seed (everything random in it is drawn from it).
        unit: the nominal unit (default: the built-in split unit).
        inputs: the true input profile (default: the built-in Fig. 4 profile).
        charge: the true charge, kg (default: uniform on :data:`CHARGE_RANGE`).
        t_end: length of the record, s.
        parameters: non-charge parameters of the true unit (default: nominal, or drifted for
            ``drift`` and ``all``); overrides the drift where given.
        n_volumes: volumes per coil of the true unit (default: the variant's draw).
        solver: ODE solver of the truth's simulation.
        sensors: an earlier record of the same unit: its sensors' lags and biases and its
            logger's constant input errors are kept (only the noise is new), as on a unit
            recorded again months later.

    Raises:
        ValueError: unknown variant.
        RuntimeError: the true unit's simulation failed.
    """
    if variant not in VARIANTS:
        raise ValueError(f"unknown truth variant {variant!r}; allowed are {list(VARIANTS)}")
    rng = np.random.default_rng(seed)
    unit = load_unit() if unit is None else unit
    every = variant == "all"
    charge = float(rng.uniform(*CHARGE_RANGE)) if charge is None else float(charge)
    truth_params = drifted_parameters(unit, rng) if every or variant == "drift" else {}
    truth_params |= dict(parameters or {})
    truth_params["M0"] = charge
    drawn = None if variant == "model" else int(rng.choice(FINE_VOLUMES))
    n_volumes = n_volumes or drawn or unit.discretisation.n_volumes
    true_unit = unit.with_changes(discretisation={"n_volumes": n_volumes})
    true_inputs = window(builtin_inputs() if inputs is None else inputs, t_end)
    simulator = VCCSimulator(true_unit, true_inputs, solver=solver, settle=SETTLE)
    clean = simulator(truth_params)
    if clean.attrs["status"] != "ok":
        raise RuntimeError(
            f"the true unit's simulation ({variant}, seed {seed}) failed: "
            f"{clean.attrs['failure_reason']}"
        )
    logged, input_offsets = true_inputs, {}
    if every or variant == "inputs":
        earlier = None if sensors is None else sensors.input_offsets
        logged, input_offsets = logged_inputs(true_inputs, rng, earlier)
    read = clean.copy()
    dt = float(np.diff(clean["time"].values[:2])[0])
    lags, biases = {}, {}
    for name in clean.data_vars:
        values = np.asarray(clean[name].values, dtype=float)
        if every or variant == "lag":
            tau = rng.uniform(*LAG_RANGE) if sensors is None else sensors.lags[name]
            lags[name] = float(tau)
            values = lagged(values[None, :], np.array([lags[name]]), dt)[0]
        if every or variant == "bias":
            if sensors is None:
                bound, relative = ACCURACY.bias_bound(clean[name].attrs["units"])
                error = _uniform(rng, bound)
                biases[name] = error * float(np.mean(values)) if relative else error
            else:
                biases[name] = sensors.biases[name]
            values = values + biases[name]
        read[name] = clean[name].copy(data=values)
    observed = SensorNoise.typical().measure(read, rng)
    return Truth(
        variant=variant,
        observed=observed,
        inputs=logged,
        charge=charge,
        parameters={spec.id: truth_params.get(spec.id, spec.nominal) for spec in unit.parameters},
        n_volumes=n_volumes,
        lags=lags,
        biases=biases,
        input_offsets=input_offsets,
    )
