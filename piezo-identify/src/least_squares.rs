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

use nalgebra::{DMatrix, DVector};

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
}
