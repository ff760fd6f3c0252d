"""What a fit under the sensors' errors alone reads on each benchmark record, for the docs.

The exact stage of a model's own record (``coils="model"``) trusts the model to the sensors'
noise and biases. This probe asks what that trust does on every record of a real-units run:
from each row's posterior mean charge (the other parameters nominal), a least-squares fit of
the plateau summaries under the sensors' budget alone (forward differences of 0.001 of each
box), its Laplace sd of the charge, and the χ² of the fit against n − p degrees of freedom.
Run ``.venv/bin/python scripts/sensors_only_fit.py ROWS.jsonl VARIANT[,VARIANT...] OUT.jsonl``
(resumable: rows already in OUT are skipped).
"""

from __future__ import annotations

import json
import sys
import time
from pathlib import Path

import numpy as np
from scipy import stats
from scipy.optimize import least_squares

from pymc_vcc.inference.error_model import SensorAccuracy
from pymc_vcc.physics.simulate import VCCSimulator
from pymc_vcc.physics.unit import load_unit
from pymc_vcc.studies.record_budget import SensorBudget, held_inputs
from pymc_vcc.studies.truths import generate_truth
from pymc_vcc.studies.unit_log import NUISANCE, SETTLE

NAMES = ("M0", *NUISANCE)
STEP = 1e-3  # forward-difference step, of each box
FAILED = 1e3  # whitened residual of a failed simulation


def fit(variant: str, seed: int, start_charge: float) -> dict:
    """The sensors-only fit of one benchmark record from ``start_charge`` (kg)."""
    truth = generate_truth(variant, seed)
    unit = load_unit()
    observed = truth.observed
    model = VCCSimulator(
        unit,
        held_inputs(truth.inputs),
        outputs=[str(name) for name in observed.data_vars],
        t_window=(0.0, float(observed["time"].values[-1])),
        parameters=NAMES,
        solver="cvode",
        settle=SETTLE,
    )
    budget = SensorBudget.of(model, observed, SensorAccuracy()).budget()
    low = np.array([unit.parameters[name].low for name in NAMES])
    high = np.array([unit.parameters[name].high for name in NAMES])
    runs = [0]

    def residual(place: np.ndarray) -> np.ndarray:
        runs[0] += 1
        run = model(dict(zip(NAMES, map(float, low + place * (high - low)), strict=True)))
        if run.attrs["status"] != "ok":
            return np.full(budget.observed.size, FAILED)
        return budget.whitened(np.stack([run[name].values for name in budget.outputs]))

    start = np.array([unit.parameters[name].nominal for name in NAMES])
    start[0] = start_charge
    started = time.perf_counter()
    found = least_squares(
        residual, (start - low) / (high - low), bounds=(0, 1), diff_step=STEP, max_nfev=60
    )
    sd = np.sqrt(np.diag(np.linalg.pinv(found.jac.T @ found.jac))) * (high - low)
    chi2 = float(2 * found.cost)
    return {
        "variant": variant,
        "seed": seed,
        "truth_kg": truth.charge,
        "fit_kg": float(low[0] + found.x[0] * (high[0] - low[0])),
        "sd_kg": float(sd[0]),
        "chi2": chi2,
        "summaries": budget.observed.size,
        "p_value": float(stats.chi2.sf(chi2, budget.observed.size - len(NAMES))),
        "simulations": runs[0],
        "seconds": time.perf_counter() - started,
    }


def main(rows_file: str, variants: str, out_file: str) -> None:
    out = Path(out_file)
    done = set()
    if out.exists():
        done = {(r["variant"], r["seed"]) for r in map(json.loads, out.read_text().splitlines())}
    with out.open("a") as sink:
        for row in map(json.loads, Path(rows_file).read_text().splitlines()):
            if row["variant"] in variants.split(",") and (row["variant"], row["seed"]) not in done:
                result = fit(row["variant"], row["seed"], row["mean_kg"])
                print(json.dumps(result), file=sink, flush=True)


if __name__ == "__main__":
    main(*sys.argv[1:])
