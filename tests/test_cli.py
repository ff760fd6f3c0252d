"""The command line parses and reports its sub-commands."""

import numpy as np
import pytest

from pymc_vcc.cli import build_parser, main


def test_help_lists_commands(capsys):
    with pytest.raises(SystemExit) as exit_info:
        main(["--help"])
    assert exit_info.value.code == 0
    out = capsys.readouterr().out
    assert "demo" in out and "bench" in out


def test_unknown_benchmark_is_a_clear_error():
    with pytest.raises(SystemExit, match="unknown benchmark"):
        main(["bench", "--only", "no-such-benchmark"])


def test_parser_requires_a_command():
    with pytest.raises(SystemExit):
        build_parser().parse_args([])


@pytest.mark.parametrize(
    ("arguments", "message"),
    [
        (["--workers", "0"], "argument --workers: must be a positive integer, got '0'"),
        (["--time-limit", "-3"], "argument --time-limit: must be a positive number"),
    ],
)
def test_bad_numbers_are_refused_by_every_executor(arguments, message, capsys):
    for executor in ("serial", "processes", "dask"):
        with pytest.raises(SystemExit) as exit_info:
            main(["sobol", "--executor", executor, *arguments])
        assert exit_info.value.code == 2
        assert message in capsys.readouterr().err


def test_errors_are_one_line_and_exit_2_and_debug_shows_the_traceback(tmp_path, capsys):
    dead = ["--executor", "dask", "--scheduler", "tcp://127.0.0.1:9", "--out", str(tmp_path)]
    assert main(["sobol", *dead]) == 2
    error = capsys.readouterr().err
    assert error.count("\n") == 1 and "Traceback" not in error
    assert "no Dask scheduler answers at tcp://127.0.0.1:9" in error
    with pytest.raises(ConnectionError, match="no Dask scheduler answers"):
        main(["sobol", *dead, "--debug"])


def test_solver_and_sampler_options():
    args = build_parser().parse_args(
        ["estimate", "--method", "smc", "--solver", "cvode", "--epsilon", "0.02"]
    )
    assert (args.method, args.solver, args.epsilon, args.particles) == ("smc", "cvode", 0.02, None)
    assert build_parser().parse_args(["leak"]).solver is None  # the study's own choice
    with pytest.raises(SystemExit):
        build_parser().parse_args(["sobol", "--solver", "euler"])


def test_benchmark_table_puts_solvers_side_by_side():
    from pymc_vcc.benchmarks.simulator import format_table

    table = format_table(
        {"sim_seconds_median_radau": 0.2, "sim_seconds_median_cvode": 0.05, "rhs_evals_radau": 2437}
    )
    header, median_row = table.splitlines()[:2]
    assert header.split() == ["radau", "cvode"]
    assert median_row.split() == ["sim_seconds_median", "0.2", "0.05"]
    assert "2437" in table


def test_version(capsys):
    from pymc_vcc import __version__

    with pytest.raises(SystemExit) as exit_info:
        main(["--version"])
    assert exit_info.value.code == 0
    assert capsys.readouterr().out.strip() == f"pymc-vcc {__version__}"


def test_every_option_has_a_help_text():
    parser = build_parser()
    commands = next(a for a in parser._actions if a.dest == "command").choices
    for name, command in commands.items():
        for action in command._actions:
            assert action.help, (name, action.option_strings)


def test_noisy_data_options_parse():
    args = build_parser().parse_args(
        ["leak", "--method", "likelihood", "--sensor-noise", "typical", "--references", "1.2"]
    )
    assert (args.sampler, args.sensor_noise, args.references) == ("likelihood", "typical", [1.2])
    assert build_parser().parse_args(["leak", "--sampler", "smc"]).sampler == "smc"
    assert build_parser().parse_args(["estimate", "--sensor-noise", "typical"]).sensor_noise
    estimate = build_parser().parse_args(
        ["estimate", "--method", "likelihood", "--fit-starts", "3"]
    )
    assert (estimate.method, estimate.fit_starts) == ("likelihood", 3)
    assert build_parser().parse_args(["estimate"]).fit_starts == 0
    validate = build_parser().parse_args(["validate", "--datasets", "3", "--methods", "ks"])
    assert (validate.datasets, validate.methods, validate.reference) == (3, ["ks"], 1.5)
    assert (validate.particles, validate.reference_table) == (None, False)
    shared = build_parser().parse_args(["leak", "--particles", "32", "--reference-table"])
    assert (shared.particles, shared.reference_table) == (32, True)


def test_box_sweep_reports_throughput_per_cpu_second():
    from pymc_vcc.benchmarks.simulator import _sweep
    from pymc_vcc.physics.unit import load_unit

    draws = load_unit().parameters.sample_uniform(2, np.random.default_rng(1))
    figures = _sweep("cvode", draws, workers=1)
    assert 0 < figures["sims_per_second"] <= figures["sims_per_cpu_second"] < 1e3


def test_the_demo_reaches_the_leak_study_without_a_log(monkeypatch):
    """The demo reuses the leak handler, whose LOG and --prior it does not have."""
    import pymc_vcc.cli as cli
    import pymc_vcc.studies as studies

    class Reached(Exception):
        pass

    def leak_study(*args, **kwargs):
        raise Reached

    monkeypatch.setattr(studies, "leak_study", leak_study)
    args = build_parser().parse_args(["demo", "--out", "x"])
    with pytest.raises(Reached):
        cli._leak(args)


def test_a_commissioning_is_calibrated_again_up_to_its_attempts(capsys):
    from pymc_vcc.studies.unit_log import COMMISSIONING_ATTEMPTS

    assert build_parser().parse_args(["calibrate", "log.csv"]).attempts == COMMISSIONING_ATTEMPTS
    assert build_parser().parse_args(["calibrate", "log.csv", "--attempts", "1"]).attempts == 1
    with pytest.raises(SystemExit):
        build_parser().parse_args(["calibrate", "log.csv", "--attempts", "0"])
    assert "--attempts: must be a positive integer, got '0'" in capsys.readouterr().err


@pytest.mark.parametrize(
    ("options", "rounds", "method", "seconds", "start"),
    [
        ([], None, "likelihood", None, 0.0),
        (
            ["--rounds", "1", "--method", "rejection", "--later-seconds", "600"],
            *(1, "rejection", 600, 0.0),
        ),
        (["--later-start", "1060"], None, "likelihood", None, 1060.0),
        (["--commission-seconds", "2120"], None, "likelihood", None, 0.0),
        (["--commission-rounds", "2"], None, "likelihood", None, 0.0),
    ],
)
def test_the_fault_benchmark_diagnoses_with_the_rounds_and_sampler_asked(
    monkeypatch, options, rounds, method, seconds, start
):
    """``validate --faults`` diagnoses as ``diagnose`` does unless told otherwise: its rounds
    (:data:`ROUNDS`, not the real-units benchmark's one) and sampler reach every diagnosis, and
    its records are as long and start where asked."""
    import pymc_vcc.cli as cli
    from pymc_vcc.studies import fault_benchmark as benchmark
    from pymc_vcc.studies.diagnose import ROUNDS

    class Reached(Exception):
        pass

    def fault_benchmark(settings, variant, n_units, **options):
        raise Reached(options)

    monkeypatch.setattr(benchmark, "fault_benchmark", fault_benchmark)
    args = build_parser().parse_args(["validate", "--faults", "all", *options])
    with pytest.raises(Reached) as reached:
        cli._validate(args)
    later_seconds = seconds or benchmark.LATER_SECONDS
    assert reached.value.args[0] == {
        "rounds": rounds or ROUNDS,
        "method": method,
        "later_seconds": later_seconds,
        "later_start": start,
        "commission_seconds": 2120.0 if "--commission-seconds" in options else 1060.0,
        "commission_rounds": 2 if "--commission-rounds" in options else 1,
    }


def test_a_fault_benchmark_refuses_bad_rounds_or_sampler_before_any_simulation():
    from pymc_vcc.studies import StudySettings
    from pymc_vcc.studies.fault_benchmark import fault_benchmark

    with pytest.raises(ValueError, match="rounds must be at least 1, got 0"):
        fault_benchmark(StudySettings(), "all", 1, rounds=0)
    with pytest.raises(ValueError, match="method 'mcmc': allowed are"):
        fault_benchmark(StudySettings(), "all", 1, method="mcmc")
    with pytest.raises(ValueError, match=r"later_seconds = 3000.0 s: .* \(0, 2120\] s"):
        fault_benchmark(StudySettings(), "all", 1, later_seconds=3000.0)
    with pytest.raises(ValueError, match=r"commission_seconds = 2200.0 s: .* \(0, 2120\] s"):
        fault_benchmark(StudySettings(), "all", 1, commission_seconds=2200.0)
    with pytest.raises(ValueError, match="rounds must be at least 1, got 0"):
        fault_benchmark(StudySettings(), "all", 1, commission_rounds=0)
    with pytest.raises(ValueError, match=r"later_start = 1500.0 s: .* starts in \[0, 1060\] s"):
        fault_benchmark(StudySettings(), "all", 1, later_start=1500.0)
    with pytest.raises(ValueError, match=r"later_start = -1.0 s"):
        fault_benchmark(StudySettings(), "all", 1, later_start=-1.0)
    with pytest.raises(ValueError, match=r"outputs \['MDOT', 'T_EVAP'\]: a record logs one or"):
        fault_benchmark(StudySettings(), "all", 1, outputs=["MDOT", "T_EVAP"])
    with pytest.raises(ValueError, match=r"outputs \[\]: a record logs one or more of \['TD'"):
        fault_benchmark(StudySettings(), "all", 1, outputs=[])


def test_the_fault_benchmark_logs_the_outputs_asked_and_refuses_others_in_one_line(
    monkeypatch, tmp_path, capsys
):
    import pymc_vcc.cli as cli
    from pymc_vcc.studies import fault_benchmark as benchmark

    class Reached(Exception):
        pass

    def fault_benchmark(settings, variant, n_units, **options):
        raise Reached(options)

    field = ["TD", "PD", "TS", "PS", "TC", "PC", "TE", "PE"]
    monkeypatch.setattr(benchmark, "fault_benchmark", fault_benchmark)
    args = build_parser().parse_args(["validate", "--faults", "all", "--outputs", *field])
    with pytest.raises(Reached) as reached:
        cli._validate(args)
    assert reached.value.args[0]["outputs"] == field
    monkeypatch.undo()
    out = tmp_path / "v"
    code = main(["validate", "--faults", "all", "--outputs", "PD", "W", "--out", str(out)])
    err = capsys.readouterr().err.strip()
    assert code != 0 and len(err.splitlines()) == 1 and "outputs ['PD', 'W']" in err
    assert not out.exists()
