"""A unit's own log through the command line: calibrate at commissioning, then the leak check
and the fault diagnosis."""

import json
import shutil

import pytest
import xarray as xr

from pymc_vcc.cli import main
from pymc_vcc.io.measurements import column_map_beside, example_log_path, load_log
from pymc_vcc.studies.diagnose import ROUNDS


@pytest.mark.slow
def test_calibrate_then_leak_on_the_shipped_example_log(tmp_path, capsys):
    """The shipped log runs with its path alone (its column map beside it); the leak check
    reads the commissioning folder as its prior."""
    log = str(example_log_path())
    commissioning = tmp_path / "commissioning"
    assert main(["calibrate", log, "--budget", "smoke", "--out", str(commissioning)]) == 0
    out = capsys.readouterr().out
    assert "charge M0 =" in out and "model reproduces it" in out
    for name in ("posterior.nc", "prior.nc", "summary.json", "report.txt", "charge.png"):
        assert (commissioning / name).is_file(), name
    tree = xr.open_datatree(commissioning / "posterior.nc", engine="h5netcdf")
    stats = tree["sample_stats"]
    assert set(stats["output"].values) == set(load_log(log).observed.data_vars)
    assert (stats["ppc_p_value"] >= 0).all() and (stats["ppc_p_value"] <= 1).all()
    assert 0.9 <= float(tree["posterior"]["M0"].mean()) <= 2.2

    later = tmp_path / "later"
    code = main(["leak", log, "--prior", str(commissioning), "--budget", "smoke", "--out",
                 str(later), "--json"])  # fmt: skip
    assert code == 0
    summary = json.loads(capsys.readouterr().out.strip().splitlines()[-1])
    assert 0.0 <= summary["alarm"] <= 1.0
    assert summary["commissioning_kg"] == pytest.approx(float(tree["posterior"]["M0"].mean()))
    assert (
        summary["charge"]["low_kg"] <= summary["charge"]["mean_kg"] <= summary["charge"]["high_kg"]
    )
    assert summary["n_simulations"] > 0
    # the tempering starts where every fault is as likely as not, not from the healthy spike
    stats = xr.open_datatree(later / "posterior.nc", engine="h5netcdf")["sample_stats"]
    assert stats.attrs["tempered_from"] == "reference"
    assert tree["sample_stats"].attrs["tempered_from"] == "prior"

    diagnosed = tmp_path / "diagnosed"
    code = main(["diagnose", log, "--prior", str(commissioning), "--budget", "smoke", "--out",
                 str(diagnosed)])  # fmt: skip
    assert code == 0
    report = capsys.readouterr().out
    assert report.startswith("verdict: ") and "non-condensable gas" in report
    for name in ("posterior.nc", "summary.json", "report.txt", "faults.png"):
        assert (diagnosed / name).is_file(), name
    faults = json.loads((diagnosed / "summary.json").read_text())["faults"]
    assert len(faults) == 7 and all(0.0 <= f["probability"] <= 1.0 for f in faults.values())
    diagnosis = xr.open_datatree(diagnosed / "posterior.nc", engine="h5netcdf")
    assert {"DP_RESTR", "P_NCG", "M0", "FO_FLOW"} <= set(diagnosis["posterior"].data_vars)
    # the model's error drawn again at the first round's posterior (the faulted unit)
    assert int(diagnosis["sample_stats"]["error_rounds"]) == ROUNDS == 2


def test_a_bad_log_is_refused_in_one_line_before_any_simulation(tmp_path, capsys):
    log = tmp_path / "unit.csv"
    shutil.copy(example_log_path(), log)
    assert main(["calibrate", str(log), "--out", str(tmp_path / "a")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "no column map" in err and "unit.columns.toml" in err
    text = column_map_beside(example_log_path()).read_text()
    column_map_beside(log).write_text(text.replace('T_outdoor_C = "T_ambient"\n', "", 1))
    assert main(["calibrate", str(log), "--out", str(tmp_path / "b")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "T_ambient" in err
    assert not (tmp_path / "b").exists()  # refused before the folder was claimed
    assert main(["leak", "--prior", str(tmp_path), "--out", str(tmp_path / "c")]) == 2
    assert "needs a LOG" in capsys.readouterr().err
    log_path = str(example_log_path())
    assert main(["leak", log_path, "--method", "smc", "--out", str(tmp_path / "d")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "a LOG takes likelihood or rejection" in err
    for option, value, message in [
        ("--fault-probability", "1.5", "fault probability must lie in (0, 1), got 1.5"),
        ("--drift", "2", "drift must lie in [0, 1] (a fraction of each range), got 2.0"),
    ]:
        argv = ["diagnose", log_path, "--prior", str(tmp_path), option, value]
        assert main([*argv, "--out", str(tmp_path / "e")]) == 2
        err = capsys.readouterr().err
        assert err.count("\n") == 1 and message in err
        assert not (tmp_path / "e").exists()
