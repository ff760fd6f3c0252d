"""Sequential calibration: GMM transfer narrows the next posterior; results save and reload."""

from dataclasses import replace

import numpy as np
import pytest

from pymc_vcc.execution.options import RunOptions
from pymc_vcc.inference.priors import GMMPrior, UniformPrior
from pymc_vcc.inference.sequential import SequentialResult, sequential_calibration
from pymc_vcc.testing import GaussianLocation, Recording

MODEL = GaussianLocation(n_time=20, sigma=1.0, low=-1.0, high=1.0)
BUDGET = dict(n_pilot=500, quantile=0.1, n_main=4000, n_desired=4000)
SERIAL = RunOptions(executor="serial")


def _datasets(n, seed=0):
    rng = np.random.default_rng(seed)
    return [MODEL({"mu": 0.3}, rng) for _ in range(n)]


def test_gmm_transfer_narrows_the_second_posterior_to_the_two_dataset_posterior():
    datasets = _datasets(2)
    common = dict(distance=MODEL.distance, run=replace(SERIAL, seed=1), **BUDGET)
    transferred = sequential_calibration(MODEL, UniformPrior(MODEL.bounds), datasets, **common)
    restarted = sequential_calibration(
        MODEL, UniformPrior(MODEL.bounds), datasets, keep_uniform=True, **common
    )
    assert isinstance(transferred.priors[1], GMMPrior)
    assert all(isinstance(prior, UniformPrior) for prior in restarted.priors)
    second = transferred[1].posterior["mu"].values.ravel()
    uniform_second = restarted[1].posterior["mu"].values.ravel()
    assert second.std() < 0.8 * uniform_second.std()
    # exact posterior given both datasets: 40 observations at once. Allowance beyond the
    # Monte Carlo error: 0.1 sd for the two ABC windows (about 3 % of sd each here) and the fit
    both = GaussianLocation(n_time=40, sigma=1.0, low=-1.0, high=1.0)
    exact = both.posterior(np.concatenate(datasets, axis=1))
    n = second.size
    assert abs(second.mean() - exact.mean()) <= (4 / np.sqrt(n) + 0.1) * exact.std()
    assert abs(second.std() / exact.std() - 1) <= 4 / np.sqrt(2 * n) + 0.1


def test_keeping_the_uniform_prior_runs_independent_stages_with_the_stage_seeds():
    datasets = _datasets(3, seed=2)
    result = sequential_calibration(
        MODEL,
        UniformPrior(MODEL.bounds),
        datasets,
        keep_uniform=True,
        distance=MODEL.distance,
        run=replace(SERIAL, seed=3),
        **(BUDGET | {"n_main": 1000, "n_desired": 50}),
    )
    assert len(result) == 3
    for k, tree in enumerate(result):
        np.testing.assert_array_equal(tree.observed_data["y"].values, datasets[k][0])
        assert tree.posterior.sizes["draw"] == 50
    assert not np.array_equal(result[0].prior["mu"].values, result[1].prior["mu"].values)


def test_a_drift_widens_each_next_prior_by_the_step_of_its_parameters():
    """Three datasets with ``drift``: each fitted prior is the last posterior widened by the
    step (here 0.1 of the range of mu, sd 0.2 against a posterior sd of ~0.2)."""
    options = dict(
        distance=MODEL.distance,
        run=replace(SERIAL, seed=3),
        **(BUDGET | {"n_main": 1000, "n_desired": 200}),
    )
    datasets = _datasets(3, seed=2)
    still, drifting = (
        sequential_calibration(MODEL, UniformPrior(MODEL.bounds), datasets, drift=d, **options)
        for d in (0.0, 0.1)
    )
    rng = np.random.default_rng(0)
    for k in (1, 2):
        posterior_sd = drifting[k - 1].posterior["mu"].values.std()
        widened = drifting.priors[k].sample(50_000, rng)[:, 0].std()
        assert widened == pytest.approx(np.hypot(posterior_sd, 0.2), rel=0.15)
    assert still.priors[1].sample(50_000, rng)[:, 0].std() == pytest.approx(
        still[0].posterior["mu"].values.std(), rel=0.1
    )


def test_results_with_noise_scales_save_and_reload_with_their_priors(tmp_path):
    result = sequential_calibration(
        MODEL,
        UniformPrior(MODEL.bounds),
        _datasets(2, seed=4),
        noise={"y": (0.0, 0.2)},
        max_components=2,
        run=replace(SERIAL, seed=5),
        **(BUDGET | {"n_main": 1500, "n_desired": 100}),
    )
    assert result.priors[0].names == result.priors[1].names == ("mu", "nu_y")
    assert result.priors[1].bounds == {"mu": (-1.0, 1.0), "nu_y": (0.0, 0.2)}
    result.to_netcdf(tmp_path / "sequence.nc")
    loaded = SequentialResult.from_netcdf(tmp_path / "sequence.nc")
    assert len(loaded) == 2
    for k in range(2):
        for group in ("posterior", "prior", "observed_data", "sample_stats"):
            assert loaded[k][group].to_dataset().identical(result[k][group].to_dataset())
        assert type(loaded.priors[k]) is type(result.priors[k])
        points = result.priors[k].sample(10, np.random.default_rng(k))
        np.testing.assert_allclose(loaded.priors[k].logpdf(points), result.priors[k].logpdf(points))


def test_a_restarted_sequence_resumes_from_its_checkpoint_folder(tmp_path):
    log = tmp_path / "calls.log"
    arguments = dict(
        simulator=Recording(MODEL, str(log)),
        first_prior=UniformPrior(MODEL.bounds),
        datasets=_datasets(2, seed=6),
        distance=MODEL.distance,
        run=replace(SERIAL, checkpoint=tmp_path / "checkpoints"),
        **(BUDGET | {"n_main": 1000, "n_desired": 50}),
    )
    first = sequential_calibration(**arguments)  # no seed: the folder keeps the drawn one
    calls = len(log.read_text().splitlines())
    again = sequential_calibration(**arguments)
    assert len(log.read_text().splitlines()) == calls
    for k in range(2):
        np.testing.assert_array_equal(again[k].posterior["mu"], first[k].posterior["mu"])
    assert sorted(p.name for p in (tmp_path / "checkpoints").iterdir()) == [
        "dataset_0.sqlite",
        "dataset_1.sqlite",
        "seed.json",
    ]


def test_bad_sequences_are_clear_errors():
    with pytest.raises(ValueError, match="datasets is empty"):
        sequential_calibration(MODEL, UniformPrior(MODEL.bounds), [], run=SERIAL)
    with pytest.raises(ValueError, match="got 2 simulators for 3 datasets"):
        sequential_calibration(
            [MODEL, MODEL],
            UniformPrior(MODEL.bounds),
            _datasets(3),
            run=SERIAL,
        )
