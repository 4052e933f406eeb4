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

from demo import matrix
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
