"""Sequential calibration: Algorithm 1 over K datasets, each posterior the next prior.

Dataset 1 uses the first (uniform) prior; dataset k > 1 uses a Gaussian mixture fitted to the
posterior of dataset k − 1 (:class:`~pymc_vcc.inference.priors.GMMPrior`, in the logit space of the
first
prior's bounds, so it never leaves them). ``keep_uniform=True`` uses the first prior at every
stage instead, as the paper's leak study does.
"""

from __future__ import annotations

import json
from collections.abc import Iterator, Mapping, Sequence
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np
import xarray as xr

from pymc_vcc.execution.options import RunOptions
from pymc_vcc.inference.distances import BatchDistance, ks_distances
from pymc_vcc.inference.noise import SensorNoise, extended_prior, model_drift, with_noise
from pymc_vcc.inference.priors import GMMPrior, Prior, prior_from_dataset
from pymc_vcc.inference.rejection import abc_rejection, split_seed
from pymc_vcc.inference.series import OutputData, prepare_observed
from pymc_vcc.inference.simulator import Simulator, check_simulator

PRIOR_GROUP = "prior_model"


def _stage_name(k: int) -> str:
    return f"dataset_{k}"


@dataclass
class SequentialResult:
    """One ABC result tree per dataset, and the prior each stage used.

    Attributes:
        trees: DataTree of dataset k (``posterior``, ``prior``, ``observed_data``,
            ``sample_stats``), in dataset order.
        priors: the prior of dataset k (the first prior, or the GMM fitted to k − 1).
    """

    trees: list[xr.DataTree]
    priors: list[Prior]

    def __len__(self) -> int:
        return len(self.trees)

    def __getitem__(self, k: int) -> xr.DataTree:
        return self.trees[k]

    def __iter__(self) -> Iterator[xr.DataTree]:
        return iter(self.trees)

    def to_datatree(self) -> xr.DataTree:
        """All stages in one tree: ``dataset_k/<group>`` and ``dataset_k/prior_model``."""
        groups: dict[str, xr.Dataset] = {}
        for k, (tree, prior) in enumerate(zip(self.trees, self.priors, strict=True)):
            for name, child in tree.children.items():
                groups[f"{_stage_name(k)}/{name}"] = child.to_dataset()
            groups[f"{_stage_name(k)}/{PRIOR_GROUP}"] = prior.to_dataset()
        combined = xr.DataTree.from_dict(groups)
        for k, tree in enumerate(self.trees):
            combined[_stage_name(k)].attrs.update(tree.attrs)
        combined.attrs["n_datasets"] = len(self.trees)
        return combined

    def to_netcdf(self, path: str | Path) -> None:
        """Write every stage and its prior to one netCDF file."""
        self.to_datatree().to_netcdf(path, engine="h5netcdf")

    @classmethod
    def from_netcdf(cls, path: str | Path) -> SequentialResult:
        """Read a result written by :meth:`to_netcdf`."""
        combined = xr.open_datatree(path, engine="h5netcdf").load()
        trees, priors = [], []
        for k in range(int(combined.attrs["n_datasets"])):
            stage = combined[_stage_name(k)]
            priors.append(prior_from_dataset(stage[PRIOR_GROUP].to_dataset()))
            tree = xr.DataTree.from_dict(
                {
                    name: child.to_dataset()
                    for name, child in stage.children.items()
                    if name != PRIOR_GROUP
                }
            )
            tree.attrs.update(stage.attrs)
            trees.append(tree)
        return cls(trees, priors)


def _root_seed(
    seed: int | np.random.SeedSequence | None, checkpoint: Path | None
) -> np.random.SeedSequence:
    entropy, spawn_key = split_seed(seed)
    if entropy is None and checkpoint is not None:
        record = checkpoint / "seed.json"
        if record.exists():
            entropy = int(json.loads(record.read_text())["entropy"])
        else:
            entropy = int(np.random.SeedSequence().entropy)
            checkpoint.mkdir(parents=True, exist_ok=True)
            record.write_text(json.dumps({"entropy": str(entropy)}))
    return np.random.SeedSequence(entropy, spawn_key=spawn_key)


def sequential_calibration(
    simulator: Simulator | Sequence[Simulator],
    first_prior: Prior,
    datasets: Sequence[OutputData],
    *,
    keep_uniform: bool = False,
    max_components: int = 5,
    drift: float = 0.0,
    n_pilot: int = 5000,
    quantile: float = 0.05,
    n_main: int = 80000,
    n_desired: int = 4000,
    noise: Mapping[str, tuple[float, float]] | None = None,
    sensor_noise: SensorNoise | None = None,
    outputs: Sequence[str] | None = None,
    distance: BatchDistance = ks_distances,
    run: RunOptions | None = None,
) -> SequentialResult:
    """Calibrate on datasets in order, passing each posterior on as the next prior.

    Args:
        simulator: one simulator for every dataset, or one per dataset (e.g. the same model
            driven by each dataset's inputs).
        first_prior: prior of the first dataset (the paper: uniform on physical bounds).
        datasets: observed outputs of each dataset, in calibration order.
        keep_uniform: use ``first_prior`` at every stage instead of the fitted GMM.
        max_components: most GMM components tried (chosen by BIC).
        drift: how far each of ``first_prior``'s parameters may move between datasets, the sd
            of a normal step in fractions of its range, allowed by each fitted prior
            (:meth:`~pymc_vcc.inference.priors.GMMPrior.fit`; 0: the posterior as it is).
        n_pilot, quantile, n_main, n_desired: the rejection sampler's budget per dataset (the
            paper's Table I: 5000 pilot draws, the 5 % quantile, 80000 main draws, 4000
            accepted).
        noise, sensor_noise, outputs, distance: how simulations are compared with the data.
        run: where and how the simulations run, as for ``abc_rejection``; its ``checkpoint``
            is a folder holding one checkpoint per dataset (``dataset_k.sqlite``: a restarted
            run resumes where it stopped), and the stages use its ``seed``'s children
            (``SeedSequence.spawn`` style, one per dataset).

    The arguments after ``drift`` are those of
    :func:`~pymc_vcc.inference.rejection.abc_rejection`, applied to each dataset.
    """
    if len(datasets) == 0:
        raise ValueError("datasets is empty; give at least one observed dataset")
    simulators = list(simulator) if isinstance(simulator, Sequence) else [simulator] * len(datasets)
    if len(simulators) != len(datasets):
        raise ValueError(
            f"got {len(simulators)} simulators for {len(datasets)} datasets; give one simulator, "
            "or one per dataset"
        )
    run = run or RunOptions()
    folder = Path(run.checkpoint) if run.checkpoint is not None else None
    root = _root_seed(run.seed, folder)
    stage_seeds = root.spawn(len(datasets))
    trees: list[xr.DataTree] = []
    priors: list[Prior] = []
    with run.open_executor() as pool:
        for k, (stage_simulator, observed) in enumerate(zip(simulators, datasets, strict=True)):
            if k == 0 or keep_uniform:
                simulated = check_simulator(stage_simulator).output_names
                used = prepare_observed(observed, outputs, output_names=simulated)
                prior = with_noise(first_prior, noise, used.names)
                if sensor_noise is not None:
                    prior = extended_prior(prior, sensor_noise.prior_bounds(used))
            else:
                prior = GMMPrior.fit(
                    trees[-1],
                    priors[0],
                    max_components=max_components,
                    seed=int(stage_seeds[k].generate_state(1)[0]),
                    drift=model_drift(first_prior, drift),
                )
            priors.append(prior)
            trees.append(
                abc_rejection(
                    stage_simulator,
                    prior,
                    observed,
                    n_pilot=n_pilot,
                    quantile=quantile,
                    n_main=n_main,
                    n_desired=n_desired,
                    noise=noise,
                    sensor_noise=sensor_noise,
                    outputs=outputs,
                    distance=distance,
                    run=replace(
                        run,
                        executor=pool,
                        checkpoint=folder / f"{_stage_name(k)}.sqlite" if folder else None,
                        seed=stage_seeds[k],
                    ),
                )
            )
    return SequentialResult(trees, priors)
