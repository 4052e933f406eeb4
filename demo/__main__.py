"""Runs seed 000's experiments in closed loop and writes CSV, PNG and report.md.

    python -m demo --out out/demo [--plant dist/FlexureStage.fmu]
                   [--controller dist/PiezoController.fmu] [--only KEY ...]
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import fmpy
from tqdm import tqdm

from .cosim import SAMPLE_PERIOD, Fmu, simulate
from .experiments import CONDITIONS, experiments, report_figures
from .report import figure, write_report

def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, required=True, help="output folder")
    parser.add_argument("--plant", type=Path, default=Path("dist/FlexureStage.fmu"))
    parser.add_argument("--controller", type=Path, default=Path("dist/PiezoController.fmu"))
    parser.add_argument("--only", nargs="*", help="run only these experiment keys")
    args = parser.parse_args(argv)
    for path in (args.plant, args.controller):
        if not path.is_file():
            print(f"{path}: no such FMU (run `make fmus`)", file=sys.stderr)
            return 2
    args.out.mkdir(parents=True, exist_ok=True)
    runs = experiments()
    if args.only:
        unknown = set(args.only) - {e.key for e in runs}
        if unknown:
            print(f"unknown experiment(s): {', '.join(sorted(unknown))}", file=sys.stderr)
            return 2
        runs = [e for e in runs if e.key in args.only]
    total_steps = sum(round(e.duration / SAMPLE_PERIOD) for e in runs)
    started = time.perf_counter()
    results = {}
    with Fmu(args.plant) as plant, Fmu(args.controller) as controller:
        spacing_um = float(controller.variables["L"].start) * 1e3
        with tqdm(total=total_steps, unit="step", unit_scale=True, desc="co-simulation") as bar:
            for experiment in runs:
                bar.set_postfix_str(experiment.key)
                run = simulate(
                    plant, controller, experiment.reference(), experiment.duration,
                    plant_parameters=experiment.plant, controller_parameters=experiment.controller,
                    progress=bar.update,
                )
                run.write_csv(args.out / f"{experiment.key}.csv")
                figure(experiment, run, spacing_um, args.out / f"{experiment.key}.png")
                results[experiment.key] = report_figures(experiment, run, spacing_um)
    wall = time.perf_counter() - started
    (args.out / "metrics.json").write_text(json.dumps(results, indent=2))
    if not args.only:
        write_report(args.out / "report.md", results, {
            "fmpy": fmpy.__version__, "step": SAMPLE_PERIOD, "preview": 2, "preset": "stage",
            "experiments": runs, "conditions": CONDITIONS, "wall": wall,
            "simulated": sum(e.duration for e in runs),
        })
        print(f"wrote {args.out / 'report.md'}")
    print(f"{len(runs)} runs, {wall:.1f} s wall time; CSV, PNG and metrics.json in {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
