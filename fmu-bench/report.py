#!/usr/bin/env python3
"""Turns the results of `cargo bench -p fmu-bench` into the project's table.

Reads criterion's `<criterion dir>/**/new/estimates.json` (with the
`benchmark.json` beside each for its name) and prints a Markdown table: cost
of one 100 us sample, FMI overhead against the direct call, real-time factor
at 10 kHz, the project's target and whether it is met. Python 3 standard
library only.

    python3 fmu-bench/report.py [--criterion-dir DIR] [--estimate median|mean|slope]

The doStep-only rows are derived: (set inputs + doStep) - (set inputs), both
measured on the same instance type (see README.md for why doStep is not timed
alone).
"""

from __future__ import annotations

import argparse
import json
import os
import sys
from pathlib import Path

#: Communication step of every benchmark [ns]: seed 000's 10 kHz.
STEP_NS = 100_000.0


def default_criterion_dir() -> Path:
    """Where criterion writes: $CRITERION_HOME, $CARGO_TARGET_DIR/criterion,
    or the workspace's target/criterion (this script lives in fmu-bench/)."""
    if os.environ.get("CRITERION_HOME"):
        return Path(os.environ["CRITERION_HOME"])
    if os.environ.get("CARGO_TARGET_DIR"):
        return Path(os.environ["CARGO_TARGET_DIR"]) / "criterion"
    return Path(__file__).resolve().parent.parent / "target" / "criterion"


class Estimate:
    """A point estimate [ns] with its 95 % confidence interval."""

    def __init__(self, point: float, low: float, high: float):
        self.point, self.low, self.high = point, low, high

    def minus(self, other: "Estimate") -> "Estimate":
        # The interval of a difference of two independent estimates is at most
        # this wide; criterion does not give their joint distribution.
        return Estimate(self.point - other.point, self.low - other.high, self.high - other.low)

    def cell(self) -> str:
        return f"{self.point:,.1f} ({self.low:,.1f}–{self.high:,.1f})"


def load_estimates(root: Path, statistic: str) -> dict[str, Estimate]:
    """Every benchmark under `root` by its full id (`group/function`)."""
    found: dict[str, Estimate] = {}
    for path in sorted(root.glob("**/new/estimates.json")):
        meta_path = path.with_name("benchmark.json")
        if meta_path.exists():
            name = json.loads(meta_path.read_text())["full_id"]
        else:
            name = str(path.parent.parent.relative_to(root))
        estimates = json.loads(path.read_text())
        entry = estimates.get(statistic)
        if entry is None:
            # `slope` exists only for linear sampling; fall back to the median.
            entry = estimates["median"]
        ci = entry["confidence_interval"]
        found[name] = Estimate(entry["point_estimate"], ci["lower_bound"], ci["upper_bound"])
    return found


def verdict(met: bool) -> str:
    return "met" if met else "**missed**"


def load_paired(root: Path) -> dict:
    """The overhead ratios the benchmark binary measured by interleaving the
    direct and the ABI workloads in short blocks (fmu-bench-paired.json)."""
    path = root / "fmu-bench-paired.json"
    return json.loads(path.read_text()) if path.exists() else {}


class Row:
    def __init__(self, name, label, estimate, overhead=None):
        #: criterion's id (or the derived `<fmu>/abi_doStep`) and what it is
        self.name, self.label = name, label
        #: criterion's estimate [ns]
        self.estimate = estimate
        #: ratio of criterion's point estimates - 1
        self.overhead = overhead
        #: [q1, median, q3] of the interleaved timing [ns] and overhead ratio - 1
        self.interleaved_ns = None
        self.interleaved_overhead = None
        self.target, self.result = "", ""

    def ns(self) -> float:
        """The time per sample the verdicts use: the interleaved median when
        there is one (it is immune to the machine's drift between two
        criterion benchmarks), criterion's estimate otherwise."""
        return self.interleaved_ns[1] if self.interleaved_ns else self.estimate.point

    def overhead_used(self) -> float | None:
        return self.interleaved_overhead[1] if self.interleaved_overhead else self.overhead


def rows(results: dict[str, Estimate], paired: dict) -> list[Row]:
    def ratio(a: Estimate | None, b: Estimate | None) -> float | None:
        return a.point / b.point - 1.0 if a and b else None

    out = []
    for fmu, step_target_ns in (("controller", 100.0), ("plant", 1000.0)):
        direct = results.get(f"{fmu}/direct_step")
        set_inputs = results.get(f"{fmu}/abi_set_inputs")
        set_step = results.get(f"{fmu}/abi_set_doStep")
        cycle = results.get(f"{fmu}/abi_set_doStep_get")
        group = []
        if direct:
            group.append(Row("direct_step", "Rust call", direct))
        if set_inputs:
            group.append(Row("abi_set_inputs", "fmi2SetReal only", set_inputs))
        if set_step and set_inputs:
            do_step = set_step.minus(set_inputs)
            row = Row("abi_doStep", "set+doStep − set", do_step, ratio(do_step, direct))
            row.target = f"≤ {step_target_ns:,.0f} ns; overhead ≤ 5 %"
            group.append(row)
        if set_step:
            group.append(Row("abi_set_doStep", "", set_step, ratio(set_step, direct)))
        if cycle:
            group.append(Row("abi_set_doStep_get", "importer's sample", cycle,
                             ratio(cycle, direct)))
        measured = paired.get(fmu, {})
        for row in group:
            row.interleaved_ns = measured.get("ns", {}).get(row.name)
            row.interleaved_overhead = measured.get("overhead", {}).get(row.name)
            row.name = f"{fmu}/{row.name}"
            if row.target:
                row.result = verdict(row.ns() <= step_target_ns)
                if row.overhead_used() is not None:
                    row.result += "; " + verdict(row.overhead_used() <= 0.05)
        out += group

    direct_loop = results.get("closed_loop/direct")
    abi_loop = results.get("closed_loop/abi")
    measured = paired.get("closed_loop", {})
    if direct_loop:
        row = Row("closed_loop/direct", "Rust calls", direct_loop)
        row.interleaved_ns = measured.get("ns", {}).get("direct")
        out.append(row)
    if abi_loop:
        row = Row("closed_loop/abi", "both FMUs, one sample", abi_loop,
                  ratio(abi_loop, direct_loop))
        row.interleaved_ns = measured.get("ns", {}).get("abi")
        row.interleaved_overhead = measured.get("overhead", {}).get("abi")
        row.target = "≥ 100x real time"
        row.result = verdict(STEP_NS / row.ns() >= 100.0)
        out.append(row)
    return out


def machine_load(root: Path) -> str | None:
    """The load the benchmark binary recorded during its run, if it did."""
    path = root / "fmu-bench-machine.json"
    if not path.exists():
        return None
    m = json.loads(path.read_text())
    return (
        f"Machine during the run ({m['elapsed_s']:.0f} s, {m['cores']} cores): "
        f"{100 * m['machine_busy_fraction']:.0f} % of all cores busy, "
        f"{100 * m['bench_fraction']:.0f} % by the benchmarks, "
        f"{100 * m['others_fraction']:.0f} % by other processes, "
        f"{100 * m['steal_fraction']:.1f} % stolen by the hypervisor; "
        f"load average {m['loadavg_before']} before, {m['loadavg_after']} after."
    )


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--criterion-dir", type=Path, default=default_criterion_dir())
    parser.add_argument("--estimate", choices=("median", "mean", "slope"), default="median",
                        help="criterion statistic used as the time per step (default: median)")
    args = parser.parse_args()

    results = load_estimates(args.criterion_dir, args.estimate)
    table = rows(results, load_paired(args.criterion_dir))
    if not table:
        print(f"no fmu-bench results under {args.criterion_dir}: run `cargo bench -p fmu-bench`",
              file=sys.stderr)
        return 1

    def triple(q, scale=1.0, unit="", sign=""):
        if not q:
            return ""
        lo, mid, hi = (scale * v for v in q)
        return f"{mid:{sign},.1f}{unit} ({lo:{sign},.1f} … {hi:{sign},.1f})"

    print(f"| benchmark | ns per sample, criterion {args.estimate} (95 % CI) "
          "| ns per sample, interleaved median (IQR) | overhead vs direct, interleaved (IQR) "
          "| overhead vs direct, criterion | real-time factor at 10 kHz | target | result |")
    print("|---|---:|---:|---:|---:|---:|---|---|")
    for row in table:
        name = f"{row.name} ({row.label})" if row.label else row.name
        criterion_overhead = "" if row.overhead is None else f"{100 * row.overhead:+.1f} %"
        interleaved_overhead = triple(row.interleaved_overhead, 100.0, " %", "+")
        rtf = f"{STEP_NS / row.ns():,.0f}x" if row.ns() > 0 else "n/a"
        print(f"| {name} | {row.estimate.cell()} | {triple(row.interleaved_ns)} "
              f"| {interleaved_overhead} | {criterion_overhead} | {rtf} | {row.target} "
              f"| {row.result} |")
    print()
    print("Real-time factors and verdicts use the interleaved medians where there are some "
          "(see fmu-bench/README.md), criterion's estimates otherwise.")
    load = machine_load(args.criterion_dir)
    if load:
        print(load)
    return 0


if __name__ == "__main__":
    sys.exit(main())
