"""What every study shares: work budgets, settings (executor, seed, output folder) and files.

A study with an output folder holds it for its whole run (:meth:`StudySettings.claim_output`:
one run per folder, checked writable before any simulation) and writes each result file
atomically, so an interrupted run leaves complete files or none.
"""

from __future__ import annotations

import functools
import json
import shutil
from collections.abc import Callable, Iterator, Mapping
from contextlib import contextmanager
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any, TypeVar

import numpy as np
import xarray as xr

from pymc_vcc.execution.executors import Executor, ExecutorKind, check_scheduler, make_executor
from pymc_vcc.execution.options import RunOptions
from pymc_vcc.execution.output_folder import OutputFolderError, atomic_path, claim_output_folder
from pymc_vcc.inference.distances import BatchDistance
from pymc_vcc.inference.noise import SensorNoise
from pymc_vcc.inference.priors import Prior
from pymc_vcc.inference.pymc.likelihood import add_likelihood
from pymc_vcc.inference.pymc.model import add_simulator
from pymc_vcc.inference.simulator import Simulator
from pymc_vcc.physics.integration.solver import Solver, get_solver

T = TypeVar("T")


@dataclass(frozen=True)
class Budget:
    """How much work a study may do.

    Attributes:
        n_pilot, quantile, n_main, n_desired: the rejection sampler's settings (Table I).
        smc_draws: SMC-ABC particles per stage.
        likelihood_draws: particles of the exact likelihood's tempered SMC on the charge alone
            (its posterior is sharp and one-dimensional: the small budget's 32 took 908
            simulations a dataset and covered 47 of 50 datasets, where 64 took 1691).
        sobol_base: Saltelli base samples of the Sobol study (N · (D + 2) simulations).
        predictive_draws: posterior draws simulated for the posterior predictive.
    """

    name: str
    n_pilot: int
    quantile: float
    n_main: int
    n_desired: int
    smc_draws: int
    likelihood_draws: int
    sobol_base: int
    predictive_draws: int

    def with_rejection_simulations(self, simulations: int) -> Budget:
        """This budget with its rejection sampler running about ``simulations`` per dataset,
        pilot and main draws and accepted draws in this budget's proportions."""
        if not isinstance(simulations, int) or simulations < 20:
            raise ValueError(f"simulations must be an integer >= 20, got {simulations!r}")
        n_pilot = max(1, round(simulations * self.n_pilot / (self.n_pilot + self.n_main)))
        n_main = simulations - n_pilot
        n_desired = max(1, round(n_main * self.n_desired / self.n_main))
        return replace(
            self,
            name=f"{self.name}-{simulations}",
            n_pilot=n_pilot,
            n_main=n_main,
            n_desired=n_desired,
        )


BUDGETS: dict[str, Budget] = {
    budget.name: budget
    for budget in (
        Budget("smoke", 16, 0.25, 32, 3, 8, likelihood_draws=8, sobol_base=2, predictive_draws=4),
        Budget(
            "small", 100, 0.1, 400, 40, 64, likelihood_draws=32, sobol_base=32, predictive_draws=50
        ),
        Budget("paper", 5000, 0.05, 80000, 4000, 2000, 256, sobol_base=10000, predictive_draws=500),
    )
}
"""Budgets by name: ``smoke`` (seconds, for tests), ``small`` (minutes), ``paper`` (Table I)."""


def get_budget(name: str | Budget) -> Budget:
    """The budget called ``name`` (a :class:`Budget` passes through)."""
    if isinstance(name, Budget):
        return name
    if name not in BUDGETS:
        raise ValueError(f"unknown budget {name!r}; choose one of {list(BUDGETS)}")
    return BUDGETS[name]


@dataclass(frozen=True)
class StudySettings:
    """Where and how a study runs.

    Attributes:
        budget: a budget name or :class:`Budget`.
        executor: ``"serial"``, ``"processes"`` (all cores) or ``"dask"``.
        scheduler: address of a running Dask scheduler (None: a local cluster for ``"dask"``).
        n_workers: worker processes (default: every core).
        out: results folder (None: nothing written).
        resume: continue from the checkpoints in ``out`` instead of starting afresh.
        seed: seeds the datasets' draws and every sampler.
        progress: show progress bars (default: when standard error is a terminal).
        time_limit: wall-time limit of one simulation, s (None: the simulator's own limit
            only); a local worker process that overruns it is stopped and replaced.
        solver: ODE solver of every simulation: a
            :class:`~pymc_vcc.physics.integration.solver.Solver`, or ``"radau"`` or ``"cvode"``
            at that method's default tolerances (default: the study's own choice, Radau
            unless the study says otherwise).
    """

    budget: str | Budget = "small"
    executor: ExecutorKind = "processes"
    scheduler: str | None = None
    n_workers: int | None = None
    out: Path | None = None
    resume: bool = False
    seed: int = 0
    progress: bool | None = None
    time_limit: float | None = None
    solver: str | Solver | None = None

    def __post_init__(self) -> None:
        get_budget(self.budget)
        RunOptions(  # refuses what a run would: the executor kind, workers, time limit
            executor=self.executor, n_workers=self.n_workers, time_limit=self.time_limit
        )
        if self.solver is not None:
            get_solver(self.solver)
        if self.scheduler is not None and self.executor != "dask":
            raise ValueError("scheduler is the address of a Dask scheduler: use executor='dask'")
        if self.scheduler is not None:
            check_scheduler(self.scheduler)
        if self.out is not None:
            object.__setattr__(self, "out", Path(self.out))

    @property
    def work(self) -> Budget:
        """The :class:`Budget` in force."""
        return get_budget(self.budget)

    def rejection_options(self) -> dict[str, Any]:
        """Keyword arguments of the rejection samplers: the budget's Table I settings."""
        work = self.work
        return {
            "n_pilot": work.n_pilot,
            "quantile": work.quantile,
            "n_main": work.n_main,
            "n_desired": work.n_desired,
        }

    def run_options(
        self,
        executor: Executor,
        *,
        seed: int | np.random.SeedSequence,
        checkpoint: Path | None = None,
    ) -> RunOptions:
        """How one of the study's runs executes: on ``executor`` (from :meth:`open_executor`),
        with this study's progress bars and time limit, from ``seed`` (this study's
        :attr:`seed` or one derived from it: no run of a study draws fresh entropy), persisted
        at ``checkpoint`` (from :meth:`checkpoint` or :meth:`checkpoint_folder`)."""
        return RunOptions(
            executor=executor,
            checkpoint=checkpoint,
            seed=seed,
            time_limit=self.time_limit,
            progress=self.progress,
        )

    @contextmanager
    def claim_output(self, study: str) -> Iterator[None]:
        """Hold ``out`` for this run (see :mod:`pymc_vcc.execution.output_folder`).

        With ``resume``, ``out`` must hold checkpoints of ``study`` (``checkpoints/<study>*``).

        Raises:
            OutputFolderError: ``out`` is not writable, another run holds it, or there is
                nothing to resume.
        """
        if self.out is None:
            yield
            return
        with claim_output_folder(self.out):
            folder = self.out / "checkpoints"
            if self.resume and not any(folder.glob(f"{study}*")):
                raise OutputFolderError(
                    f"nothing to resume: {folder} holds no checkpoint of the {study} study; "
                    "run without --resume to start afresh"
                )
            yield

    @contextmanager
    def open_executor(self) -> Iterator[Executor]:
        """An executor of the configured kind, closed on exit."""
        with make_executor(self.executor, self.n_workers, address=self.scheduler) as executor:
            yield executor

    def checkpoint(self, name: str, suffix: str = ".sqlite") -> Path | None:
        """Checkpoint file ``<out>/checkpoints/<name><suffix>``; removed first unless
        resuming."""
        if self.out is None:
            return None
        path = self.out / "checkpoints" / f"{name}{suffix}"
        path.parent.mkdir(parents=True, exist_ok=True)
        if not self.resume:
            path.unlink(missing_ok=True)
        return path

    def checkpoint_folder(self, name: str) -> Path | None:
        """Checkpoint folder ``<out>/checkpoints/<name>``; emptied first unless resuming."""
        if self.out is None:
            return None
        path = self.out / "checkpoints" / name
        if path.exists() and not self.resume:
            shutil.rmtree(path)
        path.mkdir(parents=True, exist_ok=True)
        return path

    def seeds(self, n: int) -> list[np.random.SeedSequence]:
        """``n`` independent seed sequences derived from ``seed``."""
        return np.random.SeedSequence(self.seed).spawn(n)


def holds_output_folder(study: str) -> Callable[[Callable[..., T]], Callable[..., T]]:
    """Decorate a study ``f(settings=None, ...)``: it runs holding its settings' output folder.

    The study gets its settings (default :class:`StudySettings`) as first argument and runs
    inside :meth:`StudySettings.claim_output`, so that the folder is locked and checked
    writable before any simulation.
    """

    def decorate(study_function: Callable[..., T]) -> Callable[..., T]:
        @functools.wraps(study_function)
        def run(settings: StudySettings | None = None, *args: Any, **kwargs: Any) -> T:
            settings = settings or StudySettings()
            with settings.claim_output(study):
                return study_function(settings, *args, **kwargs)

        return run

    return decorate


def write_text(path: Path, text: str) -> None:
    """Write ``text`` atomically."""
    with atomic_path(path) as partial:
        partial.write_text(text)


def write_json(path: Path, payload: Mapping[str, Any]) -> None:
    """Write ``payload`` as indented JSON, atomically."""
    write_text(path, json.dumps(payload, indent=2) + "\n")


def write_netcdf(data: xr.DataTree | xr.Dataset, path: Path) -> None:
    """Save a DataTree or Dataset as netCDF, atomically (reloads with ``xarray`` / ArviZ)."""
    with atomic_path(path) as partial:
        data.to_netcdf(partial, engine="h5netcdf")


def add_observed_node(
    simulator: Simulator,
    observed: xr.Dataset,
    prior: Prior,
    settings: StudySettings,
    *,
    likelihood: bool,
    epsilon: float,
    sensor_noise: SensorNoise | None,
    distance: str | BatchDistance = "ks",
) -> None:
    """Add a study's observed node ``outputs`` to the current PyMC model: the exact likelihood
    under ``sensor_noise`` (known scales), or the ABC ``distance`` with a kernel of width
    ``epsilon`` on simulations with ``sensor_noise`` added."""
    if likelihood:
        if sensor_noise is None:
            raise ValueError("the likelihood needs a sensor_noise")
        add_likelihood(
            "outputs",
            simulator,
            observed,
            sensor_noise=sensor_noise,
            prior=prior,
            time_limit_s=settings.time_limit,
        )
    else:
        add_simulator(
            "outputs",
            simulator,
            observed,
            prior=prior,
            epsilon=epsilon,
            sensor_noise=sensor_noise,
            distance=distance,
            time_limit_s=settings.time_limit,
        )
