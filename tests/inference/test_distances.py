"""The KS distance equals scipy's two-sample KS statistic, per output, averaged (eq. 2)."""

import numpy as np
import pytest
import xarray as xr
from scipy import stats

from pymc_vcc.inference.distances import (
    ks_distance,
    ks_distances,
    ks_statistics,
    wasserstein_distances,
    windowed_distances,
)


@pytest.mark.filterwarnings("ignore::RuntimeWarning")  # scipy's p-value for tiny samples
@pytest.mark.parametrize(("m", "n"), [(1, 1), (7, 7), (50, 13), (13, 50), (200, 1060)])
def test_ks_statistics_equal_scipy_for_continuous_data(m, n):
    rng = np.random.default_rng(m * 1000 + n)
    sims = rng.normal(size=(20, 3, m)) + rng.normal(scale=0.5, size=(20, 3, 1))
    obs = rng.normal(size=(3, n))
    ours = ks_statistics(sims, obs)
    for i in range(sims.shape[0]):
        for j in range(3):
            assert ours[i, j] == pytest.approx(
                stats.ks_2samp(sims[i, j], obs[j]).statistic, abs=1e-12
            )


def test_ks_statistics_equal_scipy_with_ties():
    rng = np.random.default_rng(3)
    sims = rng.integers(0, 6, size=(200, 2, 17)).astype(float)
    obs = rng.integers(0, 6, size=(2, 11)).astype(float)
    ours = ks_statistics(sims, obs)
    expected = [
        [stats.ks_2samp(sims[i, j], obs[j]).statistic for j in range(2)] for i in range(200)
    ]
    np.testing.assert_allclose(ours, expected, rtol=0, atol=1e-12)


def test_identical_samples_have_distance_zero_and_disjoint_ones_one():
    obs = np.linspace(0.0, 1.0, 30)[np.newaxis, :]
    assert ks_distance(obs, obs) == 0.0
    assert ks_distance(obs + 5.0, obs) == 1.0
    assert ks_distance(obs - 5.0, obs) == 1.0


def test_ks_distance_averages_outputs_of_datasets_and_selects_outputs():
    rng = np.random.default_rng(4)
    sim = xr.Dataset({name: ("time", rng.normal(size=40)) for name in ("TD", "PD", "TS")})
    obs = xr.Dataset({name: ("time", rng.normal(0.3, size=25)) for name in ("TD", "PD", "TS")})
    per_output = {
        name: stats.ks_2samp(sim[name].values, obs[name].values).statistic
        for name in ("TD", "PD", "TS")
    }
    assert ks_distance(sim, obs) == pytest.approx(np.mean(list(per_output.values())), abs=1e-12)
    assert ks_distance(sim, obs, outputs=["PD", "TS"]) == pytest.approx(
        (per_output["PD"] + per_output["TS"]) / 2, abs=1e-12
    )


def test_ks_distances_is_the_batch_form_of_ks_distance():
    rng = np.random.default_rng(5)
    sims = rng.normal(size=(30, 4, 21))
    obs = rng.normal(size=(4, 33))
    batch = ks_distances(sims, obs)
    assert batch.shape == (30,)
    np.testing.assert_allclose(batch, [ks_distance(sim, obs) for sim in sims], atol=1e-15)


def test_ks_distance_rejects_unknown_outputs_and_non_finite_values():
    obs = xr.Dataset({"TD": ("time", np.arange(5.0))})
    with pytest.raises(ValueError, match=r"unknown outputs \['PE'\]"):
        ks_distance(obs, obs, outputs=["PE"])
    with pytest.raises(ValueError, match="non-finite"):
        ks_distance(obs, obs.where(obs.TD != 2.0))
    with pytest.raises(ValueError, match="NaN or infinite"):
        ks_statistics(np.full((1, 1, 3), np.nan), np.zeros((1, 3)))
    with pytest.raises(ValueError, match="lacks output"):
        ks_distance(xr.Dataset({"PD": obs.TD}), obs)


def test_ks_statistics_rejects_mismatched_shapes():
    with pytest.raises(ValueError, match="expected sims"):
        ks_statistics(np.zeros((2, 3, 4)), np.zeros((2, 4)))


def test_wasserstein_distance_is_scipys_over_the_observed_spread():
    rng = np.random.default_rng(0)
    obs = rng.normal(size=(2, 50)) * [[1.0], [10.0]]
    for m in (50, 37):
        sims = rng.normal(0.3, 1.0, size=(3, 2, m)) * [[1.0], [10.0]]
        expected = [
            np.mean([stats.wasserstein_distance(sim[j], obs[j]) / obs[j].std() for j in range(2)])
            for sim in sims
        ]
        np.testing.assert_allclose(wasserstein_distances(sims, obs), expected, rtol=1e-12)


def test_windowed_distance_averages_out_noise_but_sees_a_shift():
    rng = np.random.default_rng(1)
    signal = np.sin(np.arange(600) / 40.0)[np.newaxis]
    obs = signal + 0.05 * rng.standard_normal(signal.shape)
    noisy_copy = signal + 0.05 * rng.standard_normal(signal.shape)
    shifted = signal + 0.1
    near, far = windowed_distances(np.stack([noisy_copy, shifted]), obs, window=10)
    assert near < 0.05 < 0.1 < far
    with pytest.raises(ValueError, match="observed grid"):
        windowed_distances(np.stack([signal[:, :300]]), obs)
