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
    text = (f"{len(rows)} runs ({len(failed)} failed), {cpu:.0f} s of master wall time in "
            f"all, on {workers} worker(s).")
    if failed:
        reasons = defaultdict(int)
        for r in failed:
            reasons[(r.get("error") or "")[:160]] += 1
        text += " Failures: " + "; ".join(f"{n} x `{why}`" for why, n in
                                           sorted(reasons.items(), key=lambda kv: -kv[1])[:3])
    return text


# --------------------------------------------------------------------------
# Envelope

def envelope_points(rows: list[dict]) -> dict:
    """Pairs each run without decoupling with the same run with it:
    (stage, method, axis, held, amplitude, frequency) -> {off, on}."""
    points = defaultdict(dict)
    for r in rows:
        if r["status"] != "ok":
            continue
        key = (r["stage"], r["method"], r["axis"], r["held"], r["amplitude"], r["frequency"])
        points[key][r["decoupling"]] = r
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
    points = envelope_points(rows)
    lines = [f"## {meta.get('title', 'Operating envelope')}", "",
             spec_comment(meta.get("spec", "")), "", run_summary(rows), "",
             *excluded_points(meta.get("spec", "")),
             f"A point **holds** when the tracking RMS (decoupling on) is at most "
             f"{100 * tracking_limit:g} % of the demanded amplitude and decoupling shrinks every "
             f"Table 3 coupling span at least {reduction_limit:g}x. Saturation: share of the "
             f"measured period with a command at the controller's limit. Speed: simulated time "
             f"over the master's wall time per run (both FMUs and the loop, on the machine and "
             f"under the load of this sweep); below 1x the loop could not keep its 10 kHz "
             f"sample in real time.", ""]
    groups = defaultdict(list)
    for key, pair in points.items():
        if "on" in pair and "off" in pair:
            groups[key[:3]].append((key[3:], pair))
    lines += ["| stage | method | axis | points holding | tracking RMS / amplitude (median, worst) "
              "| coupling reduction (median, worst) | speed x real time (median, slowest) "
              "| where it breaks |",
              "|---|---|---|---|---|---|---|---|"]
    for (stage, method, axis), items in sorted(groups.items()):
        rel = [relative_tracking(pair["on"]) for _, pair in items]
        red = [min(reductions(axis, pair["off"], pair["on"]).values()) for _, pair in items]
        holds = [r <= tracking_limit and d >= reduction_limit for r, d in zip(rel, red)]
        breaks = [(k, pair, r, d) for (k, pair), r, d, h in zip(items, rel, red, holds) if not h]
        speed = [realtime(pair[d]) for _, pair in items for d in ("off", "on")]
        lines.append(f"| {stage} | {method} | {axis} | {sum(holds)}/{len(holds)} | "
                     f"{fmt(100 * np.nanmedian(rel))} %, {fmt(100 * np.nanmax(rel))} % | "
                     f"{fmt(np.nanmedian(red))}x, {fmt(np.nanmin(red))}x | "
                     f"{fmt(np.nanmedian(speed))}x, {fmt(np.nanmin(speed))}x | "
                     f"{describe_breaks(items, holds, breaks, tracking_limit, reduction_limit)} |")
    lines.append("")
    for stage, method in sorted({k[:2] for k in groups}):
        for kind in ("tracking", "coupling"):
            name = f"envelope_{stage}_{method}_{kind}.png"
            limit = tracking_limit if kind == "tracking" else reduction_limit
            envelope_figure(groups, stage, method, kind, limit, out / name)
            lines.append(f"![{kind}, {stage}, {method}]({name})")
        lines.append("")
    return lines


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


def envelope_figure(groups, stage, method, kind, limit, path: Path) -> None:
    """One heatmap (frequency x amplitude) per axis or coupling and held
    demand, on one colour scale; the values of failing cells in red."""
    axes_present = [a for a in ("x", "y", "theta") if (stage, method, a) in groups]
    panels = []
    for axis in axes_present:
        if kind == "tracking":
            panels.append((axis, None, f"{axis}: tracking RMS / amplitude [%]"))
        else:
            for _, label in COUPLINGS[axis]:
                panels.append((axis, label, f"{label}: span without / with decoupling"))
    held_values = sorted({k[0] for a in axes_present for k, _ in groups[(stage, method, a)]})
    grids = []
    for axis, label, title in panels:
        items = groups[(stage, method, axis)]
        amplitudes = sorted({k[1] for k, _ in items})
        frequencies = sorted({k[2] for k, _ in items})
        for held in held_values:
            z = np.full((len(amplitudes), len(frequencies)), np.nan)
            for (h, a, f), pair in items:
                if h == held:
                    z[amplitudes.index(a), frequencies.index(f)] = (
                        100 * relative_tracking(pair["on"]) if kind == "tracking"
                        else reductions(axis, pair["off"], pair["on"])[label])
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
                            color="red" if fails else "white",
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
    fig.suptitle(f"{stage}, {method}: {what}", fontsize=10)
    fig.tight_layout(rect=(0, 0, 0.92, 1))
    if image is not None:
        fig.colorbar(image, ax=grid.ravel().tolist(), shrink=0.6, pad=0.02)
    fig.savefig(path, dpi=90)
    plt.close(fig)


# --------------------------------------------------------------------------
# Robustness

def robustness_section(rows: list[dict], meta: dict, out: Path) -> list[str]:
    lines = [f"## {meta.get('title', 'Robustness')}", "", spec_comment(meta.get("spec", "")),
             "", run_summary(rows), ""]
    ok = [r for r in rows if r["status"] == "ok"]
    factors = sorted({k for r in rows for k in r if k.startswith("factor.")})
    by = defaultdict(dict)
    for r in ok:
        by[(r.get("method", "preset"), r["axis"], r["sample"])][r["decoupling"]] = r
    metrics = defaultdict(dict)  # (method, name) -> sample -> value
    for (method, axis, sample), pair in by.items():
        if "on" in pair:
            metrics[(method, f"{axis} tracking RMS")][sample] = pair["on"]["tracking_rms"]
        if "on" in pair and "off" in pair:
            for label, value in reductions(axis, pair["off"], pair["on"]).items():
                metrics[(method, f"{label} reduction")][sample] = value
    lines += ["Tracking RMS with decoupling on (µm; rad for theta) and coupling reduction "
              "(span without / with decoupling) over the samples:", "",
              "| method | figure | P5 | P50 | P95 | samples |", "|---|---|---|---|---|---|"]
    for (method, name), values in sorted(metrics.items()):
        p5, p50, p95 = percentiles(values.values())
        lines.append(f"| {method} | {name} | {fmt(p5)} | {fmt(p50)} | {fmt(p95)} | "
                     f"{len(values)} |")
    lines.append("")
    lines += [saturation_summary(ok), ""]
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
    columns = sorted(sensitivity)
    lines.append("| parameter | " + " | ".join(f"{m}: {name}" for m, name in columns) + " |")
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
            lines.append(f"- {column[0]}, {column[1]}: most sensitive to "
                         f"`{worst.removeprefix('factor.')}` ({100 * effects[worst]:+.1f} % over "
                         f"its range)")
    lines.append("")
    name = "robustness.png"
    robustness_figure(metrics, sensitivity, out / name)
    lines.append(f"![robustness]({name})")
    lines.append("")
    return lines


def saturation_summary(rows: list[dict]) -> str:
    """Whether the figures measure the plant or the command limits: the runs
    whose commands sat at a limit on more than SATURATED_SHARE of their
    samples, by axis and decoupling."""
    saturated = defaultdict(lambda: [0, 0])
    for r in rows:
        key = (r.get("method", "preset"), r["axis"], r["decoupling"])
        saturated[key][1] += 1
        saturated[key][0] += (r.get("command_saturation") or 0) > SATURATED_SHARE
    hit = {k: v for k, v in saturated.items() if v[0]}
    if not hit:
        return (f"No run's commands sat at a limit on more than {100 * SATURATED_SHARE:g} % of "
                "its samples: the figures measure the plants, not the command range.")
    return (f"Commands at a limit on more than {100 * SATURATED_SHARE:g} % of the samples "
            "(those figures measure the command range as much as the plant): " + ", ".join(
                f"{method} {axis}, decoupling {decoupling}: {n} of {total} runs"
                for (method, axis, decoupling), (n, total) in sorted(hit.items())) + ".")


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


def robustness_figure(metrics: dict, sensitivity: dict, path: Path) -> None:
    keys = sorted(metrics)
    cols = 4
    rows = math.ceil(len(keys) / cols) + 1
    fig, grid = plt.subplots(rows, cols, figsize=(4 * cols, 2.6 * rows), squeeze=False)
    for i, key in enumerate(keys):
        ax = grid[i // cols][i % cols]
        values = [v for v in metrics[key].values() if v is not None and math.isfinite(v)]
        ax.hist(values, bins=20, color="C0")
        for p, style in zip(percentiles(values), (":", "-", ":")):
            ax.axvline(p, color="k", ls=style, lw=0.8)
        ax.set_title(f"{key[0]}: {key[1]}", fontsize=8)
        ax.tick_params(labelsize=7)
    for j in range(len(keys), (rows - 1) * cols):
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


def write_report(out: Path) -> Path:
    """Renders every table in `out` into out/report.md (and its PNGs)."""
    out = Path(out)
    lines = ["# Sweeps of the closed loop", "",
             "Generated by `make sweep` (`python -m demo.sweep demo/sweeps/*.toml`) from the "
             "tables in this folder, one Parquet table per study with one row per run "
             "(every swept value, the seed, the metrics, the wall time). The conditions of "
             "each study are its spec's (demo/sweeps/), quoted below.", ""]
    for path in sorted(out.glob("*.parquet")):
        rows, meta = load(path)
        section = SECTIONS.get(meta.get("report", ""))
        lines.append(f"Table: `{path.name}`.")
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
    print(write_report(args.out))
    return 0


if __name__ == "__main__":
    sys.exit(main())
