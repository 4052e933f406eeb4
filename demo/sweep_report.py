"""report.md and heatmaps (PNG) of the sweep tables in a folder.

    python -m demo.sweep_report [--out out/sweep]

Every <study>.parquet of the folder is rendered by the report its spec names
(`report = "envelope"` or `"robustness"`, kept in the table's metadata with
the spec's text); the figures are recomputed from the tables each time, so a
re-run of `make sweep` regenerates everything.
"""

from __future__ import annotations

import argparse
import json
import math
import re
import shlex
import sys
from collections import defaultdict
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from matplotlib.colors import LogNorm  # noqa: E402

from .sweep import REPORT_OPTIONS  # noqa: E402

#: Share of a run's samples with a command at its limit above which the run
#: measures the command range more than the plant.
SATURATED_SHARE = 0.01

#: Table 3's couplings per driven axis: (metric, label).
COUPLINGS = {
    "y": (("coupling_x2_span", "x2 from y"), ("coupling_x3_span", "x3 from y")),
    "x": (("coupling_y_span", "y from x"),),
    "theta": (("coupling_y_span", "y from rotation"),),
}


def load(path: Path) -> tuple[list[dict], dict]:
    import pyarrow.parquet as pq

    table = pq.read_table(path)
    meta = {k.decode(): v.decode() for k, v in (table.schema.metadata or {}).items()}
    return table.to_pylist(), meta


def spec_comment(spec_text: str) -> str:
    """The spec's leading comment block as Markdown: its paragraphs, and its
    "- " items as a list."""
    lines = []
    for line in spec_text.splitlines():
        if not line.startswith("#"):
            if line.strip():
                break
            continue
        text = line[1:].strip()
        if text.startswith("- ") or not lines or not text:
            lines.append(text)
        elif lines[-1]:
            lines[-1] += " " + text
        else:
            lines.append(text)
    out = []
    for text in lines:
        if text.startswith("- ") and out and out[-1] and not out[-1].startswith("- "):
            out.append("")
        out.append(text)
    return "\n".join(out)


def excluded_points(spec_text: str) -> list[str]:
    """The spec's [[exclude]] rules, as a Markdown paragraph (the blank
    cells of the heatmaps), with the comment that gives their reason."""
    import tomllib

    try:
        rules = tomllib.loads(spec_text).get("exclude", [])
    except tomllib.TOMLDecodeError:
        return []
    if not rules:
        return []
    text = "; ".join(", ".join(f"{k} = {v}" for k, v in rule.items()) for rule in rules)
    return [f"Not run (the spec's exclusions, blank in the heatmaps; its comments say why): "
            f"{text}.", ""]


def fmt(value, digits=3) -> str:
    if value is None or (isinstance(value, float) and not math.isfinite(value)):
        return "–"
    return f"{value:.{digits}g}"


def percentiles(values) -> tuple[float, float, float]:
    v = np.asarray([x for x in values if x is not None and math.isfinite(x)])
    if v.size == 0:
        return (math.nan,) * 3
    p5, p50, p95 = np.percentile(v, [5, 50, 95])
    return float(p5), float(p50), float(p95)


def run_summary(rows: list[dict]) -> str:
    failed = [r for r in rows if r["status"] != "ok"]
    cpu = sum(r.get("wall_s") or 0.0 for r in rows)
    workers = len({r.get("worker") for r in rows})
    # Short studies' runs take tenths of a second: "0 s" said nothing.
    wall = f"{cpu:.0f} s" if cpu >= 10 else f"{cpu:.2g} s"
    text = (f"{len(rows)} runs ({len(failed)} failed), {wall} of master wall time in "
            f"all, on {workers} worker(s).")
    if failed:
        reasons = defaultdict(int)
        for r in failed:
            reasons[(r.get("error") or "")[:160]] += 1
        text += " Failures: " + "; ".join(f"{n} x `{why}`" for why, n in
                                           sorted(reasons.items(), key=lambda kv: -kv[1])[:3])
    return text


def spec_variables(meta: dict) -> list[str]:
    """The names of the study's variables, in its spec's order (the table's
    metadata keeps the spec's text)."""
    import tomllib

    try:
        entries = tomllib.loads(meta.get("spec", "")).get("variable", [])
    except tomllib.TOMLDecodeError:
        return []
    return [entry["name"] for entry in entries
            if isinstance(entry, dict) and isinstance(entry.get("name"), str)]


def further_variables(meta: dict, read: set[str]) -> list[str]:
    """The variables of the study a report does not read itself (`read`):
    its tables and figures are split by their values, so that two runs
    that differ only in one of them are never taken for one."""
    return [name for name in spec_variables(meta) if name not in read]


def varying(rows: list[dict], names: list[str]) -> list[str]:
    """Those of `names` that take more than one value in `rows`: each gets a
    column of the report's tables (one value is said once, in a sentence)."""
    return [name for name in names if len({repr(r.get(name)) for r in rows}) > 1]


def constant_values(rows: list[dict], names: list[str]) -> list[str]:
    """The sentence that gives the variables of `names` that keep one value
    in every run (none when there are none)."""
    fixed = [name for name in names if name not in varying(rows, names) and rows]
    if not fixed:
        return []
    return ["Every run has " + ", ".join(f"{name} = {show(rows[0].get(name))}"
                                         for name in fixed) + ".", ""]


def show(value) -> str:
    """A variable's value in a table cell or a label: a number in full
    (fmt's three digits could show 0.1011 and 0.1012 as one), a case by its
    name."""
    return str(value)


def group_label(group: tuple, shown: list[str]) -> str:
    """`name = value, ...` of the variables of `group` ((name, value)
    pairs) that `shown` lists."""
    return ", ".join(f"{name} = {show(value)}" for name, value in group if name in shown)


def paired_runs(rows: list[dict], by: list[str]) -> dict[tuple, dict[str, dict]]:
    """The runs that completed, paired without and with decoupling by their
    values of `by`: {values: {"off": row, "on": row}}. `by` names every
    variable but decoupling (and a Monte Carlo's sample), so a pair is one
    point run twice. Two rows at one key and one decoupling would be one
    summarised in place of the other: that is an error of the report's
    grouping, raised rather than hidden."""
    pairs: dict[tuple, dict[str, dict]] = defaultdict(dict)
    for r in rows:
        if r["status"] != "ok":
            continue
        key = tuple(r.get(name) for name in by)
        if r["decoupling"] in pairs[key]:
            where = ", ".join(f"{name} = {show(value)}" for name, value in zip(by, key))
            raise ValueError(f"two runs of the table at {where}, decoupling "
                             f"{r['decoupling']}: the report would show one of them")
        pairs[key][r["decoupling"]] = r
    return pairs


# --------------------------------------------------------------------------
# Envelope

#: The variables the envelope report reads itself: the rest split its tables.
ENVELOPE_VARIABLES = ("stage", "method", "axis", "held", "amplitude", "frequency", "decoupling")


def envelope_points(rows: list[dict], further: list[str] = ()) -> dict:
    """Pairs each run without decoupling with the same run with it:
    (stage, method, axis, further, held, amplitude, frequency) -> {off,
    on}, `further` the ((name, value), ...) of the spec's other
    variables."""
    further = list(further)
    by = ["stage", "method", "axis", *further, "held", "amplitude", "frequency"]
    points = {}
    for key, pair in paired_runs(rows, by).items():
        extra = tuple(zip(further, key[3:3 + len(further)]))
        points[(*key[:3], extra, *key[3 + len(further):])] = pair
    return points


def relative_tracking(row: dict) -> float:
    span = row.get("demand_span") or 0.0
    return row["tracking_rms"] / (span / 2) if span > 0 else math.nan


def realtime(row: dict) -> float:
    """Simulated seconds per second of the master's wall time."""
    wall = row.get("wall_s") or 0.0
    return row["simulated_s"] / wall if wall > 0 else math.nan


def reductions(axis: str, off: dict, on: dict) -> dict:
    out = {}
    for metric, label in COUPLINGS[axis]:
        a, b = off.get(metric), on.get(metric)
        out[label] = a / b if a is not None and b else math.nan
    return out


def envelope_section(rows: list[dict], meta: dict, out: Path) -> list[str]:
    options = json.loads(meta.get("report_options", "{}"))
    tracking_limit = float(options.get("tracking_limit", REPORT_OPTIONS["tracking_limit"]))
    reduction_limit = float(options.get("reduction_limit", REPORT_OPTIONS["reduction_limit"]))
    further = further_variables(meta, set(ENVELOPE_VARIABLES))
    shown = varying(rows, further)
    points = envelope_points(rows, further)
    lines = [f"## {meta.get('title', 'Operating envelope')}", "",
             spec_comment(meta.get("spec", "")), "", run_summary(rows), "",
             *excluded_points(meta.get("spec", "")), *constant_values(rows, further),
             f"A point **holds** when the tracking RMS (decoupling on) is at most "
             f"{100 * tracking_limit:g} % of the demanded amplitude and decoupling shrinks every "
             f"Table 3 coupling span at least {reduction_limit:g}x. Saturation: share of the "
             f"measured period with a command at the controller's limit. Speed: simulated time "
             f"over the master's wall time per run (both FMUs and the loop, on the machine and "
             f"under the load of this sweep); below 1x the loop could not keep its 10 kHz "
             f"sample in real time.", ""]
    # (stage, method, axis, further) -> [((held, amplitude, frequency), pair)]
    groups = defaultdict(list)
    for key, pair in points.items():
        if "on" in pair and "off" in pair:
            groups[key[:4]].append((key[4:], pair))
    lines += ["| stage | method | axis | " + "".join(f"{name} | " for name in shown)
              + "points holding | tracking RMS / amplitude (median, worst) "
              "| coupling reduction (median, worst) | speed x real time (median, slowest) "
              "| where it breaks |",
              "|---|---|---|" + "---|" * len(shown) + "---|---|---|---|---|"]
    for (stage, method, axis, extra), items in sorted(groups.items(), key=_group_order):
        rel = [relative_tracking(pair["on"]) for _, pair in items]
        red = [min(reductions(axis, pair["off"], pair["on"]).values()) for _, pair in items]
        holds = [r <= tracking_limit and d >= reduction_limit for r, d in zip(rel, red)]
        breaks = [(k, pair, r, d) for (k, pair), r, d, h in zip(items, rel, red, holds) if not h]
        speed = [realtime(pair[d]) for _, pair in items for d in ("off", "on")]
        cells = "".join(f"{show(value)} | " for name, value in extra if name in shown)
        lines.append(f"| {stage} | {method} | {axis} | {cells}{sum(holds)}/{len(holds)} | "
                     f"{fmt(100 * np.nanmedian(rel))} %, {fmt(100 * np.nanmax(rel))} % | "
                     f"{fmt(np.nanmedian(red))}x, {fmt(np.nanmin(red))}x | "
                     f"{fmt(np.nanmedian(speed))}x, {fmt(np.nanmin(speed))}x | "
                     f"{describe_breaks(items, holds, breaks, tracking_limit, reduction_limit)} |")
    lines.append("")
    for stage, method, extra in sorted({(k[0], k[1], k[3]) for k in groups},
                                       key=lambda k: (k[0], k[1], _sortable(k[2]))):
        # A figure per value of the further variables, named by them.
        suffix = "".join(f"_{name}-{show(value)}" for name, value in extra if name in shown)
        label = group_label(extra, shown)
        for kind in ("tracking", "coupling"):
            name = re.sub(r"[^\w.=-]", "_", f"envelope_{stage}_{method}{suffix}_{kind}") + ".png"
            limit = tracking_limit if kind == "tracking" else reduction_limit
            envelope_figure(groups, (stage, method, extra), label, kind, limit, out / name)
            lines.append(f"![{kind}, {stage}, {method}{', ' + label if label else ''}]({name})")
        lines.append("")
    return lines


def _sortable(group: tuple) -> tuple:
    """A group's ((name, value), ...) in an order that mixes no types: a
    variable's values are all numbers or all case names."""
    return tuple((name, (0, value, "") if isinstance(value, (int, float)) else (1, 0, str(value)))
                 for name, value in group)


def _group_order(item) -> tuple:
    (stage, method, axis, extra), _ = item
    return stage, method, axis, _sortable(extra)


def describe_breaks(items, holds, breaks, tracking_limit, reduction_limit) -> str:
    """Share of failing points per value of each grid variable, and why."""
    if not breaks:
        return "nowhere on the grid"
    parts = []
    for index, name, unit in ((2, "f", " Hz"), (1, "amplitude", ""), (0, "held", "")):
        counts = defaultdict(lambda: [0, 0])
        for (key, _), ok in zip(items, holds):
            counts[key[index]][1] += 1
            counts[key[index]][0] += not ok
        parts.append(f"{name}: " + ", ".join(f"{fmt(v)}{unit} {n}/{total}"
                                              for v, (n, total) in sorted(counts.items())))
    reasons = defaultdict(int)
    for _, pair, rel, red in breaks:
        saturated = max(pair["on"].get("command_saturation") or 0,
                        pair["off"].get("command_saturation") or 0) > SATURATED_SHARE
        if rel > tracking_limit:
            reasons["tracking" + (", saturated" if saturated else "")] += 1
        if red < reduction_limit:
            reasons["decoupling" + (", saturated" if saturated else "")] += 1
    why = "; ".join(f"{reason} {n}" for reason, n in sorted(reasons.items(), key=lambda kv: -kv[1]))
    return "failing " + "; ".join(parts) + f" (why: {why})"


def _legible_on(image, value: float) -> str:
    """Black on a light cell (viridis's yellow end), white on a dark one:
    white on yellow could not be read."""
    red, green, blue, _ = image.cmap(image.norm(value))
    return "black" if 0.299 * red + 0.587 * green + 0.114 * blue > 0.5 else "white"


def envelope_figure(groups, where: tuple, label: str, kind, limit, path: Path) -> None:
    """One heatmap (frequency x amplitude) per axis or coupling and held
    demand, on one colour scale; the values of failing cells in red.
    `where` is (stage, method, further variables' values), `label` says the
    latter."""
    stage, method, extra = where
    axes_present = [a for a in ("x", "y", "theta") if (stage, method, a, extra) in groups]
    panels = []
    for axis in axes_present:
        if kind == "tracking":
            panels.append((axis, None, f"{axis}: tracking RMS / amplitude [%]"))
        else:
            for _, coupling in COUPLINGS[axis]:
                panels.append((axis, coupling, f"{coupling}: span without / with decoupling"))
    held_values = sorted({k[0] for a in axes_present
                          for k, _ in groups[(stage, method, a, extra)]})
    grids = []
    for axis, coupling, title in panels:
        items = groups[(stage, method, axis, extra)]
        amplitudes = sorted({k[1] for k, _ in items})
        frequencies = sorted({k[2] for k, _ in items})
        for held in held_values:
            z = np.full((len(amplitudes), len(frequencies)), np.nan)
            for (h, a, f), pair in items:
                if h == held:
                    z[amplitudes.index(a), frequencies.index(f)] = (
                        100 * relative_tracking(pair["on"]) if kind == "tracking"
                        else reductions(axis, pair["off"], pair["on"])[coupling])
            grids.append((title, held, amplitudes, frequencies, z))
    values = np.concatenate([g[-1].ravel() for g in grids])
    values = values[np.isfinite(values) & (values > 0)]
    norm = LogNorm(vmin=values.min(), vmax=max(values.max(), values.min() * 1.01)) \
        if values.size else None
    fig, grid = plt.subplots(len(panels), len(held_values), squeeze=False,
                             figsize=(3.3 * len(held_values) + 1, 2.5 * len(panels)))
    image = None
    for n, (title, held, amplitudes, frequencies, z) in enumerate(grids):
        row, col = divmod(n, len(held_values))
        ax = grid[row][col]
        image = ax.imshow(z, origin="lower", aspect="auto", norm=norm,
                          cmap="viridis_r" if kind == "coupling" else "viridis")
        for i in range(z.shape[0]):
            for j in range(z.shape[1]):
                if np.isfinite(z[i, j]):
                    fails = z[i, j] > 100 * limit if kind == "tracking" else z[i, j] < limit
                    ax.text(j, i, fmt(z[i, j], 2), ha="center", va="center", fontsize=7,
                            color="red" if fails else _legible_on(image, z[i, j]),
                            fontweight="bold" if fails else "normal")
        ax.set_xticks(range(len(frequencies)), [fmt(f) for f in frequencies], fontsize=7)
        ax.set_yticks(range(len(amplitudes)), [fmt(a) for a in amplitudes], fontsize=7)
        if row == len(panels) - 1:
            ax.set_xlabel("frequency [Hz]", fontsize=8)
        if col == 0:
            ax.set_ylabel("amplitude / stroke", fontsize=8)
        ax.set_title(f"{title}\nheld axes at {fmt(held)} of stroke", fontsize=8)
    what = (f"tracking RMS / amplitude [%] (red: above {fmt(100 * limit)} %)" if kind == "tracking"
            else f"coupling span without / with decoupling (red: below {fmt(limit)}x)")
    fig.suptitle(f"{stage}, {method}{', ' + label if label else ''}: {what}", fontsize=10)
    fig.tight_layout(rect=(0, 0, 0.92, 1))
    if image is not None:
        fig.colorbar(image, ax=grid.ravel().tolist(), shrink=0.6, pad=0.02)
    fig.savefig(path, dpi=90)
    plt.close(fig)


# --------------------------------------------------------------------------
# Robustness

#: The variables the robustness report reads itself: the rest split its tables.
ROBUSTNESS_VARIABLES = ("axis", "decoupling")


def robustness_figures(rows: list[dict], further: list[str]) -> dict:
    """The figures of each group of runs, by sample: {(group, axis, name):
    {sample: value}}, `group` the ((name, value), ...) of the `further`
    variables. A run is paired with its twin of the other decoupling by
    every variable and its sample (paired_runs), so no two runs of the
    table fall on one figure's sample."""
    metrics = defaultdict(dict)
    further = list(further)
    for key, pair in paired_runs(rows, [*further, "axis", "sample"]).items():
        group, (axis, sample) = tuple(zip(further, key)), key[len(further):]
        if "on" in pair:
            metrics[(group, axis, f"{axis} tracking RMS")][sample] = pair["on"]["tracking_rms"]
        if "on" in pair and "off" in pair:
            for label, value in reductions(axis, pair["off"], pair["on"]).items():
                metrics[(group, axis, f"{label} reduction")][sample] = value
    return dict(metrics)


def figure_unit(figure: tuple) -> str:
    """The unit of a robustness figure (group, axis, name), as an axis label
    writes it: a tracking RMS in the driven axis's (`piezo-cosim metrics`),
    a reduction a ratio ("1")."""
    from .sweep import metric_definitions

    _, axis, name = figure
    if name.endswith("tracking RMS"):
        unit = metric_definitions()["tracking_rms"]["unit"][axis]
        return {"um": "µm"}.get(unit, unit)
    return "1"


def figure_label(figure: tuple, shown: list[str]) -> str:
    """A figure as the report's tables and plots name it: the values of the
    varying further variables, then the figure."""
    group, _, name = figure
    where = group_label(group, shown)
    return f"{where}: {name}" if where else name


def robustness_section(rows: list[dict], meta: dict, out: Path) -> list[str]:
    further = further_variables(meta, set(ROBUSTNESS_VARIABLES))
    shown = varying(rows, further)
    lines = [f"## {meta.get('title', 'Robustness')}", "", spec_comment(meta.get("spec", "")),
             "", run_summary(rows), "", *constant_values(rows, further)]
    ok = [r for r in rows if r["status"] == "ok"]
    factors = sorted({k for r in rows for k in r if k.startswith("factor.")})
    metrics = robustness_figures(rows, further)
    order = sorted(metrics, key=lambda f: (_sortable(f[0]), f[2]))
    lines += ["Tracking RMS with decoupling on (µm; rad for theta) and coupling reduction "
              "(span without / with decoupling) over the samples"
              + (f", for each value of {', '.join(shown)}" if shown else "") + ":", "",
              "| " + "".join(f"{name} | " for name in shown)
              + "figure | P5 | P50 | P95 | samples |",
              "|" + "---|" * len(shown) + "---|---|---|---|---|"]
    for figure in order:
        values = metrics[figure]
        p5, p50, p95 = percentiles(values.values())
        cells = "".join(f"{show(value)} | " for name, value in figure[0] if name in shown)
        lines.append(f"| {cells}{figure[2]} | {fmt(p5)} | {fmt(p50)} | {fmt(p95)} | "
                     f"{len(values)} |")
    lines.append("")
    lines += [saturation_summary(ok, shown), ""]
    clipped = held_at_bounds(rows, factors)
    if clipped:
        lines += ["Factors held at a bound of the parameter's declared range (the model is "
                  "not defined beyond it): " + ", ".join(
                      f"`{name.removeprefix('factor.')}` in {n} of {total} samples"
                      for name, (n, total) in clipped.items()) + ".", ""]
    sensitivity = sensitivities(metrics, factors, rows)
    lines += ["Sensitivity: a least-squares fit of log(figure) on every factor, each scaled "
              "to [-1, 1] over its range; the effect is the change of the figure from the "
              "low to the high end of the parameter's range, the others at their mean "
              "(R² says how much of the spread the linear fit explains). Parameters by their "
              "largest effect on any figure:", ""]
    names = sorted({k for _, per in sensitivity.items() for k in per["effects"]},
                   key=lambda n: -max(abs(per["effects"].get(n, 0.0))
                                      for per in sensitivity.values()))
    columns = order
    lines.append("| parameter | " + " | ".join(figure_label(c, shown) for c in columns) + " |")
    lines.append("|---|" + "---|" * len(columns))
    for name in names[:12]:
        cells = [f"{100 * sensitivity[c]['effects'][name]:+.1f} %" for c in columns]
        lines.append(f"| {name.removeprefix('factor.')} | " + " | ".join(cells) + " |")
    lines.append("| R² | " + " | ".join(fmt(sensitivity[c]["r2"], 2) for c in columns) + " |")
    lines.append("")
    for column in columns:
        effects = sensitivity[column]["effects"]
        if effects:
            worst = max(effects, key=lambda n: abs(effects[n]))
            lines.append(f"- {figure_label(column, shown)}: most sensitive to "
                         f"`{worst.removeprefix('factor.')}` ({100 * effects[worst]:+.1f} % over "
                         f"its range)")
    lines.append("")
    name = "robustness.png"
    robustness_figure(metrics, order, shown, sensitivity, out / name)
    lines.append(f"![robustness]({name})")
    lines.append("")
    return lines


def saturation_summary(rows: list[dict], shown: list[str] = ()) -> str:
    """Whether the figures measure the plant or the command limits: the runs
    whose commands sat at a limit on more than SATURATED_SHARE of their
    samples, by the varying further variables (`shown`), axis and
    decoupling."""
    saturated = defaultdict(lambda: [0, 0])
    for r in rows:
        key = (tuple(show(r.get(name)) for name in shown), r["axis"], r["decoupling"])
        saturated[key][1] += 1
        saturated[key][0] += (r.get("command_saturation") or 0) > SATURATED_SHARE
    hit = {k: v for k, v in saturated.items() if v[0]}
    if not hit:
        return (f"No run's commands sat at a limit on more than {100 * SATURATED_SHARE:g} % of "
                "its samples: the figures measure the plants, not the command range.")
    return (f"Commands at a limit on more than {100 * SATURATED_SHARE:g} % of the samples "
            "(those figures measure the command range as much as the plant): " + ", ".join(
                "".join(f"{name} = {value}, " for name, value in zip(shown, values))
                + f"{axis}, decoupling {decoupling}: {n} of {total} runs"
                for (values, axis, decoupling), (n, total) in sorted(hit.items())) + ".")


def held_at_bounds(rows: list[dict], factors: list[str]) -> dict:
    """Factors whose smallest or largest value repeats over the samples: a
    uniform draw never repeats, a bound does."""
    per_sample = {r["sample"]: r for r in rows}
    out = {}
    for name in factors:
        values = [r[name] for r in per_sample.values() if r.get(name) is not None]
        if not values:
            continue
        at_bound = max(values.count(min(values)), values.count(max(values)))
        if at_bound > 1:
            out[name] = (at_bound, len(values))
    return out


def sensitivities(metrics: dict, factors: list[str], rows: list[dict]) -> dict:
    """Per figure: effects (relative change over each factor's range) and R²."""
    sample_factors = {}
    for r in rows:
        sample_factors.setdefault(r["sample"], [r[f] for f in factors])
    ranges = []
    for i, _ in enumerate(factors):
        column = np.array([v[i] for v in sample_factors.values()])
        ranges.append((column.min(), column.max()))
    out = {}
    for key, values in metrics.items():
        samples = [s for s, v in values.items() if v is not None and v > 0 and math.isfinite(v)]
        if len(samples) <= len(factors) + 1:
            out[key] = {"effects": {}, "r2": math.nan}
            continue
        x = np.array([[2 * (sample_factors[s][i] - lo) / (hi - lo) - 1 if hi > lo else 0.0
                       for i, (lo, hi) in enumerate(ranges)] for s in samples])
        y = np.log([values[s] for s in samples])
        design = np.column_stack([np.ones(len(samples)), x])
        coefficients, *_ = np.linalg.lstsq(design, y, rcond=None)
        residual = y - design @ coefficients
        total = np.sum((y - y.mean()) ** 2)
        r2 = 1 - np.sum(residual ** 2) / total if total > 0 else math.nan
        # From -1 to +1: a factor of exp(2 b).
        out[key] = {"effects": {f: float(np.exp(2 * b) - 1)
                                for f, b in zip(factors, coefficients[1:])},
                    "r2": float(r2)}
    return out


def robustness_figure(metrics: dict, order: list, shown: list[str], sensitivity: dict,
                      path: Path) -> None:
    """A histogram of each figure over the samples (its P5, P50, P95 as
    lines), in `order`, and the parameters by their largest effect."""
    cols = 4
    rows = math.ceil(len(order) / cols) + 1
    fig, grid = plt.subplots(rows, cols, figsize=(4 * cols, 2.8 * rows), squeeze=False)
    for i, figure in enumerate(order):
        ax = grid[i // cols][i % cols]
        values = [v for v in metrics[figure].values() if v is not None and math.isfinite(v)]
        ax.hist(values, bins=20, color="C0")
        for p, style in zip(percentiles(values), (":", "-", ":")):
            ax.axvline(p, color="k", ls=style, lw=0.8)
        ax.set_title(figure_label(figure, shown), fontsize=8)
        # What the x axis counts and in what: a histogram of a figure.
        unit = figure_unit(figure)
        ax.set_xlabel(f"tracking RMS [{unit}]" if unit != "1"
                      else "span without / with decoupling [1]", fontsize=7)
        ax.set_ylabel("samples", fontsize=7)
        ax.tick_params(labelsize=7)
    for j in range(len(order), (rows - 1) * cols):
        grid[j // cols][j % cols].axis("off")
    ax = plt.subplot2grid((rows, cols), (rows - 1, 0), colspan=cols, fig=fig)
    for c in range(cols):
        grid[rows - 1][c].axis("off")
    worst = defaultdict(float)
    for per in sensitivity.values():
        for name, effect in per["effects"].items():
            worst[name] = max(worst[name], abs(effect))
    top = sorted(worst, key=lambda n: -worst[n])[:15]
    ax.bar(range(len(top)), [100 * worst[n] for n in top], color="C3")
    ax.set_xticks(range(len(top)), [n.removeprefix("factor.") for n in top], rotation=30,
                  ha="right", fontsize=7)
    ax.set_ylabel("largest effect [%]")
    ax.set_title("parameters by their largest effect on any figure", fontsize=9)
    fig.tight_layout()
    fig.savefig(path, dpi=90)
    plt.close(fig)


# --------------------------------------------------------------------------

SECTIONS = {"envelope": envelope_section, "robustness": robustness_section}


def write_report(out: Path, command: str | None = None) -> Path:
    """Renders every table in `out` into out/report.md (and its PNGs).
    `command` is the command that writes it, which the report names (by
    default this module's, for `out`): it said `make sweep` and
    demo/sweeps/ whichever command and specs made it."""
    out = Path(out)
    command = command or shlex.join(["python", "-m", "demo.sweep_report", "--out", str(out)])
    lines = ["# Sweeps of the closed loop", "",
             f"Generated by `{command}` from the tables in this folder, one Parquet table per "
             f"study with one row per run (every swept value, the seed, the metrics, the wall "
             f"time). The conditions of each study are its spec's, named with its table and "
             f"quoted below.", ""]
    for path in sorted(out.glob("*.parquet")):
        rows, meta = load(path)
        section = SECTIONS.get(meta.get("report", ""))
        spec = f", from the spec `{meta['spec_path']}`" if meta.get("spec_path") else ""
        lines.append(f"Table: `{path.name}`{spec}.")
        lines.append("")
        if section is None or not rows:
            lines += [f"({len(rows)} rows; no report for this study)", ""]
            continue
        lines += section(rows, meta, out)
    report = out / "report.md"
    report.write_text("\n".join(lines) + "\n")
    return report


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=Path("out/sweep"))
    args = parser.parse_args(argv)
    print(write_report(args.out, shlex.join(["python", "-m", "demo.sweep_report",
                                             *(sys.argv[1:] if argv is None else argv)])))
    return 0


if __name__ == "__main__":
    sys.exit(main())
