"""Sobol sensitivity of the cycle's time-averaged outputs to the 26 parameters (Figs. 9, 10).

As in the paper's appendix: the model runs the first 1060 s of the input profile, each output
is averaged from 20 s to 1060 s (the first seconds are the charge controller settling), and
SALib estimates first- and total-order indices over the Table III box.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import xarray as xr

from pymc_vcc.inference.sensitivity import sobol_indices
from pymc_vcc.physics.inputs import CALIBRATION_SECONDS
from pymc_vcc.physics.simulate import VCCSimulator
from pymc_vcc.physics.unit import Unit, load_unit
from pymc_vcc.plots import plot_sobol_heatmap, save_figure
from pymc_vcc.studies.common import StudySettings, holds_output_folder, write_json, write_netcdf


@dataclass
class SobolResult:
    """Sobol indices (``S1``, ``ST`` and confidence half-widths over parameter × output)."""

    indices: xr.Dataset
    wall_seconds: float
    files: list[str] = field(default_factory=list)

    def dominant(self, threshold: float = 0.1) -> dict[str, list[str]]:
        """For each output, the parameters whose total-order index exceeds ``threshold``."""
        total = self.indices["ST"]
        return {
            str(output): [
                str(p)
                for p in total["parameter"].values
                if total.sel(output=output, parameter=p) > threshold
            ]
            for output in total["output"].values
        }

    def summary(self) -> dict:
        """The JSON summary: counts, wall time and dominant parameters per output."""
        attrs = self.indices.attrs
        return {
            "n_base": int(attrs["n_base"]),
            "n_simulations": int(attrs["n_simulations"]),
            "n_failed": int(attrs["n_failed"]),
            "n_dropped_base_samples": int(attrs["n_dropped_base_samples"]),
            "wall_seconds": round(self.wall_seconds, 2),
            "dominant_parameters": self.dominant(),
        }


@holds_output_folder("sobol")
def sobol_study(
    settings: StudySettings | None = None,
    *,
    unit: Unit | None = None,
    inputs: xr.Dataset | None = None,
    window: tuple[float, float] = (20.0, CALIBRATION_SECONDS),
) -> SobolResult:
    """First- and total-order Sobol indices of the nine outputs' averages over ``window`` (s).

    Parameters
    ----------
    settings
        Budget (its ``sobol_base`` is Saltelli's N), executor, output folder and seed.
    unit
        Unit description (default: the built-in split unit); the parameters vary over its
        bounds.
    inputs
        Input profile (default: the built-in 2120 s step profile), run up to ``window[1]``.
    window
        (start, end) of the averaging, s (the paper's appendix: 20 s to 1060 s).
    """
    started = time.perf_counter()
    unit = unit or load_unit()
    simulator = VCCSimulator(unit, inputs, t_window=(0.0, window[1]), solver=settings.solver)
    bounds = {spec.id: (spec.low, spec.high) for spec in unit.parameters}
    with settings.open_executor() as executor:
        indices = sobol_indices(
            simulator,
            bounds,
            unit.cycle_model.output_ids,
            n_base=settings.work.sobol_base,
            window=window,
            run=settings.run_options(
                executor, seed=settings.seed, checkpoint=settings.checkpoint("sobol")
            ),
        )
    result = SobolResult(indices, time.perf_counter() - started)
    if settings.out is not None:
        out = settings.out
        write_netcdf(indices, out / "sobol_indices.nc")
        write_json(out / "summary.json", result.summary())
        files = [out / "sobol_indices.nc", out / "summary.json"]
        for order, stem in (("S1", "first_order"), ("ST", "total_order")):
            files += save_figure(plot_sobol_heatmap(indices, order), out / f"sobol_{stem}")
        result.files = [str(path) for path in files]
    return result
