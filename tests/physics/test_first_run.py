"""The first run on a fresh machine: compiling the model never counts against a simulation's
wall-clock limit, is announced on screen, and gives the same numbers as a warm cache."""

import os
import subprocess
import sys
import textwrap

import numpy as np
import pytest
import xarray as xr

from pymc_vcc.physics.simulate import simulate

FIRST_RUN = textwrap.dedent(
    """
    import sys
    from pymc_vcc.physics.simulate import simulate

    result = simulate(t_end=100.0, max_wall_time=2.0)  # far less than a cold compile
    print(result.attrs["status"], result.attrs["failure_reason"])
    result.to_netcdf(sys.argv[1], engine="h5netcdf")
    """
)


@pytest.mark.slow
def test_the_first_run_with_an_empty_cache_passes_and_matches_a_warm_one(tmp_path):
    caches = {
        "NUMBA_CACHE_DIR": str(tmp_path / "numba"),
        "PYMC_VCC_CACHE": str(tmp_path / "tables"),
    }
    out = tmp_path / "first.nc"
    run = subprocess.run(
        [sys.executable, "-c", FIRST_RUN, str(out)],
        env={**os.environ, **caches},
        capture_output=True,
        text=True,
        timeout=900,
    )
    assert run.returncode == 0, run.stderr
    assert run.stdout.strip() == "ok"
    assert "compiling the cycle model, once" in run.stderr
    first = xr.open_dataset(out, engine="h5netcdf")
    warm = simulate(t_end=100.0)
    for name in warm.data_vars:
        np.testing.assert_array_equal(first[name].values, warm[name].values)
    # a second process (a sampler's worker) loads CVODE's C callbacks from the same cache
    second = subprocess.run(
        [sys.executable, "-c", SECOND_RUN],
        env={**os.environ, **caches},
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert second.returncode == 0, second.stderr
    assert second.stdout.split() == ["ok", "2", "2"], second.stdout


SECOND_RUN = textwrap.dedent(
    """
    from pymc_vcc.physics.integration import callbacks
    from pymc_vcc.physics.simulate import simulate

    made = []
    compile_callback = callbacks._compiled
    callbacks._compiled = lambda *arguments: made.append(compile_callback(*arguments)) or made[-1]
    result = simulate(t_end=10.0, solver="cvode")
    print(result.attrs["status"], len(made), sum(callback.cache_hits for callback in made))
    """
)


STALE_CACHE = textwrap.dedent(
    """
    import sys
    from pathlib import Path
    from pymc_vcc.physics.integration import warmup
    from pymc_vcc.physics.components.smooth import smooth_pos

    smooth_pos(1.0, 0.1)  # compiled and cached
    index = Path(smooth_pos._cache._cache_file._index_path)
    stamp = Path(sys.argv[1])
    assert index.exists()
    assert warmup.drop_stale_cache(stamp), "no digest recorded yet: the cache counts as stale"
    assert not index.exists() and stamp.read_text() == warmup.source_digest()
    smooth_pos(1, 1)  # a new signature compiles and is cached again
    assert index.exists()
    assert not warmup.drop_stale_cache(stamp), "same sources: the cache is kept"
    assert index.exists()
    stamp.write_text("the digest of other sources")
    assert warmup.drop_stale_cache(stamp) and not index.exists()
    """
)


def test_kernels_cached_from_other_sources_are_compiled_afresh(tmp_path):
    """Numba checks a cached kernel against its own file only; the digest of the whole physics
    package catches an edit to a kernel it calls in another file."""
    run = subprocess.run(
        [sys.executable, "-c", STALE_CACHE, str(tmp_path / "stamp")],
        env={**os.environ, "NUMBA_CACHE_DIR": str(tmp_path / "numba")},
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert run.returncode == 0, run.stderr
