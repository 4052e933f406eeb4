"""Helper run in a separate process by test_fmpy_importer.py (not a test module).

Subcommands (each prints one JSON object on stdout):

restore-state --fmu F --state-file S --time-hex T --steps N --step-hex H --inputs-hex A,B,C
    Loads the FMU in this fresh process, initializes an instance with default
    parameters, deserializes the bytes of S, sets the state, then runs N/2 steps
    with the inputs held in the state, sets the inputs A, B, C and runs the
    remaining steps. Prints the outputs after each step as float.hex() strings.

percent-log --fmu F
    Instantiates the FMU with instanceName "probe%s" and a logger routed through
    fmpy's native printf proxy (fmpy.logging.addLoggerProxy, the path fmpy's own
    default logger takes), turns logFmiCalls on, triggers a warning whose text
    contains '%' and prints every message as the importer received it. If the
    FMU did not escape '%', vsnprintf would read non-existent arguments.
"""

from __future__ import annotations

import argparse
import json
import shutil
import sys
import tempfile
from ctypes import byref

import fmpy
from fmpy import fmi2
from fmpy.fmi1 import FMICallException

OUTPUTS = ("s1", "s2", "s3", "x", "y", "theta_z")


class Logged:
    def __init__(self):
        self.records = []
        self.logger = fmi2.fmi2CallbackLoggerTYPE(self._log)
        self.callbacks = fmi2.fmi2CallbackFunctions()
        self.callbacks.logger = self.logger
        self.callbacks.allocateMemory = fmi2.fmi2CallbackAllocateMemoryTYPE(fmpy.calloc)
        self.callbacks.freeMemory = fmi2.fmi2CallbackFreeMemoryTYPE(fmpy.free)

    def _log(self, env, name, status, category, message):
        self.records.append(
            {
                "instance": name.decode("utf-8", "replace") if name else None,
                "status": status,
                "category": category.decode("utf-8", "replace") if category else None,
                "message": message.decode("utf-8", "replace") if message else None,
            }
        )


def load(fmu_path: str, instance_name: str):
    md = fmpy.read_model_description(fmu_path)
    unzip = fmpy.extract(fmu_path, unzipdir=tempfile.mkdtemp(prefix="flexure_child_"))
    fmu = fmi2.FMU2Slave(
        guid=md.guid,
        unzipDirectory=unzip,
        modelIdentifier=md.coSimulation.modelIdentifier,
        instanceName=instance_name,
    )
    vrs = {v.name: v.valueReference for v in md.modelVariables}
    return md, unzip, fmu, vrs


def restore_state(args) -> dict:
    md, unzip, fmu, vrs = load(args.fmu, "child")
    log = Logged()
    out: dict = {"log": log.records}
    try:
        fmu.instantiate(callbacks=log.callbacks, loggingOn=False)
        fmu.setupExperiment(startTime=0.0)
        fmu.enterInitializationMode()
        fmu.exitInitializationMode()
        with open(args.state_file, "rb") as f:
            data = f.read()
        state = fmu.deSerializeFMUstate(data)
        fmu.setFMUstate(state)
        fmu.freeFMUstate(state)
        out["restored_time"] = fmu.getRealStatus(fmi2.fmi2LastSuccessfulTime).hex()
        t = float.fromhex(args.time_hex)
        h = float.fromhex(args.step_hex)
        new_inputs = [float.fromhex(v) for v in args.inputs_hex.split(",")]
        out_vrs = [vrs[n] for n in OUTPUTS]
        rows = []
        for k in range(args.steps):
            if k == args.steps // 2:
                fmu.setReal([vrs["u1"], vrs["u2"], vrs["u3"]], new_inputs)
            fmu.doStep(t, h)
            t = t + h
            rows.append([v.hex() for v in fmu.getReal(out_vrs)])
        out["rows"] = rows
        fmu.terminate()
        fmu.freeInstance()
    except FMICallException as e:
        out["error"] = str(e)
    finally:
        shutil.rmtree(unzip, ignore_errors=True)
    return out


def percent_log(args) -> dict:
    from fmpy.logging import addLoggerProxy

    md, unzip, fmu, vrs = load(args.fmu, "probe%s")
    log = Logged()
    # Route this callbacks struct through fmpy's native proxy, which formats
    # the message with vsnprintf before handing it to the Python logger.
    addLoggerProxy(byref(log.callbacks))
    out: dict = {"log": log.records}
    try:
        fmu.instantiate(callbacks=log.callbacks, loggingOn=True)
        fmu.setDebugLogging(True, ["logFmiCalls"])
        categories = (fmi2.fmi2String * 1)(b"log%s%d")
        out["set_debug_logging_status"] = fmu.fmi2SetDebugLogging(fmu.component, 1, 1, categories)
        fmu.setupExperiment(startTime=0.0)
        fmu.enterInitializationMode()
        fmu.exitInitializationMode()
        fmu.doStep(0.0, 1e-4)
        fmu.terminate()
        fmu.freeInstance()
    except FMICallException as e:
        out["error"] = str(e)
    finally:
        shutil.rmtree(unzip, ignore_errors=True)
    return out


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__)
    sub = parser.add_subparsers(dest="command", required=True)
    p = sub.add_parser("restore-state")
    p.add_argument("--fmu", required=True)
    p.add_argument("--state-file", required=True)
    p.add_argument("--time-hex", required=True)
    p.add_argument("--step-hex", required=True)
    p.add_argument("--steps", type=int, required=True)
    p.add_argument("--inputs-hex", required=True)
    p = sub.add_parser("percent-log")
    p.add_argument("--fmu", required=True)
    args = parser.parse_args(argv)
    result = restore_state(args) if args.command == "restore-state" else percent_log(args)
    sys.stdout.write(json.dumps(result) + "\n")
    sys.stdout.flush()
    return 0


if __name__ == "__main__":
    sys.exit(main())
