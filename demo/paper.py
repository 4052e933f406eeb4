"""Seed 000's numbered figures and the rule each simulated figure is judged by.

One table, read by the demo's report.md and by the tests, so that the verdict
a reader sees is the one `make test` asserts. Every target is the paper's own
number (Guo et al., §5, Fig. 6-13, Table 3): a simulated figure meets it when
it is at or under the paper's.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

DEG = 180.0 / math.pi


@dataclass(frozen=True)
class Row:
    """One figure: what it is, the paper's value, the simulated one, the
    rule, whether it holds, and where the paper prints it."""

    what: str
    paper: str
    simulated: str
    rule: str
    met: bool
    where: str
    #: Measured on a run with the decoupling on (Table 3's, Fig. 11, 12b,
    #: 13b): a figure of the decoupling law.
    decoupled: bool = False


def _um(v: float) -> str:
    return f"{v:.4f} um"


def _nm(v: float) -> str:
    return f"{1e3 * v:.0f} nm"


def _nm_range(r) -> str:
    return f"[{1e3 * r[0]:.0f}, {1e3 * r[1]:.0f}] nm"


def _deg(v: float) -> str:
    return f"{v * DEG:.3g} deg"


def _deg_range(r) -> str:
    return f"[{r[0] * DEG:.3g}, {r[1] * DEG:.3g}] deg"


#: Fig. 6-7 and Fig. 11: (max, RMS) of the tracking error [um, or rad for theta].
TRACKING = {
    "fig6_y_ff": ("y sine, feedforward only", (0.2389, 0.0850), "Fig. 6"),
    "fig7_y_ffpi": ("y sine, feedforward + PI", (0.0544, 0.0134), "Fig. 7a"),
    "fig7_x_ffpi": ("x sine, feedforward + PI", (0.0701, 0.0171), "Fig. 7b"),
    "fig7_theta_ffpi": ("theta_z sine, feedforward + PI",
                        (math.radians(1.21e-4), math.radians(3.3e-5)), "Fig. 7c"),
    "fig11_composite": ("composite signal eq. (13), decoupling controller", (0.1466, 0.0425),
                        "Fig. 11"),
}

#: Table 3: coupling spans without / with decoupling [um], the run pair that
#: measures each and the metric key.
TABLE_3 = (
    ("x2 from y", "y", "coupling_x2_span", (2.2065, 0.3173)),
    ("x3 from y", "y", "coupling_x3_span", (2.7435, 0.6152)),
    ("y from x", "x", "coupling_y_span", (1.2482, 0.3239)),
    ("y from rotation", "theta", "coupling_y_span", (1.6784, 0.3718)),
)
#: The reduction the decoupling must reach on every Table 3 coupling (the
#: paper's best is 7.0x, x2 from y; its others are 3.9-4.5x).
TABLE_3_RATIO = 7.0

#: Fig. 12: the circle's x / y error bounds [um] and the contour-error 2-norm,
#: without and with decoupling. The text prints "11.19 and 5.72 with and
#: without the decoupling compensation, respectively" next to "the tracking
#: property is significantly improved when the decoupling technique is
#: enabled"; the larger 2-norm goes with the larger error bounds (+-162/+-117
#: nm without, +-97/+-65 nm with), so 11.19 is read as without, 5.72 as with.
CIRCLE = {
    "fig12_circle_coupled": ("without decoupling", (0.162, 0.117), 11.19, "Fig. 12a"),
    "fig12_circle_decoupled": ("with decoupling", (0.097, 0.065), 5.72, "Fig. 12b"),
}

#: Fig. 13: theta_z [rad] and y [um] error ranges, without and with decoupling.
Y_THETA = {
    "fig13_y_theta_coupled": ("without decoupling",
                              (math.radians(-1.68e-4), math.radians(1.87e-4)),
                              (-0.170, 0.123), "Fig. 13a"),
    "fig13_y_theta_decoupled": ("with decoupling",
                                (math.radians(-1.73e-4), math.radians(1.11e-4)),
                                (-0.113, 0.102), "Fig. 13b"),
}


def _within(measured, paper) -> bool:
    """A range at or inside the paper's: its low end not below the paper's low
    end, its high end not above the paper's high end."""
    return measured[0] >= paper[0] and measured[1] <= paper[1]


#: The runs of the table with the decoupling on: demo.experiments runs each
#: with the law fitted once (this key) and refined (this key + "_refined").
DECOUPLED = ("fig10_y_decoupled", "fig10_x_decoupled", "fig10_theta_decoupled",
             "fig11_composite", "fig12_circle_decoupled", "fig13_y_theta_decoupled")


def rows(results: dict, law: str = "") -> list[Row]:
    """Every numbered figure of seed 000 that the closed loop reproduces, with
    its verdict. `results` maps run keys to `experiments.metrics` dicts; the
    runs with the decoupling on are read under their key plus `law` (""
    for the law fitted once, as seed 000 §4 does; "_refined" for the
    start values' three rounds)."""
    def run(key: str) -> dict:
        return results[key + law if key in DECOUPLED else key]

    out = []
    for key, (what, (paper_max, paper_rms), where) in TRACKING.items():
        m = run(key)
        theta = key.startswith("fig7_theta")
        fmt = _deg if theta else _um
        paper = (f"{paper_max * DEG:.3g} / {paper_rms * DEG:.3g} deg" if theta
                 else f"{paper_max} / {paper_rms} um")
        out.append(Row(f"{what}: max / RMS error", paper,
                       f"{fmt(m['tracking_max'])} / {fmt(m['tracking_rms'])}",
                       "max and RMS <= paper",
                       m["tracking_max"] <= paper_max and m["tracking_rms"] <= paper_rms, where,
                       key in DECOUPLED))
    for name, axis, key, (paper_without, paper_with) in TABLE_3:
        without = results[f"fig7_{axis}_ffpi"][key]
        with_ = run(f"fig10_{axis}_decoupled")[key]
        ratio = without / with_
        out.append(Row(
            f"coupling span {name}, without / with decoupling (ratio)",
            f"{paper_without} / {paper_with} um ({paper_without / paper_with:.1f}x)",
            f"{without:.4f} / {with_:.4f} um ({ratio:.1f}x)",
            f"with <= {paper_with} um, ratio >= {TABLE_3_RATIO:g}x",
            with_ <= paper_with and ratio >= TABLE_3_RATIO, "Table 3", True))
    for key, (what, (paper_x, paper_y), paper_norm, where) in CIRCLE.items():
        m = run(key)
        out.append(Row(
            f"circle eq. (14)-(15) {what}: x / y error within",
            f"+-{1e3 * paper_x:.0f} / +-{1e3 * paper_y:.0f} nm",
            f"{_nm_range(m['x_error_range'])} / {_nm_range(m['y_error_range'])}",
            "|error| <= paper on each axis",
            m["x_error_max"] <= paper_x and m["y_error_max"] <= paper_y, where,
            key in DECOUPLED))
        out.append(Row(
            f"circle {what}: 2-norm of the contour error",
            f"{paper_norm}",
            f"{m['contour_2norm']:.2f} um over {m['contour_samples']} samples "
            f"(RMS {_nm(m['contour_rms'])})",
            "<= paper", m["contour_2norm"] <= paper_norm, where, key in DECOUPLED))
    for key, (what, paper_theta, paper_y, where) in Y_THETA.items():
        m = run(key)
        out.append(Row(f"y + theta_z eq. (16) {what}: theta_z error range",
                       _deg_range(paper_theta), _deg_range(m["theta_error_range"]),
                       "inside the paper's range", _within(m["theta_error_range"], paper_theta),
                       where, key in DECOUPLED))
        out.append(Row(f"y + theta_z eq. (16) {what}: y error range",
                       _nm_range(paper_y), _nm_range(m["y_error_range"]),
                       "inside the paper's range", _within(m["y_error_range"], paper_y), where,
                       key in DECOUPLED))
    return out


#: The label the refined law's rows carry (their own rows in a document).
REFINED_LABEL = "refined law: "


def refined_rows(results: dict) -> list[Row]:
    """The rows of the decoupled runs under the start values' law, refined
    over three rounds on the same runs (in-sample), labelled as such."""
    return [replace(r, what=REFINED_LABEL + r.what) for r in rows(results, "_refined")
            if r.decoupled]
