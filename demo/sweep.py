"""Sweeps and Monte Carlo studies of the closed loop on dask.distributed.

    python -m demo.sweep SPEC.toml [SPEC.toml ...] --out DIR
                         [--scheduler tcp://HOST:PORT] [--workers N]
                         [--restart] [--progress auto|bar|lines|none] [--no-report]

A spec (demo/sweeps/*.toml) is data: a scenario template for the compiled
master (piezo-cosim), the variables of a grid (numbers, or named cases that
patch the template), optionally a Monte Carlo over the plant's parameters.
The expanded runs go to dask in tasks of up to `runs_per_task` runs (default
10, fewer when the workers would otherwise run out of tasks), each task one
master process (`piezo-cosim batch`) that returns one row per run; the rows
land in DIR/<study>.parquet, one per run: every swept value, the seed (the
plant's noise.seed in that run: a Monte Carlo sample's draw where the spec's
`seed_parameter` gives it, else the scenario's own; empty where the scenario
sets none and the FMU's start value holds), the metrics, the wall time,
each column's unit (where it has one) in its Arrow field's metadata
(b"unit": the FMUs' units for variables, the master's for metrics,
`piezo-cosim metrics`).

- Runs go to a LocalCluster of N worker processes (default: one per core), or
  to an existing cluster (`dask scheduler`, `dask worker`) with --scheduler.
  The FMUs and the reference tables travel with the tasks (scattered to the
  workers, written into each worker's temporary folder); parameter sets are
  read here and sent as values, so no shared filesystem is assumed. The scheduler and every worker
  need this package importable (the scheduler unpickles the tasks, which
  name its functions), the workers also demo/bin/piezo-cosim (`make
  master`): start them from a checkout with PYTHONPATH set to it.
- A run is a pure function of its scenario (spec, sample seed), whichever
  task runs it: its key is a hash of the scenario with the contents of its
  FMUs and reference tables (an edited table makes new runs). A
  task rescheduled after a worker dies gives the same rows (a task whose
  worker died with the only copy of the FMUs is sent again, the FMUs
  scattered anew), and the table keeps each key once; two grid points that
  make one scenario are refused. A run
  that exceeds the spec's `timeout` is a row with status "timeout" and runs
  again at the next invocation (a loaded machine, not the run, may be why).
- Rows are journalled to DIR/<study>.journal.jsonl as they arrive; an
  interrupted sweep (Ctrl-C, a lost client) is folded into the table, and the
  same command skips every run already in it. Ctrl-C ends the command with
  one line, the runs kept and how to resume, and exit status 130.
- A cluster that cannot run the study is named in a message with what to do,
  exit status 3 (ClusterError): a scheduler address refused or unknown, at
  once; no worker within WORKER_WAIT_S; a scheduler or every worker that
  cannot import this package or fmpy or find the master, before any task
  (the workers that can run the tasks get them); runs lost with the workers.
  Runs that failed or timed out end the command with status 1.
- A spec that does not fit is refused before any run, with its file, line and
  problem (exit status 2): the master checks a scenario of every combination
  of named cases and one per further value of each variable. So is an --out
  that names a file, or holds a study's table that cannot be read (the file
  is left as it is, with --restart too).
- A table holds the runs of its spec as it is now: a kept row is numbered and
  named as a fresh sweep of the spec would write it (a grid extended since
  runs its new points only); the failed or timed-out rows of runs the spec no
  longer makes (a value fixed after it failed) are dropped, and a row with a
  result of such a run is refused (StaleTable: --restart, or another --out).
"""

from __future__ import annotations

import argparse
import ast
import atexit
import contextlib
import copy
import functools
import hashlib
import io
import itertools
import json
import math
import os
import re
import shlex
import shutil
import signal
import socket
import subprocess
import sys
import tempfile
import threading
import time
import tomllib
import zipfile
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from . import master


def lost_task_hint(error: BaseException) -> str:
    """What to do about a task that could not run, or a scheduler or worker
    that cannot run one, where the error says."""
    text = str(error)
    if "deserializ" in text or "No module named 'demo'" in text:
        return ("\n  If the scheduler or a worker cannot import this repository's `demo` package "
                "(the usual cause), start `dask scheduler` and `dask worker` from a checkout with "
                "PYTHONPATH set to it (README, \"Sweeps on dask\").")
    missing = re.search(r"No module named '?([\w.]+)", text)
    if missing:
        return (f"\n  The package {missing.group(1)!r} is missing there: start `dask scheduler` "
                f"and `dask worker` with this checkout's venv (.venv/bin/dask, `make venv`) and "
                f"PYTHONPATH set to the checkout (README, \"Sweeps on dask\").")
    return ""


class ClusterError(RuntimeError):
    """The cluster cannot run a study: its scheduler unreachable, no worker
    joined, a scheduler or workers that cannot run the tasks, or runs lost
    with their workers. The command ends with this one message and exit
    status EXIT_CLUSTER; the same command resumes once the cluster is
    fixed."""


#: The exit status of a command whose cluster could not run its runs
#: (ClusterError): neither runs that failed (1) nor a spec (2).
EXIT_CLUSTER = 3
#: Seconds a study waits for a first worker on a scheduler that has none
#: (workers started with it may still be connecting).
WORKER_WAIT_S = 10.0
#: Seconds a scheduler has to answer once its port takes a connection.
CONNECT_TIMEOUT_S = 10.0
#: What every worker runs before a study's tasks go out: the imports and the
#: master a task needs. A worker that cannot unpickle a task dies with the
#: connection to its scheduler (its nanny does not restart it), and the
#: study waited 30 s for a worker, then ended in a traceback; this names the
#: cause in a line. Run as exec's source: exec, a builtin, unpickles
#: anywhere.
WORKER_PROBE = "import fmpy, demo.sweep, demo.master; demo.master.binary()"
#: What the scheduler runs before a study: it unpickles the tasks.
SCHEDULER_PROBE = "import demo.sweep"


#: Columns that describe how a run was executed, not what it computed: they
#: differ between two executions of the same spec (everything else is equal).
EXECUTION_COLUMNS = ("wall_s", "task_s", "worker")

#: Seconds between two progress lines.
PROGRESS_SECONDS = 10.0
#: Seconds the end of a study waits for dask's progress bar to end its line.
BAR_END_SECONDS = 2.0

#: Most runs of one task by default: a task is one master process that opens
#: the FMUs once (about 3 ms of process and 1.4 ms of loading saved per run
#: after the first, and a tenth of the scheduler's traffic); `runs_per_task =
#: 1` in a spec gives each run its own process (FMUs that keep global state).
RUNS_PER_TASK = 10
# Times a task that could not run (its worker died, and with it the FMUs
# scattered there when no other worker held them) is sent again, with the
# FMUs scattered anew, before its runs are left for the next invocation.
TASK_RETRIES = 2
# The reports a spec may name (demo/sweep_report.py), and the variables each
# reads from every row: its tables are grouped by them, and the decoupling
# variable's cases are named "off" and "on". Any further variable of a spec
# splits a report's tables and figures by its values (a row or a figure per
# value), so that no two runs are summarised as one.
REPORT_VARIABLES = {
    "none": set(),
    "envelope": {"stage", "method", "axis", "held", "amplitude", "frequency", "decoupling"},
    "robustness": {"axis", "decoupling"},
}
# The table's own columns (execute_runs, expand): a variable by one of these
# names would overwrite them, and the rows would lose its values or their keys.
RESERVED_COLUMNS = {"run", "key", "status", "error", "steps", "simulated_s", "warnings",
                    "wall_s", "task_s", "worker", "seed", "sample"}
#: The units of the table's own columns that hold a quantity ("1": a count);
#: the others (run, key, status, error, worker, seed, sample) name or number
#: a run and have none.
OWN_COLUMN_UNITS = {"steps": "1", "simulated_s": "s", "warnings": "1", "wall_s": "s",
                    "task_s": "s"}
#: A Monte Carlo factor (factor.<parameter>) is a ratio to the nominal value.
FACTOR_UNIT = "1"
_METRIC_DEFINITIONS: dict | None = None


def metric_definitions() -> dict:
    """Every metric the master writes: {name: {"unit", "range",
    "description"}} (`piezo-cosim metrics`; names and units are written in
    its metrics.rs only). A figure of the driven axis has its unit by axis,
    {"x": "um", "y": "um", "theta": "rad"}; a range is a [min, max] pair,
    two columns in the table (flatten_metrics)."""
    global _METRIC_DEFINITIONS
    if _METRIC_DEFINITIONS is None:
        _METRIC_DEFINITIONS = master.metrics()
    return _METRIC_DEFINITIONS


def metric_columns_of(metric: str) -> list[str]:
    """The table's columns of a metric: its name, or <name>_min and
    <name>_max for a range."""
    if metric_definitions()[metric]["range"]:
        return [f"{metric}_min", f"{metric}_max"]
    return [metric]


class SpecError(ValueError):
    """A malformed spec, with its file and (where it can be found) line."""


# --------------------------------------------------------------------------
# Specs

@dataclass
class Case:
    """A named value of a categorical variable: the numbers it defines for
    expressions, and a patch merged into the scenario template."""

    name: str
    vars: dict = field(default_factory=dict)
    patch: dict = field(default_factory=dict)


@dataclass
class Variable:
    name: str
    values: list  # numbers, or Case


@dataclass
class Vary:
    """A group of plant parameters perturbed by a uniform factor in
    [1 - relative, 1 + relative]."""

    pattern: re.Pattern
    relative: float


@dataclass
class MonteCarlo:
    samples: int
    instance: str
    vary: list[Vary]
    seed_parameter: str | None


@dataclass
class Spec:
    path: Path
    text: str
    study: str
    title: str
    report: str
    seed: int
    timeout: float | None
    template: dict
    variables: list[Variable]
    exclude: list[dict]
    monte_carlo: MonteCarlo | None
    report_options: dict
    #: Most runs one task (one master process) executes.
    runs_per_task: int = RUNS_PER_TASK

    def file(self, name: str) -> Path:
        """A file the spec names (an FMU, a parameter set, a reference
        table), relative to its folder."""
        return (self.path.parent / name).resolve()


def _line_of(text: str, needle: str) -> int | None:
    """The first line holding `needle` as a whole name (so a line with
    `relativ` wins over an earlier one with `relative`), else the first line
    holding it at all."""
    lines = text.splitlines()
    whole = re.compile(rf"(?<![\w]){re.escape(needle)}(?![\w])")
    for found in (lambda line: whole.search(line), lambda line: needle in line):
        for number, line in enumerate(lines, 1):
            if found(line):
                return number
    return None


def _quoted(text: str, name: str) -> str:
    """The needle that finds a variable's `name = "..."` line, rather than an
    expression or an earlier key that holds the same word."""
    return next((q for q in (f'"{name}"', f"'{name}'") if q in text), name)


def _fail(spec_path: Path, text: str, needle: str | int | None, problem: str) -> SpecError:
    """The error of `problem` at the line of `needle` (a word to find, or a
    line number already found)."""
    if isinstance(needle, int) and not isinstance(needle, bool):
        line = needle
    else:
        line = _line_of(text, needle) if needle else None
    where = f"{spec_path}:{line}" if line else f"{spec_path}"
    return SpecError(f"{where}: {problem}")


_HEADER = re.compile(r"^\s*\[\[?([^\[\]]*)\]\]?\s*(#.*)?$")


class _SpecLines:
    """Where a key is written in a spec's TOML text, for messages: inside the
    table it belongs to, so that `seed` is found at the top level and not in
    a comment or in `"noise.seed"`, and `relative` in the Monte Carlo group
    that gives it."""

    def __init__(self, text: str):
        self.text = text
        self.lines = text.splitlines()

    def header(self, number: int) -> str | None:
        """The dotted name of the table a header line opens ([a.b] or
        [[a.b]], quotes and spaces left out), None for any other line."""
        found = _HEADER.match(self.lines[number - 1])
        return re.sub(r"[\s\"']", "", found.group(1)) if found else None

    def table(self, name: str, index: int = 0,
              within: tuple[int, int] | None = None) -> tuple[int, int] | None:
        """First and last line of the `index`-th table `name` (a [name] or a
        [[name]] header, with its subtables), searched `within` a span of
        lines; None when it is not written as a header there."""
        first, last = within or (1, len(self.lines))
        starts = [n for n in range(first, last + 1) if self.header(n) == name]
        if index >= len(starts):
            return None
        start = starts[index]
        for n in range(start + 1, last + 1):
            header = self.header(n)
            if header is not None and not header.startswith(name + "."):
                return start, n - 1
        return start, last

    def table_or_key(self, name: str) -> tuple[int, int] | None:
        """The lines of table `name` of the top level: its header's, or the
        line of its key when it is written inline (`name = { ... }`)."""
        span = self.table(name)
        if span is not None:
            return span
        line = self.key(name)
        return (line, line) if line else None

    def top(self) -> tuple[int, int]:
        """The top-level keys' lines: those before the first header."""
        first_header = next((n for n in range(1, len(self.lines) + 1)
                             if self.header(n) is not None), len(self.lines) + 1)
        return 1, first_header - 1

    def key(self, key: str, span: tuple[int, int] | None = None) -> int | None:
        """The line that sets `key` in `span` (default: the top level):
        `key = `, `"key" = ` or a dotted `key.sub = `; else the first line of
        the span holding the key as a whole word (a dotted key, `a.b`, as
        the end of a longer one: `patch.a.b = `), else the span's first line
        (its header: the key is missing there); at the top level, else the
        first line of the text holding the key."""
        first, last = span or self.top()
        name = re.escape(key)
        sets = re.compile(rf"^\s*(?:{name}|\"{name}\"|'{name}')\s*[.=]")
        whole = re.compile(rf"(?<![\w.\"']){name}(?![\w\"'])")
        # The end of a dotted key (`patch.fmu.plant.parameters = ...`).
        dotted = re.compile(rf"(?<![\w\"']){name}(?![\w\"'])")
        for found in (sets.search, whole.search, dotted.search):
            for n in range(first, last + 1):
                if found(self.lines[n - 1]):
                    return n
        if span is not None:
            return first
        return _line_of(self.text, key)


def _is_number(value) -> bool:
    """A finite number; TOML's true and false are not numbers here (Python's
    bool is an int)."""
    return (isinstance(value, (int, float)) and not isinstance(value, bool)
            and math.isfinite(value))


def _is_whole(value) -> bool:
    return isinstance(value, int) and not isinstance(value, bool)


def _is_tables(value) -> bool:
    """An array of tables, as [[name]] headers write it."""
    return isinstance(value, list) and all(isinstance(item, dict) for item in value)


def _shown(value) -> str:
    """A value as a message names it: as TOML writes a scalar, an array or a
    table by its kind."""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, dict):
        return "(a table)"
    if isinstance(value, list):
        return "(an array of tables)" if value and _is_tables(value) else "(an array)"
    shown = repr(value)
    return shown if len(shown) <= 60 else shown[:57] + "..."


SPEC_KEYS = {"study", "title", "report", "seed", "timeout", "template", "variable", "exclude",
             "monte_carlo", "report_options", "runs_per_task"}
#: What [report_options] may set, with the envelope report's defaults: the
#: largest tracking RMS as a share of the demanded amplitude, the smallest
#: reduction of a coupling span by decoupling for a point to hold.
REPORT_OPTIONS = {"tracking_limit": 0.05, "reduction_limit": 2.0}


def _check_fmu_entries(fmu, label: str, fail_at) -> None:
    """The FMU entries of a template or a patch, in the types this module
    reads before the master sees them (a path, parameter sets, parameter
    values by name); `fail_at(keys, problem)` makes the error at the line
    of the keys' path (("fmu", instance, key))."""
    if not isinstance(fmu, dict):
        raise fail_at(("fmu",), f"{label}fmu {_shown(fmu)}: a table of FMUs by instance name")
    for instance, entry in fmu.items():
        where = f"{label}fmu.{instance}"
        if not isinstance(entry, dict):
            raise fail_at(("fmu", instance), f"{where} {_shown(entry)}: a table with path, "
                                             f"parameter_sets and parameters")
        if "path" in entry and not isinstance(entry["path"], str):
            raise fail_at(("fmu", instance, "path"),
                          f"{where}.path {_shown(entry['path'])}: a file name in quotes")
        sets = entry.get("parameter_sets", [])
        if not isinstance(sets, list) or not all(isinstance(s, str) for s in sets):
            raise fail_at(("fmu", instance, "parameter_sets"),
                          f"{where}.parameter_sets {_shown(sets)}: an array of file names in "
                          f"quotes")
        if not isinstance(entry.get("parameters", {}), dict):
            raise fail_at(("fmu", instance, "parameters"),
                          f"{where}.parameters {_shown(entry['parameters'])}: a table of values "
                          f"by FMI name")


def load_spec(path: str | Path) -> Spec:
    """Reads and checks a spec file."""
    path = Path(path)
    try:
        text = path.read_text()
    except OSError as e:
        raise SpecError(f"{path}: {e.strerror}") from None
    # A byte-order mark, as some Windows editors start a UTF-8 file with:
    # tomllib refuses it ("1:1: Invalid statement"), and the Rust tools
    # skip it. Dropping it moves no line or column.
    text = text.removeprefix("\ufeff")
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as e:
        # tomllib's message ends with "(at line L, column C)".
        found = re.search(r"\(at line (\d+), column (\d+)\)", str(e))
        if found:
            where = f"{path}:{found.group(1)}:{found.group(2)}"
        elif "end of document" in str(e):
            where = f"{path}:{len(text.splitlines())}"
        else:
            where = str(path)
        problem = re.sub(r"\s*\(at (line \d+, column \d+|end of document)\)", "", str(e))
        raise SpecError(f"{where}: {problem}") from None
    lines = _SpecLines(text)

    def fail(needle, problem):
        return _fail(path, text, needle, problem)

    def fail_at(key, problem, span=None):
        """The error at the line that sets `key` in `span` (the top level)."""
        return fail(lines.key(key, span), problem)

    unknown = set(data) - SPEC_KEYS
    if unknown:
        key = sorted(unknown)[0]
        raise fail_at(key, f"unknown key {key!r} (known: {', '.join(sorted(SPEC_KEYS))})")
    for key in ("study", "template"):
        if key not in data:
            raise fail(None, f"missing {key!r}")
    study = data["study"]
    if not isinstance(study, str):
        raise fail_at("study", f"study {_shown(study)}: a name in quotes (letters, digits, "
                               f"'_', '-', '.')")
    if not re.fullmatch(r"[A-Za-z0-9_.-]+", study):
        raise fail_at("study", f"study {study!r}: use letters, digits, '_', '-', '.'")
    title = data.get("title", study)
    if not isinstance(title, str):
        raise fail_at("title", f"title {_shown(title)}: a text in quotes")
    seed = data.get("seed", 0)
    if not _is_whole(seed) or seed < 0:
        # numpy seeds its generators with whole numbers from 0 up.
        raise fail_at("seed", f"seed {_shown(seed)}: a whole number, at least 0")
    timeout = data.get("timeout")
    if timeout is not None and (not _is_number(timeout) or timeout <= 0):
        raise fail_at("timeout", f"timeout {_shown(timeout)}: a positive number of seconds")
    template = data["template"]
    template_span = lines.table_or_key("template")
    if not isinstance(template, dict):
        raise fail_at("template", f"template {_shown(template)}: a table ([template]), the "
                                  f"scenario every run starts from")
    if "fmu" in template:
        def fail_in_template(keys, problem):
            # An instance's own [template.fmu.<instance>] table, where it has one.
            instance_span = lines.table(f"template.{'.'.join(keys[:2])}") if len(keys) > 1 \
                else None
            return fail_at(keys[-1], problem, instance_span or template_span)

        _check_fmu_entries(template["fmu"], "template.", fail_in_template)

    variable_entries = data.get("variable", [])
    if not _is_tables(variable_entries):
        raise fail_at("variable", f"variable {_shown(variable_entries)}: an array of tables, "
                                  f"each a [[variable]] with name and values")
    variables = []
    for index, entry in enumerate(variable_entries):
        span = lines.table("variable", index)
        name = entry.get("name")
        extra = set(entry) - {"name", "values"}
        if extra:
            key = sorted(extra)[0]
            raise fail_at(key, f"variable {name!r}: unknown key {key!r} (a variable has name "
                               f"and values)", span)
        if "name" not in entry or "values" not in entry:
            raise fail(span[0] if span else "[[variable]]",
                       "every [[variable]] needs a name and values")
        if not isinstance(name, str) or not name:
            raise fail_at("name", f"variable name {_shown(name)}: a name in quotes", span)
        values = entry["values"]
        if isinstance(values, dict) and values:
            cases = []
            for case_name, case in values.items():
                case_span = lines.table(f"variable.values.{case_name}", within=span) or span
                if not isinstance(case, dict):
                    raise fail_at(case_name, f"case {name}.{case_name} {_shown(case)}: a table "
                                             f"with vars and patch (values is an array of "
                                             f"numbers or names, or a table of cases)", span)
                bad = set(case) - {"vars", "patch"}
                if bad:
                    raise fail(case_name, f"case {name}.{case_name}: unknown key "
                                          f"{sorted(bad)[0]!r} (a case has vars and patch)")
                case_vars = case.get("vars", {})
                if not isinstance(case_vars, dict):
                    raise fail_at("vars", f"case {name}.{case_name}: vars {_shown(case_vars)}: "
                                          f"a table of numbers by name", case_span)
                for var, value in case_vars.items():
                    # Case variables exist for expressions, which compute
                    # with numbers only.
                    if not _is_number(value):
                        raise fail_at(var, f"case {name}.{case_name}: vars.{var} "
                                           f"{_shown(value)}: a finite number", case_span)
                patch = case.get("patch", {})
                if not isinstance(patch, dict):
                    raise fail_at("patch", f"case {name}.{case_name}: patch {_shown(patch)}: a "
                                           f"table merged into the template", case_span)
                if "fmu" in patch:
                    _check_fmu_entries(patch["fmu"], f"case {name}.{case_name}: patch.",
                                       lambda keys, problem: fail_at(".".join(keys), problem,
                                                                     case_span))
                cases.append(Case(case_name, dict(case_vars), dict(patch)))
            values = cases
        elif not isinstance(values, list) or not values:
            raise fail_at("values", f"variable {name!r}: values {_shown(values)}: a non-empty "
                                    f"array of numbers or names, or a table of cases", span)
        else:
            for value in values:
                if isinstance(value, bool) or not isinstance(value, (int, float, str)) or (
                        isinstance(value, float) and not math.isfinite(value)):
                    raise fail(_quoted(text, name), f"variable {name!r}: value {_shown(value)} "
                                                    f"is not a finite number or a name")
        variables.append(Variable(name, values))
    names = [v.name for v in variables]
    metric_columns = {}
    for metric in metric_definitions():
        for column in metric_columns_of(metric):
            metric_columns[column] = metric
    for name in names:
        quoted = _quoted(text, name)
        if names.count(name) > 1:
            raise fail(quoted, f"two variables are named {name!r}")
        if name in RESERVED_COLUMNS or name.startswith("factor."):
            raise fail(quoted, f"variable {name!r}: the table has a column of that name "
                             f"({', '.join(sorted(RESERVED_COLUMNS))} and factor.* are its "
                             f"own); choose another name")
        if name in metric_columns:
            # The run's metric would overwrite the variable's value in its
            # row (or the value the metric), and the table would not say.
            metric = metric_columns[name]
            end = "lower" if name.endswith("_min") else "upper"
            what = (f"the master's metric {metric}" if metric == name else
                    f"the {end} end of the master's range metric {metric}")
            raise fail(quoted, f"variable {name!r}: the table has a metric column of that name "
                               f"({what}); choose another name")
    exclude = data.get("exclude", [])
    if not _is_tables(exclude):
        raise fail_at("exclude", f"exclude {_shown(exclude)}: an array of tables, each an "
                                 f"[[exclude]] of variable = value")
    values_of = {v.name: [getattr(value, "name", value) for value in v.values]
                 for v in variables}
    for index, rule in enumerate(exclude):
        span = lines.table("exclude", index)
        if not rule:
            raise fail(span[0] if span else "exclude",
                       "an [[exclude]] without variable = value pairs would exclude every point")
        for key, value in rule.items():
            if key not in names:
                raise fail_at(key, f"exclude names {key!r}, which is not a variable", span)
            # A value the variable does not take (a typo, or the wrong type)
            # would exclude nothing, without a word.
            if isinstance(value, bool) or not any(
                    value == known and not isinstance(known, bool) for known in values_of[key]):
                raise fail_at(key, f"exclude: {key} {_shown(value)} is not one of the "
                                   f"variable's values "
                                   f"({', '.join(map(_shown, values_of[key]))})", span)
    mc = None
    if "monte_carlo" in data:
        m = data["monte_carlo"]
        mc_span = lines.table_or_key("monte_carlo")
        if not isinstance(m, dict):
            raise fail_at("monte_carlo", f"monte_carlo {_shown(m)}: a table ([monte_carlo]) "
                                         f"with samples, instance, vary, seed_parameter")
        bad = set(m) - {"samples", "instance", "vary", "seed_parameter"}
        if bad:
            raise fail(sorted(bad)[0], f"monte_carlo: unknown key {sorted(bad)[0]!r}")
        groups = m.get("vary", [])
        if not _is_tables(groups):
            raise fail_at("vary", f"monte_carlo.vary {_shown(groups)}: an array of tables, "
                                  f"each a [[monte_carlo.vary]] with match and relative", mc_span)
        vary = []
        for index, group in enumerate(groups):
            span = lines.table("monte_carlo.vary", index) or mc_span
            bad = set(group) - {"match", "relative"}
            if bad:
                raise fail(sorted(bad)[0], f"monte_carlo.vary: unknown key {sorted(bad)[0]!r} "
                                           "(a group has match and relative)")
            if "relative" not in group:
                raise fail(group.get("match") if isinstance(group.get("match"), str) else
                           (span[0] if span else "vary"),
                           "monte_carlo.vary: every group needs `relative`, the half width of "
                           "its factors' range")
            if not isinstance(group.get("match"), str):
                raise fail_at("match", f"monte_carlo.vary: match {_shown(group.get('match'))}: "
                                       f"a regular expression in quotes", span)
            try:
                pattern = re.compile(group["match"])
            except re.error as e:
                raise fail_at("match", f"monte_carlo.vary: a regular expression `match` is "
                                       f"needed ({e})", span) from None
            relative = group["relative"]
            if not _is_number(relative):
                raise fail_at("relative", f"monte_carlo.vary: relative {_shown(relative)}: a "
                                          f"number in [0, 1), the half width of the factors' "
                                          f"range", span)
            if not 0.0 <= relative < 1.0:
                raise fail_at("relative", f"monte_carlo.vary: relative {_shown(relative)} "
                                          f"outside [0, 1)", span)
            vary.append(Vary(pattern, float(relative)))
        if "samples" not in m:
            raise fail_at("samples", "monte_carlo: samples, the number of plants drawn, is "
                                     "missing", mc_span)
        samples = m["samples"]
        if not _is_whole(samples) or samples < 1:
            raise fail_at("samples", f"monte_carlo.samples {_shown(samples)}: a whole number, "
                                     f"at least 1", mc_span)
        instance = m.get("instance", master.PLANT_INSTANCE)
        if not isinstance(instance, str):
            raise fail_at("instance", f"monte_carlo.instance {_shown(instance)}: an FMU "
                                      f"instance's name in quotes", mc_span)
        seed_parameter = m.get("seed_parameter")
        if seed_parameter is not None and (not isinstance(seed_parameter, str)
                                           or not seed_parameter):
            raise fail_at("seed_parameter", f"monte_carlo.seed_parameter "
                                            f"{_shown(seed_parameter)}: a parameter's FMI name "
                                            f"in quotes", mc_span)
        # Samples that vary nothing are one run, said as such: the grid's
        # "two points make the same run" blamed a variable or a value.
        if not vary and seed_parameter is None and samples > 1:
            raise fail(mc_span[0] if mc_span else "monte_carlo",
                       f"monte_carlo: its {samples} samples would all be one plant: give a "
                       f"[[monte_carlo.vary]] group (match, relative) to draw parameters from, "
                       f"or seed_parameter to draw the noise's seed")
        mc = MonteCarlo(samples, instance, vary, seed_parameter)
    report_options = data.get("report_options", {})
    options_span = lines.table_or_key("report_options")
    if not isinstance(report_options, dict):
        raise fail_at("report_options", f"report_options {_shown(report_options)}: a table "
                                        f"([report_options])")
    bad = set(report_options) - set(REPORT_OPTIONS)
    if bad:
        raise fail(sorted(bad)[0], f"report_options: unknown key {sorted(bad)[0]!r} (known: "
                                   f"{', '.join(sorted(REPORT_OPTIONS))})")
    for key, value in report_options.items():
        if not _is_number(value) or value <= 0:
            raise fail_at(key, f"report_options.{key} {_shown(value)}: a positive number",
                          options_span)
    report = data.get("report", "none")
    if not isinstance(report, str) or report not in REPORT_VARIABLES:
        raise fail_at("report", f"report {_shown(report)}: one of "
                                f"{', '.join(sorted(REPORT_VARIABLES))}")
    missing = REPORT_VARIABLES[report] - set(names)
    if missing:
        raise fail_at("report", f"report {report!r} reads the variables "
                                f"{', '.join(sorted(REPORT_VARIABLES[report]))}; the spec has "
                                f"no {', '.join(sorted(missing))} (report = \"none\" for a "
                                f"table alone)")
    if report != "none":
        decoupling = next(v for v in variables if v.name == "decoupling")
        cases = {getattr(value, "name", value) for value in decoupling.values}
        if cases != {"off", "on"}:
            raise fail("decoupling", f"report {report!r} compares the decoupling variable's "
                                     f"cases \"off\" and \"on\"; the spec has "
                                     f"{sorted(map(str, cases))}")
    if report == "robustness" and "monte_carlo" not in data:
        raise fail_at("report", "report 'robustness' summarizes a [monte_carlo]; the spec has "
                                "none")
    if report == "envelope" and "monte_carlo" in data:
        # Its heatmaps hold one run per grid point and decoupling case; the
        # samples of a Monte Carlo would be several (found after every run).
        raise fail_at("report", "report 'envelope' shows one run per grid point; a "
                                "[monte_carlo] gives each point several samples (report = "
                                "\"robustness\" summarizes them, \"none\" keeps the table "
                                "alone)")
    runs_per_task = data.get("runs_per_task", RUNS_PER_TASK)
    if not _is_whole(runs_per_task) or runs_per_task < 1:
        raise fail_at("runs_per_task", f"runs_per_task {_shown(runs_per_task)}: a whole "
                                       f"number, at least 1")
    return Spec(path=path, text=text, study=study, title=title,
                report=report, seed=seed,
                timeout=float(timeout) if timeout is not None else None,
                template=template, variables=variables, exclude=exclude,
                monte_carlo=mc, report_options=report_options,
                runs_per_task=runs_per_task)


# --------------------------------------------------------------------------
# Expressions: "= expr" strings in the template and the patches.

_FUNCTIONS = {"min": min, "max": max, "sqrt": math.sqrt, "radians": math.radians,
              "abs": abs, "log10": math.log10}
_OPERATORS = {ast.Add: lambda a, b: a + b, ast.Sub: lambda a, b: a - b,
              ast.Mult: lambda a, b: a * b, ast.Div: lambda a, b: a / b,
              ast.Pow: lambda a, b: a ** b}


def evaluate(expression: str, env: dict) -> float:
    """Arithmetic on numbers and the run's variables (+ - * / **, min, max,
    sqrt, radians, abs, log10, pi); nothing else is accepted."""

    def ev(node):
        if isinstance(node, ast.Expression):
            return ev(node.body)
        if isinstance(node, ast.Constant) and type(node.value) in (int, float):
            return node.value
        if isinstance(node, ast.Name):
            if node.id in env:
                return env[node.id]
            if node.id == "pi":
                return math.pi
            raise ValueError(f"unknown name {node.id!r} (known: {', '.join(sorted(env))})")
        if isinstance(node, ast.BinOp) and type(node.op) in _OPERATORS:
            return _OPERATORS[type(node.op)](ev(node.left), ev(node.right))
        if isinstance(node, ast.UnaryOp) and isinstance(node.op, (ast.USub, ast.UAdd)):
            value = ev(node.operand)
            return -value if isinstance(node.op, ast.USub) else value
        if (isinstance(node, ast.Call) and isinstance(node.func, ast.Name)
                and node.func.id in _FUNCTIONS and not node.keywords):
            return _FUNCTIONS[node.func.id](*[ev(a) for a in node.args])
        raise ValueError(f"{ast.unparse(node)!r} is not allowed in an expression")

    try:
        return ev(ast.parse(expression, mode="eval"))
    except SyntaxError as e:
        raise ValueError(f"not an expression ({e.msg})") from None


def _fill(value, env: dict, spec: Spec):
    """The template with every "= expr" string evaluated."""
    if isinstance(value, dict):
        return {k: _fill(v, env, spec) for k, v in value.items()}
    if isinstance(value, list):
        return [_fill(v, env, spec) for v in value]
    if isinstance(value, str) and value.startswith("="):
        try:
            result = evaluate(value[1:].strip(), env)
        except (ValueError, ZeroDivisionError, TypeError) as e:
            raise _fail(spec.path, spec.text, value, f"expression {value!r}: {e}") from None
        return float(result)
    return value


def _merge(base: dict, patch: dict) -> dict:
    """`patch` merged into `base`: tables recursively, anything else replaced."""
    out = dict(base)
    for key, value in patch.items():
        if isinstance(value, dict) and isinstance(out.get(key), dict):
            out[key] = _merge(out[key], value)
        else:
            out[key] = copy.deepcopy(value)
    return out


# --------------------------------------------------------------------------
# Expansion

@dataclass
class Run:
    """One task: its index, key, the scenario (FMUs by content digest) and
    the values that identify it in the table."""

    index: int
    key: str
    scenario: dict
    values: dict


def _digest(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


#: A scenario names the files that travel with the tasks by their content
#: digest: an FMU as `fmu:<digest>`, a reference table as
#: `table:<digest>/<its file name>` (the name stays in the master's messages).
FMU_PREFIX = "fmu:"
TABLE_PREFIX = "table:"


def _table_digest(file: str) -> tuple[str, str] | None:
    """(digest, file name) of a scenario's travelling table, else None."""
    if not file.startswith(TABLE_PREFIX):
        return None
    digest, _, name = file.removeprefix(TABLE_PREFIX).partition("/")
    return digest, name


def _tables(scenario: dict):
    """The `table` entries of a scenario's signals."""
    for signal in scenario.get("signal", {}).values():
        table = signal.get("table") if isinstance(signal, dict) else None
        if isinstance(table, dict) and isinstance(table.get("file"), str):
            yield table


def canonical(value) -> str:
    return json.dumps(value, sort_keys=True, separators=(",", ":"))


def _fmu_file(spec: Spec, instance: str, entry: dict) -> Path:
    """The .fmu file of an instance's entry, which must exist."""
    if "path" not in entry:
        raise _fail(spec.path, spec.text, instance, f"fmu.{instance}: no path (its .fmu file)")
    path = spec.file(entry["path"])
    if not path.is_file():
        raise _fail(spec.path, spec.text, entry["path"],
                    f"fmu.{instance}: {path} does not exist (run `make fmus`)")
    return path


def _resolve_fmus(scenario: dict, spec: Spec, fmus: dict, sets: dict, files: dict) -> dict:
    """Replaces FMU paths by their content digests (collected in `fmus`) and
    folds parameter sets into the parameter values, in `scenario` itself
    (the caller's own, fresh from _fill). `files` keeps each path's file
    once found: resolving and testing it took half of a 100,000-run grid's
    expansion."""
    for instance, entry in scenario.get("fmu", {}).items():
        if entry.get("path") not in files:
            files[entry.get("path")] = _fmu_file(spec, instance, entry)
        path = files[entry["path"]]
        if path not in fmus:
            fmus[path] = _digest(path)
        entry["path"] = f"{FMU_PREFIX}{fmus[path]}"
        values = {}
        for name in entry.pop("parameter_sets", []):
            set_path = spec.file(name)
            if set_path not in sets:
                try:
                    sets[set_path] = json.loads(set_path.read_text(encoding="utf-8-sig"))
                except (OSError, json.JSONDecodeError) as e:
                    raise _fail(spec.path, spec.text, name, f"parameter set {set_path}: {e}") \
                        from None
                if not isinstance(sets[set_path], dict):
                    raise _fail(spec.path, spec.text, name,
                                f"parameter set {set_path}: not an object of values by FMI name")
            values.update(sets[set_path])
        values.update(entry.get("parameters", {}))
        entry["parameters"] = values
    for port, signal in scenario.get("signal", {}).items():
        table = signal.get("table") if isinstance(signal, dict) else None
        if not isinstance(table, dict) or not isinstance(table.get("file"), str):
            continue  # not a table source: the master names what is wrong
        name = table["file"]
        if name not in files:
            path = spec.file(name)
            if not path.is_file():
                raise _fail(spec.path, spec.text, name,
                            f"signal {port}: reference table {path} does not exist (a table "
                            f"is read relative to the spec's folder)")
            files[name] = path
        path = files[name]
        if path not in fmus:
            fmus[path] = _digest(path)
        # Its contents are part of the run's key (an edited table is a new
        # run, as an edited FMU is), and it travels with the tasks.
        table["file"] = f"{TABLE_PREFIX}{fmus[path]}/{path.name}"
    return scenario


def _excluded(point: dict, rules: list[dict]) -> bool:
    return any(all(point.get(k) == v for k, v in rule.items()) for rule in rules)


@functools.cache
def _model_variables(fmu_path: Path) -> list:
    """The variables of an FMU's modelDescription (fmpy reads it), read once
    per file however many studies ask."""
    from fmpy import read_model_description

    return read_model_description(str(fmu_path)).modelVariables


def _plant_parameters(fmu_path: Path) -> dict:
    """Start value and declared range (min, max; None when open) of every
    Real parameter of an FMU."""
    def bound(value):
        return None if value is None else float(value)

    return {v.name: (float(v.start), bound(v.min), bound(v.max))
            for v in _model_variables(fmu_path)
            if v.causality == "parameter" and v.type == "Real" and v.start is not None}


def _range_text(low, high) -> str:
    """A declared range as an interval. FMI's min and max are inclusive, so an
    open end is declared as the double next to it (> 0 as the smallest normal
    double, sys.float_info.min): written back as the open end, (0, inf]."""
    def end(bound, toward: float, closed: str, opened: str, missing: str) -> str:
        if bound is None:
            return missing
        outside = 0.0 if abs(bound) == sys.float_info.min else math.nextafter(bound, toward)
        if len(f"{outside:g}") < len(f"{bound:g}") or (outside == 0 and bound != 0):
            return opened.format(f"{outside:g}")
        return closed.format(f"{bound:g}")
    return (f"{end(low, -math.inf, '[{}', '({}', '[-inf')}, "
            f"{end(high, math.inf, '{}]', '{})', 'inf]')}")


def perturbed(nominal: float, factor: float, low, high) -> float:
    """nominal x factor, kept within the parameter's declared range: outside
    it the model is not defined (the FMU refuses the value), e.g. a Bouc-Wen
    exponent n below 1 when its nominal value is 1."""
    value = nominal * factor
    if low is not None:
        value = max(value, low)
    if high is not None:
        value = min(value, high)
    return value


def sample_factors(spec: Spec, sample: int, names: dict[int, list[str]]) -> tuple[dict, int]:
    """The factors of Monte Carlo sample `sample` (a pure function of the
    spec's seed and the sample number) and the sample's seed."""
    rng = np.random.default_rng([spec.seed, sample])
    factors = {}
    for g, group in enumerate(spec.monte_carlo.vary):
        for name in names[g]:
            factors[name] = float(rng.uniform(1.0 - group.relative, 1.0 + group.relative))
    seed = int(rng.integers(1, 2**31 - 1))
    return factors, seed


def expand(spec: Spec) -> tuple[list[Run], dict[str, Path]]:
    """Every run of the spec, in a fixed order, and the files that travel
    with its tasks (FMUs, reference tables) by digest."""
    fmus: dict[Path, str] = {}
    sets: dict[Path, dict] = {}
    files: dict[str, Path] = {}
    points = []
    for combination in itertools.product(*[v.values for v in spec.variables]):
        point, env, patch = {}, {}, {}
        for variable, value in zip(spec.variables, combination):
            if isinstance(value, Case):
                point[variable.name] = value.name
                env.update(value.vars)
                patch = _merge(patch, value.patch)
            else:
                point[variable.name] = value
                if isinstance(value, (int, float)) and not isinstance(value, bool):
                    env[variable.name] = value
        if not _excluded(point, spec.exclude):
            points.append((point, env, patch))
    if not points:
        first_rule = _SpecLines(spec.text).table("exclude")
        raise _fail(spec.path, spec.text, first_rule[0] if first_rule else "exclude",
                    "the grid is empty (every point excluded)")

    mc = spec.monte_carlo
    vary_names: dict[int, list[str]] = {}
    nominal_start: dict = {}
    if mc is not None:
        plant_entry = spec.template.get("fmu", {}).get(mc.instance)
        if plant_entry is None:
            lines = _SpecLines(spec.text)
            raise _fail(spec.path, spec.text,
                        lines.key("instance", lines.table_or_key("monte_carlo")),
                        f"monte_carlo.instance {mc.instance!r} is not an FMU of the template")
        plant_path = _fmu_file(spec, mc.instance, plant_entry)
        nominal_start = _plant_parameters(plant_path)
        for g, group in enumerate(mc.vary):
            vary_names[g] = sorted(n for n in nominal_start if group.pattern.search(n))
            if not vary_names[g]:
                raise _fail(spec.path, spec.text, group.pattern.pattern,
                            f"monte_carlo.vary {group.pattern.pattern!r} matches no Real "
                            f"parameter of {plant_path.name}")
            # A parameter in two groups would take the last group's range
            # without a word.
            for earlier in range(g):
                both = sorted(set(vary_names[earlier]) & set(vary_names[g]))
                if both:
                    lines = _SpecLines(spec.text)
                    own = lines.table("monte_carlo.vary", g)
                    raise _fail(spec.path, spec.text,
                                lines.key("match", own) if own else group.pattern.pattern,
                                f"monte_carlo.vary {group.pattern.pattern!r} matches "
                                f"{', '.join(both)}, which "
                                f"{mc.vary[earlier].pattern.pattern!r} matches too")
    samples = range(mc.samples) if mc else [None]

    runs = []
    filled_points = []
    for point, env, patch in points:
        scenario = _fill(_merge(spec.template, patch), {**env}, spec)
        # Where the perturbed instance's values come from, to name it when
        # one of them is refused: the spec's own parameters, else its sets.
        own = scenario.get("fmu", {}).get(mc.instance, {}) if mc else {}
        origin = (dict(own.get("parameters", {})), list(own.get("parameter_sets", [])))
        filled_points.append((point, _resolve_fmus(scenario, spec, fmus, sets, files), origin))
    for sample in samples:
        factors, seed = (sample_factors(spec, sample, vary_names) if sample is not None
                         else ({}, None))
        for point, resolved, origin in filled_points:
            # A Monte Carlo sample changes its own copy; a grid point's
            # scenario is its run's alone, as it is.
            scenario = copy.deepcopy(resolved) if sample is not None else resolved
            values = dict(point)
            if sample is not None:
                parameters = scenario["fmu"][mc.instance]["parameters"]
                applied = {}
                for name, factor in factors.items():
                    start, low, high = nominal_start[name]
                    nominal = parameters.get(name, start)
                    if not _is_number(nominal):
                        problem = (f"{mc.instance}.{name} = {_shown(nominal)}: the Monte Carlo "
                                   f"perturbs it, so it must be a number")
                    elif (low is not None and nominal < low) or (high is not None
                                                                 and nominal > high):
                        # Perturbed, it would be held at the bound without a
                        # word: the nominal value is itself refused.
                        problem = (f"{mc.instance}.{name} = {nominal:g} (the nominal value the "
                                   f"Monte Carlo perturbs) is outside its declared range "
                                   f"{_range_text(low, high)}")
                    else:
                        problem = None
                    if problem:
                        own_values, set_names = origin
                        given_in = [n for n in set_names if name in sets[spec.file(n)]]
                        if name not in own_values and given_in:
                            set_path = spec.file(given_in[-1])
                            text = set_path.read_text(encoding="utf-8-sig")
                            raise _fail(set_path, text, f'"{name}"', problem)
                        raise _fail(spec.path, spec.text, name, problem)
                    parameters[name] = perturbed(nominal, factor, low, high)
                    # The factor applied, after the range (the swept value); a
                    # nominal 0 stays 0, unperturbed.
                    applied[name] = parameters[name] / nominal if nominal else 1.0
                values["sample"] = sample
                values.update({f"factor.{n}": f for n, f in applied.items()})
            # The seed column says the seed the run used, so that a row can
            # be run again from it: the sample's draw where seed_parameter
            # gives it to the plant, else the template's (or a case's)
            # noise.seed. A drawn seed that no parameter receives is not the
            # run's (it is still drawn: the later samples' factors stay).
            if sample is not None and mc.seed_parameter:
                parameters[mc.seed_parameter] = seed
                values["seed"] = seed
            else:
                values["seed"] = _noise_seed(scenario)
            key = hashlib.sha256(canonical(scenario).encode()).hexdigest()[:32]
            runs.append(Run(len(runs), key, scenario, values))
    # Two grid points that make one scenario would be one row, which says
    # only one of their values: a variable the template never uses, or a
    # value given twice.
    first_of: dict[str, Run] = {}
    for run in runs:
        twin = first_of.setdefault(run.key, run)
        if twin is not run:
            differ = [name for name in run.values if run.values[name] != twin.values.get(name)]
            names = ", ".join(f"{n} = {twin.values[n]!r} and {run.values[n]!r}" for n in differ)
            raise _fail(spec.path, spec.text, differ[0] if differ else None,
                        f"two points of the grid make the same run ({names or 'the same values'}): "
                        f"a variable the template does not use (as `= name`), or a value given "
                        f"twice")
    return runs, {digest: path for path, digest in fmus.items()}


def _noise_seed(scenario: dict):
    """The sensor-noise seed a run's scenario sets (the table's seed column
    for a grid run, and for a Monte Carlo run without seed_parameter); None
    where it sets none (the FMU's start value then holds)."""
    for entry in scenario.get("fmu", {}).values():
        seed = entry.get("parameters", {}).get("noise.seed")
        if seed is not None:
            # A seed that is not a whole number is the master's to refuse
            # (check_scenarios names it at its line); the column stays empty.
            return int(seed) if _is_number(seed) and float(seed).is_integer() else None
    return None


# --------------------------------------------------------------------------
# The task (runs on a worker)

_UNPACKED: dict[str, Path] = {}
_SCRATCH: Path | None = None


def _cache_folder() -> Path:
    """Where this process unpacks FMUs: the dask worker's local directory
    (dask removes it with the worker, and purges it after a crash), else a
    folder in the temporary directory."""
    global _SCRATCH
    try:
        from distributed import get_worker

        return Path(get_worker().local_directory) / "fmus"
    except (ImportError, ValueError):
        if _SCRATCH is None:
            _SCRATCH = Path(tempfile.mkdtemp(prefix="piezo-cosim-fmus-"))
            atexit.register(shutil.rmtree, _SCRATCH, ignore_errors=True)
        return _SCRATCH


def _unpacked(digest: str, data: bytes) -> Path:
    """The FMU `data` unpacked once per process and digest: its
    modelDescription.xml, this platform's binaries and its resources."""
    if digest in _UNPACKED and _UNPACKED[digest].is_dir():
        return _UNPACKED[digest]
    from fmpy import platform

    if hashlib.sha256(data).hexdigest() != digest:
        raise RuntimeError(f"FMU {digest[:12]}: the bytes received do not match its digest")
    target = _cache_folder() / digest
    shutil.rmtree(target, ignore_errors=True)
    target.mkdir(parents=True)
    with zipfile.ZipFile(io.BytesIO(data)) as archive:
        wanted = [name for name in archive.namelist()
                  if name == "modelDescription.xml" or name.startswith("resources/")
                  or name.startswith(f"binaries/{platform}/")]
        archive.extractall(target, members=wanted)
    _UNPACKED[digest] = target
    return target


def _written(digest: str, name: str, data: bytes) -> Path:
    """A reference table's `data` written once per process and digest, under
    its own file name (which the master's messages name)."""
    target = _cache_folder() / digest / name
    if target.is_file():
        return target
    if hashlib.sha256(data).hexdigest() != digest:
        raise RuntimeError(f"table {name}: the bytes received do not match its digest")
    target.parent.mkdir(parents=True, exist_ok=True)
    partial = target.with_name(f".{name}.partial")
    partial.write_bytes(data)
    partial.replace(target)
    return target


def flatten_metrics(metrics: dict | None) -> dict:
    """Ranges [min, max] become two columns <name>_min, <name>_max
    (`y_error_range_min`): without the `_range` they would overwrite the
    master's own `y_error_max`, the largest |e_y|."""
    row = {}
    for name, value in (metrics or {}).items():
        if isinstance(value, list):
            row[f"{name}_min"], row[f"{name}_max"] = float(value[0]), float(value[1])
        else:
            row[name] = value
    return row


def execute_runs(runs: list[Run], fmu_data: dict, timeout: float | None) -> list[dict]:
    """Runs `runs` through the master in one process (`piezo-cosim batch`:
    each FMU opened once); returns their table rows, in order. Never raises
    for a failed run: its row says why (status, error). `task_s` is the
    task's wall time shared evenly among its runs."""
    started = time.perf_counter()
    try:
        from distributed import get_worker

        worker = get_worker().address
    except (ImportError, ValueError):
        worker = "local"
    scenarios = []
    for run in runs:
        scenario = copy.deepcopy(run.scenario)
        for entry in scenario["fmu"].values():
            digest = entry["path"].removeprefix(FMU_PREFIX)
            entry["path"] = str(_unpacked(digest, fmu_data[digest]))
        for table in _tables(scenario):
            if (travelling := _table_digest(table["file"])) is not None:
                table["file"] = str(_written(*travelling, fmu_data[travelling[0]]))
        scenarios.append(scenario)
    rows = []
    for run, outcome in zip(runs, master.run_batch(scenarios, timeout=timeout)):
        row = {"run": run.index, "key": run.key, **run.values}
        if isinstance(outcome, master.MasterError):
            row.update(status="error", error=_without_stdin(str(outcome))[:2000])
        elif isinstance(outcome, subprocess.TimeoutExpired):
            # Not a property of the run (a loaded machine can cause it): the
            # row says so, and the next invocation runs it again.
            row.update(status="timeout", error=f"no result within {timeout} s")
        else:
            row.update(status="ok", error=None, steps=outcome["steps"],
                       simulated_s=outcome["simulated_s"], warnings=len(outcome["warnings"]),
                       wall_s=outcome["wall_s"])
            row.update(flatten_metrics(outcome.get("metrics")))
        rows.append(row)
    share = (time.perf_counter() - started) / max(len(runs), 1)
    for row in rows:
        row["task_s"] = share
        row["worker"] = worker
    return rows


def batches(runs: list[Run], workers: int, runs_per_task: int) -> list[list[Run]]:
    """`runs` cut into tasks of consecutive runs: at most `runs_per_task`
    each, and at least four tasks per worker while there are runs enough
    (so that the workers stay busy to the end). What a run computes does not
    depend on its task (a run has its own FMU instances)."""
    size = max(1, min(runs_per_task, math.ceil(len(runs) / (4 * max(workers, 1)))))
    return [runs[i:i + size] for i in range(0, len(runs), size)]


# --------------------------------------------------------------------------
# The table

def table_path(out: Path, study: str) -> Path:
    return out / f"{study}.parquet"


def journal_path(out: Path, study: str) -> Path:
    return out / f"{study}.journal.jsonl"


def read_rows(out: Path, study: str) -> list[dict]:
    """The rows of the table and of its journal."""
    import pyarrow.parquet as pq

    rows = []
    path = table_path(out, study)
    if path.is_file():
        try:
            rows += pq.read_table(path).to_pylist()
        except (OSError, ValueError) as e:  # pyarrow's ArrowInvalid is a ValueError
            raise UnreadableTable(
                f"{path}: not a table this command can read ({e}); it is left as it is: "
                f"move it away, or choose another --out") from None
    journal = journal_path(out, study)
    if journal.is_file():
        for line in journal.read_text().splitlines():
            try:
                rows.append(json.loads(line))
            except json.JSONDecodeError:
                # The last line of a journal whose writer was killed mid-line.
                continue
    return rows


def _fmu_variable_units(path: Path) -> dict[str, str | None]:
    """The unit of every variable of an FMU, from its modelDescription
    (None where it declares none)."""
    return {v.name: v.unit or (v.declaredType.unit if v.declaredType else None)
            for v in _model_variables(path)}


def _unit_at(keys: tuple, fmu_units: dict[str, dict]) -> str | None:
    """The unit of the scenario's value at `keys` (piezo-cosim's scenario
    format): a time, a sine's frequency or phase, an FMU parameter, or a
    signal's level in the unit of the input it drives; None where the format
    does not fix one."""
    match keys:
        case ("duration",) | ("step",) | ("metrics", "from"):
            return "s"
        case ("metrics", "spacing") | ("metrics", "contour", *_):
            return "um"
        case ("fmu", instance, "parameters", name):
            return fmu_units.get(instance, {}).get(name)
        case ("signal", _, "start" | "approach"):
            return "s"
        case ("signal", _, "sines", _, "frequency"):
            return "Hz"
        case ("signal", _, "sines", _, "phase"):
            return "rad"
        case ("signal", port, "offset") | ("signal", port, "sines", _, "amplitude"):
            instance, _, name = str(port).partition(".")
            return fmu_units.get(instance, {}).get(name)
    return None


def variable_units(spec: Spec) -> dict[str, str]:
    """The unit of each numeric variable of the grid whose value the spec
    gives, as it is (`= name`), to quantities of one known unit: an FMU
    parameter (its modelDescription's unit), a signal's offset or amplitude
    (the unit of the input it drives), a sine's frequency or phase, a time.
    A variable that only enters expressions (`= amplitude * y_stroke`, a
    share of the stroke) or feeds quantities of different units has none."""
    numeric = {v.name for v in spec.variables
               if all(_is_number(value) for value in v.values)}
    patches = [case.patch for v in spec.variables for case in v.values
               if isinstance(case, Case)]
    # An instance's FMUs: the template's, and any a case puts in its place.
    files: dict[str, set[Path]] = {}
    for tree in (spec.template, *patches):
        for instance, entry in tree.get("fmu", {}).items():
            if isinstance(entry.get("path"), str) and spec.file(entry["path"]).is_file():
                files.setdefault(instance, set()).add(spec.file(entry["path"]))
    fmu_units: dict[str, dict] = {}
    for instance, paths in files.items():
        tables = [_fmu_variable_units(path) for path in sorted(paths)]
        fmu_units[instance] = {}
        for name in set().union(*tables):
            declared = {table.get(name) for table in tables}
            # A unit the instance's FMUs do not agree on is not the variable's.
            fmu_units[instance][name] = declared.pop() if len(declared) == 1 else None
    uses: dict[str, set] = {}

    def walk(value, keys: tuple) -> None:
        if isinstance(value, dict):
            for key, item in value.items():
                walk(item, (*keys, key))
        elif isinstance(value, list):
            for index, item in enumerate(value):
                walk(item, (*keys, index))
        elif isinstance(value, str) and value.startswith("="):
            name = value[1:].strip()
            if name in numeric:
                uses.setdefault(name, set()).add(_unit_at(keys, fmu_units))

    for tree in (spec.template, *patches):
        walk(tree, ())
    return {name: units.pop() for name, units in uses.items()
            if len(units) == 1 and None not in units}


def column_units(spec: Spec, runs: list[Run]) -> dict[str, str]:
    """The unit of every column of the study's table that holds a quantity:
    the table's own (OWN_COLUMN_UNITS), the metrics' (metric_definitions; a
    figure of the driven axis in the unit of the runs' driven axes, none
    where they mix um and rad), the Monte Carlo factors' and the variables'
    (variable_units)."""
    units = dict(OWN_COLUMN_UNITS)
    driven = {run.scenario["metrics"].get("driven") for run in runs
              if isinstance(run.scenario.get("metrics"), dict)}
    for metric, definition in metric_definitions().items():
        unit = definition["unit"]
        if isinstance(unit, dict):
            # A column of runs driven on x and on theta_z mixes um and rad:
            # it claims no unit, as a variable whose values differ in unit.
            units_of_runs = {unit[axis] for axis in unit if axis in driven}
            if len(units_of_runs) != 1:
                continue
            unit = units_of_runs.pop()
        for column in metric_columns_of(metric):
            units[column] = unit
    for run in runs:
        for name in run.values:
            if name.startswith("factor."):
                units[name] = FACTOR_UNIT
    units.update(variable_units(spec))
    return units


def _rows_to_table(rows: list[dict], spec: Spec | None = None,
                   units: dict[str, str] | None = None):
    """The rows as an Arrow table: the spec (its text and path) in the
    schema's metadata, and each column's unit, where it has one, in its
    field's (b"unit")."""
    import pyarrow as pa

    # Rows differ in their metrics (a y run has no coupling_y_span, a failed
    # run none at all): every column any row has, in order of appearance.
    names = list(dict.fromkeys(name for row in rows for name in row))
    table = pa.table({name: [row.get(name) for row in rows] for name in names})
    units = units or {}
    fields = [field.with_metadata({b"unit": units[field.name].encode()})
              if field.name in units else field for field in table.schema]
    meta = None
    if spec is not None:
        meta = {b"study": spec.study.encode(), b"spec": spec.text.encode(),
                b"spec_path": str(spec.path).encode(), b"title": spec.title.encode(),
                b"report": spec.report.encode(),
                b"report_options": json.dumps(spec.report_options).encode()}
    return pa.Table.from_arrays(table.columns, schema=pa.schema(fields, metadata=meta))


def _write_atomically(table, path: Path) -> None:
    import pyarrow.parquet as pq

    scratch = path.with_name(f".{path.name}.{os.getpid()}.tmp")
    pq.write_table(table, str(scratch))
    os.replace(scratch, path)


def table_variables(out: Path, study: str) -> set[str]:
    """The names of the variables of the spec that wrote the study's table
    (its schema's metadata keeps the spec's text); none without a table."""
    import pyarrow.parquet as pq

    path = table_path(out, study)
    if not path.is_file():
        return set()
    text = (pq.read_schema(path).metadata or {}).get(b"spec", b"")
    try:
        entries = tomllib.loads(text.decode()).get("variable", [])
    except (tomllib.TOMLDecodeError, UnicodeDecodeError):
        return set()
    return {entry.get("name") for entry in entries if isinstance(entry, dict)}


def as_run_of(row: dict, run: Run, old_variables: set[str]) -> dict:
    """A row of the table as `run`'s row (the same scenario: the same key)
    in the spec as it is now: numbered, and its values named, as a fresh
    run of that spec would write them. A spec extended since (a grid's new
    value) numbers its runs anew, and the old numbers would repeat and
    interleave with the new runs'; a variable renamed would leave its old
    column. What the run computed (status, metrics, times) is kept."""
    outcome = {name: value for name, value in row.items()
               if name not in ("run", "key", "sample", "seed") and name not in run.values
               and name not in old_variables and not name.startswith("factor.")}
    return {"run": run.index, "key": run.key, **run.values, **outcome}


def consolidate(out: Path, spec: Spec, runs: dict[str, Run],
                units: dict[str, str] | None = None) -> int:
    """Folds the journal into the table: each of the spec's `runs` (by key)
    once, as that run's row (as_run_of), in run order, the columns' `units`
    in its schema. Returns the number of rows."""
    old_variables = table_variables(out, spec.study)
    rows = read_rows(out, spec.study)
    unique = {}
    for row in rows:
        # The table's rows first, then the journal's: a run executed again
        # (after a timeout) replaces its earlier row.
        if row["key"] in runs:
            unique[row["key"]] = as_run_of(row, runs[row["key"]], old_variables)
    ordered = sorted(unique.values(), key=lambda r: r["run"])
    if ordered:
        _write_atomically(_rows_to_table(ordered, spec, units), table_path(out, spec.study))
    else:
        # Its rows were all dropped (stale_rows): no table, rather than one
        # of rows that are not the spec's.
        table_path(out, spec.study).unlink(missing_ok=True)
    journal_path(out, spec.study).unlink(missing_ok=True)
    return len(ordered)


class Journal:
    """Rows as they arrive, one JSON line each, appended to
    DIR/<study>.journal.jsonl: whatever stops the client (Ctrl-C, a kill, a
    lost machine), the rows received so far are on disk, and the next
    consolidation folds them into the table."""

    def __init__(self, out: Path, study: str):
        self.file = journal_path(out, study).open("a")

    def add(self, row: dict) -> None:
        self.file.write(json.dumps(row) + "\n")
        self.file.flush()

    def close(self) -> None:
        self.file.close()


# --------------------------------------------------------------------------
# Execution

class StaleTable(SpecError):
    pass


class UnreadableTable(SpecError):
    """A file where a study's table goes that is not a Parquet table (a
    truncated copy, another program's file): refused before any run, and
    neither replaced nor deleted."""


def check_scenarios(runs: list[Run], fmus: dict[str, Path], spec: Spec) -> list[Run]:
    """Runs the master's check (load, wire, set every parameter, initialize;
    no step) here, before anything is sent, on one run of every combination
    of named cases, then on one run per further value of each variable, a
    run that differs from a checked one in that value alone: a spec that
    does not fit the FMUs fails once, with the master's message and the
    value it is about, instead of in every task (a grid value out of its
    parameter's range failed every run that had it, and the others' rows
    were kept with theirs). The checks go a few at a time (one master
    process each). Returns the runs checked."""
    references, neighbours = _runs_to_check(runs, spec)
    with ThreadPoolExecutor(max_workers=os.cpu_count() or 1) as pool:
        outcomes = list(pool.map(lambda run: _check_one(run, fmus),
                                 [run for run, _ in references + neighbours]))
    for (run, signature), error in zip(references, outcomes):
        if error is not None:
            raise _case_error(spec, run, signature, error)
    for (run, value), error in zip(neighbours, outcomes[len(references):]):
        if error is not None:
            raise _value_error(spec, run, value, error)
    return [run for run, _ in references + neighbours]


def _runs_to_check(runs: list[Run], spec: Spec) -> tuple[list, list]:
    """The runs check_scenarios checks: (run, its named cases) for the first
    run of every combination of named cases, and (run, (variable, value))
    for every value of a variable no such run has, the run being the
    neighbour of one of them (its other values equal) where the grid has
    one, else the first run with the value. Monte Carlo samples repeat the
    grid's points with factors kept within their parameters' ranges: the
    first sample's runs stand for all."""
    names = [v.name for v in spec.variables]
    first_of: dict[tuple, Run] = {}
    for run in runs:
        first_of.setdefault(tuple(run.values[name] for name in names), run)
    references, seen = [], set()
    for run in first_of.values():
        signature = tuple(sorted((k, v) for k, v in run.values.items()
                                 if k in names and isinstance(v, str)))
        if signature not in seen:
            seen.add(signature)
            references.append((run, signature))
    covered = {(name, run.values[name]) for run, _ in references for name in names}
    neighbours = []
    for index, variable in enumerate(spec.variables):
        for value in variable.values:
            value = getattr(value, "name", value)
            if (variable.name, value) in covered:
                continue
            candidates = [first_of.get((*point[:index], value, *point[index + 1:]))
                          for point in (tuple(run.values[n] for n in names)
                                        for run, _ in references)]
            run = next((c for c in candidates if c is not None), None) or next(
                (r for point, r in first_of.items() if point[index] == value), None)
            if run is None:
                continue  # every point with it is excluded
            neighbours.append((run, (variable.name, value)))
            covered.update((name, run.values[name]) for name in names)
    return references, neighbours


def local_scenario(run: Run, files: dict[str, Path]) -> dict:
    """A run's scenario with the files it names by digest (`files`, as
    `expand` returns them) back at their paths here: what the master runs
    on this machine, as a worker runs it on its copies."""
    scenario = copy.deepcopy(run.scenario)
    for entry in scenario.get("fmu", {}).values():
        entry["path"] = str(files[entry["path"].removeprefix(FMU_PREFIX)])
    for table in _tables(scenario):
        if (travelling := _table_digest(table["file"])) is not None:
            table["file"] = str(files[travelling[0]])
    return scenario


def _check_one(run: Run, fmus: dict[str, Path]) -> master.MasterError | None:
    """The master's check of one run's scenario: its error, or None."""
    scenario = local_scenario(run, fmus)
    try:
        master.check(scenario)
    except master.MasterError as e:
        return e
    return None


def _unread(error: master.MasterError) -> tuple[str, str] | None:
    """(key, problem) of a value the master cannot read, which it names by
    its key in the scenario it was sent (`<stdin>:1:253: metrics.driven:
    ...`): the place in that JSON means nothing to the spec's reader."""
    found = re.match(rf"^<stdin>:\d+:\d+: ((?:{_QUOTED_KEY}|[^:\s\"])+): (.*)$", str(error),
                     re.DOTALL)
    return found.groups() if found else None


def _without_stdin(text: str) -> str:
    """The master's message without the place in the JSON it was sent
    (`<stdin>:1:253: `, `<stdin>: `), which means nothing to the spec's
    reader."""
    return re.sub(r"^<stdin>(?::\d+)*: ", "", text)


def _port_place(spec: Spec, signature: tuple, message: str) -> tuple[str, str] | None:
    """(where, a note on it) of a message about an FMI name (`controller.kpp: ...
    has no variable`, `connection source plant.u1 is not ...`): the spec's
    line that writes the name (a parameter, a signal's port, the Monte Carlo's
    seed_parameter; quoted or bare), or the parameter set that gives it;
    None where the message names no `instance.variable` of the template."""
    named = re.sub(r"^(?:connection (?:source|destination)|signal|recorded variable) ", "",
                   _without_stdin(message))
    port = re.split(r"[:\s]", named, maxsplit=1)[0].strip('"')
    # What an FMU refused, in its log: `controller: fmi2ExitInitializationMode
    # ...: parameter translation.kp = -5 is outside its allowed range`.
    refused = re.match(r"^(\w+): .*?\bparameter (\S+) = ", named, re.DOTALL)
    if "." not in port and refused:
        port = f"{refused.group(1)}.{refused.group(2)}"
    instance, _, variable = port.partition(".")
    fmu = spec.template.get("fmu", {})
    if not variable or instance not in fmu:
        return None
    for entry in (fmu[instance], *(_case_patch(spec, n, c).get("fmu", {}).get(instance, {})
                                   for n, c in signature)):
        for name in entry.get("parameter_sets", []) if isinstance(entry, dict) else []:
            try:
                values = json.loads(spec.file(name).read_text(encoding="utf-8-sig"))
            except (OSError, json.JSONDecodeError):
                continue
            if isinstance(values, dict) and variable in values and \
                    variable not in entry.get("parameters", {}):
                set_text = spec.file(name).read_text(encoding="utf-8-sig")
                line = next((n for n, text in enumerate(set_text.splitlines(), 1)
                             if f'"{variable}"' in text), None)
                where = f"{spec.file(name)}:{line}" if line else str(spec.file(name))
                return where, " (a value of this parameter set)"
    for needle in (f'"{port}"', f'"{variable}"', f"'{variable}'"):
        line = next((n for n, text in enumerate(spec.text.splitlines(), 1)
                     if needle in text.split("#")[0]), None)
        if line:
            return f"{spec.path}:{line}", ""
    line = _line_of(spec.text, variable)
    return (f"{spec.path}:{line}", "") if line else None


def _case_error(spec: Spec, run: Run, signature: tuple,
                error: master.MasterError) -> SpecError:
    """The error of a run of named cases `signature` that does not check: at
    the line of the key the master names, in the template or in a case's
    patch, or of the spec. The run's values are named: a value of a further
    variable may be the cause."""
    names = [v.name for v in spec.variables]
    cases = ", ".join(f"{n} = {v}" if isinstance(v, str) else f"{n} = {_shown(v)}"
                      for n, v in ((n, run.values[n]) for n in names)) or "the template"
    unread = _unread(error)
    if unread:
        key, problem = unread
        lines = _SpecLines(spec.text)
        # A named case's patch wins over the template: name it first.
        patched = [(name, case) for name, case in signature
                   if _patch_sets(_case_patch(spec, name, case), _key_parts(key))]
        if patched:
            name, case = patched[-1]
            span = lines.table(f"variable.values.{case}")
            line = lines.key("patch", span) if span else None
            where = f"{spec.path}:{line}" if line else str(spec.path)
            return SpecError(f"{where}: {name} = {case}: patch {key}: {problem}")
        line = _template_line(lines, key)
        where = f"{spec.path}:{line}" if line else str(spec.path)
        source = "template" if line else "scenario"
        return SpecError(f"{where}: {source} {key}: {problem} (in the scenario of {cases})")
    text = _without_stdin(str(error))
    place = _port_place(spec, signature, text)
    if place is not None:
        return SpecError(f"{place[0]}: {text}{place[1]} (in the scenario of {cases})")
    # A check of the scenario as a whole (`metrics.from (0.4) leaves ...`):
    # at the template's line of the key it names.
    key = re.match(r"^([a-z_]+(?:\.[a-z_]+)+) ", text)
    line = _template_line(_SpecLines(spec.text), key.group(1)) if key else None
    where = f"{spec.path}:{line}" if line else str(spec.path)
    return SpecError(f"{where}: the scenario of {cases} does not run: {text}")


def _value_error(spec: Spec, run: Run, value: tuple, error: master.MasterError) -> SpecError:
    """The error of a variable's value whose run does not check, at the line
    of the variable's values. The run differs in that value alone from one
    that checked where the grid has such a run (then the value is the
    cause); the run's other values are named."""
    name, shown = value
    index = next(i for i, v in enumerate(spec.variables) if v.name == name)
    lines = _SpecLines(spec.text)
    span = lines.table("variable", index)
    line = lines.key("values", span) if span else _line_of(spec.text, _quoted(spec.text, name))
    where = f"{spec.path}:{line}" if line else str(spec.path)
    names = [v.name for v in spec.variables]
    others = ", ".join(f"{n} = {run.values[n]!r}" for n in names if n != name)
    unread = _unread(error)
    problem = (f"{unread[0]}: {unread[1]}" if unread
               else f"the scenario does not run: {_without_stdin(str(error))}")
    return SpecError(f"{where}: {name} = {_shown(shown)}: {problem} (in the scenario of "
                     f"{others or 'the template'})")


def _case_patch(spec: Spec, variable: str, case: str) -> dict:
    """The patch of the named case `case` of variable `variable`."""
    for v in spec.variables:
        if v.name == variable:
            for value in v.values:
                if isinstance(value, Case) and value.name == case:
                    return value.patch
    return {}


def _patch_sets(patch: dict, parts: list[str]) -> bool:
    """Whether `patch` sets the scenario key whose path is `parts`."""
    if not parts:
        return True
    return isinstance(patch, dict) and parts[0] in patch and _patch_sets(patch[parts[0]], parts[1:])


#: A quoted key of a path the master names (`parameters."noise.seed"`): a
#: JSON string, whose escapes are TOML's basic string's.
_QUOTED_KEY = r'"(?:[^"\\]|\\.)*"'


def _key_parts(key: str) -> list[str]:
    """The keys of a path as the master writes it, `fmu.plant.parameters."noise.seed"`
    -> ["fmu", "plant", "parameters", "noise.seed"]: dots part the keys, but
    not in a quoted one (an FMI name that holds dots or brackets)."""
    return [json.loads(part) if part.startswith('"') else part
            for part in re.findall(rf"{_QUOTED_KEY}|[^.\"]+", key)]


def _template_line(lines: _SpecLines, key: str) -> int | None:
    """The line of the spec that sets the scenario key `key` (a dotted path,
    `metrics.driven`, `fmu.plant.parameters."noise.seed"`) in its [template]:
    the key in the deepest table of the path written as a header, or None
    where the template does not write it (a named case's patch)."""
    parts = _key_parts(key)
    for depth in range(len(parts) - 1, -1, -1):
        table = ".".join(["template", *parts[:depth]])
        span = lines.table(table)
        if span is None:
            continue
        rest = parts[depth:]
        # The rest is a key of that table, possibly dotted or quoted
        # (`"noise.seed" = `), or inside an inline table of its first part.
        for name in (".".join(rest), rest[-1], rest[0]):
            found = lines.key(name, span)
            if found != span[0] or lines.header(found) is None:
                return found
        return None
    return None


def _progress_lines(done: int, total: int, failed: int, started: float, study: str) -> None:
    elapsed = time.monotonic() - started
    rate = done / elapsed if elapsed > 0 else 0.0
    to_go = (f"about {(total - done) / rate:.0f} s to go" if rate > 0
             else "no run done yet to time the rest by")
    print(f"sweep {study}: {done}/{total} runs ({100 * done / max(total, 1):.0f} %), "
          f"{failed} failed, {elapsed:.0f} s elapsed, {to_go}", flush=True)


def stale_rows(out: Path, spec: Spec, rows: list[dict], runs: dict[str, Run]) -> int:
    """The number of runs of the table's `rows` that the spec (`runs` by
    key) no longer makes, and that consolidation drops: those that failed or
    timed out, which hold no result (a grid value fixed after it failed, as
    check_scenarios now refuses it). A run the spec no longer makes whose
    row holds a result is not dropped without being asked: StaleTable."""
    stale: dict[str, list[dict]] = {}
    for row in rows:
        if row.get("key") not in runs:
            stale.setdefault(row.get("key"), []).append(row)
    results = [rows_of_key[-1] for rows_of_key in stale.values()
               if any(r.get("status") == "ok" for r in rows_of_key)]
    if results:
        named = table_variables(out, spec.study) | {v.name for v in spec.variables} | {"sample"}
        first = ", ".join(f"{name} = {value!r}" for name, value in results[0].items()
                          if name in named) or f"key {results[0].get('key')}"
        total = len({row.get("key") for row in rows})
        raise StaleTable(
            f"{table_path(out, spec.study)}: {len(results)} of its {total} runs hold results "
            f"of runs that {spec.path} no longer makes (the first: {first}; the spec, a "
            f"parameter set or an FMU changed). A table holds the runs of one spec, and "
            f"dropping these would lose their results: pass --restart to start the table "
            f"over, or choose another --out")
    return len(stale)


def run_sweep(spec: Spec, out: Path, client, restart: bool = False, progress: str = "auto",
              on_row=None, checked: bool = False, on_interrupt=None,
              expanded: tuple[list[Run], dict[str, Path]] | None = None) -> dict:
    """Runs every run of `spec` not yet in DIR/<study>.parquet on `client`'s
    cluster. `on_row(row, done)` is called after each row (tests use it to
    kill a worker mid-sweep); `checked` says `check_scenarios` passed on all
    of its runs already; `on_interrupt()` is called on Ctrl-C before the
    tasks still out are cancelled (main silences a LocalCluster's logs);
    `expanded` is expand(spec) where the caller has it (main expands every
    spec to check it: 100,000 runs took seconds to expand, twice). Prints
    how many runs the spec has and how many of them the table holds before
    any is sent. Returns a summary (`interrupted`: Ctrl-C ended it, the rows
    received are in the table)."""
    from distributed import as_completed

    out.mkdir(parents=True, exist_ok=True)
    runs, fmus = expanded or expand(spec)
    keys = {run.key: run for run in runs}
    units = column_units(spec, runs)
    if restart:
        # The spec is checked before anything is deleted: a typo keeps the table.
        if not checked:
            check_scenarios(runs, fmus, spec)
            checked = True
        table_path(out, spec.study).unlink(missing_ok=True)
        journal_path(out, spec.study).unlink(missing_ok=True)
    existing = read_rows(out, spec.study)
    dropped = stale_rows(out, spec, existing, keys)
    done_keys = {row["key"] for row in existing if row.get("status") != "timeout"}
    todo = [run for run in runs if run.key not in done_keys]
    summary = {"study": spec.study, "runs": len(runs), "skipped": len(runs) - len(todo),
               "executed": 0, "failed": 0, "timeouts": 0, "lost": 0, "interrupted": False,
               "dropped": dropped}
    if dropped:
        print(f"{spec.study}: the failed or timed-out rows of {dropped} runs that {spec.path} "
              f"no longer makes leave the table (they hold no result)", flush=True)
    print(f"{spec.study}: {len(runs)} runs ({summary['skipped']} already in the table)",
          flush=True)
    if not todo:
        summary["rows"] = consolidate(out, spec, keys, units)
        return summary
    if not checked:
        check_scenarios(todo, fmus, spec)

    def scatter() -> dict:
        # A cluster whose workers all left (a worker that cannot unpickle a
        # task ends with it) is waited for a while, then named: dask's
        # scatter waited 30 s and raised "No valid workers found".
        if not client.scheduler_info().get("workers"):
            try:
                client.wait_for_workers(1, timeout=WORKER_WAIT_S)
            except TimeoutError:
                raise ClusterError(
                    f"every worker of the dask scheduler at {client.scheduler.address} left "
                    f"while the study ran, and none joined within {WORKER_WAIT_S:g} s: the "
                    f"workers' logs say why; the same command resumes") from None
        return {digest: client.scatter(path.read_bytes(), broadcast=True, hash=True)
                for digest, path in fmus.items()}

    def submit(task: list[Run], data: dict, key: str, pure: bool):
        # Tasks prefer the workers that can run them (ready_workers): a
        # worker without this package would die of the task. Loosely: a
        # worker the nanny restarts has a new address, and tasks bound to the
        # old ones would wait for ever.
        return client.submit(execute_runs, task, data, spec.timeout, key=key, pure=pure,
                             workers=ready if refused else None,
                             allow_other_workers=bool(refused))

    mode = progress
    if mode == "auto":
        mode = "bar" if sys.stdout.isatty() else "lines"
    journal = Journal(out, spec.study)
    started = last_line = time.monotonic()
    done = 0
    printed_at = None  # the `done` of the last progress line
    futures = []
    try:
        ready, refused = ready_workers(client)
        data = scatter()
        tasks = batches(todo, len(ready), spec.runs_per_task)
        futures += [submit(task, data, "runs-" + hashlib.sha256(
                        "".join(run.key for run in task).encode()).hexdigest()[:32], pure=True)
                    for task in tasks]
        task_of = {future.key: task for future, task in zip(futures, tasks)}
        tries = {future.key: 0 for future in futures}
        bar = None
        if mode == "bar":
            from distributed.diagnostics.progressbar import progress as dask_progress

            bar = threading.Thread(target=dask_progress, args=(futures,),
                                   kwargs={"multi": False}, daemon=True)
            bar.start()
        pending = as_completed(futures)
        for future in pending:
            try:
                rows = future.result()
            except Exception as e:  # noqa: BLE001 - the task did not run (see below)
                # Not failed runs (those are rows) but a task that could not
                # run: a worker without the package or the master, a task
                # whose workers died again and again. It is sent again (a
                # worker that died took the FMUs scattered to it); then its
                # runs stay out of the table, and the next invocation runs
                # them again.
                task = task_of[future.key]
                # Only data lost with a worker is worth sending again; a
                # task that fails by itself (a worker without the package, a
                # task that kills its workers) fails again.
                lost_data = type(e).__name__ in ("FutureCancelledError", "CancelledError")
                if lost_data and tries[future.key] < TASK_RETRIES:
                    data = scatter()
                    again = submit(task, data, f"{future.key}-again", pure=False)
                    task_of[again.key], tries[again.key] = task, tries[future.key] + 1
                    pending.add(again)
                    futures.append(again)
                    continue
                if summary["lost"] == 0:
                    print(f"a run could not be executed: {type(e).__name__}: {e}"
                          + lost_task_hint(e), file=sys.stderr, flush=True)
                summary["lost"] += len(task)
                continue
            for row in rows:
                journal.add(row)
                done += 1
                summary["executed"] += 1
                summary["failed"] += row["status"] == "error"
                summary["timeouts"] += row["status"] == "timeout"
                if on_row is not None:
                    on_row(row, done)
            if mode == "lines" and time.monotonic() - last_line >= PROGRESS_SECONDS:
                last_line = time.monotonic()
                _progress_lines(done, len(todo), summary["failed"], started, spec.study)
                printed_at = done
        if bar is not None:
            # dask's bar draws in place, its line unended, until it learns
            # (every 100 ms) that its tasks are done and clears it: what is
            # printed next waits for that, or starts a line of its own (a
            # bar whose task was sent again may not end).
            bar.join(timeout=BAR_END_SECONDS)
            if bar.is_alive():
                print(flush=True)
    except KeyboardInterrupt:
        # Ctrl-C, wherever it lands once the runs are being sent: the rows
        # received so far are in the journal and go into the table below;
        # the tasks still out are dropped, and the next invocation runs
        # their runs.
        summary["interrupted"] = True
        if on_interrupt is not None:
            on_interrupt()
        client.cancel(futures)
    finally:
        journal.close()
        summary["rows"] = consolidate(out, spec, keys, units)
        summary["wall_s"] = time.monotonic() - started
    if mode == "lines" and not summary["interrupted"] and printed_at != done:
        _progress_lines(done, len(todo), summary["failed"], started, spec.study)
    return summary


#: A preload (the text of a module) for a LocalCluster's workers. Ctrl-C in
#: a terminal interrupts its whole foreground process group: the worker
#: processes, and the masters they run, would die with tracebacks of their
#: own, and a master killed mid-run would come back as a failed run. Each
#: worker, a restarted one too, ignores SIGINT once it has started (its
#: masters inherit that), so that an interrupt is this process's alone to
#: handle: run_sweep and main end the study in order.
WORKER_PRELOAD = """
import signal


def dask_setup(worker):
    signal.signal(signal.SIGINT, signal.SIG_IGN)
"""


@contextlib.contextmanager
def make_client(scheduler: str | None, workers: int | None):
    """A client of an existing scheduler, or of a LocalCluster of `workers`
    single-threaded processes (default: one per core), closed on leaving."""
    if scheduler:
        from distributed import Client

        reach(scheduler)
        try:
            client = Client(scheduler, timeout=f"{CONNECT_TIMEOUT_S:g}s")
        except (OSError, TimeoutError) as e:
            raise ClusterError(f"no dask scheduler answered at {scheduler} within "
                               f"{CONNECT_TIMEOUT_S:g} s ({e}): is it a dask scheduler's "
                               f"address?") from None
        with client:
            yield client
        return
    from multiprocessing import resource_tracker

    # A worker process starts ignoring SIGINT when its preload runs, a second
    # or so after it starts. Until the cluster is up this thread holds an
    # interrupt back (raised once the cluster is there to close in order),
    # and so do the threads it starts: distributed's, when this is its first
    # import (the command line's case), whose worker processes inherit the
    # blocked signal. multiprocessing's resource tracker, started with the
    # first process, would unblock SIGINT in the thread that starts it: it
    # is started first.
    resource_tracker.ensure_running()
    held = signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT})
    try:
        from distributed import Client, LocalCluster

        with LocalCluster(n_workers=workers or os.cpu_count() or 1, threads_per_worker=1,
                          processes=True, dashboard_address=None,
                          preload=[WORKER_PRELOAD]) as cluster, Client(cluster) as client:
            try:
                # A held interrupt is taken here and raised as such: let
                # through by the unblocking, it may land in a callback
                # (distributed's garbage collection diagnostics), where
                # Python reports an exception and drops it.
                interrupted = signal.sigtimedwait({signal.SIGINT}, 0)
                signal.pthread_sigmask(signal.SIG_SETMASK, held)
                if interrupted:
                    raise KeyboardInterrupt
                yield client
            except KeyboardInterrupt:
                silence_cluster_logs(client)
                raise
    finally:
        signal.pthread_sigmask(signal.SIG_SETMASK, held)


def reach(address: str) -> None:
    """Raises ClusterError, in a line and at once, when nothing takes a TCP
    connection at a scheduler's `address` (a host unknown, a connection
    refused): dask's client retried for its whole timeout (30 s), then
    ended in a traceback. Addresses of other protocols are left to it."""
    from distributed.comm.addressing import parse_address, parse_host_port

    try:
        scheme, location = parse_address(address, strict=False)
        if scheme not in ("tcp", "tls"):
            return
        host, port = parse_host_port(location)
    except ValueError as e:
        raise ClusterError(f"--scheduler {address}: not a scheduler's address ({e}); "
                           f"tcp://HOST:PORT") from None
    try:
        socket.create_connection((host, port), timeout=CONNECT_TIMEOUT_S).close()
    except socket.gaierror as e:
        raise ClusterError(f"cannot reach the dask scheduler at {address}: host {host!r} not "
                           f"found ({e.strerror})") from None
    except ConnectionRefusedError:
        raise ClusterError(f"cannot reach the dask scheduler at {address}: connection refused "
                           f"(no scheduler listens on port {port} of {host}; start `dask "
                           f"scheduler` there, README \"Sweeps on dask\")") from None
    except OSError as e:
        raise ClusterError(f"cannot reach the dask scheduler at {address}: "
                           f"{e.strerror or e or type(e).__name__}") from None


def ready_workers(client) -> tuple[list[str], list[str]]:
    """The workers of `client`'s cluster that can run a study's tasks (they
    import this package and fmpy and find the master) and those that
    cannot, after the scheduler has shown it can unpickle the tasks; waits
    WORKER_WAIT_S for a first worker. Raises ClusterError when the scheduler
    or every worker cannot, naming the cause and what to do; names on
    stderr the workers that cannot when others can (run_sweep's tasks prefer
    the others: dask may still give such a worker a task once none of them
    is left, and the task then ends it, as a lost run)."""
    import logging

    address = client.scheduler.address
    # A probe that fails is logged with its traceback by the scheduler of a
    # LocalCluster, in this process: the ClusterError says it in a line.
    logger = logging.getLogger("distributed")
    level = logger.level
    logger.setLevel(logging.CRITICAL)
    try:
        try:
            client.run_on_scheduler(exec, SCHEDULER_PROBE, {})
        except Exception as e:  # noqa: BLE001 - the scheduler's own error, named
            raise ClusterError(f"the dask scheduler at {address} cannot read the tasks: "
                               f"{type(e).__name__}: {e}" + lost_task_hint(e)) from None
        if not client.scheduler_info().get("workers"):
            try:
                client.wait_for_workers(1, timeout=WORKER_WAIT_S)
            except TimeoutError:
                raise ClusterError(f"the dask scheduler at {address} has no worker (none joined "
                                   f"within {WORKER_WAIT_S:g} s): start `dask worker {address}` "
                                   f"(README, \"Sweeps on dask\")") from None
        outcomes = client.run(exec, WORKER_PROBE, {}, on_error="return")
    finally:
        logger.setLevel(level)
    bad = {worker: error for worker, error in outcomes.items()
           if isinstance(error, BaseException)}
    if bad:
        worker, error = next(iter(bad.items()))
        why = f"{worker}: {type(error).__name__}: {error}"
        if len(bad) == len(outcomes):
            raise ClusterError(f"no worker of the dask scheduler at {address} can run the tasks "
                               f"({len(bad)} of {len(outcomes)}; {why})" + lost_task_hint(error))
        print(f"{len(bad)} of {len(outcomes)} workers cannot run the tasks and get none "
              f"({', '.join(bad)}; {why})" + lost_task_hint(error), file=sys.stderr, flush=True)
    return [worker for worker in outcomes if worker not in bad], list(bad)


def silence_cluster_logs(client) -> None:
    """Silences dask's logs in this process and in `client`'s workers (a
    LocalCluster's, whose logs are this process's output) before an
    interrupted study drops its tasks: the scheduler and the workers would
    report every task cancelled and every scattered FMU lost, which is what
    an interrupt means."""
    import logging

    def silence():
        logging.getLogger("distributed").setLevel(logging.CRITICAL)

    silence()
    try:
        client.run(silence)
    except Exception:  # noqa: BLE001 - a worker already gone has nothing to say
        pass


def main(argv=None) -> int:
    # The keys of each study's runs, by study, once expanded: what an
    # interrupt says is kept is the rows of these runs in the tables.
    run_keys: dict[str, set] = {}
    args = None
    try:
        args = _arguments(argv)
        # The command as given, for the report to say what made it.
        args.command = shlex.join(["python", "-m", "demo.sweep",
                                   *(sys.argv[1:] if argv is None else argv)])
        return _run_studies(args, run_keys)
    except KeyboardInterrupt:
        print(interrupted_message(run_keys, args.out if args else None,
                                  bool(args and args.restart)), file=sys.stderr)
        return 130


def positive_count(text: str) -> int:
    """An argument that counts something, 1 or more: dask's LocalCluster
    takes 0 workers as "one per core", which --workers 0 did silently."""
    try:
        count = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a whole number") from None
    if count < 1:
        raise argparse.ArgumentTypeError(f"{count} is not a count of workers (1 or more)")
    return count


def _arguments(argv):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("specs", nargs="+", type=Path, help="sweep spec files (TOML)")
    parser.add_argument("--out", type=Path, default=Path("out/sweep"),
                        help="folder of the tables and the report (default out/sweep)")
    parser.add_argument("--scheduler", help="address of a running dask scheduler "
                                            "(tcp://HOST:PORT); default: a LocalCluster")
    parser.add_argument("--workers", type=positive_count, help="LocalCluster worker processes "
                                                               "(default: one per core)")
    parser.add_argument("--restart", action="store_true",
                        help="discard the existing tables of these specs and run everything")
    parser.add_argument("--progress", choices=("auto", "bar", "lines", "none"), default="auto",
                        help="dask's progress bar (a terminal), periodic lines, or nothing")
    parser.add_argument("--no-report", action="store_true", help="do not write report.md")
    return parser.parse_args(argv)


def interrupted_message(run_keys: dict, out: Path | None, restart: bool) -> str:
    """The one line an interrupted command ends with: the runs of each study
    its table keeps (the rows received before the interrupt, and those of
    earlier invocations), and how to resume: the same command, which skips
    them, but without --restart, which would discard them."""
    kept = []
    for study, keys in run_keys.items():
        rows = {row.get("key") for row in read_rows(out, study)} & keys
        if rows:
            kept.append(f"{len(rows)} of {len(keys)} runs of {study} kept in "
                        f"{table_path(out, study)}")
        else:
            kept.append(f"no run of {study} kept ({len(keys)} to run)")
    resume = ("run the same command without --restart to resume (with it, to start over)"
              if restart else "run the same command again to resume")
    if not kept:
        return f"interrupted before any run: {resume}"
    return f"interrupted: {'; '.join(kept)}; {resume}"


def _run_studies(args, run_keys: dict) -> int:
    """main's work: the specs checked, their runs sent, the report written;
    the exit status. A KeyboardInterrupt is left to main."""
    expanded = {}
    try:
        specs = [load_spec(path) for path in args.specs]
        master.binary()
        studies = [spec.study for spec in specs]
        for spec in specs:
            if studies.count(spec.study) > 1:
                raise SpecError(f"{spec.path}: study {spec.study!r} is the study of another "
                                f"spec given; each study has its own table")
            # Every spec's runs are checked before any runs: a typo in the
            # last spec fails now, not after the first ones have run. Each is
            # expanded once, here: run_sweep takes the runs.
            runs, fmus = expanded[spec.study] = expand(spec)
            check_scenarios(runs, fmus, spec)
            run_keys[spec.study] = {run.key for run in runs}
        check_out(args.out, studies)
    except (SpecError, FileNotFoundError) as e:
        print(e, file=sys.stderr)
        return 2
    try:
        return _run_on_cluster(args, specs, expanded)
    except ClusterError as e:
        print(e, file=sys.stderr)
        return EXIT_CLUSTER


def check_out(out: Path, studies: list[str]) -> None:
    """Raises SpecError (status 2) before any run when `out` cannot hold
    the studies' tables: a file, not a folder, or one that cannot be made;
    a table there that cannot be read (UnreadableTable). Either failed in a
    traceback once the cluster had started, with the status of failed
    runs."""
    if out.exists() and not out.is_dir():
        raise SpecError(f"{out}: --out names a file; it names the folder of the tables")
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as e:
        raise SpecError(f"{out}: cannot make the folder of the tables ({e.strerror})") from None
    for study in studies:
        read_rows(out, study)


def summary_line(summary: dict, table: Path) -> str:
    """The line that ends a study: its runs executed, failed, timed out and
    skipped, and its table, or that there is none (every run lost: the
    table named before was a file that did not exist)."""
    rows = (f"{summary['rows']} rows in {table}" if summary["rows"]
            else f"no table written ({table}): no run has finished")
    return (f"{summary['study']}: {summary['executed']} runs executed "
            f"({summary['failed']} failed, {summary['timeouts']} timed out), "
            f"{summary['skipped']} already in the table; {rows}"
            + (f"; {summary['wall_s']:.1f} s" if "wall_s" in summary else ""))


def _run_on_cluster(args, specs: list[Spec], expanded: dict) -> int:
    """_run_studies' part on the cluster: each spec's runs (`expanded`:
    expand(spec) by study), then the report; the exit status. A
    ClusterError is left to _run_studies."""
    timed_out = failed = 0
    with make_client(args.scheduler, args.workers) as client:
        print(f"dask: {len(client.scheduler_info()['workers'])} workers "
              f"({args.scheduler or 'LocalCluster'})", flush=True)
        for spec in specs:
            try:
                summary = run_sweep(spec, args.out, client, args.restart, args.progress,
                                    checked=True, on_interrupt=None if args.scheduler else
                                    lambda: silence_cluster_logs(client),
                                    expanded=expanded[spec.study])
            except SpecError as e:
                print(e, file=sys.stderr)
                return 2
            if summary["interrupted"]:
                # The rows received are in the table; main says how many.
                raise KeyboardInterrupt
            print(summary_line(summary, table_path(args.out, spec.study)), flush=True)
            failed += summary["failed"]
            if summary["timeouts"]:
                timed_out += summary["timeouts"]
                print(f"{summary['timeouts']} runs gave no result within {spec.timeout} s: run "
                      f"the same command again to retry them", file=sys.stderr)
            if summary["lost"]:
                # The cluster's failure, not the runs': no row says why.
                print(f"{summary['lost']} runs could not be executed (see above): run the "
                      f"same command again to retry them", file=sys.stderr)
                return EXIT_CLUSTER
    if not args.no_report:
        from .sweep_report import write_report

        report = write_report(args.out, args.command)
        print(f"report: {report}")
    # The report shows what is in the tables; a table with timed-out or
    # failed runs is not complete, and the exit status says so.
    if failed:
        print(f"{failed} run{'s' if failed != 1 else ''} failed: their rows say why (status, "
              f"error)", file=sys.stderr)
    return 1 if timed_out or failed else 0


if __name__ == "__main__":
    sys.exit(main())
