"""The ``pymc-vcc`` command line: the paper's studies, the demo and the benchmarks.

Every error is one line on standard error and exit status 2 (``--debug``: the traceback); an
interrupted study says how to resume it.
"""

from __future__ import annotations

import argparse
import importlib
import json
import sys
import time
from collections.abc import Callable, Sequence
from dataclasses import replace
from pathlib import Path

from pymc_vcc import __version__
from pymc_vcc.execution.executors import EXECUTOR_KINDS
from pymc_vcc.inference.samplers import SAMPLERS, SMC_KERNELS
from pymc_vcc.physics.integration.solver import METHODS


def _settings(args: argparse.Namespace):
    from pymc_vcc.studies import StudySettings

    study_options = {  # commands without a budget, resume or seed take StudySettings' own
        name: getattr(args, name) for name in ("budget", "resume", "seed") if hasattr(args, name)
    }
    return StudySettings(
        executor=args.executor,
        scheduler=args.scheduler,
        n_workers=args.workers,
        out=Path(args.out),
        progress=None if not args.json else False,
        time_limit=args.time_limit,
        solver=args.solver,
        **study_options,
    )


def _written_files(folder: Path, since: float) -> list[str]:
    """Every file under ``folder`` written at or after ``since`` (a ``time.time()``), sorted."""
    if not folder.is_dir():
        return []
    return sorted(
        str(path) for path in folder.rglob("*") if path.is_file() and path.stat().st_mtime >= since
    )


def _report(args: argparse.Namespace, text: str, summary: dict) -> int:
    files = _written_files(Path(args.out), args.started)
    if not args.json:
        print(text)
        print(f"\nresults written to {args.out} ({len(files)} files)")
    else:
        print(json.dumps({**summary, "out": str(args.out), "files": files}))
    return 0


def _record(args: argparse.Namespace) -> int:
    """``calibrate LOG`` and ``leak LOG``: a unit's own record."""
    from pymc_vcc.physics.unit import load_unit
    from pymc_vcc.studies.unit_log import record_study

    result = record_study(
        _settings(args),
        args.log,
        column_map=args.columns,
        unit=load_unit(args.unit) if args.unit else None,
        commissioning=getattr(args, "prior", None),
        drift=args.drift,
        alarm_fraction=args.alarm_fraction,
        rounds=args.rounds,
        coils=args.coils,
        method=_record_method(args),
        attempts=getattr(args, "attempts", 1),
    )
    text = (
        f"{result.format_table()}\n\n{result.n_simulations} simulations, "
        f"{result.wall_seconds:.0f} s"
    )
    misfit = [name for name, check in result.checks.items() if check["misfit"]]
    if misfit:
        text += f"\nwarning: the model cannot reproduce {', '.join(misfit)}"
    return _report(args, text, result.summary())


def _diagnose(args: argparse.Namespace) -> int:
    """``diagnose LOG --prior COMMISSIONING``: the unit's faults since commissioning."""
    from pymc_vcc.physics.unit import load_unit
    from pymc_vcc.studies.diagnose import diagnose_study

    result = diagnose_study(
        _settings(args),
        args.log,
        args.prior,
        column_map=args.columns,
        unit=load_unit(args.unit) if args.unit else None,
        drift=args.drift,
        coils=args.coils,
        rounds=args.rounds,
        method=args.method,
        fault_probability=args.fault_probability,
        model_form=args.model_form,
        named=args.named,
        likely=args.likely,
    )
    n_simulations = int(result.tree["sample_stats"]["n_simulations"])
    return _report(
        args, f"{result.format_table()}\n\n{n_simulations} simulations", result.summary()
    )


def _record_method(args: argparse.Namespace) -> str:
    """The sampler of a log's calibration: ``--method`` of ``calibrate``, or ``leak``'s."""
    if "sampler" not in args:
        return args.method
    if args.sampler == "smc":
        raise ValueError(
            "--method smc is the idealised study's; a LOG takes likelihood or rejection"
        )
    return args.sampler or "likelihood"


def _leak(args: argparse.Namespace) -> int:
    if getattr(args, "log", None) is not None:  # demo runs the leak study without a log
        return _record(args)
    if getattr(args, "prior", None) is not None:
        raise ValueError("--prior (a commissioning result) needs a LOG to identify the charge on")
    from pymc_vcc.physics.inputs import CALIBRATION_SECONDS
    from pymc_vcc.studies import leak_study

    inputs = _inputs(args)
    end = None if inputs is None else min(CALIBRATION_SECONDS, float(inputs["time"][-1]))
    window = {} if end is None else {"t_calibration": end}
    result = leak_study(
        _settings(args),
        references_kg=args.references,
        sampler=args.sampler or "rejection",
        alarm_fraction=args.alarm_fraction,
        sensor_noise=_sensor_noise(args),
        inputs=inputs,
        reference_table=args.reference_table,
        smc_draws=args.particles,
        **window,
    )
    text = (
        f"{result.format_table()}\n\n{result.n_simulations} simulations, "
        f"{result.wall_seconds:.0f} s, sampler {result.sampler}"
    )
    return _report(args, text, result.summary())


def _sensor_noise(args: argparse.Namespace):
    from pymc_vcc.inference.noise import SensorNoise

    return SensorNoise.typical() if args.sensor_noise == "typical" else None


def _inputs(args: argparse.Namespace):
    from pymc_vcc.physics.inputs import load_inputs_csv

    return load_inputs_csv(args.inputs) if args.inputs else None


def _demo(args: argparse.Namespace) -> int:
    from pymc_vcc.execution.output_folder import claim_output_folder
    from pymc_vcc.physics.refrigerant.diagram import save_property_diagram

    with claim_output_folder(args.out):
        save_property_diagram(Path(args.out))
        return _leak(args)


def _estimate(args: argparse.Namespace) -> int:
    from pymc_vcc.studies import estimation_study

    settings = _settings(args)
    if args.simulations is not None:
        budget = settings.work.with_rejection_simulations(args.simulations)
        settings = replace(settings, budget=budget)
    result = estimation_study(
        settings,
        method=args.method,
        smc_epsilon=args.epsilon,
        smc_draws=args.particles,
        sensor_noise=_sensor_noise(args),
        distance=args.distance,
        kernel_steps=args.kernel_steps,
        kernel=args.kernel,
        fit_starts=args.fit_starts,
        refine=args.refine,
        drift=args.drift,
    )
    text = (
        f"{result.format_table()}\n\n{result.n_simulations} simulations "
        f"({' + '.join(map(str, result.simulations))} by dataset, and "
        f"{result.identify_simulations} to find what the data cannot identify), "
        f"{result.wall_seconds:.0f} s (sd ratio: posterior sd / sd of the uniform Table III prior)"
    )
    return _report(args, text, result.summary())


def _validate(args: argparse.Namespace) -> int:
    if args.faults:
        if args.truth:
            raise ValueError("--faults names its own variant; give it without --truth")
        from pymc_vcc.studies.diagnose import ROUNDS
        from pymc_vcc.studies.fault_benchmark import check_outputs, fault_benchmark

        if args.outputs is not None:  # before the output folder is made
            check_outputs(args.outputs)
        scored = fault_benchmark(
            _settings(args),
            args.faults,
            args.datasets,
            rounds=ROUNDS if args.rounds is None else args.rounds,
            method=args.method,
            later_seconds=args.later_seconds,
            later_start=args.later_start,
            commission_seconds=args.commission_seconds,
            commission_rounds=args.commission_rounds,
            **({} if args.outputs is None else {"outputs": args.outputs}),
        )
        text = f"{scored.format_table()}\n\n{scored.wall_seconds:.0f} s"
        return _report(args, text, scored.summary())
    if args.truth:
        from pymc_vcc.studies.real_units import real_units_benchmark

        benchmark = real_units_benchmark(
            _settings(args),
            args.truth,
            args.datasets,
            alarm=args.alarm,
            rounds=1 if args.rounds is None else args.rounds,
            method=args.method,
        )
        text = f"{benchmark.format_table()}\n\n{benchmark.wall_seconds:.0f} s"
        return _report(args, text, benchmark.summary())
    from pymc_vcc.studies.validation import validation_study

    result = validation_study(
        _settings(args),
        reference_kg=args.reference,
        n_datasets=args.datasets,
        methods=args.methods,
        reference_table=args.reference_table,
        smc_draws=args.particles,
    )
    text = f"{result.format_table()}\n\n{result.wall_seconds:.0f} s"
    return _report(args, text, result.summary())


def _sobol(args: argparse.Namespace) -> int:
    from pymc_vcc.studies import sobol_study

    result = sobol_study(_settings(args))
    summary = result.summary()
    lines = [
        f"{output:5s} {', '.join(p) or '-'}" for output, p in summary["dominant_parameters"].items()
    ]
    text = (
        "parameters with total-order Sobol index > 0.1, per output:\n"
        + "\n".join(lines)
        + f"\n\n{summary['n_simulations']} simulations ({summary['n_failed']} failed, "
        f"{summary['n_dropped_base_samples']} base samples dropped), {result.wall_seconds:.0f} s"
    )
    return _report(args, text, summary)


def _identify(args: argparse.Namespace) -> int:
    from pymc_vcc.studies import identify_study

    result = identify_study(
        _settings(args),
        inputs=_inputs(args),
        parameters=args.parameters,
        at=dict(args.at or []),
        **({} if args.t_end is None else {"t_end": args.t_end}),
        step=args.step,
        fit=args.fit or (),
    )
    text = (
        f"{result.format_table()}\n\n{result.identifiability.simulations} simulations, "
        f"{result.wall_seconds:.0f} s (sd ratio: expected posterior sd / prior sd for exact-"
        f"likelihood calibration on the first {result.t_end:g} s under typical sensors)"
    )
    return _report(args, text, result.summary())


def _assignment(text: str) -> tuple[str, float]:
    """An argparse type: ``NAME=VALUE`` with a number for VALUE."""
    name, _, value = text.partition("=")
    try:
        return name.strip(), float(value)
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"must be NAME=VALUE with a number, got {text!r}"
        ) from None


def _bench(args: argparse.Namespace) -> int:
    from pymc_vcc.benchmarks import BENCHMARKS

    selected = args.only or list(BENCHMARKS)
    unknown = sorted(set(selected) - set(BENCHMARKS))
    if unknown:
        raise SystemExit(f"unknown benchmark(s) {unknown}; available: {list(BENCHMARKS)}")
    results: dict[str, object] = {}
    for name in selected:
        module = importlib.import_module(f"pymc_vcc.benchmarks.{name}")
        part = module.run(quick=args.quick)
        if not args.json:
            print(f"[{name}]")
            if hasattr(module, "format_table"):  # figures side by side (e.g. per solver)
                print(module.format_table(part))
            for key, value in part.items():
                print(f"  {key:32s} {value}")
        results.update(part)
    if args.json:
        print(json.dumps(results))
    return 0


def _number_or_off(text: str) -> float | None:
    """An argparse type: a number, or ``off`` (None)."""
    if text.strip().lower() == "off":
        return None
    try:
        return float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"must be a number or 'off', got {text!r}") from None


def _positive(kind: type[int] | type[float]) -> Callable[[str], int | float]:
    """An argparse type: a number of ``kind`` greater than zero."""

    def parse(text: str) -> int | float:
        try:
            value = kind(text)
        except ValueError:
            value = None
        if value is None or not value > 0 or value != value:
            noun = "integer" if kind is int else "number"
            raise argparse.ArgumentTypeError(f"must be a positive {noun}, got {text!r}")
        return value

    return parse


def _add_study_options(parser: argparse.ArgumentParser, out: str, budget: str) -> None:
    parser.add_argument(
        "--budget",
        choices=["smoke", "small", "paper"],
        default=budget,
        help="work budget: smoke (seconds), small (minutes), paper (Table I)",
    )
    _add_run_options(parser, out)
    parser.add_argument(
        "--resume", action="store_true", help="continue from the checkpoints in --out"
    )
    parser.add_argument(
        "--seed", type=int, default=0, help="seed of every random stream (default 0)"
    )


def _add_run_options(parser: argparse.ArgumentParser, out: str) -> None:
    """Where simulations run, with which solver, and where the results go."""
    parser.add_argument(
        "--executor",
        choices=list(EXECUTOR_KINDS),
        default="processes",
        help="where simulations run: this process, local worker processes or a Dask cluster "
        "(default: processes)",
    )
    parser.add_argument(
        "--scheduler", metavar="ADDRESS", help="address of a Dask scheduler (with --executor dask)"
    )
    parser.add_argument(
        "--workers", type=_positive(int), help="worker processes (default: every core)"
    )
    parser.add_argument(
        "--time-limit",
        type=_positive(float),
        metavar="SECONDS",
        help="wall-time limit of one simulation; a local worker running longer is stopped "
        "and the simulation counted as failed (time-limit)",
    )
    parser.add_argument(
        "--out", default=out, help=f"folder the results are written into (default {out})"
    )
    parser.add_argument(
        "--solver",
        choices=list(METHODS),
        help="ODE solver at its default tolerances: radau (scipy, the reference) or cvode "
        "(SUNDIALS, faster) (default: the study's own, radau unless it says otherwise)",
    )
    parser.add_argument(
        "--json",
        action="store_true",
        help="print one JSON object last: the summary, --out and every file written",
    )


def _add_sensor_noise_option(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--sensor-noise",
        choices=["none", "typical"],
        default="none",
        help="noise on the reference data, accounted for by the sampler: none (the paper) or "
        "typical (0.3 K, 0.5 %% of pressure, 1 %% of mass flow)",
    )


def _add_shared_sampler_options(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--particles",
        type=_positive(int),
        help="smc and likelihood: SMC particles per dataset (default: the budget's)",
    )
    parser.add_argument(
        "--reference-table",
        action="store_true",
        help="rejection: simulate the budget's prior draws once and calibrate every dataset on "
        "that shared table (each adds its own sensor noise); counted once, as shared",
    )


def _add_rounds_option(parser: argparse.ArgumentParser, default: int | None = 1) -> None:
    """``--rounds`` (None: the study's own default, 1, or the diagnosis's with ``--faults``)."""
    from pymc_vcc.studies.diagnose import ROUNDS

    said = default if default is not None else f"1; with --faults, {ROUNDS} as diagnose"
    parser.add_argument(
        "--rounds",
        type=_positive(int),
        default=default,
        help="calibrations in turn, each after the first with half of the model error drawn at "
        "the previous posterior and half where the first round drew it, within the same cap on "
        f"simulations (default {said})",
    )


def _add_record_method_option(parser: argparse.ArgumentParser) -> None:
    from pymc_vcc.studies.unit_log import METHODS as RECORD_METHODS

    parser.add_argument(
        "--method",
        choices=list(RECORD_METHODS),
        default="likelihood",
        help="sampler under the error budget: likelihood (SMC, recommended) or rejection (the "
        "paper's ABC rejection with the budget's distance) (default likelihood)",
    )


def _add_attempts_option(parser: argparse.ArgumentParser) -> None:
    from pymc_vcc.studies.unit_log import COMMISSIONING_ATTEMPTS

    parser.add_argument(
        "--attempts",
        type=_positive(int),
        default=COMMISSIONING_ATTEMPTS,
        help="calibrations at most, each from a new seed while the predictive check fails; "
        f"the best is kept (default {COMMISSIONING_ATTEMPTS})",
    )


def _add_record_options(parser: argparse.ArgumentParser, rounds: int = 1) -> None:
    """Options of the commands that read a unit's own log (``rounds``: the default of
    ``--rounds``)."""
    from pymc_vcc.studies.record_budget import COILS

    _add_rounds_option(parser, rounds)
    parser.add_argument(
        "--coils",
        choices=list(COILS),
        default="finer",
        help="whose coils made the log: finer (a physical unit, the default) or model (data "
        "this model generated: no coil offset, and a first log's posterior refined under the "
        "sensors' errors alone)",
    )
    parser.add_argument(
        "--columns",
        metavar="TOML",
        help="column map of the log: [columns] file column = id, [units] file column = unit, "
        "time_column (default: LOG.columns.toml beside the log)",
    )
    parser.add_argument(
        "--unit", metavar="TOML", help="unit description (default: the built-in split unit)"
    )
    parser.add_argument(
        "--drift",
        type=float,
        default=0.03,
        help="with --prior: sd of each parameter's change since commissioning, as a fraction "
        "of its range, unless a fault moved it (default 0.03)",
    )


def _add_leak_options(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--method",
        "--sampler",
        dest="sampler",
        choices=list(SAMPLERS),
        help="rejection (the paper's ABC, the default), smc (SMC-ABC) or likelihood (exact "
        "likelihood under --sensor-noise, tempered SMC); with a LOG, the sampler under its "
        "error budget: likelihood (the default) or rejection",
    )
    _add_sensor_noise_option(parser)
    parser.add_argument(
        "--inputs",
        metavar="CSV",
        help="input profile (columns as load_inputs_csv; default: the built-in step profile); "
        "calibrated over the paper's calibration window (its first 1060 s), or all of it if "
        "shorter",
    )
    parser.add_argument(
        "--references",
        type=float,
        nargs="+",
        default=[2.0, 1.5, 1.0],
        metavar="KG",
        help="reference charges of the datasets, kg (default: 2.0 1.5 1.0)",
    )
    parser.add_argument(
        "--alarm-fraction",
        type=float,
        default=0.9,
        help="leak alarm: P(M0 < fraction × first reference charge) (default 0.9)",
    )
    _add_shared_sampler_options(parser)


def _add_validate_options(parser: argparse.ArgumentParser) -> None:
    from pymc_vcc.studies.fault_benchmark import LATER_SECONDS, LATER_START, PROFILE_SECONDS
    from pymc_vcc.studies.validation import METHODS

    parser.add_argument("--reference", type=float, default=1.5, metavar="KG", help="true charge")
    from pymc_vcc.studies.truths import RECORD_SECONDS, VARIANTS

    parser.add_argument(
        "--datasets", type=_positive(int), default=20, help="datasets per case (default 20)"
    )
    parser.add_argument(
        "--truth",
        nargs="+",
        choices=list(VARIANTS),
        help="the real-units benchmark instead: units that are not the model (finer coils, "
        "sensor lags and biases, logged inputs off, drifted parameters, all), each charge "
        "calibrated among the nuisance parameters under the error budget",
    )
    parser.add_argument(
        "--faults",
        choices=list(VARIANTS),
        metavar="VARIANT",
        help="the fault benchmark instead: --datasets units of this truth variant, each "
        "commissioned, then diagnosed with no fault, with each standard fault and with two at once",
    )
    _add_rounds_option(parser, None)
    _add_record_method_option(parser)
    parser.add_argument(
        "--later-seconds",
        type=_positive(float),
        default=LATER_SECONDS,
        help=f"with --faults: length of each later record, s (default {LATER_SECONDS:.0f}; at "
        f"most the built-in profile's {PROFILE_SECONDS:.0f})",
    )
    parser.add_argument(
        "--commission-seconds",
        type=_positive(float),
        default=RECORD_SECONDS,
        help=f"with --faults: length of each unit's commissioning record, s (default "
        f"{RECORD_SECONDS:.0f}; at most {PROFILE_SECONDS:.0f})",
    )
    parser.add_argument(
        "--commission-rounds",
        type=_positive(int),
        default=1,
        help="with --faults: calibrations in turn at each unit's commissioning, as calibrate's "
        "--rounds (default 1)",
    )
    parser.add_argument(
        "--later-start",
        type=float,
        default=LATER_START,
        metavar="SECONDS",
        help="with --faults: where in the built-in profile each later record begins, s "
        f"(default {LATER_START:.0f}: at the commissioning's operating points; "
        f"{PROFILE_SECONDS - LATER_SECONDS:.0f}: at others, as on another day's weather)",
    )
    parser.add_argument(
        "--outputs",
        nargs="+",
        metavar="ID",
        help="with --faults: the outputs every record logs (default: the nine; a field unit "
        "without a mass-flow meter: TD PD TS PS TC PC TE PE)",
    )
    parser.add_argument(
        "--alarm",
        action="store_true",
        help="with --truth: also each unit unchanged and 20 %% lighter against its "
        "commissioning, for the leak alarm's false-alarm and detection rates",
    )
    parser.add_argument(
        "--methods",
        nargs="+",
        choices=list(METHODS),
        default=["ks", "ks-noise", "windowed", "likelihood"],
        help="methods compared on the same noisy datasets (default: ks ks-noise windowed "
        "likelihood)",
    )
    _add_shared_sampler_options(parser)


def build_parser() -> argparse.ArgumentParser:
    """The argument parser of ``pymc-vcc``, one sub-command per job."""
    from pymc_vcc.inference.distances import BATCH_DISTANCES
    from pymc_vcc.studies.estimate import REFERENCE_STEP

    parser = argparse.ArgumentParser(
        prog="pymc-vcc",
        description="Bayesian calibration of dynamic vapor-compression-cycle models.",
    )
    parser.add_argument("--version", action="version", version=f"%(prog)s {__version__}")
    commands = parser.add_subparsers(dest="command", required=True)

    demo = commands.add_parser(
        "demo",
        help="the main job: refrigerant tables vs CoolProp, then the leak study (Table II) at "
        "a small budget on all cores",
    )
    _add_study_options(demo, "results/demo", "small")
    _add_leak_options(demo)
    demo.set_defaults(handler=_demo)

    estimate = commands.add_parser(
        "estimate", help="sequential estimation of all 26 parameters on two datasets (Figs. 4-8)"
    )
    _add_study_options(estimate, "results/estimate", "small")
    _add_sensor_noise_option(estimate)
    estimate.add_argument(
        "--method",
        choices=list(SAMPLERS),
        default="rejection",
        help="sampler: the paper's ABC rejection, SMC-ABC (far fewer simulations), or tempered "
        "SMC on the exact likelihood (needs --sensor-noise typical)",
    )
    estimate.add_argument(
        "--simulations",
        type=int,
        help="rejection: about this many simulations per dataset, pilot, main and accepted draws "
        "in the budget's proportions (default: the budget's)",
    )
    estimate.add_argument(
        "--epsilon",
        type=float,
        default=0.01,
        help="SMC-ABC: width of the Gaussian kernel on the distance (default 0.01)",
    )
    estimate.add_argument(
        "--distance",
        choices=list(BATCH_DISTANCES),
        default="ks",
        help="ABC distance: the paper's KS, Wasserstein-1 of the values, or windowed (10 s "
        "means, time-aligned) (default ks)",
    )
    estimate.add_argument(
        "--particles",
        type=int,
        help="smc and likelihood: particles per dataset (default: the budget's)",
    )
    estimate.add_argument(
        "--kernel-steps",
        type=int,
        help="smc and likelihood: at most this many mutation steps per stage (default: until "
        "the particles decorrelate, PyMC's rule)",
    )
    estimate.add_argument(
        "--kernel",
        choices=list(SMC_KERNELS),
        default="imh",
        help="smc and likelihood: mutation kernel, imh (independent proposals from a Gaussian "
        "fitted to the particles, PyMC's default) or mh (random-walk steps) (default imh)",
    )
    estimate.add_argument(
        "--fit-starts",
        type=int,
        default=0,
        help="likelihood: temper from the Laplace approximations of least-squares fits from "
        "this many starts instead of from the prior (default 0: from the prior)",
    )
    estimate.add_argument(
        "--refine",
        type=int,
        default=0,
        metavar="SIMULATIONS",
        help="smc: after each dataset's SMC-ABC, this many new simulations around its posterior, "
        "over two rounds, for regression-adjusted ABC (learnt summaries, local-linear "
        "adjustment), whose posterior replaces it (default 0: none)",
    )
    estimate.add_argument(
        "--drift",
        type=float,
        default=REFERENCE_STEP,
        metavar="FRACTION",
        help="the step of each parameter between the datasets that dataset 2's prior allows: "
        "the sd of a normal step, in fractions of each range (default %(default)s, the step "
        "the second reference parameters took; 0: dataset 1's posterior as it is, the paper's)",
    )
    estimate.set_defaults(handler=_estimate)

    leak = commands.add_parser(
        "leak",
        help="the charge of a unit's LOG against its commissioning (--prior), or without LOG "
        "the paper's idealised study (Table II: M0 alone, the other 25 parameters known)",
    )
    leak.add_argument("log", nargs="?", metavar="LOG", help="a CSV log of the unit")
    leak.add_argument(
        "--prior",
        metavar="COMMISSIONING",
        help="the folder (or posterior.nc) written by `pymc-vcc calibrate` at commissioning",
    )
    _add_study_options(leak, "results/leak", "small")
    _add_leak_options(leak)
    _add_record_options(leak)
    leak.set_defaults(handler=_leak)

    diagnose = commands.add_parser(
        "diagnose",
        help="the faults of a unit's LOG since its commissioning (--prior): each fault's "
        "intensity and probability, a verdict, and what the unit lost at its rating point",
    )
    diagnose.add_argument("log", metavar="LOG", help="a CSV log of the unit")
    diagnose.add_argument(
        "--prior",
        metavar="COMMISSIONING",
        required=True,
        help="the folder (or posterior.nc) written by `pymc-vcc calibrate` at commissioning",
    )
    from pymc_vcc.studies.diagnose import LIKELY, NAMED, POSSIBLE, RIVAL, ROUNDS
    from pymc_vcc.studies.faults import FAULT_PROBABILITY, MODEL_FORM

    diagnose.add_argument(
        "--fault-probability",
        type=float,
        default=FAULT_PROBABILITY,
        help="each fault's prior probability since commissioning, in (0, 1) (default "
        f"{FAULT_PROBABILITY})",
    )
    diagnose.add_argument(
        "--model-form",
        type=float,
        default=MODEL_FORM,
        help="relative sd of the model's reading of a fault's intensity on a unit that is not "
        f"the model, >= 0 (default {MODEL_FORM}: measured on the fault benchmark; 0: the "
        "model's reading alone)",
    )
    diagnose.add_argument(
        "--named",
        type=float,
        default=NAMED,
        metavar="P",
        help=f"the probability beyond its threshold that names a fault, in [{POSSIBLE}, 1) "
        f"(default {NAMED}; lower names more faults near their thresholds, for more false "
        "alarms)",
    )
    diagnose.add_argument(
        "--likely",
        type=_number_or_off,
        default=LIKELY,
        metavar="P",
        help="when no fault reaches --named, name the likeliest as likely if its probability "
        f"is at least P and no other fault's reaches {RIVAL}; P in [{POSSIBLE}, --named], or "
        f"off (default {'off' if LIKELY is None else LIKELY})",
    )
    _add_study_options(diagnose, "results/diagnose", "small")
    _add_record_options(diagnose, rounds=ROUNDS)
    _add_record_method_option(diagnose)
    diagnose.set_defaults(handler=_diagnose)

    calibrate = commands.add_parser(
        "calibrate",
        help="calibrate a unit on its own CSV log (commissioning): the charge among the "
        "parameters that drift, sensor and model errors accounted for",
    )
    calibrate.add_argument("log", metavar="LOG", help="a CSV log of the unit")
    _add_study_options(calibrate, "results/calibrate", "small")
    _add_record_options(calibrate)
    _add_record_method_option(calibrate)
    _add_attempts_option(calibrate)
    calibrate.set_defaults(handler=_record, alarm_fraction=0.9)

    validate = commands.add_parser(
        "validate",
        help="charge identification on noisy data: methods side by side over noise seeds, with "
        "the coverage of their 95 %% intervals",
    )
    _add_study_options(validate, "results/validate", "small")
    _add_validate_options(validate)
    validate.set_defaults(handler=_validate)

    sobol = commands.add_parser("sobol", help="Sobol sensitivity (Figs. 9 and 10)")
    _add_study_options(sobol, "results/sobol", "small")
    sobol.set_defaults(handler=_sobol)

    identify = commands.add_parser(
        "identify",
        help="which parameter combinations noisy data from the profile identify (local Fisher "
        "information under typical sensors)",
    )
    _add_run_options(identify, "results/identify")
    identify.add_argument(
        "--parameters", nargs="+", metavar="ID", help="parameters examined (default: all)"
    )
    identify.add_argument(
        "--at",
        nargs="+",
        type=_assignment,
        metavar="ID=VALUE",
        help="the point, SI units (default: nominal)",
    )
    identify.add_argument(
        "--t-end",
        type=_positive(float),
        metavar="SECONDS",
        help="calibration window: the first SECONDS of the profile (default: the paper's "
        "calibration window, the first half of the built-in profile)",
    )
    identify.add_argument(
        "--inputs", metavar="CSV", help="input profile (default: the built-in step profile)"
    )
    identify.add_argument(
        "--step",
        type=_positive(float),
        default=0.1,
        help="central-difference half-step, in prior sds (default 0.1)",
    )
    identify.add_argument(
        "--fit",
        nargs="+",
        metavar="ID",
        help="also show how far a calibration of these parameters is pulled by each of the "
        "others being off (e.g. --fit M0 CF_VOL ...: which held parameters confound the charge)",
    )
    identify.set_defaults(handler=_identify)

    bench = commands.add_parser("bench", help="speed benchmarks")
    bench.add_argument("--json", action="store_true", help="print one JSON object last")
    bench.add_argument("--quick", action="store_true", help="fewer repetitions")
    bench.add_argument("--only", nargs="+", metavar="NAME", help="run only these benchmarks")
    bench.set_defaults(handler=_bench)
    parser.add_argument("--debug", action="store_true", help="show the traceback of an error")
    for command in commands.choices.values():
        command.add_argument(
            "--debug",
            action="store_true",
            default=argparse.SUPPRESS,
            help="show the traceback of an error",
        )
    return parser


def _run(args: argparse.Namespace) -> int:
    """Run the sub-command; an error is one line and exit status 2 (unless ``--debug``)."""
    try:
        return args.handler(args)
    except KeyboardInterrupt:
        if args.debug:
            raise
        resume = " (continue with --resume)" if getattr(args, "out", None) else ""
        print(f"pymc-vcc {args.command}: interrupted{resume}", file=sys.stderr)
        return 130
    except Exception as error:
        if args.debug:
            raise
        message = " ".join(str(error).split()) or type(error).__name__
        print(
            f"pymc-vcc {args.command}: error: {message} (--debug shows the traceback)",
            file=sys.stderr,
        )
        return 2


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the ``pymc-vcc`` console script."""
    args = build_parser().parse_args(argv)
    args.started = time.time()
    return _run(args)


if __name__ == "__main__":
    sys.exit(main())
