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
import pathlib
import sys
from ctypes import byref

from fmpy import fmi2
from fmpy.fmi1 import FMICallException

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parent.parent))
from demo.fmu import Fmu, Instance, LogCapture  # noqa: E402

OUTPUTS = ("s1", "s2", "s3", "x", "y", "theta_z")


def records(log) -> list[dict]:
    """The messages as the importer received them."""
    return [{"instance": r.instance_name, "status": r.status, "category": r.category,
             "message": r.raw} for r in log.records]


def restore_state(args) -> dict:
    out: dict = {}
    with Fmu(args.fmu) as fmu:
        s = fmu.instantiate("child")
        try:
            s.initialize()
            s.restore_bytes(pathlib.Path(args.state_file).read_bytes())
            out["restored_time"] = s.last_successful_time().hex()
            s.time = float.fromhex(args.time_hex)
            h = float.fromhex(args.step_hex)
            new_inputs = [float.fromhex(v) for v in args.inputs_hex.split(",")]
            rows = []
            for k in range(args.steps):
                if k == args.steps // 2:
                    s.set_real(dict(zip(("u1", "u2", "u3"), new_inputs)))
                s.fmu.doStep(s.time, h)
                s.time = s.time + h
                rows.append([v.hex() for v in s.get(*OUTPUTS)])
            out["rows"] = rows
            s.fmu.terminate()
        except FMICallException as e:
            out["error"] = str(e)
        finally:
            s.free()
            out["log"] = records(s.log)
    return out


def percent_log(args) -> dict:
    from fmpy.logging import addLoggerProxy

    out: dict = {}
    with Fmu(args.fmu) as fmu:
        slave = fmu.load("probe%s")
        log = LogCapture()
        # Route this callbacks struct through fmpy's native proxy, which
        # formats the message with vsnprintf before handing it to the
        # Python logger.
        addLoggerProxy(byref(log.callbacks))
        s = Instance(fmu, slave, log)
        try:
            slave.instantiate(callbacks=log.callbacks, loggingOn=True)
            slave.setDebugLogging(True, ["logFmiCalls"])
            categories = (fmi2.fmi2String * 1)(b"log%s%d")
            out["set_debug_logging_status"] = slave.fmi2SetDebugLogging(
                slave.component, 1, 1, categories)
            s.initialize()
            s.fmu.doStep(0.0, 1e-4)
            s.fmu.terminate()
        except FMICallException as e:
            out["error"] = str(e)
        finally:
            s.free()
            out["log"] = records(log)
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
