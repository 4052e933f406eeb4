//! The linear half of the separable fit: min_θ ‖Xθ − u‖² for a tall regressor
//! matrix X.
//!
//! Method: each column is scaled to unit 2-norm, the scaled matrix is
//! factorised by Householder QR (X = QR), Qᵀu is formed by applying the
//! reflectors (Q is never built), and the small p×p triangle R is solved by
//! SVD with singular values below 10⁻¹² of the largest dropped.
//!
//! Why: the columns of seed 000's regressors differ in scale by orders of
//! magnitude (y³ reaches 10³–10⁵ µm³ while H_i is a few µm and ẏ·H_i can be
//! 10³ µm²/s), and some are nearly collinear (H_1 = z and H_2 with r_2 =
//! 0.025·u1max differ only at reversals; G's linear term and H_1 coincide
//! wherever z = y). Normal equations would square the condition number, which
//! for these columns reaches 10⁶–10⁸, and lose most digits; QR works on X
//! itself, is backward stable, and column scaling removes the part of the
//! ill-conditioning that is only units. The SVD of R turns a numerically
//! rank-deficient case (e.g. a dead-zone weight that makes two operators
//! identical, or u1max = 0) into the minimum-norm solution instead of a blow
//! up. The residual sum of squares is read from the components of Qᵀu beyond
//! the first p (plus the part of the first p that a truncated SVD leaves), a
//! sum of squares with no cancellation, so F is accurate even when it is
//! 10⁻²⁰ of ‖u‖² (exact recovery).

use nalgebra::{DMatrix, DMatrixView, DVector, DVectorView};

/// Singular values of the scaled R below this fraction of the largest are
/// treated as zero.
const RELATIVE_SINGULAR_VALUE_FLOOR: f64 = 1e-12;

/// A least-squares solution.
#[derive(Clone, Debug, PartialEq)]
pub struct LinearSolution {
    /// θ, in the units of the original (unscaled) columns.
    pub coefficients: Vec<f64>,
    /// ‖Xθ − u‖².
    pub residual_sum_of_squares: f64,
    /// Numerical rank of the column-scaled X.
    pub rank: usize,
}

/// Solves min ‖Xθ − u‖² (module comment). `x` has one row per sample and at
/// most as many columns as rows.
pub fn solve_least_squares(x: DMatrix<f64>, u: &[f64]) -> LinearSolution {
    solve_scaled(x, u, 0.0)
}

/// [`solve_least_squares`] with Tikhonov regularisation of the column-scaled
/// coefficients, λ‖θ_s‖², λ the largest for which the residual sum of
/// squares grows by at most the fraction `rss_increase` (the discrepancy
/// principle).
///
/// Why: when two regressors are nearly collinear (two backlash operators
/// that barely move over the fitted samples, with the constant), least
/// squares gives them huge opposite weights that cancel on the samples and
/// explain a trace of their residual. Anywhere the two differ more, outside
/// the fitted range or after a small drift of the state, the cancellation
/// fails and the model is off by the weights' size. Among all coefficient
/// sets that fit the samples equally well (within `rss_increase`, 10⁻³: the
/// RMS within 0.05 %), the regularised solve returns the one with the
/// smallest scaled weights; a direction the data support strongly keeps its
/// weight, one that merely cancels loses it. With an exact fit (F = 0) λ is
/// 0 and nothing changes.
pub fn solve_least_squares_regularized(
    x: DMatrix<f64>,
    u: &[f64],
    rss_increase: f64,
) -> LinearSolution {
    solve_scaled(x, u, rss_increase)
}

/// Column-scaled QR, SVD of R; Tikhonov with the discrepancy principle when
/// `rss_increase` > 0 (module comment and the two callers).
fn solve_scaled(mut x: DMatrix<f64>, u: &[f64], rss_increase: f64) -> LinearSolution {
    let (rows, columns) = x.shape();
    assert_eq!(rows, u.len(), "one target per regressor row");
    assert!(rows >= columns, "least squares needs rows >= columns");

    // A zero column (an operator left out, a centred constant) keeps scale
    // None and gets a coefficient of exactly 0: rounding in the SVD mixes
    // ~1e-16 of it into the kept directions, which, unscaled, would not
    // shrink with the data's units (a displacement in pm gave such a column
    // a weight that moved the model by volts).
    let mut scales: Vec<Option<f64>> = vec![None; columns];
    for (j, scale) in scales.iter_mut().enumerate() {
        let mut column = x.column_mut(j);
        let norm = column.norm();
        if norm > 0.0 && norm.is_finite() {
            column /= norm;
            *scale = Some(norm);
        }
    }

    let qr = x.qr();
    let mut qt_u = DVector::from_column_slice(u);
    qr.q_tr_mul(&mut qt_u);
    let r = qr.r();
    let head = qt_u.rows(0, columns).into_owned();
    let svd = r.clone().svd(true, true);
    let largest = svd.singular_values.max();
    let floor = largest * RELATIVE_SINGULAR_VALUE_FLOOR;
    let rank = svd.singular_values.iter().filter(|s| **s > floor).count();
    // ‖u − Xθ‖² = ‖Qᵀu − [R; 0]θ‖²: the tail of Qᵀu plus what the head misses.
    let tail: f64 = qt_u.rows(columns, rows - columns).norm_squared();
    let scaled_theta = if largest <= 0.0 {
        DVector::zeros(columns)
    } else if rss_increase > 0.0 {
        let u_svd = svd.u.as_ref().expect("U was computed");
        let v_t = svd.v_t.as_ref().expect("V was computed");
        let components = u_svd.tr_mul(&head);
        let sigma = &svd.singular_values;
        // Head residual for λ: Σ (λ/(σ² + λ))²·c² over the kept directions,
        // c² for the dropped ones.
        let residual = |lambda: f64| -> f64 {
            sigma
                .iter()
                .zip(components.iter())
                .map(|(s, c)| {
                    if *s > floor {
                        (lambda / (s * s + lambda) * c).powi(2)
                    } else {
                        c * c
                    }
                })
                .sum::<f64>()
        };
        let unregularised = tail + residual(0.0);
        let allowed = (1.0 + rss_increase) * unregularised;
        // The residual grows with λ: bisect ln λ between 10⁻³⁰ and 1 of σ_max².
        let (mut low, mut high) = ((1e-30 * largest * largest).ln(), (largest * largest).ln());
        if tail + residual(low.exp()) > allowed {
            high = low;
        }
        for _ in 0..100 {
            let middle = 0.5 * (low + high);
            if tail + residual(middle.exp()) <= allowed {
                low = middle;
            } else {
                high = middle;
            }
        }
        let lambda = if high == low { 0.0 } else { low.exp() };
        let mut theta = DVector::zeros(columns);
        for (i, (s, c)) in sigma.iter().zip(components.iter()).enumerate() {
            if *s > floor {
                theta += v_t.row(i).transpose() * (s * c / (s * s + lambda));
            }
        }
        theta
    } else {
        svd.solve(&head, floor)
            .expect("U and V were computed, so the SVD can solve")
    };

    let mut scaled_theta = scaled_theta;
    for (theta, scale) in scaled_theta.iter_mut().zip(&scales) {
        if scale.is_none() {
            *theta = 0.0;
        }
    }
    let head_miss = (&head - &r * &scaled_theta).norm_squared();
    let coefficients = scaled_theta
        .iter()
        .zip(&scales)
        .map(|(theta, scale)| scale.map_or(0.0, |scale| theta / scale))
        .collect();
    LinearSolution {
        coefficients,
        residual_sum_of_squares: tail + head_miss,
        rank,
    }
}

/// A centred column whose norm is below this fraction of the column's own
/// norm is constant up to rounding, and counts as zero.
const CONSTANT_COLUMN_TOLERANCE: f64 = 1e-10;

/// Solves min ‖Xθ − u‖² where column `intercept` of X is the constant 1:
/// the other columns and u are centred (their means over the rows taken
/// out), solved by [`solve_least_squares`], and the intercept follows from
/// the means.
///
/// Why: a column that is constant over the rows (a hysteresis operator that
/// did not move on the fitted samples) is the intercept again. The plain
/// solve splits the constant among all such columns, minimum-norm in scaled
/// units, and each then carries a weight the data never tested: outside the
/// fitted range, where the operator moves again, that weight bends the
/// model by an amount no sample justified. Centred, such a column is zero
/// and gets no weight; the residual is the same.
pub fn solve_least_squares_with_intercept(
    x: DMatrix<f64>,
    u: &[f64],
    intercept: usize,
) -> LinearSolution {
    solve_centred(x, u, intercept, 0.0)
}

/// [`solve_least_squares_with_intercept`] regularised as
/// [`solve_least_squares_regularized`] (the intercept is not penalised).
pub fn solve_least_squares_with_intercept_regularized(
    x: DMatrix<f64>,
    u: &[f64],
    intercept: usize,
    rss_increase: f64,
) -> LinearSolution {
    solve_centred(x, u, intercept, rss_increase)
}

fn solve_centred(
    x: DMatrix<f64>,
    u: &[f64],
    intercept: usize,
    rss_increase: f64,
) -> LinearSolution {
    let (rows, columns) = x.shape();
    assert!(intercept < columns, "the intercept is one of the columns");
    assert_eq!(rows, u.len(), "one target per regressor row");
    let others: Vec<usize> = (0..columns).filter(|&j| j != intercept).collect();
    let n = rows.max(1) as f64;
    let u_mean = u.iter().sum::<f64>() / n;
    let means: Vec<f64> = others.iter().map(|&j| x.column(j).sum() / n).collect();
    let mut centred = DMatrix::zeros(rows, others.len());
    for (k, (&j, mean)) in others.iter().zip(&means).enumerate() {
        let original = x.column(j).norm();
        let mut column = centred.column_mut(k);
        column.copy_from(&x.column(j));
        column.add_scalar_mut(-mean);
        if column.norm() <= CONSTANT_COLUMN_TOLERANCE * original {
            column.fill(0.0);
        }
    }
    let targets: Vec<f64> = u.iter().map(|v| v - u_mean).collect();
    let solution = solve_scaled(centred, &targets, rss_increase);
    let mut coefficients = vec![0.0; columns];
    let mut constant = u_mean;
    for (k, &j) in others.iter().enumerate() {
        coefficients[j] = solution.coefficients[k];
        constant -= solution.coefficients[k] * means[k];
    }
    coefficients[intercept] = constant;
    LinearSolution {
        coefficients,
        residual_sum_of_squares: solution.residual_sum_of_squares,
        rank: solution.rank + 1,
    }
}

/// Rows [`NormalEquations`] gathers before adding them to XᵀX in one
/// matrix product.
const NORMAL_EQUATION_BLOCK: usize = 256;

/// XᵀX and Xᵀu accumulated row by row, for the many cheap solves of a search.
///
/// The separable search solves a least-squares problem for every trial
/// (c, w_s). QR on the tall X costs 2·N·p² flops and a matrix of N·p values
/// per trial; the normal equations cost N·p² (added in blocks of rows by
/// nalgebra's matrix product, which runs the vectorised kernels of
/// `matrixmultiply`) and keep only a block. Their weakness, a condition
/// number squared, costs accuracy in θ along the nearly collinear
/// directions, where X barely changes the fit: the fitted values, and so the
/// residual, are off by about ε·κ(X)·‖u‖ (κ(X) ≤ 10⁸ for the column-scaled
/// regressors here: a relative error of 10⁻¹⁶ in F at worst). The residual is
/// therefore not read from the normal equations (u·u − θ·Xᵀu cancels) but
/// summed directly ([`NormalEquations::residual_sum_of_squares`]). When the
/// scaled XᵀX is not numerically positive definite (κ(X)² beyond 10¹⁶),
/// [`NormalEquations::solve`] solves by QR on the rows it keeps instead.
#[derive(Clone, Debug)]
pub struct NormalEquations {
    columns: usize,
    gram: DMatrix<f64>,
    rhs: DVector<f64>,
    /// Every row added, one after the other (Xᵀ column-major), kept for the
    /// residual.
    rows: Vec<f64>,
    targets: Vec<f64>,
    /// Rows already in `gram` and `rhs`.
    summed: usize,
}

impl NormalEquations {
    /// Empty sums for `columns` regressors; `capacity` rows are expected.
    pub fn new(columns: usize, capacity: usize) -> Self {
        NormalEquations {
            columns,
            gram: DMatrix::zeros(columns, columns),
            rhs: DVector::zeros(columns),
            rows: Vec::with_capacity(columns * capacity),
            targets: Vec::with_capacity(capacity),
            summed: 0,
        }
    }

    /// Adds one row x (`columns` values) with target u.
    #[inline]
    pub fn add_row(&mut self, x: &[f64], u: f64) {
        self.rows.extend_from_slice(&x[..self.columns]);
        self.targets.push(u);
        if self.targets.len() - self.summed == NORMAL_EQUATION_BLOCK {
            self.flush();
        }
    }

    /// Adds the rows not yet summed to XᵀX and Xᵀu.
    fn flush(&mut self) {
        let (p, k) = (self.columns, self.targets.len() - self.summed);
        if k == 0 {
            return;
        }
        let block = &self.rows[self.summed * p..];
        let transposed = DMatrixView::from_slice(block, p, k);
        let rows = DMatrixView::from_slice_with_strides(block, k, p, p, 1);
        self.gram.gemm(1.0, &transposed, &rows, 1.0);
        let targets = DVectorView::from_slice(&self.targets[self.summed..], k);
        self.rhs.gemv(1.0, &transposed, &targets, 1.0);
        self.summed += k;
    }

    /// ‖Xθ − u‖² summed over the rows (not from the normal equations, which
    /// cancel: the type's comment).
    pub fn residual_sum_of_squares(&self, theta: &[f64]) -> f64 {
        self.rows
            .chunks_exact(self.columns)
            .zip(&self.targets)
            .map(|(x, u)| {
                let fitted: f64 = x.iter().zip(theta).map(|(x, t)| x * t).sum();
                (u - fitted).powi(2)
            })
            .sum()
    }

    /// θ by column-scaled QR of the kept rows ([`solve_least_squares`]) on
    /// the `used` columns, the others 0.
    fn solve_by_qr(&self, used: &[usize]) -> Option<Vec<f64>> {
        let x = DMatrix::from_fn(self.targets.len(), used.len(), |row, a| {
            self.rows[row * self.columns + used[a]]
        });
        let solution = solve_least_squares(x, &self.targets);
        let mut coefficients = vec![0.0; self.columns];
        for (a, &i) in used.iter().enumerate() {
            coefficients[i] = solution.coefficients[a];
        }
        coefficients
            .iter()
            .all(|t| t.is_finite())
            .then_some(coefficients)
    }

    /// Rows added so far.
    pub fn rows(&self) -> usize {
        self.targets.len()
    }

    /// θ minimising ‖Xθ − u‖², by Cholesky of the column-scaled XᵀX; a column
    /// that is zero throughout gets 0. When the scaled XᵀX is not positive
    /// definite in floating point (κ(X)² beyond 10¹⁶: columns nearly
    /// collinear), by [`solve_least_squares`] on the rows kept, as the final
    /// solve does. Why not the Gram matrix's own eigendecomposition: dropping
    /// its eigenvalues below 10⁻¹² of the largest truncates X at 10⁻⁶·σ_max,
    /// which throws away directions that carry fit; on the XY200S's x record
    /// (eq. 6) the search then settled at F = 1275 V² where QR's cost leads
    /// it to 801 V². None when θ is not finite.
    pub fn solve(&mut self) -> Option<Vec<f64>> {
        self.solve_with(&vec![true; self.columns])
    }

    /// [`NormalEquations::solve`] on the columns where `active` is set only
    /// (the others get 0).
    pub fn solve_with(&mut self, active: &[bool]) -> Option<Vec<f64>> {
        self.flush();
        let used: Vec<usize> = (0..self.columns)
            .filter(|&i| active[i] && self.gram[(i, i)] > 0.0)
            .collect();
        let scales: Vec<f64> = used.iter().map(|&i| self.gram[(i, i)].sqrt()).collect();
        let k = used.len();
        let scaled = DMatrix::from_fn(k, k, |a, b| {
            self.gram[(used[a], used[b])] / (scales[a] * scales[b])
        });
        let rhs = DVector::from_fn(k, |a, _| self.rhs[used[a]] / scales[a]);
        let Some(cholesky) = scaled.cholesky() else {
            return self.solve_by_qr(&used);
        };
        let theta = cholesky.solve(&rhs);
        if theta.iter().any(|t| !t.is_finite()) {
            return None;
        }
        let mut coefficients = vec![0.0; self.columns];
        for (a, &i) in used.iter().enumerate() {
            coefficients[i] = theta[a] / scales[a];
        }
        Some(coefficients)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn recovers_an_exact_solution_with_badly_scaled_columns() {
        let n = 200;
        let t: Vec<f64> = (0..n).map(|i| i as f64 * 0.05).collect();
        let x = DMatrix::from_fn(n, 4, |i, j| match j {
            0 => 1.0,
            1 => 1e3 * t[i],
            2 => 1e-3 * t[i].sin(),
            _ => t[i].powi(3) * 1e4,
        });
        let theta = [0.3, -2e-3, 7e2, 5e-6];
        let u: Vec<f64> = (0..n)
            .map(|i| (0..4).map(|j| x[(i, j)] * theta[j]).sum())
            .collect();
        let solution = solve_least_squares(x, &u);
        assert_eq!(solution.rank, 4);
        for (got, want) in solution.coefficients.iter().zip(theta) {
            assert!((got - want).abs() <= 1e-9 * want.abs(), "{got} vs {want}");
        }
        // ‖u‖² ≈ 10⁶ here; an exact fit leaves rounding only.
        assert!(solution.residual_sum_of_squares < 1e-18, "{solution:?}");
    }

    #[test]
    fn residual_matches_the_direct_sum_of_squares() {
        let n = 50;
        let x = DMatrix::from_fn(n, 2, |i, j| if j == 0 { 1.0 } else { i as f64 });
        let u: Vec<f64> = (0..n).map(|i| (i as f64 * 0.3).sin()).collect();
        let solution = solve_least_squares(x.clone(), &u);
        let theta = DVector::from_vec(solution.coefficients.clone());
        let direct = (&x * theta - DVector::from_vec(u)).norm_squared();
        assert!((solution.residual_sum_of_squares - direct).abs() <= 1e-12 * direct);
    }

    #[test]
    fn rank_deficiency_gives_the_minimum_norm_solution() {
        // Two identical columns and an all-zero one: the weight is shared evenly
        // and the zero column gets 0.
        let n = 30;
        let x = DMatrix::from_fn(n, 3, |i, j| if j == 2 { 0.0 } else { i as f64 });
        let u: Vec<f64> = (0..n).map(|i| 2.0 * i as f64).collect();
        let solution = solve_least_squares(x, &u);
        assert_eq!(solution.rank, 1);
        assert!((solution.coefficients[0] - 1.0).abs() < 1e-12);
        assert!((solution.coefficients[1] - 1.0).abs() < 1e-12);
        assert_eq!(solution.coefficients[2], 0.0);
        assert!(solution.residual_sum_of_squares < 1e-20);
    }

    #[test]
    fn a_constant_column_gets_no_weight_beside_an_intercept() {
        // Columns: intercept, a ramp, a column constant at 5 (an operator
        // that never moved). The plain solve shares the constant between the
        // intercept and that column; with the intercept it stays there.
        let n = 50;
        let x = DMatrix::from_fn(n, 3, |i, j| match j {
            0 => 1.0,
            1 => i as f64 * 0.1,
            _ => 5.0,
        });
        let u: Vec<f64> = (0..n).map(|i| 2.0 + 0.3 * i as f64 * 0.1).collect();
        let plain = solve_least_squares(x.clone(), &u);
        assert!(plain.coefficients[2].abs() > 0.01, "{plain:?}");
        let centred = solve_least_squares_with_intercept(x, &u, 0);
        assert_eq!(centred.coefficients[2], 0.0);
        assert!((centred.coefficients[0] - 2.0).abs() < 1e-12);
        assert!((centred.coefficients[1] - 0.3).abs() < 1e-12);
        assert!(centred.residual_sum_of_squares < 1e-20);
        assert!((plain.residual_sum_of_squares - centred.residual_sum_of_squares).abs() < 1e-20);
    }

    #[test]
    fn a_zero_column_gets_exactly_zero_at_any_scale() {
        // Ill-conditioned live columns beside a zero one: the zero one's
        // weight is 0, not rounding, and the others scale with the units.
        let n = 300;
        let column = |i: usize, j: usize, scale: f64| {
            let t = i as f64 / n as f64;
            scale
                * match j {
                    0 => t,
                    1 => t + 1e-6 * (37.0 * t).sin(),
                    2 => 0.0,
                    _ => t * t,
                }
        };
        let u: Vec<f64> = (0..n)
            .map(|i| {
                let t = i as f64 / n as f64;
                1.0 + 2.0 * t + 0.5 * t * t + 1e-4 * (91.0 * t).sin()
            })
            .collect();
        for (rss_increase, scale) in [(0.0, 1.0), (0.0, 1e6), (1e-3, 1.0), (1e-3, 1e6)] {
            let x = DMatrix::from_fn(n, 5, |i, j| if j == 4 { 1.0 } else { column(i, j, scale) });
            let solution = solve_least_squares_with_intercept_regularized(x, &u, 4, rss_increase);
            assert_eq!(solution.coefficients[2], 0.0, "{solution:?}");
            let unit = solve_least_squares_with_intercept_regularized(
                DMatrix::from_fn(n, 5, |i, j| if j == 4 { 1.0 } else { column(i, j, 1.0) }),
                &u,
                4,
                rss_increase,
            );
            for j in [0, 1, 3] {
                let expected = unit.coefficients[j] / scale;
                assert!(
                    (solution.coefficients[j] - expected).abs()
                        <= 1e-6 * expected.abs().max(1e-12 / scale),
                    "column {j}, scale {scale}: {solution:?} against {unit:?}"
                );
            }
        }
    }

    #[test]
    fn regularisation_drops_weights_that_only_cancel() {
        // Two regressors equal to the ramp t up to traces of 10⁻⁵ that
        // differ; u = t + noise + 1.5·10⁻⁵ of the first trace. Least squares
        // explains that last sliver with weights 1.5 and −0.5 (their
        // difference multiplies the traces); it is 0.02 % of the residual,
        // so the regularised solve shares the ramp evenly instead.
        let n = 400;
        let t = |i: usize| i as f64 / n as f64;
        let trace = |i: usize, k: f64| ((i as f64) * k).sin();
        let x = DMatrix::from_fn(n, 3, |i, j| match j {
            0 => 1.0,
            1 => t(i) + 1e-5 * trace(i, 0.37),
            _ => t(i) + 1e-5 * trace(i, 0.91),
        });
        let u: Vec<f64> = (0..n)
            .map(|i| t(i) + 1e-3 * trace(i, 2.3) + 1.5e-5 * trace(i, 0.37))
            .collect();
        let plain = solve_least_squares_with_intercept(x.clone(), &u, 0);
        let regular = solve_least_squares_with_intercept_regularized(x, &u, 0, 1e-3);
        assert!(plain.coefficients[1] > 1.2, "{plain:?}");
        let [_, w1, w2] = [
            regular.coefficients[0],
            regular.coefficients[1],
            regular.coefficients[2],
        ];
        assert!((w1 - w2).abs() < 0.2, "{regular:?}");
        assert!((w1 + w2 - 1.0).abs() < 1e-2, "{regular:?}");
        assert!(
            regular.residual_sum_of_squares <= 1.001 * plain.residual_sum_of_squares * (1.0 + 1e-9)
        );
        // An exact fit is not regularised.
        let exact: Vec<f64> = (0..n).map(|i| 2.0 + 3.0 * t(i)).collect();
        let x = DMatrix::from_fn(n, 2, |i, j| if j == 0 { 1.0 } else { t(i) });
        let fit = solve_least_squares_regularized(x, &exact, 1e-3);
        assert!((fit.coefficients[1] - 3.0).abs() < 1e-10, "{fit:?}");
    }

    #[test]
    fn normal_equations_agree_with_qr() {
        let n = 300;
        let x = DMatrix::from_fn(n, 4, |i, j| {
            let t = i as f64 * 0.02;
            match j {
                0 => 1.0,
                1 => 1e3 * t,
                2 => 0.0,
                _ => (t * 1.7).sin() * 1e-2,
            }
        });
        let u: Vec<f64> = (0..n).map(|i| (i as f64 * 0.11).cos() + 0.3).collect();
        let mut normal = NormalEquations::new(4, n);
        for i in 0..n {
            let row: Vec<f64> = (0..4).map(|j| x[(i, j)]).collect();
            normal.add_row(&row, u[i]);
        }
        assert_eq!(normal.rows(), n);
        let theta = normal.solve().unwrap();
        let qr = solve_least_squares(x.clone(), &u);
        assert_eq!(theta[2], 0.0);
        let rss = |t: &[f64]| -> f64 {
            (0..n)
                .map(|i| {
                    let fitted: f64 = (0..4).map(|j| x[(i, j)] * t[j]).sum();
                    (u[i] - fitted).powi(2)
                })
                .sum()
        };
        assert!(
            (rss(&theta) - qr.residual_sum_of_squares).abs() < 1e-12 * qr.residual_sum_of_squares
        );
        assert!((normal.residual_sum_of_squares(&theta) - rss(&theta)).abs() < 1e-12 * rss(&theta));
    }

    #[test]
    fn normal_equations_fall_back_to_qr_and_keep_a_weak_direction() {
        // Two columns that differ by 3·10⁻⁹ of a sine: κ(X) ≈ 10⁹, so XᵀX
        // (κ ≈ 10¹⁸) is not positive definite in floating point here (its
        // Cholesky fails). u holds that difference at 10⁻⁴ of its size, which
        // QR resolves (its fitted values are good to about ε·κ(X) ≈ 10⁻⁷ of
        // ‖u‖); truncating XᵀX's eigenvalues below 10⁻¹² of the largest, as
        // the solve did before, drops it and leaves all of it.
        let n = 2000;
        let t = |i: usize| i as f64 / n as f64;
        let s = |i: usize| (i as f64 * 0.031).sin();
        let x = DMatrix::from_fn(n, 2, |i, j| if j == 0 { t(i) } else { t(i) + 3e-9 * s(i) });
        let u: Vec<f64> = (0..n).map(|i| t(i) + 1e-4 * s(i)).collect();
        let mut normal = NormalEquations::new(2, n);
        for i in 0..n {
            normal.add_row(&[x[(i, 0)], x[(i, 1)]], u[i]);
        }
        let theta = normal.solve().unwrap();
        let weak: f64 = (0..n).map(|i| (1e-4 * s(i)).powi(2)).sum();
        let residual = normal.residual_sum_of_squares(&theta);
        assert!(residual < 1e-3 * weak, "{residual} against {weak}");
        // Where Cholesky fails (rounding decides, at κ ≈ 10¹⁸), θ is QR's.
        let d = normal.gram.diagonal().map(f64::sqrt);
        let scaled = DMatrix::from_fn(2, 2, |a, b| normal.gram[(a, b)] / (d[a] * d[b]));
        if scaled.cholesky().is_none() {
            assert_eq!(theta, solve_least_squares(x, &u).coefficients);
        }
    }

    #[test]
    fn normal_equations_give_the_minimum_norm_solution_of_a_singular_system() {
        // Two identical columns: Cholesky fails, the weight is shared evenly.
        let mut normal = NormalEquations::new(2, 10);
        for i in 0..10 {
            let v = i as f64 + 1.0;
            normal.add_row(&[v, v], 2.0 * v);
        }
        let theta = normal.solve().unwrap();
        assert!(
            (theta[0] - 1.0).abs() < 1e-12 && (theta[1] - 1.0).abs() < 1e-12,
            "{theta:?}"
        );
        assert!(normal.residual_sum_of_squares(&theta) < 1e-20);
    }
}
