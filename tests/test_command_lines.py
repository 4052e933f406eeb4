"""The Python commands as a script calls them: exit statuses, what a mistake
in the arguments does (a line naming it, status 2, before any run), and what
an interrupt or a closed pipe leaves on disk.

The runs are faked where the command's own logic is under test (the
matrix's 270 runs take half a minute), so that each test takes a second or
two; the FMUs and the master are loaded where a check needs them.
"""

from __future__ import annotations

import json
import subprocess
import sys

import pytest

from demo import master, matrix, sweep
from tests.conftest import REPO_ROOT, require_closed_loop_build

PLANT = REPO_ROOT / "dist" / "FlexureStage.fmu"
CONTROLLER = REPO_ROOT / "dist" / "PiezoController.fmu"
EXAMPLE = REPO_ROOT / "piezo-cosim" / "examples" / "table3_y.toml"


@pytest.fixture(autouse=True)
def built():
    require_closed_loop_build()


# --------------------------------------------------------------------------
# demo.matrix

def missed_row(args) -> dict:
    """A row whose bounds all miss, for each case, without running it."""
    case = args[0]
    figures = {"tracking_rms": 1.0, "pose_coupling_x2_span": 1.0,
               "pose_coupling_x3_span": 1.0, "pose_coupling_y_span": 1.0}
    return matrix.evaluate_metrics(case, figures, figures)


def matrix_args(out) -> list[str]:
    return ["--out", str(out), "--plant", str(PLANT), "--controller", str(CONTROLLER)]


def test_the_matrix_exits_0_when_it_ran_whatever_its_verdicts(tmp_path, monkeypatch, capsys):
    monkeypatch.setattr(matrix, "_run_case", missed_row)
    assert matrix.main(matrix_args(tmp_path / "m")) == 0
    text = (tmp_path / "m" / "matrix.md").read_text()
    assert "0 of 81 bounded cases met" in text and "**missed**" in text


def test_the_matrix_refuses_an_out_it_cannot_make_before_any_run(tmp_path, monkeypatch, capsys):
    ran = []
    monkeypatch.setattr(matrix, "_run_case", lambda args: ran.append(args) or missed_row(args))
    blocker = tmp_path / "a-file"
    blocker.write_text("")
    assert matrix.main(matrix_args(blocker / "out")) == 2
    assert ran == []
    error = capsys.readouterr().err.strip()
    assert len(error.splitlines()) == 1 and str(blocker / "out") in error


def test_the_matrix_names_a_missing_fmu_in_a_line_with_status_2(tmp_path, monkeypatch, capsys):
    ran = []
    monkeypatch.setattr(matrix, "_run_case", lambda args: ran.append(args) or missed_row(args))
    missing = tmp_path / "nonexistent.fmu"
    status = matrix.main(["--out", str(tmp_path / "m"), "--plant", str(missing)])
    assert status == 2 and ran == []
    error = capsys.readouterr().err.strip()
    assert len(error.splitlines()) == 1 and str(missing) in error


def test_a_closed_stdout_still_gets_the_matrix_written(tmp_path):
    # The reader is gone before the first line (as `| head -1` after it):
    # every print meets a closed pipe.
    out = tmp_path / "m"
    script = ("import sys; from demo import matrix; from tests.test_command_lines import "
              "missed_row, matrix_args; matrix._run_case = missed_row; "
              f"sys.exit(matrix.main(matrix_args({str(out)!r})))")
    process = subprocess.Popen([sys.executable, "-c", script], cwd=REPO_ROOT,
                               stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    process.stdout.close()
    error = process.stderr.read().decode()
    assert process.wait(timeout=60) == 0, error
    assert error == ""
    assert (out / "matrix.md").is_file()


# --------------------------------------------------------------------------
# python -m demo (the report)

SHORT = "fig8_y_10hz_ff"  # 1.5 s simulated, about a second


def test_an_interrupt_mid_write_keeps_the_previous_file_whole(tmp_path, monkeypatch):
    from demo import __main__ as report_command
    from demo import cosim

    previous = "t[s],y[um]\n0,1\n"
    (tmp_path / f"{SHORT}.csv").write_text(previous)

    def interrupted_write(run, path):
        path.write_text("t[s],y[um]\n0,")  # a part of the file, then Ctrl-C
        raise KeyboardInterrupt

    monkeypatch.setattr(cosim.Run, "write_csv", interrupted_write)
    try:
        status = report_command.main(["--out", str(tmp_path), "--only", SHORT])
    except KeyboardInterrupt:  # as raised, it would end the test session
        pytest.fail("the interrupt escaped the command")
    assert status == 130
    assert (tmp_path / f"{SHORT}.csv").read_text() == previous
    assert sorted(p.name for p in tmp_path.iterdir()) == [f"{SHORT}.csv"]


def test_only_keeps_the_other_runs_and_the_report_agrees(tmp_path, monkeypatch):
    from demo import __main__ as report_command
    from demo.experiments import experiments

    earlier = {e.key: {"from": "an earlier run"} for e in experiments()}
    (tmp_path / "metrics.json").write_text(json.dumps(earlier))
    reported = {}

    def write_report(path, results, context):
        reported.update(results)
        path.write_text("the report")

    monkeypatch.setattr(report_command, "write_report", write_report)
    assert report_command.main(["--out", str(tmp_path), "--only", SHORT]) == 0
    written = json.loads((tmp_path / "metrics.json").read_text())
    assert set(written) == set(earlier)
    assert written[SHORT] != earlier[SHORT] and "tracking_rms" in written[SHORT]
    assert all(written[key] == earlier[key] for key in earlier if key != SHORT)
    assert json.dumps(reported) == json.dumps(written)  # the same figures, as JSON holds them
    assert (tmp_path / "report.md").read_text() == "the report"


def _sets(tmp_path, plant: str, controller: str) -> list[str]:
    (tmp_path / "plant.json").write_text(plant)
    (tmp_path / "controller.json").write_text(controller)
    return ["--plant-parameters", str(tmp_path / "plant.json"),
            "--controller-parameters", str(tmp_path / "controller.json")]


@pytest.mark.parametrize("plant, controller, problem", [
    ('{"mode.x.frequency": 800.0,\n "pzt[1].A": }', "{}", "plant.json: line 2, column 14"),
    ('{"no.such.parameter": 1.0}', "{}", "'no.such.parameter' is not a parameter of FlexureStage.fmu"),
    ("{}", '{"translation.kp": "high"}',
     "controller.json: 'translation.kp' = 'high' is not a finite number"),
    ("[1, 2]", "{}", "plant.json: a parameter set is a JSON object"),
    ('{"mode.x.frequency": NaN}', "{}", "'mode.x.frequency' = nan is not a finite number"),
])
def test_a_malformed_parameter_set_is_refused_before_any_run(tmp_path, capsys, plant, controller,
                                                             problem):
    from demo import __main__ as report_command
    out = tmp_path / "out"
    assert report_command.main(["--out", str(out), *_sets(tmp_path, plant, controller)]) == 2
    assert problem in capsys.readouterr().err
    assert not out.exists(), "nothing is run or written"


def test_a_partial_run_on_other_parameters_than_the_folders_is_refused(tmp_path, capsys,
                                                                       monkeypatch):
    """--only adds to a folder's figures only when they are of the same
    parameters: report.md would otherwise name one set for runs of two."""
    from demo import __main__ as report_command
    monkeypatch.setattr(report_command, "write_report", lambda path, *_: path.write_text("r"))
    out = tmp_path / "out"
    assert report_command.main(["--out", str(out), "--only", SHORT]) == 0
    assert json.loads((out / "parameters.json").read_text())["plant"] is None
    sets = _sets(tmp_path, '{"mode.x.frequency": 801.0}', '{"translation.kp": 0.04}')
    assert report_command.main(["--out", str(out), "--only", SHORT, *sets]) == 2
    assert "holds runs on other parameters" in capsys.readouterr().err
    other = tmp_path / "other"
    assert report_command.main(["--out", str(other), "--only", SHORT, *sets]) == 0
    assert report_command.main(["--out", str(other), "--only", SHORT, *sets]) == 0
    assert json.loads((other / "parameters.json").read_text())["plant"] == {
        "mode.x.frequency": 801.0}


def test_a_plant_set_without_its_controller_is_refused(tmp_path, capsys):
    from demo import __main__ as report_command
    (tmp_path / "plant.json").write_text("{}")
    status = report_command.main(["--out", str(tmp_path / "out"),
                                  "--plant-parameters", str(tmp_path / "plant.json")])
    assert status == 2
    assert "go together" in capsys.readouterr().err


def test_the_sets_replace_the_start_values_and_keep_each_runs_settings():
    """`on_parameter_sets`: the sets under every run's own settings (the
    noise switch and seed, the controller's switches), the law fitted once
    where a run takes it, and the XY200S runs on their own stage."""
    from demo.experiments import experiments, on_parameter_sets
    plant_set = {"mode.x.frequency": 801.0, "noise.enabled": False, "noise.rms": 0.007}
    controller_set = {"translation.kp": 0.04, "feedback_x": False, "compensation.dk[1]": 1.0}
    once = {"compensation.dk[1]": 2.0, "translation.kp": 9.9}  # only its law is taken
    runs = experiments()
    moved = on_parameter_sets(runs, plant_set, controller_set, once)
    assert [e.key for e in moved] == [e.key for e in runs]
    for e, m in zip(runs, moved):
        if "xy200s" in e.key:
            assert m is e
            continue
        assert m.plant == {**plant_set, **e.plant}
        assert m.plant["noise.enabled"] is True and m.plant["noise.rms"] == 0.007
        takes_once = any(k.startswith("compensation.") for k in e.controller)
        assert m.controller["compensation.dk[1]"] == (2.0 if takes_once else 1.0), e.key
        assert m.controller["translation.kp"] == e.controller.get("translation.kp", 0.04)
        # Every switch of the run, also one equal to the shipped start value.
        assert all(m.controller[k] == v for k, v in e.controller.items()
                   if not k.startswith("compensation.")), e.key
    assert any("xy200s" in e.key for e in runs)
    # A set whose switch differs from the start value does not override a run's.
    decoupled = {e.key: m for e, m in zip(runs, on_parameter_sets(
        runs, {}, {"decoupling": False})) if e.controller.get("decoupling") is True}
    assert decoupled and all(m.controller["decoupling"] is True for m in decoupled.values())


# --------------------------------------------------------------------------
# demo.master

@pytest.mark.parametrize("name", ["series.parquet", "series.csv"])
def test_a_series_path_that_is_a_folder_is_refused_before_the_run(tmp_path, name):
    folder = tmp_path / name
    folder.mkdir()
    done = subprocess.run([sys.executable, "-m", "demo.master", "run", str(EXAMPLE),
                           "--series", str(folder)], cwd=REPO_ROOT, capture_output=True,
                          text=True, timeout=60)
    assert done.returncode == 2 and done.stdout == ""
    assert len(done.stderr.strip().splitlines()) == 1 and str(folder) in done.stderr


def test_piezo_cosim_names_a_folder_given_as_the_series(tmp_path):
    """`piezo-cosim run --series .` was told to name the file .csv; it is a
    folder, and is said to be one."""
    done = subprocess.run([str(REPO_ROOT / "demo" / "bin" / "piezo-cosim"), "run", str(EXAMPLE),
                           "--series", str(tmp_path)], capture_output=True, text=True,
                          timeout=60)
    assert done.returncode == 2 and done.stdout == ""
    assert done.stderr.strip() == f"{tmp_path}: is a folder; give the name of the file to write"


def test_a_series_in_a_missing_folder_is_refused_before_the_run(tmp_path, monkeypatch):
    def no_run(*args, **kwargs):
        raise AssertionError("the master was started")

    monkeypatch.setattr(master.subprocess, "run", no_run)
    target = tmp_path / "missing" / "series.parquet"
    with pytest.raises(master.MasterError) as refused:
        master.run(EXAMPLE, series=target)
    assert refused.value.returncode == 2 and str(target) in str(refused.value)


# --------------------------------------------------------------------------
# demo.sweep

SPEC = f"""
study = "tiny"

[template]
duration = 0.05

[template.fmu.plant]
path = "{PLANT}"

[template.fmu.controller]
path = "{CONTROLLER}"

[template.metrics]
driven = "y"
from = 0.0

[template.signal."controller.y_ref"]
offset = 1.0
sines = [{{ amplitude = 1.0, frequency = "= frequency" }}]

[[variable]]
name = "frequency"
values = [5.0]
"""


@pytest.mark.parametrize("workers", ["0", "-2"])
def test_a_sweep_refuses_no_workers_at_the_parser(tmp_path, workers, capsys):
    with pytest.raises(SystemExit) as refused:
        sweep.main([str(tmp_path / "spec.toml"), "--workers", workers])
    assert refused.value.code == 2
    assert "--workers" in capsys.readouterr().err


def test_a_sweep_out_that_is_a_file_is_refused_before_any_run(tmp_path, capsys):
    spec = tmp_path / "tiny.toml"
    spec.write_text(SPEC)
    out = tmp_path / "results"
    out.write_text("mine")
    assert sweep.main([str(spec), "--out", str(out), "--progress", "none"]) == 2
    error = capsys.readouterr().err.strip()
    assert len(error.splitlines()) == 1 and str(out) in error
    assert out.read_text() == "mine"


@pytest.mark.parametrize("restart", [[], ["--restart"]])
def test_a_truncated_table_is_named_and_kept(tmp_path, restart, capsys):
    import pyarrow as pa
    import pyarrow.parquet as pq

    spec = tmp_path / "tiny.toml"
    spec.write_text(SPEC)
    out = tmp_path / "out"
    out.mkdir()
    table = sweep.table_path(out, "tiny")
    pq.write_table(pa.table({"run": list(range(1000)), "key": [str(i) for i in range(1000)]}),
                   str(table))
    truncated = table.read_bytes()[: table.stat().st_size // 2]
    table.write_bytes(truncated)
    assert sweep.main([str(spec), "--out", str(out), "--progress", "none", *restart]) == 2
    error = capsys.readouterr().err.strip()
    assert len(error.splitlines()) == 1 and str(table) in error
    assert table.read_bytes() == truncated


def test_a_spec_with_a_byte_order_mark_is_read(tmp_path):
    spec = tmp_path / "tiny.toml"
    spec.write_text(SPEC, encoding="utf-8-sig")
    assert spec.read_bytes().startswith(b"\xef\xbb\xbf")
    loaded = sweep.load_spec(spec)
    assert loaded.study == "tiny"


# --------------------------------------------------------------------------
# piezo-identify on a plant FMU

def test_a_parameter_set_the_plant_refuses_is_what_was_given(tmp_path):
    """`piezo-identify bouc-wen --plant` with a parameter set whose value
    the FMU refuses when it starts a session exits 2 (what was given does
    not fit), naming the parameter, before any run; a call refused while
    the plant runs would be the run's (exit 1)."""
    parameters = tmp_path / "gain.json"
    parameters.write_text('{"amplifier.gain": -5}')
    done = subprocess.run(
        [str(REPO_ROOT / "target" / "release" / "piezo-identify"), "bouc-wen", "--plant",
         str(PLANT), "--plant-parameters", str(parameters), "--periods", "2"],
        capture_output=True, text=True)
    assert done.returncode == 2, done.stderr
    assert "while starting a session" in done.stderr, done.stderr
    assert "amplifier.gain = -5 is outside its allowed range" in done.stderr, done.stderr


def test_the_controller_given_as_the_plant_is_refused_before_any_run(tmp_path):
    """PiezoController has variables named u1..u3 and s1..s3 too, with the
    causalities the other way round: `stage --plant` took it for a plant,
    ran, and failed at its first fmi2SetReal on an output (exit 1). It is
    now refused when opened, exit 2, and nothing is written."""
    out = tmp_path / "preset.json"
    done = subprocess.run(
        [str(REPO_ROOT / "target" / "release" / "piezo-identify"), "stage", "--plant",
         str(CONTROLLER), "--out", str(out)],
        capture_output=True, text=True)
    assert done.returncode == 2, done.stderr
    assert done.stderr.strip() == (
        f'{CONTROLLER}: u1 has causality "output", a plant\'s "input": a plant needs inputs '
        "u1..u3 [V] and outputs s1..s3 [um]"), done.stderr
    assert done.stdout == "" and not out.exists()


def test_a_name_the_plant_lacks_names_the_parameter_file(tmp_path):
    """A mistyped name in --plant-parameters is the file's fault: the message
    names the file first (it named only the FMU), then the FMU's nearest
    name; `--rounds 0` and a negative `--scale` are refused by the tool's
    own messages, before any run."""
    parameters = tmp_path / "mine.json"
    parameters.write_text('{"pzt[1].pp": 1.0}')
    binary = str(REPO_ROOT / "target" / "release" / "piezo-identify")
    out = tmp_path / "preset.json"
    done = subprocess.run([binary, "stage", "--plant", str(PLANT), "--plant-parameters",
                           str(parameters), "--out", str(out)], capture_output=True, text=True)
    assert done.returncode == 2, done.stderr
    assert done.stderr.strip() == (
        f'{parameters}: {PLANT}: no parameter pzt[1].pp (did you mean "pzt[1].p"?)'), done.stderr
    for extra, said in ((["--rounds", "0"], "'0' for '--rounds <ROUNDS>'"),
                        (["--scale", "-1"], "--scale -1: give a positive factor")):
        done = subprocess.run([binary, "stage", "--out", str(out), *extra],
                              capture_output=True, text=True)
        assert done.returncode == 2 and said in done.stderr, done.stderr
    assert not out.exists()


def test_a_plant_run_that_makes_no_loop_or_too_many_samples_is_refused():
    """`bouc-wen --plant` refuses, before the run, a rate that samples the
    sine fewer than 20 times a period (its refusal blamed the settling) and
    a run of more than 2,000,000 samples (--plant-rate 1e7 fitted 15 million
    for hours)."""
    binary = str(REPO_ROOT / "target" / "release" / "piezo-identify")
    for extra, said in (
            (["--plant-rate", "3"],
             "--plant-rate 3 Hz samples the 2 Hz sine 1.500 times a period; give 20 or more"),
            (["--plant-rate", "1e7"],
             "--periods 3 of the 2 Hz sine at --plant-rate 10000000 Hz make 15000000 samples; "
             "at most 2000000 are fitted (fewer periods or a lower rate)")):
        done = subprocess.run([binary, "bouc-wen", "--plant", str(PLANT), *extra],
                              capture_output=True, text=True, timeout=60)
        assert done.returncode == 2, done.stderr
        assert done.stderr.strip() == said, done.stderr


def test_a_plant_run_beyond_the_amplifier_is_refused():
    """`bouc-wen --plant` refuses, before the run, a --peak the plant's
    amplifier would clip (--peak 1000 fitted a saturated record with exit
    0): on the 3-DOF stage its input range ends at 13 V, on the XY200S its
    150 V output at gain 15 ends the command at 10 V, the default peak."""
    binary = str(REPO_ROOT / "target" / "release" / "piezo-identify")
    xy200s = str(REPO_ROOT / "dist" / "presets" / "FlexureStage.xy200s.json")
    for extra, said in (
            (["--peak", "1000"], "amplifier.input_max is 13 V"),
            (["--peak", "13.5"], "amplifier.input_max is 13 V"),
            (["--plant-parameters", xy200s, "--peak", "10.5"],
             "amplifier.v_max 150 V at amplifier.gain 15 is a command of 10 V")):
        done = subprocess.run([binary, "bouc-wen", "--plant", str(PLANT), *extra],
                              capture_output=True, text=True, timeout=60)
        assert done.returncode == 2, done.stderr
        assert done.stderr.strip() == (
            f"--peak {extra[-1]} V is beyond what the plant's amplifier follows: {said}; the "
            "sine would be clipped there, and the record would not be the drive it claims"), \
            done.stderr
        assert done.stdout == ""


def test_a_parameter_set_with_a_byte_order_mark_is_read(tmp_path):
    """A sweep's parameter set saved with a byte-order mark reads as its
    twin without one, as piezo-cosim reads it (json.loads refused it)."""
    (tmp_path / "noise.json").write_text('{"noise.seed": 7}', encoding="utf-8-sig")
    spec = tmp_path / "tiny.toml"
    spec.write_text(SPEC.replace(f'path = "{PLANT}"',
                                 f'path = "{PLANT}"\nparameter_sets = ["noise.json"]'))
    runs, _ = sweep.expand(sweep.load_spec(spec))
    assert len(runs) == 1
