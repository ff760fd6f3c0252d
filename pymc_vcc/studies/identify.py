"""Which parameter combinations noisy data from a test profile identify (``pymc-vcc identify``).

The local Fisher information of the unit's outputs over the calibration window, under typical
field sensors (:meth:`~pymc_vcc.inference.noise.SensorNoise.typical`), at one point of the
parameter box: the expected posterior sd / prior sd of each parameter for an exact-likelihood
calibration on such data, and the combinations the data leave unidentified
(:mod:`pymc_vcc.inference.identifiability`). No data are needed: it is a question about the
profile and the sensors.
"""

from __future__ import annotations

import time
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field

import numpy as np
import pandas as pd
import xarray as xr

from pymc_vcc.inference.identifiability import Identifiability, identifiability
from pymc_vcc.inference.noise import SensorNoise
from pymc_vcc.physics.inputs import CALIBRATION_SECONDS
from pymc_vcc.physics.integration.solver import DIFFERENCING_TOLERANCE_SCALE, get_solver
from pymc_vcc.physics.simulate import VCCSimulator
from pymc_vcc.physics.unit import Unit, load_unit
from pymc_vcc.studies.common import StudySettings, holds_output_folder, write_json, write_text


@dataclass
class IdentifyResult:
    """The local identifiability and how it was found."""

    identifiability: Identifiability
    t_end: float
    wall_seconds: float
    fit: Sequence[str] = ()
    files: list[str] = field(default_factory=list)

    @property
    def confounding(self) -> pd.DataFrame | None:
        """With ``fit``: each held parameter's pull on the fitted ones (see
        :meth:`~pymc_vcc.inference.identifiability.Identifiability.confounding`), the
        largest pull on the first fitted parameter first."""
        if not self.fit:
            return None
        table = self.identifiability.confounding(self.fit)
        return table.reindex(table[self.fit[0]].abs().sort_values(ascending=False).index)

    def summary(self) -> dict:
        """The JSON summary: the point, expected sd ratios, unidentified directions, counts."""
        found = self.identifiability
        return {
            "t_end": self.t_end,
            "at": found.at,
            "prior_sd": found.prior_sd,
            "sd_ratio": found.sd_ratio,
            "conditional_sd_ratio": found.conditional_sd_ratio,
            "not_identified": [d.summary() for d in found.not_identified()],
            "failed": found.failed,
            "confounding": None if self.confounding is None else self.confounding.to_dict("index"),
            "n_simulations": found.simulations,
            "wall_seconds": round(self.wall_seconds, 2),
        }

    def format_table(self) -> str:
        """The per-parameter table and the unidentified directions (and, with ``fit``, the
        held parameters' pull on the fitted ones), as printed."""
        text = str(self.identifiability)
        if self.confounding is not None:
            pull = self.confounding.to_string(float_format=lambda x: f"{x:.3g}")
            text += (
                f"\n\nFitting {', '.join(self.fit)}: the shift of each estimate when a held "
                "parameter's true value is 1 prior sd above the value held (SI units)\n" + pull
            )
        return text


@holds_output_folder("identify")
def identify_study(
    settings: StudySettings | None = None,
    *,
    unit: Unit | None = None,
    inputs: xr.Dataset | None = None,
    parameters: Sequence[str] | None = None,
    at: Mapping[str, float] | None = None,
    t_end: float = CALIBRATION_SECONDS,
    step: float = 0.1,
    sensor_noise: SensorNoise | None = None,
    fit: Sequence[str] = (),
) -> IdentifyResult:
    """Local identifiability of ``parameters`` (default: all of the unit's) at ``at`` (default:
    nominal; SI units) from the first ``t_end`` s of ``inputs`` (default: the built-in
    profile) under ``sensor_noise`` (default: typical); with ``fit``, how far a calibration
    of those is pulled by each of the others being off. A parameter's prior is uniform within
    its stated tolerance (:class:`~pymc_vcc.physics.parameters.ParameterSpec`), else on its
    bounds."""
    started = time.perf_counter()
    unit = unit or load_unit()
    examined = list(parameters) if parameters is not None else list(unit.parameters.ids)
    if unexamined := [name for name in fit if name not in examined]:
        raise ValueError(f"fitted parameter(s) {unexamined} are not among those examined")
    simulator = VCCSimulator(
        unit,
        inputs,
        t_window=(0.0, t_end),
        parameters=parameters,
        solver=get_solver(settings.solver).scaled(DIFFERENCING_TOLERANCE_SCALE),
    )
    point = {spec.id: spec.nominal for spec in unit.parameters} | dict(at or {})
    ranges = {spec.id: spec.known_range() for spec in unit.parameters if spec.id in examined}
    known = {pid: (high - low) / np.sqrt(12.0) for pid, (low, high) in ranges.items()}
    with settings.open_executor() as executor:
        found = identifiability(
            simulator,
            sensor_noise or SensorNoise.typical(),
            at=point,
            prior_sd=known,
            step=step,
            run=settings.run_options(executor, seed=settings.seed),
        )
    result = IdentifyResult(found, float(t_end), time.perf_counter() - started, tuple(fit))
    if settings.out is not None:
        out = settings.out
        write_json(out / "summary.json", result.summary())
        write_text(out / "identifiability.csv", found.to_dataframe().to_csv())
        result.files = [str(out / "summary.json"), str(out / "identifiability.csv")]
    return result
