"""One result layout for both samplers, as ArviZ and netCDF expect it.

``pm.sample_smc`` returns its per-stage statistics as object arrays holding one list per chain
(dims ``(chain, beta_dim_0)`` of length 1, which netCDF refuses as soon as a list mixes ints and
floats), the observed data of a ``pm.Simulator`` node as one 2-D variable without units, and
the settings of its last chain only. :func:`standard_layout` rewrites such a tree in the layout
of :func:`~pymc_vcc.inference.rejection.abc_rejection` and
:func:`~pymc_vcc.inference.predictive.simulate_predictive`:

* ``observed_data``: one variable per output (named as the output; ``<node>_<output>`` when the
  model has several simulator nodes) over its ``time``, with ``units`` and ``long_name``;
* ``sample_stats``: every stage statistic over ``(chain, stage)`` as numbers (NaN after the
  last stage of a chain that had fewer), and the totals over all chains as 0-d variables named
  as the rejection sampler's: ``n_simulations`` (run and resumed: what the posterior rests on),
  ``n_failed`` and ``n_resumed``.
"""

from __future__ import annotations

import numpy as np
import xarray as xr
from pymc.distributions.simulator import SimulatorRV
from pymc.model import Model

from pymc_vcc.inference.pymc.model import SimulatorFunction
from pymc_vcc.physics.cycles import MEASURABLE_OUTPUT_INFO

TOTALS = {
    "n_simulations": ("simulations", "resumed_simulations"),
    "n_failed": ("failed_simulations",),
    "n_resumed": ("resumed_simulations",),
}
"""Total over all chains and stages -> the stage statistics it adds up (those present; the
first must be)."""


def _numbers(row: np.ndarray) -> np.ndarray:
    """One chain's stage values as floats: ``row`` holds numbers, or one list of them when
    PyMC stacked chains with different numbers of stages."""
    return np.concatenate([np.asarray(entry, dtype=float).ravel() for entry in row])


def stage_statistics(sample_stats: xr.Dataset, n_chains: int | None = None) -> xr.Dataset:
    """``sample_stats`` with every per-stage statistic over ``(chain, stage)``: ragged lists of
    several chains, and the stages of a single chain (``n_chains == 1``), which PyMC lays out
    along ``chain``."""
    single = n_chains == 1 and sample_stats.sizes.get("chain", 1) != 1
    if single:
        sample_stats = sample_stats.expand_dims("smc_chain").rename(chain="stage_index")
        sample_stats = sample_stats.rename(smc_chain="chain").drop_vars("stage_index")
    per_stage = {}
    for name, variable in sample_stats.data_vars.items():
        if variable.dims[:1] != ("chain",):
            continue
        if variable.dtype != object and not (single and variable.ndim == 2):
            continue
        if single:
            chains = [np.asarray(row, dtype=float) for row in variable.values]
        else:
            chains = [_numbers(np.atleast_1d(row)) for row in variable.values]
        width = max(len(stages) for stages in chains)
        table = np.full((len(chains), width), np.nan)
        for index, stages in enumerate(chains):
            table[index, : len(stages)] = stages
        per_stage[name] = variable.dims[1:], table
    result = sample_stats.drop_vars(list(per_stage)).drop_dims(
        [dim for dims, _ in per_stage.values() for dim in dims], errors="ignore"
    )
    for name, (_, table) in per_stage.items():
        result[name] = (("chain", "stage"), table)
    if "chain" in result.dims and "chain" not in result.coords:
        result = result.assign_coords(chain=np.arange(result.sizes["chain"]))
    if per_stage:
        result = result.assign_coords(stage=np.arange(result.sizes["stage"]))
        result["stage"].attrs["long_name"] = "SMC stage (tempering step)"
    for total, stats in TOTALS.items():
        if stats[0] in result:
            counts = [np.nansum(result[stat].values) for stat in stats if stat in result]
            result[total] = ((), int(sum(counts)))
    return result


def observed_outputs(model: Model) -> xr.Dataset:
    """One variable per output of every ``pm.Simulator`` node of ``model`` made by
    :func:`~pymc_vcc.inference.pymc.model.add_simulator`, with units and long names."""
    nodes = [
        rv
        for rv in model.observed_RVs
        if isinstance(rv.owner.op, SimulatorRV)
        and isinstance(type(rv.owner.op).fn, SimulatorFunction)
    ]
    variables = {}
    for rv in nodes:
        dataset = type(rv.owner.op).fn.observed.dataset
        time_dim = f"{rv.name}_time" if len(nodes) > 1 else "time"
        for output, variable in dataset.data_vars.items():
            attrs = dict(variable.attrs)
            if output in MEASURABLE_OUTPUT_INFO:
                attrs.setdefault("long_name", MEASURABLE_OUTPUT_INFO[output][0])
                attrs.setdefault("units", MEASURABLE_OUTPUT_INFO[output][1])
            name = f"{rv.name}_{output}" if len(nodes) > 1 else str(output)
            values = variable.rename({variable.dims[0]: time_dim}).assign_attrs(attrs)
            time = variable[variable.dims[0]]
            variables[name] = values.drop_vars(values.coords, errors="ignore").assign_coords(
                {time_dim: (time_dim, time.values, time.attrs)}
            )
    return xr.Dataset(variables)


def standard_layout(tree: xr.DataTree, model: Model) -> xr.DataTree:
    """A result of ``pm.sample_smc`` in the layout of the project's samplers (see the module).

    :func:`~pymc_vcc.inference.pymc.smc.sample_smc_abc` returns it so; a result of
    ``pm.sample_smc(kernel=ParallelIMH)`` (or of PyMC's own kernels) needs this call.

    Args:
        tree: the DataTree ``pm.sample_smc`` returned (left unchanged).
        model: the model it sampled.

    Returns:
        A copy with ``sample_stats`` over ``(chain, stage)`` with the simulation totals, and
        ``observed_data`` one variable per output with units.
    """
    result = tree.copy()
    if "sample_stats" in result.children:
        stats = result["sample_stats"].to_dataset()
        n_chains = result["posterior"].sizes["chain"] if "posterior" in result.children else None
        result["sample_stats"] = xr.DataTree(stage_statistics(stats, n_chains))
    observed = observed_outputs(model)
    if observed.data_vars and "observed_data" in result.children:
        attrs = result["observed_data"].attrs
        result["observed_data"] = xr.DataTree(observed.assign_attrs(attrs))
    return result


__all__ = ["TOTALS", "observed_outputs", "stage_statistics", "standard_layout"]
