"""The standard faults of a vapour-compression unit, as the model sees them.

Each fault of the fault-detection literature's standard set (Yuill and Braun's evaluation of
FDD protocols; ASHRAE RP-1043) moves some of the unit's parameters (a calibration parameter of
Table III, or one of the cycle's fault parameters, ``unit.faults``). Its *intensity* on a later
record is taken relative to the unit as commissioned, each later posterior draw paired with a
draw of the commissioning posterior (:func:`fault_intensities`), so that what commissioning
left unknown widens it, and spread by the model's form error (:func:`with_model_form`), so that
what the model lacks widens it too; a fault counts beyond its detection threshold. The diagnosis
(:mod:`pymc_vcc.studies.diagnose`) names faults from these intensities; the leak alarm
(:mod:`pymc_vcc.studies.unit_log`) is the undercharge's.
"""

from __future__ import annotations

import functools
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import Literal

import numpy as np
import xarray as xr
from scipy.special import ndtr

from pymc_vcc.physics.cycles.split_unit import air_conductance
from pymc_vcc.physics.unit import Unit
from pymc_vcc.studies.record_budget import CHARGE


@dataclass(frozen=True)
class Fault:
    """One fault of the standard set, as the model sees it.

    Attributes:
        name: what a service engineer calls it.
        parameters: the parameters it moves (spread together by its slab in
            :func:`~pymc_vcc.studies.unit_log.later_prior`; its intensity is the largest of
            their moves, unless it has a :attr:`measure`).
        direction: −1 if the fault lowers them, +1 if it raises them.
        threshold: the smallest intensity that counts as the fault.
        relative: intensity as a fraction of the commissioned value (else in the parameter's
            own unit, from 0: a fault parameter is 0 on a healthy unit).
        display: (unit, factor) of the intensity in the report (``("%", 100)``, ...).
        measure: the quantity of the unit the intensity is taken on instead (unit, parameter
            draws -> values), when the data see a combination of the parameters, not each.
    """

    name: str
    parameters: tuple[str, ...]
    direction: int
    threshold: float
    relative: bool = True
    display: tuple[str, float] = ("%", 100.0)
    measure: Callable[[Unit, Mapping[str, np.ndarray]], np.ndarray] | None = None

    def intensity(
        self,
        draws: Mapping[str, np.ndarray],
        commissioned: Mapping[str, np.ndarray],
        unit: Unit | None = None,
    ) -> np.ndarray:
        """The fault's intensity per posterior draw.

        Args:
            draws: parameter -> its posterior draws.
            commissioned: parameter -> its value at commissioning (relative faults), one
                commissioning posterior draw paired with each of ``draws``.
            unit: the unit, for a fault measured on a quantity derived from the parameters
                (:attr:`measure`).
        """
        if self.measure is not None:
            if unit is None:
                raise ValueError(f"the intensity of {self.name!r} is measured on the unit")
            before = self.measure(unit, commissioned)
            return self.direction * (self.measure(unit, draws) / before - 1.0)
        moves = []
        for pid in self.parameters:
            if self.relative:
                moves.append(self.direction * (draws[pid] / commissioned[pid] - 1.0))
            else:
                moves.append(self.direction * draws[pid])
        return np.max(moves, axis=0)


def coil_conductance(
    coil: Literal["condenser", "evaporator"], unit: Unit, draws: Mapping[str, np.ndarray]
) -> np.ndarray:
    """A coil's effective air-side conductance of each draw, W/K
    (:func:`~pymc_vcc.physics.cycles.split_unit.air_conductance`; parameters not drawn at
    nominal).

    Args:
        coil: which coil.
        unit: the unit.
        draws: parameter -> values, one per draw (ids of neither table are ignored).
    """
    known = [pid for pid in draws if pid in unit.parameters.ids or pid in unit.faults.ids]
    n = len(draws[known[0]])
    values = np.empty(n)
    for k in range(n):
        theta, faults = unit.parameter_vectors({pid: float(draws[pid][k]) for pid in known})
        constants = unit.cycle_model.constants(unit, theta, faults=faults)
        values[k] = air_conductance(constants, coil, unit.discretisation.n_volumes)
    return values


FAULTS: tuple[Fault, ...] = (
    Fault("undercharge", (CHARGE,), -1, 0.10),
    Fault("overcharge", (CHARGE,), +1, 0.10),
    Fault(
        "condenser fouling or low outdoor airflow",
        ("HTC_CA", "FO_FLOW"),
        -1,
        0.20,
        measure=functools.partial(coil_conductance, "condenser"),
    ),
    Fault(
        "low indoor airflow",
        ("FI_FLOW", "HTC_EA"),
        -1,
        0.20,
        measure=functools.partial(coil_conductance, "evaporator"),
    ),
    Fault("compressor valve leakage", ("F_LEAK",), +1, 0.10, False),
    Fault("liquid-line restriction", ("DP_RESTR",), +1, 50e3, False, ("kPa", 1e-3)),
    Fault("non-condensable gas", ("P_NCG",), +1, 50e3, False, ("kPa", 1e-3)),
)
"""The standard faults of a unit cooling, and their detection thresholds: charge ±10 % (the
field's tolerance), the condenser's or the evaporator's air-side conductance −20 % (a coil's
fouling and its fan's airflow lower it alike, and the data see it, not each: commissioning pins
the conductances to a few per cent and leaves the HTC and the airflow apart at ±25-35 %; a
dirty indoor coil thus reads as low indoor airflow), 10 % of the compressor's displaced gas
leaking back (at the rating point: the capacity −5 %, the evaporating pressure +30 kPa), a
restriction of 50 kPa at the rated flow, 50 kPa of non-condensable gas (about 2 % of the
condensing pressure: twice a pressure sensor's accuracy)."""

FAULT_PROBABILITY = 0.1
"""Prior probability that a unit has any one fault (of a group of parameters a fault moves) at
its later record; at most two at once (:meth:`~pymc_vcc.inference.priors.GMMPrior.with_slabs`).
A healthy unit is the likelier prior state, so that a fault is named only when the data ask
for it (a uniform prior put 83 % of its mass on a restriction above its threshold)."""
ERROR_FAULT_PROBABILITY = 0.05
"""Each fault's probability in the prior a later record's model error is drawn at. One Gaussian
prices every state's error: drawn where each fault was as likely as not (0.5), the faulted
draws' errors set its correlations, a healthy unit's record fitted 13 nats worse than with a
liquid-line restriction that was not there (a benchmark unit), and the restriction was named."""
REFERENCE_FAULT_PROBABILITY = 0.5
"""Each fault's probability in the distribution a later record's SMC tempers from: its first
particles reach every fault's range."""
HEALTHY_FAULT_FRACTION = 0.005
"""Where a healthy unit's fault parameters lie, a fraction of their range from 0 (the median of
a logit normal of sd 1: 95 % below 2 % of the range, far below every threshold)."""


MODEL_FORM = 0.15
"""Relative sd of the model's reading of a fault's intensity on a unit that is not the model
(:func:`with_model_form`). The model reads a real unit's fault through parameters that also
absorb what it lacks (finer coils, sensor lags and biases, drift), so its intensities miss by a
fraction that changes from unit to unit and that no posterior of the model sees (a 30 % charge
loss read 25 % (22-28), a valve leak of 25 % read 23 % (21-24)). Measured on the fault
benchmark's units 0-900 at ``2f9e949`` (90 faulted cases) as the split-conformal 95 % quantile
of the spread each case needed for its 95 % interval to cover its truth
(:func:`~pymc_vcc.studies.fault_benchmark.model_form_needed`): 0.150; what it gives on other
units is on the docs' faults page."""


def check_model_form(spread: float) -> None:
    """Refuse a model-form spread that is negative or not finite, in one line."""
    if not (np.isfinite(spread) and spread >= 0.0):
        raise ValueError(f"model form spread must be a finite fraction >= 0, got {spread}")


def with_model_form(
    intensities: Mapping[str, np.ndarray], seed: int, spread: float = MODEL_FORM
) -> dict[str, np.ndarray]:
    """Each fault's intensity draws, each multiplied by 1 + N(0, s²), s = ``spread``: the model's
    reading of an intensity marginalised over its form error (:data:`MODEL_FORM`).

    Args:
        intensities: fault name -> the model's intensity draws (:func:`fault_intensities`).
        seed: seeds the form error's draws.
        spread: the form error's relative sd (0: the model's reading as it is).
    """
    check_model_form(spread)
    rng = np.random.default_rng([seed, 1])
    return {
        name: draws * (1.0 + rng.normal(0.0, spread, np.shape(draws)))
        for name, draws in intensities.items()
    }


def beyond_probability(read: np.ndarray, threshold: float, spread: float = MODEL_FORM) -> float:
    """P(intensity >= ``threshold``) of the model's intensity draws ``read`` spread by its form
    error as :func:`with_model_form` spreads them, the form error integrated out exactly: the
    mean over draws r of P(r (1 + N(0, s²)) >= threshold). Drawing one form error per
    posterior draw instead adds noise of its own (a sd of about 0.03 where P is near 0.9, at 96
    draws).

    Args:
        read: the model's draws of one fault's intensity (:func:`fault_intensities`).
        threshold: the fault's threshold (> 0).
        spread: the form error's relative sd, s (0: the share of draws beyond it).
    """
    check_model_form(spread)
    read = np.asarray(read, dtype=float)
    if spread == 0.0:
        return float(np.mean(read >= threshold))
    safe = np.where(read == 0.0, 1.0, read)
    needed = (threshold / safe - 1.0) / spread  # the form error that takes a draw to it
    beyond = np.where(read > 0.0, ndtr(-needed), ndtr(needed))
    return float(np.mean(np.where(read == 0.0, 0.0, beyond)))


def check_fault_probability(probability: float) -> None:
    """Refuse a fault probability outside (0, 1), in one line."""
    if not 0.0 < probability < 1.0:
        raise ValueError(f"fault probability must lie in (0, 1), got {probability}")


def moved_parameters(unit: Unit) -> list[str]:
    """The calibration parameters a fault moves (a commissioning posterior must hold them)."""
    return [
        pid
        for fault in FAULTS
        if fault.relative
        for pid in fault.parameters
        if pid in unit.parameters.ids
    ]


def fault_intensities(
    later: Mapping[str, np.ndarray],
    commissioning: xr.Dataset,
    unit: Unit,
    seed: int,
    faults: Sequence[Fault] = FAULTS,
) -> dict[str, np.ndarray]:
    """Each fault's intensity per draw of a later record's posterior.

    Args:
        later: parameter -> the later posterior's draws (the unit's charge in ``M0``).
        commissioning: the commissioning posterior (its ``posterior`` group); one of its draws,
            picked at random (``seed``), is paired with each later draw
            (:func:`paired_commissioning`).
        unit: the unit.
        seed: seeds the pairing.
        faults: the faults (default: the standard set).
    """
    paired = paired_commissioning(len(later[CHARGE]), commissioning, seed)
    commissioned = {pid: values for pid, values in paired.items() if pid in unit.parameters.ids}
    return {fault.name: fault.intensity(later, commissioned, unit) for fault in faults}


def paired_commissioning(
    n_later: int, commissioning: xr.Dataset, seed: int
) -> dict[str, np.ndarray]:
    """One commissioning posterior draw per later draw, picked at random (``seed``): each
    variable of ``commissioning`` (its ``posterior`` group) -> its ``n_later`` paired values."""
    n_commissioning = commissioning.sizes["chain"] * commissioning.sizes["draw"]
    picks = np.random.default_rng(seed).integers(0, n_commissioning, n_later)
    return {
        str(name): commissioning[name].values.ravel()[picks] for name in commissioning.data_vars
    }


__all__ = [
    "FAULTS",
    "FAULT_PROBABILITY",
    "MODEL_FORM",
    "Fault",
    "beyond_probability",
    "check_fault_probability",
    "check_model_form",
    "coil_conductance",
    "fault_intensities",
    "moved_parameters",
    "paired_commissioning",
    "with_model_form",
]
