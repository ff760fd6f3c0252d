"""Distances between simulated and observed output time series.

The paper's distance (its eq. 2) is the two-sample Kolmogorov–Smirnov statistic of each output's
values, averaged over outputs. Samplers call distances in batch form,
``distance(sims, obs) -> d`` with ``sims`` of shape (n_simulations, n_outputs, m) and ``obs`` of
shape (n_outputs, n), returning ``d`` of shape (n_simulations,); ``m`` and ``n`` may differ.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence

import numpy as np
import xarray as xr
from scipy.stats import wasserstein_distance

from pymc_vcc.inference.series import OutputData, prepare_observed

BatchDistance = Callable[[np.ndarray, np.ndarray], np.ndarray]
"""``distance(sims (N, n_outputs, m), obs (n_outputs, n)) -> (N,)``, dimensionless."""


def _require_finite(values: np.ndarray, what: str) -> None:
    if not np.isfinite(values).all():
        raise ValueError(
            f"{what} contain NaN or infinite values; the KS statistic needs finite data"
        )


def ks_statistics(sims: np.ndarray, obs: np.ndarray) -> np.ndarray:
    """Two-sample KS statistic of every output of every simulation against the observations.

    Args:
        sims: simulated values, shape (N, n_outputs, m).
        obs: observed values, shape (n_outputs, n).

    Returns:
        Array (N, n_outputs): sup_t |F_sim(t) − F_obs(t)| of each output's empirical CDFs,
        equal to ``scipy.stats.ks_2samp(sim, obs).statistic``.
    """
    sims = np.asarray(sims, dtype=float)
    obs = np.asarray(obs, dtype=float)
    if sims.ndim != 3 or obs.ndim != 2 or sims.shape[1] != obs.shape[0]:
        raise ValueError(
            f"expected sims (N, n_outputs, m) and obs (n_outputs, n); got {sims.shape} and "
            f"{obs.shape}"
        )
    if sims.shape[2] == 0 or obs.shape[1] == 0:
        raise ValueError("the KS statistic needs at least one value per output in sims and obs")
    _require_finite(sims, "simulated outputs")
    _require_finite(obs, "observed outputs")
    n_sims, n_outputs, m = sims.shape
    n = obs.shape[1]
    sorted_sims = np.sort(sims, axis=2)
    below = np.arange(m)  # sims strictly below the i-th sorted value (exact for the first tie)
    statistics = np.empty((n_sims, n_outputs))
    for j in range(n_outputs):
        sorted_obs = np.sort(obs[j])
        at_or_below = np.searchsorted(sorted_obs, sorted_sims[:, j, :], side="right")
        strictly_below = np.searchsorted(sorted_obs, sorted_sims[:, j, :], side="left")
        # Integer numerators over n*m: the sup of F_sim − F_obs sits at a simulated value (after
        # its jump), the sup of F_obs − F_sim just before one (or is 0 beyond all of them).
        sim_ahead = ((below + 1) * n - at_or_below * m).max(axis=1)
        obs_ahead = (strictly_below * m - below * n).max(axis=1)
        statistics[:, j] = np.maximum(np.maximum(sim_ahead, obs_ahead), 0) / (n * m)
    return statistics


def ks_distances(sims: np.ndarray, obs: np.ndarray) -> np.ndarray:
    """The paper's distance for many simulations at once: KS statistics averaged over outputs.

    Parameters
    ----------
    sims
        Simulated outputs, shape (N, n_outputs, m), in the outputs' SI units.
    obs
        Observed outputs, shape (n_outputs, n), same units and output order.

    Returns
    -------
    numpy.ndarray
        Shape (N,), each distance in [0, 1] (dimensionless).
    """
    return ks_statistics(sims, obs).mean(axis=1)


def ks_distance(
    sim: OutputData,
    obs: OutputData,
    outputs: Sequence[str] | None = None,
) -> float:
    """KS distance of one simulation (eq. 2 of the paper, averaged over outputs).

    Args:
        sim: simulated outputs, a Dataset (one 1-D variable per output) or an array
            (outputs, m); a 1-D array is one output.
        obs: observed outputs in the same form (Dataset variables or array rows), (outputs, n).
        outputs: output names to compare (default: every output of ``obs``); for arrays the rows
            are named ``y0, y1, ...``.

    Returns:
        The mean over outputs of the two-sample KS statistic, in [0, 1].
    """
    observed = prepare_observed(obs, outputs)
    if isinstance(sim, xr.Dataset):
        missing = [name for name in observed.names if name not in sim.data_vars]
        if missing:
            raise ValueError(f"simulated Dataset lacks output(s) {missing}")
        rows = [np.asarray(sim[name].values, dtype=float).ravel() for name in observed.names]
    else:
        array = np.asarray(sim, dtype=float)
        if array.ndim == 1:
            array = array[np.newaxis, :]
        if array.ndim != 2 or array.shape[0] != len(observed.all_names):
            raise ValueError(
                f"simulated array has shape {array.shape}; expected ({len(observed.all_names)}, m)"
            )
        rows = [array[index] for index in observed.row_indices]
    statistics = [
        ks_statistics(row[np.newaxis, np.newaxis, :], observed.values[j : j + 1])[0, 0]
        for j, row in enumerate(rows)
    ]
    return float(np.mean(statistics))


def output_scales(obs: np.ndarray) -> np.ndarray:
    """Each observed output's spread over time (n_outputs, 1); a tiny floor if it is flat."""
    spread = obs.std(axis=1, keepdims=True)
    floor = 1e-6 * np.abs(obs).mean(axis=1, keepdims=True)
    return np.maximum(spread, np.maximum(floor, np.finfo(float).tiny))


def wasserstein_distances(sims: np.ndarray, obs: np.ndarray) -> np.ndarray:
    """1-D Wasserstein-1 distance of each output's values, over the observed spread, averaged.

    Like KS it compares value distributions (no time alignment), but it keeps decreasing as the
    simulated values approach the observed ones instead of saturating at 1.

    Parameters
    ----------
    sims
        Simulated outputs, shape (N, n_outputs, m), in the outputs' SI units.
    obs
        Observed outputs, shape (n_outputs, n), same units and output order.

    Returns
    -------
    numpy.ndarray
        Shape (N,), dimensionless (each output's distance over its observed spread).
    """
    sims = np.asarray(sims, dtype=float)
    obs = np.asarray(obs, dtype=float)
    _require_finite(sims, "simulated outputs")
    _require_finite(obs, "observed outputs")
    if sims.shape[2] == obs.shape[1]:  # equal sizes: the mean gap of the sorted values
        gaps = np.abs(np.sort(sims, axis=2) - np.sort(obs, axis=1)[np.newaxis]).mean(axis=2)
    else:
        gaps = np.array(
            [[wasserstein_distance(row, obs[j]) for j, row in enumerate(sim)] for sim in sims]
        )
    return (gaps / output_scales(obs).T).mean(axis=1)


def window_means(values: np.ndarray, window: int) -> np.ndarray:
    """Means of consecutive ``window``-sample blocks along the last (time) axis; a partial
    block at the end is dropped. (..., n) → (..., n // window)."""
    usable = values.shape[-1] - values.shape[-1] % window
    if usable == 0:
        raise ValueError(f"window={window} exceeds the {values.shape[-1]} observed time points")
    return values[..., :usable].reshape(*values.shape[:-1], -1, window).mean(axis=-1)


def windowed_distances(sims: np.ndarray, obs: np.ndarray, window: int = 10) -> np.ndarray:
    """RMS difference of ``window``-sample means over time, over the observed spread, averaged.

    Time-aligned (it needs the simulations on the observed grid): averaging over windows
    divides the sensor noise by √window while keeping the slow dynamics that carry the
    parameters.

    Parameters
    ----------
    sims
        Simulated outputs on the observed time grid, shape (N, n_outputs, n), SI units.
    obs
        Observed outputs, shape (n_outputs, n), same units and output order.
    window
        Samples per window (10: 10 s windows on the 1 s grid).

    Returns
    -------
    numpy.ndarray
        Shape (N,), dimensionless (RMS gap over each output's observed spread).
    """
    sims = np.asarray(sims, dtype=float)
    obs = np.asarray(obs, dtype=float)
    if sims.shape[1:] != obs.shape:
        raise ValueError(
            f"windowed distance needs simulations on the observed grid: sims {sims.shape[1:]} "
            f"per simulation, observed {obs.shape}"
        )
    _require_finite(sims, "simulated outputs")
    _require_finite(obs, "observed outputs")
    gaps = (window_means(sims, window) - window_means(obs, window)) / output_scales(obs)
    return np.sqrt((gaps**2).mean(axis=2)).mean(axis=1)


BATCH_DISTANCES: dict[str, BatchDistance] = {
    "ks": ks_distances,
    "wasserstein": wasserstein_distances,
    "windowed": windowed_distances,
}
"""The ABC distances a study can be asked for by name: the paper's KS, Wasserstein-1 and the
time-aligned windowed distance."""
