//! Orthonormal bases of weighted design columns by Householder QR (faer, run sequentially so that
//! the bits do not depend on the number of threads), for the searches of the model-check loop:
//!
//! - [`OrthoBase`]: the columns that do not change with a nonlinear parameter (offsets, fitted
//!   shapes) factored once; every value of the parameter then costs only the projection of its
//!   own few columns (variable projection, Golub & Pereyra 1973, SIAM J. Numer. Anal. 10:413):
//!   min_β ‖W(y − Fβ_F − C(θ)β_C)‖² = min_β_C ‖P(Wy) − P(WC(θ))β_C‖², P = I − QQᵀ.
//! - [`nested_rss`]: the weighted residual sums of squares of nested column sets (fixed columns
//!   plus the first k columns of a series, k = 0..K) from one QR of the projected series and data
//!   (Golub & Van Loan, Matrix Computations, 4th ed., §5.3: the last column of R of [A | y] holds
//!   Qᵀy), which is what an information criterion needs to choose a series' order.

use super::lsq::Basis;
use super::{check_finite, check_len, ModelCheckError};
use faer::dyn_stack::{MemBuffer, MemStack};
use faer::linalg::householder;
use faer::linalg::matmul::matmul;
use faer::linalg::qr;
use faer::{Accum, Conj, Mat, Par};

/// Relative size of a pivot of the column-pivoted QR below which a (unit-norm) column counts as
/// dependent on the others.
pub const RANK_TOLERANCE: f64 = 1e-10;

/// An orthonormal basis Q (n × rank) of the span of weighted columns W·c_j.
#[derive(Debug, Clone)]
pub struct OrthoBase {
    q: Mat<f64>,
}

impl OrthoBase {
    /// The basis of the columns `cols` (each n values) weighted by `w` (n values, 1/σ): columns
    /// scaled to unit norm, Householder QR with column pivoting, the pivots above
    /// [`RANK_TOLERANCE`] × the largest kept (all-zero columns are skipped).
    pub fn new(cols: &[Vec<f64>], w: &[f64]) -> Result<OrthoBase, ModelCheckError> {
        check_finite("weights", w)?;
        Ok(match PivotedQr::of(cols, w)? {
            Some(f) => OrthoBase { q: thin_q(f.a, &f.coeff, f.rank) },
            None => OrthoBase { q: Mat::zeros(w.len(), 0) },
        })
    }

    /// Number of samples n.
    pub fn nrows(&self) -> usize {
        self.q.nrows()
    }

    /// Rank of the weighted columns (number of basis vectors).
    pub fn rank(&self) -> usize {
        self.q.ncols()
    }

    /// Removes from every column of `m` (n × k) its part in the span: m − Q(Qᵀm), twice ("twice is
    /// enough", Giraud et al. 2005) for orthogonality to rounding.
    pub fn project_out(&self, m: &mut Mat<f64>) {
        if self.rank() == 0 || m.ncols() == 0 {
            return;
        }
        let mut c = Mat::<f64>::zeros(self.rank(), m.ncols());
        for _ in 0..2 {
            matmul(c.as_mut(), Accum::Replace, self.q.transpose(), m.as_ref(), 1.0, Par::Seq);
            matmul(m.as_mut(), Accum::Add, self.q.as_ref(), c.as_ref(), -1.0, Par::Seq);
        }
    }

    /// Weighted columns `cols` (each n values, times `w`) with their part in the span removed, as an
    /// n × k matrix.
    pub fn projected(&self, cols: &[Vec<f64>], w: &[f64]) -> Mat<f64> {
        let mut m = Mat::<f64>::from_fn(w.len(), cols.len(), |i, j| cols[j][i] * w[i]);
        self.project_out(&mut m);
        m
    }

    /// [`OrthoBase::projected`] as columns; a column with less than 1e-9 of its weighted norm left
    /// is dependent on the span and returned as zeros.
    pub fn project_columns(&self, cols: &[Vec<f64>], w: &[f64]) -> Vec<Vec<f64>> {
        let m = self.projected(cols, w);
        cols.iter()
            .enumerate()
            .map(|(j, c)| {
                let n0 = c.iter().zip(w).map(|(x, w)| (x * w).powi(2)).sum::<f64>().sqrt();
                let v: Vec<f64> = (0..w.len()).map(|i| m[(i, j)]).collect();
                let n1 = v.iter().map(|x| x * x).sum::<f64>().sqrt();
                if n0 > 0.0 && n1 > 1e-9 * n0 {
                    v
                } else {
                    vec![0.0; w.len()]
                }
            })
            .collect()
    }

    /// The weighted sum of squares that `cols` explain beyond the span: ‖P_C·r‖² with r =
    /// `target` (weighted, already projected off the span) and C the projected weighted columns
    /// ([`OrthoBase::project_columns`], orthonormalised by modified Gram–Schmidt). The RSS of the
    /// joint fit is ‖r‖² minus this.
    pub fn explained(&self, target: &[f64], cols: &[Vec<f64>], w: &[f64]) -> f64 {
        let mut b = Basis::default();
        for v in self.project_columns(cols, w).into_iter().filter(|v| v.iter().any(|x| *x != 0.0)) {
            b.push(v);
        }
        b.q.iter().map(|q| q.iter().zip(target).map(|(a, b)| a * b).sum::<f64>().powi(2)).sum()
    }

    /// A vector (n values, times `w`) with its part in the span removed.
    pub fn project_vector(&self, y: &[f64], w: &[f64]) -> Vec<f64> {
        let m = self.projected(&[y.to_vec()], w);
        (0..w.len()).map(|i| m[(i, 0)]).collect()
    }
}

/// Weighted linear least squares for designs with many columns: β̂ = argmin Σ_i (w_i·(y_i −
/// Σ_j X_ij β_j))² by Householder QR with column pivoting of the unit-norm weighted columns
/// (faer, sequential). Columns whose pivot is below [`RANK_TOLERANCE`] × the largest are dependent
/// on the others and get β_j = 0 (a basic solution; all-zero columns too). Returns (β, y − Xβ).
/// Costs about 2np² flops against the SVD's ≈ 4np² + 8p³ (`fit_signature`), which also gives
/// standard errors and the condition number; use this one where only the fit is needed.
pub fn lstsq_qr(y: &[f64], cols: &[Vec<f64>], w: &[f64]) -> Result<(Vec<f64>, Vec<f64>), ModelCheckError> {
    let n = w.len();
    check_len("y", n, y.len())?;
    check_finite("y", y)?;
    let mut beta = vec![0.0; cols.len()];
    if let Some(PivotedQr { a, coeff, perm, keep, rank }) = PivotedQr::of(cols, w)? {
        let r = Mat::<f64>::from_fn(rank, rank, |i, j| if i <= j { a[(i, j)] } else { 0.0 });
        let q = thin_q(a, &coeff, rank);
        let mut qty = vec![0.0; rank];
        for (k, v) in qty.iter_mut().enumerate() {
            *v = (0..n).map(|i| q[(i, k)] * y[i] * w[i]).sum();
        }
        // Back substitution R z = Qᵀ(Wy); z_k belongs to the pivoted column perm[k].
        let mut z = vec![0.0; rank];
        for i in (0..rank).rev() {
            let s: f64 = qty[i] - (i + 1..rank).map(|j| r[(i, j)] * z[j]).sum::<f64>();
            z[i] = s / r[(i, i)];
        }
        for (k, zk) in z.iter().enumerate() {
            let (j, norm) = keep[perm[k]];
            beta[j] = zk / norm;
        }
    }
    let residual: Vec<f64> = (0..n)
        .map(|i| y[i] - cols.iter().zip(&beta).filter(|(_, b)| **b != 0.0).map(|(c, b)| c[i] * b).sum::<f64>())
        .collect();
    Ok((beta, residual))
}

/// A Householder QR with column pivoting of the unit-norm weighted columns W·c_j/‖W·c_j‖ (all-zero
/// columns left out), in place as faer stores it, with the numerical rank: the pivots above
/// [`RANK_TOLERANCE`] × the largest.
struct PivotedQr {
    /// R on and above the diagonal, the Householder essentials below it.
    a: Mat<f64>,
    /// Block Householder coefficients.
    coeff: Mat<f64>,
    /// Column k of the factorisation is kept column `perm[k]`.
    perm: Vec<usize>,
    /// Kept columns: (index into the input columns, weighted norm).
    keep: Vec<(usize, f64)>,
    /// Numerical rank.
    rank: usize,
}

impl PivotedQr {
    /// The factorisation of `cols` weighted by `w`, or `None` when no column is nonzero (or n = 0).
    fn of(cols: &[Vec<f64>], w: &[f64]) -> Result<Option<PivotedQr>, ModelCheckError> {
        let n = w.len();
        let mut keep: Vec<(usize, f64)> = Vec::new();
        for (j, c) in cols.iter().enumerate() {
            check_len(&format!("column {j}"), n, c.len())?;
            check_finite(&format!("column {j}"), c)?;
            let norm = c.iter().zip(w).map(|(x, w)| (x * w).powi(2)).sum::<f64>().sqrt();
            if norm > 0.0 {
                keep.push((j, norm));
            }
        }
        let p = keep.len();
        if p == 0 || n == 0 {
            return Ok(None);
        }
        let mut a = Mat::<f64>::from_fn(n, p, |i, k| cols[keep[k].0][i] * w[i] / keep[k].1);
        let size = n.min(p);
        let bs = qr::no_pivoting::factor::recommended_block_size::<f64>(n, p);
        let mut coeff = Mat::<f64>::zeros(bs, size);
        let mut perm = vec![0usize; p];
        let mut perm_inv = vec![0usize; p];
        let mut mem = MemBuffer::new(qr::col_pivoting::factor::qr_in_place_scratch::<usize, f64>(
            n,
            p,
            bs,
            Par::Seq,
            Default::default(),
        ));
        qr::col_pivoting::factor::qr_in_place(
            a.as_mut(),
            coeff.as_mut(),
            &mut perm,
            &mut perm_inv,
            Par::Seq,
            MemStack::new(&mut mem),
            Default::default(),
        );
        let d0 = a[(0, 0)].abs();
        let rank = (0..size).take_while(|&j| a[(j, j)].abs() > RANK_TOLERANCE * d0).count();
        Ok(Some(PivotedQr { a, coeff, perm, keep, rank }))
    }
}

/// The first `rank` columns of Q of a Householder QR stored in place in `a` (essentials below the
/// diagonal, unit diagonal implied) with block coefficients `coeff`.
fn thin_q(mut a: Mat<f64>, coeff: &Mat<f64>, rank: usize) -> Mat<f64> {
    let (n, p) = a.shape();
    for j in 0..p.min(n) {
        for i in 0..=j {
            a[(i, j)] = if i == j { 1.0 } else { 0.0 };
        }
    }
    for j in n.min(p)..p {
        for i in 0..n {
            a[(i, j)] = 0.0;
        }
    }
    let size = n.min(p);
    let basis = a.get(.., ..size);
    let mut q = Mat::<f64>::from_fn(n, rank, |i, j| if i == j { 1.0 } else { 0.0 });
    let mut mem = MemBuffer::new(householder::apply_block_householder_sequence_on_the_left_in_place_scratch::<f64>(
        n,
        coeff.nrows(),
        rank,
    ));
    householder::apply_block_householder_sequence_on_the_left_in_place_with_conj(
        basis,
        coeff.as_ref(),
        Conj::No,
        q.as_mut(),
        Par::Seq,
        MemStack::new(&mut mem),
    );
    q
}

/// Residual sums of squares of nested column sets ([`nested_rss`]).
#[derive(Debug, Clone, PartialEq)]
pub struct NestedRss {
    /// rss[m]: the weighted RSS with the base and the series columns `used[..m]` (rss[0]: base only).
    pub rss: Vec<f64>,
    /// Indices of the series columns taken, in order.
    pub used: Vec<usize>,
}

/// Checks the inputs of [`nested_rss`] and [`greedy_rss`] (one value per sample in `y`, every series
/// column and the base, all finite) and returns the number of samples n.
fn check_series(y: &[f64], w: &[f64], base: &OrthoBase, series: &[Vec<f64>]) -> Result<usize, ModelCheckError> {
    let n = w.len();
    check_len("y", n, y.len())?;
    check_finite("y", y)?;
    for (j, c) in series.iter().enumerate() {
        check_len(&format!("series column {j}"), n, c.len())?;
        check_finite(&format!("series column {j}"), c)?;
    }
    check_len("base rows", n, base.nrows())?;
    Ok(n)
}

/// Weighted residual sums of squares Σ(w_i·r_i)² of `y` after least squares on the span of
/// `base` plus the first columns of `series`, in the series' order (no pivoting): a series column
/// that the base alone spans (less than 1e-9 of its weighted norm left after the projection, or
/// all zero) adds nothing and is skipped; the nesting stops before the first column dependent on
/// the base and the series columns before it (its part left ≤ 1e-9), so that the caller cannot
/// choose an order these samples cannot determine.
pub fn nested_rss(y: &[f64], w: &[f64], base: &OrthoBase, series: &[Vec<f64>]) -> Result<NestedRss, ModelCheckError> {
    let n = check_series(y, w, base, series)?;
    // The series columns the base does not span (projected, unit weighted norm before), then W·y.
    let projected = base.project_columns(series, w);
    let used: Vec<usize> = (0..series.len()).filter(|&j| projected[j].iter().any(|v| *v != 0.0)).collect();
    let norms: Vec<f64> =
        series.iter().map(|c| c.iter().zip(w).map(|(x, w)| (x * w).powi(2)).sum::<f64>().sqrt()).collect();
    let k = used.len();
    let yp = base.project_vector(y, w);
    let mut m =
        Mat::<f64>::from_fn(n, k + 1, |i, j| if j < k { projected[used[j]][i] / norms[used[j]] } else { yp[i] });
    let rss0: f64 = yp.iter().map(|v| v * v).sum();
    let mut out = NestedRss { rss: vec![rss0], used: Vec::new() };
    if k == 0 || n <= k {
        return Ok(out);
    }
    let bs = qr::no_pivoting::factor::recommended_block_size::<f64>(n, k + 1);
    let mut coeff = Mat::<f64>::zeros(bs, (k + 1).min(n));
    let mut mem =
        MemBuffer::new(qr::no_pivoting::factor::qr_in_place_scratch::<f64>(n, k + 1, bs, Par::Seq, Default::default()));
    qr::no_pivoting::factor::qr_in_place(
        m.as_mut(),
        coeff.as_mut(),
        Par::Seq,
        MemStack::new(&mut mem),
        Default::default(),
    );
    // R[j][j]: the part of unit column j left after the base and the columns before it;
    // R[j][k] = q_jᵀ(Wy).
    let mut rss = rss0;
    for j in 0..k {
        if m[(j, j)].abs() <= 1e-9 {
            break;
        }
        rss = (rss - m[(j, k)].powi(2)).max(0.0);
        out.rss.push(rss);
        out.used.push(used[j]);
    }
    Ok(out)
}

/// Weighted residual sums of squares along a greedy forward selection of `series` columns on
/// top of `base` (orthogonal matching pursuit; Pati, Rezaiifar & Krishnaprasad 1993): at each
/// step the column whose part left after the base and the columns already taken explains the
/// most of the current weighted residual, (aᵀr)²/‖a‖², enters. Returns the path as a
/// [`NestedRss`] (`used` in the order taken, `rss[m]` after the first m). For series whose signal
/// sits in a few terms anywhere in the series (rail waviness in a cosine series of the
/// accelerations), where nesting by degree would charge every term below it. The path stops when
/// no column is left with more than 1e-9 of its weighted norm outside the span, or when the best
/// column explains less than `stop` × the current mean square (rss/n) for 20 steps in a row.
/// Sequential: the same bits on any number of threads.
pub fn greedy_rss(
    y: &[f64],
    w: &[f64],
    base: &OrthoBase,
    series: &[Vec<f64>],
    stop: f64,
) -> Result<NestedRss, ModelCheckError> {
    let n = check_series(y, w, base, series)?;
    let k = series.len();
    // Projected weighted columns at unit norm (before the projection; a column the base spans is
    // zero and never taken).
    let mut a = base.projected(series, w);
    let mut left = vec![0.0; k];
    for j in 0..k {
        let n0 = series[j].iter().zip(w).map(|(x, w)| (x * w).powi(2)).sum::<f64>().sqrt();
        let n1 = (0..n).map(|i| a[(i, j)].powi(2)).sum::<f64>().sqrt();
        if n0 > 0.0 && n1 > 1e-9 * n0 {
            for i in 0..n {
                a[(i, j)] /= n0;
            }
            left[j] = (n1 / n0).powi(2);
        } else {
            left[j] = 0.0;
        }
    }
    let mut r = base.project_vector(y, w);
    let mut rss: f64 = r.iter().map(|v| v * v).sum();
    let mut out = NestedRss { rss: vec![rss], used: Vec::new() };
    // c_j = a_jᵀr (r stays orthogonal to the columns taken, so this is the part left's product).
    let mut corr = Mat::<f64>::zeros(k, 1);
    let rm = Mat::<f64>::from_fn(n, 1, |i, _| r[i]);
    matmul(corr.as_mut(), Accum::Replace, a.transpose(), rm.as_ref(), 1.0, Par::Seq);
    let mut taken = vec![false; k];
    let mut q: Vec<Vec<f64>> = Vec::new();
    let mut weak = 0;
    let mut d = Mat::<f64>::zeros(k, 1);
    while out.used.len() < k.min(n) {
        let mut best: Option<(usize, f64)> = None;
        for j in 0..k {
            if taken[j] || left[j] <= 1e-12 {
                continue;
            }
            let sc = corr[(j, 0)].powi(2) / left[j];
            if best.is_none_or(|(_, b)| sc > b) {
                best = Some((j, sc));
            }
        }
        let Some((j, _)) = best else { break };
        taken[j] = true;
        // The part of column j outside the columns taken (twice, for orthogonality to rounding).
        let mut v: Vec<f64> = (0..n).map(|i| a[(i, j)]).collect();
        for _ in 0..2 {
            for qk in &q {
                let dot: f64 = qk.iter().zip(&v).map(|(x, y)| x * y).sum();
                for (vi, qi) in v.iter_mut().zip(qk) {
                    *vi -= dot * qi;
                }
            }
        }
        let norm = v.iter().map(|x| x * x).sum::<f64>().sqrt();
        if norm <= 1e-9 {
            left[j] = 0.0;
            continue;
        }
        v.iter_mut().for_each(|x| *x /= norm);
        let qr_: f64 = v.iter().zip(&r).map(|(x, y)| x * y).sum();
        for (ri, vi) in r.iter_mut().zip(&v) {
            *ri -= qr_ * vi;
        }
        let mean_sq = rss / n as f64;
        rss = (rss - qr_ * qr_).max(0.0);
        out.rss.push(rss);
        out.used.push(j);
        // Update every column's part left and its product with the residual: d_j = a_jᵀv.
        let vm = Mat::<f64>::from_fn(n, 1, |i, _| v[i]);
        matmul(d.as_mut(), Accum::Replace, a.transpose(), vm.as_ref(), 1.0, Par::Seq);
        for jj in 0..k {
            left[jj] = (left[jj] - d[(jj, 0)].powi(2)).max(0.0);
            corr[(jj, 0)] -= d[(jj, 0)] * qr_;
        }
        q.push(v);
        weak = if qr_ * qr_ < stop * mean_sq { weak + 1 } else { 0 };
        if weak >= 20 {
            break;
        }
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The span of (1, x, 2x + 1) on 6 points has rank 2; projecting x² off it leaves x² minus its
    /// least-squares line, and nested RSS of y = 1 + x + 3x² − x³ on the base {1, x} with the series
    /// (x², x³, x⁴) is (RSS of the line fit, RSS of the quadratic fit, 0, 0): checked against
    /// the normal equations solved independently (nalgebra-free Gauss elimination on 3×3).
    #[test]
    fn basis_rank_projection_and_nested_rss() {
        let x: Vec<f64> = (0..6).map(|i| i as f64 * 0.3 - 0.5).collect();
        let one = vec![1.0; 6];
        let dep: Vec<f64> = x.iter().map(|v| 2.0 * v + 1.0).collect();
        let w = vec![1.0; 6];
        let b = OrthoBase::new(&[one.clone(), x.clone(), dep, vec![0.0; 6]], &w).unwrap();
        assert_eq!(b.rank(), 2);
        let y: Vec<f64> = x.iter().map(|v| 1.0 + v + 3.0 * v * v - v.powi(3)).collect();
        let pw = |k: i32| x.iter().map(|v| v.powi(k)).collect::<Vec<f64>>();
        let nr = nested_rss(&y, &w, &b, &[pw(2), pw(3), pw(4)]).unwrap();
        assert_eq!(nr.used, vec![0, 1, 2]);
        let rss = nr.rss;
        // Independent: least squares by the normal equations of [1, x, x²].
        let fit = |cols: &[Vec<f64>]| -> f64 {
            let p = cols.len();
            let mut a = vec![vec![0.0; p + 1]; p];
            for r in 0..p {
                for c in 0..p {
                    a[r][c] = cols[r].iter().zip(&cols[c]).map(|(u, v)| u * v).sum();
                }
                a[r][p] = cols[r].iter().zip(&y).map(|(u, v)| u * v).sum();
            }
            for i in 0..p {
                for r in 0..p {
                    if r != i {
                        let f = a[r][i] / a[i][i];
                        for c in 0..=p {
                            a[r][c] -= f * a[i][c];
                        }
                    }
                }
            }
            let beta: Vec<f64> = (0..p).map(|i| a[i][p] / a[i][i]).collect();
            (0..6).map(|i| (y[i] - (0..p).map(|j| beta[j] * cols[j][i]).sum::<f64>()).powi(2)).sum()
        };
        let r1 = fit(&[one.clone(), x.clone()]);
        let r2 = fit(&[one.clone(), x.clone(), pw(2)]);
        assert!((rss[0] - r1).abs() <= 1e-10 * r1, "{} {r1}", rss[0]);
        assert!((rss[1] - r2).abs() <= 1e-10 * r1, "{} {r2}", rss[1]);
        // An exact fit: rounding only (1e-12 of the first RSS).
        assert!(rss[2] <= 1e-12 * rss[0] && rss[3] <= 1e-12 * rss[0], "{rss:?}");
        // A series column the base spans is skipped; one dependent on the series before it stops
        // the nesting.
        let nr = nested_rss(&y, &w, &b, &[pw(1), pw(2), pw(2), pw(3)]).unwrap();
        assert_eq!(nr.used, vec![1]);
        assert!((nr.rss[1] - r2).abs() <= 1e-10 * r1);
        // Projection: what is left of x² is orthogonal to 1 and x.
        let m = b.projected(&[pw(2)], &w);
        let dot = |a: &[f64]| (0..6).map(|i| a[i] * m[(i, 0)]).sum::<f64>();
        assert!(dot(&one).abs() < 1e-14 && dot(&x).abs() < 1e-14);
    }

    /// The QR least squares agrees with the SVD one (`fit_signature`) on a weighted cubic with a
    /// duplicated and an all-zero column: the same fitted values to 1e-12, and the duplicate's
    /// pair of coefficients sums to the SVD's pair sum.
    #[test]
    fn qr_least_squares_matches_the_svd_fit() {
        use crate::modelcheck::{fit_signature, Sigma};
        let x: Vec<f64> = (0..40).map(|i| (i as f64 * 0.37).sin() + 0.01 * i as f64).collect();
        let y: Vec<f64> =
            x.iter().enumerate().map(|(i, v)| 0.3 - 1.2 * v + 0.5 * v.powi(3) + 0.01 * ((i * 7) % 5) as f64).collect();
        let sig: Vec<f64> = (0..40).map(|i| 0.5 + 0.02 * i as f64).collect();
        let w: Vec<f64> = sig.iter().map(|s| 1.0 / s).collect();
        let cols = vec![
            vec![1.0; 40],
            x.clone(),
            x.iter().map(|v| v * v).collect(),
            x.iter().map(|v| v.powi(3)).collect(),
            x.clone(),
            vec![0.0; 40],
        ];
        let (b, r) = lstsq_qr(&y, &cols, &w).unwrap();
        let f = fit_signature(&y, &cols, &Sigma::PerSample(sig)).unwrap();
        for i in 0..40 {
            assert!((r[i] - f.residual[i]).abs() < 1e-12, "{i}: {} {}", r[i], f.residual[i]);
        }
        assert!((b[1] + b[4] - f.coefficients[1] - f.coefficients[4]).abs() < 1e-10);
        assert_eq!(b[5], 0.0);
        assert!((b[0] - f.coefficients[0]).abs() < 1e-10 && (b[3] - f.coefficients[3]).abs() < 1e-10);
    }

    /// On a larger design (2 000 samples, 3 offsets, 300 series columns cos(k·x) with the blocked
    /// QR paths of faer) the nested RSS at 50 and 150 columns equals the RSS of a direct
    /// least-squares fit ([`lstsq_qr`]) of the same columns, to 1e-9 relative.
    #[test]
    fn nested_rss_matches_direct_fits_on_a_large_design() {
        let n = 2000;
        let x: Vec<f64> = (0..n).map(|i| i as f64 / n as f64).collect();
        let y: Vec<f64> = x
            .iter()
            .enumerate()
            .map(|(i, v)| (17.0 * v).sin() + 0.3 * (113.0 * v).cos() + 0.01 * ((i * 37) % 11) as f64)
            .collect();
        let w: Vec<f64> = (0..n).map(|i| 1.0 + 0.5 * (i % 3) as f64).collect();
        let base_cols: Vec<Vec<f64>> =
            (0..3).map(|g| (0..n).map(|i| if i % 3 == g { 1.0 } else { 0.0 }).collect()).collect();
        let series: Vec<Vec<f64>> = (1..=300).map(|k| x.iter().map(|v| (k as f64 * v * 3.0).cos()).collect()).collect();
        let b = OrthoBase::new(&base_cols, &w).unwrap();
        let nr = nested_rss(&y, &w, &b, &series).unwrap();
        assert!(nr.used.len() >= 150, "{}", nr.used.len());
        // (Near all 300 the cosines cos(3k·x) on [0, 1) grow nearly dependent and the direct
        // fit's pivot rank decisions differ from the nesting's: 0.2 % apart at 300.)
        for m in [50, 150] {
            let mut cols = base_cols.clone();
            cols.extend(nr.used[..m].iter().map(|&j| series[j].clone()));
            let (_, r) = lstsq_qr(&y, &cols, &w).unwrap();
            let direct: f64 = r.iter().zip(&w).map(|(r, w)| (r * w).powi(2)).sum();
            assert!((nr.rss[m] - direct).abs() <= 1e-9 * nr.rss[0], "m {m}: {} vs {direct}", nr.rss[m]);
        }
    }
}
