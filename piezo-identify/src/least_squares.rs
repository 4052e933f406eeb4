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
pub fn solve_least_squares(mut x: DMatrix<f64>, u: &[f64]) -> LinearSolution {
    let (rows, columns) = x.shape();
    assert_eq!(rows, u.len(), "one target per regressor row");
    assert!(rows >= columns, "least squares needs rows >= columns");

    let mut scales = vec![1.0; columns];
    for (j, scale) in scales.iter_mut().enumerate() {
        let mut column = x.column_mut(j);
        let norm = column.norm();
        if norm > 0.0 && norm.is_finite() {
            column /= norm;
            *scale = norm;
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
    let scaled_theta = if largest > 0.0 {
        svd.solve(&head, floor)
            .expect("U and V were computed, so the SVD can solve")
    } else {
        DVector::zeros(columns)
    };

    // ‖u − Xθ‖² = ‖Qᵀu − [R; 0]θ‖²: the tail of Qᵀu plus what the head misses.
    let tail: f64 = qt_u.rows(columns, rows - columns).norm_squared();
    let head_miss = (&head - &r * &scaled_theta).norm_squared();
    let coefficients = scaled_theta
        .iter()
        .zip(&scales)
        .map(|(theta, scale)| theta / scale)
        .collect();
    LinearSolution {
        coefficients,
        residual_sum_of_squares: tail + head_miss,
        rank,
    }
}

/// Eigenvalues of the scaled XᵀX below this fraction of the largest are
/// dropped when Cholesky fails ([`NormalEquations::solve`]).
pub const GRAM_EIGENVALUE_FLOOR: f64 = 1e-12;

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
/// [`NormalEquations::solve`] truncates its eigendecomposition instead.
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

    /// Rows added so far.
    pub fn rows(&self) -> usize {
        self.targets.len()
    }

    /// θ minimising ‖Xθ − u‖², by Cholesky of the column-scaled XᵀX; a column
    /// that is zero throughout gets 0. When the scaled XᵀX is not positive
    /// definite in floating point (κ(X)² beyond 10¹⁶: columns nearly
    /// collinear), by its eigendecomposition with eigenvalues below
    /// [`GRAM_EIGENVALUE_FLOOR`] of the largest dropped, the minimum-norm
    /// solution on the rest (a truncated SVD of X at 10⁻⁶·σ_max, coarser than
    /// [`solve_least_squares`]'s 10⁻¹², which is why the search's final
    /// solve is by QR). None when θ is not finite.
    pub fn solve(&mut self) -> Option<Vec<f64>> {
        self.flush();
        let used: Vec<usize> = (0..self.columns)
            .filter(|&i| self.gram[(i, i)] > 0.0)
            .collect();
        let scales: Vec<f64> = used.iter().map(|&i| self.gram[(i, i)].sqrt()).collect();
        let k = used.len();
        let scaled = DMatrix::from_fn(k, k, |a, b| {
            self.gram[(used[a], used[b])] / (scales[a] * scales[b])
        });
        let rhs = DVector::from_fn(k, |a, _| self.rhs[used[a]] / scales[a]);
        let theta = match scaled.clone().cholesky() {
            Some(cholesky) => cholesky.solve(&rhs),
            None => {
                let eigen = scaled.symmetric_eigen();
                let largest = eigen.eigenvalues.max();
                let floor = largest * GRAM_EIGENVALUE_FLOOR;
                let mut theta = DVector::zeros(k);
                for (j, &lambda) in eigen.eigenvalues.iter().enumerate() {
                    if lambda > floor {
                        let v = eigen.eigenvectors.column(j);
                        theta += v * (v.dot(&rhs) / lambda);
                    }
                }
                theta
            }
        };
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
        assert!((rss(&theta) - qr.residual_sum_of_squares).abs() < 1e-12 * qr.residual_sum_of_squares);
        assert!((normal.residual_sum_of_squares(&theta) - rss(&theta)).abs() < 1e-12 * rss(&theta));
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
        assert!((theta[0] - 1.0).abs() < 1e-12 && (theta[1] - 1.0).abs() < 1e-12, "{theta:?}");
        assert!(normal.residual_sum_of_squares(&theta) < 1e-20);
    }
}
