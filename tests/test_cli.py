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


def test_noisy_data_options_parse():
    args = build_parser().parse_args(
        ["leak", "--method", "likelihood", "--sensor-noise", "typical", "--references", "1.2"]
    )
    assert (args.sampler, args.sensor_noise, args.references) == ("likelihood", "typical", [1.2])
    assert build_parser().parse_args(["leak", "--sampler", "smc"]).sampler == "smc"
    assert build_parser().parse_args(["estimate", "--sensor-noise", "typical"]).sensor_noise
    validate = build_parser().parse_args(["validate", "--datasets", "3", "--methods", "ks"])
    assert (validate.datasets, validate.methods, validate.reference) == (3, ["ks"], 1.5)
