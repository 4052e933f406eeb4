"""Sweeps on dask.distributed (demo/sweep.py): a LocalCluster, an existing
scheduler with two worker processes on 127.0.0.1, a worker killed mid-sweep,
an interrupted sweep continued, a timed-out run run again, and the same table
whatever the number of workers.

The spec is small and its runs short (8 runs of 0.3-0.6 s of the loop at
10 kHz, a two-sample Monte Carlo over a grid of four), so that the cluster's
start-up dominates and the file stays lean; the reliability assertions do
not depend on the runs' length.
"""

from __future__ import annotations

import contextlib
import copy
import json
import os
import re
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from demo import master, sweep
from tests.conftest import REPO_ROOT, require_closed_loop_build

PLANT = REPO_ROOT / "dist" / "FlexureStage.fmu"
CONTROLLER = REPO_ROOT / "dist" / "PiezoController.fmu"
DASK = Path(sys.executable).parent / "dask"

SPEC = f"""
study = "small"
seed = 7

[monte_carlo]
samples = 2
seed_parameter = "noise.seed"
[[monte_carlo.vary]]
match = '^pzt\\[1\\]\\.(A|beta)$'
relative = 0.10
[[monte_carlo.vary]]
match = '^amplifier\\.gain$'
relative = 0.03

[template]
duration = "= 0.2 + 2 / frequency"
[template.fmu.plant]
path = "{PLANT}"
parameters = {{ "noise.enabled" = true }}
[template.fmu.controller]
path = "{CONTROLLER}"
[template.metrics]
driven = "y"
from = "= 0.2 + 1 / frequency"
[template.signal."controller.y_ref"]
offset = 6.0
sines = [{{ amplitude = "= amplitude", frequency = "= frequency" }}]
[template.signal."controller.x_ref"]
offset = 6.0
start = 0.2
approach = 0.2

[[variable]]
name = "frequency"
values = [5.0, 10.0]
[[variable]]
name = "decoupling"
[variable.values.off]
patch.fmu.controller.parameters = {{ decoupling = false }}
[variable.values.on]
patch.fmu.controller.parameters = {{ decoupling = true }}
[[variable]]
name = "amplitude"
values = [2.0]
"""

RUNS = 8


@pytest.fixture(scope="module")
def spec_path(tmp_path_factory):
    require_closed_loop_build()
    path = tmp_path_factory.mktemp("spec") / "small.toml"
    path.write_text(SPEC)
    return path


def rows_of(out: Path) -> list[dict]:
    import pyarrow.parquet as pq

    return pq.read_table(out / "small.parquet").to_pylist()


def results(rows: list[dict]) -> list[dict]:
    """The rows without the columns that describe the execution."""
    return [{k: v for k, v in r.items() if k not in sweep.EXECUTION_COLUMNS} for r in rows]


def local_sweep(spec_path, out, workers, **kwargs):
    from distributed import Client, LocalCluster

    with LocalCluster(n_workers=workers, threads_per_worker=1, processes=True,
                      dashboard_address=None) as cluster, Client(cluster) as client:
        return sweep.run_sweep(sweep.load_spec(spec_path), out, client, progress="none",
                               **kwargs)


def local_sweeps(sweeps: list[tuple[Path, Path]], workers: int = 1, **kwargs) -> list[dict]:
    """run_sweep of each (spec, out) in turn, on one LocalCluster."""
    from distributed import Client, LocalCluster

    with LocalCluster(n_workers=workers, threads_per_worker=1, processes=True,
                      dashboard_address=None) as cluster, Client(cluster) as client:
        return [sweep.run_sweep(sweep.load_spec(spec), out, client, progress="none", **kwargs)
                for spec, out in sweeps]


@pytest.fixture(scope="module")
def reference_out(spec_path, tmp_path_factory):
    """The folder of the spec's table from a LocalCluster of one worker."""
    out = tmp_path_factory.mktemp("one-worker")
    summary = local_sweep(spec_path, out, workers=1)
    assert summary["executed"] == RUNS and summary["failed"] == 0, summary
    return out


@pytest.fixture(scope="module")
def reference_table(reference_out):
    """The spec's table from a LocalCluster of one worker."""
    return rows_of(reference_out)


def test_a_local_cluster_sweep_makes_one_row_per_run(spec_path, reference_table):
    rows = reference_table
    assert [r["run"] for r in rows] == list(range(RUNS))
    assert len({r["key"] for r in rows}) == RUNS
    assert all(r["status"] == "ok" and r["error"] is None for r in rows)
    # Every swept value, the seed, the metrics, the wall time.
    first = rows[0]
    for column in ("frequency", "decoupling", "amplitude", "sample", "seed",
                   "factor.pzt[1].A", "factor.pzt[1].beta", "factor.amplifier.gain",
                   "tracking_rms", "tracking_max", "coupling_x2_span", "coupling_x3_range_min",
                   "wall_s", "task_s", "worker"):
        assert column in first, column
    factors = [r["factor.pzt[1].A"] for r in rows]
    assert all(0.9 <= f <= 1.1 for f in factors)
    # The four grid points of a sample share its plant and its seed.
    assert len({(r["sample"], r["factor.pzt[1].A"], r["seed"]) for r in rows}) == 2
    # A row is what the master gives for that run directly.
    spec = sweep.load_spec(spec_path)
    runs, fmus = sweep.expand(spec)
    scenario = sweep.local_scenario(runs[5], fmus)
    direct = master.run(scenario)["metrics"]
    assert set(direct) <= set(sweep.metric_definitions()), "the master's own list names them"
    assert rows[5]["tracking_rms"] == direct["tracking_rms"]
    assert rows[5]["coupling_x2_range_min"] == direct["coupling_x2_range"][0]


def test_the_table_carries_each_columns_unit(reference_out):
    """Each column that holds a quantity has its unit in its Arrow field's
    metadata (b"unit"): a variable the unit of what it sets in the FMUs (the
    amplitude of controller.y_ref, by the FMU's modelDescription), a metric
    its definition's, a Monte Carlo factor a ratio; the columns that name or
    number a run have none."""
    import pyarrow.parquet as pq
    from fmpy import read_model_description

    schema = pq.read_schema(sweep.table_path(reference_out, "small"))
    units = {field.name: field.metadata[b"unit"].decode() for field in schema
             if field.metadata and b"unit" in field.metadata}
    controller = {v.name: v.unit for v in read_model_description(str(CONTROLLER)).modelVariables}
    expected = {"frequency": "Hz", "amplitude": controller["y_ref"], "tracking_rms": "um",
                "tracking_max": "um", "demand_span": "um", "coupling_x2_span": "um",
                "coupling_x2_range_min": "um", "coupling_x2_range_max": "um",
                "command_saturation": "1", "samples": "1", "factor.pzt[1].A": "1",
                "factor.amplifier.gain": "1", "steps": "1", "warnings": "1",
                "simulated_s": "s", "wall_s": "s", "task_s": "s"}
    assert controller["y_ref"] == "um"
    assert {name: units.get(name) for name in expected} == expected
    metric_columns = {column for metric in sweep.metric_definitions()
                      for column in sweep.metric_columns_of(metric)}
    assert {name for name in schema.names if name in metric_columns} <= set(units)
    for name in ("run", "key", "status", "error", "worker", "seed", "sample", "decoupling"):
        assert name in schema.names and name not in units, name
    assert schema.metadata[b"study"] == b"small", "the spec stays in the schema's metadata"


def test_a_figure_of_the_driven_axis_has_a_unit_only_where_the_runs_share_one():
    """A table of runs driven on x, y and theta_z holds tracking figures in
    um and in rad: such a column claims no unit (a reader that parses units
    gets none rather than a sentence), as a variable whose values differ. A
    table of y runs holds um. The envelope's amplitude and held demand are
    shares of a stroke, used in expressions only: the FMUs give them no
    unit, and the table claims none."""
    spec = sweep.load_spec(REPO_ROOT / "demo" / "sweeps" / "envelope.toml")
    runs = sweep.expand(spec)[0]
    units = sweep.column_units(spec, runs)
    assert {run.scenario["metrics"]["driven"] for run in runs} == {"x", "y", "theta"}
    assert "tracking_rms" not in units and "demand_span" not in units
    assert (units["coupling_y_span"], units["frequency"]) == ("um", "Hz")
    assert "amplitude" not in units and "held" not in units
    y_runs = [run for run in runs if run.scenario["metrics"]["driven"] == "y"]
    assert sweep.column_units(spec, y_runs)["tracking_rms"] == "um"


def test_an_interrupt_before_any_row_says_no_run_is_kept(tmp_path):
    message = sweep.interrupted_message({"small": {"k1", "k2"}}, tmp_path / "none", False)
    assert message == ("interrupted: no run of small kept (2 to run); run the same command "
                       "again to resume")


def test_the_same_spec_gives_the_same_table_on_two_workers(spec_path, reference_table,
                                                          tmp_path):
    summary = local_sweep(spec_path, tmp_path, workers=2)
    assert summary["executed"] == RUNS
    rows = rows_of(tmp_path)
    assert len({r["worker"] for r in rows}) == 2, "both workers ran runs"
    assert results(rows) == results(reference_table)


def test_an_interrupted_sweep_continues_where_it_stopped(tmp_path):
    """Ctrl-C once the first rows are in, as a terminal sends it: SIGINT to
    the whole process group of `python -m demo.sweep`, its dask workers and
    their masters too. The command ends with one line, the runs kept and how
    to resume, and status 130; the workers' tracebacks and dask's logs of
    the cancelled tasks were printed before. The same command again runs
    only what is missing."""
    spec_path = tmp_path / "longer.toml"
    # Long enough (a few seconds at about 50 ms a run) that the interrupt
    # lands while runs are still going on a fast machine too.
    spec_path.write_text(SPEC.replace("samples = 2", "samples = 40"))
    runs = 40 * 4
    out = tmp_path / "out"
    env = {**os.environ, "PYTHONPATH": str(REPO_ROOT)}
    command = [sys.executable, "-m", "demo.sweep", str(spec_path), "--out", str(out),
               "--workers", "1", "--progress", "none", "--no-report"]
    # Ctrl-C as in a terminal: `make test` started as a background job (a CI
    # runner's shell without job control) hands its commands an ignored
    # SIGINT, which Python then keeps ignoring, and the sweep ran to its end;
    # the child gets the default disposition back, so Python raises
    # KeyboardInterrupt as a user's terminal would have it. In a process
    # group of its own, the interrupt reaches it and its descendants only.
    child = subprocess.Popen(command, cwd=REPO_ROOT, env=env, stdout=subprocess.PIPE,
                             stderr=subprocess.PIPE, text=True, process_group=0,
                             preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    journal = sweep.journal_path(out, "small")
    deadline = time.monotonic() + 120
    try:
        while not (journal.is_file() and journal.read_text().count("\n") >= 2):
            if child.poll() is not None or time.monotonic() > deadline:
                pytest.fail("no rows journalled: " + child.communicate()[1])
            time.sleep(0.01)
        os.killpg(child.pid, signal.SIGINT)
        stdout, stderr = child.communicate(timeout=120)
    finally:
        if child.poll() is None:
            os.killpg(child.pid, signal.SIGKILL)
            child.wait()
    assert child.returncode == 130, (stdout, stderr)
    assert not journal.exists(), "the journal is folded into the table"
    first = rows_of(out)
    assert 2 <= len(first) < runs, len(first)
    assert stderr == (f"interrupted: {len(first)} of {runs} runs of small kept in "
                      f"{sweep.table_path(out, 'small')}; run the same command again to "
                      f"resume\n"), stderr
    # Nothing of the study is left running: the cluster's processes and
    # their masters have ended with it.
    deadline = time.monotonic() + 30
    with contextlib.suppress(ProcessLookupError):
        while time.monotonic() < deadline:
            os.killpg(child.pid, 0)
            time.sleep(0.1)
        pytest.fail("processes of the interrupted study are still running")
    done = subprocess.run(command, cwd=REPO_ROOT, env=env, capture_output=True, text=True,
                          timeout=300)
    assert done.returncode == 0, done.stderr
    assert f"{runs - len(first)} runs executed" in done.stdout, done.stdout
    assert f"{len(first)} already in the table" in done.stdout, done.stdout
    rows = rows_of(out)
    assert [r["run"] for r in rows] == list(range(runs))
    # The rows of the first part are kept as they were, not run again.
    kept = {r["key"]: r for r in rows}
    assert all(kept[r["key"]] == r for r in first)


@contextlib.contextmanager
def cluster(folder: Path, workers: int, scheduler_env: dict, worker_env: dict | list[dict],
            cwd: Path):
    """`dask scheduler` and `workers` `dask worker` processes on 127.0.0.1,
    each started in `cwd` with its environment (`worker_env`: one for all,
    or one per worker). They stop themselves if left
    behind: the scheduler after 60 s without work, the workers 30 s after
    losing it; leaving the block stops them anyway. Yields the address."""
    scheduler_file = folder / "scheduler.json"
    processes = []
    logs = []

    def start(env, *args):
        logs.append(open(folder / f"{len(processes)}.log", "w"))
        processes.append(subprocess.Popen([str(DASK), *args], cwd=cwd, env=env,
                                          stdout=logs[-1], stderr=subprocess.STDOUT))

    try:
        # Port 0 for its HTTP server too (health checks, even without the
        # dashboard): 8787 may belong to a user's cluster or another test's.
        start(scheduler_env, "scheduler", "--host", "127.0.0.1", "--port", "0",
              "--no-dashboard", "--dashboard-address", "127.0.0.1:0",
              "--scheduler-file", str(scheduler_file), "--idle-timeout", "60s")
        deadline = time.monotonic() + 60
        while not scheduler_file.is_file():
            if time.monotonic() > deadline or processes[0].poll() is not None:
                pytest.fail("the dask scheduler did not start: "
                            + (folder / "0.log").read_text())
            time.sleep(0.1)
        address = json.loads(scheduler_file.read_text())["address"]
        for n in range(workers):
            start(worker_env[n] if isinstance(worker_env, list) else worker_env, "worker",
                  address, "--nthreads", "1", "--nworkers", "1", "--no-dashboard", "--host",
                  "127.0.0.1", "--death-timeout", "30s", "--lifetime", "600s")
        from distributed import Client

        if workers:
            with Client(address, timeout="30s") as client:
                client.wait_for_workers(workers, timeout=60)
        yield address
    finally:
        for process in reversed(processes):
            if process.poll() is None:
                process.terminate()
        for process in processes:
            try:
                process.wait(timeout=30)
            except subprocess.TimeoutExpired:
                process.kill()
                process.wait()
        for log in logs:
            log.close()


@pytest.fixture(scope="module")
def dask_cluster(tmp_path_factory):
    """A scheduler and two workers started as the README says: from the
    checkout, PYTHONPATH set to it."""
    env = {**os.environ, "PYTHONPATH": str(REPO_ROOT)}
    with cluster(tmp_path_factory.mktemp("cluster"), 2, env, env, REPO_ROOT) as address:
        yield address


def test_a_scheduler_that_cannot_import_the_package_is_named_with_the_fix(spec_path,
                                                                           tmp_path):
    """The scheduler unpickles the tasks, which name `demo`'s functions: one
    started outside the checkout without PYTHONPATH runs nothing, and the
    sweep says what to do (the README's recipe sets PYTHONPATH for both)."""
    bare = {k: v for k, v in os.environ.items() if k != "PYTHONPATH"}
    with_package = {**os.environ, "PYTHONPATH": str(REPO_ROOT)}
    (tmp_path / "cluster").mkdir()
    with cluster(tmp_path / "cluster", 1, bare, with_package, tmp_path) as address:
        done = subprocess.run(
            [sys.executable, "-m", "demo.sweep", str(spec_path), "--out", str(tmp_path / "out"),
             "--scheduler", address, "--progress", "none", "--no-report"],
            cwd=REPO_ROOT, env=with_package, capture_output=True, text=True, timeout=300)
    # Before any task is sent, in a few lines and with the status of a
    # cluster that cannot run the study (not 1: no run failed).
    assert done.returncode == sweep.EXIT_CLUSTER == 3, done.stdout + done.stderr
    assert done.stderr.startswith(f"the dask scheduler at {address} cannot read the tasks: "
                                  f"ModuleNotFoundError: No module named 'demo'"), done.stderr
    assert "start `dask scheduler` and `dask worker` from a checkout with PYTHONPATH" \
        in done.stderr, done.stderr
    assert len(done.stderr.splitlines()) == 2 and "Traceback" not in done.stderr, done.stderr
    assert not (tmp_path / "out" / "small.parquet").exists()


def test_a_worker_that_cannot_import_the_package_is_named_at_once(spec_path, tmp_path):
    """A worker started without PYTHONPATH died of the first task it could
    not unpickle; the study waited 30 s for a worker to scatter the FMUs to,
    then ended in a 60-line traceback (`No valid workers found`), exit 1,
    the hint never printed. Every worker now runs the tasks' imports first:
    none can, and the command says so in a few lines, at once, exit 3."""
    bare = {k: v for k, v in os.environ.items() if k != "PYTHONPATH"}
    with_package = {**os.environ, "PYTHONPATH": str(REPO_ROOT)}
    (tmp_path / "cluster").mkdir()
    with cluster(tmp_path / "cluster", 1, with_package, bare, tmp_path) as address:
        started = time.monotonic()
        done = subprocess.run(
            [sys.executable, "-m", "demo.sweep", str(spec_path), "--out", str(tmp_path / "out"),
             "--scheduler", address, "--progress", "none", "--no-report"],
            cwd=REPO_ROOT, env=with_package, capture_output=True, text=True, timeout=300)
        elapsed = time.monotonic() - started
    assert done.returncode == 3, done.stdout + done.stderr
    assert done.stderr.startswith(f"no worker of the dask scheduler at {address} can run the "
                                  f"tasks (1 of 1; tcp://"), done.stderr
    assert "ModuleNotFoundError: No module named 'demo'" in done.stderr, done.stderr
    assert "from a checkout with PYTHONPATH set to it" in done.stderr, done.stderr
    assert len(done.stderr.splitlines()) == 2 and "Traceback" not in done.stderr, done.stderr
    assert elapsed < 20, elapsed


def test_a_worker_that_cannot_run_the_tasks_gets_none(spec_path, reference_table, tmp_path):
    """With a worker that cannot import the package beside one that can,
    the study runs on the latter, and says which worker gets no task."""
    bare = {k: v for k, v in os.environ.items() if k != "PYTHONPATH"}
    with_package = {**os.environ, "PYTHONPATH": str(REPO_ROOT)}
    (tmp_path / "cluster").mkdir()
    with cluster(tmp_path / "cluster", 2, with_package, [bare, with_package],
                 tmp_path) as address:
        done = subprocess.run(
            [sys.executable, "-m", "demo.sweep", str(spec_path), "--out", str(tmp_path / "out"),
             "--scheduler", address, "--progress", "none", "--no-report"],
            cwd=REPO_ROOT, env=with_package, capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stdout + done.stderr
    assert done.stderr.startswith("1 of 2 workers cannot run the tasks and get none (tcp://"), \
        done.stderr
    rows = rows_of(tmp_path / "out")
    assert len({r["worker"] for r in rows}) == 1
    assert results(rows) == results(reference_table)


def test_a_scheduler_without_workers_is_named_after_a_short_wait(spec_path, tmp_path,
                                                                 monkeypatch):
    """A scheduler with no worker: the study waited 30 s in dask's scatter,
    then ended in a traceback. It waits WORKER_WAIT_S for a worker to join,
    then says what to start."""
    from distributed import Client

    monkeypatch.setattr(sweep, "WORKER_WAIT_S", 1.0)
    env = {**os.environ, "PYTHONPATH": str(REPO_ROOT)}
    (tmp_path / "cluster").mkdir()
    with cluster(tmp_path / "cluster", 0, env, env, REPO_ROOT) as address, \
            Client(address, timeout="30s") as client:
        with pytest.raises(sweep.ClusterError) as e:
            sweep.run_sweep(sweep.load_spec(spec_path), tmp_path / "out", client,
                            progress="none")
    assert str(e.value) == (f"the dask scheduler at {address} has no worker (none joined "
                            f"within 1 s): start `dask worker {address}` (README, \"Sweeps on "
                            f"dask\")")


def test_a_missing_package_on_the_cluster_is_named_with_the_fix():
    assert "this checkout's venv" in sweep.lost_task_hint(
        ModuleNotFoundError("No module named 'fmpy'"))
    assert "PYTHONPATH set to it" in sweep.lost_task_hint(
        ModuleNotFoundError("No module named 'demo'"))
    assert sweep.lost_task_hint(RuntimeError("a task failed")) == ""


def test_a_scheduler_that_cannot_be_reached_is_named_in_a_line(spec_path, tmp_path):
    """A wrong or unreachable --scheduler took dask's 30 s and a 56-line
    traceback, exit 1 (as for failed runs). A refused connection or an
    unknown host is now one line at once, naming the address and the
    cause, exit 3."""
    for address, cause in (("tcp://127.0.0.1:1", "connection refused (no scheduler listens "
                                                 "on port 1 of 127.0.0.1"),
                           ("tcp://nosuchhost.invalid:8786", "host 'nosuchhost.invalid' not "
                                                             "found")):
        with pytest.raises(sweep.ClusterError) as e, sweep.make_client(address, None):
            pass
        assert str(e.value).startswith(f"cannot reach the dask scheduler at {address}: {cause}"), \
            str(e.value)
    started = time.monotonic()
    done = subprocess.run(
        [sys.executable, "-m", "demo.sweep", str(spec_path), "--out", str(tmp_path / "out"),
         "--scheduler", "tcp://127.0.0.1:1", "--progress", "none", "--no-report"],
        cwd=REPO_ROOT, capture_output=True, text=True, timeout=300,
        env={**os.environ, "PYTHONPATH": str(REPO_ROOT)})
    assert done.returncode == 3, done.stderr
    assert done.stderr.startswith("cannot reach the dask scheduler at tcp://127.0.0.1:1: "
                                  "connection refused") and done.stderr.count("\n") == 1, \
        done.stderr
    assert time.monotonic() - started < 20


def test_a_sweep_on_a_scheduler_with_two_workers(spec_path, reference_table, dask_cluster,
                                                 tmp_path):
    env = {**os.environ, "PYTHONPATH": str(REPO_ROOT)}
    done = subprocess.run(
        [sys.executable, "-m", "demo.sweep", str(spec_path), "--out", str(tmp_path),
         "--scheduler", dask_cluster, "--progress", "lines", "--no-report"],
        cwd=REPO_ROOT, env=env, capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr
    assert "dask: 2 workers" in done.stdout
    assert f"sweep small: {RUNS}/{RUNS} runs (100 %)" in done.stdout, done.stdout
    rows = rows_of(tmp_path)
    assert len({r["worker"] for r in rows}) == 2
    assert results(rows) == results(reference_table)


def test_killing_a_worker_mid_sweep_loses_and_duplicates_no_run(spec_path, reference_table,
                                                               dask_cluster, tmp_path,
                                                               monkeypatch):
    from distributed import Client

    # Tasks of two runs (the default would give eight runs on two workers
    # a task each): the killed worker loses a task of several runs, which
    # another worker runs whole.
    def in_pairs(runs, workers, runs_per_task):
        return [runs[i:i + 2] for i in range(0, len(runs), 2)]

    monkeypatch.setattr(sweep, "batches", in_pairs)
    killed = {}
    with Client(dask_cluster, timeout="30s") as client:
        client.wait_for_workers(2, timeout=60)
        pids = client.run(os.getpid)

        def kill_one(row, done):
            if not killed and row["worker"] in pids:
                # The other worker process: it is running or about to run a task.
                victim = next(a for a in pids if a != row["worker"])
                os.kill(pids[victim], signal.SIGKILL)
                killed.update(address=victim, after=done)

        summary = sweep.run_sweep(sweep.load_spec(spec_path), tmp_path, client,
                                  progress="none", on_row=kill_one)
        # The nanny restarts the worker, for the next test's sake.
        client.wait_for_workers(2, timeout=60)
    assert killed and killed["after"] < RUNS, killed
    assert summary["executed"] == RUNS and summary["failed"] == 0, summary
    rows = rows_of(tmp_path)
    assert [r["run"] for r in rows] == list(range(RUNS))
    assert results(rows) == results(reference_table)


def test_a_lone_worker_killed_mid_sweep_loses_no_run(spec_path, reference_table, tmp_path,
                                                    monkeypatch):
    """With one worker, the FMUs scattered to it die with it: the tasks left
    were lost ("already forgotten") until the sweep learnt to scatter them
    again and resend the tasks to the worker the nanny restarts."""
    from distributed import Client

    monkeypatch.setattr(sweep, "batches",
                        lambda runs, workers, size: [runs[i:i + 2] for i in range(0, len(runs), 2)])
    env = {**os.environ, "PYTHONPATH": str(REPO_ROOT)}
    (tmp_path / "cluster").mkdir()
    killed = {}
    with cluster(tmp_path / "cluster", 1, env, env, REPO_ROOT) as address, \
            Client(address, timeout="30s") as client:
        client.wait_for_workers(1, timeout=60)
        pids = client.run(os.getpid)

        def kill_it(row, done):
            if not killed:
                os.kill(next(iter(pids.values())), signal.SIGKILL)
                killed.update(after=done)

        summary = sweep.run_sweep(sweep.load_spec(spec_path), tmp_path / "out", client,
                                  progress="none", on_row=kill_it)
    assert killed and killed["after"] < RUNS, killed
    assert summary["lost"] == 0 and summary["executed"] == RUNS, summary
    rows = rows_of(tmp_path / "out")
    assert [r["run"] for r in rows] == list(range(RUNS))
    assert results(rows) == results(reference_table)


def test_a_run_that_timed_out_is_run_again(spec_path, reference_table, tmp_path):
    """A run over the spec's timeout is a row saying so (a loaded machine,
    not the run, may be why); the next invocation runs it again, and its
    result replaces that row."""
    import pyarrow.parquet as pq

    spec = sweep.load_spec(spec_path)
    runs, fmus = sweep.expand(spec)
    data = {digest: path.read_bytes() for digest, path in fmus.items()}
    slow = copy.deepcopy(runs[3])
    slow.scenario["duration"] = 600.0  # 3 s of the master at least
    # In a task of three runs: the slow one times out alone (the others take
    # about 15 ms each), the next one runs on in a new master process.
    before, row, after = sweep.execute_runs([runs[2], slow, runs[4]], data, timeout=0.5)
    assert row["status"] == "timeout" and row["key"] == runs[3].key, row
    assert row["error"] == "no result within 0.5 s"
    assert (before["status"], after["status"]) == ("ok", "ok"), (before, after)
    assert results([before, after]) == results([reference_table[2], reference_table[4]])
    table = [dict(r) for r in reference_table]
    table[3] = row
    pq.write_table(sweep._rows_to_table(table, spec), sweep.table_path(tmp_path, "small"))
    summary = local_sweep(spec_path, tmp_path, workers=1)
    assert (summary["executed"], summary["skipped"], summary["timeouts"]) == (1, RUNS - 1, 0)
    assert results(rows_of(tmp_path)) == results(reference_table)


def test_a_stale_table_is_not_mixed_with_new_runs(spec_path, reference_table, tmp_path):
    """A table made by another spec (or other FMUs) is refused, not extended."""
    import pyarrow as pa
    import pyarrow.parquet as pq

    stale = [dict(r, key="0" * 32) for r in reference_table[:1]]
    pq.write_table(pa.Table.from_pylist(stale), tmp_path / "small.parquet")
    with pytest.raises(sweep.StaleTable, match="--restart"):
        sweep.run_sweep(sweep.load_spec(spec_path), tmp_path, client=None)


def test_spec_errors_name_the_file_and_line(tmp_path):
    bad = tmp_path / "bad.toml"
    bad.write_text(SPEC.replace('duration = "= 0.2 + 2 / frequency"',
                                'duration = "= 0.2 + 2 / frequncy"'))
    runs = None
    with pytest.raises(sweep.SpecError) as e:
        runs = sweep.expand(sweep.load_spec(bad))
    assert runs is None
    line = SPEC.splitlines().index('duration = "= 0.2 + 2 / frequency"') + 1
    assert str(e.value).startswith(f"{bad}:{line}: "), str(e.value)
    assert "unknown name 'frequncy'" in str(e.value)
    bad.write_text("study = 'x'\n[template]\nduration = = 1.0\nstep = 1e-4\n")
    with pytest.raises(sweep.SpecError, match=rf"^{bad}:3:12: Invalid value$"):
        sweep.load_spec(bad)
    bad.write_text("study = 'x'\n[template]\nduration = 1.0\n[[variable]]\nname = 'f'\n"
                   "valuess = [1.0]\n")
    with pytest.raises(sweep.SpecError, match=rf"^{bad}:6: variable 'f': unknown key 'valuess'"):
        sweep.load_spec(bad)
    # Inside a Monte Carlo group and the report's options too: a misspelt
    # `relative` would have left its parameters unperturbed, a misspelt limit
    # the report's default in force.
    typo = SPEC.replace("relative = 0.03", "relativ = 0.03")
    bad.write_text(typo)
    line = typo.splitlines().index("relativ = 0.03") + 1
    with pytest.raises(sweep.SpecError,
                       match=rf"^{bad}:{line}: monte_carlo.vary: unknown key 'relativ'"):
        sweep.load_spec(bad)
    bad.write_text(SPEC + "[report_options]\ntracking_limt = 0.02\n")
    line = len(SPEC.splitlines()) + 2
    with pytest.raises(sweep.SpecError,
                       match=rf"^{bad}:{line}: report_options: unknown key 'tracking_limt'"):
        sweep.load_spec(bad)


def test_a_variable_named_as_a_table_column_is_refused(tmp_path):
    """A variable `key` replaced every row's key (the table kept 0 rows of
    16), `run` the run index, `seed` the seed."""
    bad = tmp_path / "bad.toml"
    for name in ("key", "run", "seed", "status", "factor.x"):
        text = SPEC.replace('name = "amplitude"', f'name = "{name}"')
        bad.write_text(text)
        line = text.splitlines().index(f'name = "{name}"') + 1
        with pytest.raises(sweep.SpecError,
                           match=rf"^{bad}:{line}: variable '{re.escape(name)}': the table "
                                 rf"has a column of that name"):
            sweep.load_spec(bad)


def test_a_variable_named_as_a_metric_column_is_refused(tmp_path):
    """A variable `tracking_rms` was overwritten in every row by the run's
    metric of that name (and `coupling_x2_range_min` by one end of a range
    metric), and the table kept one of the two values without a word."""
    bad = tmp_path / "bad.toml"
    for name, clash in (
            ("tracking_rms", "the master's metric tracking_rms"),
            ("samples", "the master's metric samples"),
            ("y_error_max", "the master's metric y_error_max"),
            ("coupling_x2_range_min", "the lower end of the master's range metric "
                                      "coupling_x2_range"),
            ("theta_error_range_max", "the upper end of the master's range metric "
                                      "theta_error_range")):
        text = SPEC.replace('name = "amplitude"', f'name = "{name}"').replace(
            '"= amplitude"', f'"= {name}"')
        bad.write_text(text)
        line = text.splitlines().index(f'name = "{name}"') + 1
        with pytest.raises(sweep.SpecError) as e:
            sweep.load_spec(bad)
        assert str(e.value) == (f"{bad}:{line}: variable '{name}': the table has a metric "
                                f"column of that name ({clash}); choose another name")


def test_the_metric_definitions_are_the_masters_metrics():
    """The names a variable may not take and the units the table carries come
    from the master (`piezo-cosim metrics`, whose own test ties the list to
    what it computes): every metric a run writes is there, with its unit."""
    definitions = sweep.metric_definitions()
    assert definitions == master.metrics()
    assert definitions["coupling_x2_range"] == {
        "unit": "um", "range": True, "description": "[min, max] of e_x2 in a y run"}
    assert definitions["tracking_rms"]["unit"] == {"x": "um", "y": "um", "theta": "rad"}
    assert sweep.metric_columns_of("coupling_x2_range") == ["coupling_x2_range_min",
                                                           "coupling_x2_range_max"]
    assert sweep.metric_columns_of("coupling_x2_span") == ["coupling_x2_span"]


#: A spec with every key of the format written, one to a line.
FULL_SPEC = SPEC.replace('seed = 7\n', 'title = "A small study"\nreport = "none"\nseed = 7\n'
                                       'timeout = 60\nruns_per_task = 5\n').replace(
    "[monte_carlo]\n", '[monte_carlo]\ninstance = "plant"\n').replace(
    "[variable.values.off]\n", "[variable.values.off]\nvars = { k = 1.0 }\n") + """
[[exclude]]
frequency = 10.0
decoupling = "on"

[report_options]
tracking_limit = 0.05
reduction_limit = 2.0
"""

#: Values of the wrong type for a key, as TOML writes them.
WRONG_VALUES = ('"text"', "-1", "2.5", "true", "[]", "[1.0, 2.0]", '["a"]', "{ a = 1.0 }",
                "nan")


def test_every_key_of_the_spec_format_refuses_a_wrong_type_at_its_line(tmp_path):
    """Each `key = value` line of a spec with every key of the format, its
    value replaced by each of WRONG_VALUES: the spec is read and expanded
    as before, or refused as a SpecError that names the file and a line;
    a value of another type than the line's own, at that line (a variable's
    value: at its name's line). A string where numbers were expected, a
    negative or fractional count or seed, a boolean where a number was
    expected, a table where an array was, ended in Python tracebacks, or
    were taken (`seed = true`, `samples = 2.5`)."""
    import tomllib

    def toml_type(value: str) -> type:
        return type(tomllib.loads(f"x = {value}")["x"])

    bad = tmp_path / "bad.toml"
    lines = FULL_SPEC.splitlines()
    sweep.expand(sweep.load_spec(_written(bad, FULL_SPEC)))
    refused, accepted, table = 0, [], ""
    for number, line in enumerate(lines, 1):
        header = re.match(r"^\[+([^\]]+)\]+$", line)
        if header:
            table = header.group(1)
        setting = re.match(r"^([\w.\"\[\]]+) = (.*)$", line)
        if not setting:
            continue
        key, own = setting.groups()
        for value in WRONG_VALUES:
            text = "\n".join(lines[:number - 1] + [f"{key} = {value}"] + lines[number:])
            try:
                sweep.expand(sweep.load_spec(_written(bad, text)))
                # Taken: only a value of the line's own kind may be (a
                # number for a number), or one in the scenario template,
                # which the master checks (test_a_template_value_of_the_wrong_
                # type_is_named_by_its_key).
                numbers = {toml_type(value), toml_type(own)} <= {int, float}
                if not (table.startswith("template") or numbers
                        or toml_type(value) is toml_type(own)):
                    accepted.append(f"{line!r} -> {value}")
            except sweep.SpecError as e:
                refused += 1
                where = re.match(rf"{re.escape(str(bad))}:(\d+): ", str(e))
                assert where, (line, value, str(e))
                if toml_type(value) is toml_type(own):
                    # A value of the right type may fail where it is used
                    # (a variable renamed: the rule that excludes by it).
                    continue
                named = int(where.group(1))
                if key == "values":
                    name_line = max(n for n, row in enumerate(lines[:number], 1)
                                    if row.startswith("name = "))
                    assert named in (number, name_line), (line, value, str(e))
                else:
                    assert named == number, (line, value, str(e))
    assert not accepted, "taken though of another kind:\n" + "\n".join(accepted)
    assert refused > 100, refused


#: (the template's text, replaced by, the message after `file:line: `).
TEMPLATE_VALUES = {
    "metrics": ('driven = "y"', "driven = true",
                "template metrics.driven: invalid type: boolean `true`, expected one of `y`, `x`, "
                "`theta`, `xy`, `ytheta` (in the scenario of frequency = 5.0, decoupling = off, "
                "amplitude = 2.0)"),
    "signal": ("offset = 6.0\nsines", 'offset = "text"\nsines',
               'template signal."controller.y_ref".offset: invalid type: string "text", expected '
               "f64 (in the scenario of frequency = 5.0, decoupling = off, amplitude = 2.0)"),
    "parameter": ('"noise.enabled" = true }', '"noise.enabled" = true, "mode.x.damping" = "low" }',
                  'template fmu.plant.parameters."mode.x.damping": invalid type: string "low", '
                  "expected a number, or true or false (in the scenario of frequency = 5.0, "
                  "decoupling = off, amplitude = 2.0)"),
    # A named case's patch, not the template, gives the value.
    "patch": ("parameters = {{ decoupling = true }}".replace("{{", "{").replace("}}", "}"),
              'parameters = { decoupling = "yes" }',
              'decoupling = on: patch fmu.controller.parameters.decoupling: invalid type: '
              'string "yes", expected a number, or true or false'),
    # A parameter the Monte Carlo perturbs is read before the master sees it.
    "perturbed": ('"noise.enabled" = true }', '"noise.enabled" = true, "amplifier.gain" = "high" }',
                  "plant.amplifier.gain = 'high': the Monte Carlo perturbs it, so it must be a "
                  "number"),
}


#: SPEC without its Monte Carlo study, whose seed_parameter would set
#: noise.seed over the template's.
GRID_SPEC = re.sub(r"\[monte_carlo\].*?(?=\n\[template\])", "", SPEC, flags=re.DOTALL)
TEMPLATE_VALUES["seed"] = (
    '"noise.enabled" = true }', '"noise.enabled" = true, "noise.seed" = "s" }',
    'template fmu.plant.parameters."noise.seed": invalid type: string "s", expected a number, '
    "or true or false (in the scenario of frequency = 5.0, decoupling = off, "
    "amplitude = 2.0)")


@pytest.mark.parametrize("case", TEMPLATE_VALUES)
def test_a_template_value_of_the_wrong_type_is_named_by_its_key(tmp_path, case):
    """The template goes to the master as JSON, which reads it: a value it
    cannot read is named by its key and its line in the spec, not by a
    column of the JSON the spec's reader never sees (nor by a traceback, as
    a perturbed parameter's string was)."""
    old, new, message = TEMPLATE_VALUES[case]
    spec = GRID_SPEC if case == "seed" else SPEC
    assert "[monte_carlo]" not in GRID_SPEC and "[template]" in GRID_SPEC
    text = spec.replace(old, new)
    assert text != spec
    bad = _written(tmp_path / "bad.toml", text)
    line = next(n for n, row in enumerate(text.splitlines(), 1) if new.split("\n")[0] in row)
    done = subprocess.run([sys.executable, "-m", "demo.sweep", str(bad), "--out",
                           str(tmp_path / "out")], capture_output=True, text=True,
                          cwd=REPO_ROOT, timeout=120)
    assert done.returncode == 2, done.stderr
    assert done.stderr.strip() == f"{bad}:{line}: {message}", done.stderr


def _written(path: Path, text: str) -> Path:
    path.write_text(text)
    return path


def test_wrong_types_in_a_spec_are_named_with_file_line_and_problem(tmp_path):
    """The cases of the issue, and the tables given where arrays are
    expected (and back): each message names the file, the line and what the
    key takes."""
    bad = tmp_path / "bad.toml"
    mc_group = "[[monte_carlo.vary]]\nmatch = '^amplifier\\.gain$'\nrelative = 0.03\n"
    assert mc_group in SPEC
    for text, at, problem in (
            (SPEC.replace("values = [5.0, 10.0]", 'values = "5.0, 10.0"'),
             'values = "5.0, 10.0"',
             "variable 'frequency': values '5.0, 10.0': a non-empty array of numbers or "
             "names, or a table of cases"),
            (SPEC.replace("samples = 2", "samples = -1"), "samples = -1",
             "monte_carlo.samples -1: a whole number, at least 1"),
            (SPEC.replace("samples = 2", "samples = 2.5"), "samples = 2.5",
             "monte_carlo.samples 2.5: a whole number, at least 1"),
            (SPEC.replace("seed = 7", "seed = -7"), "seed = -7",
             "seed -7: a whole number, at least 0"),
            (SPEC.replace("seed = 7", "seed = 7.5"), "seed = 7.5",
             "seed 7.5: a whole number, at least 0"),
            (SPEC.replace("seed = 7", "seed = 7\nruns_per_task = 2.5"), "runs_per_task = 2.5",
             "runs_per_task 2.5: a whole number, at least 1"),
            (SPEC.replace("relative = 0.03", "relative = true"), "relative = true",
             "monte_carlo.vary: relative true: a number in [0, 1), the half width of the "
             "factors' range"),
            (SPEC.replace("seed = 7", "seed = 7\ntimeout = true"), "timeout = true",
             "timeout true: a positive number of seconds"),
            (SPEC + "[report_options]\ntracking_limit = true\n", "tracking_limit = true",
             "report_options.tracking_limit true: a positive number"),
            (SPEC + '[exclude]\nfrequency = 5.0\n', "[exclude]",
             "exclude (a table): an array of tables, each an [[exclude]] of variable = value"),
            (SPEC + '[[exclude]]\nfrequency = 7.0\n', "frequency = 7.0",
             "exclude: frequency 7.0 is not one of the variable's values (5.0, 10.0)"),
            (SPEC.replace(mc_group, "").replace("[[monte_carlo.vary]]", "[monte_carlo.vary]"),
             "[monte_carlo.vary]",
             "monte_carlo.vary (a table): an array of tables, each a [[monte_carlo.vary]] "
             "with match and relative"),
            (SPEC.replace("[monte_carlo]", "[[monte_carlo]]"), "[[monte_carlo]]",
             "monte_carlo (an array of tables): a table ([monte_carlo]) with samples, "
             "instance, vary, seed_parameter"),
            (SPEC.replace("[variable.values.off]\n", "[variable.values.off]\nvars = [1.0]\n"),
             "vars = [1.0]", "case decoupling.off: vars (an array): a table of numbers by name"),
            (SPEC.replace("[variable.values.off]\n",
                          "[variable.values.off]\nvars = { k = 'a' }\n"),
             "vars = { k = 'a' }", "case decoupling.off: vars.k 'a': a finite number"),
            (SPEC.replace("{ decoupling = true }", "[true]"),
             "patch.fmu.controller.parameters = [true]",
             "case decoupling.on: patch.fmu.controller.parameters (an array): a table of "
             "values by FMI name"),
            (SPEC.replace(f'path = "{CONTROLLER}"', "path = 3"), "path = 3",
             "template.fmu.controller.path 3: a file name in quotes"),
            (SPEC.replace('seed_parameter = "noise.seed"', "seed_parameter = 1"),
             "seed_parameter = 1",
             "monte_carlo.seed_parameter 1: a parameter's FMI name in quotes"),
            (SPEC.replace('study = "small"', "study = 3"), "study = 3",
             "study 3: a name in quotes (letters, digits, '_', '-', '.')")):
        bad.write_text(text)
        line = text.splitlines().index(at) + 1
        with pytest.raises(sweep.SpecError) as e:
            sweep.expand(sweep.load_spec(bad))
        assert str(e.value) == f"{bad}:{line}: {problem}"


def test_a_spec_error_ends_the_command_with_status_2_and_no_traceback(tmp_path):
    bad = tmp_path / "bad.toml"
    text = SPEC.replace("samples = 2", "samples = 2.5")
    bad.write_text(text)
    done = subprocess.run([sys.executable, "-m", "demo.sweep", str(bad), "--out",
                           str(tmp_path / "out"), "--no-report"], cwd=REPO_ROOT,
                          capture_output=True, text=True, timeout=120)
    line = text.splitlines().index("samples = 2.5") + 1
    assert (done.returncode, done.stdout) == (2, ""), done
    assert done.stderr == f"{bad}:{line}: monte_carlo.samples 2.5: a whole number, at least 1\n"
    assert not (tmp_path / "out").exists()


def test_restart_keeps_the_table_when_the_spec_does_not_run(spec_path, reference_table,
                                                            tmp_path):
    """`--restart` with a misspelt parameter deleted the table, then refused."""
    import pyarrow as pa
    import pyarrow.parquet as pq

    table = tmp_path / "small.parquet"
    pq.write_table(pa.Table.from_pylist(reference_table), table)
    bad = tmp_path / "bad.toml"
    bad.write_text(SPEC.replace('"noise.enabled" = true', '"noise.enabld" = true'))
    with pytest.raises(sweep.SpecError, match="has no variable"):
        sweep.run_sweep(sweep.load_spec(bad), tmp_path, client=None, restart=True)
    assert pq.read_table(table).num_rows == len(reference_table)


def test_grid_values_that_make_no_run_of_their_own_are_refused(tmp_path):
    """An unused variable collapsed 16 runs into 4 rows, each claiming one of
    its values; a NaN value failed every run with the master's JSON error."""
    bad = tmp_path / "bad.toml"
    text = SPEC + '[[variable]]\nname = "unused"\nvalues = [1.0, 2.0]\n'
    bad.write_text(text)
    with pytest.raises(sweep.SpecError, match=r"two points of the grid make the same run "
                                              r"\(unused = 1.0 and 2.0\)"):
        sweep.expand(sweep.load_spec(bad))
    text = SPEC.replace("values = [2.0]", "values = [2.0, nan]")
    bad.write_text(text)
    line = text.splitlines().index('name = "amplitude"') + 1
    with pytest.raises(sweep.SpecError, match=rf"^{bad}:{line}: variable 'amplitude': value nan "
                                              rf"is not a finite number or a name"):
        sweep.load_spec(bad)


def test_a_report_the_spec_cannot_feed_is_refused(tmp_path):
    """`report = "envelop"` was taken silently, and "robustness" on a spec
    without its variables crashed after every run, and every later report
    into the same folder."""
    bad = tmp_path / "bad.toml"
    for report, problem in (
            ("envelop", "report 'envelop': one of envelope, none, robustness"),
            ("robustness", "report 'robustness' reads the variables axis, decoupling; the "
                           "spec has no axis")):
        text = f'report = "{report}"\n' + SPEC
        bad.write_text(text)
        with pytest.raises(sweep.SpecError, match=rf"^{bad}:1: {re.escape(problem)}"):
            sweep.load_spec(bad)


def test_a_parameter_in_two_monte_carlo_groups_is_refused(tmp_path):
    """Overlapping groups gave the parameter the last group's range silently
    (+-1 % instead of the +-50 % meant)."""
    bad = tmp_path / "bad.toml"
    text = SPEC.replace("match = '^amplifier\\.gain$'", "match = '^pzt\\[1\\]\\.A$'")
    assert text != SPEC
    bad.write_text(text)
    with pytest.raises(sweep.SpecError, match=r"matches pzt\[1\]\.A, which .* matches too"):
        sweep.expand(sweep.load_spec(bad))


def test_a_range_metric_keeps_the_masters_largest_error():
    """`y_error_range` as `y_error_min`/`y_error_max` overwrote the master's
    `y_error_max` (the largest |e_y|) with the range's upper end."""
    row = sweep.flatten_metrics({"y_error_max": 0.03022, "y_error_range": [-0.03022, 0.02444]})
    assert row == {"y_error_max": 0.03022, "y_error_range_min": -0.03022,
                   "y_error_range_max": 0.02444}


def test_runs_go_to_tasks_in_order_and_keep_every_worker_busy(tmp_path):
    runs = list(range(1000))
    tasks = sweep.batches(runs, workers=2, runs_per_task=10)
    assert [len(t) for t in tasks] == [10] * 100
    assert [r for t in tasks for r in t] == runs
    # Few runs: at least four tasks a worker, down to one run a task.
    assert [len(t) for t in sweep.batches(runs[:8], workers=2, runs_per_task=10)] == [1] * 8
    assert [len(t) for t in sweep.batches(runs[:50], workers=2, runs_per_task=10)] == [7] * 7 + [1]
    assert [len(t) for t in sweep.batches(runs[:30], workers=1, runs_per_task=1)] == [1] * 30
    assert sweep.batches([], workers=2, runs_per_task=10) == []
    spec = tmp_path / "s.toml"
    spec.write_text("study = 'x'\nruns_per_task = 0\n[template]\nduration = 1.0\n")
    with pytest.raises(sweep.SpecError, match=rf"^{spec}:2: runs_per_task 0: a whole number"):
        sweep.load_spec(spec)
    spec.write_text("study = 'x'\nruns_per_task = 3\n[template]\nduration = 1.0\n")
    assert sweep.load_spec(spec).runs_per_task == 3


def test_expressions_accept_arithmetic_only():
    assert sweep.evaluate("max(1 / f, 0.5) + 2 ** 2", {"f": 4.0}) == 4.5
    for text in ("__import__('os')", "f.real", "[1][0]", "open('x')"):
        with pytest.raises(ValueError):
            sweep.evaluate(text, {"f": 1.0})


def test_the_default_robustness_study_turns_the_rotation_about_xs_rotation_home():
    """Table 3's rotation run, as the demo and the `stage` identification
    run it, turns about x at half its stroke (seed 000 §3.2; one source:
    demo/experiment_conditions.json). About x = 0 the commands saturate on
    most samples and the study's theta figures would measure that."""
    import tomllib

    spec = tomllib.loads((REPO_ROOT / "demo" / "sweeps" / "robustness.toml").read_text())
    axis = next(v for v in spec["variable"] if v["name"] == "axis")
    rotation = axis["values"]["theta"]["patch"]["signal"]["controller.x_ref"]
    conditions = json.loads((REPO_ROOT / "demo" / "experiment_conditions.json").read_text())
    assert rotation["offset"] == conditions["homes_um"]["rotation"]["x"]


def test_the_robustness_report_says_whether_commands_saturated():
    """A figure from runs whose commands sat at their limit measures the
    command range, not the plant: the report names those runs, or says that
    there were none."""
    from demo.sweep_report import saturation_summary

    def row(axis, decoupling, saturation):
        return {"axis": axis, "decoupling": decoupling, "command_saturation": saturation}

    clean = [row("x", "on", 0.0), row("theta", "off", 0.005)]
    assert saturation_summary(clean).startswith("No run's commands sat at a limit")
    saturated = clean + [row("theta", "on", 0.6), row("theta", "on", 0.0)]
    summary = saturation_summary(saturated)
    assert "theta, decoupling on: 1 of 2 runs" in summary, summary
    assert "theta, decoupling off" not in summary and "x, decoupling" not in summary, summary
    # By the values of a further variable of the spec, when it takes several.
    split = [dict(r, held=h) for r in saturated for h in (0.0, 3.0)]
    split[-1]["command_saturation"] = 0.0  # theta, on, 0.0 runs; the 3.0 twin does not
    summary = saturation_summary(split, ["held"])
    assert "held = 0.0, theta, decoupling on: 1 of 2 runs" in summary, summary
    assert "held = 3.0, theta, decoupling on: 1 of 2 runs" in summary, summary


def _variables_spec(*names: str) -> str:
    """A spec's text as a table's metadata keeps it, for the reports: they
    read its variables' names from it."""
    return "".join(f'[[variable]]\nname = "{name}"\nvalues = [0.0]\n' for name in names)


def _report_table(lines: list[str], first: str) -> list[dict]:
    """The Markdown table of a report's `lines` whose header starts with
    `| first |`, as rows by column name."""
    start = next(i for i, line in enumerate(lines) if line.startswith(f"| {first} |"))
    header = [cell.strip() for cell in lines[start].strip("|").split("|")]
    rows = []
    for line in lines[start + 2:]:
        if not line.startswith("|"):
            break
        rows.append(dict(zip(header, (cell.strip() for cell in line.strip("|").split("|")))))
    return rows


def test_the_robustness_report_keeps_a_further_variables_runs_apart(tmp_path):
    """A Monte Carlo spec with a variable the report does not read (`held`,
    two values) gave one row per figure, paired by (axis, sample) alone:
    the held = 3 runs overwrote the held = 0 ones and P5/P50/P95 were theirs
    alone, without a word. Each value now has its rows, and the samples
    they count add up to the table's runs."""
    from demo.sweep_report import COUPLINGS, fmt, percentiles, robustness_section

    rows = []
    for held in (0.0, 3.0):
        for axis in ("y", "x"):
            for sample in range(12):
                for decoupling in ("off", "on"):
                    gain = (1 + held) * (1 + 0.1 * sample) * (
                        3 + sample if decoupling == "off" else 1)
                    rows.append({"run": len(rows), "status": "ok", "held": held, "axis": axis,
                                 "decoupling": decoupling, "sample": sample,
                                 "factor.a": 0.9 + 0.015 * sample, "tracking_rms": 0.01 * gain,
                                 "coupling_x2_span": gain, "coupling_x3_span": 2 * gain,
                                 "coupling_y_span": gain, "command_saturation": 0.0,
                                 "wall_s": 0.01, "worker": "w"})
    meta = {"spec": _variables_spec("held", "axis", "decoupling"), "title": "t"}
    lines = robustness_section(rows, meta, tmp_path)
    table = _report_table(lines, "held")
    assert {row["held"] for row in table} == {"0.0", "3.0"}, table
    # Every run is counted once: the tracking figures count the runs with
    # decoupling on, each coupling's reduction pairs one with its twin
    # without.
    on = [r for r in rows if r["decoupling"] == "on"]
    assert sum(int(row["samples"]) for row in table
               if row["figure"].endswith("tracking RMS")) == len(on)
    assert sum(int(row["samples"]) for row in table if row["figure"].endswith("reduction")) \
        == sum(len(COUPLINGS[r["axis"]]) for r in on)
    for held in (0.0, 3.0):
        row = next(row for row in table
                   if row["held"] == str(held) and row["figure"] == "y tracking RMS")
        values = [r["tracking_rms"] for r in on if r["held"] == held and r["axis"] == "y"]
        assert row["P50"] == fmt(percentiles(values)[1]), (held, row)
    assert (tmp_path / "robustness.png").is_file()


def test_the_envelope_report_keeps_a_further_variables_runs_apart(tmp_path, monkeypatch):
    """The envelope paired runs by (stage, method, axis, held, amplitude,
    frequency): a spec with a further variable (`kp`, two values) had each
    kp = 0.05 run replaced by its kp = 0.5 twin. Each value now has its row
    and its heatmaps, and the points they count add up to the table; each
    figure's title says its value (a loop over the couplings overwrote it,
    and titled the coupling figure by its last panel, "x3 from y")."""
    from matplotlib.figure import Figure

    from demo.sweep_report import envelope_section

    titles = []
    save = Figure.savefig
    monkeypatch.setattr(Figure, "savefig", lambda figure, *args, **kwargs: (
        titles.append(figure.get_suptitle()), save(figure, *args, **kwargs)))

    rows = []
    for kp in (0.05, 0.5):
        for frequency in (1.0, 10.0):
            for decoupling in ("off", "on"):
                span = 2.0 if decoupling == "off" else (0.1 if kp == 0.05 else 1.5)
                rows.append({"run": len(rows), "status": "ok", "stage": "flexure",
                             "method": "m", "axis": "y", "held": 0.0, "amplitude": 0.1,
                             "frequency": frequency, "kp": kp, "decoupling": decoupling,
                             "tracking_rms": 0.01, "demand_span": 2.0,
                             "coupling_x2_span": span, "coupling_x3_span": span,
                             "simulated_s": 1.0, "wall_s": 0.01, "worker": "w"})
    meta = {"spec": _variables_spec("stage", "method", "axis", "decoupling", "held",
                                    "amplitude", "frequency", "kp"), "title": "t"}
    lines = envelope_section(rows, meta, tmp_path)
    table = _report_table(lines, "stage")
    assert [(row["kp"], row["points holding"]) for row in table] == [("0.05", "2/2"),
                                                                     ("0.5", "0/2")], table
    assert 2 * sum(int(row["points holding"].split("/")[1]) for row in table) == len(rows)
    for kp in ("0.05", "0.5"):
        assert (tmp_path / f"envelope_flexure_m_kp-{kp}_coupling.png").is_file(), kp
    assert len(titles) == 4 and all("kp" in title for title in titles), titles
    assert not any("x3 from y" in title for title in titles), titles


def test_a_report_refuses_to_show_one_run_in_place_of_another():
    """The reports pair runs by every variable the spec has; two rows that
    still meet there would be one shown for both, which is refused."""
    from demo.sweep_report import paired_runs

    row = {"status": "ok", "axis": "y", "sample": 0, "decoupling": "on"}
    assert paired_runs([row, dict(row, decoupling="off")], ["axis", "sample"]) == {
        ("y", 0): {"on": row, "off": dict(row, decoupling="off")}}
    with pytest.raises(ValueError, match="axis = y, sample = 0, decoupling on: the report "
                                         "would show one of them"):
        paired_runs([row, dict(row)], ["axis", "sample"])


def test_a_nominal_value_outside_its_range_is_refused_not_held_at_the_bound(spec_path,
                                                                            tmp_path):
    """A Monte Carlo perturbs the template's value; one the FMU would refuse
    (a gain of -1) was held at the bound of its declared range before, and
    the run reported a value the spec never gave. It is refused, by name."""
    bad = tmp_path / "bad.toml"
    text = spec_path.read_text().replace('parameters = { "noise.enabled" = true }',
                                         'parameters = { "noise.enabled" = true, '
                                         '"amplifier.gain" = -1.0 }')
    assert "amplifier.gain" in text
    bad.write_text(text)
    line = next(i for i, row in enumerate(text.splitlines(), 1) if "amplifier.gain" in row
                and "-1.0" in row)
    with pytest.raises(sweep.SpecError) as e:
        sweep.expand(sweep.load_spec(bad))
    assert str(e.value) == (f"{bad}:{line}: plant.amplifier.gain = -1 (the nominal value the "
                            "Monte Carlo perturbs) is outside its declared range (0, inf]")
    # From a parameter set, the set's file and line are named.
    parameter_set = tmp_path / "plant.json"
    parameter_set.write_text('{\n  "noise.rms": 0.001,\n  "amplifier.gain": -1.0\n}\n')
    bad.write_text(spec_path.read_text().replace(
        'parameters = { "noise.enabled" = true }',
        f'parameters = {{ "noise.enabled" = true }}\nparameter_sets = ["{parameter_set}"]'))
    with pytest.raises(sweep.SpecError) as e:
        sweep.expand(sweep.load_spec(bad))
    assert str(e.value).startswith(f"{parameter_set}:3: plant.amplifier.gain = -1 "), str(e.value)



def test_the_seed_column_is_the_seed_the_run_used(spec_path, tmp_path):
    """A Monte Carlo without seed_parameter wrote the seed it drew for each
    sample into the seed column though no parameter received it: a row run
    again with that seed gave another result (the run had used the
    template's noise.seed). The column is the plant's noise.seed in every
    run: drawn where seed_parameter gives it, the template's otherwise, and
    empty where the scenario sets none (the FMU's start value)."""
    def seeds(text: str) -> list[tuple]:
        runs = sweep.expand(sweep.load_spec(_written(tmp_path / "s.toml", text)))[0]
        return [(run.values["seed"], run.scenario["fmu"]["plant"]["parameters"].get("noise.seed"))
                for run in runs]

    drawn = seeds(SPEC)
    assert all(column == used for column, used in drawn), drawn
    assert len({column for column, _ in drawn}) == 2, "one seed per sample"
    unseeded = SPEC.replace('seed_parameter = "noise.seed"\n', "")
    assert unseeded != SPEC
    assert {column for column, _ in seeds(unseeded)} == {None}
    fixed = unseeded.replace('"noise.enabled" = true }', '"noise.enabled" = true, '
                                                        '"noise.seed" = 5 }')
    assert fixed != unseeded
    assert set(seeds(fixed)) == {(5, 5)}
    # The samples' factors do not depend on where the seed goes.
    factors = [{k: v for k, v in run.values.items() if k.startswith("factor.")}
               for text in (SPEC, unseeded)
               for run in sweep.expand(sweep.load_spec(_written(tmp_path / "s.toml", text)))[0]]
    assert factors[:RUNS] == factors[RUNS:]


def test_a_grid_extended_into_its_table_numbers_its_runs_as_a_fresh_sweep(spec_path,
                                                                          reference_out,
                                                                          tmp_path):
    """A frequency added to the grid and the sweep resumed into the same
    folder kept the old rows' run numbers, which the new expansion gives to
    other runs: 0, 1, 2, 3, 3, 4, 5, 7 in the grid of the issue. A kept row
    is now the row a fresh sweep of the spec as it is writes, number
    included; only wall_s, task_s and worker differ (EXECUTION_COLUMNS)."""
    import shutil

    extended = _written(tmp_path / "small.toml",
                        spec_path.read_text().replace("values = [5.0, 10.0]",
                                                      "values = [5.0, 7.0, 10.0]"))
    resumed, fresh = tmp_path / "resumed", tmp_path / "fresh"
    resumed.mkdir()
    shutil.copy(sweep.table_path(reference_out, "small"), resumed)
    first, second = local_sweeps([(extended, resumed), (extended, fresh)])
    assert (first["executed"], first["skipped"]) == (RUNS // 2, RUNS), first
    assert second["executed"] == RUNS + RUNS // 2, second
    rows = rows_of(resumed)
    assert [r["run"] for r in rows] == list(range(RUNS + RUNS // 2))
    assert results(rows) == results(rows_of(fresh))


def _kp_spec(values: str) -> str:
    """SPEC at one frequency, the controller's translation.kp swept over
    `values` (4 runs a value)."""
    text = SPEC.replace("values = [5.0, 10.0]", "values = [10.0]").replace(
        f'path = "{CONTROLLER}"\n',
        f'path = "{CONTROLLER}"\nparameters = {{ "translation.kp" = "= kp" }}\n')
    return text + f'[[variable]]\nname = "kp"\nvalues = {values}\n'


def test_every_value_of_every_variable_is_checked_before_any_run(tmp_path, monkeypatch):
    """The check ran one scenario per combination of named cases, so a grid
    value out of its parameter's range (kp = -5) went to the cluster and
    failed every run that had it. It is refused before any run, at the
    line of the variable's values, and the run checked for it differs from
    a checked one in that value alone."""
    text = _kp_spec("[0.05, -5.0]")
    bad = _written(tmp_path / "bad.toml", text)
    spec = sweep.load_spec(bad)
    runs, fmus = sweep.expand(spec)
    line = text.splitlines().index("values = [0.05, -5.0]") + 1
    with pytest.raises(sweep.SpecError) as e:
        sweep.check_scenarios(runs, fmus, spec)
    assert str(e.value).startswith(
        f"{bad}:{line}: kp = -5.0: the scenario does not run: controller: "), str(e.value)
    assert "translation.kp = -5 is outside its allowed range" in str(e.value), str(e.value)
    assert str(e.value).endswith("(in the scenario of frequency = 10.0, decoupling = 'off', "
                                 "amplitude = 2.0)"), str(e.value)
    # Every value of every variable is in a run checked, once or so each.
    grid = _written(tmp_path / "grid.toml", _kp_spec("[0.05, 0.1, 0.2]").replace(
        "values = [10.0]", "values = [5.0, 10.0, 20.0]").replace(
        "values = [2.0]", "values = [1.0, 2.0]"))
    spec = sweep.load_spec(grid)
    runs, fmus = sweep.expand(spec)
    checked = sweep.check_scenarios(runs, fmus, spec)
    values = {(v.name, getattr(value, "name", value)) for v in spec.variables
              for value in v.values}
    assert {(name, run.values[name]) for run in checked for name, _ in values} == values
    assert len(checked) == 2 + 2 + 2 + 1, "the cases' two runs, then one run a further value"


def test_a_table_keeps_its_runs_when_a_failed_value_is_fixed(tmp_path):
    """The rerun after fixing a value that failed refused the table ("4 of
    its 8 rows are not runs of ...: pass --restart"), which threw the good
    rows away too. The failed rows of the value no longer swept hold no
    result and leave the table; the rows that are still runs of the spec
    are kept, and only the new value runs. A run the spec no longer makes
    whose row holds a result still needs --restart, and the message says
    which and why."""
    bad = _written(tmp_path / "bad.toml", _kp_spec("[0.05, -5.0]"))
    fixed = _written(tmp_path / "fixed.toml", _kp_spec("[0.05, 5.0]"))
    narrowed = _written(tmp_path / "narrowed.toml", _kp_spec("[5.0]"))
    out = tmp_path / "out"
    # As an earlier version sent it: unchecked.
    first, second = local_sweeps([(bad, out), (fixed, out)], checked=True)
    assert (first["executed"], first["failed"]) == (8, 4), first
    assert (second["executed"], second["skipped"], second["dropped"]) == (4, 4, 4), second
    rows = rows_of(out)
    assert [(r["run"], r["status"]) for r in rows] == [(n, "ok") for n in range(8)]
    assert {r["kp"] for r in rows} == {0.05, 5.0}
    with pytest.raises(sweep.StaleTable) as e:
        sweep.run_sweep(sweep.load_spec(narrowed), out, client=None)
    assert str(e.value).startswith(
        f"{out / 'small.parquet'}: 4 of its 8 runs hold results of runs that {narrowed} no "
        f"longer makes (the first: frequency = 10.0, decoupling = 'off', amplitude = 2.0, "
        f"kp = 0.05, sample = 0; "), str(e.value)
    assert "pass --restart" in str(e.value)


def test_a_sweep_says_how_many_runs_before_sending_them_and_expands_once(
        spec_path, reference_out, tmp_path, monkeypatch, capsys):
    """A 500 x 200 grid never said how many runs it had before starting (in
    bar mode, not at all), and its spec was expanded twice, to check it and
    to run it (22 s each at 100,000 runs). The command says "N runs (M
    already in the table)" before sending any, and expands each spec once."""
    import shutil

    expanded = []
    expand = sweep.expand
    monkeypatch.setattr(sweep, "expand", lambda spec: expanded.append(spec.study) or expand(spec))
    extended = _written(tmp_path / "small.toml",
                        spec_path.read_text().replace("values = [5.0, 10.0]",
                                                      "values = [5.0, 7.0, 10.0]"))
    out = tmp_path / "out"
    out.mkdir()
    shutil.copy(sweep.table_path(reference_out, "small"), out)
    status = sweep.main([str(extended), "--out", str(out), "--workers", "1", "--progress", "bar",
                         "--no-report"])
    lines = capsys.readouterr().out.splitlines()
    assert status == 0, lines
    assert expanded == ["small"]
    count = lines.index(f"small: {RUNS + RUNS // 2} runs ({RUNS} already in the table)")
    done = next(n for n, line in enumerate(lines) if f"small: {RUNS // 2} runs executed" in line)
    assert count < done, lines


def _in_a_terminal(command: list[str], env: dict) -> tuple[int, str]:
    """`command` run with its stdout on a pseudo-terminal (its stderr
    discarded): its exit status and what it wrote there."""
    import pty

    control, terminal = pty.openpty()
    child = subprocess.Popen(command, cwd=REPO_ROOT, env=env, stdout=terminal,
                             stderr=subprocess.DEVNULL, stdin=subprocess.DEVNULL)
    os.close(terminal)
    chunks = []
    try:
        while True:
            try:
                chunk = os.read(control, 1 << 16)
            except OSError:  # EIO: the child closed the terminal
                break
            if not chunk:
                break
            chunks.append(chunk)
    finally:
        os.close(control)
        status = child.wait(timeout=300)
    return status, b"".join(chunks).decode(errors="replace")


def test_the_summary_starts_its_own_line_after_the_progress_bar(spec_path, tmp_path):
    """In a terminal, dask's bar draws in place without ending its line, and
    the study's summary was printed after its last state, on its line."""
    status, text = _in_a_terminal(
        [sys.executable, "-m", "demo.sweep", str(spec_path), "--out", str(tmp_path),
         "--workers", "1", "--no-report"], {**os.environ, "PYTHONPATH": str(REPO_ROOT)})
    assert status == 0, text
    assert "% Completed" in text, "the bar is drawn in a terminal"
    before = text[:text.index(f"small: {RUNS} runs executed")]
    assert before.endswith(("\r", "\n")), repr(before[-120:])


def test_the_report_names_the_command_and_the_spec_that_made_it(spec_path, reference_out,
                                                                 tmp_path):
    """report.md said "Generated by `make sweep` ... demo/sweeps/" for a
    user's own spec and command too."""
    import shutil

    from demo.sweep_report import write_report

    shutil.copy(sweep.table_path(reference_out, "small"), tmp_path)
    text = write_report(tmp_path, "python -m demo.sweep my.toml --out x").read_text()
    assert "Generated by `python -m demo.sweep my.toml --out x` from the tables" in text, text
    assert f"Table: `small.parquet`, from the spec `{spec_path}`." in text, text
    assert "make sweep" not in text and "demo/sweeps" not in text, text
    assert f"`python -m demo.sweep_report --out {tmp_path}`" in write_report(tmp_path).read_text()


def test_the_robustness_histograms_say_what_their_x_axis_measures(tmp_path, monkeypatch):
    """The histograms had no x-axis label: a tracking RMS in the driven
    axis's unit (um, rad for theta), a reduction a ratio."""
    import matplotlib.pyplot as plt

    from demo import sweep_report

    figures = []
    close = plt.close
    monkeypatch.setattr(sweep_report.plt, "close",
                        lambda fig=None: figures.append(fig) or close(fig))
    rows = [{"status": "ok", "axis": axis, "decoupling": decoupling, "sample": sample,
             "tracking_rms": 0.01 * (1 + sample), "coupling_y_span": 1 + sample % 3 + (
                 decoupling == "off"), "command_saturation": 0.0, "wall_s": 0.01}
            for axis in ("x", "theta") for sample in range(8) for decoupling in ("off", "on")]
    sweep_report.robustness_section(rows, {"spec": _variables_spec("axis", "decoupling")},
                                    tmp_path)
    labels = {ax.get_title(): ax.get_xlabel() for ax in figures[0].axes if ax.get_title()}
    assert labels["x tracking RMS"] == "tracking RMS [µm]", labels
    assert labels["theta tracking RMS"] == "tracking RMS [rad]", labels
    assert labels["y from x reduction"] == "span without / with decoupling [1]", labels


def test_a_study_whose_runs_were_all_lost_names_no_table_file(tmp_path):
    """Every run lost, the summary said "0 rows in .../grid.parquet", a
    file that did not exist."""
    import pyarrow as pa
    import pyarrow.parquet as pq

    summary = {"study": "grid", "executed": 0, "failed": 0, "timeouts": 0, "skipped": 0,
               "rows": 0, "wall_s": 0.2}
    table = sweep.table_path(tmp_path, "grid")
    assert sweep.summary_line(summary, table) == (
        f"grid: 0 runs executed (0 failed, 0 timed out), 0 already in the table; no table "
        f"written ({table}): no run has finished; 0.2 s")
    assert sweep.summary_line(dict(summary, executed=8, rows=8), table).endswith(
        f"; 8 rows in {table}; 0.2 s")
    # Nor is a table left whose rows all left it (failed runs of a value
    # no longer swept), which would say "0 rows" of a file that has some.
    text = _kp_spec("[0.05]").replace('study = "small"', 'study = "grid"')
    spec = sweep.load_spec(_written(tmp_path / "s.toml", text))
    pq.write_table(pa.Table.from_pylist([{"run": 0, "key": "0" * 32, "status": "error",
                                          "error": "out of range"}]), table)
    runs = {run.key: run for run in sweep.expand(spec)[0]}
    assert sweep.consolidate(tmp_path, spec, runs) == 0
    assert not table.exists()


def test_an_envelope_report_of_a_monte_carlo_is_refused_before_any_run(tmp_path):
    """The envelope report holds one run per grid point and decoupling case:
    a [monte_carlo] gives each point several samples, and the report used to
    fail on them after every run had been made."""
    envelope = (REPO_ROOT / "demo" / "sweeps" / "envelope.toml").read_text()
    assert 'report = "envelope"' in envelope and "[monte_carlo]" not in envelope
    dist = REPO_ROOT / "dist"
    text = envelope.replace('"../../dist/', f'"{dist}/') + (
        "\n[monte_carlo]\nsamples = 2\ninstance = \"plant\"\n"
        "[[monte_carlo.vary]]\nmatch = '^amplifier\\\\.gain$'\nrelative = 0.03\n")
    spec = _written(tmp_path / "env_mc.toml", text)
    line = next(n for n, row in enumerate(text.splitlines(), 1) if row.startswith("report"))
    done = subprocess.run([sys.executable, "-m", "demo.sweep", str(spec), "--out",
                           str(tmp_path / "out")], capture_output=True, text=True,
                          cwd=REPO_ROOT, timeout=120)
    assert done.returncode == 2, done.stderr
    assert done.stderr.strip().startswith(f"{spec}:{line}: report 'envelope' shows one run per "
                                          "grid point"), done.stderr
    assert not (tmp_path / "out").exists() or not any((tmp_path / "out").glob("*.parquet"))


TABLE_SPEC = f"""
study = "small"

[template]
duration = 0.3

[template.fmu.plant]
path = "{PLANT}"

[template.fmu.controller]
path = "{CONTROLLER}"
parameters = {{ "translation.ki" = "= ki" }}

[template.metrics]
driven = "y"
from = 0.15

[template.signal."controller.y_ref"]
table = {{ file = "step.csv", column = "y_ref" }}

[[variable]]
name = "ki"
values = [20.0, 50.0]
"""


def test_a_reference_table_is_read_beside_the_spec_and_its_contents_key_the_runs(
        tmp_path, monkeypatch):
    """A relative reference table was read from the current folder, not the
    spec's (from another folder the sweep blamed a file that exists, and a
    file of that name there would have been read without a word), and its
    contents were not part of the runs' keys: a table edited after a sweep
    kept the old rows with "0 runs executed", exit 0. The table now travels
    with the tasks by its digest, as the FMUs do, so an edited table makes
    new runs, and the rows of the old ones are refused (StaleTable)."""
    folder = tmp_path / "study"
    folder.mkdir()
    spec = _written(folder / "table.toml", TABLE_SPEC)
    step = folder / "step.csv"
    step.write_text("t[ms],y_ref[nm]\n0,0\n99.9,0\n100,4000\n300,4000\n")
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    (elsewhere / "step.csv").write_text("t,y_ref\n0,0\n0.3,9\n")  # not the spec's
    monkeypatch.chdir(elsewhere)
    out = tmp_path / "out"
    (summary,) = local_sweeps([(spec, out)])
    assert (summary["executed"], summary["failed"]) == (2, 0), summary
    rows = rows_of(out)
    # The step reaches 4 um at 0.1 s (ms and nm converted), not the 9 um ramp here.
    runs, files = sweep.expand(sweep.load_spec(spec))
    direct = master.run(sweep.local_scenario(runs[0], files))["metrics"]
    assert rows[0]["tracking_rms"] == direct["tracking_rms"]
    assert direct["demand_span"] == pytest.approx(0.0, abs=1e-12)  # 4 um held over the window
    # Edited, the table makes other runs: the old rows are refused, not kept.
    step.write_text("t[ms],y_ref[nm]\n0,0\n99.9,0\n100,8000\n300,8000\n")
    assert {r.key for r in sweep.expand(sweep.load_spec(spec))[0]}.isdisjoint(
        {r["key"] for r in rows})
    with pytest.raises(sweep.StaleTable):
        sweep.run_sweep(sweep.load_spec(spec), out, client=None)
    # A table that is not beside the spec is named with the line that names it.
    step.unlink()
    with pytest.raises(sweep.SpecError) as missing:
        sweep.expand(sweep.load_spec(spec))
    assert str(missing.value) == (
        f"{spec}:19: signal controller.y_ref: reference table {step} does not exist (a table "
        f"is read relative to the spec's folder)")


def _check_error(path: Path) -> str:
    """The refusal of the spec at `path` by expansion or its check, before
    any run (no cluster)."""
    with pytest.raises(sweep.SpecError) as e:
        spec = sweep.load_spec(path)
        runs, files = sweep.expand(spec)
        sweep.check_scenarios(runs, files, spec)
    return str(e.value)


def _line(text: str, needle: str) -> int:
    return next(n for n, row in enumerate(text.splitlines(), 1) if needle in row)


def test_a_misspelt_name_is_named_where_the_spec_writes_it(tmp_path):
    """A name the FMUs lack was named with the file alone ("the scenario of
    the template does not run: controller.translation.kpp: ..."), in a
    template, a case's patch, a parameter set or the Monte Carlo's
    seed_parameter alike, and a check of the whole scenario with the
    master's `<stdin>`. Each is now at the line that writes it (a set's own
    file and line), with the values of the run checked."""
    cases = {
        "template": ('"noise.enabled" = true }', '"noise.enabled" = true, "noise.enabld" = 1 }',
                     '"noise.enabld"'),
        "patch": ("parameters = {{ decoupling = true }}".replace("{{", "{").replace("}}", "}"),
                  "parameters = { decoupling = true, feedbak_x = true }", "feedbak_x"),
        "seed_parameter": ('seed_parameter = "noise.seed"', 'seed_parameter = "noise.sed"',
                           '"noise.sed"'),
    }
    for case, (old, new, needle) in cases.items():
        text = SPEC.replace(old, new)
        assert text != SPEC, case
        error = _check_error(_written(tmp_path / f"{case}.toml", text))
        assert error.startswith(f"{tmp_path / f'{case}.toml'}:{_line(text, needle)}: "), error
        assert "has no variable" in error and "<stdin>" not in error, error
        decoupling = "on" if case == "patch" else "off"  # the case whose patch has it
        assert error.endswith(f"(in the scenario of frequency = 5.0, decoupling = {decoupling}, "
                              f"amplitude = 2.0)"), error
    # A parameter set's value: the set's file and line.
    (tmp_path / "mine.json").write_text('{\n  "amplifier.gain": 10,\n  "pzt[1].AA": 1\n}')
    text = GRID_SPEC.replace(f'path = "{PLANT}"\n',
                             f'path = "{PLANT}"\nparameter_sets = ["mine.json"]\n')
    error = _check_error(_written(tmp_path / "set.toml", text))
    assert error.startswith(f"{tmp_path / 'mine.json'}:3: plant.pzt[1].AA: "), error
    assert "(a value of this parameter set)" in error, error
    # A value the FMU refuses when its initialization ends, at its line.
    text = SPEC.replace('"noise.enabled" = true }', '"noise.enabled" = true, '
                        '"mode.x.damping" = -1 }')
    assert text != SPEC
    error = _check_error(_written(tmp_path / "range.toml", text))
    assert error.startswith(f"{tmp_path / 'range.toml'}:{_line(text, 'mode.x.damping')}: "
                            f"plant: fmi2"), error
    # A check of the whole scenario, at the template's line of its key.
    text = SPEC.replace('from = "= 0.2 + 1 / frequency"', 'from = "= 5 / frequency"')
    error = _check_error(_written(tmp_path / "from.toml", text))
    assert error.startswith(f"{tmp_path / 'from.toml'}:{_line(text, 'from = ')}: the scenario "
                            f"of frequency = 5.0, decoupling = off, amplitude = 2.0 does not run: "
                            f"metrics.from (1) leaves 0 of the run's samples"), error


def test_a_monte_carlo_that_varies_nothing_or_twice_is_named_at_its_group(tmp_path):
    """A Monte Carlo with no group and no seed_parameter was refused as two
    grid points making one run ("a variable the template does not use");
    two groups matching one parameter were named at the first group's line,
    not the later one's."""
    text = re.sub(r'seed_parameter = "noise.seed"\n\[\[monte_carlo.vary\]\].*?(?=\n\[template\])',
                  "", SPEC, flags=re.DOTALL)
    assert "[[monte_carlo.vary]]" not in text
    error = _check_error(_written(tmp_path / "nothing.toml", text))
    assert error == (f"{tmp_path / 'nothing.toml'}:{_line(text, '[monte_carlo]')}: monte_carlo: "
                     f"its 2 samples would all be one plant: give a [[monte_carlo.vary]] group "
                     f"(match, relative) to draw parameters from, or seed_parameter to draw the "
                     f"noise's seed"), error
    text = SPEC.replace("match = '^amplifier\\.gain$'", "match = 'pzt.1..A$'")
    assert text != SPEC
    error = _check_error(_written(tmp_path / "twice.toml", text))
    later = _line(text, "match = 'pzt.1..A$'")
    assert error.startswith(f"{tmp_path / 'twice.toml'}:{later}: monte_carlo.vary "
                            f"'pzt.1..A$' matches pzt[1].A, which "), error
