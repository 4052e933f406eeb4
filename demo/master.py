"""The compiled co-simulation master, piezo-cosim, from Python.

    python -m demo.master run SCENARIO.toml [--series FILE.parquet|FILE.csv]

The master is a Rust program (piezo-cosim/) shipped inside this package as
demo/bin/piezo-cosim (`make master` builds and copies it; $PIEZO_COSIM
overrides the path). Python runs it as a child process: `run` one process per
run, `run_batch` one process for many runs (`piezo-cosim batch`: each FMU
opened once, instantiated per run):
- a run is isolated from the dask worker that asked for it: an FMU that
  crashes or hangs (any FMU can be loaded) ends its own process, reported as
  a failed run with its message (in a batch, that run; the runs after it go
  on in a new process); a timeout stops it;
- each run has its own FMU instances, so it is a pure function of its
  scenario for any FMU that keeps its state in its instances, as FMI 2.0
  asks (these FMUs do: runs that share their process equal runs that do not,
  bit for bit, piezo-cosim/tests/master.rs); for an FMU that keeps global
  state, one process per run (`run`, or a sweep's `runs_per_task = 1`);
- the CLI users run and the sweeps run are the same binary, with no Python
  ABI to build against.
What a process costs, about 3 ms started from Python, and what opening the two
FMUs costs, about 1.4 ms, are paid once per batch (docs/sweeps.md).

A scenario is a dict (or a TOML/JSON file) in the format of
piezo-cosim/src/scenario.rs; `run` hands it to the master as JSON on stdin
and returns the master's JSON result (metrics, wall time, warnings).
"""

from __future__ import annotations

import argparse
import json
import os
import re
import selectors
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from .cosim import COMMANDS, CONTROLLER_INSTANCE, PLANT_INSTANCE, REFERENCES, SENSORS

PACKAGE = Path(__file__).resolve().parent
REPO = PACKAGE.parent
#: Where `make master` puts the binary.
SHIPPED = PACKAGE / "bin" / "piezo-cosim"


class MasterError(RuntimeError):
    """A run that did not complete: the scenario did not fit (exit 2) or an
    FMU failed (exit 1), with the master's message."""

    def __init__(self, message: str, returncode: int | None = None):
        super().__init__(message)
        self.returncode = returncode


def binary() -> Path:
    """The piezo-cosim executable: $PIEZO_COSIM, else demo/bin/piezo-cosim."""
    override = os.environ.get("PIEZO_COSIM")
    path = Path(override) if override else SHIPPED
    if not path.is_file():
        raise FileNotFoundError(
            f"{path}: the co-simulation master is not built (run `make master`)")
    return path


def metrics() -> dict:
    """Every metric a run can report: {name: {"unit", "range",
    "description"}}, as `piezo-cosim metrics` prints it (a driven-axis
    figure's unit by axis: {"x": "um", "y": "um", "theta": "rad"})."""
    done = subprocess.run([str(binary()), "metrics"], capture_output=True, text=True,
                          timeout=60)
    if done.returncode != 0:
        raise MasterError(done.stderr.strip() or f"piezo-cosim exited with {done.returncode}",
                          done.returncode)
    return json.loads(done.stdout)


def connections() -> list[dict]:
    """The stage's closed loop as the master's connection table, from
    demo.cosim's wiring (the same table the master uses by default)."""
    table = [{"from": f"{CONTROLLER_INSTANCE}.{a}", "to": f"{PLANT_INSTANCE}.{b}"}
             for a, b in COMMANDS]
    table += [{"from": f"{PLANT_INSTANCE}.{a}", "to": f"{CONTROLLER_INSTANCE}.{b}"}
              for a, b in SENSORS]
    return table


def reference_port(name: str) -> str:
    """The controller input a reference (x_ref, y_ref, theta_ref) drives."""
    if name not in REFERENCES:
        raise KeyError(f"{name!r} is not one of {REFERENCES}")
    return f"{CONTROLLER_INSTANCE}.{name}"


def run(scenario: dict | str | Path, series: str | Path | None = None,
        timeout: float | None = None, cwd: str | Path | None = None) -> dict:
    """Runs one scenario through piezo-cosim; returns its JSON result.

    `scenario` is a dict (sent as JSON on stdin; relative paths are relative
    to `cwd`, default the working directory) or a .toml/.json file (paths
    relative to the file). `series` (.csv or .parquet) records every Real
    output and signal. Raises MasterError when the run fails and
    subprocess.TimeoutExpired after `timeout` seconds."""
    exe = str(binary())
    if series is not None:
        refuse_series(Path(series))
    with tempfile.TemporaryDirectory(prefix="piezo-cosim-") as scratch:
        # --parent: the run ends with this process (a killed dask worker
        # leaves no run behind).
        args = [exe, "run", "--parent", str(os.getpid())]
        csv = None
        if series is not None:
            series = Path(series)
            csv = series if series.suffix == ".csv" else Path(scratch) / "series.csv"
            args += ["--series", str(csv)]
        if isinstance(scenario, dict):
            args.append("-")
            stdin = json.dumps(scenario)
        else:
            args.append(str(scenario))
            stdin = None
        done = subprocess.run(args, input=stdin, capture_output=True, text=True,
                              timeout=timeout, cwd=cwd)
        if done.returncode != 0:
            message = done.stderr.strip() or f"piezo-cosim exited with {done.returncode}"
            raise MasterError(message, done.returncode)
        result = json.loads(done.stdout)
        if series is not None and csv != series:
            write_parquet(read_series(csv), series, series_units(csv))
    return result


def refuse_series(path: Path) -> None:
    """Raises MasterError (status 2, the scenario's) when `path` cannot be
    where a run's series goes: checked before the run, not after it. A
    Parquet series is written here, from the master's CSV, once the run has
    ended: a folder or a missing folder failed there, in a traceback."""
    if path.is_dir():
        raise MasterError(f"{path}: is a folder; name the series file in it", 2)
    folder = path.parent
    if not folder.is_dir():
        raise MasterError(f"{path}: there is no folder {folder} to write the series in", 2)
    if not os.access(folder, os.W_OK | os.X_OK):
        raise MasterError(f"{path}: the folder {folder} is not writable", 2)


def run_batch(scenarios: list[dict], timeout: float | None = None,
              cwd: str | Path | None = None) -> list:
    """Runs `scenarios` (dicts, paths relative to `cwd`) in one piezo-cosim
    process, or more when one fails hard; returns, for each scenario in
    order, what `run` would: its JSON result, or the MasterError or
    subprocess.TimeoutExpired that `run` would have raised (returned, not
    raised: the other runs have results).

    `timeout` bounds each run, counted from the previous result: a run past
    it is killed with its process, and the runs after it go on in a new one;
    so does every run after one whose process died (an FMU that crashed)."""
    outcomes: list = []
    while len(outcomes) < len(scenarios):
        outcomes += _batch_process(scenarios[len(outcomes):], timeout, cwd)
    return outcomes


def _batch_process(scenarios: list[dict], timeout: float | None, cwd) -> list:
    """One `piezo-cosim batch` process over `scenarios`: the outcomes of the
    runs it answered, then (when it stopped early) the outcome of the run it
    stopped at."""
    args = [str(binary()), "batch", "--parent", str(os.getpid()), "-"]
    with tempfile.TemporaryFile("w+") as lines, tempfile.TemporaryFile("w+") as errors:
        # Files, not pipes, for the input and the error stream: nothing
        # blocks on a full pipe whatever the batch's size.
        lines.write("".join(json.dumps(scenario) + "\n" for scenario in scenarios))
        lines.seek(0)
        process = subprocess.Popen(args, stdin=lines, stdout=subprocess.PIPE, stderr=errors,
                                   cwd=cwd)
        outcomes: list = []
        pending = b""

        def stop(outcome) -> list:
            """Ends the process; `outcome` is the run it stopped at."""
            process.kill()
            process.wait()
            process.stdout.close()
            outcomes.append(outcome)
            return outcomes

        with selectors.DefaultSelector() as selector:
            selector.register(process.stdout, selectors.EVENT_READ)
            deadline = None if timeout is None else time.monotonic() + timeout
            while len(outcomes) < len(scenarios):
                wait = None if deadline is None else max(deadline - time.monotonic(), 0.0)
                if not selector.select(wait):
                    return stop(subprocess.TimeoutExpired(args, timeout))
                chunk = os.read(process.stdout.fileno(), 1 << 16)
                if not chunk:
                    break
                pending += chunk
                *complete, pending = pending.split(b"\n")
                for line in complete:
                    try:
                        result = json.loads(line)
                    except json.JSONDecodeError:
                        # Not the master's (it writes results on a stream of
                        # their own): the process is not to be trusted with
                        # the remaining runs.
                        text = line[:200].decode(errors="replace")
                        return stop(MasterError(
                            f"piezo-cosim wrote {text!r} where a result was due", None))
                    result.pop("line", None)
                    if result["status"] == "error":
                        outcomes.append(MasterError(result["error"], result["exit"]))
                    else:
                        outcomes.append(result)
                if complete and timeout is not None:
                    deadline = time.monotonic() + timeout
        returncode = process.wait()
        process.stdout.close()
        if len(outcomes) < len(scenarios):
            errors.seek(0)
            why = (f"was killed by signal {-returncode}" if returncode < 0
                   else f"exited with {returncode}")
            message = errors.read().strip() or f"piezo-cosim {why} during this run"
            outcomes.append(MasterError(message, returncode))
    return outcomes


def check(scenario: dict, cwd: str | Path | None = None) -> dict:
    """Checks a scenario against its FMUs without stepping (`piezo-cosim
    check`): every connection, signal and parameter resolved, the FMUs
    initialized. Raises MasterError with the master's message."""
    done = subprocess.run([str(binary()), "check", "-"], input=json.dumps(scenario),
                          capture_output=True, text=True, cwd=cwd)
    if done.returncode != 0:
        message = done.stderr.strip() or f"piezo-cosim exited with {done.returncode}"
        raise MasterError(message, done.returncode)
    return json.loads(done.stdout)


_HEADER_UNIT = re.compile(r"^(.*?)\[([^\[\]]*)\]$")


def series_units(path: str | Path) -> dict[str, str]:
    """The unit of each column of a series CSV that its header gives in
    brackets (`plant.x[um]`, `t[s]`), by the column's name."""
    with Path(path).open() as f:
        header = f.readline().strip().split(",")
    return {found.group(1): found.group(2) for found in map(_HEADER_UNIT.match, header) if found}


def read_series(path: str | Path) -> dict[str, np.ndarray]:
    """A series CSV written by piezo-cosim, as columns by name (`t`,
    `plant.x`: the header's units left out; `series_units` gives them)."""
    path = Path(path)
    with path.open() as f:
        header = f.readline().strip().split(",")
    names = [found.group(1) if (found := _HEADER_UNIT.match(h)) else h for h in header]
    data = np.loadtxt(path, delimiter=",", skiprows=1, ndmin=2)
    return {name: data[:, i] for i, name in enumerate(names)}


def write_parquet(columns: dict[str, np.ndarray], path: str | Path,
                  units: dict[str, str] | None = None) -> None:
    """The columns as a Parquet table, each column's unit (where `units`
    gives one) in its Arrow field's metadata (b"unit"), as a sweep's table
    carries them."""
    import pyarrow as pa
    import pyarrow.parquet as pq

    units = units or {}
    fields = [pa.field(name, pa.float64(), metadata={b"unit": units[name].encode()}
                       if name in units else None) for name in columns]
    table = pa.table({k: pa.array(v) for k, v in columns.items()}, schema=pa.schema(fields))
    pq.write_table(table, str(path))


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    sub = parser.add_subparsers(dest="command", required=True)
    go = sub.add_parser("run", help="run one scenario; print its result as JSON")
    go.add_argument("scenario", type=Path, help="scenario file (.toml or .json)")
    go.add_argument("--series", type=Path, help="write the time series (.csv or .parquet)")
    args = parser.parse_args(argv)
    if args.series is not None and args.series.suffix not in (".csv", ".parquet"):
        print(f"{args.series}: name the series .csv or .parquet", file=sys.stderr)
        return 2
    started = time.perf_counter()
    try:
        result = run(args.scenario, series=args.series)
    except (MasterError, FileNotFoundError) as e:
        print(e, file=sys.stderr)
        return getattr(e, "returncode", None) or 2
    result["python_wall_s"] = time.perf_counter() - started
    print(json.dumps(result, indent=2))
    return 0


if __name__ == "__main__":
    sys.exit(main())
