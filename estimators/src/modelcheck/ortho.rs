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

use super::{check_finite, check_len, ModelCheckError};
use faer::dyn_stack::{MemBuffer, MemStack};
use faer::linalg::householder;
use faer::linalg::matmul::matmul;
use faer::linalg::qr;
use faer::{Accum, Conj, Mat, Par};
use rayon::prelude::*;

/// Relative size of a pivot of the column-pivoted QR below which a (unit-norm) column counts as
/// dependent on the others.
pub const RANK_TOLERANCE: f64 = 1e-10;

/// Columns per task of [`OrthoBase::project_out`].
const PROJECT_COLUMNS: usize = 16;

/// An orthonormal basis Q (n × rank) of the span of weighted columns W·c_j.
#[derive(Debug, Clone)]
pub struct OrthoBase {
    q: Mat<f64>,
}

impl OrthoBase {
    /// The basis of the columns `cols` (each n values) weighted by `w` (n values, 1/σ): columns
    /// scaled to unit norm (all-zero columns skipped), factored as a tall-skinny QR (Demmel et al.
    /// 2012, SIAM J. Sci. Comput. 34:A206): each block of rows (`qr_block_rows`: an even number of
    /// equal blocks of at most [`QR_ROW_BLOCK`]; two halves from 2 × [`QR_HALF_BLOCK`] rows up to
    /// it, one block below) by an unpivoted blocked Householder QR
    /// (level 3, the blocks side by side), then the stacked R factors by a Householder QR with
    /// column pivoting, whose pivots above [`RANK_TOLERANCE`] × the largest count the rank (the
    /// stacked R's Gram matrix is the columns', so these are the pivots of the pivoted QR of all
    /// rows in exact arithmetic), and Q as each block's reflectors applied to its rows of the small
    /// Q. The pivoted QR of all rows (level 2) took 0.40–0.48 s for 19 910 × 203–209 unit columns,
    /// where the unpivoted one of 257 took 0.22 s. The bits do not depend on the number of threads
    /// (fixed blocks, each sequential inside).
    pub fn new(cols: &[Vec<f64>], w: &[f64]) -> Result<OrthoBase, ModelCheckError> {
        check_finite("weights", w)?;
        Ok(match unit_columns(cols, w)? {
            Some((a, _)) => OrthoBase { q: tall_thin_q(a, 0.0) },
            None => OrthoBase { q: Mat::zeros(w.len(), 0) },
        })
    }

    /// The basis of this span and the weighted columns `cols` (each n values, times `w`) together,
    /// built on this one: each column scaled to unit norm and its part in this span removed
    /// ([`OrthoBase::project_out`]), then those parts factored as [`OrthoBase::new`] factors its
    /// columns, the pivots above [`RANK_TOLERANCE`] kept (the tolerance of [`OrthoBase::new`], whose
    /// largest pivot is a unit-norm column's). The basis of [`OrthoBase::new`] over all the columns
    /// at the work of the new ones: about 2·n·k·(rank + k) for k new columns.
    pub fn extended(&self, cols: &[Vec<f64>], w: &[f64]) -> Result<OrthoBase, ModelCheckError> {
        check_finite("weights", w)?;
        check_len("weights", self.nrows(), w.len())?;
        let Some((mut a, _)) = unit_columns(cols, w)? else { return Ok(self.clone()) };
        self.project_out(&mut a);
        Ok(self.joined(&tall_thin_q(a, 1.0)))
    }

    /// This basis followed by the columns of `extra` (n × k, orthonormal and orthogonal to it).
    fn joined(&self, extra: &Mat<f64>) -> OrthoBase {
        let (n, r0) = (self.nrows(), self.rank());
        // index: j − r0 only where j ≥ r0; both bases have n rows (checked by the callers).
        let q =
            Mat::<f64>::from_fn(n, r0 + extra.ncols(), |i, j| if j < r0 { self.q[(i, j)] } else { extra[(i, j - r0)] });
        OrthoBase { q }
    }

    /// Number of samples n.
    pub fn nrows(&self) -> usize {
        self.q.nrows()
    }

    /// Rank of the weighted columns (number of basis vectors).
    pub fn rank(&self) -> usize {
        self.q.ncols()
    }

    /// The basis Q (n × rank, orthonormal columns). A basis [`OrthoBase::extended`] from this one
    /// begins with these columns, to the bit.
    pub fn q(&self) -> faer::MatRef<'_, f64> {
        self.q.as_ref()
    }

    /// Removes from every column of `m` (n × k) its part in the span: m − Q(Qᵀm), twice ("twice is
    /// enough", Giraud et al. 2005) for orthogonality to rounding. Blocks of 16 columns side by
    /// side (rayon), each block's products sequential: a column's result does not
    /// depend on the columns beside it, so these are the bits of one sequential product on any
    /// number of threads.
    pub fn project_out(&self, m: &mut Mat<f64>) {
        if self.rank() == 0 || m.ncols() == 0 {
            return;
        }
        let mut blocks = Vec::new();
        let mut rest = m.as_mut();
        while rest.ncols() > 0 {
            let width = PROJECT_COLUMNS.min(rest.ncols());
            let (block, others) = rest.split_at_col_mut(width);
            blocks.push(block);
            rest = others;
        }
        blocks.into_par_iter().for_each(|mut block| {
            let mut c = Mat::<f64>::zeros(self.rank(), block.ncols());
            for _ in 0..2 {
                matmul(c.as_mut(), Accum::Replace, self.q.transpose(), block.as_ref(), 1.0, Par::Seq);
                matmul(block.as_mut(), Accum::Add, self.q.as_ref(), c.as_ref(), -1.0, Par::Seq);
            }
        });
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
        let m = self.projected_independent(cols, w);
        (0..cols.len()).map(|j| m.col_as_slice(j).to_vec()).collect()
    }

    /// [`OrthoBase::project_columns`] as an n × k matrix (for products with other bases).
    pub fn projected_independent(&self, cols: &[Vec<f64>], w: &[f64]) -> Mat<f64> {
        let mut m = self.projected(cols, w);
        for (j, c) in cols.iter().enumerate() {
            let n0 = c.iter().zip(w).map(|(x, w)| (x * w).powi(2)).sum::<f64>().sqrt();
            let n1 = m.col_as_slice(j).iter().map(|x| x * x).sum::<f64>().sqrt();
            if !(n0 > 0.0 && n1 > 1e-9 * n0) {
                m.col_as_slice_mut(j).iter_mut().for_each(|x| *x = 0.0);
            }
        }
        m
    }

    /// The weighted sum of squares that `cols` explain beyond the span: ‖P_C·r‖² with r =
    /// `target` (weighted, already projected off the span) and C the projected weighted columns,
    /// in Gram form ([`OrthoBase::projected_fit`]). The RSS of the joint fit is ‖r‖² minus this.
    pub fn explained(&self, target: &[f64], cols: &[Vec<f64>], w: &[f64]) -> f64 {
        self.projected_fit(target, cols, w, false).0
    }

    /// The least squares of `target` (weighted, already projected off the span) on the weighted
    /// columns W·`cols` with their part in the span removed, in Gram form (variable projection
    /// without forming the projected columns):
    ///
    /// ```text
    /// M = Qᵀ(WC)        G = (WC)ᵀ(WC) − MᵀM = (PWC)ᵀ(PWC)        b = (WC)ᵀ·target
    /// explained = bᵀG⁺b                residual = target − (WC·β − Q·Mβ),  Gβ = b
    /// ```
    ///
    /// Each product runs over a column's non-zero rows only (a mode's segments live on a fraction of
    /// the samples), so an evaluation costs rank × (non-zeros) + k² × (overlaps + rank) flops instead
    /// of the n × rank × k of projecting the columns. G is scaled by the columns' own weighted norms
    /// and factored by a Cholesky that drops dependent columns: a column with less than 1e-5 of its weighted norm
    /// outside the span and the columns before it (pivot ≤ 1e-10) is dependent and left out (the
    /// normal equations resolve no finer). Returns (explained weighted sum of squares, the residual
    /// when `want_residual`).
    pub fn projected_fit(
        &self,
        target: &[f64],
        cols: &[Vec<f64>],
        w: &[f64],
        want_residual: bool,
    ) -> (f64, Option<Vec<f64>>) {
        let x = Weighted::of(cols, w);
        let m = self.products(std::slice::from_ref(&x)).pop().unwrap_or_default();
        self.fit_weighted(target, &x, &m, want_residual)
    }

    /// The weighted residual sum of squares of the least squares of [`OrthoBase::projected_fit`]:
    /// ‖target‖² − explained, or, where that difference is less than [`GRAM_CANCELLATION`] of
    /// ‖target‖² (the columns explain nearly all of the target, and the difference of two nearly
    /// equal sums has lost its digits), the sum of squares of the explicit residual (the products
    /// M = Qᵀ(WC) formed once for both). A closed loop's following error is millimetres against
    /// nanometres of noise: ‖target‖² ≈ 4·10¹⁴ for an RSS of 1.5·10⁴ (σ units, generator draw
    /// 2046), where the Gram-form difference moved by about 1 between nearby loop gains and a
    /// golden-section search over kv cycled through three values in successive refits.
    pub fn residual_ss(&self, target: &[f64], cols: &[Vec<f64>], w: &[f64]) -> f64 {
        let x = Weighted::of(cols, w);
        let m = self.products(std::slice::from_ref(&x)).pop().unwrap_or_default();
        let ss = dot(target, target);
        let explained = self.fit_weighted(target, &x, &m, false).0;
        if ss - explained > GRAM_CANCELLATION * ss {
            return ss - explained;
        }
        match self.fit_weighted(target, &x, &m, true).1 {
            Some(r) => dot(&r, &r),
            None => ss - explained,
        }
    }

    /// [`OrthoBase::explained`] of several column sets (each the columns of one value of a
    /// candidate's hyper-parameters): the products M = Qᵀ(WC) of all the sets' columns are formed
    /// together (the columns with the same non-zero rows in one product over those rows only, Q's
    /// rows read and packed once for all of them), then each set's Gram-form fit on its own. Each
    /// set's result is [`OrthoBase::projected_fit`]'s on that set alone up to rounding (a product's
    /// order of summation depends on how many columns share it), and is the same whatever the
    /// number of threads (it calls no other thread).
    pub fn explained_each(&self, target: &[f64], sets: &[&[Vec<f64>]], w: &[f64]) -> Vec<f64> {
        let xs: Vec<Weighted> = sets.iter().map(|c| Weighted::of(c, w)).collect();
        self.explained_weighted(target, &xs)
    }

    /// [`OrthoBase::explained_each`] of column sets given as runs ([`SparseColumn`]; each run in
    /// row order inside the n rows of `w`, as [`SparseColumn::dense`] would place it): each
    /// product over a run's rows only.
    pub fn explained_each_sparse(&self, target: &[f64], sets: &[&[SparseColumn]], w: &[f64]) -> Vec<f64> {
        let xs: Vec<Weighted> = sets.iter().map(|c| Weighted::of_sparse(c, w)).collect();
        self.explained_weighted(target, &xs)
    }

    fn explained_weighted(&self, target: &[f64], xs: &[Weighted]) -> Vec<f64> {
        let ms = self.products(xs);
        xs.iter().zip(&ms).map(|(x, m)| self.fit_weighted(target, x, m, false).0).collect()
    }

    /// M = Qᵀ(WC) (rank values per column) for every column of every set, a group of columns by
    /// one product over the group's rows [lo, hi) (each column in its place, zero elsewhere; Q's rows
    /// read and packed once for the group):
    ///
    /// - one set (one evaluation): the columns on more than an eighth of the rows in one group over
    ///   the rows they span, each other column alone over its own rows;
    /// - several sets (a batch of a search's evaluations): the columns with the same non-zero rows
    ///   (a mode's response on one pass, a sensor's channels) in one group, over those rows only.
    fn products(&self, sets: &[Weighted]) -> Vec<Vec<Vec<f64>>> {
        let (rank, n) = (self.rank(), self.nrows());
        // Empty until a column's first run is multiplied.
        let mut m: Vec<Vec<Vec<f64>>> = sets.iter().map(|x| vec![Vec::new(); x.runs.len()]).collect();
        // Groups by (lo, hi, the run alone): their members (set, column, run).
        type Key = (usize, usize, Option<(usize, usize, usize)>);
        let mut groups: std::collections::BTreeMap<Key, Vec<(usize, usize, usize)>> = Default::default();
        let one = sets.len() == 1;
        for (s, x) in sets.iter().enumerate() {
            let wide = |v: &[f64]| 8 * v.len() > n;
            let span = (0..x.runs.len())
                .filter(|&j| x.norm[j] > 0.0)
                .flat_map(|j| x.runs[j].iter().filter(|(_, v)| wide(v)).map(|(lo, v)| (*lo, lo + v.len())))
                .reduce(|a, b| (a.0.min(b.0), a.1.max(b.1)));
            for j in (0..x.runs.len()).filter(|&j| x.norm[j] > 0.0 && rank > 0) {
                for (r, (lo, v)) in x.runs[j].iter().enumerate().filter(|(_, (_, v))| !v.is_empty()) {
                    let key = match span {
                        Some((a, b)) if one && wide(v) => (a, b, None),
                        Some(_) | None if one => (*lo, lo + v.len(), Some((s, j, r))),
                        Some(_) | None => (*lo, lo + v.len(), None),
                    };
                    groups.entry(key).or_default().push((s, j, r));
                }
            }
        }
        for ((lo, hi, _), members) in groups {
            let q = self.q.as_ref().subrows(lo, hi - lo);
            let mut out = Mat::<f64>::zeros(rank, members.len());
            if let [(s, j, r)] = members[..] {
                // index: the run's hi − lo values (the group is the run's own rows).
                let v = faer::MatRef::from_column_major_slice(&sets[s].runs[j][r].1, hi - lo, 1);
                matmul(out.as_mut(), Accum::Replace, q.transpose(), v, 1.0, Par::Seq);
            } else {
                let mut block = Mat::<f64>::zeros(hi - lo, members.len());
                for (c, &(s, j, r)) in members.iter().enumerate() {
                    let (a, v) = &sets[s].runs[j][r];
                    // index: the run's rows lie inside the group's rows [lo, hi).
                    block.col_as_slice_mut(c)[a - lo..a - lo + v.len()].copy_from_slice(v);
                }
                matmul(out.as_mut(), Accum::Replace, q.transpose(), block.as_ref(), 1.0, Par::Seq);
            }
            // A column's M: its first run's product, then each other run's added (one run: the
            // product).
            for (c, &(s, j, _)) in members.iter().enumerate() {
                let col = &mut m[s][j];
                if col.is_empty() {
                    *col = (0..rank).map(|a| out[(a, c)]).collect();
                } else {
                    col.iter_mut().enumerate().for_each(|(a, x)| *x += out[(a, c)]);
                }
            }
        }
        // A column with no product (zero, or a base of rank 0): zeros.
        m.iter_mut().flatten().filter(|col| col.is_empty()).for_each(|col| col.resize(rank, 0.0));
        m
    }

    /// The Gram-form least squares of [`OrthoBase::projected_fit`] from the weighted columns `x`
    /// and their products `m` with Q ([`OrthoBase::products`]).
    fn fit_weighted(
        &self,
        target: &[f64],
        x: &Weighted,
        m: &[Vec<f64>],
        want_residual: bool,
    ) -> (f64, Option<Vec<f64>>) {
        let (k, rank) = (x.runs.len(), self.rank());
        let (runs, norm) = (&x.runs, &x.norm);
        // Sums over a column's runs (or pairs of runs): the first term, then the others added.
        let sum = |it: &mut dyn Iterator<Item = f64>| it.reduce(|a, b| a + b).unwrap_or(0.0);
        let mut g = vec![vec![0.0; k]; k];
        let mut b = vec![0.0; k];
        for i in 0..k {
            if norm[i] == 0.0 {
                continue;
            }
            // index: a run's rows lie inside the n rows (`Weighted::of`, checked for sparse columns).
            b[i] = sum(&mut runs[i].iter().map(|(lo, v)| dot(v, &target[*lo..lo + v.len()]))) / norm[i];
            for j in 0..=i {
                if norm[j] == 0.0 {
                    continue;
                }
                let mut overlaps = runs[i].iter().flat_map(|(li, vi)| {
                    runs[j].iter().filter_map(move |(lj, vj)| {
                        let (l2, h2) = (*li.max(lj), (li + vi.len()).min(lj + vj.len()));
                        (l2 < h2).then(|| dot(&vi[l2 - li..h2 - li], &vj[l2 - lj..h2 - lj]))
                    })
                });
                let own = sum(&mut overlaps);
                let v = (own - dot(&m[i], &m[j])) / (norm[i] * norm[j]);
                g[i][j] = v;
                g[j][i] = v;
            }
        }
        let chol = cholesky_with_dropping(&g, &b);
        if !want_residual {
            return (chol.score, None);
        }
        // β: Lᵀβ̃ = z over the kept pivots, β_j = β̃_j/‖Wc_j‖.
        let mut beta = vec![0.0; k];
        for i in (0..k).rev() {
            if chol.l[i][i] > 0.0 {
                let s: f64 = chol.z[i] - (i + 1..k).map(|r| chol.l[r][i] * beta[r]).sum::<f64>();
                beta[i] = s / chol.l[i][i];
            }
        }
        let mut residual = target.to_vec();
        let mut mb = vec![0.0; rank];
        for j in (0..k).filter(|&j| beta[j] != 0.0) {
            let bj = beta[j] / norm[j];
            for (lo, v) in &runs[j] {
                for (t, v) in v.iter().enumerate() {
                    residual[lo + t] -= bj * v;
                }
            }
            for (acc, mj) in mb.iter_mut().zip(&m[j]) {
                *acc += bj * mj;
            }
        }
        for (a, mba) in mb.iter().enumerate() {
            for (r, q) in residual.iter_mut().zip(self.q.col_as_slice(a)) {
                *r += mba * q;
            }
        }
        (chol.score, Some(residual))
    }

    /// A vector (n values, times `w`) with its part in the span removed.
    pub fn project_vector(&self, y: &[f64], w: &[f64]) -> Vec<f64> {
        let m = self.projected(&[y.to_vec()], w);
        (0..w.len()).map(|i| m[(i, 0)]).collect()
    }
}

/// Fraction of ‖target‖² below which [`OrthoBase::residual_ss`] sums the explicit residual
/// rather than subtracting the explained sum from ‖target‖²: 10⁻⁸ keeps at least eight digits of
/// the difference against the rounding of sums of squares (ε ≈ 10⁻¹⁶ of ‖target‖²) and of the
/// Gram matrix's condition.
pub const GRAM_CANCELLATION: f64 = 1e-8;

/// The part of a unit column left outside the columns taken below which [`greedy_rss`] no longer
/// takes it (1e-4 of its norm): the steps run in Gram form (classical Gram–Schmidt in coefficient
/// space), whose loss of orthogonality grows as ε·κ², so κ stays below 1e4.
pub const GREEDY_LEFT: f64 = 1e-8;

/// aⱼᵀv for every column j of `a` (n × k), the columns shared out over threads (rayon), each
/// product by [`dot`] on one thread: the same bits on any number of threads.
fn columns_dot(a: &Mat<f64>, v: &[f64]) -> Vec<f64> {
    (0..a.ncols()).into_par_iter().with_min_len(16).map(|j| dot(a.col_as_slice(j), v)).collect()
}

/// A column that is zero outside its runs of rows: (first row, values) per run, the runs in row
/// order and not overlapping. A candidate whose columns live on a few channels of a long stack (a
/// structural mode's response on each pass) gives them so, and a search over its hyper-parameters
/// then never writes, reads or multiplies the zeros ([`OrthoBase::explained_each_sparse`]).
#[derive(Debug, Clone, PartialEq, Default)]
pub struct SparseColumn {
    /// (first row, values) of each run.
    pub runs: Vec<(usize, Vec<f64>)>,
}

impl SparseColumn {
    /// The column as n values (zero outside its runs). Runs that reach past n are cut at n.
    pub fn dense(&self, n: usize) -> Vec<f64> {
        let mut out = vec![0.0; n];
        for (lo, v) in &self.runs {
            let hi = lo.saturating_add(v.len()).min(n);
            if *lo < hi {
                // index: lo < hi ≤ n and hi − lo ≤ the run's length (both cut above).
                out[*lo..hi].copy_from_slice(&v[..hi - lo]);
            }
        }
        out
    }
}

/// Columns weighted, each as its runs of rows (the inputs of [`OrthoBase::products`]).
struct Weighted {
    /// Per column, its runs: (first row, W·c over the run's rows), in row order.
    runs: Vec<Vec<(usize, Vec<f64>)>>,
    /// ‖W·c_j‖.
    norm: Vec<f64>,
}

impl Weighted {
    /// Dense columns, each cut to one run over its non-zero rows ([`nonzero_rows`]).
    fn of(cols: &[Vec<f64>], w: &[f64]) -> Weighted {
        let runs: Vec<Vec<(usize, Vec<f64>)>> = cols
            .iter()
            .map(|c| {
                let (lo, hi) = nonzero_rows(c);
                vec![(lo, (lo..hi).map(|i| c[i] * w[i]).collect())]
            })
            .collect();
        Weighted::with_norms(runs)
    }

    /// Columns given as runs (checked by the caller: in row order, inside the n rows of `w`).
    fn of_sparse(cols: &[SparseColumn], w: &[f64]) -> Weighted {
        let runs: Vec<Vec<(usize, Vec<f64>)>> = cols
            .iter()
            .map(|c| {
                c.runs.iter().map(|(lo, v)| (*lo, v.iter().zip(&w[*lo..]).map(|(x, w)| x * w).collect())).collect()
            })
            .collect();
        Weighted::with_norms(runs)
    }

    fn with_norms(runs: Vec<Vec<(usize, Vec<f64>)>>) -> Weighted {
        let norm = runs.iter().map(|r| r.iter().map(|(_, v)| dot(v, v)).sum::<f64>().sqrt()).collect();
        Weighted { runs, norm }
    }
}

/// The rows [lo, hi) outside which a column is zero (lo = hi for an all-zero column).
fn nonzero_rows(c: &[f64]) -> (usize, usize) {
    let lo = c.iter().position(|x| *x != 0.0).unwrap_or(c.len());
    let hi = c.iter().rposition(|x| *x != 0.0).map_or(lo, |i| i + 1);
    (lo, hi.max(lo))
}

/// Σ aᵢbᵢ in four interleaved partial sums (vectorisable; the same order, so the same bits, on
/// every call).
pub(crate) fn dot(a: &[f64], b: &[f64]) -> f64 {
    let n = a.len().min(b.len());
    let mut acc = [0.0; 4];
    let (ca, cb) = (a[..n].chunks_exact(4), b[..n].chunks_exact(4));
    let (ra, rb) = (ca.remainder(), cb.remainder());
    for (x, y) in ca.zip(cb) {
        for t in 0..4 {
            acc[t] += x[t] * y[t];
        }
    }
    let tail: f64 = ra.iter().zip(rb).map(|(x, y)| x * y).sum();
    (acc[0] + acc[1]) + (acc[2] + acc[3]) + tail
}

/// A Cholesky factorisation G = LLᵀ of a scaled Gram matrix with dependent columns left out, and
/// the explained sum of squares of its right-hand side ([`cholesky_with_dropping`]).
struct DroppingCholesky {
    /// Lower triangle; a dropped column's row and diagonal are zero.
    l: Vec<Vec<f64>>,
    /// z = L⁻¹b over the kept pivots (0 at a dropped one).
    z: Vec<f64>,
    /// ‖z‖² = bᵀG⁺b over the kept columns.
    score: f64,
}

/// Cholesky of `g` (symmetric, each column scaled by its own norm so that a pivot is the share of
/// the column's squared norm left after the columns before it) with column i dropped when its
/// pivot is ≤ 1e-10 (dependent on the ones before it; a zero column always), and z = L⁻¹`b`.
fn cholesky_with_dropping(g: &[Vec<f64>], b: &[f64]) -> DroppingCholesky {
    let q = g.len();
    let mut l = vec![vec![0.0; q]; q];
    let mut z = vec![0.0; q];
    let mut score = 0.0;
    for i in 0..q {
        if g[i][i] <= 0.0 {
            continue;
        }
        for j in 0..=i {
            if j < i && l[j][j] == 0.0 {
                continue;
            }
            let s: f64 = g[i][j] - (0..j).map(|k| l[i][k] * l[j][k]).sum::<f64>();
            if j == i {
                if s > 1e-10 {
                    l[i][i] = s.sqrt();
                }
            } else {
                l[i][j] = s / l[j][j];
            }
        }
        if l[i][i] > 0.0 {
            let zi = (b[i] - (0..i).map(|k| l[i][k] * z[k]).sum::<f64>()) / l[i][i];
            z[i] = zi;
            score += zi * zi;
        } else {
            // A dropped column: no part of its own; zero its row so later columns ignore it.
            l[i].iter_mut().for_each(|v| *v = 0.0);
        }
    }
    DroppingCholesky { l, z, score }
}

/// Weighted linear least squares for designs with many columns: β̂ = argmin Σ_i (w_i·(y_i −
/// Σ_j X_ij β_j))² by QR of the unit-norm weighted columns with the weighted data beside them,
/// [W·X/‖W·X‖ | W·y], factored by blocks of rows as [`OrthoBase::new`] factors its columns (each
/// block's unpivoted Householder QR, then the stacked R factors' columns of X by a QR with column
/// pivoting, whose reflectors take the stacked data column along): ‖W(y − Xβ)‖² = ‖z − R_X β‖² +
/// a constant, so β̂ solves the small pivoted system (Golub & Van Loan, Matrix Computations, 4th
/// ed., §5.4.1). Columns whose pivot is below [`RANK_TOLERANCE`] × the largest are dependent on
/// the others and get β_j = 0 (a basic solution; all-zero columns too). Returns (β, y − Xβ).
/// Costs about 2np² flops at level-3 speed against the SVD's ≈ 4np² + 8p³ (`fit_signature`),
/// which also gives standard errors and the condition number; use this one where only the fit is
/// needed.
pub fn lstsq_qr(y: &[f64], cols: &[Vec<f64>], w: &[f64]) -> Result<(Vec<f64>, Vec<f64>), ModelCheckError> {
    let n = w.len();
    check_len("y", n, y.len())?;
    check_finite("y", y)?;
    let mut beta = vec![0.0; cols.len()];
    if let Some((a, keep)) = unit_columns(cols, w)? {
        let p = a.ncols();
        // index: j < p + 1 columns, the last the weighted data.
        let aug = Mat::<f64>::from_fn(n, p + 1, |i, j| if j < p { a[(i, j)] } else { y[i] * w[i] });
        drop(a);
        let stacked = RowBlockQr::of(aug).stacked;
        let mut z = stacked.get(.., p..).to_owned();
        let PivotedQr { a: mut f, coeff, perm, rank } = PivotedQr::factor(stacked.get(.., ..p).to_owned(), 0.0);
        let r = Mat::<f64>::from_fn(rank, rank, |i, j| if i <= j { f[(i, j)] } else { 0.0 });
        let size = unit_reflectors(&mut f);
        apply_reflectors(f.get(.., ..size), &coeff, z.as_mut(), Reflect::Transposed);
        // Back substitution R δ = Qᵀz; δ_k belongs to the pivoted column perm[k].
        let mut d = vec![0.0; rank];
        for i in (0..rank).rev() {
            let s: f64 = z[(i, 0)] - (i + 1..rank).map(|j| r[(i, j)] * d[j]).sum::<f64>();
            d[i] = s / r[(i, i)];
        }
        for (k, dk) in d.iter().enumerate() {
            let (j, norm) = keep[perm[k]];
            beta[j] = dk / norm;
        }
    }
    let residual: Vec<f64> = (0..n)
        .map(|i| y[i] - cols.iter().zip(&beta).filter(|(_, b)| **b != 0.0).map(|(c, b)| c[i] * b).sum::<f64>())
        .collect();
    Ok((beta, residual))
}

/// The unit-norm weighted columns W·c_j/‖W·c_j‖ of `cols` (n × p, all-zero columns left out) and
/// the kept ones (index into `cols`, weighted norm); None when no column is nonzero (or n = 0).
/// Errors on a column whose length is not n or with a non-finite value.
#[allow(clippy::type_complexity)]
fn unit_columns(cols: &[Vec<f64>], w: &[f64]) -> Result<Option<(Mat<f64>, Vec<(usize, f64)>)>, ModelCheckError> {
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
    if keep.is_empty() || n == 0 {
        return Ok(None);
    }
    let a = Mat::<f64>::from_fn(n, keep.len(), |i, k| cols[keep[k].0][i] * w[i] / keep[k].1);
    Ok(Some((a, keep)))
}

/// A Householder QR with column pivoting, in place as faer stores it, with the numerical rank:
/// the pivots above [`RANK_TOLERANCE`] × a reference ([`PivotedQr::factor`]).
struct PivotedQr {
    /// R on and above the diagonal, the Householder essentials below it.
    a: Mat<f64>,
    /// Block Householder coefficients.
    coeff: Mat<f64>,
    /// Column k of the factorisation is column `perm[k]` of the input.
    perm: Vec<usize>,
    /// Numerical rank.
    rank: usize,
}

impl PivotedQr {
    /// The factorisation of `a` (n × p, p ≥ 1) in place, its rank counted by the pivots above
    /// [`RANK_TOLERANCE`] × `reference` (0: × the largest pivot).
    fn factor(mut a: Mat<f64>, reference: f64) -> PivotedQr {
        let (n, p) = a.shape();
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
        let d0 = if reference > 0.0 { reference } else { a[(0, 0)].abs() };
        let rank = (0..size).take_while(|&j| a[(j, j)].abs() > RANK_TOLERANCE * d0).count();
        PivotedQr { a, coeff, perm, rank }
    }
}

/// The first `rank` columns of Q of a Householder QR stored in place in `a` (essentials below the
/// diagonal, unit diagonal implied) with block coefficients `coeff`.
fn thin_q(mut a: Mat<f64>, coeff: &Mat<f64>, rank: usize) -> Mat<f64> {
    let n = a.nrows();
    let size = unit_reflectors(&mut a);
    let mut q = Mat::<f64>::from_fn(n, rank, |i, j| if i == j { 1.0 } else { 0.0 });
    apply_reflectors(a.get(.., ..size), coeff, q.as_mut(), Reflect::H);
    q
}

/// Which product with the reflectors [`apply_reflectors`] takes.
#[derive(Clone, Copy)]
enum Reflect {
    /// x ← H·x.
    H,
    /// x ← Hᵀ·x.
    Transposed,
}

/// x ← H·x or Hᵀ·x (`how`), H the product of the Householder reflectors `basis` (n × p, made as
/// faer applies them: [`unit_reflectors`]) with block coefficients `coeff`, x n × k. The columns
/// of x are independent: from [`APPLY_SPLIT_COLUMNS`] columns and [`APPLY_SPLIT_WORK`] on, x is
/// split into halves (the first the wider) applied side by side (rayon), each sequential inside;
/// the split depends on the shapes alone, so the bits do not depend on the number of threads.
fn apply_reflectors(basis: faer::MatRef<'_, f64>, coeff: &Mat<f64>, x: faer::MatMut<'_, f64>, how: Reflect) {
    use householder::*;
    let k = x.ncols();
    if k >= APPLY_SPLIT_COLUMNS && basis.nrows() * basis.ncols() * k >= APPLY_SPLIT_WORK {
        let (left, right) = x.split_at_col_mut(k.div_ceil(2));
        rayon::join(|| apply_reflectors(basis, coeff, left, how), || apply_reflectors(basis, coeff, right, how));
        return;
    }
    type Apply = fn(faer::MatRef<'_, f64>, faer::MatRef<'_, f64>, Conj, faer::MatMut<'_, f64>, Par, &mut MemStack);
    let (scratch, apply): (fn(usize, usize, usize) -> faer::dyn_stack::StackReq, Apply) = match how {
        Reflect::H => (
            apply_block_householder_sequence_on_the_left_in_place_scratch::<f64>,
            apply_block_householder_sequence_on_the_left_in_place_with_conj::<f64>,
        ),
        Reflect::Transposed => (
            apply_block_householder_sequence_transpose_on_the_left_in_place_scratch::<f64>,
            apply_block_householder_sequence_transpose_on_the_left_in_place_with_conj::<f64>,
        ),
    };
    let mut mem = MemBuffer::new(scratch(basis.nrows(), coeff.nrows(), x.ncols()));
    apply(basis, coeff.as_ref(), Conj::No, x, Par::Seq, MemStack::new(&mut mem));
}

/// Fewest columns of x that [`apply_reflectors`] splits in two: 64 (halves of at least 32
/// columns keep faer's matrix products at full speed).
const APPLY_SPLIT_COLUMNS: usize = 64;

/// Least work (rows × reflectors × columns) that [`apply_reflectors`] splits: 2²² (about 4 ms of
/// products on one core; below it a split costs more than it saves).
const APPLY_SPLIT_WORK: usize = 1 << 22;

/// The reflectors of a Householder QR stored in place in `a` (n × p) made as faer applies them:
/// unit diagonal and zeros above it in the first min(n, p) columns, their number returned.
fn unit_reflectors(a: &mut Mat<f64>) -> usize {
    let size = a.nrows().min(a.ncols());
    for j in 0..size {
        for i in 0..=j {
            a[(i, j)] = if i == j { 1.0 } else { 0.0 };
        }
    }
    size
}

/// The unpivoted blocked Householder QR of `a` (n × p) in place, sequential (R on and above the
/// diagonal, the reflectors' essentials below it); returns the block coefficients.
fn householder_qr(a: &mut Mat<f64>) -> Mat<f64> {
    let (n, p) = a.shape();
    let bs = qr::no_pivoting::factor::recommended_block_size::<f64>(n, p);
    let mut coeff = Mat::<f64>::zeros(bs, n.min(p));
    let mut mem =
        MemBuffer::new(qr::no_pivoting::factor::qr_in_place_scratch::<f64>(n, p, bs, Par::Seq, Default::default()));
    qr::no_pivoting::factor::qr_in_place(
        a.as_mut(),
        coeff.as_mut(),
        Par::Seq,
        MemStack::new(&mut mem),
        Default::default(),
    );
    coeff
}

/// Rows per block of [`OrthoBase::new`]'s factorisation above this many rows: 16 384 (at
/// 165 columns a block is 22 MB).
pub const QR_ROW_BLOCK: usize = 16_384;

/// The fewest rows of each half when [`OrthoBase::new`] splits a stack of at most
/// [`QR_ROW_BLOCK`] rows in two (so that the halves are factored side by side): 4 096. A
/// 15 000-sample stack is two blocks of 7 500 rows; one of fewer than 8 192 rows stays whole.
pub const QR_HALF_BLOCK: usize = 4_096;

/// Rows per block of the tall-skinny QR of `n` rows ([`tall_thin_q`]): above [`QR_ROW_BLOCK`],
/// the fewest blocks of at most that many rows, made an even number and equal but for the last
/// (19 910 rows: two of 9 955; 100 000: eight of 12 500), so that two cores share the work
/// evenly (blocks of 16 384 rows and the rest left one core with 82 % of it); two halves (the
/// first the longer) from 2 × [`QR_HALF_BLOCK`] rows up to it, else all `n`. It depends on `n`
/// alone, so the bits do not depend on the number of threads.
fn qr_block_rows(n: usize) -> usize {
    if n > QR_ROW_BLOCK {
        n.div_ceil(n.div_ceil(QR_ROW_BLOCK).next_multiple_of(2))
    } else if n >= 2 * QR_HALF_BLOCK {
        n.div_ceil(2)
    } else {
        n.max(1)
    }
}

/// The unpivoted Householder QR of `a` (n × p, p ≥ 1) by blocks of rows ([`qr_block_rows`]), the
/// blocks side by side (rayon), each sequential inside: the bits depend on n alone.
struct RowBlockQr {
    /// Rows per block (the last may have fewer).
    rows: usize,
    /// Each block's first row and end.
    blocks: Vec<(usize, usize)>,
    /// Each block factored in place (R on and above the diagonal, reflectors below) and its block
    /// coefficients.
    local: Vec<(Mat<f64>, Mat<f64>)>,
    /// Each block's first row in `stacked`.
    offsets: Vec<usize>,
    /// Each block's rows in `stacked`: min(its rows, p).
    sizes: Vec<usize>,
    /// The blocks' R factors stacked (Σ sizes × p): its Gram matrix is aᵀa.
    stacked: Mat<f64>,
}

impl RowBlockQr {
    fn of(a: Mat<f64>) -> RowBlockQr {
        let (n, p) = a.shape();
        let rows = qr_block_rows(n);
        let blocks: Vec<(usize, usize)> = (0..n.div_ceil(rows)).map(|b| (b * rows, ((b + 1) * rows).min(n))).collect();
        let local: Vec<(Mat<f64>, Mat<f64>)> = blocks
            .par_iter()
            .map(|&(lo, hi)| {
                let mut blk = a.as_ref().subrows(lo, hi - lo).to_owned();
                let coeff = householder_qr(&mut blk);
                (blk, coeff)
            })
            .collect();
        drop(a);
        let sizes: Vec<usize> = blocks.iter().map(|(lo, hi)| (hi - lo).min(p)).collect();
        let offsets: Vec<usize> = sizes.iter().scan(0, |o, s| Some(std::mem::replace(o, *o + s))).collect();
        let mut stacked = Mat::<f64>::zeros(sizes.iter().sum(), p);
        for ((blk, _), (&off, &size)) in local.iter().zip(offsets.iter().zip(&sizes)) {
            for j in 0..p {
                for i in 0..size.min(j + 1) {
                    stacked[(off + i, j)] = blk[(i, j)];
                }
            }
        }
        RowBlockQr { rows, blocks, local, offsets, sizes, stacked }
    }
}

/// The thin Q (n × rank) of the columns `a` (n × p, p ≥ 1) by blocks of rows ([`RowBlockQr`],
/// Demmel et al. 2012, SIAM J. Sci. Comput. 34:A206), the rank counted by the pivots of the
/// stacked R factors' pivoted QR above [`RANK_TOLERANCE`] × `reference` (0: × the largest pivot):
/// their Gram matrix is the columns', so the pivots are those of the pivoted QR of all rows in
/// exact arithmetic.
fn tall_thin_q(a: Mat<f64>, reference: f64) -> Mat<f64> {
    let n = a.nrows();
    let RowBlockQr { rows, blocks, local, offsets, sizes, stacked } = RowBlockQr::of(a);
    let f = PivotedQr::factor(stacked, reference);
    let small = thin_q(f.a, &f.coeff, f.rank);
    let rank = small.ncols();
    // Each block's rows of Q: its reflectors applied to its rows of the small Q (zero below).
    let parts: Vec<Mat<f64>> = local
        .into_par_iter()
        .zip(blocks.par_iter().zip(offsets.par_iter().zip(&sizes)))
        .map(|((mut blk, coeff), (&(lo, hi), (&off, &size)))| {
            let mut x = Mat::<f64>::zeros(hi - lo, rank);
            for j in 0..rank {
                for i in 0..size {
                    x[(i, j)] = small[(off + i, j)];
                }
            }
            let reflectors = unit_reflectors(&mut blk);
            apply_reflectors(blk.get(.., ..reflectors), &coeff, x.as_mut(), Reflect::H);
            x
        })
        .collect();
    // index: row i lies in block i / rows (the blocks are `rows` rows but the last).
    Mat::<f64>::from_fn(n, rank, |i, j| parts[i / rows][(i % rows, j)])
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
    Ok(NestedSeries::new(y, w, base, series)?.nested)
}

/// [`nested_rss`] kept factored, so that the nested sums with other columns added to the base come
/// without a second QR of the series ([`NestedSeries::with_extra`]): a model's error motion whose
/// order is chosen again with each of several candidates in the model (`diagnose`) shares the
/// series' QR, the candidates' few columns each costing O(n·k·c) (Qᵀ applied to c columns) where
/// the QR of the series after a base holding them costs O(n·k²).
#[derive(Debug, Clone)]
pub struct NestedSeries {
    /// The sums without other columns ([`nested_rss`]'s result).
    pub nested: NestedRss,
    /// The base the series and the data were projected off.
    base: OrthoBase,
    /// The series' Householder reflectors, one block per factoring ([`NestedSeries::new`], then
    /// each [`NestedSeries::extended`]): together the QR of the unit projected series columns off
    /// the base, k of them; empty when the series is not factored (no column off the base, or
    /// n ≤ k).
    blocks: Vec<Reflectors>,
    /// The reflector of the data's remainder: row k of Qᵀ(W·y) on, after the series' reflectors
    /// (the last column of the QR of [series | W·y]); None when not factored.
    data: Option<Reflectors>,
    /// Qᵀ of the projected W·y: rows 0..=k (the rows below are zero); the projected W·y itself
    /// (n values) when the series is not factored.
    zy: Vec<f64>,
    /// The projected W·y with the series' reflectors applied (n values, before the data's own):
    /// where a further block starts.
    qy: Vec<f64>,
    /// Series columns given so far (the index of a further block's first).
    given: usize,
    /// Columns factored (k): those off the base.
    factored: usize,
    /// The nesting stopped at a dependent column: a further block adds no sums.
    stopped: bool,
}

/// One block of Householder reflectors acting on rows `from..` of an n-row matrix: `basis`
/// (n − from rows, essentials below a unit diagonal, [`unit_reflectors`]) and its block
/// coefficients.
#[derive(Debug, Clone)]
struct Reflectors {
    from: usize,
    basis: Mat<f64>,
    coeff: Mat<f64>,
}

impl Reflectors {
    /// The Householder QR of `t` (rows `from..` of an n-row matrix) in place: R's diagonal, its
    /// reflectors.
    fn factor(from: usize, mut t: Mat<f64>) -> (Vec<f64>, Reflectors) {
        let coeff = householder_qr(&mut t);
        let diag = (0..t.nrows().min(t.ncols())).map(|j| t[(j, j)]).collect();
        unit_reflectors(&mut t);
        (diag, Reflectors { from, basis: t, coeff })
    }

    /// x ← H·x or Hᵀ·x on rows `from..` of x.
    fn apply(&self, x: &mut Mat<f64>, how: Reflect) {
        let rows = x.nrows();
        apply_reflectors(self.basis.as_ref(), &self.coeff, x.get_mut(self.from..rows, ..), how);
    }
}

/// [`NestedRss`] with other columns in the base ([`NestedSeries::with_extra`]).
#[derive(Debug, Clone, PartialEq)]
pub struct NestedRssWith {
    /// rss[m]: the weighted RSS with the base, the other columns and the series columns `used[..m]`.
    pub rss: Vec<f64>,
    /// Indices of the series columns taken, in order ([`NestedSeries::nested`]'s).
    pub used: Vec<usize>,
    /// rank[m]: how many of the other columns' directions are left outside the base and the series
    /// columns `used[..m]` (the parameters they add to that fit).
    pub rank: Vec<usize>,
}

impl NestedSeries {
    /// The QR of the series after `base` and the nested sums ([`nested_rss`]).
    pub fn new(y: &[f64], w: &[f64], base: &OrthoBase, series: &[Vec<f64>]) -> Result<NestedSeries, ModelCheckError> {
        check_series(y, w, base, series)?;
        let yp = base.project_vector(y, w);
        let rss0: f64 = yp.iter().map(|v| v * v).sum();
        let mut out = NestedSeries {
            nested: NestedRss { rss: vec![rss0], used: Vec::new() },
            base: base.clone(),
            blocks: Vec::new(),
            data: None,
            zy: yp.clone(),
            qy: yp,
            given: 0,
            factored: 0,
            stopped: false,
        };
        if !out.with_block(w, series) {
            out.given = series.len();
        }
        Ok(out)
    }

    /// [`NestedSeries::new`] with the columns `series` (those given before first, then more),
    /// the columns given before not factored again: their reflectors are applied to the new
    /// columns, and only what is left of these is factored (a QR of the new block on the rows
    /// below the old). The same sums as [`NestedSeries::new`] on all of `series`, up to rounding,
    /// at the cost of the new columns alone (the series before is consumed: its reflectors are kept,
    /// not copied).
    pub fn extended(self, y: &[f64], w: &[f64], series: &[Vec<f64>]) -> Result<NestedSeries, ModelCheckError> {
        // The columns given before were checked then.
        check_series(y, w, &self.base, series.get(self.given..).unwrap_or(&[]))?;
        if self.blocks.is_empty() || series.len() < self.given {
            return NestedSeries::new(y, w, &self.base, series);
        }
        let mut out = self;
        out.data = None;
        match out.with_block(w, &series[out.given..]) {
            true => Ok(out),
            false => NestedSeries::new(y, w, &out.base, series),
        }
    }

    /// `self` with the block `more` (columns given after those before) factored below the
    /// columns before: each column projected off the base (unit weighted norm before; one the
    /// base spans is skipped), the earlier reflectors applied, the rows below the earlier columns
    /// factored; then the data's remainder reflected. False, and `self` untouched, when the columns
    /// off the base would be n or more (not factored: [`NestedSeries::new`] keeps the projected W·y
    /// alone).
    fn with_block(&mut self, w: &[f64], more: &[Vec<f64>]) -> bool {
        let n = self.base.nrows();
        let projected = self.base.project_columns(more, w);
        let used: Vec<usize> = (0..more.len()).filter(|&j| projected[j].iter().any(|v| *v != 0.0)).collect();
        let k0 = self.factored;
        if k0 + used.len() >= n {
            return false;
        }
        if !used.is_empty() {
            let norms: Vec<f64> =
                more.iter().map(|c| c.iter().zip(w).map(|(x, w)| (x * w).powi(2)).sum::<f64>().sqrt()).collect();
            let mut m = Mat::<f64>::from_fn(n, used.len(), |i, j| projected[used[j]][i] / norms[used[j]]);
            for b in &self.blocks {
                b.apply(&mut m, Reflect::Transposed);
            }
            let (diag, refl) = Reflectors::factor(k0, m.get(k0.., ..).to_owned());
            let mut qy = Mat::<f64>::from_fn(n, 1, |i, _| self.qy[i]);
            refl.apply(&mut qy, Reflect::Transposed);
            self.qy = (0..n).map(|i| qy[(i, 0)]).collect();
            // R[j][j]: the part of unit column j left after the base and the columns before it;
            // (Qᵀ·W·y)_j what it explains.
            let mut rss = *self.nested.rss.last().unwrap_or(&0.0);
            for (j, &d) in diag.iter().enumerate() {
                if self.stopped || d.abs() <= 1e-9 {
                    self.stopped = true;
                    break;
                }
                rss = (rss - self.qy[k0 + j].powi(2)).max(0.0);
                self.nested.rss.push(rss);
                self.nested.used.push(self.given + used[j]);
            }
            self.blocks.push(refl);
            self.factored += used.len();
        }
        self.given += more.len();
        let k = self.factored;
        if k == 0 {
            self.zy = self.qy.clone();
            return true;
        }
        // The data's remainder (rows k on) reflected onto row k.
        let (diag, refl) = Reflectors::factor(k, Mat::<f64>::from_fn(n - k, 1, |i, _| self.qy[k + i]));
        self.zy = self.qy[..k].iter().copied().chain(diag).collect();
        self.data = Some(refl);
        true
    }

    /// Every reflector of the factored QR in order: the series' blocks, then the data's.
    fn reflectors(&self) -> impl DoubleEndedIterator<Item = &Reflectors> {
        self.blocks.iter().chain(self.data.iter())
    }

    /// The series' orthonormal directions q_0.., one per column taken (`nested.used`, in order), as
    /// an n × m matrix: the weighted series columns off the base and the ones before.
    pub fn q(&self) -> Mat<f64> {
        let m = self.nested.used.len();
        let mut q = Mat::<f64>::from_fn(self.base.nrows(), m, |i, j| if i == j { 1.0 } else { 0.0 });
        if m > 0 {
            self.reflectors().rev().for_each(|r| r.apply(&mut q, Reflect::H));
        }
        q
    }

    /// q_jᵀ(W·y) for each direction of [`NestedSeries::q`] (the data's W·y off the base):
    /// rss[j] − rss[j + 1] = (q_jᵀ(W·y))².
    pub fn qty(&self) -> &[f64] {
        &self.zy[..self.nested.used.len()]
    }

    /// The nested sums with the columns `extra` (each n values, weighted by `w`) in the base as
    /// well: rss[m] = min ‖W(y − Bβ − Eγ − S_mδ)‖², B the base, E `extra`, S_m the series columns
    /// `used[..m]`, each from the parts of W·E (unit norm before the projection) and W·y left
    /// outside B and S_m — the rows of Qᵀ(W·E) and Qᵀ(W·y) from m on, their rows below the series
    /// compressed to a triangle — by a pivoted QR of those few columns (a direction counts where
    /// its pivot is above [`RANK_TOLERANCE`] × the largest and above 1e-9 of its unit norm, the rule
    /// of [`OrthoBase::projected_independent`]). Equal to [`nested_rss`] with E in the base up to
    /// rounding, except that a series column E makes dependent adds nothing and is not skipped
    /// (its entry repeats the one before).
    pub fn with_extra(&self, extra: &[Vec<f64>], w: &[f64]) -> Result<NestedRssWith, ModelCheckError> {
        let n = self.base.nrows();
        check_len("weights", n, w.len())?;
        for (j, c) in extra.iter().enumerate() {
            check_len(&format!("extra column {j}"), n, c.len())?;
            check_finite(&format!("extra column {j}"), c)?;
        }
        // W·E off the base, unit weighted norm before the projection (a part ≤ 1e-9 of it is zero).
        let mut z = self.base.projected_independent(extra, w);
        for (j, c) in extra.iter().enumerate() {
            let norm = c.iter().zip(w).map(|(x, w)| (x * w).powi(2)).sum::<f64>().sqrt();
            let scale = if norm > 0.0 { 1.0 / norm } else { 0.0 };
            z.col_as_slice_mut(j).iter_mut().for_each(|x| *x *= scale);
        }
        // Qᵀ(W·E): rows 0..k along the series' directions, row k along the data's remainder; the
        // rows below hold no data and are compressed to a triangle (an orthogonal change of them).
        // `lead`: the rows that hold data (k + 1 when factored, else n).
        let lead = self.zy.len();
        let tail = if !self.blocks.is_empty() {
            self.reflectors().for_each(|r| r.apply(&mut z, Reflect::Transposed));
            let mut t = z.get(lead.., ..).to_owned();
            let rows = t.nrows().min(t.ncols());
            if rows > 0 {
                householder_qr(&mut t);
            }
            Mat::<f64>::from_fn(rows, t.ncols(), |i, j| if i <= j { t[(i, j)] } else { 0.0 })
        } else {
            Mat::zeros(0, z.ncols())
        };
        // Unfactored (nothing of the series off the base): `zy` is W·y off the base, every row data.
        let zy = &self.zy;
        let mut out = NestedRssWith { rss: Vec::new(), used: self.nested.used.clone(), rank: Vec::new() };
        for m in 0..self.nested.rss.len() {
            let rows = lead - m + tail.nrows();
            let at = |i: usize, j: usize| if i < lead - m { z[(m + i, j)] } else { tail[(i - (lead - m), j)] };
            let cols: Vec<Vec<f64>> = (0..z.ncols())
                .map(|j| {
                    let c: Vec<f64> = (0..rows).map(|i| at(i, j)).collect();
                    let left = c.iter().map(|x| x * x).sum::<f64>().sqrt();
                    if left > 1e-9 {
                        c
                    } else {
                        vec![0.0; rows]
                    }
                })
                .collect();
            let beta: Vec<f64> = (0..rows).map(|i| if i < lead - m { zy[m + i] } else { 0.0 }).collect();
            let ones = vec![1.0; rows];
            let small = OrthoBase::new(&cols, &ones)?;
            out.rss.push(small.project_vector(&beta, &ones).iter().map(|v| v * v).sum());
            out.rank.push(small.rank());
        }
        Ok(out)
    }
}

/// Weighted residual sums of squares along a greedy forward selection of `series` columns on
/// top of `base` (orthogonal matching pursuit; Pati, Rezaiifar & Krishnaprasad 1993): at each
/// step the column whose part left after the base and the columns already taken explains the
/// most of the current weighted residual, (aᵀr)²/‖a‖², enters. Returns the path as a
/// [`NestedRss`] (`used` in the order taken, `rss[m]` after the first m). For series whose signal
/// sits in a few terms anywhere in the series (rail waviness in a cosine series of the
/// accelerations), where nesting by degree would charge every term below it. The path stops when
/// no column has a part left above [`GREEDY_LEFT`] (of its unit weighted norm, outside the base and
/// the columns taken), or when the best column explains less than `stop` × the current mean square
/// (rss/n) for 20 steps in a row. The steps run on the Gram matrix of the projected columns (one
/// sequential level-3 product): the same bits on any number of threads.
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
    let r = base.project_vector(y, w);
    let rss: f64 = r.iter().map(|v| v * v).sum();
    // c_j = a_jᵀr (r stays orthogonal to the columns taken, so this is the part left's product).
    let corr = columns_dot(&a, &r);
    // The Gram matrix G = AᵀA of the projected unit columns, one level-3 product (compute-bound),
    // where each step's Aᵀv would read all of A again (memory-bound); the steps then run in the
    // coefficients of the columns taken.
    let g = super::lsq::gram_of(a.as_ref());
    Ok(greedy_steps(&g, left, corr, rss, n, stop))
}

/// [`greedy_rss`] with the series' weighted Gram matrix given: `gram` = (WS)ᵀ(WS) (k × k,
/// row-major, W = diag(`w`)), for a caller that has it more cheaply than from the columns (the
/// series are fixed combinations of columns whose Gram matrix it keeps). The projection off the
/// base is then taken in Gram form, as in [`OrthoBase::projected_fit`]: with M = Qᵀ(WS) and r the
/// weighted target off the base,
///
/// ```text
/// G = (WS)ᵀ(WS) − MᵀM = (PWS)ᵀ(PWS)      c = (WS)ᵀr      ‖PWs_j‖² = G_jj
/// ```
///
/// then the same steps. A column with less than 1e-9 of its weighted norm left is never taken.
/// Errors as [`greedy_rss`], and when `gram` is not k × k or not finite.
pub fn greedy_rss_with_gram(
    y: &[f64],
    w: &[f64],
    base: &OrthoBase,
    series: &[Vec<f64>],
    gram: &[f64],
    stop: f64,
) -> Result<NestedRss, ModelCheckError> {
    let n = w.len();
    check_len("y", n, y.len())?;
    check_finite("y", y)?;
    check_len("base rows", n, base.nrows())?;
    for (j, c) in series.iter().enumerate() {
        check_len(&format!("series column {j}"), n, c.len())?;
        check_finite(&format!("series column {j}"), c)?;
    }
    let r = base.project_vector(y, w);
    let ws = Mat::<f64>::from_fn(n, series.len(), |i, j| series[j][i] * w[i]);
    let mut m = Mat::<f64>::zeros(base.rank(), series.len());
    if base.rank() > 0 {
        matmul(m.as_mut(), Accum::Replace, base.q.transpose(), ws.as_ref(), 1.0, Par::Seq);
    }
    greedy_rss_from_products(dot(&r, &r), m.as_ref(), &columns_dot(&ws, &r), gram, n, stop)
}

/// The steps of [`greedy_rss_with_gram`] from the products it forms, for a caller that has them
/// more cheaply than from the series' columns (each series column a combination of columns whose
/// products with the base it keeps): M = Qᵀ(WS) (`m`, rank × k), c = (WS)ᵀr (`raw_corr`, k
/// values) and ‖r‖² (`rss0`), where r is the weighted target off the base
/// ([`OrthoBase::project_vector`]), the series' weighted Gram matrix `gram` ((WS)ᵀ(WS), k × k,
/// row-major) and the number of samples `n`:
///
/// ```text
/// G = (WS)ᵀ(WS) − MᵀM = (PWS)ᵀ(PWS)      ‖PWs_j‖² = G_jj
/// ```
///
/// A column with less than 1e-9 of its weighted norm left is never taken. Errors when the sizes
/// disagree or a product is not finite.
pub fn greedy_rss_from_products(
    rss0: f64,
    m: faer::MatRef<'_, f64>,
    raw_corr: &[f64],
    gram: &[f64],
    n: usize,
    stop: f64,
) -> Result<NestedRss, ModelCheckError> {
    let k = raw_corr.len();
    check_len("series products with the base", k, m.ncols())?;
    check_len("series Gram matrix", k * k, gram.len())?;
    check_finite("series Gram matrix", gram)?;
    check_finite("series products with the target", raw_corr)?;
    for j in 0..k {
        for i in 0..m.nrows() {
            let value = m[(i, j)];
            if !value.is_finite() {
                let what = "series products with the base (column-major)".to_string();
                return Err(ModelCheckError::NotFinite { what, index: j * m.nrows() + i, value });
            }
        }
    }
    let mtm = t_times_self(m);
    let n0: Vec<f64> = (0..k).map(|j| gram[j * k + j].max(0.0).sqrt()).collect();
    let mut left = vec![0.0; k];
    for j in 0..k {
        let part = gram[j * k + j] - mtm[(j, j)];
        if n0[j] > 0.0 && part > 1e-18 * n0[j] * n0[j] {
            left[j] = part / (n0[j] * n0[j]);
        }
    }
    let unit = |j: usize| if left[j] > 0.0 { 1.0 / n0[j] } else { 0.0 };
    // G in place of MᵀM.
    let mut g = mtm;
    for i in 0..k {
        for (j, gij) in gram[i * k..(i + 1) * k].iter().enumerate() {
            g[(i, j)] = (gij - g[(i, j)]) * unit(i) * unit(j);
        }
    }
    let corr: Vec<f64> = (0..k).map(|j| raw_corr[j] * unit(j)).collect();
    Ok(greedy_steps(&g, left, corr, rss0, n, stop))
}

/// Columns of each task of [`t_times_self`].
const GRAM_COLUMNS_PER_TASK: usize = 64;

/// MᵀM (k × k) of `m` (r × k), blocks of [`GRAM_COLUMNS_PER_TASK`] columns side by side (rayon),
/// each block's product sequential: a column of a product has the same bits whatever the other
/// columns beside it, so these are the bits of one sequential product on any number of threads.
fn t_times_self(m: faer::MatRef<'_, f64>) -> Mat<f64> {
    let k = m.ncols();
    let blocks: Vec<Mat<f64>> = (0..k.div_ceil(GRAM_COLUMNS_PER_TASK))
        .into_par_iter()
        .map(|b| {
            let lo = b * GRAM_COLUMNS_PER_TASK;
            let width = GRAM_COLUMNS_PER_TASK.min(k - lo);
            let mut out = Mat::<f64>::zeros(k, width);
            matmul(out.as_mut(), Accum::Replace, m.transpose(), m.subcols(lo, width), 1.0, Par::Seq);
            out
        })
        .collect();
    // index: column j lies in block j / GRAM_COLUMNS_PER_TASK.
    Mat::<f64>::from_fn(k, k, |i, j| blocks[j / GRAM_COLUMNS_PER_TASK][(i, j % GRAM_COLUMNS_PER_TASK)])
}

/// The steps of [`greedy_rss`] on the Gram matrix `g` of the projected unit columns, each
/// column's part `left` outside the base (of its unit norm), their products `corr` with the
/// projected target and its sum of squares `rss0`, over `n` samples.
fn greedy_steps(g: &Mat<f64>, mut left: Vec<f64>, mut corr: Vec<f64>, rss0: f64, n: usize, stop: f64) -> NestedRss {
    let k = corr.len();
    let mut rss = rss0;
    let mut out = NestedRss { rss: vec![rss], used: Vec::new() };
    let mut taken = vec![false; k];
    // Step s's unit vector v_s = Σ_t coef[s][t]·a_{used[t]} and its products d_s = Aᵀv_s.
    let mut coef: Vec<Vec<f64>> = Vec::new();
    let mut prods: Vec<Vec<f64>> = Vec::new();
    let mut weak = 0;
    while out.used.len() < k.min(n) {
        let mut best: Option<(usize, f64)> = None;
        for j in 0..k {
            if taken[j] || left[j] <= GREEDY_LEFT {
                continue;
            }
            let sc = corr[j].powi(2) / left[j];
            if best.is_none_or(|(_, b)| sc > b) {
                best = Some((j, sc));
            }
        }
        let Some((j, _)) = best else { break };
        taken[j] = true;
        // v = (a_j − Σ_t (a_jᵀv_t)·v_t)/‖·‖, the norm being √(part left).
        let norm = left[j].sqrt();
        let s = out.used.len();
        let mut c = vec![0.0; s + 1];
        c[s] = 1.0;
        for (ct, dt) in coef.iter().zip(&prods) {
            for (u, x) in c.iter_mut().zip(ct) {
                *u -= dt[j] * x;
            }
        }
        c.iter_mut().for_each(|x| *x /= norm);
        let qr_ = corr[j] / norm;
        let mean_sq = rss / n as f64;
        rss = (rss - qr_ * qr_).max(0.0);
        out.rss.push(rss);
        out.used.push(j);
        // Every column's part left and product with the residual: d = Aᵀv = Σ_t c_t·G[:, used_t].
        let mut d = vec![0.0; k];
        for (ct, &col) in c.iter().zip(&out.used) {
            for (dd, gv) in d.iter_mut().zip(g.col_as_slice(col)) {
                *dd += ct * gv;
            }
        }
        for jj in 0..k {
            left[jj] = (left[jj] - d[jj].powi(2)).max(0.0);
            corr[jj] -= d[jj] * qr_;
        }
        coef.push(c);
        prods.push(d);
        weak = if qr_ * qr_ < stop * mean_sq { weak + 1 } else { 0 };
        if weak >= 20 {
            break;
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::super::lsq::Basis;
    use super::*;

    /// [`OrthoBase::project_out`] by blocks of columns against the two products over all the
    /// columns at once, written here: 20 000 samples, a base of 70 cosine columns, 53 columns to
    /// project (three full blocks and a part): the same bits, and each column orthogonal to the
    /// base within 1e-12 of its norm.
    #[test]
    fn projection_by_blocks_of_columns_keeps_the_bits_of_one_product() {
        let n = 20_000;
        let w: Vec<f64> = (0..n).map(|i| 1.0 + 0.3 * (i as f64 * 0.011).sin()).collect();
        let cos = |a: f64, b: f64| (0..n).map(|i| (a * i as f64 / n as f64 + b).cos()).collect::<Vec<f64>>();
        let cols: Vec<Vec<f64>> = (0..70).map(|j| cos(3.1 * j as f64, 0.2 * j as f64)).collect();
        let base = OrthoBase::new(&cols, &w).unwrap();
        let m0 = Mat::<f64>::from_fn(n, 53, |i, j| ((i * (j + 3)) as f64 * 1e-3).sin() + (i as f64 * 1e-4) * j as f64);
        let mut by_blocks = m0.clone();
        base.project_out(&mut by_blocks);
        let mut whole = m0.clone();
        let mut c = Mat::<f64>::zeros(base.rank(), whole.ncols());
        for _ in 0..2 {
            matmul(c.as_mut(), Accum::Replace, base.q().transpose(), whole.as_ref(), 1.0, Par::Seq);
            matmul(whole.as_mut(), Accum::Add, base.q(), c.as_ref(), -1.0, Par::Seq);
        }
        for j in 0..53 {
            assert_eq!(by_blocks.col_as_slice(j), whole.col_as_slice(j), "column {j}");
            let norm = m0.col_as_slice(j).iter().map(|x| x * x).sum::<f64>().sqrt();
            for a in 0..base.rank() {
                let along: f64 = base.q().col(a).iter().zip(by_blocks.col_as_slice(j)).map(|(q, x)| q * x).sum();
                assert!(along.abs() <= 1e-12 * norm, "column {j} along {a}: {along:e}");
            }
        }
    }

    /// The Gram form of the greedy selection ([`greedy_rss_with_gram`]) against the column form
    /// ([`greedy_rss`]): 600 weighted samples, a polynomial base of rank 3, 40 cosine columns of
    /// which four carry the target (plus noise), one column inside the base's span and one
    /// all-zero: the same columns taken in the same order, and every residual sum of squares
    /// within 1e-9 of the first.
    #[test]
    fn greedy_selection_in_gram_form_takes_the_same_path() {
        let n = 600;
        let x: Vec<f64> = (0..n).map(|i| i as f64 / n as f64).collect();
        let w: Vec<f64> = (0..n).map(|i| 1.0 + 0.4 * (i as f64 * 0.23).cos()).collect();
        let pw = |k: i32| x.iter().map(|v| v.powi(k)).collect::<Vec<f64>>();
        let base = OrthoBase::new(&[pw(0), pw(1), pw(2)], &w).unwrap();
        let mut series: Vec<Vec<f64>> =
            (1..=40).map(|j| x.iter().map(|v| (std::f64::consts::PI * j as f64 * v).cos()).collect()).collect();
        series.push(x.iter().map(|v| 2.0 - 3.0 * v * v).collect());
        series.push(vec![0.0; n]);
        let y: Vec<f64> = (0..n)
            .map(|i| {
                3.0 * series[4][i] - 2.0 * series[17][i]
                    + 0.5 * series[30][i]
                    + 0.1 * series[2][i]
                    + 0.01 * (i as f64 * 2.9).sin()
                    + x[i]
            })
            .collect();
        let k = series.len();
        let gram: Vec<f64> = (0..k * k)
            .map(|e| (0..n).map(|i| series[e / k][i] * series[e % k][i] * w[i] * w[i]).sum::<f64>())
            .collect();
        let a = greedy_rss(&y, &w, &base, &series, 1e-6).unwrap();
        let b = greedy_rss_with_gram(&y, &w, &base, &series, &gram, 1e-6).unwrap();
        assert!(a.used.len() >= 4);
        assert_eq!(a.used, b.used);
        for (p, q) in a.rss.iter().zip(&b.rss) {
            assert!((p - q).abs() <= 1e-9 * a.rss[0], "{p} vs {q}");
        }
        assert!(!a.used.contains(&40) && !a.used.contains(&41));
        assert!(greedy_rss_with_gram(&y, &w, &base, &series, &gram[1..], 1e-6).is_err());
    }

    /// A basis extended by more columns ([`OrthoBase::extended`]) against the basis of all of them
    /// at once ([`OrthoBase::new`]): 500 weighted samples, a base of 6 polynomial and cosine
    /// columns (one dependent), 12 new columns of which 3 lie in the span of the others and one is
    /// all-zero. The same rank (the independent count, 5 + 8), orthonormal columns (QᵀQ = I to
    /// 1e-12) and the same projection of a test vector (to 1e-10 of its norm).
    #[test]
    fn an_extended_basis_spans_what_the_whole_basis_spans() {
        let n = 500;
        let x: Vec<f64> = (0..n).map(|i| i as f64 / n as f64).collect();
        let w: Vec<f64> = (0..n).map(|i| 0.5 + (i as f64 * 0.37).sin().abs()).collect();
        let cosine = |k: f64| x.iter().map(|v| (std::f64::consts::PI * k * v).cos() * (1.0 + k)).collect::<Vec<f64>>();
        let pw = |k: i32| x.iter().map(|v| v.powi(k)).collect::<Vec<f64>>();
        let combo = |a: &[f64], b: &[f64], s: f64| a.iter().zip(b).map(|(p, q)| p + s * q).collect::<Vec<f64>>();
        let mut first = vec![pw(0), pw(1), pw(2), cosine(3.0), cosine(7.0)];
        first.push(combo(&first[1], &first[3], -2.5));
        let mut more: Vec<Vec<f64>> = (0..8).map(|k| cosine(11.0 + 2.3 * k as f64)).collect();
        more.push(combo(&more[2], &first[0], 4.0));
        more.push(combo(&first[4], &first[2], 1e-3));
        more.push(combo(&more[0], &more[7], -1.0));
        more.push(vec![0.0; n]);
        let base = OrthoBase::new(&first, &w).unwrap();
        let ext = base.extended(&more, &w).unwrap();
        let all: Vec<Vec<f64>> = first.iter().chain(&more).cloned().collect();
        let whole = OrthoBase::new(&all, &w).unwrap();
        assert_eq!(base.rank(), 5);
        assert_eq!(ext.rank(), 13);
        assert_eq!(whole.rank(), 13);
        let gram = super::super::lsq::gram_of(ext.q.as_ref());
        for i in 0..13 {
            for j in 0..13 {
                let e = if i == j { 1.0 } else { 0.0 };
                assert!((gram[(i, j)] - e).abs() <= 1e-12, "QᵀQ[{i},{j}] = {}", gram[(i, j)]);
            }
        }
        let v: Vec<f64> = (0..n).map(|i| (i as f64 * 0.071).sin() + x[i].powi(3)).collect();
        let (a, b) = (ext.project_vector(&v, &w), whole.project_vector(&v, &w));
        let norm = v.iter().zip(&w).map(|(p, q)| (p * q).powi(2)).sum::<f64>().sqrt();
        let diff = a.iter().zip(&b).map(|(p, q)| (p - q).powi(2)).sum::<f64>().sqrt();
        assert!(diff <= 1e-10 * norm, "projections differ by {diff} of {norm}");
    }

    /// The factorisation by blocks of rows ([`OrthoBase::new`], [`OrthoBase::extended`]) against
    /// one Householder QR with column pivoting over all rows (`whole_rows`, the factorisation
    /// before the blocks): 2 × [`QR_ROW_BLOCK`] + 50 weighted samples (four blocks: three of 8 205
    /// rows, the last of 8 203), 2 × [`QR_HALF_BLOCK`] + 1 (two halves), 70 columns of which 3 are
    /// combinations of others and one is zero on all but the last 40 rows, one column all-zero;
    /// then 30 more columns, 2 of them in the span. The same ranks (66, then 94), orthonormal
    /// columns (QᵀQ = I to 1e-12) and the same projection of a test vector (to 1e-10 of its norm);
    /// a one-block stack too (500 rows).
    #[test]
    fn a_basis_by_blocks_of_rows_spans_what_the_whole_basis_spans() {
        for n in [2 * QR_ROW_BLOCK + 50, 2 * QR_HALF_BLOCK + 1, 500] {
            let x: Vec<f64> = (0..n).map(|i| i as f64 / n as f64).collect();
            let w: Vec<f64> = (0..n).map(|i| 0.5 + (i as f64 * 0.37).sin().abs()).collect();
            let wave = |k: f64| x.iter().map(|v| (std::f64::consts::PI * k * v + 0.3 * k).cos()).collect::<Vec<f64>>();
            let combo = |a: &[f64], b: &[f64], s: f64| a.iter().zip(b).map(|(p, q)| p + s * q).collect::<Vec<f64>>();
            let mut first: Vec<Vec<f64>> = (0..66).map(|k| wave(1.0 + 1.7 * k as f64)).collect();
            first.push(combo(&first[3], &first[40], -2.5));
            first.push(combo(&first[10], &first[65], 1e-3));
            first.push(combo(&first[0], &first[1], 7.0));
            first.push(vec![0.0; n]);
            // Zero but on the last 40 rows: one more independent column.
            first[20] = (0..n).map(|i| if i + 40 >= n { x[i] * x[i] } else { 0.0 }).collect();
            let mut more: Vec<Vec<f64>> = (0..28).map(|k| wave(120.3 + 2.9 * k as f64)).collect();
            more.push(combo(&more[2], &first[5], 4.0));
            more.push(combo(&first[7], &first[9], 0.5));
            let v: Vec<f64> = (0..n).map(|i| (i as f64 * 0.071).sin() + x[i].powi(3)).collect();
            let norm = v.iter().zip(&w).map(|(p, q)| (p * q).powi(2)).sum::<f64>().sqrt();
            // The pivoted QR of all rows at once: of the unit columns, then of the new ones' parts
            // off that span (pivots counted against 1, a unit column's).
            let whole_rows = |a: Mat<f64>, reference: f64| {
                let f = PivotedQr::factor(a, reference);
                thin_q(f.a, &f.coeff, f.rank)
            };
            let whole = OrthoBase { q: whole_rows(unit_columns(&first, &w).unwrap().unwrap().0, 0.0) };
            let mut parts = unit_columns(&more, &w).unwrap().unwrap().0;
            whole.project_out(&mut parts);
            let ext_whole = whole.joined(&whole_rows(parts, 1.0));
            let blocked = OrthoBase::new(&first, &w).unwrap();
            let ext_blocked = blocked.extended(&more, &w).unwrap();
            for (a, b, rank) in [(&whole, &blocked, 66), (&ext_whole, &ext_blocked, 94)] {
                assert_eq!((a.rank(), b.rank()), (rank, rank), "{n} rows");
                let gram = super::super::lsq::gram_of(b.q.as_ref());
                for i in 0..rank {
                    for j in 0..rank {
                        let e = if i == j { 1.0 } else { 0.0 };
                        assert!((gram[(i, j)] - e).abs() <= 1e-12, "{n} rows: QᵀQ[{i},{j}] = {}", gram[(i, j)]);
                    }
                }
                let (pa, pb) = (a.project_vector(&v, &w), b.project_vector(&v, &w));
                let diff = pa.iter().zip(&pb).map(|(p, q)| (p - q).powi(2)).sum::<f64>().sqrt();
                assert!(diff <= 1e-10 * norm, "{n} rows: projections differ by {diff} of {norm}");
            }
        }
    }

    /// The Gram form of a projected fit ([`OrthoBase::projected_fit`]) against the explicit one
    /// (columns projected off the base, orthonormalised by twice-applied Gram–Schmidt, the target's
    /// components removed): on 400 weighted samples, a polynomial base of rank 4, candidate columns
    /// dense and supported on a few rows (segments, as a mode's), one a combination of others, the
    /// explained sum of squares and the residual agree to 1e-9 of the target's norm.
    #[test]
    fn projected_fit_in_gram_form_matches_the_explicit_projection() {
        let n = 400;
        let x: Vec<f64> = (0..n).map(|i| i as f64 / n as f64).collect();
        let w: Vec<f64> = (0..n).map(|i| 1.0 + 0.5 * (i as f64 * 0.37).sin()).collect();
        let pw = |k: i32| x.iter().map(|v| v.powi(k)).collect::<Vec<f64>>();
        let base = OrthoBase::new(&[pw(0), pw(1), pw(2), pw(3)], &w).unwrap();
        let seg = |a: usize, b: usize, f: f64| -> Vec<f64> {
            (0..n).map(|i| if i >= a && i < b { (f * x[i]).sin() + 0.3 } else { 0.0 }).collect()
        };
        let dense: Vec<f64> = x.iter().map(|v| (9.0 * v).cos() * v).collect();
        let (s1, s2) = (seg(10, 60, 40.0), seg(50, 130, 55.0));
        let comb: Vec<f64> = (0..n).map(|i| 2.0 * s1[i] - dense[i]).collect();
        let cols = vec![dense.clone(), s1, s2, comb, seg(300, 320, 70.0), vec![0.0; n]];
        let y: Vec<f64> = (0..n).map(|i| (23.0 * x[i]).sin() + 0.1 * (i as f64 * 1.7).cos() + cols[2][i]).collect();
        let target = base.project_vector(&y, &w);
        let (explained, residual) = base.projected_fit(&target, &cols, &w, true);
        let residual = residual.unwrap();
        let mut b = Basis::default();
        for v in base.project_columns(&cols, &w).into_iter().filter(|v| v.iter().any(|x| *x != 0.0)) {
            b.push(v);
        }
        let mut r = target.clone();
        let mut want = 0.0;
        for q in &b.q {
            let d: f64 = q.iter().zip(&target).map(|(a, b)| a * b).sum();
            want += d * d;
            r.iter_mut().zip(q).for_each(|(r, q)| *r -= d * q);
        }
        let scale: f64 = target.iter().map(|v| v * v).sum();
        assert!(b.q.len() == 4, "independent columns {}", b.q.len());
        assert!((explained - want).abs() <= 1e-9 * scale, "explained {explained} against {want}");
        let dr = residual.iter().zip(&r).map(|(a, b)| (a - b).powi(2)).sum::<f64>().sqrt();
        assert!(dr <= 1e-9 * scale.sqrt(), "residual differs by {dr}");
    }

    /// Columns that explain nearly all of the target (a closed loop's following error, millimetres
    /// against nanometres of noise: here 10⁶ times the noise, a ratio RSS/‖target‖² of about
    /// 10⁻¹²): [`OrthoBase::residual_ss`] is the RSS of the Householder projection onto all the
    /// columns to 10⁻⁹ of itself, where the Gram-form difference ‖target‖² − explained keeps only
    /// the digits that ε·‖target‖² ≈ 10⁻² leaves of an RSS of about 4; a target the columns explain
    /// less of gets that difference, to the bit.
    #[test]
    fn residual_ss_keeps_its_digits_where_the_columns_explain_nearly_all() {
        let n = 400;
        let x: Vec<f64> = (0..n).map(|i| i as f64 / n as f64).collect();
        let w: Vec<f64> = (0..n).map(|i| 1.0 + 0.5 * (i as f64 * 0.37).sin()).collect();
        let fixed = vec![vec![1.0; n], x.clone()];
        let base = OrthoBase::new(&fixed, &w).unwrap();
        let lag: Vec<f64> = x.iter().map(|v| (1.0 - (-7.0 * v).exp()) * (3.0 * v).cos()).collect();
        let noise: Vec<f64> = (0..n).map(|i| 0.1 * ((i as f64 * 2.3).sin() + (i as f64 * 0.71).cos())).collect();
        let truth = |scale: f64| -> (Vec<f64>, f64) {
            let y: Vec<f64> = (0..n).map(|i| scale * lag[i] + noise[i] + 0.2 * x[i]).collect();
            let all = OrthoBase::new(&[fixed[0].clone(), fixed[1].clone(), lag.clone()], &w).unwrap();
            let r = all.project_vector(&y, &w);
            (base.project_vector(&y, &w), r.iter().map(|v| v * v).sum())
        };
        let cols = [lag.clone()];
        let (target, want) = truth(1e6);
        let got = base.residual_ss(&target, &cols, &w);
        let ss: f64 = target.iter().map(|v| v * v).sum();
        assert!(want < 1e-10 * ss, "the case cancels: RSS {want} of {ss}");
        assert!((got - want).abs() <= 1e-9 * want, "residual_ss {got} against {want}");
        let (target, _) = truth(1.0);
        let ss = dot(&target, &target);
        let gram = ss - base.explained(&target, &cols, &w);
        assert!(gram > GRAM_CANCELLATION * ss);
        assert_eq!(base.residual_ss(&target, &cols, &w).to_bits(), gram.to_bits());
    }

    /// A batch of column sets at once ([`OrthoBase::explained_each`], dense, and
    /// [`OrthoBase::explained_each_sparse`], the same columns as runs, one of them on three runs
    /// with gaps, as a sensor's response over interleaved channels): each set's explained sum of
    /// squares is [`OrthoBase::projected_fit`]'s on that set alone to 1e-12 of the target's squared
    /// norm (the products' order of summation differs), in the order given, on 600 weighted samples.
    #[test]
    fn batched_and_sparse_projected_fits_match_one_at_a_time() {
        let n = 600;
        let x: Vec<f64> = (0..n).map(|i| i as f64 / n as f64).collect();
        let w: Vec<f64> = (0..n).map(|i| 1.0 + 0.4 * (i as f64 * 0.23).cos()).collect();
        let base = OrthoBase::new(&[vec![1.0; n], x.clone(), x.iter().map(|v| v * v).collect()], &w).unwrap();
        let y: Vec<f64> = (0..n).map(|i| (31.0 * x[i]).sin() + 0.2 * (i as f64 * 1.3).cos()).collect();
        let target = base.project_vector(&y, &w);
        let run = |lo: usize, hi: usize, f: f64| (lo, (lo..hi).map(|i| (f * x[i]).sin() + 0.1).collect::<Vec<f64>>());
        let sparse_sets: Vec<Vec<SparseColumn>> = (0..5)
            .map(|s| {
                let f = 20.0 + 7.0 * s as f64;
                vec![
                    SparseColumn { runs: vec![run(0, 100, f), run(200, 300, f), run(400, 500, f)] },
                    SparseColumn { runs: vec![run(100, 200, 1.3 * f)] },
                    SparseColumn { runs: vec![run(0, 600, 0.5 * f)] },
                    SparseColumn::default(),
                ]
            })
            .collect();
        let dense_sets: Vec<Vec<Vec<f64>>> =
            sparse_sets.iter().map(|set| set.iter().map(|c| c.dense(n)).collect()).collect();
        let dense_refs: Vec<&[Vec<f64>]> = dense_sets.iter().map(Vec::as_slice).collect();
        let sparse_refs: Vec<&[SparseColumn]> = sparse_sets.iter().map(Vec::as_slice).collect();
        let batch = base.explained_each(&target, &dense_refs, &w);
        let batch_sparse = base.explained_each_sparse(&target, &sparse_refs, &w);
        let scale: f64 = target.iter().map(|v| v * v).sum();
        assert_eq!(batch.len(), 5);
        assert_eq!(batch_sparse.len(), 5);
        for (s, set) in dense_sets.iter().enumerate() {
            let one = base.projected_fit(&target, set, &w, false).0;
            assert!(one > 1e-3 * scale, "set {s} explains {one} of {scale}");
            assert!((batch[s] - one).abs() <= 1e-12 * scale, "set {s}: batch {} against {one}", batch[s]);
            assert!((batch_sparse[s] - one).abs() <= 1e-12 * scale, "set {s}: runs {} against {one}", batch_sparse[s]);
        }
    }

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
    /// [`lstsq_qr`] by blocks of rows (2 × [`QR_ROW_BLOCK`] + 50 weighted samples: four blocks,
    /// three of 8 205 rows and the last of 8 203) leaves the residual of the projection off the
    /// columns' basis ([`OrthoBase::new`], Q formed and applied) to 1e-10 of the data's weighted
    /// norm, with 40 well-conditioned columns (cosines of whole half-periods) of which two are
    /// combinations of others and one all-zero, and its coefficients reproduce the fitted values.
    #[test]
    fn least_squares_by_blocks_of_rows_leaves_the_projection_residual() {
        let n = 2 * QR_ROW_BLOCK + 50;
        let x: Vec<f64> = (0..n).map(|i| i as f64 / n as f64).collect();
        let w: Vec<f64> = (0..n).map(|i| 0.5 + (i as f64 * 0.37).sin().abs()).collect();
        let mut cols: Vec<Vec<f64>> = (0..37)
            .map(|k| x.iter().map(|v| (std::f64::consts::PI * k as f64 * v + 0.2 * k as f64).cos()).collect())
            .collect();
        cols.push(cols[3].iter().zip(&cols[30]).map(|(a, b)| a - 2.0 * b).collect());
        cols.push(cols[7].iter().map(|a| 3.0 * a).collect());
        cols.push(vec![0.0; n]);
        let y: Vec<f64> = (0..n).map(|i| (x[i] * 40.0).sin() + x[i].powi(3) + 0.01 * ((i * 7) % 5) as f64).collect();
        let (beta, r) = lstsq_qr(&y, &cols, &w).unwrap();
        let projected = OrthoBase::new(&cols, &w).unwrap().project_vector(&y, &w);
        let norm = y.iter().zip(&w).map(|(a, b)| (a * b).powi(2)).sum::<f64>().sqrt();
        let diff = (0..n).map(|i| (r[i] * w[i] - projected[i]).powi(2)).sum::<f64>().sqrt();
        assert!(diff <= 1e-10 * norm, "residuals differ by {diff} of {norm}");
        let refit = (0..n).map(|i| y[i] - cols.iter().zip(&beta).map(|(c, b)| c[i] * b).sum::<f64>() - r[i]);
        assert!(refit.map(f64::abs).fold(0.0, f64::max) <= 1e-10 * norm);
        assert_eq!(beta[39], 0.0);
        assert_eq!(beta.iter().filter(|b| **b == 0.0).count(), 3, "one zero column, two dependent");
    }

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

    /// The nested sums with other columns in the base from the series' one QR
    /// ([`NestedSeries::with_extra`]) are those of [`nested_rss`] with them in the base: a few
    /// columns off the series (a ramp times a step, a wave), and one the series spans (x itself,
    /// its first column), which adds nothing from there on and leaves one direction fewer.
    #[test]
    fn nested_sums_with_extra_columns_match_a_qr_with_them_in_the_base() {
        let n = 1500;
        let x: Vec<f64> = (0..n).map(|i| (i as f64 + 0.3 * ((i * 7) % 5) as f64) / n as f64).collect();
        let y: Vec<f64> = x
            .iter()
            .enumerate()
            .map(|(i, v)| (5.0 * v).sin() + 0.2 * (61.0 * v).cos() + if i % 2 == 0 { 0.05 } else { -0.02 })
            .collect();
        let w: Vec<f64> = (0..n).map(|i| 1.0 + 0.25 * (i % 4) as f64).collect();
        let base_cols: Vec<Vec<f64>> = vec![vec![1.0; n], (0..n).map(|i| (i % 2) as f64).collect()];
        let series: Vec<Vec<f64>> =
            (1..=60).map(|k| x.iter().map(|v| (k as f64 * std::f64::consts::PI * v).cos()).collect()).collect();
        let b = OrthoBase::new(&base_cols, &w).unwrap();
        let ns = NestedSeries::new(&y, &w, &b, &series).unwrap();
        assert_eq!(ns.nested, nested_rss(&y, &w, &b, &series).unwrap());
        let step: Vec<f64> = x.iter().enumerate().map(|(i, v)| if i % 2 == 0 { v * v } else { 0.0 }).collect();
        let wave: Vec<f64> = x.iter().map(|v| (97.0 * v).sin()).collect();
        for extra in [vec![step.clone(), wave.clone()], vec![series[0].clone(), wave]] {
            let with = ns.with_extra(&extra, &w).unwrap();
            let mut cols = base_cols.clone();
            cols.extend(extra.iter().cloned());
            let joint = OrthoBase::new(&cols, &w).unwrap();
            let direct = nested_rss(&y, &w, &joint, &series).unwrap();
            // Pair the direct nesting's entries with the shared one's by the last column taken.
            for (m, used) in std::iter::once(None).chain(direct.used.iter().map(Some)).enumerate() {
                let k = used.map_or(0, |u| with.used.iter().position(|v| v == u).unwrap() + 1);
                let scale = direct.rss[0];
                assert!(
                    (with.rss[k] - direct.rss[m]).abs() <= 1e-9 * scale,
                    "{m}: {} vs {}",
                    with.rss[k],
                    direct.rss[m]
                );
                assert_eq!(b.rank() + k + with.rank[k], joint.rank() + m, "parameters at {m}");
            }
        }
    }

    /// A series factored in blocks ([`NestedSeries::extended`]: 20 columns, then 25 more, one of
    /// them the base's own, then 15 more) gives the sums, directions, Qᵀ(W·y) and sums with other
    /// columns of one QR of all 60 ([`NestedSeries::new`]) to rounding.
    #[test]
    fn a_series_factored_in_blocks_matches_one_qr_of_all_its_columns() {
        let n = 900;
        let x: Vec<f64> = (0..n).map(|i| (i as f64 + 0.4 * ((i * 3) % 7) as f64) / n as f64).collect();
        let y: Vec<f64> = x
            .iter()
            .enumerate()
            .map(|(i, v)| (4.0 * v).cos() + 0.1 * (47.0 * v).sin() + 0.01 * (i % 3) as f64)
            .collect();
        let w: Vec<f64> = (0..n).map(|i| 1.0 + 0.5 * (i % 3) as f64).collect();
        let base_cols: Vec<Vec<f64>> = vec![vec![1.0; n], x.clone()];
        let mut series: Vec<Vec<f64>> =
            (1..=60).map(|k| x.iter().map(|v| (k as f64 * std::f64::consts::PI * v).cos()).collect()).collect();
        series[30] = x.clone();
        let b = OrthoBase::new(&base_cols, &w).unwrap();
        let whole = NestedSeries::new(&y, &w, &b, &series).unwrap();
        let blocks = NestedSeries::new(&y, &w, &b, &series[..20])
            .and_then(|s| s.extended(&y, &w, &series[..45]))
            .and_then(|s| s.extended(&y, &w, &series))
            .unwrap();
        assert_eq!(blocks.nested.used, whole.nested.used);
        assert!(!whole.nested.used.contains(&30));
        let scale = whole.nested.rss[0];
        for (a, b) in blocks.nested.rss.iter().zip(&whole.nested.rss) {
            assert!((a - b).abs() <= 1e-12 * scale, "{a} vs {b}");
        }
        assert_eq!(blocks.zy.len(), whole.zy.len());
        for (a, b) in blocks.zy.iter().zip(&whole.zy) {
            assert!((a - b).abs() <= 1e-10 * scale.sqrt(), "{a} vs {b}");
        }
        let (qa, qb) = (blocks.q(), whole.q());
        let diff =
            (0..qa.ncols()).flat_map(|j| (0..n).map(move |i| (i, j))).map(|(i, j)| (qa[(i, j)] - qb[(i, j)]).abs());
        assert!(diff.fold(0.0, f64::max) <= 1e-10);
        let extra = vec![x.iter().map(|v| (83.0 * v).sin()).collect::<Vec<f64>>()];
        let (ea, eb) = (blocks.with_extra(&extra, &w).unwrap(), whole.with_extra(&extra, &w).unwrap());
        assert_eq!(ea.rank, eb.rank);
        for (a, b) in ea.rss.iter().zip(&eb.rss) {
            assert!((a - b).abs() <= 1e-10 * scale, "{a} vs {b}");
        }
    }
}
