"""Speed of the compiled master and of sweeps on dask (a benchmark script,
not a test; docs/sweeps.md keeps its figures).

    python -m demo.sweep_bench [--runs 1000] [--repeat 20] [--out out/sweep-bench]

1. One 4 s closed-loop run at 10 kHz (piezo-cosim/examples/table3_y.toml:
   Table 3's y run with decoupling, sensor noise, metrics) through
   piezo-cosim, `--repeat` times:
   the process's wall time as a sweep task sees it (start to exit, FMUs
   from unpacked folders), the master's own wall time (loading, loop,
   metrics) and the loop's; real-time factor = 4 s / wall time.
2. A sweep of `--runs` runs of 2 s each (a 10 x 10 grid of sine frequency
   and amplitude on y over a Monte Carlo of plants) on a LocalCluster of one
   worker, then of two: wall time from submission to the written table, and
   the speed-up.
The machine's load is recorded beside each figure (load average and the
share of all cores busy, from /proc): on a shared machine it moves every
figure.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import sys
import tempfile
import time
import tomllib
from pathlib import Path

from . import master, sweep

REPO = Path(__file__).resolve().parent.parent
PLANT = REPO / "dist" / "FlexureStage.fmu"
CONTROLLER = REPO / "dist" / "PiezoController.fmu"
SINGLE_RUN = REPO / "piezo-cosim" / "examples" / "table3_y.toml"


def cpu_busy() -> tuple[int, int]:
    """(busy, total) jiffies of all cores since boot."""
    fields = [int(v) for v in Path("/proc/stat").read_text().split("\n")[0].split()[1:]]
    idle = fields[3] + fields[4]  # idle + iowait
    total = sum(fields[:8])
    return total - idle, total


class Load:
    """Load average and the share of all cores busy over a measurement."""

    def __enter__(self):
        self.start = cpu_busy()
        self.load_before = os.getloadavg()[0]
        return self

    def __exit__(self, *exc):
        busy, total = cpu_busy()
        self.busy = (busy - self.start[0]) / max(total - self.start[1], 1)
        self.load_after = os.getloadavg()[0]

    def text(self) -> str:
        return (f"load average {self.load_before:.2f} -> {self.load_after:.2f}, "
                f"{100 * self.busy:.0f} % of {os.cpu_count()} cores busy (all processes)")


def unpacked(fmu: Path, into: Path) -> Path:
    import zipfile

    folder = into / fmu.stem
    with zipfile.ZipFile(fmu) as archive:
        archive.extractall(folder)
    return folder


def single_run(repeat: int, scratch: Path) -> dict:
    scenario = tomllib.loads(SINGLE_RUN.read_text())
    # As a sweep task runs it: the FMUs from their unpacked folders.
    scenario["fmu"]["plant"]["path"] = str(unpacked(PLANT, scratch))
    scenario["fmu"]["controller"]["path"] = str(unpacked(CONTROLLER, scratch))
    master.run(scenario)  # warm the page cache
    process, wall, loop = [], [], []
    with Load() as load:
        for _ in range(repeat):
            started = time.perf_counter()
            result = master.run(scenario)
            process.append(time.perf_counter() - started)
            wall.append(result["wall_s"])
            loop.append(result["loop_s"])
    median = {name: statistics.median(v) for name, v in
              (("process_s", process), ("master_wall_s", wall), ("loop_s", loop))}
    return {**median, "repeat": repeat, "simulated_s": 4.0,
            "realtime_process": 4.0 / median["process_s"],
            "realtime_master": 4.0 / median["master_wall_s"],
            "realtime_loop": 4.0 / median["loop_s"],
            "tracking_rms": result["metrics"]["tracking_rms"], "load": load.text()}


SPEC = """
study = "bench"
seed = 1

[monte_carlo]
samples = {samples}
seed_parameter = "noise.seed"
[[monte_carlo.vary]]
match = '^pzt\\[[123]\\]\\.(A|beta|gamma)$'
relative = 0.10

[template]
duration = 2.0
[template.fmu.plant]
path = "{plant}"
parameters = {{ "noise.enabled" = true }}
[template.fmu.controller]
path = "{controller}"
parameters = {{ feedback_x = false, feedback_theta = false, decoupling = true }}
[template.metrics]
driven = "y"
from = 1.0
[template.signal."controller.y_ref"]
offset = 7.0
sines = [{{ amplitude = "= amplitude", frequency = "= frequency", phase = -1.5707963267948966 }}]
[template.signal."controller.x_ref"]
offset = 8.0
start = 0.3
approach = 0.3

[[variable]]
name = "frequency"
values = [0.5, 1.0, 1.5, 2.0, 2.5, 3.0, 3.5, 4.0, 4.5, 5.0]
[[variable]]
name = "amplitude"
values = [0.5, 1.0, 1.5, 2.0, 2.5, 3.0, 3.5, 4.0, 4.5, 5.0]
"""


def sweep_runs(runs: int, workers: int, scratch: Path) -> dict:
    from distributed import Client, LocalCluster

    if runs % 100:
        raise SystemExit("--runs must be a multiple of 100 (a 10 x 10 grid per sample)")
    spec_path = scratch / "bench.toml"
    spec_path.write_text(SPEC.format(samples=runs // 100, plant=PLANT, controller=CONTROLLER))
    spec = sweep.load_spec(spec_path)
    out = scratch / f"out-{workers}"
    started = time.perf_counter()
    with LocalCluster(n_workers=workers, threads_per_worker=1, processes=True,
                      dashboard_address=None) as cluster, Client(cluster) as client:
        cluster_s = time.perf_counter() - started
        with Load() as load:
            t0 = time.perf_counter()
            summary = sweep.run_sweep(spec, out, client, restart=True, progress="none")
            sweep_s = time.perf_counter() - t0
    import pyarrow.parquet as pq

    rows = pq.read_table(sweep.table_path(out, "bench")).to_pylist()
    return {"workers": workers, "runs": summary["executed"], "failed": summary["failed"],
            "rows": len(rows), "sweep_s": sweep_s, "cluster_start_s": cluster_s,
            "runs_per_s": summary["executed"] / sweep_s,
            "mean_master_wall_s": statistics.fmean(r["wall_s"] for r in rows),
            "mean_task_s": statistics.fmean(r["task_s"] for r in rows),
            "load": load.text()}


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--runs", type=int, default=1000)
    parser.add_argument("--repeat", type=int, default=20)
    parser.add_argument("--out", type=Path, default=Path("out/sweep-bench"))
    args = parser.parse_args(argv)
    for path in (PLANT, CONTROLLER):
        if not path.is_file():
            print(f"{path}: run `make fmus`", file=sys.stderr)
            return 2
    master.binary()
    args.out.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory(prefix="sweep-bench-") as scratch:
        scratch = Path(scratch)
        single = single_run(args.repeat, scratch)
        print(f"one 4 s run: process {1e3 * single['process_s']:.1f} ms "
              f"({single['realtime_process']:.0f}x real time), master "
              f"{1e3 * single['master_wall_s']:.1f} ms ({single['realtime_master']:.0f}x), "
              f"loop {1e3 * single['loop_s']:.1f} ms ({single['realtime_loop']:.0f}x); "
              f"{single['load']}", flush=True)
        sweeps = []
        for workers in (1, 2):
            result = sweep_runs(args.runs, workers, scratch)
            sweeps.append(result)
            print(f"{result['runs']} runs of 2 s on {workers} worker(s): "
                  f"{result['sweep_s']:.1f} s ({result['runs_per_s']:.1f} runs/s; cluster "
                  f"start {result['cluster_start_s']:.1f} s); {result['load']}", flush=True)
    speedup = sweeps[0]["sweep_s"] / sweeps[1]["sweep_s"]
    print(f"2 workers / 1 worker: {speedup:.2f}x")
    report = {"single_run": single, "sweeps": sweeps, "speedup_2_workers": speedup,
              "cpu_count": os.cpu_count(), "when": time.strftime("%Y-%m-%d %H:%M:%S")}
    path = args.out / "bench.json"
    path.write_text(json.dumps(report, indent=2))
    print(f"wrote {path}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
