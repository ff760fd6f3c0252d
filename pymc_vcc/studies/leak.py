"""Refrigerant-leak identification (the paper's Section IV-B and Table II).

Datasets differ only in the total charge M0 (a progressing leak); each is calibrated for M0
alone with a uniform prior (no sequential prior: the leak may have moved M0 far from the last
posterior). Beyond the paper, a leak alarm gives the posterior probability that the charge is
below a fraction of the as-commissioned charge (the first reference).

With ``sensor_noise`` the reference data are measured as by real sensors (noise added with the
dataset's seed) and every method accounts for it: the ABC samplers add the same noise to each
simulation before the distance; ``"likelihood"`` uses the exact likelihood of the data under that
noise with PyMC's tempered SMC.
"""

from __future__ import annotations

import time
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
import pymc as pm
import xarray as xr

from pymc_vcc.execution.progress import progress_enabled
from pymc_vcc.inference.distances import BatchDistance, ks_distances
from pymc_vcc.inference.noise import SensorNoise
from pymc_vcc.inference.priors import UniformPrior
from pymc_vcc.inference.pymc.smc import sample_smc_abc
from pymc_vcc.inference.reference_table import ReferenceTable, simulate_table, table_rejection
from pymc_vcc.inference.rejection import abc_rejection
from pymc_vcc.inference.samplers import SAMPLERS, Sampler
from pymc_vcc.physics.inputs import CALIBRATION_SECONDS
from pymc_vcc.physics.simulate import VCCSimulator
from pymc_vcc.physics.unit import Unit, load_unit
from pymc_vcc.plots import plot_charge_posteriors, save_figure
from pymc_vcc.studies.common import (
    StudySettings,
    add_observed_node,
    holds_output_folder,
    write_json,
    write_netcdf,
    write_text,
)
from pymc_vcc.studies.precision import decimals, fixed

INTERVAL = 0.95  # central posterior interval reported and checked for the truth
CHARGE = "M0"


@dataclass
class LeakResult:
    """What the leak study found.

    Attributes:
        table: Table II, one row per dataset: reference_kg, mean_kg, sd_kg, p_leak, the 95 %
            interval (low_kg, high_kg), whether it covers the reference, and simulations.
        trees: the posterior DataTree of each dataset.
        sampler: ``"rejection"``, ``"smc"`` or ``"likelihood"``.
        n_simulations: forward simulations the posteriors rest on (run, or resumed from
            checkpoints).
        wall_seconds: wall time of the whole study, s.
        alarm_threshold_kg: charge below which the alarm counts a leak, kg.
        shared_table: whether the datasets shared one reference table (then
            ``n_simulations`` is its size and each row's count the table rows it used).
    """

    table: list[dict[str, float]]
    trees: list[xr.DataTree]
    sampler: str
    n_simulations: int
    wall_seconds: float
    alarm_threshold_kg: float
    shared_table: bool = False
    files: list[str] = field(default_factory=list)

    def summary(self) -> dict:
        """The JSON summary: rows, simulations, wall time, sampler."""
        return {
            "rows": self.table,
            "n_simulations": self.n_simulations,
            "wall_seconds": round(self.wall_seconds, 2),
            "sampler": self.sampler,
            "alarm_threshold_kg": self.alarm_threshold_kg,
            "shared_table": self.shared_table,
        }

    def format_table(self) -> str:
        """Table II as aligned text, with the leak probability."""
        lines = [
            "Identification of refrigerant mass (kg)",
            f"{'Mean (kg)':>10} {'SD (kg)':>9} {'Reference (kg)':>15} "
            f"{'P(M0 < ' + format(self.alarm_threshold_kg, '.2f') + ' kg)':>18}",
        ]
        for row in self.table:
            places = decimals(row["sd_kg"])  # the mean as precise as its sd, never sd "0.000"
            lines.append(
                f"{fixed(row['mean_kg'], places, 10)} {fixed(row['sd_kg'], places, 9)} "
                f"{row['reference_kg']:15.2f} {row['p_leak']:18.3f}"
            )
        return "\n".join(lines)


def leak_alarm(tree: xr.DataTree, threshold_kg: float) -> float:
    """Posterior probability that the charge is below ``threshold_kg``."""
    draws = tree["posterior"][CHARGE].values.ravel()
    return float(np.mean(draws < threshold_kg)) if draws.size else float("nan")


def reference_data(
    simulator: VCCSimulator,
    charge: float,
    sensor_noise: SensorNoise | None = None,
    rng: np.random.Generator | None = None,
) -> xr.Dataset:
    """The outputs of the unit at ``charge`` over the simulator's window, as sensors read them.

    Without ``sensor_noise`` the simulation itself; with it, noise drawn from ``rng``.
    """
    result = simulator({CHARGE: charge})
    if result.attrs["status"] != "ok":
        raise RuntimeError(
            f"the reference simulation with {CHARGE} = {charge} kg failed: "
            f"{result.attrs['failure_reason']}"
        )
    if sensor_noise is None:
        return result
    return sensor_noise.measure(result, rng if rng is not None else np.random.default_rng())


def calibrate_charge(
    sampler: str,
    simulator: VCCSimulator,
    prior: UniformPrior,
    observed: xr.Dataset,
    settings: StudySettings,
    executor,
    seed: np.random.SeedSequence,
    checkpoint_name: str,
    epsilon: float,
    sensor_noise: SensorNoise | None,
    distance: BatchDistance,
    table: ReferenceTable | None = None,
    smc_draws: int | None = None,
) -> tuple[xr.DataTree, int]:
    """The posterior of the charge on one dataset, and the simulations it took.

    ``sensor_noise`` is the noise the sampler accounts for (None: none, as the paper);
    ``checkpoint_name`` names its checkpoint under ``settings.out``. With a ``table``, rejection
    runs on its rows (see :func:`shared_table`) and the count is the rows this dataset used.
    ``smc_draws``: SMC particles (default: the budget's ``likelihood_draws`` for the likelihood,
    its ``smc_draws`` for SMC-ABC).
    """
    if sampler == "rejection" and table is not None:
        work = settings.work
        tree = table_rejection(
            table,
            observed,
            quantile=work.quantile,
            n_desired=work.n_desired,
            sensor_noise=sensor_noise,
            distance=distance,
            seed=seed,
        )
        return tree, int(tree["sample_stats"]["n_simulations"])
    if sampler == "rejection":
        tree = abc_rejection(
            simulator,
            prior,
            observed,
            sensor_noise=sensor_noise,
            distance=distance,
            run=settings.run_options(
                executor, seed=seed, checkpoint=settings.checkpoint(checkpoint_name)
            ),
            **settings.rejection_options(),
        )
        return tree, int(tree["sample_stats"]["n_simulations"])
    work = settings.work
    with pm.Model():
        add_observed_node(
            simulator,
            observed,
            prior,
            settings,
            likelihood=sampler == "likelihood",
            epsilon=epsilon,
            sensor_noise=sensor_noise,
            distance=distance,
        )
        tree = sample_smc_abc(
            smc_draws or (work.likelihood_draws if sampler == "likelihood" else work.smc_draws),
            executor=executor,
            random_seed=int(seed.generate_state(1)[0]),
            checkpoint=settings.checkpoint(checkpoint_name),
            progressbar=progress_enabled(settings.progress),
        )
    stats = tree["sample_stats"]
    return tree, int(stats["simulations"].sum() + stats["resumed_simulations"].sum())


def shared_table(
    simulator: VCCSimulator,
    prior: UniformPrior,
    template: xr.Dataset,
    settings: StudySettings,
    executor,
    seed: np.random.SeedSequence,
    name: str,
) -> ReferenceTable:
    """One reference table of the budget's pilot and main draws, shared by every dataset.

    Drawn with ``seed`` (the studies pass the first dataset's, whose result then equals a run
    without the table); checkpointed in the folder ``name`` under ``settings.out``.
    """
    work = settings.work
    return simulate_table(
        simulator,
        prior,
        template,
        n_pilot=work.n_pilot,
        n_main=work.n_main,
        run=settings.run_options(executor, seed=seed, checkpoint=settings.checkpoint_folder(name)),
    )


@holds_output_folder("leak")
def leak_study(
    settings: StudySettings | None = None,
    *,
    references_kg: Sequence[float] = (2.0, 1.5, 1.0),
    sampler: Sampler = "rejection",
    unit: Unit | None = None,
    inputs: xr.Dataset | None = None,
    t_calibration: float = CALIBRATION_SECONDS,
    alarm_fraction: float = 0.9,
    smc_epsilon: float = 0.02,
    sensor_noise: SensorNoise | None = None,
    distance: BatchDistance = ks_distances,
    reference_table: bool = False,
    smc_draws: int | None = None,
) -> LeakResult:
    """Calibrate the charge M0 on one simulated dataset per reference charge (Table II).

    Args:
        settings: budget, executor, seed and results folder.
        references_kg: true charges of the datasets, kg (the paper: 2.0, 1.5, 1.0).
        sampler: ``"rejection"`` (the paper's), ``"smc"`` (PyMC SMC-ABC, parallel kernel) or
            ``"likelihood"`` (the exact likelihood under ``sensor_noise``, PyMC's tempered SMC).
        unit: unit description (default: the built-in one).
        inputs: input profile (default: the built-in step profile).
        t_calibration: calibration window [0, t_calibration] s (the paper: 1060 s).
        alarm_fraction: the alarm reports P(M0 < alarm_fraction · references_kg[0]).
        smc_epsilon: width of SMC-ABC's Gaussian kernel on the distance.
        sensor_noise: noise of the sensors: added to the reference data (with the dataset's
            seed) and accounted for by the sampler; None: noise-free data (the paper).
        distance: the ABC samplers' batch distance (default: the paper's KS distance).
        reference_table: rejection only: simulate the budget's draws once and calibrate every
            dataset on that shared table (:mod:`pymc_vcc.inference.reference_table`); the
            study's simulation count is then the table's size.
        smc_draws: particles of the SMC samplers (default: the budget's ``likelihood_draws``
            or ``smc_draws``).
    """
    started = time.perf_counter()
    if sampler not in SAMPLERS:
        raise ValueError(f"sampler must be one of {list(SAMPLERS)}, got {sampler!r}")
    if sampler == "likelihood" and sensor_noise is None:
        raise ValueError(
            "sampler='likelihood' needs a sensor_noise (the likelihood of noise-free data is "
            "degenerate); pass e.g. SensorNoise.typical()"
        )
    if not 0 < alarm_fraction <= 1:
        raise ValueError(f"alarm_fraction must be in (0, 1], got {alarm_fraction}")
    unit = unit or load_unit()
    spec = unit.parameters[CHARGE]
    outside = [m for m in references_kg if not spec.low <= m <= spec.high]
    if not references_kg or outside:
        raise ValueError(
            f"references_kg must be charges within the prior bounds [{spec.low}, {spec.high}] "
            f"kg, got {list(references_kg)}"
        )
    simulator = VCCSimulator(
        unit, inputs, t_window=(0.0, t_calibration), parameters=[CHARGE], solver=settings.solver
    )
    prior = UniformPrior({CHARGE: (spec.low, spec.high)})
    threshold = alarm_fraction * float(references_kg[0])

    trees, rows, n_simulations = [], [], 0
    seeds = settings.seeds(len(references_kg))
    table = None
    with settings.open_executor() as executor:
        for stage, (reference, seed) in enumerate(zip(references_kg, seeds, strict=True)):
            noise_rng = np.random.default_rng(seed.spawn(1)[0])
            observed = reference_data(simulator, reference, sensor_noise, noise_rng)
            if reference_table and sampler == "rejection" and table is None:
                table = shared_table(
                    simulator, prior, observed, settings, executor, seeds[0], "leak_table"
                )
                n_simulations = table.n_simulations
            tree, ran = calibrate_charge(
                sampler,
                simulator,
                prior,
                observed,
                settings,
                executor,
                seed,
                f"leak_{stage}" if sampler == "rejection" else f"leak_{sampler}_{stage}",
                smc_epsilon,
                sensor_noise,
                distance,
                table,
                smc_draws,
            )
            draws = tree["posterior"][CHARGE].values.ravel()
            if draws.size < 2:
                raise RuntimeError(
                    f"the {sampler} sampler accepted {draws.size} draw(s) for the dataset with "
                    f"{CHARGE} = {reference} kg; raise the budget (n_main, quantile)"
                )
            low, high = np.quantile(draws, [(1 - INTERVAL) / 2, (1 + INTERVAL) / 2])
            rows.append(
                {
                    "reference_kg": float(reference),
                    "mean_kg": float(draws.mean()),
                    "sd_kg": float(draws.std(ddof=1)),
                    "p_leak": leak_alarm(tree, threshold),
                    "low_kg": float(low),
                    "high_kg": float(high),
                    "covered": bool(low <= reference <= high),
                    "n_simulations": ran,
                }
            )
            trees.append(tree)
            n_simulations += ran if table is None else 0

    result = LeakResult(
        rows,
        trees,
        sampler,
        n_simulations,
        time.perf_counter() - started,
        threshold,
        shared_table=table is not None,
    )
    if settings.out is not None:
        result.files = _write(result, settings)
    return result


def _write(result: LeakResult, settings: StudySettings) -> list[str]:
    out = settings.out
    out.mkdir(parents=True, exist_ok=True)
    files = []
    for stage, tree in enumerate(result.trees):
        path = out / f"posterior_{stage}.nc"
        write_netcdf(tree, path)
        files.append(path)
    table = out / "table_ii.csv"
    header = "reference_kg,mean_kg,sd_kg,p_leak\n"
    write_text(
        table,
        header
        + "".join(
            f"{r['reference_kg']},{r['mean_kg']:.8g},{r['sd_kg']:.8g},{r['p_leak']:.4f}\n"
            for r in result.table
        ),
    )
    write_text(out / "table_ii.txt", result.format_table() + "\n")
    write_json(out / "summary.json", result.summary())
    figure = plot_charge_posteriors(result.trees, [r["reference_kg"] for r in result.table])
    files += [table, out / "table_ii.txt", out / "summary.json"]
    files += save_figure(figure, out / "charge_posteriors")
    return [str(path) for path in files]
