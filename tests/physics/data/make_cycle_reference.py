"""Write the regression reference of the built-in cooling unit: ``cycle_reference.npz``.

The nine outputs and the diagnostics on the built-in Fig. 4 step profile (2120 s, every 10 s)
at nominal parameters and at 20 fixed uniform draws from the Table III box. The test
``tests/physics/test_cycle_reference.py`` compares the simulator against it. Regenerate only
when the physics changes on purpose:

    .venv/bin/python tests/physics/data/make_cycle_reference.py
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

REFERENCE = Path(__file__).with_name("cycle_reference.npz")
N_DRAWS = 20
SEED = 20261123
OUTPUT_INTERVAL = 10.0  # s


def reference_parameters() -> list[dict[str, float]]:
    """Nominal (an empty mapping) followed by the fixed box draws."""
    from pymc_vcc.physics.unit import load_unit

    draws = load_unit().parameters.sample_uniform(N_DRAWS, np.random.default_rng(SEED))
    return [{}, *draws]


def simulate_reference(params: dict[str, float]):
    """One reference run (outputs and diagnostics) with today's simulator; the wall-clock limit
    is lifted so that neither a cold compile nor a busy machine can fail a run."""
    from pymc_vcc.physics.simulate import simulate

    return simulate(
        params=params, output_interval=OUTPUT_INTERVAL, diagnostics=True, max_wall_time=3600.0
    )


def main() -> None:
    runs = [simulate_reference(params) for params in reference_parameters()]
    names = list(runs[0].data_vars)
    np.savez_compressed(
        REFERENCE,
        names=np.array(names),
        time=runs[0]["time"].values,
        values=np.stack([[run[name].values for name in names] for run in runs]),
        status=np.array([run.attrs["status"] for run in runs]),
        n_rhs=np.array([run.attrs["n_rhs"] for run in runs]),
    )
    failed = sum(run.attrs["status"] != "ok" for run in runs)
    print(f"wrote {REFERENCE}: {len(runs)} runs, {len(names)} variables, {failed} failed")


if __name__ == "__main__":
    main()
