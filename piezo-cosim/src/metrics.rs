//! The figures seed 000 reports for its experiments (§3.2, §5: Fig. 6-13,
//! Table 3), computed as demo/experiments.py computes them.
//!
//! Errors are demand minus sensor reading, over the samples at or after the
//! window's start: e_y = y_d − s1, e_x = x_d − (s2 + s3)/2,
//! e_θ = θ_d − (s2 − s3)/L, and the coupling errors of the two x sensors
//! e_x2 = x_d2 − s2, e_x3 = x_d3 − s3 with x_d2,3 = x_d ± θ_d·L/2. A Table 3
//! coupling is the span (max − min) of the error on an axis the run does not
//! drive. [µm], and [rad] for θ.

use std::collections::BTreeMap;

use serde_json::{Map, Value, json};

use crate::scenario::{CONTROLLER, Driven, MetricsSpec, PLANT};

/// Metric name → number, or [min, max] for a range.
pub type Metrics = Map<String, Value>;

/// The unit of a metric's values.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum MetricUnit {
    /// The same for every run: "um", "rad", or "1" (a count or a share).
    Fixed(&'static str),
    /// The driven axis's: um for x and y, rad for θ_z.
    DrivenAxis,
}

/// A metric the master computes (`compute` writes no other).
#[derive(Clone, Copy, Debug)]
pub struct MetricDefinition {
    pub name: &'static str,
    pub unit: MetricUnit,
    /// A [min, max] pair rather than one number.
    pub range: bool,
    pub description: &'static str,
}

const fn metric(
    name: &'static str,
    unit: MetricUnit,
    range: bool,
    description: &'static str,
) -> MetricDefinition {
    MetricDefinition {
        name,
        unit,
        range,
        description,
    }
}

const UM: MetricUnit = MetricUnit::Fixed("um");
const RAD: MetricUnit = MetricUnit::Fixed("rad");
const ONE: MetricUnit = MetricUnit::Fixed("1");

/// Every metric, with its unit: what `piezo-cosim metrics` prints and what
/// tools that tabulate the results (demo/sweep.py) read, so that names and
/// units are written here only. Which ones a run writes depends on its
/// `metrics.driven` and `metrics.pose`.
pub const METRICS: &[MetricDefinition] = &[
    metric("samples", ONE, false, "samples in the window"),
    metric(
        "tracking_max",
        MetricUnit::DrivenAxis,
        false,
        "largest |error| of the driven axis (x, y, theta)",
    ),
    metric(
        "tracking_rms",
        MetricUnit::DrivenAxis,
        false,
        "RMS error of the driven axis",
    ),
    metric(
        "demand_span",
        MetricUnit::DrivenAxis,
        false,
        "span of the driven axis's demand (twice a sine's amplitude)",
    ),
    metric(
        "coupling_x_span",
        UM,
        false,
        "span of e_x in a y run (Table 3)",
    ),
    metric(
        "coupling_x2_span",
        UM,
        false,
        "span of e_x2, the x sensor s2's coupling error, in a y run",
    ),
    metric(
        "coupling_x2_range",
        UM,
        true,
        "[min, max] of e_x2 in a y run",
    ),
    metric(
        "coupling_x3_span",
        UM,
        false,
        "span of e_x3, the x sensor s3's coupling error, in a y run",
    ),
    metric(
        "coupling_x3_range",
        UM,
        true,
        "[min, max] of e_x3 in a y run",
    ),
    metric(
        "coupling_y_span",
        UM,
        false,
        "span of e_y in an x or theta run (Table 3)",
    ),
    metric(
        "coupling_y_range",
        UM,
        true,
        "[min, max] of e_y in an x or theta run",
    ),
    metric(
        "contour_2norm",
        UM,
        false,
        "2-norm of the circle's contour error (Fig. 12)",
    ),
    metric("contour_rms", UM, false, "RMS contour error"),
    metric("contour_samples", ONE, false, "samples the 2-norm sums"),
    metric("x_error_range", UM, true, "[min, max] of e_x (xy runs)"),
    metric(
        "y_error_range",
        UM,
        true,
        "[min, max] of e_y (xy and ytheta runs)",
    ),
    metric("x_error_max", UM, false, "largest |e_x| (xy runs)"),
    metric(
        "y_error_max",
        UM,
        false,
        "largest |e_y| (xy and ytheta runs)",
    ),
    metric(
        "theta_error_range",
        RAD,
        true,
        "[min, max] of e_theta (ytheta runs)",
    ),
    metric(
        "theta_error_max",
        RAD,
        false,
        "largest |e_theta| (ytheta runs)",
    ),
    metric(
        "pose_coupling_x_span",
        UM,
        false,
        "span of the noise-free x pose in a y run",
    ),
    metric(
        "pose_coupling_x2_span",
        UM,
        false,
        "span of the noise-free pose at s2 in a y run",
    ),
    metric(
        "pose_coupling_x3_span",
        UM,
        false,
        "span of the noise-free pose at s3 in a y run",
    ),
    metric(
        "pose_coupling_y_span",
        UM,
        false,
        "span of the noise-free y pose in an x or theta run",
    ),
    metric(
        "command_saturation",
        ONE,
        false,
        "share of the window in which a command sits at a limit of the command range",
    ),
];

/// [`METRICS`] as JSON: `{name: {unit, range, description}}`, a driven-axis
/// unit as `{"x": "um", "y": "um", "theta": "rad"}`.
pub fn definitions_json() -> Value {
    let unit = |unit: MetricUnit| match unit {
        MetricUnit::Fixed(unit) => json!(unit),
        MetricUnit::DrivenAxis => json!({"x": "um", "y": "um", "theta": "rad"}),
    };
    Value::Object(
        METRICS
            .iter()
            .map(|m| {
                let definition = json!({
                    "unit": unit(m.unit),
                    "range": m.range,
                    "description": m.description,
                });
                (m.name.to_owned(), definition)
            })
            .collect(),
    )
}

/// The demands, by input of the controller.
const REFERENCES: [&str; 3] = ["x_ref", "y_ref", "theta_ref"];
/// The sensors the errors are read from: s1 reads y, s2 and s3 the x pair.
const SENSORS: [&str; 3] = ["s1", "s2", "s3"];
/// The controller's commands (saturation).
const COMMANDS: [&str; 3] = ["u1", "u2", "u3"];
/// The plant's platform pose, free of sensor noise (`MetricsSpec::pose`):
/// x, y [µm] and θ_z [rad].
const POSE: [&str; 3] = ["x", "y", "theta_z"];

pub(crate) fn sensor_ports() -> Vec<String> {
    SENSORS.iter().map(|s| format!("{PLANT}.{s}")).collect()
}

pub(crate) fn pose_ports() -> Vec<String> {
    POSE.iter().map(|p| format!("{PLANT}.{p}")).collect()
}

pub(crate) fn command_ports() -> Vec<String> {
    COMMANDS
        .iter()
        .map(|u| format!("{CONTROLLER}.{u}"))
        .collect()
}

/// Tolerance of the window's start, as demo/experiments.py (`- 1e-12`).
pub(crate) const WINDOW_SLACK: f64 = 1e-12;

fn rms(v: &[f64]) -> f64 {
    (v.iter().map(|x| x * x).sum::<f64>() / v.len() as f64).sqrt()
}

fn max_abs(v: &[f64]) -> f64 {
    v.iter().fold(0.0, |m, x| m.max(x.abs()))
}

fn range(v: &[f64]) -> (f64, f64) {
    v.iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), &x| {
            (lo.min(x), hi.max(x))
        })
}

fn span(v: &[f64]) -> f64 {
    let (lo, hi) = range(v);
    hi - lo
}

fn range_value(v: &[f64]) -> Value {
    let (lo, hi) = range(v);
    json!([lo, hi])
}

/// The index of the first sample of `times` the metrics use (`from` on).
pub(crate) fn first_sample(spec: &MetricsSpec, times: &[f64]) -> usize {
    times
        .iter()
        .position(|&t| t >= spec.from - WINDOW_SLACK)
        .unwrap_or(times.len())
}

/// Computes the metrics of a run. `columns` holds the recorded outputs and
/// the signals at every communication point, by `instance.variable`;
/// `constant(port)` gives the value of an input no signal drives (its start
/// value) or of a parameter.
pub(crate) fn compute(
    spec: &MetricsSpec,
    times: &[f64],
    spacing: f64,
    columns: &BTreeMap<&str, &[f64]>,
    constant: &dyn Fn(&str) -> f64,
) -> Metrics {
    let first = first_sample(spec, times);
    let n = times.len();
    let windowed = |port: String| -> Vec<f64> {
        match columns.get(port.as_str()) {
            Some(values) => values[first..].to_vec(),
            None => vec![constant(&port); n - first],
        }
    };
    let [x_d, y_d, th_d] = REFERENCES.map(|r| windowed(format!("{CONTROLLER}.{r}")));
    let [s1, s2, s3] = SENSORS.map(|s| windowed(format!("{PLANT}.{s}")));
    let samples = s1.len();
    let e_x: Vec<f64> = (0..samples)
        .map(|i| x_d[i] - 0.5 * (s2[i] + s3[i]))
        .collect();
    let e_y: Vec<f64> = (0..samples).map(|i| y_d[i] - s1[i]).collect();
    let e_theta: Vec<f64> = (0..samples)
        .map(|i| th_d[i] - (s2[i] - s3[i]) / spacing)
        .collect();
    let e_x2: Vec<f64> = (0..samples)
        .map(|i| x_d[i] + th_d[i] * spacing / 2.0 - s2[i])
        .collect();
    let e_x3: Vec<f64> = (0..samples)
        .map(|i| x_d[i] - th_d[i] * spacing / 2.0 - s3[i])
        .collect();

    let mut m = Metrics::new();
    m.insert("samples".into(), json!(samples));
    if samples == 0 {
        return m;
    }
    match spec.driven {
        Driven::Y | Driven::X | Driven::Theta => {
            let tracking = match spec.driven {
                Driven::Y => &e_y,
                Driven::X => &e_x,
                _ => &e_theta,
            };
            let demand = match spec.driven {
                Driven::Y => &y_d,
                Driven::X => &x_d,
                _ => &th_d,
            };
            m.insert("tracking_max".into(), json!(max_abs(tracking)));
            m.insert("tracking_rms".into(), json!(rms(tracking)));
            // The driven demand's span over the window, the scale a tracking
            // error is judged against (a sine's span is twice its amplitude).
            m.insert("demand_span".into(), json!(span(demand)));
            if spec.driven == Driven::Y {
                m.insert("coupling_x_span".into(), json!(span(&e_x)));
                m.insert("coupling_x2_span".into(), json!(span(&e_x2)));
                m.insert("coupling_x2_range".into(), range_value(&e_x2));
                m.insert("coupling_x3_span".into(), json!(span(&e_x3)));
                m.insert("coupling_x3_range".into(), range_value(&e_x3));
            } else {
                m.insert("coupling_y_span".into(), json!(span(&e_y)));
                m.insert("coupling_y_range".into(), range_value(&e_y));
            }
        }
        Driven::Xy => {
            let circle = spec.contour.expect("validated: xy metrics have a contour");
            let [cx, cy] = circle.centre;
            let contour: Vec<f64> = (0..samples)
                .map(|i| (0.5 * (s2[i] + s3[i]) - cx).hypot(s1[i] - cy) - circle.radius)
                .collect();
            let norm = contour.iter().map(|c| c * c).sum::<f64>().sqrt();
            m.insert("contour_2norm".into(), json!(norm));
            m.insert("contour_rms".into(), json!(rms(&contour)));
            m.insert("contour_samples".into(), json!(samples));
            m.insert("x_error_range".into(), range_value(&e_x));
            m.insert("y_error_range".into(), range_value(&e_y));
            m.insert("x_error_max".into(), json!(max_abs(&e_x)));
            m.insert("y_error_max".into(), json!(max_abs(&e_y)));
        }
        Driven::Ytheta => {
            m.insert("theta_error_range".into(), range_value(&e_theta));
            m.insert("y_error_range".into(), range_value(&e_y));
            m.insert("theta_error_max".into(), json!(max_abs(&e_theta)));
            m.insert("y_error_max".into(), json!(max_abs(&e_y)));
        }
    }
    if spec.pose {
        // The Table 3 couplings of a single-axis run on the pose: the held
        // demands are constant over the window, so the span of the pose is
        // the span of its error. x2, x3: the pose at the two x sensors.
        let [x, y, theta] = POSE.map(|p| windowed(format!("{PLANT}.{p}")));
        match spec.driven {
            Driven::Y => {
                let at = |sign: f64| -> Vec<f64> {
                    (0..samples)
                        .map(|i| x[i] + sign * theta[i] * spacing / 2.0)
                        .collect()
                };
                m.insert("pose_coupling_x_span".into(), json!(span(&x)));
                m.insert("pose_coupling_x2_span".into(), json!(span(&at(1.0))));
                m.insert("pose_coupling_x3_span".into(), json!(span(&at(-1.0))));
            }
            Driven::X | Driven::Theta => {
                m.insert("pose_coupling_y_span".into(), json!(span(&y)));
            }
            Driven::Xy | Driven::Ytheta => {}
        }
    }
    // Share of the window in which a command sits at a limit of the
    // controller's range: where tracking or decoupling runs out of authority.
    let (low, high) = (
        constant(&format!("{CONTROLLER}.command_min")),
        constant(&format!("{CONTROLLER}.command_max")),
    );
    let commands = COMMANDS.map(|u| windowed(format!("{CONTROLLER}.{u}")));
    let at_limit = (0..samples)
        .filter(|&i| {
            commands
                .iter()
                .any(|u| u[i] <= low + 1e-9 || u[i] >= high - 1e-9)
        })
        .count();
    m.insert(
        "command_saturation".into(),
        json!(at_limit as f64 / samples as f64),
    );
    m
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scenario::Circle;

    fn spec(driven: Driven) -> MetricsSpec {
        MetricsSpec {
            driven,
            from: 1.0,
            spacing: None,
            contour: Some(Circle {
                centre: [6.0, 6.0],
                radius: 5.0,
            }),
            pose: false,
        }
    }

    /// A run of 4 samples at t = 0, 0.5, 1, 1.5 whose sensors read
    /// `s` and whose demands are `x_d`, `y_d`, `th_d`.
    fn metrics_of(driven: Driven, s: [[f64; 4]; 3], d: [[f64; 4]; 3]) -> Metrics {
        let times = [0.0, 0.5, 1.0, 1.5];
        let columns: BTreeMap<&str, &[f64]> = BTreeMap::from([
            ("plant.s1", &s[0][..]),
            ("plant.s2", &s[1][..]),
            ("plant.s3", &s[2][..]),
            ("controller.x_ref", &d[0][..]),
            ("controller.y_ref", &d[1][..]),
            ("controller.theta_ref", &d[2][..]),
        ]);
        let constant = |port: &str| match port {
            "controller.command_min" => 0.0,
            "controller.command_max" => 10.0,
            _ => 5.0,
        };
        // L = 2 um keeps the numbers readable.
        compute(&spec(driven), &times, 2.0, &columns, &constant)
    }

    #[test]
    fn single_axis_y_tracking_and_table_3_couplings() {
        let m = metrics_of(
            Driven::Y,
            [
                [0.0, 0.0, 1.1, 2.0],
                [0.0, 0.0, 3.0, 3.5],
                [0.0, 0.0, 3.0, 2.5],
            ],
            [[3.0; 4], [0.0, 0.0, 1.0, 2.2], [0.0; 4]],
        );
        assert_eq!(m["samples"], json!(2));
        let e_y = [1.0 - 1.1, 2.2 - 2.0];
        assert!((m["tracking_max"].as_f64().unwrap() - 0.2).abs() < 1e-12);
        let rms = ((e_y[0] * e_y[0] + e_y[1] * e_y[1]) / 2.0f64).sqrt();
        assert!((m["tracking_rms"].as_f64().unwrap() - rms).abs() < 1e-15);
        // e_x2 = 3 - s2: 0, -0.5; e_x3 = 3 - s3: 0, 0.5.
        assert_eq!(m["coupling_x2_span"], json!(0.5));
        assert_eq!(m["coupling_x3_range"], json!([0.0, 0.5]));
        assert_eq!(m["coupling_x_span"], json!(0.0));
        assert_eq!(m["command_saturation"], json!(0.0));
    }

    #[test]
    fn theta_errors_use_the_sensor_spacing() {
        let m = metrics_of(
            Driven::Theta,
            [[1.0; 4], [0.0, 0.0, 1.0, 1.2], [0.0, 0.0, -1.0, -1.0]],
            [[0.0; 4], [1.0; 4], [0.0, 0.0, 1.0, 1.0]],
        );
        // theta = (s2 - s3)/L = 1.0, 1.1: errors 0, -0.1.
        assert!((m["tracking_max"].as_f64().unwrap() - 0.1).abs() < 1e-12);
        assert_eq!(m["coupling_y_span"], json!(0.0));
    }

    #[test]
    fn contour_error_is_the_distance_to_the_circle() {
        // On the circle at (11, 6), then 0.1 outside at (6, 11.1).
        let m = metrics_of(
            Driven::Xy,
            [
                [6.0, 6.0, 6.0, 11.1],
                [0.0, 0.0, 11.0, 6.0],
                [0.0, 0.0, 11.0, 6.0],
            ],
            [[0.0; 4], [0.0; 4], [0.0; 4]],
        );
        assert!((m["contour_2norm"].as_f64().unwrap() - 0.1).abs() < 1e-12);
        assert_eq!(m["contour_samples"], json!(2));
    }

    #[test]
    fn pose_couplings_are_the_spans_of_the_pose_at_the_sensors() {
        let times = [0.0, 0.5, 1.0, 1.5];
        let zeros = [0.0; 4];
        let x = [9.0, 9.0, 1.0, 1.5];
        let y = [9.0, 9.0, 2.0, 2.25];
        let theta = [9.0, 9.0, 0.25, 0.0];
        let columns: BTreeMap<&str, &[f64]> = BTreeMap::from([
            ("plant.s1", &zeros[..]),
            ("plant.s2", &zeros[..]),
            ("plant.s3", &zeros[..]),
            ("plant.x", &x[..]),
            ("plant.y", &y[..]),
            ("plant.theta_z", &theta[..]),
        ]);
        let constant = |_: &str| 0.0;
        let with_pose = |driven| MetricsSpec {
            pose: true,
            ..spec(driven)
        };
        // L = 2: x2 = x + theta = 1.25, 1.5 and x3 = x - theta = 0.75, 1.5
        // over the window t >= 1.
        let m = compute(&with_pose(Driven::Y), &times, 2.0, &columns, &constant);
        assert_eq!(m["pose_coupling_x_span"], json!(0.5));
        assert_eq!(m["pose_coupling_x2_span"], json!(0.25));
        assert_eq!(m["pose_coupling_x3_span"], json!(0.75));
        assert!(m.get("pose_coupling_y_span").is_none());
        let m = compute(&with_pose(Driven::Theta), &times, 2.0, &columns, &constant);
        assert_eq!(m["pose_coupling_y_span"], json!(0.25));
        // Without `pose`, no pose figures (and no pose outputs needed).
        let m = compute(&spec(Driven::X), &times, 2.0, &columns, &constant);
        assert!(m.keys().all(|k| !k.starts_with("pose_")));
    }

    #[test]
    fn every_metric_written_is_defined_and_every_definition_is_written() {
        let times = [0.0, 0.5, 1.0, 1.5];
        let ramp = [0.0, 0.5, 1.0, 1.5];
        let columns: BTreeMap<&str, &[f64]> = [
            "plant.s1",
            "plant.s2",
            "plant.s3",
            "plant.x",
            "plant.y",
            "plant.theta_z",
            "controller.x_ref",
            "controller.y_ref",
            "controller.theta_ref",
        ]
        .into_iter()
        .map(|port| (port, &ramp[..]))
        .collect();
        let constant = |_: &str| 0.0;
        let mut written = std::collections::BTreeSet::new();
        for driven in [
            Driven::X,
            Driven::Y,
            Driven::Theta,
            Driven::Xy,
            Driven::Ytheta,
        ] {
            for pose in [false, true] {
                let run = MetricsSpec {
                    pose,
                    ..spec(driven)
                };
                for (name, value) in compute(&run, &times, 2.0, &columns, &constant) {
                    let definition = METRICS
                        .iter()
                        .find(|m| m.name == name)
                        .unwrap_or_else(|| panic!("{name} is written but not in METRICS"));
                    assert_eq!(
                        definition.range,
                        value.is_array(),
                        "{name}: range or number"
                    );
                    written.insert(name);
                }
            }
        }
        let defined: std::collections::BTreeSet<String> =
            METRICS.iter().map(|m| m.name.to_owned()).collect();
        assert_eq!(written, defined, "METRICS names a metric no run writes");
    }

    #[test]
    fn the_definitions_print_with_their_units() {
        let json = definitions_json();
        assert_eq!(json["coupling_x2_range"]["unit"], json!("um"));
        assert_eq!(json["coupling_x2_range"]["range"], json!(true));
        assert_eq!(json["theta_error_max"]["unit"], json!("rad"));
        assert_eq!(json["tracking_rms"]["unit"]["theta"], json!("rad"));
        assert_eq!(json["command_saturation"]["unit"], json!("1"));
        assert_eq!(json.as_object().unwrap().len(), METRICS.len());
    }
}
