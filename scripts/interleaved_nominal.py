"""Two checkouts' nominal CVODE runs timed side by side, for before/after speed claims.

    .venv/bin/python scripts/interleaved_nominal.py OLD_CHECKOUT NEW_CHECKOUT [ROUNDS]

Each checkout runs in a process of its own (its code on ``PYTHONPATH``) that builds the
built-in unit's 1060 s simulator once and warms it up; then the two take turns, five runs a
turn (the first alternating), ROUNDS turns each (default 40). Printed: each checkout's median
CPU time a run (the median of its turns' medians), the median and quartiles of the turns'
ratios new / old (steadier than either time on a shared machine) and the largest difference of
their outputs as a fraction of each output's largest magnitude.
"""

from __future__ import annotations

import os
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

WORKER = """
import sys, time
import numpy as np
from pymc_vcc.physics.simulate import VCCSimulator
simulator = VCCSimulator(t_window=(0.0, 1060.0), solver="cvode")
run = simulator({}, None)
np.save(sys.argv[1], np.stack([run[name].values for name in run.data_vars]))
print("ready", flush=True)
for line in sys.stdin:
    times = []
    for _ in range(int(line)):
        start = time.process_time()
        simulator({}, None)
        times.append(time.process_time() - start)
    print(float(np.median(times)), flush=True)
"""

RUNS_A_TURN = 5


def main() -> None:
    checkouts = [str(Path(path).resolve()) for path in sys.argv[1:3]]
    rounds = int(sys.argv[3]) if len(sys.argv) > 3 else 40
    folder = Path(tempfile.mkdtemp())
    workers = []
    for k, checkout in enumerate(checkouts):
        worker = subprocess.Popen(
            [sys.executable, "-c", WORKER, str(folder / f"{k}.npy")],
            cwd=checkout,
            env=os.environ | {"PYTHONPATH": checkout},
            stdin=subprocess.PIPE,
            stdout=subprocess.PIPE,
            text=True,
        )
        assert worker.stdin and worker.stdout
        while worker.stdout.readline().strip() != "ready":
            pass
        workers.append(worker)
    medians: list[list[float]] = [[], []]
    for turn in range(rounds):
        for k in (0, 1) if turn % 2 == 0 else (1, 0):
            worker = workers[k]
            assert worker.stdin and worker.stdout
            worker.stdin.write(f"{RUNS_A_TURN}\n")
            worker.stdin.flush()
            medians[k].append(1e3 * float(worker.stdout.readline()))
    for worker in workers:
        assert worker.stdin
        worker.stdin.close()
        worker.wait()
    old, new = np.array(medians[0]), np.array(medians[1])
    ratio = new / old
    low, mid, high = np.percentile(ratio, [25, 50, 75])
    print(f"old {np.median(old):.2f} ms, new {np.median(new):.2f} ms a run (CPU, median)")
    print(f"new / old: {mid:.3f} (quartiles {low:.3f}-{high:.3f}), {1 / mid:.2f} times as fast")
    before, after = np.load(folder / "0.npy"), np.load(folder / "1.npy")
    scale = np.nanmax(np.abs(before), axis=1, keepdims=True)
    print(
        f"largest output difference: {np.nanmax(np.abs(after - before) / scale):.1e} of its scale"
    )


if __name__ == "__main__":
    main()
