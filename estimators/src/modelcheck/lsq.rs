//! Weighted linear least squares of a residual on signature columns (DESIGN.md §8 `diagnose`).
//!
//! [`fit_signature`] solves min_β Σ_i ((r_i − Σ_j X_ij β_j)/σ_i)² with faer's thin SVD on the
//! column-scaled weighted design, so rank deficiency (two signatures that are identical on these
//! samples) is detected and reported rather than producing huge, cancelling coefficients.

use super::{check_finite, check_len, check_min, ModelCheckError, Sigma};
use faer::Mat;
use serde::{Deserialize, Serialize};

/// A weighted linear least-squares fit of a residual.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct LinearFit {
    /// Fitted coefficients β_j, in residual unit per column unit.
    pub coefficients: Vec<f64>,
    /// Standard errors of β_j: √[(XᵀWX)⁻¹]_jj with W = diag(1/σ_i²) when σ is known, times
    /// √(RSS/(n − rank)) when σ is unknown; infinite (JSON null) for a coefficient that these
    /// samples cannot determine (rank deficiency).
    pub std_errors: Vec<f64>,
    /// The new residual r_i − Σ_j X_ij β_j, in the residual's unit.
    #[serde(skip)]
    pub residual: Vec<f64>,
    /// Residual sum of squares Σ r_new,i², in the residual's unit squared.
    pub rss: f64,
    /// χ² = Σ (r_new,i/σ_i)² when σ is known.
    pub chi2: Option<f64>,
    /// Numerical rank of the weighted design (< number of columns when columns are dependent).
    pub rank: usize,
    /// Degrees of freedom n − rank.
    pub dof: usize,
    /// Condition number s_max/s_min of the weighted design with unit-norm columns (∞ if
    /// rank-deficient).
    pub condition_number: f64,
}

/// Weighted linear least squares of a residual on signature columns:
/// β̂ = argmin Σ_i ((r_i − Σ_j X_ij β_j)/σ_i)² (unweighted when σ is unknown), solved by the thin
/// SVD (faer) of A = W^{1/2} X D⁻¹ (D = column norms): β̂ = D⁻¹ Σ_{s_k > tol} v_k (u_kᵀ W^{1/2} r)/s_k,
/// tol = 1e-10·s_max (columns dependent to 1e-10 relative count as dependent); Cov(β̂) = D⁻¹ V S⁻² Vᵀ D⁻¹ (× RSS/(n − rank) when σ is unknown).
///
/// `columns` holds p columns of n values each (one value per sample). Needs n > p.
pub fn fit_signature(residual: &[f64], columns: &[Vec<f64>], sigma: &Sigma) -> Result<LinearFit, ModelCheckError> {
    let n = residual.len();
    let p = columns.len();
    if p == 0 {
        return Err(ModelCheckError::Invalid("fit_signature: need at least one signature column, got none".into()));
    }
    check_min("fit_signature (columns + 1)", p + 1, n)?;
    check_finite("residual", residual)?;
    for (j, c) in columns.iter().enumerate() {
        check_len(&format!("column {j}"), n, c.len())?;
        check_finite(&format!("column {j}"), c)?;
    }
    let w = sigma.weights(n)?;
    let norms: Vec<f64> = columns
        .iter()
        .map(|c| {
            let s = c.iter().zip(&w).map(|(x, w)| (x * w).powi(2)).sum::<f64>().sqrt();
            if s > 0.0 {
                s
            } else {
                1.0
            }
        })
        .collect();
    let a = Mat::<f64>::from_fn(n, p, |i, j| columns[j][i] * w[i] / norms[j]);
    let svd = a.thin_svd().map_err(|e| ModelCheckError::Numerical(format!("SVD did not converge: {e:?}")))?;
    let u = svd.U();
    let v = svd.V();
    let s = svd.S().column_vector();
    let s_max = (0..p).map(|k| s[k]).fold(0.0, f64::max);
    let tol = 1e-10 * s_max;
    let keep: Vec<usize> = (0..p).filter(|&k| s[k] > tol && s[k] > 0.0).collect();
    let rank = keep.len();
    let b: Vec<f64> = residual.iter().zip(&w).map(|(r, w)| r * w).collect();
    let mut beta = vec![0.0; p];
    for &k in &keep {
        let ub: f64 = (0..n).map(|i| u[(i, k)] * b[i]).sum();
        for (j, bj) in beta.iter_mut().enumerate() {
            *bj += v[(j, k)] * ub / s[k];
        }
    }
    for (bj, nj) in beta.iter_mut().zip(&norms) {
        *bj /= nj;
    }
    let new_res: Vec<f64> =
        (0..n).map(|i| residual[i] - (0..p).map(|j| columns[j][i] * beta[j]).sum::<f64>()).collect();
    let rss: f64 = new_res.iter().map(|r| r * r).sum();
    let chi2_w: f64 = new_res.iter().zip(&w).map(|(r, w)| (r * w).powi(2)).sum();
    let dof = n - rank;
    let scale = if sigma.is_known() { 1.0 } else { (chi2_w / dof as f64).sqrt() };
    let std_errors = (0..p)
        .map(|j| {
            let null: f64 = (0..p).filter(|k| !keep.contains(k)).map(|k| v[(j, k)].powi(2)).sum();
            if null > 1e-12 {
                f64::INFINITY
            } else {
                let var: f64 = keep.iter().map(|&k| (v[(j, k)] / s[k]).powi(2)).sum();
                var.sqrt() / norms[j] * scale
            }
        })
        .collect();
    let s_min = (0..p).map(|k| s[k]).fold(f64::INFINITY, f64::min);
    Ok(LinearFit {
        coefficients: beta,
        std_errors,
        residual: new_res,
        rss,
        chi2: sigma.is_known().then_some(chi2_w),
        rank,
        dof,
        condition_number: if rank == p { s_max / s_min } else { f64::INFINITY },
    })
}

/// Orthonormal basis (modified Gram–Schmidt with re-orthogonalisation, "twice is enough") of
/// weighted columns; a column whose remaining norm is below 1e-9 of its own norm is dependent
/// and dropped. Used for the fast ΔRSS evaluations of the hyper-parameter search.
#[derive(Debug, Clone, Default)]
pub(crate) struct Basis {
    pub q: Vec<Vec<f64>>,
}

impl Basis {
    /// Removes the components of `v` along the basis (twice, for numerical orthogonality).
    pub fn project_out(&self, v: &mut [f64]) {
        for _ in 0..2 {
            for q in &self.q {
                let d: f64 = q.iter().zip(v.iter()).map(|(a, b)| a * b).sum();
                for (vi, qi) in v.iter_mut().zip(q) {
                    *vi -= d * qi;
                }
            }
        }
    }

    /// Adds `v` (already weighted) to the basis; returns the coefficients of v along the old
    /// basis vectors and its new normalised length, or `None` for the length if dependent.
    pub fn push(&mut self, mut v: Vec<f64>) -> (Vec<f64>, Option<f64>) {
        let norm0 = v.iter().map(|x| x * x).sum::<f64>().sqrt();
        let mut coef = vec![0.0; self.q.len()];
        for _ in 0..2 {
            for (c, q) in coef.iter_mut().zip(&self.q) {
                let d: f64 = q.iter().zip(v.iter()).map(|(a, b)| a * b).sum();
                *c += d;
                for (vi, qi) in v.iter_mut().zip(q) {
                    *vi -= d * qi;
                }
            }
        }
        let norm = v.iter().map(|x| x * x).sum::<f64>().sqrt();
        if norm0 == 0.0 || norm <= 1e-9 * norm0 {
            return (coef, None);
        }
        for x in v.iter_mut() {
            *x /= norm;
        }
        self.q.push(v);
        (coef, Some(norm))
    }
}

/// Small weighted least squares by MGS QR with column dropping: returns (β, χ²) for
/// min Σ (w_i (y_i − Σ_j X_ij β_j))²; a dependent column gets β_j = 0.
pub(crate) fn small_lstsq(cols: &[&[f64]], y: &[f64], w: &[f64]) -> (Vec<f64>, f64) {
    let p = cols.len();
    let mut basis = Basis::default();
    // R factor: for each kept column, its coefficients on earlier basis vectors and diagonal.
    let mut kept: Vec<usize> = Vec::with_capacity(p);
    let mut r_rows: Vec<(Vec<f64>, f64)> = Vec::with_capacity(p);
    for (j, c) in cols.iter().enumerate() {
        let v: Vec<f64> = c.iter().zip(w).map(|(x, w)| x * w).collect();
        let (coef, norm) = basis.push(v);
        if let Some(nrm) = norm {
            kept.push(j);
            r_rows.push((coef, nrm));
        }
    }
    let mut yw: Vec<f64> = y.iter().zip(w).map(|(y, w)| y * w).collect();
    let qty: Vec<f64> = basis.q.iter().map(|q| q.iter().zip(&yw).map(|(a, b)| a * b).sum()).collect();
    basis.project_out(&mut yw);
    let chi2: f64 = yw.iter().map(|x| x * x).sum();
    // Back-substitution: R is upper triangular with R[i][m] = r_rows[m].0[i] (i < m), R[m][m] = norm.
    let m = kept.len();
    let mut z = vec![0.0; m];
    for a in (0..m).rev() {
        let mut s = qty[a];
        for b in a + 1..m {
            s -= r_rows[b].0[a] * z[b];
        }
        z[a] = s / r_rows[a].1;
    }
    let mut beta = vec![0.0; p];
    for (a, &j) in kept.iter().enumerate() {
        beta[j] = z[a];
    }
    (beta, chi2)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn exact_fit_and_hand_worked_standard_error() {
        // r = 1 + 2x at x = 0, 1, 2, 3 with σ = 0.5: exact fit, zero residual.
        let x = vec![0.0, 1.0, 2.0, 3.0];
        let r: Vec<f64> = x.iter().map(|x| 1.0 + 2.0 * x).collect();
        let f = fit_signature(&r, &[vec![1.0; 4], x.clone()], &Sigma::Constant(0.5)).unwrap();
        assert!((f.coefficients[0] - 1.0).abs() < 1e-13 && (f.coefficients[1] - 2.0).abs() < 1e-13);
        assert!(f.rss < 1e-24 && f.rank == 2 && f.dof == 2);
        // Hand-worked: slope variance σ²/Σ(x − x̄)² = 0.25/5 → SE = 0.2236068;
        // intercept variance σ²(1/n + x̄²/Sxx) = 0.25·(0.25 + 2.25/5) = 0.175 → 0.4183300.
        assert!((f.std_errors[1] - (0.05f64).sqrt()).abs() < 1e-13);
        assert!((f.std_errors[0] - (0.175f64).sqrt()).abs() < 1e-13);
        // small_lstsq agrees.
        let (b, chi) = small_lstsq(&[&[1.0; 4], &x], &r, &[2.0; 4]);
        assert!((b[0] - 1.0).abs() < 1e-13 && (b[1] - 2.0).abs() < 1e-13 && chi < 1e-24);
    }

    #[test]
    fn dependent_columns_are_reported() {
        let x = vec![0.0, 1.0, 2.0, 3.0, 4.0];
        let r = vec![0.1, 0.9, 2.1, 2.9, 4.2];
        let two_x: Vec<f64> = x.iter().map(|x| 2.0 * x).collect();
        let f = fit_signature(&r, &[x.clone(), two_x.clone()], &Sigma::Unknown).unwrap();
        assert_eq!(f.rank, 1);
        assert!(f.std_errors.iter().all(|s| s.is_infinite()));
        // The fitted values are still the projection onto x: slope Σxr/Σx² = (0 + 0.9 + 4.2 + 8.7 + 16.8)/30 = 30.6/30.
        let slope = f.coefficients[0] + 2.0 * f.coefficients[1];
        assert!((slope - 30.6 / 30.0).abs() < 1e-12);
        let (b, _) = small_lstsq(&[&x, &two_x], &r, &[1.0; 5]);
        assert!((b[0] - 30.6 / 30.0).abs() < 1e-12 && b[1] == 0.0);
        assert!(fit_signature(&r, &[vec![1.0, f64::NAN, 1.0, 1.0, 1.0]], &Sigma::Unknown).is_err());
        assert!(fit_signature(&r, &[x], &Sigma::Constant(-1.0)).is_err());
    }
}

/// Squared relative distance below which a scaled column counts as dependent on the columns
/// already chosen ([`solve_normal`]), in units of the scaled Gram matrix's largest eigenvalue:
/// 1e-11, a column within ≈ 3e-6·√λ_max of their span. Relative to λ_max, as an
/// eigendecomposition's cut is: a family of strongly correlated columns (neighbouring waves of an
/// overcomplete cosine series) has λ_max up to its size. A direction kept near the cut takes a
/// coefficient fitted to the noise (≈ σ/√λ), which an alternating fit (the joint mode fit,
/// `coupled.rs`) feeds into its next design, so where the cut falls must not decide the answer.
/// Measured on generator draw 1006 (a 58.669 Hz mode, ζ 0.0307, compare from stated values): at a
/// cut of 1e-13 the joint fit ended at 59.058 Hz, ζ 0.0295, normalised RMS 1.142, with a few of
/// ~150 directions per solve sitting within a factor 5 of the cut; at 1e-12, 1e-11, 1e-10 and 1e-9
/// it ended at 58.671–58.673 Hz, ζ 0.0307, normalised RMS 0.984–0.989.
pub const DEPENDENT_PIVOT: f64 = 1e-11;

/// Power iterations of [`largest_eigenvalue`] at most.
const POWER_ITERATIONS: usize = 30;

/// [`largest_eigenvalue`] stops once an iteration moves the estimate by less than this fraction:
/// the estimate only places [`solve_normal`]'s cut, and cuts from 1e-12 to 1e-9 gave the same
/// joint fit to four digits ([`DEPENDENT_PIVOT`]).
const POWER_HOLD: f64 = 1e-6;

/// [`largest_eigenvalue_until`] run to its end: the tests' reference.
#[cfg(test)]
fn largest_eigenvalue(m: &Mat<f64>) -> f64 {
    largest_eigenvalue_until(m, |_| false)
}

/// The largest eigenvalue of the symmetric positive semi-definite `m` (≥ its largest diagonal
/// entry), by power iterations from the vector of ones (Rayleigh quotient; deterministic), until
/// one moves it by less than [`POWER_HOLD`] (at most [`POWER_ITERATIONS`]). A slight
/// underestimate at worst (the Rayleigh quotient only grows towards it), which only makes
/// [`solve_normal`]'s cut a little stricter.
///
/// The iterations end early once `enough` holds for a lower bound of that estimate: each
/// iteration's Rayleigh quotient λ_k less 10⁻¹² of it (the quotients of power iterates on a
/// positive semi-definite matrix never decrease, so the estimate is at least λ_k; their rounding,
/// about p·ε, is below the margin). It then returns λ_k (at least the largest diagonal entry).
/// [`NormalFactor::new`] asks only which pivots the cut at the estimate keeps: once the cut at
/// this lower bound keeps those of the cut at an upper bound, every value between them does.
fn largest_eigenvalue_until(m: &Mat<f64>, enough: impl Fn(f64) -> bool) -> f64 {
    let p = m.nrows();
    let top_diag = (0..p).map(|i| m[(i, i)]).fold(0.0_f64, f64::max);
    let mut v = vec![1.0 / (p.max(1) as f64).sqrt(); p];
    let mut lambda = 0.0_f64;
    for _ in 0..POWER_ITERATIONS {
        // (M·v)_i = column i of M (symmetric) against v: contiguous columns of the column-major M.
        let mv: Vec<f64> = (0..p).map(|i| super::ortho::dot(m.col_as_slice(i), &v)).collect();
        let last = lambda;
        lambda = v.iter().zip(&mv).map(|(a, b)| a * b).sum();
        if enough(lambda * (1.0 - 1e-12)) {
            break;
        }
        let norm = mv.iter().map(|x| x * x).sum::<f64>().sqrt();
        if !(norm > 0.0) || (lambda - last).abs() < POWER_HOLD * lambda {
            break;
        }
        v = mv.iter().map(|x| x / norm).collect();
    }
    lambda.max(top_diag)
}

/// Gershgorin's bound on the eigenvalues of the symmetric `m`: max_i Σ_j |m_ij| ≥ λ_max (each
/// column read contiguously; M is symmetric, so its columns' sums are its rows').
fn row_sum_bound(m: &Mat<f64>) -> f64 {
    (0..m.ncols()).map(|j| m.col_as_slice(j).iter().map(|v| v.abs()).sum::<f64>()).fold(0.0, f64::max)
}

/// Least squares from the normal equations: β̂ minimising ‖y − Xβ‖² given only the Gram matrix
/// N = XᵀX (`gram`, p × p, row-major, symmetric) and b = Xᵀy. Solved by faer's Cholesky
/// factorisation with diagonal pivoting (LAPACK's `dpstrf`) of the Jacobi-scaled M = D⁻¹ND⁻¹
/// (D = √diag N, so M has a unit diagonal): P·M·Pᵀ = L·Lᵀ, each step taking the column farthest
/// from the span of those already taken. Its pivot L_jj² is that column's squared distance from
/// their span (relative to its own norm); the pivots do not increase, and the first below
/// [`DEPENDENT_PIVOT`]·λ_max(M) ends the factor at rank r. At full rank, L·Lᵀ·z = P·D⁻¹b by two triangular
/// solves; at rank r < p, with L the first r columns of the factor (p × r), the minimum-norm
/// z = (L·Lᵀ)⁺·P·D⁻¹b (the pseudo-inverse of the scaled matrix restricted to what the chosen
/// columns span, as an eigendecomposition's cut would give), from two triangular solves with the
/// leading r × r block and a projection on the p − r null directions of Lᵀ ([`NormalFactor`]): work
/// r²·(p − r) beyond the factor, where forming LᵀL took p·r²; β̂ = D⁻¹Pᵀz. The minimum norm
/// matters to a caller that feeds the coefficients back into the next
/// design (alternating fits): a component along a dependency of this design need not be one of
/// the next. A column with zero norm gets β = 0. For designs whose Gram matrix is
/// cheap to update while the columns themselves are not (many samples, few columns that change by
/// small per-block transforms). Errors on a size mismatch or a non-finite entry.
pub fn solve_normal(gram: &[f64], b: &[f64]) -> Result<Vec<f64>, ModelCheckError> {
    let p = b.len();
    check_len("solve_normal: Gram matrix", p * p, gram.len())?;
    check_finite("solve_normal: Gram matrix", gram)?;
    check_finite("solve_normal: right-hand side", b)?;
    NormalFactor::new(gram, p)?.solve(b)
}

/// The factor of one Gram matrix N (p × p) in [`solve_normal`], for several right-hand sides:
/// each [`NormalFactor::solve`] gives the same bits as `solve_normal(N, b)`.
pub struct NormalFactor {
    /// 1/D_jj (0 for a column with zero norm).
    inv: Vec<f64>,
    /// The pivoted Cholesky factor L of P·M·Pᵀ in the lower triangle, and P (perm[j]: the column
    /// of M at step j).
    m: Mat<f64>,
    perm: Vec<usize>,
    /// Below full rank r (d = p − r dependent columns): N₁ = −L₁⁻ᵀ·L₂ᵀ (r × d; L₁ the leading r × r
    /// block of L, L₂ the d × r block below it), so that the columns of N = [N₁; I_d] span the null
    /// space of Lᵀ, and the Cholesky factor of NᵀN = I_d + N₁ᵀN₁.
    low: Option<(Mat<f64>, nalgebra::Cholesky<f64, nalgebra::Dyn>)>,
}

impl NormalFactor {
    /// Factors `gram` (p × p, row-major, symmetric, finite; [`solve_normal`] for the method).
    /// Errors on a size mismatch, a non-finite entry or a failed factorisation.
    pub fn new(gram: &[f64], p: usize) -> Result<Self, ModelCheckError> {
        use faer::dyn_stack::{MemBuffer, MemStack};
        use faer::linalg::cholesky::llt_pivoting::factor::{cholesky_in_place, cholesky_in_place_scratch};
        check_len("solve_normal: Gram matrix", p * p, gram.len())?;
        check_finite("solve_normal: Gram matrix", gram)?;
        let inv: Vec<f64> =
            (0..p).map(|j| gram[j * p + j].max(0.0).sqrt()).map(|d| if d > 0.0 { 1.0 / d } else { 0.0 }).collect();
        let scaled = || Mat::<f64>::from_fn(p, p, |i, j| gram[i * p + j] * inv[i] * inv[j]);
        let mut m = scaled();
        // The cut's estimate of λ_max(M) lies between M's largest diagonal entry and Gershgorin's
        // bound ([`largest_eigenvalue`]): when the cuts at both ends keep the same leading
        // pivots, that is the rank at any estimate, and the power iterations (on M formed again:
        // the factor overwrites it) are skipped.
        let top_diag = (0..p).map(|i| m[(i, i)]).fold(0.0_f64, f64::max);
        let above = row_sum_bound(&m) * (1.0 + 1e-12);
        let (mut perm, mut perm_inv) = (vec![0usize; p], vec![0usize; p]);
        let par = faer::Par::Seq; // sequential: the same bits on any thread count
        let mut buf = MemBuffer::new(cholesky_in_place_scratch::<usize, f64>(p, par, Default::default()));
        let (info, _) =
            cholesky_in_place(m.as_mut(), &mut perm, &mut perm_inv, par, MemStack::new(&mut buf), Default::default())
                .map_err(|e| ModelCheckError::Numerical(format!("solve_normal: pivoted Cholesky: {e:?}")))?;
        let kept = |cut: f64| (0..info.rank).take_while(|&j| m[(j, j)] * m[(j, j)] >= cut).count();
        let at_above = kept(DEPENDENT_PIVOT * above);
        let r = match kept(DEPENDENT_PIVOT * top_diag) {
            r if r == at_above => r,
            // The iterations end once a lower bound of their estimate keeps what the upper one
            // does ([`largest_eigenvalue_until`]).
            _ => {
                kept(DEPENDENT_PIVOT * largest_eigenvalue_until(&scaled(), |lo| kept(DEPENDENT_PIVOT * lo) == at_above))
            }
        };
        let low = if r == p {
            None
        } else {
            // Rank r: P·M·Pᵀ ≈ L·Lᵀ with L the first r columns (p × r). N₁ by back substitution
            // with L₁ᵀ, one null direction (a row of L₂) at a time.
            let d = p - r;
            let mut n1 = Mat::<f64>::zeros(r, d);
            for e in 0..d {
                for j in (0..r).rev() {
                    let s: f64 = (j + 1..r).map(|k| m[(k, j)] * n1[(k, e)]).sum();
                    n1[(j, e)] = (-m[(r + e, j)] - s) / m[(j, j)];
                }
            }
            let g = nalgebra::DMatrix::from_fn(d, d, |a, b| {
                f64::from(u8::from(a == b)) + (0..r).map(|k| n1[(k, a)] * n1[(k, b)]).sum::<f64>()
            });
            let chol = nalgebra::Cholesky::new(g)
                .ok_or_else(|| ModelCheckError::Numerical("solve_normal: NᵀN not positive definite".into()))?;
            Some((n1, chol))
        };
        Ok(Self { inv, m, perm, low })
    }

    /// β̂ with N·β̂ = b ([`solve_normal`]). Errors on a size mismatch or a non-finite entry of b.
    pub fn solve(&self, b: &[f64]) -> Result<Vec<f64>, ModelCheckError> {
        let p = self.perm.len();
        check_len("solve_normal: right-hand side", p, b.len())?;
        check_finite("solve_normal: right-hand side", b)?;
        let (m, perm, inv) = (&self.m, &self.perm, &self.inv);
        // c = P·D⁻¹b.
        let c: Vec<f64> = (0..p).map(|j| b[perm[j]] * inv[perm[j]]).collect();
        // L₁·L₁ᵀ·z = c over the first r entries by two triangular solves (L₁: the leading r × r
        // block of L).
        let solve_l1 = |z: &mut [f64], r: usize| {
            for j in 0..r {
                let s: f64 = (0..j).map(|k| m[(j, k)] * z[k]).sum();
                z[j] = (z[j] - s) / m[(j, j)];
            }
            for j in (0..r).rev() {
                let s: f64 = (j + 1..r).map(|k| m[(k, j)] * z[k]).sum();
                z[j] = (z[j] - s) / m[(j, j)];
            }
        };
        let z = match &self.low {
            None => {
                // Full rank: L·Lᵀ·z = c.
                let mut z = c;
                solve_l1(&mut z, p);
                z
            }
            Some((n1, chol)) => {
                // The minimum-norm z of L·Lᵀ·z = c, (L·Lᵀ)⁺·c: with Π = I − N·(NᵀN)⁻¹·Nᵀ the
                // projection onto the span of L, z₀ = [(L₁·L₁ᵀ)⁻¹·(Π·c)₁; 0] solves L·Lᵀ·z₀ = Π·c
                // (Π·c = L·a gives (Π·c)₂ = L₂·L₁⁻¹·(Π·c)₁), and z = Π·z₀ is the solution in the
                // span of L.
                let (r, d) = (n1.nrows(), n1.ncols());
                let project = |v: &mut [f64]| {
                    let nv =
                        nalgebra::DVector::from_fn(d, |e, _| (0..r).map(|k| n1[(k, e)] * v[k]).sum::<f64>() + v[r + e]);
                    let s = chol.solve(&nv);
                    for (k, x) in v.iter_mut().enumerate().take(r) {
                        *x -= (0..d).map(|e| n1[(k, e)] * s[e]).sum::<f64>();
                    }
                    for (e, x) in v[r..].iter_mut().enumerate() {
                        *x -= s[e];
                    }
                };
                let mut z = c;
                project(&mut z);
                z[r..].fill(0.0);
                solve_l1(&mut z, r);
                project(&mut z);
                z
            }
        };
        let mut beta = vec![0.0; p];
        for (j, zj) in z.iter().enumerate() {
            beta[perm[j]] = zj * inv[perm[j]];
        }
        Ok(beta)
    }
}

/// Columns of one length stored together (column-major, `n` rows), for the products a least
/// squares of many samples and few columns needs when its design changes only by small mixes of
/// fixed columns ([`solve_normal`]): the Gram matrix CᵀC, the products Cᵀv with other columns and
/// the combinations C·β. Each is one sequential faer product, so the same inputs give the same
/// bits on any number of threads.
#[derive(Debug, Clone)]
pub struct Columns {
    m: Mat<f64>,
}

impl Columns {
    /// The columns `cols`, each of `n` values. Errors when a column's length is not `n`.
    pub fn new(n: usize, cols: &[&[f64]]) -> Result<Self, ModelCheckError> {
        for (j, c) in cols.iter().enumerate() {
            check_len(&format!("column {j}"), n, c.len())?;
        }
        Ok(Self { m: Mat::from_fn(n, cols.len(), |i, j| cols[j][i]) })
    }

    /// Number of values per column.
    pub fn rows(&self) -> usize {
        self.m.nrows()
    }

    /// Number of columns.
    pub fn count(&self) -> usize {
        self.m.ncols()
    }

    /// G = CᵀC, G_jk = Σ_i c_ij·c_ik (count × count, row-major; its lower triangle computed and
    /// mirrored).
    pub fn gram(&self) -> Vec<f64> {
        let k = self.count();
        let g = gram_of(self.m.as_ref());
        (0..k * k).map(|e| g[(e / k, e % k)]).collect()
    }

    /// Cᵀ·[v_1 … v_m]: the products Σ_i c_ij·v_i of every column j with each of `vs` (count × m,
    /// row-major). Errors when a vector's length is not the columns' length.
    pub fn t_mul(&self, vs: &[&[f64]]) -> Result<Vec<f64>, ModelCheckError> {
        let other = Columns::new(self.rows(), vs)?;
        let (k, m) = (self.count(), vs.len());
        let mut p = Mat::<f64>::zeros(k, m);
        faer::linalg::matmul::matmul(
            p.as_mut(),
            faer::Accum::Replace,
            self.m.transpose(),
            other.m.as_ref(),
            1.0,
            faer::Par::Seq,
        );
        Ok((0..k * m).map(|e| p[(e / m, e % m)]).collect())
    }

    /// The thin QR factorisation C = Q·R (Householder, faer, sequential): Q (rows × count, orthonormal
    /// columns) and R (count × count, upper triangular, row-major). ‖C·β‖ = ‖R·β‖ for every β, so
    /// R·β stands in for C·β wherever only norms and inner products of combinations matter (a
    /// compressed residual: count values in place of rows). None when there are fewer rows than
    /// columns.
    pub fn thin_qr(&self) -> Option<(Columns, Vec<f64>)> {
        let (n, k) = (self.rows(), self.count());
        if n < k {
            return None;
        }
        let qr = self.m.qr();
        let r = qr.thin_R();
        let rv = (0..k * k).map(|e| if e % k >= e / k { r[(e / k, e % k)] } else { 0.0 }).collect();
        Some((Columns { m: qr.compute_thin_Q() }, rv))
    }

    /// C·[β_1 … β_m] by one product: each β's combination (one value per row), as [`Columns::combine`]
    /// gives one. Errors when a β's length is not the number of columns.
    pub fn combine_each(&self, betas: &[&[f64]]) -> Result<Vec<Vec<f64>>, ModelCheckError> {
        for (j, b) in betas.iter().enumerate() {
            check_len(&format!("coefficients {j}"), self.count(), b.len())?;
        }
        let b = Mat::<f64>::from_fn(self.count(), betas.len(), |i, j| betas[j][i]);
        let mut out = Mat::<f64>::zeros(self.rows(), betas.len());
        faer::linalg::matmul::matmul(
            out.as_mut(),
            faer::Accum::Replace,
            self.m.as_ref(),
            b.as_ref(),
            1.0,
            faer::Par::Seq,
        );
        Ok((0..betas.len()).map(|j| out.col_as_slice(j).to_vec()).collect())
    }

    /// C·β = Σ_j β_j·c_j (one value per row). Errors when β's length is not the number of columns.
    pub fn combine(&self, beta: &[f64]) -> Result<Vec<f64>, ModelCheckError> {
        check_len("coefficients", self.count(), beta.len())?;
        let b = faer::MatRef::from_column_major_slice(beta, beta.len(), 1);
        let mut out = Mat::<f64>::zeros(self.rows(), 1);
        faer::linalg::matmul::matmul(out.as_mut(), faer::Accum::Replace, self.m.as_ref(), b, 1.0, faer::Par::Seq);
        Ok((0..self.rows()).map(|i| out[(i, 0)]).collect())
    }
}

/// The Gram matrix AᵀA of the columns of `a`: its lower triangle by one sequential faer product
/// (half the products of the full one, each entry the same sum to the bit), mirrored.
pub(crate) fn gram_of(a: faer::MatRef<'_, f64>) -> Mat<f64> {
    use faer::linalg::matmul::triangular::{matmul, BlockStructure};
    let k = a.ncols();
    let mut g = Mat::<f64>::zeros(k, k);
    matmul(
        g.as_mut(),
        BlockStructure::TriangularLower,
        faer::Accum::Replace,
        a.transpose(),
        BlockStructure::Rectangular,
        a,
        BlockStructure::Rectangular,
        1.0,
        faer::Par::Seq,
    );
    for j in 0..k {
        for i in 0..j {
            g[(i, j)] = g[(j, i)];
        }
    }
    g
}

#[cfg(test)]
mod columns_tests {
    use super::Columns;

    /// Three columns of 1 000 values against the sums written out: the Gram matrix, the products
    /// with two vectors and a combination, each within 1e-12 relative; a wrong length is an error.
    #[test]
    fn products_of_stored_columns_are_the_sums_they_stand_for() {
        let n = 1000;
        let col = |a: f64| -> Vec<f64> { (0..n).map(|i| (i as f64 * a).sin() + a).collect() };
        let cs = [col(0.1), col(0.37), col(1.3)];
        let refs: Vec<&[f64]> = cs.iter().map(|c| c.as_slice()).collect();
        let c = Columns::new(n, &refs).unwrap();
        assert_eq!((c.rows(), c.count()), (n, 3));
        let dot = |a: &[f64], b: &[f64]| a.iter().zip(b).map(|(x, y)| x * y).sum::<f64>();
        let close = |a: f64, b: f64| (a - b).abs() <= 1e-12 * a.abs().max(b.abs()).max(1.0);
        let g = c.gram();
        for j in 0..3 {
            for k in 0..3 {
                assert!(close(g[j * 3 + k], dot(&cs[j], &cs[k])));
            }
        }
        let vs = [col(0.05), col(2.0)];
        let p = c.t_mul(&[&vs[0], &vs[1]]).unwrap();
        for j in 0..3 {
            for m in 0..2 {
                assert!(close(p[j * 2 + m], dot(&cs[j], &vs[m])));
            }
        }
        let y = c.combine(&[1.0, -2.0, 0.5]).unwrap();
        for i in 0..n {
            assert!(close(y[i], cs[0][i] - 2.0 * cs[1][i] + 0.5 * cs[2][i]));
        }
        let ys = c.combine_each(&[&[1.0, -2.0, 0.5], &[0.0, 3.0, -1.0]]).unwrap();
        for i in 0..n {
            assert!(close(ys[0][i], y[i]) && close(ys[1][i], 3.0 * cs[1][i] - cs[2][i]));
        }
        assert!(c.combine_each(&[&[1.0, 2.0, 3.0], &[1.0]]).is_err());
        assert!(c.combine(&[1.0]).is_err());
        assert!(c.t_mul(&[&[1.0, 2.0]]).is_err());
    }

    /// The thin QR of four columns of 300 values, one a combination of two others: Q has
    /// orthonormal columns (QᵀQ = I to 1e-12), R is upper triangular, Q·R gives the columns back
    /// (1e-12 of their largest value) and ‖R·β‖ = ‖C·β‖ for a β (1e-12 relative); fewer rows than
    /// columns give None.
    #[test]
    fn thin_qr_of_stored_columns_is_an_isometry() {
        let n = 300;
        let col = |a: f64| -> Vec<f64> { (0..n).map(|i| (i as f64 * a).sin() * (1.0 + a) + a).collect() };
        let mut cs = vec![col(0.1), col(0.37), col(1.3)];
        cs.push(cs[0].iter().zip(&cs[2]).map(|(a, b)| 2.0 * a - b).collect());
        let refs: Vec<&[f64]> = cs.iter().map(|c| c.as_slice()).collect();
        let c = Columns::new(n, &refs).unwrap();
        let (q, r) = c.thin_qr().unwrap();
        assert_eq!((q.rows(), q.count(), r.len()), (n, 4, 16));
        let g = q.gram();
        for j in 0..4 {
            for k in 0..4 {
                let e = if j == k { 1.0 } else { 0.0 };
                assert!((g[j * 4 + k] - e).abs() <= 1e-12, "QᵀQ[{j},{k}] = {}", g[j * 4 + k]);
                if k < j {
                    assert_eq!(r[j * 4 + k], 0.0);
                }
            }
        }
        let top = cs.iter().flatten().fold(0.0_f64, |m, v| m.max(v.abs()));
        for k in 0..4 {
            let back = q.combine(&(0..4).map(|j| r[j * 4 + k]).collect::<Vec<f64>>()).unwrap();
            assert!(back.iter().zip(&cs[k]).all(|(a, b)| (a - b).abs() <= 1e-12 * top), "column {k}");
        }
        let beta = [0.3, -1.1, 2.0, 0.7];
        let cb: f64 = c.combine(&beta).unwrap().iter().map(|v| v * v).sum::<f64>().sqrt();
        let rb: f64 = (0..4).map(|j| (0..4).map(|k| r[j * 4 + k] * beta[k]).sum::<f64>().powi(2)).sum::<f64>().sqrt();
        assert!((cb - rb).abs() <= 1e-12 * cb, "{cb} vs {rb}");
        let short = Columns::new(3, &[&[1.0, 2.0, 3.0], &[0.0, 1.0, 0.0], &[1.0, 1.0, 1.0], &[2.0, 0.0, 1.0]]).unwrap();
        assert!(short.thin_qr().is_none());
    }
}

#[cfg(test)]
mod normal_tests {
    use super::solve_normal;

    /// The rank [`super::NormalFactor`] keeps is the rank at the cut from the power iterations run
    /// to their end, whether it skipped them, ended them early ([`super::largest_eigenvalue_until`])
    /// or ran them out. 300 random Gram matrices: p = 12–40 columns on 3p samples,
    /// families of strongly correlated columns (λ_max of the scaled matrix from about 1 to p/2),
    /// and one to three near-dependent columns whose squared distance from the others' span, as a
    /// fraction of their norm, is log-uniform over 10⁻¹⁴–10⁻⁸: across the band [10⁻¹¹·1,
    /// 10⁻¹¹·Gershgorin] where the rank depends on λ_max. Reference: faer's pivoted Cholesky of the
    /// same scaled matrix cut at [`super::DEPENDENT_PIVOT`] × [`super::largest_eigenvalue`], as
    /// before the power iterations were skipped. At least 10 draws must land in the band (the
    /// branch that runs them) and at least 10 outside it with a dependent column cut (the branch
    /// that skips them).
    #[test]
    fn the_rank_kept_is_the_rank_at_the_power_iterations_cut() {
        use faer::dyn_stack::{MemBuffer, MemStack};
        use faer::linalg::cholesky::llt_pivoting::factor::{cholesky_in_place, cholesky_in_place_scratch};
        use rand::{Rng, SeedableRng};
        use rand_distr::{Distribution, StandardNormal};
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(2026);
        let (mut in_band, mut skipped_cut) = (0, 0);
        for draw in 0..300 {
            let p = rng.gen_range(12..=40usize);
            let n = 3 * p;
            let normal = |r: &mut rand_chacha::ChaCha8Rng| -> f64 { StandardNormal.sample(r) };
            let mut cols: Vec<Vec<f64>> = Vec::new();
            // Families of correlated columns: a shared part plus a little of their own.
            while cols.len() < p - 3 {
                let size = 1 + (normal(&mut rng).abs() * 4.0) as usize;
                let shared: Vec<f64> = (0..n).map(|_| normal(&mut rng)).collect();
                let own = 10f64.powf(-2.0 * normal(&mut rng).abs());
                for _ in 0..size.min(p - 3 - cols.len()) {
                    cols.push(shared.iter().map(|s| s + own * normal(&mut rng)).collect());
                }
            }
            let near = 1 + rng.gen_range(0..3usize);
            while cols.len() < p {
                let comb: Vec<f64> = (0..n).map(|i| cols.iter().take(5).map(|c| c[i]).sum::<f64>()).collect();
                let noise: Vec<f64> = (0..n).map(|_| normal(&mut rng)).collect();
                let norm = |v: &[f64]| v.iter().map(|x| x * x).sum::<f64>().sqrt();
                let frac = 10f64.powf(-14.0 + 6.0 * rng.gen::<f64>());
                let delta = frac.sqrt() * norm(&comb) / norm(&noise);
                cols.push(comb.iter().zip(&noise).map(|(c, e)| c + delta * e).collect());
                if cols.len() >= p - 3 + near {
                    break;
                }
            }
            let p = cols.len();
            let dot = |a: &[f64], b: &[f64]| a.iter().zip(b).map(|(x, y)| x * y).sum::<f64>();
            let gram: Vec<f64> = (0..p * p).map(|k| dot(&cols[k / p], &cols[k % p])).collect();
            // The reference: the cut at the power iterations' λ_max.
            let inv: Vec<f64> = (0..p).map(|j| 1.0 / gram[j * p + j].sqrt()).collect();
            let scaled = faer::Mat::<f64>::from_fn(p, p, |i, j| gram[i * p + j] * inv[i] * inv[j]);
            let mut m = scaled.clone();
            let (mut perm, mut perm_inv) = (vec![0usize; p], vec![0usize; p]);
            let par = faer::Par::Seq;
            let mut buf = MemBuffer::new(cholesky_in_place_scratch::<usize, f64>(p, par, Default::default()));
            let (info, _) = cholesky_in_place(
                m.as_mut(),
                &mut perm,
                &mut perm_inv,
                par,
                MemStack::new(&mut buf),
                Default::default(),
            )
            .unwrap();
            let kept = |cut: f64| (0..info.rank).take_while(|&j| m[(j, j)] * m[(j, j)] >= cut).count();
            let want = kept(super::DEPENDENT_PIVOT * super::largest_eigenvalue(&scaled));
            let factor = super::NormalFactor::new(&gram, p).unwrap();
            let got = factor.low.as_ref().map_or(p, |(n1, _)| n1.nrows());
            assert_eq!(got, want, "draw {draw}: p {p}, rank {got} kept, {want} at the power iterations' cut");
            let bound = super::row_sum_bound(&scaled) * (1.0 + 1e-12);
            if kept(super::DEPENDENT_PIVOT) != kept(super::DEPENDENT_PIVOT * bound) {
                in_band += 1;
            } else if want < p {
                skipped_cut += 1;
            }
        }
        assert!(in_band >= 10 && skipped_cut >= 10, "{in_band} draws in the band, {skipped_cut} cut without it");
        eprintln!(
            "rank decided by the power iterations in {in_band} of 300 draws; a cut without them in {skipped_cut}"
        );
    }

    /// y = 2·x₁ − 3·x₂ exactly on 50 samples, with a third column equal to x₁ + x₂ (dependent):
    /// the minimum-norm solution (in the columns scaled to unit norm, z_j = ‖x_j‖·β_j) reproduces y
    /// (residual ≤ 1e-9 of |y|) and has no component along the dependency, z ⊥ (‖x₁‖, ‖x₂‖, −‖x₃‖).
    #[test]
    fn normal_equations_reproduce_an_exact_fit_with_a_dependent_column() {
        let n = 50;
        let x1: Vec<f64> = (0..n).map(|i| (i as f64 * 0.37).sin()).collect();
        let x2: Vec<f64> = (0..n).map(|i| (i as f64 * 0.11).cos() * 1e3).collect();
        let x3: Vec<f64> = x1.iter().zip(&x2).map(|(a, b)| a + b).collect();
        let cols = [x1, x2, x3];
        let y: Vec<f64> = (0..n).map(|i| 2.0 * cols[0][i] - 3.0 * cols[1][i]).collect();
        let dot = |a: &[f64], b: &[f64]| a.iter().zip(b).map(|(x, y)| x * y).sum::<f64>();
        let gram: Vec<f64> = (0..9).map(|k| dot(&cols[k / 3], &cols[k % 3])).collect();
        let b: Vec<f64> = cols.iter().map(|c| dot(c, &y)).collect();
        let beta = solve_normal(&gram, &b).unwrap();
        let fit: Vec<f64> = (0..n).map(|i| (0..3).map(|j| beta[j] * cols[j][i]).sum::<f64>()).collect();
        let err = fit.iter().zip(&y).map(|(a, b)| (a - b).powi(2)).sum::<f64>().sqrt();
        assert!(err <= 1e-9 * dot(&y, &y).sqrt(), "residual {err}, β {beta:?}");
        let d2: Vec<f64> = (0..3).map(|j| gram[j * 3 + j]).collect();
        let along = d2[0] * beta[0] + d2[1] * beta[1] - d2[2] * beta[2];
        let scale = (0..3).map(|j| d2[j] * beta[j].abs()).sum::<f64>();
        assert!(along.abs() <= 1e-9 * scale, "{beta:?}: component {along} of {scale}");
    }

    /// Several dependencies and a target off the columns' span: 9 columns of very different
    /// scales, 3 of them combinations of the others, y with a part off their span. β̂ is the
    /// minimum-norm least squares in the unit-norm columns, z = (X·D⁻¹)⁺·y from nalgebra's SVD
    /// (singular values below 1e-9 of the largest cut), β̂ = D⁻¹z, to 1e-8 of ‖z‖.
    #[test]
    fn normal_equations_with_dependencies_give_the_minimum_norm_least_squares() {
        let n = 80;
        let scales = [1.0, 1e3, 1e-2, 5.0, 1e-4, 30.0];
        let mut cols: Vec<Vec<f64>> = scales
            .iter()
            .enumerate()
            .map(|(j, s)| (0..n).map(|i| s * ((i as f64) * (0.13 + 0.071 * j as f64) + j as f64).sin()).collect())
            .collect();
        for (a, b, wa, wb) in [(0, 1, 2.0, -0.5), (2, 3, 1.0, 3.0), (4, 0, -1.0, 1e-3)] {
            let c: Vec<f64> = (0..n).map(|i| wa * cols[a][i] + wb * cols[b][i]).collect();
            cols.push(c);
        }
        let p = cols.len();
        let y: Vec<f64> = (0..n).map(|i| cols[1][i] - 4.0 * cols[3][i] + (i as f64 * 1.91).cos() * 7.0).collect();
        let dot = |a: &[f64], b: &[f64]| a.iter().zip(b).map(|(x, y)| x * y).sum::<f64>();
        let gram: Vec<f64> = (0..p * p).map(|k| dot(&cols[k / p], &cols[k % p])).collect();
        let b: Vec<f64> = cols.iter().map(|c| dot(c, &y)).collect();
        let beta = solve_normal(&gram, &b).unwrap();
        let d: Vec<f64> = (0..p).map(|j| gram[j * p + j].sqrt()).collect();
        let xs = nalgebra::DMatrix::from_fn(n, p, |i, j| cols[j][i] / d[j]);
        let z = xs.svd(true, true).solve(&nalgebra::DVector::from_vec(y.clone()), 1e-9 * 3.0).unwrap();
        let zn = z.norm();
        for j in 0..p {
            assert!((beta[j] * d[j] - z[j]).abs() <= 1e-8 * zn, "column {j}: {} vs {}", beta[j] * d[j], z[j]);
        }
    }

    /// Independent columns of very different scales: y = 2·x₁ − 3·x₂ + 0.5·x₃
    /// plus a part orthogonal to nothing in particular; β equals the least squares of the
    /// columns themselves (faer's SVD fit, [`super::fit_signature`]) to 1e-9 relative.
    #[test]
    fn normal_equations_of_independent_columns_give_the_least_squares() {
        let n = 200;
        let x1: Vec<f64> = (0..n).map(|i| (i as f64 * 0.37).sin()).collect();
        let x2: Vec<f64> = (0..n).map(|i| (i as f64 * 0.11).cos() * 1e3).collect();
        let x3: Vec<f64> = (0..n).map(|i| (i as f64 / n as f64).powi(2) * 1e-4).collect();
        let cols = [x1, x2, x3];
        let y: Vec<f64> =
            (0..n).map(|i| 2.0 * cols[0][i] - 3.0 * cols[1][i] + 0.5 * cols[2][i] + (i as f64 * 1.7).cos()).collect();
        let dot = |a: &[f64], b: &[f64]| a.iter().zip(b).map(|(x, y)| x * y).sum::<f64>();
        let gram: Vec<f64> = (0..9).map(|k| dot(&cols[k / 3], &cols[k % 3])).collect();
        let b: Vec<f64> = cols.iter().map(|c| dot(c, &y)).collect();
        let beta = solve_normal(&gram, &b).unwrap();
        let svd = super::fit_signature(&y, &cols, &super::Sigma::Unknown).unwrap();
        for (a, e) in beta.iter().zip(&svd.coefficients) {
            assert!((a - e).abs() <= 1e-9 * e.abs().max(1e-3), "{beta:?} vs {:?}", svd.coefficients);
        }
    }
}
