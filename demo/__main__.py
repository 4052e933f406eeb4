"""Runs seed 000's experiments in closed loop and writes CSV, PNG and report.md.

    python -m demo --out out/demo [--plant dist/FlexureStage.fmu]
                   [--controller dist/PiezoController.fmu] [--only KEY ...]

Each file is written under a temporary name in --out and renamed into place:
an interrupted run leaves every file complete, the new or the previous one.
metrics.json holds the figures of every run in --out: those of this
invocation replace theirs, and --only (or Ctrl-C) keeps the others. report.md
is written from metrics.json whenever it holds every run, so the two agree.
"""

from __future__ import annotations

import argparse
import contextlib
import json
import math
import os
import sys
import time
from pathlib import Path

import fmpy
from tqdm import tqdm

from .cosim import SAMPLE_PERIOD, Fmu, simulate
from .experiments import CONDITIONS, experiments, on_parameter_sets, report_figures
from .report import figure, write_report


@contextlib.contextmanager
def replaced(path: Path):
    """A temporary name beside `path` (same folder, same suffix, which
    matplotlib reads the format from) to write to; renamed to `path` once
    the block ends, removed if it raises. Ctrl-C mid-write left a truncated
    CSV under its final name beside the previous run's report."""
    partial = path.with_name(f".{path.stem}.{os.getpid()}.partial{path.suffix}")
    try:
        yield partial
        os.replace(partial, path)
    finally:
        partial.unlink(missing_ok=True)


def previous_metrics(path: Path) -> dict:
    """The figures an earlier invocation left in metrics.json, by run key;
    none when there is no such file or it is not one this command wrote."""
    try:
        entries = json.loads(path.read_text())
    except FileNotFoundError:
        return {}
    except (OSError, ValueError) as e:
        print(f"{path}: not read ({e}); it is rewritten with this invocation's runs only",
              file=sys.stderr)
        return {}
    return entries if isinstance(entries, dict) else {}


def recorded_provenance(path: Path) -> dict:
    """The parameters an earlier invocation ran on (parameters.json); the
    start values when it wrote none."""
    try:
        return json.loads(path.read_text())
    except (OSError, ValueError):
        return {"plant": None, "controller": None, "fitted_once": None}


def read_parameter_set(path: Path, fmu: Path) -> dict:
    """A parameter set by FMI name: a JSON object whose every name is a
    parameter of `fmu`, every value a number or a Boolean."""
    try:
        text = path.read_text(encoding="utf-8")
    except OSError as e:
        raise ValueError(f"{path}: cannot read it ({e.strerror})") from None
    try:
        values = json.loads(text)
    except json.JSONDecodeError as e:
        raise ValueError(f"{path}: line {e.lineno}, column {e.colno}: {e.msg}") from None
    if not isinstance(values, dict):
        raise ValueError(f"{path}: a parameter set is a JSON object of names and values")
    parameters = {v.name for v in fmpy.read_model_description(str(fmu)).modelVariables
                  if v.causality == "parameter"}
    for name, value in values.items():
        if name not in parameters:
            raise ValueError(f"{path}: {name!r} is not a parameter of {fmu.name}")
        if not isinstance(value, (bool, int, float)) or not math.isfinite(value):
            raise ValueError(f"{path}: {name!r} = {value!r} is not a finite number or a Boolean")
    return values


def parameter_sets(args) -> tuple[dict, dict, dict | None] | None:
    """The plant and controller sets the options name (both or neither), and
    the law fitted once; None for the start values."""
    given = (args.plant_parameters, args.controller_parameters)
    if not any(given) and args.controller_fitted_once is None:
        return None
    if not all(given):
        raise ValueError("--plant-parameters and --controller-parameters go together (and "
                         "--controller-fitted-once needs both): a controller is identified on "
                         "its stage (piezo-identify stage)")
    once = (read_parameter_set(args.controller_fitted_once, args.controller)
            if args.controller_fitted_once else None)
    return (read_parameter_set(args.plant_parameters, args.plant),
            read_parameter_set(args.controller_parameters, args.controller), once)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, required=True, help="output folder")
    parser.add_argument("--plant", type=Path, default=Path("dist/FlexureStage.fmu"))
    parser.add_argument("--controller", type=Path, default=Path("dist/PiezoController.fmu"))
    parser.add_argument("--only", nargs="*",
                        help="run only these experiment keys (metrics.json keeps the others)")
    parser.add_argument(
        "--plant-parameters", type=Path, metavar="SET",
        help="FlexureStage parameters by FMI name (a dist/presets/FlexureStage.*.json file, or "
             "flexure-stage-parameters' output): the experiments on that stage")
    parser.add_argument(
        "--controller-parameters", type=Path, metavar="SET",
        help="PiezoController parameters by FMI name, identified on that stage "
             "(piezo-identify stage, then piezo-controller-parameters)")
    parser.add_argument(
        "--controller-fitted-once", type=Path, metavar="SET",
        help="the same identification's law fitted once (its --out-fitted-once preset, by FMI "
             "name), for the runs of seed 000's table; default: the law of "
             "--controller-parameters")
    args = parser.parse_args(argv)
    for path in (args.plant, args.controller):
        if not path.is_file():
            print(f"{path}: no such FMU (run `make fmus`)", file=sys.stderr)
            return 2
    try:
        sets = parameter_sets(args)
    except ValueError as e:
        print(e, file=sys.stderr)
        return 2
    args.out.mkdir(parents=True, exist_ok=True)
    every_run = experiments()
    if sets:
        every_run = on_parameter_sets(every_run, *sets)
    runs = every_run
    # What the runs ran on, beside metrics.json: a partial run may only add
    # to figures of the same parameters, or report.md would mix two stages.
    provenance_path = args.out / "parameters.json"
    provenance = {"plant": None, "controller": None, "fitted_once": None} if not sets else {
        "plant": sets[0], "controller": sets[1], "fitted_once": sets[2]}
    if args.only:
        unknown = set(args.only) - {e.key for e in runs}
        if unknown:
            print(f"unknown experiment(s): {', '.join(sorted(unknown))}", file=sys.stderr)
            return 2
        runs = [e for e in runs if e.key in args.only]
        if previous_metrics(args.out / "metrics.json") and \
                recorded_provenance(provenance_path) != provenance:
            print(f"{args.out} holds runs on other parameters than these "
                  f"({provenance_path.name} says which): run them all, or use another --out",
                  file=sys.stderr)
            return 2
    total_steps = sum(round(e.duration / SAMPLE_PERIOD) for e in runs)
    started = time.perf_counter()
    results = {}
    interrupted = False
    try:
        with Fmu(args.plant) as plant, Fmu(args.controller) as controller:
            # The sensors' spacing the controller converts rotations with.
            spacing_mm = sets[1].get("L") if sets else None
            spacing_um = float(spacing_mm or controller.variables["L"].start) * 1e3
            with tqdm(total=total_steps, unit="step", unit_scale=True,
                      desc="co-simulation") as bar:
                for experiment in runs:
                    bar.set_postfix_str(experiment.key)
                    run = simulate(
                        plant, controller, experiment.reference(), experiment.duration,
                        plant_parameters=experiment.plant,
                        controller_parameters=experiment.controller, progress=bar.update,
                    )
                    with replaced(args.out / f"{experiment.key}.csv") as partial:
                        run.write_csv(partial)
                    with replaced(args.out / f"{experiment.key}.png") as partial:
                        figure(experiment, run, spacing_um, partial)
                    results[experiment.key] = report_figures(experiment, run, spacing_um)
    except KeyboardInterrupt:
        # The runs finished so far are on disk; their figures go into
        # metrics.json (and report.md) below, as an --only of them would.
        interrupted = True
    wall = time.perf_counter() - started
    metrics_path, report_path = args.out / "metrics.json", args.out / "report.md"
    ran_everything = not interrupted and len(runs) == len(every_run)
    # A complete invocation writes its own runs alone (an entry of a run no
    # longer defined goes); a partial one keeps the others' figures, so that
    # metrics.json and report.md still describe every file in the folder.
    merged = results if ran_everything else {**previous_metrics(metrics_path), **results}
    if results:
        with replaced(metrics_path) as partial:
            partial.write_text(json.dumps(merged, indent=2))
        with replaced(provenance_path) as partial:
            partial.write_text(json.dumps(provenance, indent=2))
    missing = [e.key for e in every_run if e.key not in merged]
    if results and not missing:
        with replaced(report_path) as partial:
            write_report(partial, merged, {
                "fmpy": fmpy.__version__, "step": SAMPLE_PERIOD, "preview": 2, "preset": "stage",
                "sets": None if not sets else {
                    "plant": args.plant_parameters.name,
                    "controller": args.controller_parameters.name,
                    "fitted_once": (args.controller_fitted_once or args.controller_parameters).name,
                },
                "experiments": every_run, "conditions": CONDITIONS, "wall": wall,
                "simulated": sum(e.duration for e in runs if e.key in results),
                "ran": None if ran_everything else len(results),
            })
        print(f"wrote {report_path}")
    elif results and report_path.exists():
        print(f"{report_path} left as it was: metrics.json lacks {len(missing)} runs "
              f"(run without --only to write both)", file=sys.stderr)
    if interrupted:
        print(f"interrupted: {len(results)} of {len(runs)} runs written to {args.out}, "
              f"each file complete; run the same command again to run them all",
              file=sys.stderr)
        return 130
    print(f"{len(runs)} runs, {wall:.1f} s wall time; CSV, PNG and metrics.json in {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
