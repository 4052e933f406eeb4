"""README's "Your fitted models in PiezoController": its blocks run from the
repository's root as a user pastes them (a real P-885 record fitted by
`piezo-identify`, the fits merged into the `stage` controller preset, the
preset turned into a set by FMI name), and PiezoController, loaded with that
set, gives for a demand the voltage the fitted model gives for it:

- the `inverse-pi` fit: `u2_ff` and `u3_ff` equal the tool's `--predictions`
  (the same model, evaluated by the same `piezo_models::ModifiedInversePi`),
  one communication step later, for the record's displacement measured from
  the model's zero;
- the `bouc-wen` fit (`hysteresis_model = 2`, eq. 6): driven by the fitted
  model's own displacement for the record's voltage, `u2_ff` gives that
  voltage back, once the start's difference has settled; with the preset's
  `bouc_wen.rest_cycle` left at its value instead of the fit's 0 it does not,
  which is why the README says to set it.
"""

from __future__ import annotations

import csv
import json
import re
import subprocess
import sys

import fmpy
import numpy as np
import pytest

from tests.conftest import REPO_ROOT

README = REPO_ROOT / "README.md"
CONTROLLER = REPO_ROOT / "dist" / "PiezoController.fmu"
OWN = REPO_ROOT / "out" / "own"
FEEDFORWARD_ONLY = {"feedback_x": False, "feedback_y": False, "feedback_theta": False,
                    "decoupling": False}
# The two evaluate eq. (3) with different steps (the tool's RK4 substeps per
# input unit, the controller's SIMULATE_MAX_DU): 6.4e-9 V apart on this record
# for the README's --monotone fit, 2.5e-7 V for the fit without it.
BOUC_WEN_ROUND_TRIP_V = 1e-6
# The controller starts the inverse from 0 V, the tool's fit from the
# record's first sample (1.8 V, mid-cycle); that difference dies out within
# the record's first two 1 Hz cycles (the last sample off by more than 1e-6 V
# is at 1.8 s).
SETTLED_AFTER_S = 2.0


def readme_blocks() -> list[tuple[str, str]]:
    text = README.read_text(encoding="utf-8")
    start = text.index("### Your fitted models in PiezoController")
    section = text[start:text.index("\n### ", start + 1)]
    return re.findall(r"^```(sh|python)\n(.*?)^```$", section, re.MULTILINE | re.DOTALL)


@pytest.fixture(scope="module")
def own_set():
    """Runs the README's blocks; the set they make, by FMI name."""
    for path in (CONTROLLER, REPO_ROOT / "target" / "release" / "piezo-identify",
                 REPO_ROOT / "target" / "release" / "piezo-controller-parameters"):
        if not path.is_file():
            pytest.fail(f"{path} is missing: run `make fmus`", pytrace=False)
    blocks = readme_blocks()
    assert [language for language, _ in blocks] == ["sh", "python", "sh"], blocks
    for language, code in blocks:
        runner = [sys.executable, "-c"] if language == "python" else ["bash", "-euo", "pipefail", "-c"]
        done = subprocess.run([*runner, code], cwd=REPO_ROOT, capture_output=True, text=True)
        assert done.returncode == 0, f"{code}\n{done.stdout[-2000:]}\n{done.stderr[-3000:]}"
    return json.loads((OWN / "PiezoController.mine.json").read_text())


def fit_with_predictions(command: str, tmp_path, name: str) -> tuple[dict, dict]:
    """The README's fit, again with `--predictions` (the same model: the fit
    is deterministic for its seed): its model file and its columns."""
    sh = readme_blocks()[0][1]
    line = next(row for row in sh.splitlines() if row.startswith(f"$B {command} "))
    record = "piezo-identify/tests/data/piezo-p885/Model_Vi_Do.dat"
    arguments = line.split()[2:]
    arguments = [record if a == "$R" else a for a in arguments]
    arguments = [str(tmp_path / f"{name}.json") if a.startswith("out/own/") else a
                 for a in arguments]
    done = subprocess.run([str(REPO_ROOT / "target" / "release" / "piezo-identify"), command,
                           *arguments, "--predictions", str(tmp_path / f"{name}.csv")],
                          cwd=REPO_ROOT, capture_output=True, text=True)
    assert done.returncode == 0, done.stderr
    rows = list(csv.DictReader(open(tmp_path / f"{name}.csv")))
    columns = {key: np.array([float(r[key]) for r in rows]) for key in rows[0] if key != "part"}
    return json.loads((tmp_path / f"{name}.json").read_text()), columns


def run_controller(start: dict, x_ref: np.ndarray, dt: float) -> dict:
    t = np.arange(len(x_ref)) * dt
    signals = np.zeros(len(t), dtype=[("time", float), ("x_ref", float)])
    signals["time"], signals["x_ref"] = t, x_ref
    return fmpy.simulate_fmu(str(CONTROLLER), start_values=start | FEEDFORWARD_ONLY,
                             input=signals, step_size=dt, output_interval=dt, stop_time=t[-1],
                             output=["u2_ff", "u3_ff"])


def centred_moving_average(y: np.ndarray, half_width: int) -> np.ndarray:
    """`piezo_identify::validation::smoothed_between_steps` of a record without
    voltage steps: the window shrinks on both sides at the ends, centred."""
    n = np.arange(len(y))
    reach = np.minimum(np.minimum(n, len(y) - 1 - n), half_width)
    low, high = n - reach, n + reach + 1
    sums = np.concatenate([[0.0], np.cumsum(y)])
    return (sums[high] - sums[low]) / (high - low)


def test_the_inverse_pi_fit_runs_in_the_controller_as_fitted(own_set, tmp_path):
    model, columns = fit_with_predictions("inverse-pi", tmp_path, "x_inverse_pi")
    assert model["params"] == json.loads((OWN / "x_inverse_pi.json").read_text())["params"]
    # The model's input: the displacement smoothed as the fit smoothed it
    # (the record has no voltage steps), from the model's zero.
    x_ref = (centred_moving_average(columns["displacement_um"],
                                    model["smoothing_half_width_samples"])
             - model["displacement_offset_um"])
    run = run_controller(own_set, x_ref, model["sample_period_s"])
    # A communication step's outputs are those of the inputs at its start.
    expected = columns["proposed_v"][:-1]
    print(f"inverse-pi: u2_ff off the tool's predictions by at most "
          f"{np.abs(run['u2_ff'][1:] - expected).max():.2e} V")
    assert np.abs(run["u2_ff"][1:] - expected).max() <= 1e-9
    assert np.abs(run["u3_ff"][1:] - expected).max() <= 1e-9
    assert np.ptp(expected) > 3.0  # the record's whole 0..3.6 V, not a corner of it


def test_the_feedback_counts_from_the_fits_zero(own_set, tmp_path):
    """The record's raw readings as s2 and s3 (the P-885 sensor reads about
    -96 um at the model's zero) and the same displacement from the model's
    zero as x_ref: with the README's sensor offsets the x PI law sees only
    the record's noise about its smoothing; without them, the whole offset,
    which the feedback would drive out against the feedforward."""
    model, columns = fit_with_predictions("inverse-pi", tmp_path, "x_inverse_pi")
    offset = model["displacement_offset_um"]
    assert own_set["sensor_offset[2]"] == own_set["sensor_offset[3]"] == offset
    raw = columns["displacement_um"]
    x_ref = centred_moving_average(raw, model["smoothing_half_width_samples"]) - offset
    dt = model["sample_period_s"]
    t = np.arange(len(x_ref)) * dt
    signals = np.zeros(len(t), dtype=[("time", float), ("x_ref", float), ("s2", float),
                                      ("s3", float)])
    signals["time"], signals["x_ref"], signals["s2"], signals["s3"] = t, x_ref, raw, raw

    def e_x(start: dict) -> np.ndarray:
        run = fmpy.simulate_fmu(str(CONTROLLER), start_values=start | FEEDFORWARD_ONLY,
                                input=signals, step_size=dt, output_interval=dt,
                                stop_time=t[-1], output=["e_x"])
        return run["e_x"][1:]  # a step's outputs are those of its start's inputs

    with_offsets = e_x(own_set)
    rms = np.sqrt(np.mean(with_offsets ** 2))
    print(f"e_x with the fit's zero as sensor offsets: RMS {rms:.3f} um "
          f"(the fit's offset {offset:.3f} um)")
    # What is left is the record's noise about its moving average (0.067 um
    # RMS away from the ends, where the window shrinks): a tenth of a
    # micrometre, against the offset's hundred.
    assert rms < 0.1
    without = e_x(own_set | {f"sensor_offset[{k}]": 0.0 for k in (1, 2, 3)})
    assert np.abs(np.median(without) + offset) < 0.1, np.median(without)


def test_the_bouc_wen_fit_inverts_to_the_voltage_it_was_fitted_for(own_set, tmp_path):
    model, columns = fit_with_predictions("bouc-wen", tmp_path, "x_bouc_wen")
    assert model["params"] == json.loads((OWN / "x_bouc_wen.json").read_text())["params"]
    x_ref = columns["bouc_wen_um"] - model["sensor_offset_um"]
    dt = model["sample_period_s"]
    settled = np.arange(len(x_ref) - 1) * dt >= SETTLED_AFTER_S
    voltage = columns["voltage_v"][:-1]
    as_set = own_set | {"hysteresis_model": 2}
    assert as_set["bouc_wen.rest_cycle"] == 0.0
    error = run_controller(as_set, x_ref, dt)["u2_ff"][1:] - voltage
    print(f"bouc-wen: u2_ff off the record's voltage by at most {np.abs(error[settled]).max():.2e} V "
          f"after {SETTLED_AFTER_S} s")
    assert np.abs(error[settled]).max() <= BOUC_WEN_ROUND_TRIP_V
    # The stage preset's rest (its models were fitted from a cycled rest):
    # the fit's model started from the wrong state, off by percent of the span.
    stage_rest = json.loads(
        (REPO_ROOT / "piezo-models" / "presets" / "piezo_controller_stage.json").read_text()
    )["bouc_wen"]["rest_cycle"]
    wrong = run_controller(as_set | {"bouc_wen.rest_cycle": stage_rest}, x_ref, dt)
    off = np.abs(wrong["u2_ff"][1:] - voltage)[settled].max()
    print(f"bouc-wen with the stage preset's rest_cycle {stage_rest}: off by "
          f"{100 * off / np.ptp(voltage):.1f} % of the span")
    assert off > 0.01 * np.ptp(voltage), off
