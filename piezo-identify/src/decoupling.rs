//! Estimation of seed 000's decoupling law (eq. 11, Table 2) from single-axis
//! runs, as its §4 does: "the decoupling compensation signal for the
//! non-actuated directions is calculated based on the experimental results
//! from single axis actuation testing (Fig. 7)".
//!
//! Each compensation D_i(f) = clamp(Δk_i·f + Δb_i, q_i, p_i) is added to the
//! input of an inverse model, so it must equal the coupling error of its
//! channel, demand − measurement, as a function of the driving demand f:
//!
//! | i | channel (error) | driving demand f | run |
//! |---|---|---|---|
//! | 1 | x2: x_d2 − s2 | y_d [µm] | y sine |
//! | 2 | x3: x_d3 − s3 | y_d [µm] | y sine |
//! | 3 | y: y_d − s1 | x_d [µm] | x sine |
//! | 4 | y: y_d − s1 | θ_zd [µrad] | θ sine |
//!
//! The fit minimises Σ (e − D(f))² over (Δk, Δb, p, q): least squares for the
//! line, then Nelder-Mead from the line with the cutoffs at the extremes of the
//! error; a cutoff that ends beyond the line's range over the data does
//! nothing and is set to ±10 µm, which Table 2 uses for "no cutoff", or to
//! the line's reach over the data where that is beyond ±10 µm.

use argmin::core::{CostFunction, Executor};
use argmin::solver::neldermead::NelderMead;
use piezo_models::DecouplingParams;

/// Table 2's value of an unused cutoff [µm].
pub const NO_CUTOFF: f64 = 10.0;

/// Smallest share of the samples a cutoff must clamp to be kept.
const MIN_CLAMPED: f64 = 0.05;

/// One fitted compensation D(f) = clamp(Δk·f + Δb, q, p).
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize)]
pub struct Compensation {
    pub dk: f64,
    pub db: f64,
    pub p: f64,
    pub q: f64,
    /// RMS of e − D(f) over the data [µm].
    pub residual_rms: f64,
    /// Span (max − min) of e − D(f) over the data [µm]: the coupling a
    /// perfect application of D would leave.
    pub residual_span: f64,
    /// Span of e itself [µm].
    pub error_span: f64,
}

impl Compensation {
    /// Compensation `index` (0-based) of a parameter set, without fit
    /// statistics.
    pub fn of(params: &DecouplingParams, index: usize) -> Compensation {
        Compensation {
            dk: params.dk[index],
            db: params.db[index],
            p: params.p[index],
            q: params.q[index],
            residual_rms: 0.0,
            residual_span: 0.0,
            error_span: 0.0,
        }
    }

    /// The compensation that does nothing: D(f) = 0, both cutoffs unused.
    pub fn none(no_cutoff: f64) -> Compensation {
        Compensation {
            dk: 0.0,
            db: 0.0,
            p: no_cutoff,
            q: -no_cutoff,
            residual_rms: 0.0,
            residual_span: 0.0,
            error_span: 0.0,
        }
    }

    /// D(f) = clamp(Δk·f + Δb, q, p), as `piezo_models::decouple` applies it.
    pub fn eval(&self, f: f64) -> f64 {
        (self.dk * f + self.db).max(self.q).min(self.p)
    }
}

fn clamped(params: &[f64], f: f64) -> f64 {
    (params[0] * f + params[1]).max(params[3]).min(params[2])
}

struct ClampedLine<'a> {
    f: &'a [f64],
    e: &'a [f64],
}

impl CostFunction for ClampedLine<'_> {
    type Param = Vec<f64>;
    type Output = f64;

    fn cost(&self, params: &Self::Param) -> Result<f64, argmin::core::Error> {
        Ok(self
            .f
            .iter()
            .zip(self.e)
            .map(|(f, e)| (e - clamped(params, *f)).powi(2))
            .sum::<f64>()
            / self.f.len() as f64)
    }
}

/// Why a compensation could not be fitted.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum DecouplingError {
    #[error("{0} samples: a compensation needs at least 3 (driving demand, coupling error) pairs")]
    TooFewSamples(usize),
    #[error("driving demand and coupling error have {0} and {1} samples")]
    LengthMismatch(usize, usize),
    #[error("the driving demand does not vary (span {0}): no slope can be fitted")]
    ConstantDemand(f64),
    #[error("sample {0} is not finite")]
    NotFinite(usize),
    #[error("Nelder-Mead failed: {0}")]
    Optimizer(String),
}

fn span(v: impl Iterator<Item = f64> + Clone) -> f64 {
    let max = v.clone().fold(f64::NEG_INFINITY, f64::max);
    let min = v.fold(f64::INFINITY, f64::min);
    max - min
}

/// Fits one compensation to pairs (driving demand `f`, coupling error `e`),
/// with Table 2's ±10 µm for an unused cutoff.
pub fn fit_compensation(f: &[f64], e: &[f64]) -> Result<Compensation, DecouplingError> {
    fit_compensation_with_cutoff(f, e, NO_CUTOFF)
}

/// [`fit_compensation`] on a stage of another size: `no_cutoff` [µm] is the
/// value that marks an unused cutoff (Table 2's 10 µm on seed 000's 12 µm
/// strokes; a cutoff must lie beyond any compensation the stage needs).
pub fn fit_compensation_with_cutoff(
    f: &[f64],
    e: &[f64],
    no_cutoff: f64,
) -> Result<Compensation, DecouplingError> {
    if f.len() != e.len() {
        return Err(DecouplingError::LengthMismatch(f.len(), e.len()));
    }
    if f.len() < 3 {
        return Err(DecouplingError::TooFewSamples(f.len()));
    }
    if let Some(i) = (0..f.len()).find(|&i| !(f[i].is_finite() && e[i].is_finite())) {
        return Err(DecouplingError::NotFinite(i));
    }
    let f_span = span(f.iter().copied());
    if f_span <= 1e-12 {
        return Err(DecouplingError::ConstantDemand(f_span));
    }
    // Least-squares line.
    let n = f.len() as f64;
    let (mf, me) = (f.iter().sum::<f64>() / n, e.iter().sum::<f64>() / n);
    let sff: f64 = f.iter().map(|v| (v - mf).powi(2)).sum();
    let sfe: f64 = f.iter().zip(e).map(|(a, b)| (a - mf) * (b - me)).sum();
    let dk = sfe / sff;
    let db = me - dk * mf;
    let e_max = e.iter().copied().fold(f64::NEG_INFINITY, f64::max);
    let e_min = e.iter().copied().fold(f64::INFINITY, f64::min);
    let problem = ClampedLine { f, e };
    // An unused cutoff: `no_cutoff`, or beyond the line's reach over the
    // data where that is farther (a coupling of more than 10 µm on a larger
    // stage), so that it clamps nothing the data hold.
    let unused = |dk: f64, db: f64| {
        let reach = f.iter().map(|v| dk * v + db);
        (
            no_cutoff.max(reach.clone().fold(f64::NEG_INFINITY, f64::max)),
            (-no_cutoff).min(reach.fold(f64::INFINITY, f64::min)),
        )
    };
    let (line_p, line_q) = unused(dk, db);
    let line = vec![dk, db, line_p, line_q];
    let start = vec![dk, db, e_max, e_min];
    // A simplex around the start: each vertex moves one parameter by a step
    // of the size the data give it.
    // The slope's step is a tenth of the slope, and at least what moves the
    // compensation by a tenth of the error's span over the demand's: in the
    // demand's own unit, so that the fit is the same whatever that unit is
    // (D4's θ_zd in µrad runs to hundreds where D1-D3's µm run to ten).
    let e_span = (e_max - e_min).max(1e-3);
    let steps = [
        0.1 * dk.abs().max(0.1 * e_span / f_span),
        0.1 * e_span,
        0.1 * e_span,
        0.1 * e_span,
    ];
    let mut simplex = vec![start.clone()];
    for (j, step) in steps.iter().enumerate() {
        let mut vertex = start.clone();
        vertex[j] += step;
        simplex.push(vertex);
    }
    let solver = NelderMead::new(simplex)
        .with_sd_tolerance(1e-12)
        .map_err(|e| DecouplingError::Optimizer(e.to_string()))?;
    let result = Executor::new(problem, solver)
        .configure(|state| state.max_iters(4000))
        .run()
        .map_err(|e| DecouplingError::Optimizer(e.to_string()))?;
    let problem = ClampedLine { f, e };
    let mut best = result
        .state
        .best_param
        .clone()
        .filter(|p| p.iter().all(|v| v.is_finite()))
        .unwrap_or(line.clone());
    // Keep the clamped fit only where it beats the plain line.
    if problem.cost(&best).unwrap_or(f64::INFINITY) >= problem.cost(&line).unwrap_or(0.0) {
        best = line.clone();
    }
    // A cutoff that clamps only a few samples at an end of the sweep is
    // fitting noise, not the saturation Table 2's cutoffs describe: keep a
    // cutoff only where it holds at least MIN_CLAMPED of the samples.
    let clamped_share = |above: &dyn Fn(f64) -> bool| {
        f.iter().filter(|v| above(best[0] * *v + best[1])).count() as f64 / n
    };
    let keep_upper = clamped_share(&|v| v > best[2]) >= MIN_CLAMPED;
    let keep_lower = clamped_share(&|v| v < best[3]) >= MIN_CLAMPED;
    if !keep_upper && !keep_lower {
        best = line;
    } else {
        let (unused_p, unused_q) = unused(best[0], best[1]);
        if !keep_upper {
            best[2] = unused_p;
        }
        if !keep_lower {
            best[3] = unused_q;
        }
    }
    // A cutoff beyond what the line reaches over the data does nothing.
    let reach = f.iter().map(|v| best[0] * v + best[1]);
    let (line_max, line_min) = (
        reach.clone().fold(f64::NEG_INFINITY, f64::max),
        reach.fold(f64::INFINITY, f64::min),
    );
    if best[2] >= line_max || best[2] < best[3] {
        best[2] = no_cutoff.max(line_max);
    }
    if best[3] <= line_min {
        best[3] = (-no_cutoff).min(line_min);
    }
    let mut compensation = Compensation {
        dk: best[0],
        db: best[1],
        p: best[2],
        q: best[3],
        residual_rms: 0.0,
        residual_span: 0.0,
        error_span: e_max - e_min,
    };
    let residual: Vec<f64> = f
        .iter()
        .zip(e)
        .map(|(f, e)| e - compensation.eval(*f))
        .collect();
    compensation.residual_rms = (residual.iter().map(|r| r * r).sum::<f64>() / n).sqrt();
    compensation.residual_span = span(residual.iter().copied());
    Ok(compensation)
}

/// The four compensations as the controller's parameter set.
pub fn decoupling_params(compensations: &[Compensation; 4]) -> DecouplingParams {
    DecouplingParams {
        dk: compensations.map(|c| c.dk),
        db: compensations.map(|c| c.db),
        p: compensations.map(|c| c.p),
        q: compensations.map(|c| c.q),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn recovers_a_line_with_an_upper_cutoff() {
        let f: Vec<f64> = (0..400).map(|i| 1.0 + 10.0 * i as f64 / 399.0).collect();
        let truth = Compensation {
            dk: 0.3,
            db: -0.4,
            p: 1.8,
            q: -NO_CUTOFF,
            residual_rms: 0.0,
            residual_span: 0.0,
            error_span: 0.0,
        };
        let e: Vec<f64> = f.iter().map(|v| truth.eval(*v)).collect();
        let fit = fit_compensation(&f, &e).unwrap();
        assert!((fit.dk - 0.3).abs() < 1e-4, "{fit:?}");
        assert!((fit.db + 0.4).abs() < 1e-3, "{fit:?}");
        assert!((fit.p - 1.8).abs() < 1e-3, "{fit:?}");
        assert_eq!(fit.q, -NO_CUTOFF, "no lower cutoff in the data");
        assert!(fit.residual_rms < 1e-4);
    }

    #[test]
    fn a_plain_line_gets_no_cutoffs() {
        let f: Vec<f64> = (0..200).map(|i| i as f64 * 0.05).collect();
        let e: Vec<f64> = f
            .iter()
            .enumerate()
            .map(|(i, v)| -0.2 * v + 1.5 + 0.01 * ((i * 7919 % 13) as f64 - 6.0) / 6.0)
            .collect();
        let fit = fit_compensation(&f, &e).unwrap();
        assert!((fit.dk + 0.2).abs() < 2e-3, "{fit:?}");
        assert!((fit.db - 1.5).abs() < 1e-2, "{fit:?}");
        assert!(fit.p >= NO_CUTOFF && fit.q <= -NO_CUTOFF, "{fit:?}");
        // The noise spans 0.02; the fitted line differs from the true one by
        // its estimation error (a few 1e-3 over the sweep).
        assert!(fit.residual_span <= 0.025, "{fit:?}");
    }

    /// A coupling beyond Table 2's ±10 µm (27 % of a 50 µm stroke, as the
    /// stage's D2 is of its 12 µm) is a plain line: its unused cutoffs lie
    /// beyond its reach, where ±10 µm had clamped it (a residual of 3.5 µm).
    #[test]
    fn a_line_beyond_ten_micrometres_is_not_clamped() {
        let f: Vec<f64> = (0..500).map(|i| 50.0 * i as f64 / 499.0).collect();
        let e: Vec<f64> = f
            .iter()
            .enumerate()
            .map(|(i, v)| 0.27 * v - 0.05 + 0.01 * ((i * 7919 % 13) as f64 - 6.0) / 6.0)
            .collect();
        let fit = fit_compensation(&f, &e).unwrap();
        assert!((fit.dk - 0.27).abs() < 1e-4, "{fit:?}");
        assert!((fit.db + 0.05).abs() < 5e-3, "{fit:?}");
        assert!(
            fit.p >= 0.27 * 50.0 - 0.05 && fit.q <= -NO_CUTOFF,
            "{fit:?}"
        );
        assert!(fit.residual_span <= 0.025, "{fit:?}");
        // Falling as steeply: the lower cutoff moves out instead.
        let falling: Vec<f64> = e.iter().map(|v| -v).collect();
        let fit = fit_compensation(&f, &falling).unwrap();
        assert!(
            fit.q <= -(0.27 * 50.0 - 0.05) && fit.p >= NO_CUTOFF,
            "{fit:?}"
        );
        assert!(fit.residual_span <= 0.025, "{fit:?}");
    }

    #[test]
    fn bad_input_is_refused() {
        assert_eq!(
            fit_compensation(&[1.0, 2.0], &[0.0, 0.0]),
            Err(DecouplingError::TooFewSamples(2))
        );
        assert_eq!(
            fit_compensation(&[1.0; 5], &[0.0, 1.0, 2.0, 3.0, 4.0]),
            Err(DecouplingError::ConstantDemand(0.0))
        );
        assert_eq!(
            fit_compensation(&[1.0, 2.0, f64::NAN], &[0.0; 3]),
            Err(DecouplingError::NotFinite(2))
        );
    }
}
