"""Write ``pymc_vcc/data/example_log.csv``: a synthetic field log of the built-in unit.

The truth is :func:`pymc_vcc.physics.simulate.simulate` of the built-in unit at nominal parameters
on the built-in step profile. The log covers 300 s to 1800 s of it (the unit already running),
sampled every 1.5-3.5 s, with sensor noise, engineering units (°C, bar gauge, g/s, %, rpm), ISO
timestamps, a logger outage of 80 s and a 45 s drop-out of the suction temperature sensor.
Run ``.venv/bin/python scripts/make_example_log.py`` to regenerate it.
"""

from __future__ import annotations

import csv
from datetime import datetime, timedelta
from pathlib import Path

import numpy as np

from pymc_vcc.physics.inputs import builtin_inputs, input_segments
from pymc_vcc.physics.simulate import simulate

START, END = 300.0, 1800.0
"""The stretch of the truth the log covers, s."""
OUTAGE = (1150.0, 1230.0)
"""Logger outage: no rows, s of the truth."""
TS_DROPOUT = (600.0, 645.0)
"""Suction temperature sensor reads nothing, s of the truth."""
CLOCK = datetime(2024, 7, 15, 13, 5, 0)
"""Wall-clock time of truth time START."""
OUT = Path(__file__).resolve().parents[1] / "pymc_vcc" / "data" / "example_log.csv"
ATMOSPHERE = 101325.0

COLUMNS = {
    # file column: (variable, to engineering units, noise sd in engineering units, decimals)
    "EEV_position_pct": ("valve_opening", lambda v: 100.0 * v, 0.0, 1),
    "Compressor_rpm": ("compressor_speed", lambda v: 60.0 * v, 0.0, 0),
    "T_outdoor_C": ("T_ambient", lambda v: v - 273.15, 0.1, 2),
    "T_return_air_C": ("T_indoor", lambda v: v - 273.15, 0.1, 2),
    "T_discharge_C": ("TD", lambda v: v - 273.15, 0.3, 2),
    "P_discharge_barg": ("PD", lambda v: (v - ATMOSPHERE) / 1e5, 0.05, 3),
    "T_suction_C": ("TS", lambda v: v - 273.15, 0.2, 2),
    "P_suction_barg": ("PS", lambda v: (v - ATMOSPHERE) / 1e5, 0.03, 3),
    "T_liquid_C": ("TC", lambda v: v - 273.15, 0.2, 2),
    "T_evap_out_C": ("TE", lambda v: v - 273.15, 0.2, 2),
    "Mass_flow_g_s": ("MDOT", lambda v: 1e3 * v, 0.2, 2),
}


def main() -> None:
    """Simulate the truth and write the log."""
    rng = np.random.default_rng(20240715)
    inputs = builtin_inputs()
    truth = simulate(inputs=inputs, t_end=END, output_interval=0.5)
    edges, held = input_segments(inputs)
    steps = rng.uniform(1.5, 3.5, size=int((END - START) / 1.5) + 1)
    times = START + np.concatenate([[0.0], np.cumsum(steps)])
    times = times[(times <= END) & ((times < OUTAGE[0]) | (times > OUTAGE[1]))]
    segment = np.clip(np.searchsorted(edges, times, side="right") - 1, 0, len(held) - 1)
    input_columns = {"valve_opening": 0, "compressor_speed": 1, "T_ambient": 2, "T_indoor": 3}
    rows = []
    for k, t in enumerate(times):
        stamp = CLOCK + timedelta(seconds=float(t - START))
        row = [stamp.isoformat(timespec="milliseconds"), "RUN"]
        for variable, convert, noise, decimals in COLUMNS.values():
            if variable in input_columns:
                si = held[segment[k], input_columns[variable]]
            else:
                si = float(np.interp(t, truth["time"].values, truth[variable].values))
            value = convert(si) + noise * rng.standard_normal()
            dropped = variable == "TS" and TS_DROPOUT[0] <= t <= TS_DROPOUT[1]
            row.append("" if dropped else f"{value:.{decimals}f}")
        rows.append(row)
    with OUT.open("w", newline="") as handle:
        writer = csv.writer(handle)
        writer.writerow(["Timestamp", "Status", *COLUMNS])
        writer.writerows(rows)
    print(f"wrote {len(rows)} rows to {OUT} ({OUT.stat().st_size / 1e3:.0f} kB)")


if __name__ == "__main__":
    main()
