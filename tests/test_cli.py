"""The command line parses and reports its sub-commands."""

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


def test_solver_and_sampler_options():
    args = build_parser().parse_args(
        ["estimate", "--method", "smc", "--solver", "cvode", "--epsilon", "0.02"]
    )
    assert (args.method, args.solver, args.epsilon, args.particles) == ("smc", "cvode", 0.02, None)
    assert build_parser().parse_args(["leak"]).solver is None  # the unit's own choice
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
