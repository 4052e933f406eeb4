"""Measures the FlexureStage FMU's calibration fingerprints through fmpy and
writes report.md (each figure beside seed 000's) and the CSV of every run.

    python tests/fingerprint_report.py --fmu dist/FlexureStage.fmu --out out/plant
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from plant_fingerprints import (  # noqa: E402
    COUPLING_LOOP_WIDTH_MIN,
    LOOP_ASYMMETRY_MIN,
    LOOP_WIDTH_RANGE,
    TARGETS,
    Plant,
    measure,
)


def write_sweep_csv(path: Path, sweep) -> None:
    data = np.column_stack([sweep.t, sweep.commands, sweep.sensors])
    np.savetxt(path, data, delimiter=",", header="t_s,u1_V,u2_V,u3_V,s1_um,s2_um,s3_um", comments="")


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--fmu", required=True, type=Path)
    parser.add_argument("--out", required=True, type=Path)
    args = parser.parse_args()
    if not args.fmu.is_file():
        print(f"{args.fmu}: no such FMU (run make fmus)", file=sys.stderr)
        return 2
    args.out.mkdir(parents=True, exist_ok=True)
    started = time.perf_counter()
    plant = Plant(str(args.fmu))
    steps = ["strokes", "x home command", "rotation range", "theta_z resonance", "major loops",
             "coupling sweeps", "ultimate gains"]

    def progress(message: str) -> None:
        done = steps.index(message) if message in steps else 0
        bar = "#" * done + "." * (len(steps) - done)
        print(f"[{bar}] {message} ({time.perf_counter() - started:.0f} s)", flush=True)

    try:
        fp = measure(plant, progress)
    finally:
        plant.close()
    print(f"[{'#' * len(steps)}] done ({time.perf_counter() - started:.0f} s)")

    for name in ("y_sweep", "x_sweep", "rotation_sweep"):
        write_sweep_csv(args.out / f"{name}.csv", getattr(fp.couplings, name))

    rows = []
    failures = 0
    for key, target in TARGETS.items():
        measured = fp.value(key)
        error = measured / target.paper - 1.0
        ok = abs(error) <= target.relative_tolerance
        failures += not ok
        rows.append(
            f"| {target.name} | {target.paper:g} {target.unit} | {measured:.5g} {target.unit} "
            f"| {error:+.1%} | ±{target.relative_tolerance:.0%} | {'yes' if ok else 'NO'} | {target.source} |"
        )
    for axis in ("x", "y"):
        shape = getattr(fp, f"loop_{axis}")
        ratio = shape.max_width / getattr(fp, f"stroke_{axis}")
        ok = LOOP_WIDTH_RANGE[0] <= ratio <= LOOP_WIDTH_RANGE[1] and shape.asymmetry > LOOP_ASYMMETRY_MIN
        failures += not ok
        rows.append(
            f"| major loop {axis}: width / stroke, asymmetry | 8-15 %, asymmetric | {ratio:.1%}, "
            f"{shape.asymmetry:.2f} | | | {'yes' if ok else 'NO'} | issue |"
        )
    for key, shape in fp.couplings.shapes.items():
        ok = shape.width_ratio >= COUPLING_LOOP_WIDTH_MIN
        failures += not ok
        rows.append(
            f"| {key}: loop width / span | hysteretic (>= 5 %) | {shape.width_ratio:.1%} | | | "
            f"{'yes' if ok else 'NO'} | seed 001 eq. 8 |"
        )
    report = [
        "# FlexureStage calibration fingerprints",
        "",
        f"Measured through `{args.fmu}` with fmpy (procedures: tests/plant_fingerprints.py).",
        f"x home command: {fp.u_home:.6f} V; sweep amplitudes: y {fp.couplings.y_sweep.amplitude:.4f} V, "
        f"x {fp.couplings.x_sweep.amplitude:.4f} V, rotation ±{fp.couplings.rotation_sweep.amplitude:.4f} V.",
        "",
        "| figure | seed 000 | simulated | error | tolerance | within | where |",
        "|---|---|---|---|---|---|---|",
        *rows,
        "",
        "CSV: y_sweep.csv, x_sweep.csv, rotation_sweep.csv (t, commands, sensors).",
        "",
    ]
    (args.out / "report.md").write_text("\n".join(report))
    print("\n".join(report))
    print(f"wrote {args.out / 'report.md'}")
    return 1 if failures else 0


if __name__ == "__main__":
    sys.exit(main())
