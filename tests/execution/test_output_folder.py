"""One run per output folder: a lock that refuses a second run and outlives a dead one, atomic
result files, and a writable folder checked before any simulation."""

import json
import subprocess
import sys
import textwrap

import pytest

from pymc_vcc.cli import main
from pymc_vcc.execution.output_folder import (
    LOCK_NAME,
    OutputFolderError,
    atomic_path,
    claim_output_folder,
)
from pymc_vcc.studies import StudySettings, sobol_study

HOLDER = textwrap.dedent(
    """
    import sys, time
    from pymc_vcc.execution.output_folder import claim_output_folder

    with claim_output_folder(sys.argv[1]):
        print("holding", flush=True)
        time.sleep(120)
    """
)


@pytest.fixture
def held_folder(tmp_path):
    """A folder held by another live process (killed after the test)."""
    folder = tmp_path / "out"
    holder = subprocess.Popen(
        [sys.executable, "-c", HOLDER, str(folder)], stdout=subprocess.PIPE, text=True
    )
    assert holder.stdout.readline().strip() == "holding"
    yield folder, holder.pid
    holder.kill()
    holder.wait()


def test_a_second_run_on_a_held_folder_is_refused_naming_the_other_run(held_folder, capsys):
    folder, pid = held_folder
    message = rf"{folder}.*in use by another run \(pid {pid}"
    with pytest.raises(OutputFolderError, match=message), claim_output_folder(folder):
        pass
    # the command refuses at once, before any simulation, in one line
    status = main(["sobol", "--budget", "smoke", "--executor", "serial", "--out", str(folder)])
    error = capsys.readouterr().err
    assert status == 2
    assert f"in use by another run (pid {pid}" in error and "Traceback" not in error
    assert not (folder / "checkpoints").exists()


def test_a_lock_left_by_a_dead_run_is_taken_over_with_a_message(tmp_path, capsys):
    folder = tmp_path / "out"
    folder.mkdir()
    dead = {"pid": 999999, "host": "elsewhere", "started": "2026-01-01T00:00:00+00:00"}
    (folder / LOCK_NAME).write_text(json.dumps(dead))
    with claim_output_folder(folder):
        owner = json.loads((folder / LOCK_NAME).read_text())
    assert "pid 999999 on elsewhere" in capsys.readouterr().err
    assert owner["pid"] != 999999
    assert (folder / LOCK_NAME).read_text() == ""  # released: empty, kept in place


def test_claims_nest_within_one_process(tmp_path):
    with claim_output_folder(tmp_path), claim_output_folder(tmp_path / "."):
        pass
    with claim_output_folder(tmp_path):  # released by the outer claim
        pass


def test_an_unwritable_folder_is_refused_before_any_simulation(tmp_path, capsys):
    blocker = tmp_path / "a_file"
    blocker.write_text("not a folder")
    with pytest.raises(OutputFolderError, match="is not writable"):
        sobol_study(StudySettings(budget="smoke", executor="serial", out=blocker / "out"))
    status = main(["leak", "--budget", "smoke", "--out", str(blocker / "out")])
    error = capsys.readouterr().err.strip()
    assert status == 2 and error.count("\n") == 0 and "is not writable" in error


def test_a_run_that_wrote_nothing_leaves_no_folder_it_made(tmp_path, capsys):
    """A command stopped by a bad option leaves no empty output folder (nor the parents it
    made); a folder that was there, or that the run wrote a file into, stays."""
    new = tmp_path / "a" / "b" / "out"
    with pytest.raises(ValueError), claim_output_folder(new):
        (new / "checkpoints").mkdir()
        raise ValueError("a bad option")
    assert list(tmp_path.iterdir()) == []
    with claim_output_folder(new):
        (new / "summary.json").write_text("{}")
    assert (new / "summary.json").is_file()
    there = tmp_path / "there"
    there.mkdir()
    with claim_output_folder(there):
        pass
    assert there.is_dir()
    status = main(["validate", "--faults", "all", "--later-start", "99999", "--out",
                   str(tmp_path / "cli")])  # fmt: skip
    assert status == 2 and "later_start" in capsys.readouterr().err
    assert not (tmp_path / "cli").exists()


def test_an_interrupted_write_leaves_the_previous_file_whole(tmp_path):
    target = tmp_path / "summary.json"
    target.write_text('{"good": true}')
    with pytest.raises(KeyboardInterrupt), atomic_path(target) as partial:
        partial.write_text('{"trunc')
        raise KeyboardInterrupt
    assert target.read_text() == '{"good": true}'
    assert [path.name for path in tmp_path.iterdir()] == ["summary.json"]
    with atomic_path(target) as partial:
        partial.write_text('{"new": true}')
    assert target.read_text() == '{"new": true}'


def test_resume_without_a_checkpoint_says_so(tmp_path, capsys):
    status = main(["sobol", "--budget", "smoke", "--out", str(tmp_path), "--resume"])
    error = capsys.readouterr().err
    assert status == 2 and "nothing to resume" in error and "sobol" in error
