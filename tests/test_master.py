"""The compiled co-simulation master (piezo-cosim) against the fmpy master of
demo/cosim.py.

Both masters load the same FMU binaries and make the same FMI calls in the
same order, so every signal must agree to 1e-12 um (V for the commands):
what differs is only who keeps the loop, how parameters are applied (by FMI
name, from parameter sets or the scenario) and how the references reach the
controller. The references are handed to piezo-cosim as a table sampled at
the very times the master asks for (t_k = k·h for the record, (k + 2)·h for
the controller), so the comparison does not depend on how an experiment writes
its trajectory.
"""

from __future__ import annotations

import json
import math
import re
import subprocess
import sys

import numpy as np
import pytest

from demo import cosim, master
from demo.cosim import (
    CONTROLLER_OUTPUTS,
    PLANT_OUTPUTS,
    REFERENCES,
    SAMPLE_PERIOD,
    Fmu,
    simulate,
)
from demo.experiments import START, experiments, metrics
from tests.conftest import REPO_ROOT, require_closed_loop_build

PLANT = REPO_ROOT / "dist" / "FlexureStage.fmu"
CONTROLLER = REPO_ROOT / "dist" / "PiezoController.fmu"
PRESETS = REPO_ROOT / "dist" / "presets"
PREVIEW = 2
TOLERANCE = 1e-12


@pytest.fixture(scope="module", autouse=True)
def built():
    require_closed_loop_build()


def reference_table(reference, duration: float, folder) -> dict:
    """The references as piezo-cosim signals: a CSV sampled at t_k = k·h and
    at t_k + preview·h, computed as demo/cosim.py computes those times."""
    steps = round(duration / SAMPLE_PERIOD)
    t = np.arange(steps + 1) * SAMPLE_PERIOD
    ahead = (np.arange(steps) + PREVIEW) * SAMPLE_PERIOD  # (k + preview)·h, as both masters
    times = np.unique(np.concatenate([t, ahead]))
    values = np.asarray(reference(times), dtype=float)
    path = folder / "references.csv"
    with path.open("w") as f:
        f.write("t," + ",".join(REFERENCES) + "\n")
        for time, row in zip(times, values):
            f.write(",".join(repr(float(v)) for v in (time, *row)) + "\n")
    return {master.reference_port(name): {"table": {"file": str(path), "column": name}}
            for name in REFERENCES}


def compare(series: dict, run) -> dict:
    """Largest difference of every signal the fmpy master records."""
    worst = {}
    for name in PLANT_OUTPUTS:
        worst[f"plant.{name}"] = np.max(np.abs(series[f"plant.{name}"] - run.plant[name]))
    for name in CONTROLLER_OUTPUTS:
        worst[f"controller.{name}"] = np.max(
            np.abs(series[f"controller.{name}"] - run.controller[name]))
    for i, name in enumerate(REFERENCES):
        worst[f"controller.{name}"] = np.max(
            np.abs(series[f"controller.{name}"] - run.references[:, i]))
    assert np.array_equal(series["t"], run.t)
    return worst


# One experiment of each seed: seed 000's Table 3 y run with decoupling
# (seed 000's method, FlexureStage as it starts), and seed 001's coupling run
# on the XY200S parameter set with seed 001's method (plant parameters from
# the preset file, controller parameters by name).
EXPERIMENTS = ("fig10_y_decoupled", "abw_xy_xy200s_inverse_bouc_wen_model_based_coupling_x_decoupled")


@pytest.mark.parametrize("key", EXPERIMENTS)
def test_master_equals_the_fmpy_master_on_every_signal(key, tmp_path):
    chosen = {e.key: e for e in experiments()}
    if key not in chosen:
        pytest.fail(f"demo.experiments has no experiment {key!r}: pick the reference "
                    f"experiments of this test again", pytrace=False)
    experiment = chosen[key]
    with Fmu(PLANT) as plant, Fmu(CONTROLLER) as controller:
        spacing_um = float(controller.variables["L"].start) * 1e3
        run = simulate(plant, controller, experiment.reference(), experiment.duration,
                       plant_parameters=experiment.plant,
                       controller_parameters=experiment.controller, preview=PREVIEW)
    plant_entry = {"path": str(PLANT), "parameters": experiment.plant}
    if "xy200s" in key:
        # The same values, as the preset file plus the run's own settings.
        preset = json.loads((PRESETS / "FlexureStage.xy200s.json").read_text())
        assert {**preset, **experiment.plant} == experiment.plant
        plant_entry = {"path": str(PLANT),
                       "parameter_sets": [str(PRESETS / "FlexureStage.xy200s.json")],
                       "parameters": {k: v for k, v in experiment.plant.items()
                                      if k not in preset or preset[k] != v}}
    metric_spec = {"driven": experiment.driven, "from": START + experiment.measure_from}
    scenario = {
        "step": SAMPLE_PERIOD, "duration": experiment.duration, "preview": PREVIEW,
        "fmu": {cosim.PLANT_INSTANCE: plant_entry,
                cosim.CONTROLLER_INSTANCE: {"path": str(CONTROLLER),
                                            "parameters": experiment.controller}},
        "connection": master.connections(),
        "signal": reference_table(experiment.reference(), experiment.duration, tmp_path),
        "metrics": metric_spec,
    }
    result = master.run(scenario, series=tmp_path / "series.csv")
    worst = compare(master.read_series(tmp_path / "series.csv"), run)
    assert max(worst.values()) <= TOLERANCE, {k: v for k, v in worst.items() if v > 0}

    # The metrics are demo/experiments.py's, from the same samples.
    expected = metrics(experiment, run, spacing_um)
    got = result["metrics"]
    for name, value in expected.items():
        if isinstance(value, tuple):
            assert got[name] == pytest.approx(list(value), abs=TOLERANCE), name
        else:
            assert got[name] == pytest.approx(value, abs=TOLERANCE, rel=1e-12), name


def test_sine_signals_are_the_python_formula(tmp_path):
    """Signals written as data (offset, sines, start, approach) against the
    same formula evaluated in Python, through both masters."""
    y_path = {"offset": 3.0, "sines": [{"amplitude": 3.0, "frequency": 2.0,
                                       "phase": -math.pi / 2}]}
    x_ramp = {"offset": 6.0, "start": 0.3, "approach": 0.3}

    def reference(t):
        t = np.asarray(t, dtype=float)
        y = 3.0 + 3.0 * np.array([math.sin(2 * math.pi * 2.0 * tau - math.pi / 2) for tau in t])
        blend = 0.5 * (1 - np.cos(np.pi * np.clip(t / 0.3, 0, 1)))
        x = np.where(t >= 0.3, 6.0, blend * 6.0)
        return np.column_stack([x, y, np.zeros_like(t)])

    duration = 0.8
    controller_parameters = {"feedback_x": False, "feedback_theta": False, "decoupling": True}
    with Fmu(PLANT) as plant, Fmu(CONTROLLER) as controller:
        run = simulate(plant, controller, reference, duration,
                       controller_parameters=controller_parameters)
    scenario = {
        "duration": duration,
        "fmu": {"plant": {"path": str(PLANT)},
                "controller": {"path": str(CONTROLLER), "parameters": controller_parameters}},
        "signal": {"controller.y_ref": y_path, "controller.x_ref": x_ramp,
                   "controller.theta_ref": {"offset": 0.0}},
    }
    master.run(scenario, series=tmp_path / "s.csv")
    worst = compare(master.read_series(tmp_path / "s.csv"), run)
    assert max(worst.values()) <= TOLERANCE, {k: v for k, v in worst.items() if v > 0}


def test_the_masters_share_the_stage_wiring():
    """piezo-cosim's default connections are demo/cosim.py's table."""
    source = (REPO_ROOT / "piezo-cosim" / "src" / "scenario.rs").read_text()

    def pairs(name):
        found = re.search(rf"pub const {name}: \[\(&str, &str\); \d+\] = \[(.*?)\];", source)
        assert found, f"{name} not found in piezo-cosim/src/scenario.rs"
        return tuple(re.findall(r'\("(\w+)", "(\w+)"\)', found.group(1)))

    assert pairs("STAGE_COMMANDS") == cosim.COMMANDS
    assert pairs("STAGE_SENSORS") == cosim.SENSORS
    for constant, value in (("PLANT", cosim.PLANT_INSTANCE),
                            ("CONTROLLER", cosim.CONTROLLER_INSTANCE)):
        assert f'pub const {constant}: &str = "{value}";' in source


def run_cli(*args, input=None):
    return subprocess.run([str(master.binary()), *args], capture_output=True, text=True,
                          input=input)


def test_the_example_scenario_runs_as_documented():
    """piezo-cosim/examples/table3_y.toml (the run docs/sweeps.md times),
    with its relative paths, from any working directory."""
    example = REPO_ROOT / "piezo-cosim" / "examples" / "table3_y.toml"
    done = subprocess.run([str(master.binary()), "run", str(example)], capture_output=True,
                          text=True, cwd="/")
    assert done.returncode == 0, done.stderr
    result = json.loads(done.stdout)
    assert (result["status"], result["steps"], result["simulated_s"]) == ("ok", 40000, 4.0)
    metrics = result["metrics"]
    assert metrics["samples"] == 20001  # t = 2..4 s at 10 kHz
    assert metrics["demand_span"] == pytest.approx(10.0, abs=1e-9)
    for name in ("tracking_rms", "tracking_max", "coupling_x2_span", "coupling_x3_span"):
        assert math.isfinite(metrics[name]) and metrics[name] > 0, name


def test_a_malformed_scenario_names_file_line_and_problem(tmp_path):
    path = tmp_path / "bad.toml"
    path.write_text(f'duration = 1.0\n[fmu.plant]\npath = "{PLANT}"\nparamters = {{}}\n')
    done = run_cli("run", str(path))
    assert done.returncode == 2
    assert done.stderr.startswith(f"{path}:4:"), done.stderr
    assert "unknown field `paramters`" in done.stderr


def test_a_misspelt_variable_names_the_scenarios_file_and_line(tmp_path):
    """The FMUs, not the parser, know that `feedbak_y` or `x_reff` is no
    variable: the message still names the scenario's file and the line the
    name is written on (README: exit 2 names the file, line and problem)."""
    path = tmp_path / "typo.toml"
    path.write_text(f'duration = 0.01\n[fmu.plant]\npath = "{PLANT}"\n[fmu.controller]\n'
                    f'path = "{CONTROLLER}"\nparameters = {{ feedbak_y = true }}\n')
    done = run_cli("run", str(path))
    assert done.returncode == 2
    assert done.stderr.startswith(f"{path}:6: controller.feedbak_y: "), done.stderr
    assert 'has no variable "feedbak_y"' in done.stderr
    path.write_text(f'duration = 0.01\n[fmu.plant]\npath = "{PLANT}"\n[fmu.controller]\n'
                    f'path = "{CONTROLLER}"\n\n[signal."controller.x_reff"]\noffset = 1.0\n')
    done = run_cli("check", str(path))
    assert done.returncode == 2
    assert done.stderr.startswith(f"{path}:7: controller.x_reff: "), done.stderr


def test_an_unknown_parameter_is_refused_by_name(tmp_path):
    scenario = {"duration": 0.01, "fmu": {
        "plant": {"path": str(PLANT), "parameters": {"pzt[4].A": 1.0}},
        "controller": {"path": str(CONTROLLER)}}}
    with pytest.raises(master.MasterError, match=r"plant\.pzt\[4\]\.A.*no variable") as e:
        master.run(scenario)
    assert e.value.returncode == 2


def test_a_value_the_fmu_refuses_fails_the_run_with_its_log():
    """A parameter value the FMU refuses is the scenario's to fix: exit 2,
    as an unknown name is (1 is an FMU that failed while running)."""
    scenario = {"duration": 0.01, "fmu": {
        "plant": {"path": str(PLANT), "parameters": {"mode.theta.frequency": -790.0}},
        "controller": {"path": str(CONTROLLER)}}}
    with pytest.raises(master.MasterError) as e:
        master.run(scenario)
    assert e.value.returncode == 2
    assert "fmi2ExitInitializationMode" in str(e.value) or "fmi2SetReal" in str(e.value)
    assert "mode.theta.frequency" in str(e.value), str(e.value)


def test_series_as_parquet_from_python(tmp_path):
    import pyarrow.parquet as pq

    scenario = tmp_path / "s.toml"
    scenario.write_text(f"""
duration = 0.05
[fmu.plant]
path = "{PLANT}"
[fmu.controller]
path = "{CONTROLLER}"
[signal."controller.y_ref"]
offset = 1.0
""")
    out = tmp_path / "s.parquet"
    done = subprocess.run([sys.executable, "-m", "demo.master", "run", str(scenario),
                           "--series", str(out)], capture_output=True, text=True, cwd=REPO_ROOT)
    assert done.returncode == 0, done.stderr
    assert json.loads(done.stdout)["steps"] == 500
    table = pq.read_table(out)
    assert table.num_rows == 501
    assert {"t", "controller.y_ref", "plant.s1", "controller.u1"} <= set(table.column_names)


def scenario_of(example: str) -> dict:
    """An example scenario as the dict `run_batch` takes (absolute paths)."""
    import tomllib

    path = REPO_ROOT / "piezo-cosim" / "examples" / example
    scenario = tomllib.loads(path.read_text())
    for entry in scenario["fmu"].values():
        entry["path"] = str((path.parent / entry["path"]).resolve())
    return scenario


def test_a_batch_gives_what_single_runs_give_and_keeps_failures_apart():
    """`run_batch` (one piezo-cosim process, each FMU opened once): every
    result equals that of a run of its own, bit for bit; a run the master
    refuses is that run's MasterError, and the runs after it go on."""
    first = scenario_of("table3_y.toml")
    first["duration"], first["metrics"]["from"] = 0.5, 0.25
    other = json.loads(json.dumps(first))
    other["fmu"]["plant"]["parameters"]["noise.seed"] = 7
    refused = json.loads(json.dumps(first))
    refused["fmu"]["plant"]["parameters"]["pzt[4].A"] = 1.0
    outcomes = master.run_batch([first, refused, other, first])
    assert isinstance(outcomes[1], master.MasterError) and outcomes[1].returncode == 2
    assert "pzt[4].A" in str(outcomes[1])
    for scenario, outcome in zip([first, other, first], [outcomes[0], outcomes[2], outcomes[3]]):
        assert outcome["metrics"] == master.run(scenario)["metrics"]
    assert outcomes[0]["metrics"] != outcomes[2]["metrics"], "the seed moves the noise"


PRINTING_DLOPEN = r"""
#define _GNU_SOURCE
#include <dlfcn.h>
#include <unistd.h>
/* Prints to the standard output whenever a library is opened, as an FMU's
   C code may print: the master opens the FMUs' binaries after it has moved
   its results to a stream of their own. */
void *dlopen(const char *file, int mode) {
    static void *(*real)(const char *, int);
    if (!real) real = (void *(*)(const char *, int))dlsym(RTLD_NEXT, "dlopen");
    (void)!write(1, "an FMU says hello\n", 18);
    return real(file, mode);
}
"""


def test_what_an_fmu_prints_never_mixes_with_the_results(tmp_path):
    """Text an FMU writes to the standard output goes to the error stream:
    each line the master prints is a result (here an LD_PRELOADed dlopen
    prints whenever the master loads an FMU's binary)."""
    import os
    import shutil

    compiler = shutil.which("cc") or shutil.which("gcc")
    if compiler is None:
        pytest.skip("no C compiler")
    source = tmp_path / "printing_dlopen.c"
    source.write_text(PRINTING_DLOPEN)
    library = tmp_path / "printing_dlopen.so"
    subprocess.run([compiler, "-shared", "-fPIC", "-o", str(library), str(source), "-ldl"],
                   check=True)
    scenario = scenario_of("table3_y.toml")
    scenario["duration"], scenario["metrics"]["from"] = 0.05, 0.0
    lines = "".join(json.dumps(s) + "\n" for s in (scenario, scenario))
    env = {**os.environ, "LD_PRELOAD": str(library)}
    for args, stdin, expected in ((["batch", "-"], lines, 2),
                                  (["run", "-"], json.dumps(scenario), 1)):
        done = subprocess.run([str(master.binary()), *args], input=stdin, capture_output=True,
                              text=True, env=env)
        assert done.returncode == 0, done.stderr
        assert "an FMU says hello" in done.stderr, "the preloaded dlopen ran"
        results = done.stdout.splitlines()
        assert len(results) == expected, done.stdout
        assert all(json.loads(line)["status"] == "ok" for line in results)


def test_a_batch_process_that_writes_no_result_fails_that_run_alone(tmp_path, monkeypatch):
    """A line that is not a result (a master that is not ours, or broken)
    fails the run it stands for and ends that process; the next run gets a
    new one."""
    fake = tmp_path / "piezo-cosim"
    fake.write_text("#!/bin/sh\nread first\necho 'not a result'\nsleep 30\n")
    fake.chmod(0o755)
    monkeypatch.setenv("PIEZO_COSIM", str(fake))
    outcomes = master.run_batch([{"duration": 1.0}, {"duration": 2.0}], timeout=20)
    assert [type(o) for o in outcomes] == [master.MasterError, master.MasterError]
    assert all("wrote 'not a result' where a result was due" in str(o) for o in outcomes)


def test_a_batch_file_resolves_paths_from_its_folder_and_names_bad_lines(tmp_path):
    """`piezo-cosim batch FILE.jsonl` from another working directory: paths
    relative to the file's folder, one result line per scenario line (blank
    lines skipped), a malformed line answered with its file, line and
    column; the exit status is the highest of the lines'."""
    import os

    scenario = scenario_of("table3_y.toml")
    scenario["duration"], scenario["metrics"]["from"] = 0.05, 0.0
    for entry in scenario["fmu"].values():
        entry["path"] = os.path.relpath(entry["path"], tmp_path)
    runs = tmp_path / "runs.jsonl"
    runs.write_text(json.dumps(scenario) + "\n" + '{"duration": 1.0, "fmu": 3}\n\n'
                    + json.dumps(scenario) + "\n")
    done = subprocess.run([str(master.binary()), "batch", str(runs)], capture_output=True,
                          text=True, cwd="/")
    # Every line answered, and the status says one of them did not fit.
    assert done.returncode == 2, done.stderr
    results = [json.loads(line) for line in done.stdout.splitlines()]
    assert [(r["line"], r["status"]) for r in results] == [(1, "ok"), (2, "error"), (4, "ok")]
    assert results[1]["exit"] == 2
    assert results[1]["error"].startswith(f"{runs}:2:26: fmu: invalid type: integer `3`")
    assert results[0]["metrics"] == results[2]["metrics"]


def test_run_outputs_are_checked_before_the_run_and_a_table_holds_finite_numbers(tmp_path):
    """`piezo-cosim run`: an --out that is the scenario itself, a folder, a
    file the scenario reads (its reference table), or one file for --out
    and --series is refused before the run (exit 2) and the files are left
    as they were; /dev/null takes both, and a link is written through, not
    replaced. A reference table with NaN is refused at its line (exit 2; it
    reached the controller's fmi2SetReal as an FMU failure, exit 1), its
    line counted with the blank lines before it."""
    scenario = scenario_of("table3_y.toml")
    scenario["duration"], scenario["metrics"]["from"] = 0.05, 0.0
    path = tmp_path / "run.json"
    path.write_text(json.dumps(scenario))
    before = path.read_bytes()
    binary = str(master.binary())
    table = tmp_path / "y.csv"
    table.write_text("t,y\n0,0\n0.05,1\n")
    scenario["signal"]["controller.y_ref"] = {"table": {"file": str(table), "column": "y"}}
    path.write_text(json.dumps(scenario))
    before = path.read_bytes()
    for args, problem in (
            (["--out", str(tmp_path / "." / "run.json")], "is the scenario being run"),
            (["--out", str(tmp_path)], "is a folder"),
            (["--series", str(table)], "which the scenario reads"),
            (["--out", str(tmp_path / "r.csv"), "--series", str(tmp_path / "r.csv")],
             "--series and --out both name")):
        done = subprocess.run([binary, "run", str(path), *args], capture_output=True, text=True)
        assert done.returncode == 2, done.stderr
        assert problem in done.stderr, done.stderr
        assert done.stdout == ""
    assert path.read_bytes() == before and table.read_text() == "t,y\n0,0\n0.05,1\n"
    done = subprocess.run([binary, "run", str(path), "--out", "/dev/null", "--series", "/dev/null"],
                          capture_output=True, text=True)
    assert done.returncode == 0, done.stderr
    real, link = tmp_path / "real.json", tmp_path / "link.json"
    real.write_text("{}")
    link.symlink_to(real)
    done = subprocess.run([binary, "run", str(path), "--out", str(link)], capture_output=True,
                          text=True)
    assert done.returncode == 0, done.stderr
    assert link.is_symlink() and json.loads(real.read_text())["status"] == "ok"
    table.write_text("t,y\n0,0\n\n0.02,1\n0.04,nan\n")
    scenario["signal"]["controller.y_ref"] = {"table": {"file": str(table), "column": "y"}}
    path.write_text(json.dumps(scenario))
    done = subprocess.run([binary, "run", str(path)], capture_output=True, text=True)
    assert done.returncode == 2, done.stderr
    assert f'{table}:5: column "y": "nan" is not a finite number' in done.stderr, done.stderr


def test_a_reference_tables_step_edge_agrees_with_the_fmpy_master(tmp_path):
    """The preview's times were t_k + 2h in the fmpy master and (k + 2)·h in
    the compiled one: the last bit apart, which on a table's step edge (0 to
    4 um between 99.9 and 100 ms) put the two 2.8e-12 um apart. Both take
    (k + 2)·h now."""
    table = tmp_path / "step.csv"
    table.write_text("t[ms],y_ref[nm]\n0,0\n99.9,0\n100,4000\n150,4000\n")
    times_s, y_um = np.array([0.0, 0.0999, 0.1, 0.15]), np.array([0.0, 0.0, 4.0, 4.0])

    def reference(t):
        demand = np.zeros((len(t), 3))
        demand[:, 1] = np.interp(t, times_s, y_um)
        return demand

    parameters = {"feedback_x": True, "feedback_y": True, "feedback_theta": True}
    with Fmu(PLANT) as plant, Fmu(CONTROLLER) as controller:
        run = simulate(plant, controller, reference, 0.15, controller_parameters=parameters,
                       preview=PREVIEW)
    scenario = {
        "step": SAMPLE_PERIOD, "duration": 0.15, "preview": PREVIEW,
        "fmu": {cosim.PLANT_INSTANCE: {"path": str(PLANT)},
                cosim.CONTROLLER_INSTANCE: {"path": str(CONTROLLER), "parameters": parameters}},
        "connection": master.connections(),
        "signal": {master.reference_port("y_ref"): {"table": {"file": str(table),
                                                              "column": "y_ref"}}},
    }
    master.run(scenario, series=tmp_path / "series.csv")
    series = master.read_series(tmp_path / "series.csv")
    worst = max(np.max(np.abs(series[f"plant.{name}"] - run.plant[name]))
                for name in PLANT_OUTPUTS)
    assert worst <= TOLERANCE, worst


def test_a_series_carries_each_columns_unit(tmp_path):
    """The series had no units (`t,controller.y_ref,...`), where the sweep
    tables carry theirs: its CSV header now gives each column's unit as the
    FMUs declare it, in brackets as a reference table's header takes it, and
    a Parquet series has it in each field's metadata (b"unit")."""
    import pyarrow.parquet as pq

    scenario = {"duration": 0.01,
                "fmu": {cosim.PLANT_INSTANCE: {"path": str(PLANT)},
                        cosim.CONTROLLER_INSTANCE: {"path": str(CONTROLLER)}},
                "signal": {master.reference_port("y_ref"): {"offset": 1.0}}}
    master.run(scenario, series=tmp_path / "s.csv")
    header = (tmp_path / "s.csv").read_text().splitlines()[0].split(",")
    assert header[0] == "t[s]"
    for column in ("plant.s1[um]", "plant.theta_z[rad]", "controller.u1[V]",
                   "controller.y_ref[um]", "controller.e_theta[rad]"):
        assert column in header, (column, header)
    columns = master.read_series(tmp_path / "s.csv")
    assert "t" in columns and "plant.s1" in columns
    master.run(scenario, series=tmp_path / "s.parquet")
    schema = pq.read_schema(tmp_path / "s.parquet")
    units = {f.name: f.metadata[b"unit"].decode() for f in schema if f.metadata}
    assert units["t"] == "s" and units["plant.s1"] == "um" and units["controller.u1"] == "V"
