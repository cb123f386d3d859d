//! Fitting a model: linear parameters by weighted least squares, hyper-parameters searched.

use super::*;
use faer::linalg::matmul::matmul;
use faer::{Accum, Mat, Par};
use rayon::prelude::*;

// ------------------------------------------------------------------------------------------
// Fitting a model.

/// A fitted effect of the model: its shape, hyper-parameters and where its columns sit.
#[derive(Clone, Debug, PartialEq)]
pub(crate) struct FitTerm {
    pub(crate) index: usize,
    pub(crate) name: EffectName,
    pub(crate) shape: Shape,
    /// Hyper-parameter values and whether each is searched (not given).
    pub(crate) hyper: Vec<f64>,
    pub(crate) searched: Vec<bool>,
    /// Per hyper-parameter: a searched value that ends at a limit of its range (within 1 % of the
    /// step to the grid's next value, `at_grid_end`; the joint mode fit's box, coupled.rs): the
    /// criterion still improves beyond it, so it is a bound of the search, not an estimate.
    pub(crate) at_bound: Vec<bool>,
}

/// The result of fitting a model to the channels.
pub(crate) struct FitState {
    pub(crate) terms: Vec<FitTerm>,
    /// All linear columns: offsets first, then each term's.
    pub(crate) cols: Vec<Vec<f64>>,
    pub(crate) coefs: Vec<f64>,
    pub(crate) residual: Vec<f64>,
    pub(crate) n_offsets: usize,
    /// The data less the known (given) effects' predictions: what the linear columns fit.
    pub(crate) target: Vec<f64>,
    /// Per fitted error motion, how its shape was set.
    pub(crate) shapes: Vec<ShapeChoice>,
}

impl FitState {
    /// The linear columns that are not all zero: the parameters the fit has.
    pub(crate) fn nonzero_columns(&self) -> usize {
        self.cols.iter().filter(|c| c.iter().any(|v| *v != 0.0)).count()
    }

    /// The fitted error motions whose order BIC chose (the model gives none), with those orders.
    pub(crate) fn free_orders(&self) -> Vec<(EffectName, u32)> {
        self.shapes.iter().filter(|c| !c.given && c.max.is_some()).map(|c| (c.name, c.order)).collect()
    }

    /// BIC with σ unknown ([`bic_unknown_sigma`]) of this fit over n samples weighted by `w`,
    /// with its [`FitState::nonzero_columns`] as the linear parameters.
    pub(crate) fn bic_unknown_sigma(&self, w: &[f64], n: usize) -> f64 {
        bic_unknown_sigma(weighted_ss(&self.residual, w), n, self.nonzero_columns())
    }
}

/// The setup of an order search for the fitted motion `terms[ti]`: its model entry, the basis it asks
/// for (Legendre unless given), the span of its shape's range (m), and the design columns of every other
/// term (held while this motion's order is searched).
fn order_search_setup<'m>(
    st: &Stack,
    model: &'m Model,
    terms: &[FitTerm],
    ti: usize,
) -> (&'m ModelEffect, ShapeBasis, f64, Vec<Vec<f64>>) {
    let me = &model.effects[terms[ti].index];
    let basis = requested_basis(me).unwrap_or(ShapeBasis::Legendre);
    let span = {
        let r = shape(st, terms[ti].name, 1, 1, false).range;
        r.1 - r.0
    };
    let others: Vec<FitTerm> = terms.iter().enumerate().filter(|(i, _)| *i != ti).map(|(_, t)| t.clone()).collect();
    (me, basis, span, design(st, &others))
}

pub(crate) fn design(st: &Stack, terms: &[FitTerm]) -> Vec<Vec<f64>> {
    let mut cols = st.offsets();
    for t in terms {
        cols.extend(columns(st, t.name, &t.shape, &t.hyper));
    }
    cols
}

/// Drops columns that are all zero (an effect no channel sees) so the solver sees a clean design;
/// returns the kept indices. A large design ([`large_design`]: flexible shapes or time series) is
/// solved by pivoted QR (`lstsq_qr`, ≈ 2np² flops) instead of the SVD.
pub(crate) fn solve(r: &[f64], cols: &[Vec<f64>], sigma: &Sigma) -> Result<(Vec<f64>, Vec<f64>), ModelCheckError> {
    let keep: Vec<usize> = (0..cols.len()).filter(|&j| cols[j].iter().any(|v| *v != 0.0)).collect();
    let sub: Vec<Vec<f64>> = keep.iter().map(|&j| cols[j].clone()).collect();
    if sub.is_empty() {
        return Ok((vec![0.0; cols.len()], r.to_vec()));
    }
    let (coefficients, residual) = if large_design(r.len(), sub.len()) {
        let w = sigma.weights(r.len())?;
        lstsq_qr(r, &sub, &w)?
    } else {
        let fit = fit_signature(r, &sub, sigma)?;
        (fit.coefficients, fit.residual)
    };
    let mut beta = vec![0.0; cols.len()];
    for (k, &j) in keep.iter().enumerate() {
        beta[j] = if coefficients[k].is_finite() { coefficients[k] } else { 0.0 };
    }
    Ok((beta, residual))
}

/// [`solve`] block by block: channels are linked when some column is non-zero on both, and each
/// group of linked channels (its samples and the columns non-zero there) is an independent least
/// squares problem (e.g. a y and a z accelerometer with their own offsets and shapes), solved
/// alone. The same solution as one solve of the whole design, at a fraction of the cost of a
/// large one.
pub(crate) fn solve_blocks(
    st: &Stack,
    r: &[f64],
    cols: &[Vec<f64>],
    sigma: &Sigma,
) -> Result<(Vec<f64>, Vec<f64>), ModelCheckError> {
    let starts: Vec<usize> = st.channel_starts();
    let m = st.chans.len();
    let seen = |col: &[f64], j: usize| col[starts[j]..starts[j] + st.chans[j].y.len()].iter().any(|v| *v != 0.0);
    // Union-find over channels.
    let mut parent: Vec<usize> = (0..m).collect();
    fn root(p: &mut [usize], mut i: usize) -> usize {
        while p[i] != i {
            p[i] = p[p[i]];
            i = p[i];
        }
        i
    }
    for col in cols {
        let on: Vec<usize> = (0..m).filter(|&j| seen(col, j)).collect();
        for w in on.windows(2) {
            let (a, b) = (root(&mut parent, w[0]), root(&mut parent, w[1]));
            parent[a.max(b)] = a.min(b);
        }
    }
    let roots: Vec<usize> = (0..m).map(|j| root(&mut parent, j)).collect();
    let mut blocks: Vec<usize> = roots.clone();
    blocks.sort_unstable();
    blocks.dedup();
    if blocks.len() <= 1 || !large_design(r.len(), cols.len()) {
        return solve(r, cols, sigma);
    }
    let per = sigma.weights(r.len())?;
    let mut beta = vec![0.0; cols.len()];
    let mut residual = vec![0.0; r.len()];
    for b in blocks {
        let rows: Vec<usize> =
            (0..m).filter(|&j| roots[j] == b).flat_map(|j| starts[j]..starts[j] + st.chans[j].y.len()).collect();
        let pick = |v: &[f64]| rows.iter().map(|&i| v[i]).collect::<Vec<f64>>();
        let which: Vec<usize> = (0..cols.len()).filter(|&k| rows.iter().any(|&i| cols[k][i] != 0.0)).collect();
        let sub: Vec<Vec<f64>> = which.iter().map(|&k| pick(&cols[k])).collect();
        let sig_b = Sigma::PerSample(pick(&per).iter().map(|w| 1.0 / w).collect());
        let (bb, rb) = solve(&pick(r), &sub, &sig_b)?;
        for (k, v) in which.iter().zip(bb) {
            beta[*k] = v;
        }
        for (i, v) in rows.iter().zip(rb) {
            residual[*i] = v;
        }
    }
    Ok((beta, residual))
}

/// Number of design columns above which fits use QR and the hyper-parameter searches factor the
/// columns that do not change once (variable projection); the point tables stay below it.
pub(crate) const LARGE_DESIGN: usize = 100;

/// Number of samples above which a design of any width is treated as large: a time series of
/// 20 000 samples with 20 columns costs an SVD per evaluation of a hyper-parameter (≈ 40 per
/// golden-section search) where one QR of the fixed columns serves all; point tables (a few
/// hundred rows) stay below it.
pub(crate) const LARGE_SAMPLES: usize = 4000;

/// Whether a design of `rows` samples and `cols` columns is solved by QR and searched by
/// variable projection ([`LARGE_DESIGN`], [`LARGE_SAMPLES`]).
pub(crate) fn large_design(rows: usize, cols: usize) -> bool {
    cols > LARGE_DESIGN || rows > LARGE_SAMPLES
}

pub(crate) fn weighted_ss(r: &[f64], w: &[f64]) -> f64 {
    r.iter().zip(w).map(|(a, b)| (a * b).powi(2)).sum()
}

/// The minimum of f on [a, b] (a, b > 0) searched on a log scale: Brent's minimisation
/// (`vmt_estimators::modelcheck::brent_min`) of f(eˡ), l ∈ [ln a, ln b], l to √ε relative and
/// [`LINE_SEARCH_TOL`] absolute, at most `evals` evaluations. It replaced a golden-section search
/// of 42 evaluations (l to 2·10⁻⁹ absolute, finer than f resolves): a closed loop's kv took 11–15
/// on the benchmark's encoder set, 0.15 s less per fit.
pub(crate) fn line_minimum(a: f64, b: f64, evals: usize, f: &mut dyn FnMut(f64) -> f64) -> f64 {
    line_minimum_each(&[(a, b)], evals, &mut |xs| xs.iter().map(|&x| f(x)).collect())[0]
}

/// Absolute tolerance on ln x of [`line_minimum`]: 10⁻⁹ (the relative √ε ≈ 1.5·10⁻⁸ of ln x
/// rules unless ln x is near 0).
pub(crate) const LINE_SEARCH_TOL: f64 = 1e-9;

/// [`line_minimum`] on several intervals `ranges` in lockstep (`brent_min_each`): `f` gets the
/// next point of every search still running together and returns their values in order. Each
/// search ends where [`line_minimum`] alone would.
pub(crate) fn line_minimum_each(
    ranges: &[(f64, f64)],
    evals: usize,
    f: &mut dyn FnMut(&[f64]) -> Vec<f64>,
) -> Vec<f64> {
    let logs: Vec<(f64, f64)> = ranges.iter().map(|&(a, b)| (a.ln(), b.ln())).collect();
    let mut on_logs = |ls: &[f64]| -> Vec<f64> { f(&ls.iter().map(|l| l.exp()).collect::<Vec<f64>>()) };
    brent_min_each(&mut on_logs, &logs, LINE_SEARCH_TOL, evals).into_iter().map(|(l, _)| l.exp()).collect()
}

/// How a fitted error motion's shape was set (FORMAT.md §4 `shapes`).
#[derive(Clone, Debug, PartialEq)]
pub(crate) struct ShapeChoice {
    pub(crate) name: EffectName,
    /// The order used (highest Legendre degree).
    pub(crate) order: u32,
    /// The order BIC prefers on these data (= `order` when BIC chose it).
    pub(crate) best: u32,
    /// The model gave `order`.
    pub(crate) given: bool,
    /// Highest order searched by BIC (what the data support: m − 1 distinct positions, the
    /// [`LeadCap`] when the model fits a cyclic lead, [`MAX_ACCEL_ORDER`]); None when the order
    /// was not searched.
    pub(crate) max: Option<u32>,
    /// Seen only through accelerometers: its constant and slope have no acceleration and are
    /// pinned at 0 (not fitted).
    pub(crate) pinned: bool,
    /// The series' basis.
    pub(crate) basis: ShapeBasis,
    /// A sparse series: the number of terms selected of 1..=order (None: all of them).
    pub(crate) terms: Option<usize>,
    /// The order's cap against a cyclic lead (point tables), when a lead is fitted or searched.
    pub(crate) lead_cap: Option<LeadCap>,
}

/// BIC of a weighted residual sum of squares `ss` over n samples with p linear parameters,
/// σ unknown (Schwarz 1978): n·ln(ss/n) + p·ln n. Free of the stated σ's scale, so a σ stated
/// too small or missing does not change the chosen order.
pub(crate) fn bic_unknown_sigma(ss: f64, n: usize, p: usize) -> f64 {
    let nf = n as f64;
    nf * (ss.max(1e-300) / nf).ln() + p as f64 * nf.ln()
}

/// A fitted error motion's order held below what a cyclic lead of period P could be confused
/// with: a Legendre series of order K on a range of length L has K zeros, so its shortest
/// (mean) wavelength is ≈ 2L/K ([`ShapeBasis::shortest_wavelength`] for the other bases); it can
/// represent a wave of period P, and a lead and the shape are then separable on no data, once
/// 2L/K ≤ P. The cap is the largest K with 2L/K > P.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct LeadCap {
    /// The period P (m): the model's fitted cyclic lead's, or the longest period a `cyclic_lead`
    /// candidate is searched at on these positions.
    pub(crate) period: f64,
    /// The model fits the cyclic lead (else: the lead is a diagnose candidate).
    pub(crate) in_model: bool,
    /// The largest order K with 2L/K > P.
    pub(crate) order: u32,
    /// The order BIC prefers below the cap.
    pub(crate) capped_best: u32,
    /// The order BIC prefers over 1..m − 1 without the cap.
    pub(crate) free_best: u32,
    /// BIC (σ unknown, [`bic_unknown_sigma`]) at `free_best` minus at `capped_best` (≤ 0): what the
    /// orders beyond the cap gain.
    pub(crate) free_gain: f64,
    /// The series' basis and the length L (m) of its range.
    pub(crate) basis: ShapeBasis,
    pub(crate) span: f64,
}

impl LeadCap {
    /// The largest order (≤ `free_best`) whose shortest wavelength stays longer than `period` (m).
    pub(crate) fn order_below(&self, period: f64) -> u32 {
        (1..=self.free_best).take_while(|&o| self.basis.shortest_wavelength(self.span, o) > period).last().unwrap_or(1)
    }
}

/// The cyclic-lead period (m) that caps the order of the fitted error motions, with whether the
/// model fits the lead: the fitted lead's period (from `first`), or, when the model lacks a lead
/// that some channel's drive would show, the longest period the candidate is searched at
/// ([`hyper_grid`]). None when no lead is fitted or searched here.
pub(crate) fn lead_period(st: &Stack, model: &Model, first: &FitState) -> Option<(f64, bool)> {
    if let Some(t) = first.terms.iter().find(|t| t.name == EffectName::CyclicLead) {
        return t.hyper.first().copied().filter(|p| p.is_finite() && *p > 0.0).map(|p| (p, true));
    }
    if model.get(EffectName::CyclicLead, model.axis).is_some() || !st.chans.iter().any(|c| c.s_drive() != 0.0) {
        return None;
    }
    hyper_grid(st, EffectName::CyclicLead, Hyper::Period).0.last().map(|p| (*p, false))
}

/// The series basis a model asks for a fitted error motion (`basis`, FORMAT.md §2); None for
/// `poly` or none: the Legendre series (a cosine series where only accelerometers see it).
pub(crate) fn requested_basis(me: &ModelEffect) -> Option<ShapeBasis> {
    match me.basis {
        None | Some(Basis::Poly) => None,
        Some(Basis::Bspline) => Some(ShapeBasis::Bspline),
        Some(Basis::Harmonics) => Some(ShapeBasis::Harmonics),
        Some(Basis::Table) => Some(ShapeBasis::Table),
    }
}

/// First block of orders of a nested series search ([`order_curve`]): the block doubles while BIC's
/// best order lies in its second half.
pub(crate) const ORDER_BLOCK: u32 = 64;

/// Most coordinate-wise sweeps over a fit's searched hyper-parameters ([`fit_model_fixed`]):
/// each sweep is one grid search and golden-section refinement per value; they stop earlier once
/// no value moves.
pub(crate) const HYPER_SWEEPS_MAX: usize = 6;

/// Largest number of B-splines searched by BIC (each number is a separate fit, O(n·N²)).
pub(crate) const BSPLINE_SEARCH_MAX: u32 = 100;

/// The numbers of B-splines BIC compares, up to `max`: every N from 2 to 16, then steps of ≈ 15 %
/// (a B-spline series is not nested, so each N is its own fit; neighbouring N differ little).
pub(crate) fn bspline_orders(max: u32) -> Vec<u32> {
    let mut out: Vec<u32> = (2..=max.min(16)).collect();
    let mut n = 16.0_f64;
    while (n as u32) < max {
        n = (n * 1.15).ceil();
        out.push((n as u32).min(max));
    }
    out.dedup();
    out
}

/// The orders BIC chooses among for error motion `name` in `basis`, each with the weighted RSS of
/// `target` after the offsets and the other terms (`base`) and its series, and its number of linear
/// parameters: Legendre degrees 1..=`top` (`top` = m − 1) and harmonics 1..=(`top` − 1)/2 from the nested
/// sums of one QR (`nested_rss`; for harmonics only complete sine–cosine pairs); B-spline numbers
/// [`bspline_orders`] up to min(`top` + 1, [`BSPLINE_SEARCH_MAX`]), one fit each; a table only at one value per distinct
/// position (`top` + 1: its meaning, not a choice).
pub(crate) fn order_curve(
    st: &Stack,
    name: EffectName,
    basis: ShapeBasis,
    top: u32,
    target: &[f64],
    w: &[f64],
    base: &OrthoBase,
) -> Result<Vec<(u32, f64, usize)>, ModelCheckError> {
    match basis {
        ShapeBasis::Legendre | ShapeBasis::Cosine | ShapeBasis::Harmonics => {
            Ok(FactoredCurve::new(st, name, basis, top, target, w, base)?.curve)
        }
        ShapeBasis::Bspline | ShapeBasis::Table => {
            let orders: Vec<u32> = match basis {
                ShapeBasis::Table => vec![top + 1],
                _ => bspline_orders((top + 1).min(BSPLINE_SEARCH_MAX)),
            };
            // One QR per N (`nested_rss`, its last sum: the whole series; columns the targets
            // cannot determine are not counted).
            orders
                .into_par_iter()
                .map(|o| {
                    let nr = nested_rss(target, w, base, &series_columns(st, name, basis, o))?;
                    // index: `nested_rss` gives at least rss[0], the base alone.
                    Ok((o, nr.rss[nr.rss.len() - 1], base.rank() + nr.used.len()))
                })
                .collect()
        }
    }
}

/// The columns of error motion `name`'s series of user order `order` in `basis`.
fn series_columns(st: &Stack, name: EffectName, basis: ShapeBasis, order: u32) -> Vec<Vec<f64>> {
    let sh = shape(st, name, 1, order, false);
    let sh = if basis == ShapeBasis::Legendre { sh } else { sh.in_basis(st, basis, order) };
    columns(st, name, &sh, &[])
}

/// An [`order_curve`] of a nested series (Legendre, cosine, harmonics) with its last QR kept
/// ([`NestedSeries`]): the curve with other columns in the model — a diagnose candidate's, with
/// which the orders are chosen again ([`rechoose_orders`]) — then costs the candidate's columns
/// through the kept reflectors (O(n·k·c)), not another QR of n × k series columns (O(n·k²); about
/// 1.7 s at 512 orders on 19 910 samples, once per candidate).
pub(crate) struct FactoredCurve {
    /// The motion and its basis.
    name: EffectName,
    basis: ShapeBasis,
    /// m − 1, m the distinct positions: the highest order searched.
    top: u32,
    /// The series' columns factored: the block where the search stopped.
    block: u32,
    /// Rank of the base (offsets and the other terms).
    base_rank: usize,
    /// The other fitted motions' orders in the base (the curve serves a search with these only).
    others: Vec<(EffectName, u32)>,
    /// The series' QR after the base.
    series: NestedSeries,
    /// The curve with nothing else in the model.
    pub(crate) curve: Vec<(u32, f64, usize)>,
}

impl FactoredCurve {
    /// [`order_curve`] of a nested series, its QR kept: for Legendre and cosine series, the orders
    /// in doubling blocks (64, 128, …, `top`), one QR each (Legendre: each block's new columns
    /// factored below the ones before, [`NestedSeries::extended`]; a search to 512 orders on the
    /// benchmark's 19 910-sample encoder set took 0.94 s of QR as four whole QRs, 0.63 s so): the search stops at a block where BIC's
    /// best order lies in its first half (the orders after it, at least half the block, each cost
    /// ln n and none brought BIC back below). On an encoder log every sample is a distinct
    /// position, so `top` = m − 1 is thousands of orders: one QR of all of them (n × m) took
    /// minutes and gigabytes, where BIC's choice sits at tens. Harmonics: all of them at once.
    fn new(
        st: &Stack,
        name: EffectName,
        basis: ShapeBasis,
        top: u32,
        target: &[f64],
        w: &[f64],
        base: &OrthoBase,
    ) -> Result<FactoredCurve, ModelCheckError> {
        let mut k = match basis {
            ShapeBasis::Harmonics => (top.saturating_sub(1) / 2).max(1),
            _ => ORDER_BLOCK.min(top),
        };
        // The series' columns of the blocks before, kept (Legendre: a column's values are the
        // same bits whatever the order the basis is evaluated to, so a block adds only its own).
        let mut cols: Vec<Vec<f64>> = Vec::new();
        let mut last: Option<NestedSeries> = None;
        loop {
            if basis == ShapeBasis::Legendre {
                // index: column counts ≤ k, a u32 order (`top`), narrowed back.
                let new: Vec<u32> = (cols.len() as u32 + 1..=k).collect();
                cols.extend(columns(st, name, &shape(st, name, 1, k, false).selected(new), &[]));
            } else {
                cols = series_columns(st, name, basis, k);
            }
            // Legendre: the blocks before factored once, each further one below them
            // (`NestedSeries::extended`); other bases' columns change with the order.
            let series = match last.take().filter(|_| basis == ShapeBasis::Legendre) {
                Some(s) => s.extended(target, w, &cols)?,
                None => NestedSeries::new(target, w, base, &cols)?,
            };
            let nr = &series.nested;
            let curve = curve_entries(basis, &nr.rss, &nr.used, |m| base.rank() + m);
            if basis == ShapeBasis::Harmonics || block_ends(&curve, k, top, st.n) {
                return Ok(FactoredCurve {
                    name,
                    basis,
                    top,
                    block: k,
                    base_rank: base.rank(),
                    others: Vec::new(),
                    series,
                    curve,
                });
            }
            last = Some(series);
            k = (2 * k).min(top);
        }
    }

    /// The curve with the columns `extra` in the model as well (weighted by `w`), the blocks
    /// searched as [`FactoredCurve::new`] does up to order `top` (at most the curve's); `None`
    /// where that search goes past the block factored (the caller then searches with a QR of its
    /// own).
    fn with_extra(
        &self,
        extra: &[Vec<f64>],
        w: &[f64],
        n: usize,
        top: u32,
    ) -> Result<Option<Vec<(u32, f64, usize)>>, ModelCheckError> {
        let nr = self.series.with_extra(extra, w)?;
        let params = |m: usize| self.base_rank + m + nr.rank[m];
        if self.basis == ShapeBasis::Harmonics {
            return Ok(Some(curve_entries(self.basis, &nr.rss, &nr.used, params)));
        }
        let top = top.min(self.top);
        let mut k = ORDER_BLOCK.min(top);
        while k <= self.block {
            // The series of order k: the block's first k columns.
            // index: column indices compared with the order k (≤ top, a u32); nothing indexed.
            let taken = nr.used.iter().take_while(|&&u| u < k as usize).count();
            let curve = curve_entries(self.basis, &nr.rss[..=taken], &nr.used[..taken], params);
            if block_ends(&curve, k, top, n) {
                return Ok(Some(curve));
            }
            k = (2 * k).min(top);
        }
        Ok(None)
    }
}

/// The orders of a nested series' curve: per number m of series columns taken, (the order of the
/// m-th column taken, the lowest when none is, rss[m], `params(m)`); for harmonics only the
/// slope and complete sine–cosine pairs.
fn curve_entries(
    basis: ShapeBasis,
    rss: &[f64],
    used: &[usize],
    params: impl Fn(usize) -> usize,
) -> Vec<(u32, f64, usize)> {
    (0..rss.len())
        .filter_map(|k| {
            let index = if k == 0 { basis.top_index(1) } else { used[k - 1] as u32 + 1 };
            // Harmonics: the slope, then complete sine–cosine pairs (a cosine's odd index).
            let complete = k == 0 || basis != ShapeBasis::Harmonics || (index % 2 == 1 && index >= 3);
            complete.then(|| (basis.user_order(index).max(1), rss[k], params(k)))
        })
        .collect()
}

/// Whether a doubling order search stops at block `k` with `curve`: at `top`, where the nesting
/// stopped on a dependent column, or when BIC's best order is in the block's first half.
fn block_ends(curve: &[(u32, f64, usize)], k: u32, top: u32, n: usize) -> bool {
    let bic = |c: &(u32, f64, usize)| bic_unknown_sigma(c.1, n, c.2);
    let best = curve.iter().min_by(|a, b| bic(a).total_cmp(&bic(b))).map_or(1, |c| c.0);
    k >= top || curve.last().is_some_and(|c| c.0 < k) || 2 * best <= k
}

/// Fits the model (see [`fit_model_fixed`]); each fitted error motion whose model gives no `order`
/// gets the Legendre order that BIC (σ unknown, [`bic_unknown_sigma`]) prefers among 1..=m − 1,
/// m the distinct sample positions (the data cannot support more shape coefficients after the
/// offsets), from the nested residual sums of squares of one QR (`nested_rss`) with the offsets
/// and the other terms held at a first fit's columns (coordinate-wise, two sweeps when several
/// motions are fitted); then the model is refitted at the chosen orders with its searches.
///
/// Shape and cyclic lead are decided jointly ([`LeadCap`]): when the model fits a cyclic lead of
/// period P, the orders are searched only up to the cap (2L/K > P), so the shape cannot absorb the
/// lead; when the lead is a diagnose candidate, the fit keeps the order BIC prefers over 1..m − 1
/// and records the order below the cap (for the candidate's base) and what the orders beyond it
/// gain (`diagnose` weighs the lead against them). For a given `order` the preferred one is still
/// computed (a shape too stiff for the data is a finding). Data with accelerometer channels:
/// [`fit_orders_nested`].
pub(crate) fn fit_model_on(st: &Stack, model: &Model, sigma: &Sigma, w: &[f64]) -> Result<FitState, ModelCheckError> {
    fit_model_from(st, model, sigma, w, None)
}

/// [`fit_model_on`] again on a stack whose loop gains or interpolation shift an earlier fit
/// `earlier` of the same model set ([`fit_all`]'s refits): the same order search, started from
/// that fit's orders instead of [`DEFAULT_ORDER`] (on point tables and encoder logs; data with
/// accelerometer channels start as [`fit_model_on`]). The first fit of the search sets the terms
/// the orders are chosen against: at the default order a closed loop's kv comes out biased by the
/// stiff shape, and BIC then climbs to a few hundred orders before the next round brings them
/// back (generator draw 2046: orders up to 512 searched in each of four refits of 1.5–1.7 s that
/// chose 9, 6, 6 and 6; from the orders before, each refit takes 0.12 s).
pub(crate) fn refit_model_on(
    st: &Stack,
    model: &Model,
    sigma: &Sigma,
    w: &[f64],
    earlier: &FitState,
) -> Result<FitState, ModelCheckError> {
    fit_model_from(st, model, sigma, w, Some(earlier))
}

fn fit_model_from(
    st: &Stack,
    model: &Model,
    sigma: &Sigma,
    w: &[f64],
    earlier: Option<&FitState>,
) -> Result<FitState, ModelCheckError> {
    let default = |me: &ModelEffect| me.order.unwrap_or(DEFAULT_ORDER);
    let accel = st.chans.iter().any(|c| c.is_accel());
    let start = |me: &ModelEffect| match earlier.filter(|_| !accel && me.order.is_none()) {
        Some(e) => e.shapes.iter().find(|c| c.name == me.effect.name).map_or(default(me), |c| c.order),
        None => default(me),
    };
    let first = fit_model_fixed(st, model, sigma, w, &|_, me: &ModelEffect| (start(me), None))?;
    let m = distinct_positions(st).len() as u32;
    let top = m.saturating_sub(1).max(1);
    let motions: Vec<usize> = (0..first.terms.len()).filter(|&t| first.terms[t].name.is_error_motion()).collect();
    if accel {
        return fit_orders_nested(st, model, sigma, w, first, &motions);
    }
    if motions.is_empty() {
        return Ok(first);
    }
    let lead = lead_period(st, model, &first);
    let n = st.n;
    // The other terms' searched values (a servo loop's kv, a time constant) are those of a fit at
    // the default orders, which a stiff shape biases: the orders are chosen again once against the
    // fit at the chosen orders, and the model refitted if they move (a closed loop's coupling
    // through a biased kv made BIC take hundreds of orders that the refitted model rejected).
    // With such terms, the first round from the default orders searches the first block of a
    // doubling series' orders only (ORDER_BLOCK): against a fit at the default orders, a closed
    // loop's kv is far off (generator draw 2054: 38.6/s for 51.3) and BIC soaked up the lag's
    // misfit with 317 orders, searched to 1 024 (6.8 s of a 9.8 s diagnose), which the next round
    // brought back to 14. A refit from an earlier fit's orders searches them all: its kv is that
    // fit's (capped there, a hidden cyclic lead's 199 orders went to 64 and back up to 386 in
    // every refit, draw 2000: 58 s against 30 s).
    let others_searched =
        |fs: &FitState| fs.terms.iter().any(|t| !t.name.is_error_motion() && t.searched.iter().any(|s| *s));
    let first_block = earlier.is_none() && others_searched(&first);
    // The orders the first fit holds: a round that chooses them again keeps that fit (a refit at
    // them would be the same fit, and the next round the same choice).
    let user_orders = |terms: &[FitTerm]| -> BTreeMap<usize, u32> {
        motions.iter().map(|&ti| (terms[ti].index, terms[ti].shape.basis.user_order(terms[ti].shape.order))).collect()
    };
    let mut last: Option<BTreeMap<usize, u32>> = Some(user_orders(&first.terms));
    let mut round_fit = first;
    for round in 0..2 {
        let mut terms = round_fit.terms.clone();
        // Per motion: (order BIC prefers within the searched range, highest searched, lead cap).
        let mut best: BTreeMap<usize, (u32, u32, Option<LeadCap>)> = BTreeMap::new();
        let sweeps = if motions.len() > 1 { 2 } else { 1 };
        for _ in 0..sweeps {
            for &ti in &motions {
                let name = terms[ti].name;
                let (me, basis, span, mut fixed) = order_search_setup(st, model, &terms, ti);
                fixed.retain(|c| c.iter().any(|v| *v != 0.0));
                let base = OrthoBase::new(&fixed, w)?;
                // (user order, weighted RSS, linear parameters) of every order BIC may choose.
                let round_top = match basis {
                    ShapeBasis::Legendre | ShapeBasis::Cosine if round == 0 && first_block => top.min(ORDER_BLOCK),
                    ShapeBasis::Legendre
                    | ShapeBasis::Cosine
                    | ShapeBasis::Harmonics
                    | ShapeBasis::Bspline
                    | ShapeBasis::Table => top,
                };
                let curve = order_curve(st, name, basis, round_top, &round_fit.target, w, &base)?;
                let bic = |k: usize| bic_unknown_sigma(curve[k].1, n, curve[k].2);
                let argmin = |upto: u32| {
                    (0..curve.len())
                        .filter(|&k| curve[k].0 <= upto)
                        .min_by(|a, b| bic(*a).total_cmp(&bic(*b)))
                        .unwrap_or(0)
                };
                let searched = curve.last().map_or(1, |c| c.0);
                let k_free = argmin(u32::MAX);
                // A table represents any shape at its positions: no order separates it from a lead.
                let cap = lead.filter(|_| basis != ShapeBasis::Table).map(|(p, in_model)| {
                    let order =
                        (1..=searched).take_while(|&o| basis.shortest_wavelength(span, o) > p).last().unwrap_or(1);
                    let k_cap = argmin(order);
                    LeadCap {
                        period: p,
                        in_model,
                        order,
                        capped_best: curve[k_cap].0,
                        free_best: curve[k_free].0,
                        free_gain: bic(k_free) - bic(k_cap),
                        basis,
                        span,
                    }
                });
                let chosen = match cap {
                    Some(c) if c.in_model => c.capped_best,
                    _ => curve[k_free].0,
                };
                let max = match cap {
                    Some(c) if c.in_model => c.order.min(searched),
                    _ => searched,
                };
                best.insert(ti, (chosen, max, cap));
                let order = me.order.unwrap_or(chosen);
                terms[ti].shape = match requested_basis(me) {
                    Some(b) => shape(st, name, 1, order, false).in_basis(st, b, order),
                    None => shape(st, name, 1, order, false),
                };
            }
        }
        let chosen = user_orders(&terms);
        let unchanged = last.as_ref() == Some(&chosen);
        if !unchanged {
            round_fit = fit_model_fixed(st, model, sigma, w, &|index: usize, me: &ModelEffect| {
                (chosen.get(&index).copied().unwrap_or(default(me)), None)
            })?;
        }
        for c in round_fit.shapes.iter_mut() {
            if let Some(&(b, mx, cap)) = motions.iter().find(|&&ti| terms[ti].name == c.name).map(|ti| &best[ti]) {
                c.best = b;
                c.max = Some(mx);
                c.lead_cap = cap;
            }
        }
        // Nothing else searched: the other terms do not move with the orders.
        if unchanged || !others_searched(&round_fit) {
            break;
        }
        last = Some(chosen);
    }
    Ok(round_fit)
}

/// The orders of a model's fitted error motions re-chosen by BIC with a diagnose candidate in the
/// model (every candidate, every basis; point tables and friction sweeps, not data with
/// accelerometer channels, whose sparse series are chosen by [`fit_orders_nested`]): starting from
/// `start` (motion, order), coordinate-wise over the motions whose order the model does not give
/// (two sweeps when several), each from its [`order_curve`] with the offsets, the other terms at
/// their current orders and the candidate's columns `extra` held. A periodic candidate of period
/// `period` (m) caps every series but a table below it (shortest wavelength 2L/K > P,
/// [`LeadCap`]): a shape that could represent the wave would absorb it. Returns the orders and the
/// BIC with σ unknown, n·ln(RSS/n) + (rank + `k_extra`)·ln n ([`bic_unknown_sigma`]), of the model
/// with the candidate (rank: offsets, terms, series and candidate columns; `k_extra`: the
/// candidate's searched hyper-parameters).
pub(crate) fn rechoose_orders(
    st: &Stack,
    model: &Model,
    fs: &FitState,
    w: &[f64],
    extra: &[Vec<f64>],
    k_extra: usize,
    period: Option<f64>,
    start: &[(EffectName, u32)],
    factored: &[FactoredCurve],
) -> Result<(Vec<(EffectName, u32)>, f64), ModelCheckError> {
    let top = (distinct_positions(st).len() as u32).saturating_sub(1).max(1);
    let mut orders: Vec<(EffectName, u32)> = start.to_vec();
    let mut terms = terms_at(st, model, fs, &orders);
    let sweeps = if orders.len() > 1 { 2 } else { 1 };
    let mut bic = bic_unknown_sigma(weighted_ss(&fs.residual, w), st.n, fs.cols.len() + extra.len() + k_extra);
    for _ in 0..sweeps {
        for slot in 0..orders.len() {
            let name = orders[slot].0;
            let Some(ti) = terms.iter().position(|t| t.name == name) else { continue };
            let (me, basis, span, mut fixed) = order_search_setup(st, model, &terms, ti);
            // The motion's curve with the same other orders factored already: the candidate's
            // columns through its QR; else a QR of the series after the base holding them.
            let allowed = |o: u32| {
                basis == ShapeBasis::Table || period.is_none_or(|p| basis.shortest_wavelength(span, o) > p) || o == 1
            };
            // The orders of a series in doubling blocks (Legendre, cosine: user order = columns)
            // above the highest allowed are not searched: the blocks below it end as they would
            // without the limit, and BIC's choice is among the allowed orders.
            let top_allowed = match basis {
                ShapeBasis::Legendre | ShapeBasis::Cosine => (1..=top).take_while(|&o| allowed(o)).last().unwrap_or(1),
                ShapeBasis::Harmonics | ShapeBasis::Bspline | ShapeBasis::Table => top,
            };
            let others: Vec<(EffectName, u32)> = orders.iter().filter(|(m, _)| *m != name).copied().collect();
            let shared = factored.iter().find(|c| c.name == name && c.basis == basis && c.others == others);
            let curve = match shared.map(|c| c.with_extra(extra, w, st.n, top_allowed)).transpose()?.flatten() {
                Some(curve) => curve,
                None => {
                    fixed.extend(extra.iter().cloned());
                    fixed.retain(|c| c.iter().any(|v| *v != 0.0));
                    let base = OrthoBase::new(&fixed, w)?;
                    order_curve(st, name, basis, top_allowed, &fs.target, w, &base)?
                }
            };
            let score = |k: usize| bic_unknown_sigma(curve[k].1, st.n, curve[k].2 + k_extra);
            let Some(k) =
                (0..curve.len()).filter(|&k| allowed(curve[k].0)).min_by(|a, b| score(*a).total_cmp(&score(*b)))
            else {
                continue;
            };
            bic = score(k);
            orders[slot].1 = curve[k].0;
            terms[ti].shape = shape_at(st, me, curve[k].0);
        }
    }
    Ok((orders, bic))
}

/// The fit's terms with the motions `orders` names at those orders (in the basis their model entry
/// asks for).
fn terms_at(st: &Stack, model: &Model, fs: &FitState, orders: &[(EffectName, u32)]) -> Vec<FitTerm> {
    let mut terms = fs.terms.clone();
    for t in terms.iter_mut() {
        if let Some((_, o)) = orders.iter().find(|(m, _)| *m == t.name) {
            t.shape = shape_at(st, &model.effects[t.index], *o);
        }
    }
    terms
}

/// The shape of model entry `me`'s motion at user order `order`, in the basis the entry asks for.
fn shape_at(st: &Stack, me: &ModelEffect, order: u32) -> Shape {
    match requested_basis(me) {
        Some(b) => shape(st, me.effect.name, 1, order, false).in_basis(st, b, order),
        None => shape(st, me.effect.name, 1, order, false),
    }
}

/// Per fitted motion of `orders` (motion, order: the model's fitted error motions whose order it
/// does not give), its [`order_curve`] after the offsets and the other terms at `orders`, factored
/// ([`FactoredCurve`]) for [`rechoose_orders`] with each candidate of a diagnosis: the curves of
/// its first sweep (and of later ones where the other orders stay) then cost no QR of a series.
/// Series that are not nested (B-splines, a table) have none.
pub(crate) fn factored_curves(
    st: &Stack,
    model: &Model,
    fs: &FitState,
    w: &[f64],
    orders: &[(EffectName, u32)],
) -> Result<Vec<FactoredCurve>, ModelCheckError> {
    let top = (distinct_positions(st).len() as u32).saturating_sub(1).max(1);
    let terms = terms_at(st, model, fs, orders);
    let mut out = Vec::new();
    for &(name, _) in orders {
        let Some(ti) = terms.iter().position(|t| t.name == name) else { continue };
        let (_, basis, _, mut fixed) = order_search_setup(st, model, &terms, ti);
        if matches!(basis, ShapeBasis::Bspline | ShapeBasis::Table) {
            continue;
        }
        fixed.retain(|c| c.iter().any(|v| *v != 0.0));
        let base = OrthoBase::new(&fixed, w)?;
        let mut curve = FactoredCurve::new(st, name, basis, top, &fs.target, w, &base)?;
        curve.others = orders.iter().filter(|(m, _)| *m != name).copied().collect();
        out.push(curve);
    }
    Ok(out)
}

/// The greedy selection of a cosine series ([`greedy_rss`]) stops after 20 terms in a row that
/// each explain less than this many times the residual mean square (BIC charges ln n ≥ 5 each).
pub(crate) const GREEDY_STOP: f64 = 1.0;

/// Largest number of values (columns × samples) of the series searched for one error motion
/// (memory: 8 bytes each, 512 MB, held about three times during the search). Below the
/// wavelengths it lets the series reach, a guideway's waviness stays in the residual, where its
/// strongest line can win the mode search: at 20 M, a 100 000-sample set at 10 kHz (three passes
/// over 0.42 m) reached only 8.5 mm (99 frequencies) under a waviness of 4–40 mm, and `diagnose`
/// put a 32.54 Hz mode (ζ 0.0306) at 74.17 Hz (ζ 0.0050, peak memory 1.8 GB); at 64 M it reaches
/// 2.6 mm (319 frequencies) and finds 32.79 Hz, ζ 0.0264 (peak memory 2.8 GB, 252 s of CPU).
pub(crate) const MAX_SERIES_VALUES: usize = 64_000_000;

/// The joint choice of a shape's order and a cyclic lead's period (`diagnose`, [`LeadCap`]).
#[derive(Clone, Debug, PartialEq)]
pub(crate) struct LeadScan {
    /// The lead period P* (m) of the lowest joint BIC.
    pub(crate) period: f64,
    /// Per binding motion, its order in that joint fit (the scanned motion's chosen by BIC below
    /// its cap at P*, the others held at their orders below the cap at the longest period).
    pub(crate) orders: Vec<(EffectName, u32)>,
    /// BIC (σ unknown) of the lead at P* with the shapes at `orders`, minus that of the shapes
    /// alone at the orders BIC prefers without a lead (the model as fitted): < 0 favours the lead.
    pub(crate) delta_bic: f64,
    /// Number of periods scanned.
    pub(crate) scanned: usize,
}

/// Local minima of the lead scan's grid refined ([`lead_shape_scan`]).
pub(crate) const LEAD_SCAN_MINIMA: usize = 8;

/// Periods per e-fold of the lead scan ([`lead_shape_scan`]): steps of 0.25 %, so that a lead
/// over 25 periods drifts by at most 25·2π·0.00125 ≈ 0.2 rad between a grid point and the truth.
pub(crate) const LEAD_SCAN_PER_E: f64 = 400.0;

/// Periods of the lead scan ([`lead_shape_scan`]) whose products with the nested series are formed
/// together: 16 periods (32 columns) per read of the series.
pub(crate) const LEAD_SCAN_CHUNK: usize = 16;

/// Scans the cyclic lead's periods P over [p_lo, p_hi] (m) jointly with the order of the first
/// binding motion's series (a nested basis: Legendre or harmonics): for every P, every order K with
/// shortest wavelength > P ([`LeadCap::order_below`]) is scored by BIC with σ unknown,
/// n·ln(RSS/n) + (rank + K + 3)·ln n (the lead's sine, cosine and period), where the RSS comes from
/// one orthonormal nested basis of the series (its Householder QR off the other columns,
/// [`NestedSeries`], the other binding motions held at their orders below the cap at p_hi) and a
/// 2 × 2 solve per (P, K) (variable projection). The grid's best minima are refined by
/// Brent's searches between their neighbours, run in lockstep ([`line_minimum_each`]: one matrix
/// product per round for all of them; 22 rounds on the benchmark's encoder sets, where golden
/// section took 31). Compared with the shapes alone at their free BIC order.
/// None when the motion's basis is not nested (B-splines, table) or nothing is scanned.
pub(crate) fn lead_shape_scan(
    st: &Stack,
    fs: &FitState,
    binding: &[(EffectName, LeadCap)],
    w: &[f64],
    (p_lo, p_hi): (f64, f64),
) -> Result<Option<LeadScan>, ModelCheckError> {
    let Some(&(m0, cap0)) = binding.first() else { return Ok(None) };
    if !matches!(cap0.basis, ShapeBasis::Legendre | ShapeBasis::Harmonics) || !(p_hi > p_lo) {
        return Ok(None);
    }
    let held: Vec<(EffectName, u32)> = binding[1..].iter().map(|(m, l)| (*m, l.order_below(p_hi))).collect();
    let mut terms = fs.terms.clone();
    for t in terms.iter_mut() {
        if let Some((_, o)) = held.iter().find(|(m, _)| *m == t.name) {
            let sh = shape(st, t.name, 1, *o, false);
            t.shape = if t.shape.basis == ShapeBasis::Legendre { sh } else { sh.in_basis(st, t.shape.basis, *o) };
        }
    }
    let others: Vec<FitTerm> = terms.iter().filter(|t| t.name != m0).cloned().collect();
    let fixed: Vec<Vec<f64>> = design(st, &others).into_iter().filter(|c| c.iter().any(|v| *v != 0.0)).collect();
    let base = OrthoBase::new(&fixed, w)?;
    let top = cap0.free_best;
    let sh = shape(st, m0, 1, top, false);
    let sh = if cap0.basis == ShapeBasis::Legendre { sh } else { sh.in_basis(st, cap0.basis, top) };
    // The series' nested orthonormal directions q_j (weighted, off the base: `NestedSeries`), with
    // the user order each one completes; t = W·target off the base, qt_j = q_jᵀt, rss the nested sums.
    let series = NestedSeries::new(&fs.target, w, &base, &columns(st, m0, &sh, &[]))?;
    let q_index: Vec<u32> = series.nested.used.iter().map(|&j| j as u32 + 1).collect();
    let q_order: Vec<u32> = q_index.iter().map(|&j| cap0.basis.user_order(j)).collect();
    let qt = series.qty().to_vec();
    let rss = series.nested.rss.clone();
    let qm = series.q();
    drop(series);
    let t = base.project_vector(&fs.target, w);
    let n = st.n;
    let rb = base.rank();
    // A basis vector completes an order only at a harmonic's cosine (complete pairs, odd index ≥ 3).
    let complete =
        |k: usize| k == 0 || cap0.basis != ShapeBasis::Harmonics || (q_index[k - 1] % 2 == 1 && q_index[k - 1] >= 3);
    let order_of = |k: usize| if k == 0 { 1 } else { q_order[k - 1] };
    let free = (0..rss.len())
        .filter(|&k| complete(k))
        .map(|k| bic_unknown_sigma(rss[k], n, rb + k))
        .fold(f64::INFINITY, f64::min);
    let lead_shape = shape(st, EffectName::CyclicLead, 1, DEFAULT_ORDER, false);
    let t_dot = |a: &[f64]| a.iter().zip(&t).map(|(x, y)| x * y).sum::<f64>();
    // The order below the cap at the longest period: a base every period shares.
    let k_long = (0..rss.len()).rev().find(|&k| order_of(k) <= cap0.order_below(p_hi)).unwrap_or(0);
    // One period's (BIC, K) and power from its projected columns (cp0, cp1) and their products with
    // the series (columns j and j + 1 of m).
    let joint_at = |p: f64, cp0: &[f64], cp1: &[f64], m: &Mat<f64>, j: usize| -> ((f64, usize), f64) {
        let dot = |a: &[f64], b: &[f64]| a.iter().zip(b).map(|(x, y)| x * y).sum::<f64>();
        let (mut g00, mut g01, mut g11) = (dot(cp0, cp0), dot(cp0, cp1), dot(cp1, cp1));
        let (mut b0, mut b1) = (t_dot(cp0), t_dot(cp1));
        let limit = cap0.order_below(p);
        let mut best = (f64::INFINITY, 0);
        let mut power = 0.0;
        for k in 0..rss.len() {
            if k > 0 {
                let (c0, c1) = (m[(k - 1, j)], m[(k - 1, j + 1)]);
                g00 -= c0 * c0;
                g01 -= c0 * c1;
                g11 -= c1 * c1;
                b0 -= c0 * qt[k - 1];
                b1 -= c1 * qt[k - 1];
            }
            if order_of(k) > limit && k > k_long {
                break;
            }
            let det = g00 * g11 - g01 * g01;
            let explained = if det > 1e-12 * (g00 * g11).max(1e-300) {
                (g11 * b0 * b0 - 2.0 * g01 * b0 * b1 + g00 * b1 * b1) / det
            } else {
                0.0
            };
            if k == k_long {
                power = explained;
            }
            if order_of(k) > limit || !complete(k) {
                continue;
            }
            let b = bic_unknown_sigma((rss[k] - explained).max(0.0), n, rb + k + 3);
            if b < best.0 {
                best = (b, k);
            }
        }
        (best, power)
    };
    // The directions' products with a chunk of periods' columns, c_k = q_kᵀ·cp, come from one
    // matrix product (the series read once per chunk: per period, K dot products of n values each
    // read it all, and the scan spent half of a hidden lead's diagnose there), over the directions
    // the chunk's periods reach: below each one's cap, and all up to `k_long`.
    let reach = |p: f64| {
        let limit = cap0.order_below(p);
        (1..rss.len()).find(|&k| order_of(k) > limit && k > k_long).unwrap_or(rss.len() - 1)
    };
    // Per period p of `ps`: (BIC, K) of the lead at p with the best order K below its cap, and the
    // weighted sum of squares the lead explains over the orders up to `k_long` (a periodogram with
    // these columns).
    let joint_and_power = |ps: &[f64]| -> Vec<((f64, usize), f64)> {
        // The sine and cosine columns of each period.
        let hs: Vec<&[f64]> = ps.iter().map(std::slice::from_ref).collect();
        let raw: Vec<Vec<f64>> = columns_each(st, EffectName::CyclicLead, &lead_shape, &hs)
            .into_iter()
            .flat_map(|cols| cols.into_iter().take(2))
            .collect();
        let cp = base.projected_independent(&raw, w);
        let rows = ps.iter().map(|&p| reach(p)).max().unwrap_or(0);
        let mut m = Mat::<f64>::zeros(rows, raw.len());
        matmul(m.as_mut(), Accum::Replace, qm.get(.., ..rows).transpose(), cp.as_ref(), 1.0, Par::Seq);
        ps.iter()
            .enumerate()
            .map(|(i, &p)| joint_at(p, cp.col_as_slice(2 * i), cp.col_as_slice(2 * i + 1), &m, 2 * i))
            .collect()
    };
    // index: (p_lo, p_hi) is the catalogue's lead range (`period_range`: 2–60 mm, ratio ≤ 30), so at most
    // ln(30)·400 ≈ 1 361 periods.
    let count = (((p_hi / p_lo).ln() * LEAD_SCAN_PER_E).ceil() as usize).max(2);
    let grid = log_grid(p_lo, p_hi, count);
    // In fixed chunks of periods (the same bits on any number of threads).
    let scored: Vec<((f64, usize), f64)> = grid.par_chunks(LEAD_SCAN_CHUNK).flat_map_iter(joint_and_power).collect();
    let scores: Vec<(f64, usize)> = scored.iter().map(|s| s.0).collect();
    let power: Vec<f64> = scored.iter().map(|s| s.1).collect();
    // The grid's lowest local minima, each refined by golden-section search between its neighbours: a
    // strong lead's dip is narrower than a grid step at high signal-to-noise (its phase drifts by
    // 2π·(L/P)·δP/P over the travel), so its grid point can score worse than a distant minimum until
    // refined.
    let mut minima: Vec<usize> = (0..grid.len())
        .filter(|&i| {
            let s = scores[i].0;
            (i == 0 || s <= scores[i - 1].0) && (i + 1 == grid.len() || s <= scores[i + 1].0)
        })
        .collect();
    minima.sort_by(|a, b| scores[*a].0.total_cmp(&scores[*b].0).then(a.cmp(b)));
    minima.truncate(LEAD_SCAN_MINIMA);
    // And the periods where a lead explains most over the shapes of the longest period's cap (the
    // periodogram's peaks): a strong lead there scores badly on the grid (its dip is narrower than a
    // step) but its main lobe, 1/(periods over the travel) wide, holds grid points.
    let mut peaks: Vec<usize> = (0..grid.len())
        .filter(|&i| (i == 0 || power[i] >= power[i - 1]) && (i + 1 == grid.len() || power[i] >= power[i + 1]))
        .collect();
    peaks.sort_by(|a, b| power[*b].total_cmp(&power[*a]).then(a.cmp(b)));
    for i in peaks.into_iter().take(LEAD_SCAN_MINIMA / 2) {
        if !minima.contains(&i) {
            minima.push(i);
        }
    }
    // The searches in lockstep (`line_minimum_each`): each round's periods in one batch, so that the
    // series is read once per round instead of once per search and period.
    let ranges: Vec<(f64, f64)> =
        minima.iter().map(|&i| (grid[i.saturating_sub(1)], grid[(i + 1).min(grid.len() - 1)])).collect();
    // In fixed chunks of LEAD_SCAN_CHUNK / 4 periods side by side (the same bits on any number of
    // threads).
    let joint_each = |ps: &[f64]| -> Vec<(f64, usize)> {
        ps.par_chunks(LEAD_SCAN_CHUNK / 4).flat_map_iter(|c| joint_and_power(c).into_iter().map(|s| s.0)).collect()
    };
    let ps = line_minimum_each(&ranges, 32, &mut |ps| joint_each(ps).into_iter().map(|s| s.0).collect());
    let refined: Vec<(f64, (f64, usize))> = minima
        .iter()
        .zip(ps.iter().zip(joint_each(&ps)))
        .map(|(&i, (&p, jp))| if jp.0 < scores[i].0 { (p, jp) } else { (grid[i], scores[i]) })
        .collect();
    let Some(&(p, (bic, k))) = refined.iter().min_by(|a, b| a.1 .0.total_cmp(&b.1 .0)) else { return Ok(None) };
    let mut orders = vec![(m0, order_of(k))];
    orders.extend(held);
    Ok(Some(LeadScan { period: p, orders, delta_bic: bic - free, scanned: grid.len() }))
}

/// Highest number of frequencies searched for an error motion seen only by accelerometers (cost
/// cap; wavelengths down to 2L/600, 2 mm on a 0.6 m travel).
pub(crate) const MAX_ACCEL_ORDER: u32 = 600;

/// The highest index 2 + 2N of the series ([`ShapeBasis::Cosine`]: P_3, P_4, then a cosine and a
/// sine per frequency) of error motion `name` that the accelerometer channels seeing it resolve:
/// the shortest wavelength 2L/N (L the range) must span at least two sample spacings |v|·Δt of
/// the pass that samples the position most finely (the Nyquist condition in position), and N <
/// the distinct positions seen; N capped at [`MAX_ACCEL_ORDER`], at a quarter of the samples that
/// see the motion and by [`MAX_SERIES_VALUES`].
pub(crate) fn resolvable_order(st: &Stack, name: EffectName, range: (f64, f64)) -> u32 {
    let seeing: Vec<&Channel> = st.chans.iter().filter(|c| c.s_motion(name) != 0.0).collect();
    let rows: usize = seeing.iter().map(|c| c.y.len()).sum();
    let mut xs: Vec<f64> = seeing.iter().flat_map(|c| c.x.iter().copied()).collect();
    xs.sort_by(f64::total_cmp);
    xs.dedup();
    let dx = seeing
        .iter()
        .filter_map(|c| {
            let mut d: Vec<f64> = (1..c.t.len()).map(|i| (c.v[i] * (c.t[i] - c.t[i - 1])).abs()).collect();
            d.retain(|v| *v > 0.0);
            d.sort_by(f64::total_cmp);
            d.get(d.len() / 2).copied()
        })
        .fold(f64::INFINITY, f64::min);
    // Cosines: cos(kπ(x − a)/L) has the wavelength 2L/k ≥ 2·dx for k ≤ L/dx.
    let by_spacing = if dx.is_finite() { ((range.1 - range.0) / dx).floor() } else { f64::INFINITY };
    let cap = (MAX_ACCEL_ORDER as f64).min(by_spacing).min(xs.len().saturating_sub(1) as f64).min((rows / 4) as f64);
    // Indices: P_3, P_4, then a cosine and a sine per frequency; the dictionary's values (columns
    // × samples) held to [`MAX_SERIES_VALUES`].
    let by_memory = ((MAX_SERIES_VALUES / st.n.max(1)) as f64 / 2.0 - 1.0).floor();
    (2.0 + 2.0 * cap.min(by_memory).max(1.0)) as u32
}

/// The order choice of [`fit_model_on`] on data with accelerometer channels: for each fitted
/// error motion, BIC with σ unknown, n_m·ln(RSS_k/n_m) + (rank + k)·ln n_m, over the orders 1..N
/// ([`resolvable_order`]) from the nested residual sums of squares of one QR (`nested_rss`),
/// on the n_m samples of the channels that see the motion, with the offsets and every other term
/// held at their columns (a column shared with other channels is refitted on these samples
/// alone). The constant and slope of a motion seen only by accelerometers have no acceleration:
/// their columns are zero there and they are not fitted (pinned at 0, said in the report).
/// A `gravity_tilt` in the model has each accelerometer's degree chosen after the motions
/// ([`choose_tilt_orders`]). Coordinate-wise over the motions, then the tilt, two sweeps when
/// several motions share a channel or a tilt's degree rose above the one the motions were chosen
/// against; then the model is refitted at the chosen orders with its searches.
fn fit_orders_nested(
    st: &Stack,
    model: &Model,
    sigma: &Sigma,
    w: &[f64],
    first: FitState,
    motions: &[usize],
) -> Result<FitState, ModelCheckError> {
    let mut terms = first.terms.clone();
    // A `gravity_tilt` (a model gives it no `order`): its degree chosen per accelerometer as well.
    let tilt = (0..terms.len()).find(|&t| terms[t].name == EffectName::GravityTilt);
    if motions.is_empty() && tilt.is_none() {
        return Ok(first);
    }
    let mut best: BTreeMap<usize, (u32, u32)> = BTreeMap::new();
    // A second sweep when two motions share a channel (else each choice is independent), or when a
    // sensor's tilt came out of a higher degree than the one the motions were chosen against: what
    // the higher terms take, the motions may have taken in their place (generator draw 1004 of
    // `accel_hidden_roll`: degree 4 after a cubic; without the second sweep the roll was 2.8 × its
    // bound, with it 0.4 ×). A tilt of that degree or lower leaves the motions as chosen (on the
    // draws 5000–5029 of that study, a second sweep then moved the roll's error by at most 0.15 of
    // its bound, and a second choice of the motions costs about 1 s of CPU on 15 000 samples).
    let shared = motions.len() > 1
        && st.chans.iter().any(|c| motions.iter().filter(|&&ti| c.s_motion(first.terms[ti].name) != 0.0).count() > 1);
    let n_sensors = accel_sensors(st).len();
    let degrees = |terms: &[FitTerm]| -> Vec<u32> {
        tilt.map_or(vec![], |ti| (0..n_sensors).map(|s| terms[ti].shape.tilt_order(s)).collect())
    };
    let rows_of = |name: EffectName| -> Vec<usize> {
        let mut out = Vec::new();
        let mut k = 0;
        for c in st.chans {
            if c.s_motion(name) != 0.0 {
                out.extend(k..k + c.y.len());
            }
            k += c.y.len();
        }
        out
    };
    // Motion `ti`'s order chosen against the other terms of `terms`: (the order chosen, the
    // highest searched, its shape).
    let choose = |terms: &[FitTerm], ti: usize| -> Result<(u32, u32, Shape), ModelCheckError> {
        let name = terms[ti].name;
        let rows = rows_of(name);
        let range = shape(st, name, 1, 1, false).range;
        let top = resolvable_order(st, name, range);
        let others: Vec<FitTerm> = terms.iter().enumerate().filter(|(i, _)| *i != ti).map(|(_, t)| t.clone()).collect();
        let pick = |v: &[f64]| rows.iter().map(|&i| v[i]).collect::<Vec<f64>>();
        let fixed: Vec<Vec<f64>> =
            design(st, &others).iter().map(|c| pick(c)).filter(|c| c.iter().any(|v| *v != 0.0)).collect();
        // The series on the rows that see the motion. Seen by accelerometers alone, its columns
        // read each sample and nothing of the stack (no loop): they are built on a stack of those
        // channels (half the values of the whole stack's columns with two sensors); else the whole
        // stack's columns, each dropped once its rows are picked.
        let sh = shape(st, name, 1, top, false);
        let seeing: Vec<Channel> = st.chans.iter().filter(|c| c.s_motion(name) != 0.0).cloned().collect();
        let series: Vec<Vec<f64>> = if !seeing.is_empty() && seeing.iter().all(|c| c.is_accel()) {
            columns(&Stack::new(&seeing), name, &sh, &[])
        } else {
            columns(st, name, &sh, &[]).into_iter().map(|c| pick(&c)).collect()
        };
        drop(seeing);
        let (orders, nested): (Vec<u32>, Vec<Vec<f64>>) = series
            .into_iter()
            .enumerate()
            .map(|(k, c)| (k as u32 + 1, c))
            .filter(|(_, c)| c.iter().any(|v| *v != 0.0))
            .unzip();
        let wr = pick(w);
        let y = pick(&first.target);
        let base = OrthoBase::new(&fixed, &wr)?;
        let me = &model.effects[terms[ti].index];
        let sparse = sh.basis == ShapeBasis::Cosine && me.order.is_none();
        // The order in which the series enters: by degree (nested orders), or for a cosine series
        // greedily, each step the term that explains most of what is left (rail waviness puts the
        // signal at a few high orders, where nesting by degree would charge every order below
        // it; at the fast pass the short waves alias, so the terms are not orthogonal there).
        let nr = if sparse {
            greedy_rss(&y, &wr, &base, &nested, GREEDY_STOP)?
        } else {
            nested_rss(&y, &wr, &base, &nested)?
        };
        let nm = rows.len() as f64;
        let bic = |k: usize| nm * (nr.rss[k].max(1e-300) / nm).ln() + (base.rank() + k) as f64 * nm.ln();
        let k = (0..nr.rss.len()).min_by(|a, b| bic(*a).total_cmp(&bic(*b))).unwrap_or(0);
        let searched = orders.iter().copied().max().unwrap_or(1);
        if sparse {
            // The terms taken (at least the best one), in ascending order.
            let mut sel: Vec<u32> = nr.used[..k.max(1).min(nr.used.len())].iter().map(|&j| orders[j]).collect();
            sel.sort_unstable();
            if sel.is_empty() {
                sel.push(1);
            }
            let chosen = *sel.last().unwrap_or(&1);
            Ok((chosen, searched, shape(st, name, 1, chosen, false).selected(sel)))
        } else {
            // k series columns taken: the order of the k-th (1 when none is needed); the columns
            // the offsets span (P_2 per pass on accelerometers) are skipped but kept in the series.
            let chosen = if k == 0 { 1 } else { orders[nr.used[k - 1]] };
            Ok((chosen, searched, shape(st, name, 1, me.order.unwrap_or(chosen), false)))
        }
    };
    for sweep in 0..2 {
        let against = degrees(&terms);
        if shared {
            for &ti in motions {
                let (chosen, searched, sh) = choose(&terms, ti)?;
                best.insert(ti, (chosen, searched));
                terms[ti].shape = sh;
            }
        } else {
            // Independent choices (no channel sees two of the motions): each on its own thread.
            let out: Vec<Result<(u32, u32, Shape), ModelCheckError>> =
                motions.par_iter().map(|&ti| choose(&terms, ti)).collect();
            for (&ti, r) in motions.iter().zip(out) {
                let (chosen, searched, sh) = r?;
                best.insert(ti, (chosen, searched));
                terms[ti].shape = sh;
            }
        }
        if let Some(ti) = tilt {
            terms[ti].shape = choose_tilt_orders(st, &terms, ti, &first.target, w)?;
        }
        let rose = degrees(&terms).iter().zip(&against).any(|(now, was)| now > was);
        if sweep == 1 || !(shared || rose) {
            break;
        }
    }
    // Per model entry: the order and, for a motion, its sparse selection; for the tilt, each
    // accelerometer's degree.
    let mut chosen: BTreeMap<usize, (u32, Option<Vec<u32>>)> =
        motions.iter().map(|&ti| (terms[ti].index, (terms[ti].shape.order, terms[ti].shape.select.clone()))).collect();
    if let Some(ti) = tilt {
        chosen.insert(terms[ti].index, (terms[ti].shape.order, Some(terms[ti].shape.tilt_orders.clone())));
    }
    let default = |me: &ModelEffect| me.order.unwrap_or(DEFAULT_ORDER);
    let mut fs = fit_model_fixed(st, model, sigma, w, &|index: usize, me: &ModelEffect| {
        chosen.get(&index).cloned().unwrap_or((default(me), None))
    })?;
    for c in fs.shapes.iter_mut() {
        if let Some(&(b, m)) = motions.iter().find(|&&ti| terms[ti].name == c.name).map(|ti| &best[ti]) {
            c.best = b;
            c.max = Some(m);
            c.pinned = st.chans.iter().filter(|ch| ch.s_motion(c.name) != 0.0).all(|ch| ch.is_accel());
        }
    }
    Ok(fs)
}

/// Highest Legendre degree of an accelerometer's `gravity_tilt` that BIC may choose
/// ([`choose_tilt_orders`]): a roll or pitch of correlation length ≥ 0.1 m over a travel of up to
/// 1 m is within a few hundredths of a µrad at degree 20, and the monomials are still written
/// ([`MONOMIAL_MAX_ORDER`]).
pub(crate) const TILT_MAX_ORDER: u32 = 20;

/// The `gravity_tilt` of term `ti` with each accelerometer's Legendre degree chosen by BIC with σ
/// unknown, n_s·ln(RSS_k/n_s) + (rank + k)·ln n_s, over the degrees 3..N (N: [`TILT_MAX_ORDER`],
/// at most the distinct positions less one and a quarter of the samples, and every sensor's
/// columns within [`MAX_SERIES_VALUES`]) from the nested residual
/// sums of one QR (`nested_rss`) on the n_s samples of that sensor, with the offsets and every other
/// term held at their columns (the other sensors' tilts are nil there). A fixed cubic cannot follow
/// a wavy roll at piezo-level noise: what it misses is taken up by the flexible straightness and
/// biases the tilt (generator draw 5011: 2.6 × the roll's Cramér–Rao bound).
fn choose_tilt_orders(
    st: &Stack,
    terms: &[FitTerm],
    ti: usize,
    target: &[f64],
    w: &[f64],
) -> Result<Shape, ModelCheckError> {
    let sensors = accel_sensors(st);
    let others: Vec<FitTerm> = terms.iter().enumerate().filter(|(i, _)| *i != ti).map(|(_, t)| t.clone()).collect();
    let fixed_all = design(st, &others);
    // Every sensor's columns span the stack: their values held to [`MAX_SERIES_VALUES`].
    let by_memory =
        u32::try_from(MAX_SERIES_VALUES / st.n.max(1).saturating_mul(sensors.len().max(1))).unwrap_or(u32::MAX);
    let mut orders = Vec::with_capacity(sensors.len());
    for (s, name) in sensors.iter().enumerate() {
        let mut rows = Vec::new();
        let mut xs = Vec::new();
        let mut k = 0;
        for c in st.chans {
            if c.sensor == *name && c.is_accel() {
                rows.extend(k..k + c.y.len());
                xs.extend(c.x.iter().take(c.y.len()).copied());
            }
            k += c.y.len();
        }
        xs.sort_by(f64::total_cmp);
        xs.dedup();
        let pick = |v: &[f64]| rows.iter().map(|&i| v[i]).collect::<Vec<f64>>();
        let fixed: Vec<Vec<f64>> = fixed_all.iter().map(|c| pick(c)).filter(|c| c.iter().any(|v| *v != 0.0)).collect();
        let (wr, y) = (pick(w), pick(target));
        let base = OrthoBase::new(&fixed, &wr)?;
        let top =
            TILT_MAX_ORDER.min(xs.len().saturating_sub(1) as u32).min((rows.len() / 4) as u32).min(by_memory).max(1);
        let only: Vec<u32> = (0..sensors.len()).map(|j| if j == s { top } else { 0 }).collect();
        let sh = terms[ti].shape.clone().with_tilt_orders(&sensors, only);
        let series: Vec<Vec<f64>> = columns(st, EffectName::GravityTilt, &sh, &[]).iter().map(|c| pick(c)).collect();
        let nr = nested_rss(&y, &wr, &base, &series)?;
        let nm = rows.len() as f64;
        let bic = |k: usize| nm * (nr.rss[k].max(1e-300) / nm).ln() + (base.rank() + k) as f64 * nm.ln();
        // At least the cubic (DEFAULT_ORDER) where the samples allow it; series column j is degree
        // j + 1. A lower degree, chosen against the shapes and a mode's columns as fitted apart,
        // left a roll unfitted once the mode was coupled to the shapes (generator draw 5020 of
        // `accel_hidden_resonance_and_roll`: degree 1, normalised RMS 1.32 after both were added,
        // 0.98 with the cubic).
        // index: DEFAULT_ORDER is the constant 3, widened; the range below is over `nr.rss` itself.
        let k_min = (DEFAULT_ORDER as usize).min(nr.rss.len().saturating_sub(1)).max(1);
        let k = (k_min..nr.rss.len()).min_by(|a, b| bic(*a).total_cmp(&bic(*b))).unwrap_or(0);
        orders.push(if k == 0 { 1 } else { nr.used[k - 1] as u32 + 1 });
    }
    Ok(terms[ti].shape.clone().with_tilt_orders(&sensors, orders))
}

/// Fits the model with each fitted error motion's Legendre order from `order_of(effect index, effect)`
/// (the order and a sparse selection of the series; for `gravity_tilt`, each accelerometer's
/// degree in place of the selection): linear parameters by weighted least squares,
/// hyper-parameters searched (module doc).
pub(crate) fn fit_model_fixed(
    st: &Stack,
    model: &Model,
    sigma: &Sigma,
    w: &[f64],
    order_of: &dyn Fn(usize, &ModelEffect) -> (u32, Option<Vec<u32>>),
) -> Result<FitState, ModelCheckError> {
    fit_model_orders(st, model, sigma, w, order_of, None)
}

/// [`fit_model_fixed`] with the hyper-parameters of every term that is not an error motion held
/// at their values in `held` (a fit of the same model): the model's shapes refitted at other
/// orders, for a candidate to be ranked against (`diagnose`). Refitted without the candidate, a
/// loop gain kv absorbs part of what the candidate explains (a strong cyclic lead seen through a
/// closed loop biased kv, and then the lead's period, by 1e-4), which the candidate's linear
/// columns cannot undo.
pub(crate) fn fit_model_held(
    st: &Stack,
    model: &Model,
    sigma: &Sigma,
    w: &[f64],
    order_of: &dyn Fn(usize, &ModelEffect) -> (u32, Option<Vec<u32>>),
    held: &FitState,
) -> Result<FitState, ModelCheckError> {
    fit_model_orders(st, model, sigma, w, order_of, Some(held))
}

/// Whether a model effect's linear parts are fitted: every effect with `fit = true`, and a given
/// resonance or gravity_tilt (a model states a mode's frequency and damping, a tilt has no
/// parameter of its own, never their linear parts: the mode shape at each sensor, its free
/// vibration, a sensor's tilt polynomial; those are fitted with the stated values held).
fn linear_parts_fitted(me: &ModelEffect) -> bool {
    me.fit || matches!(me.effect.name, EffectName::Resonance | EffectName::GravityTilt)
}

/// The prediction of a model's given effects (those whose linear parts are not fitted,
/// [`linear_parts_fitted`]) at every sample of `st`, each through the stack's closed loop
/// ([`known_prediction`]).
pub(crate) fn given_prediction(st: &Stack, model: &Model) -> Vec<f64> {
    let mut known = vec![0.0; st.n];
    for me in &model.effects {
        if me.effect.axis != model.axis || !predicts(me.effect.name) || linear_parts_fitted(me) {
            continue;
        }
        // The simulator's friction law (`vmt_sim::effects::Model::friction`): a given Stribeck
        // law carries the Coulomb level (its `fc`, unset: the coulomb effect's), so a given
        // coulomb beside a given stribeck adds nothing of its own (it would count Fc twice).
        let stribeck_known = model.get(EffectName::Stribeck, model.axis).is_some_and(|s| !s.fit);
        if me.effect.name == EffectName::Coulomb && stribeck_known {
            continue;
        }
        let mut e = me.effect.clone();
        if let EffectParams::Stribeck(sp) = &mut e.params {
            // The simulator's law: stribeck.fc unset takes the coulomb level.
            if sp.fc.is_none() {
                sp.fc = model.get(EffectName::Coulomb, model.axis).and_then(|c| c.effect.params.get("fc"));
            }
        }
        for (k, v) in known_prediction(st, &e).into_iter().enumerate() {
            known[k] += v;
        }
    }
    known
}

fn fit_model_orders(
    st: &Stack,
    model: &Model,
    sigma: &Sigma,
    w: &[f64],
    order_of: &dyn Fn(usize, &ModelEffect) -> (u32, Option<Vec<u32>>),
    held: Option<&FitState>,
) -> Result<FitState, ModelCheckError> {
    let known = given_prediction(st, model);
    let mut terms: Vec<FitTerm> = Vec::new();
    for (index, me) in model.effects.iter().enumerate() {
        if me.effect.axis != model.axis || !predicts(me.effect.name) || !linear_parts_fitted(me) {
            continue;
        }
        let (order, select) = order_of(index, me);
        let mut sh = shape(st, me.effect.name, 1, order, lacks_coulomb(model));
        if let Some(sel) = select {
            sh = match me.effect.name {
                EffectName::GravityTilt => sh.with_tilt_orders(&accel_sensors(st), sel),
                _ => sh.selected(sel),
            };
        }
        let sh = match requested_basis(me) {
            Some(b) => sh.in_basis(st, b, order),
            None => sh,
        };
        let mut hyper = Vec::new();
        let mut searched = Vec::new();
        for &h in &sh.hypers {
            let given = !me.fit || me.given.iter().any(|g| g == h.as_str());
            let start = me.effect.params.get(h.as_str()).unwrap_or(1.0);
            // A given period (screw lead, signal period) is held; a given τ is a starting value.
            // A damping that these data cannot resolve (no predicted excitation) is held. Every
            // hyper-parameter of an effect with `fit = false` is held.
            let resolvable = h != Hyper::Damping || hyper_grid(st, me.effect.name, h).1;
            hyper.push(if given || !resolvable { start } else { f64::NAN });
            // A given period or Stribeck shape exponent is held (the diagnosis searched it).
            searched.push(me.fit && !(given && matches!(h, Hyper::Period | Hyper::Shape)) && resolvable);
        }
        if let Some(h) = held.and_then(|h| h.terms.iter().find(|t| t.index == index && !t.name.is_error_motion())) {
            if h.hyper.len() == hyper.len() {
                hyper.clone_from(&h.hyper);
                searched.iter_mut().for_each(|s| *s = false);
            }
        }
        let at_bound = vec![false; hyper.len()];
        terms.push(FitTerm { index, name: me.effect.name, shape: sh, hyper, searched, at_bound });
    }
    let y = st.y();
    let r0: Vec<f64> = y.iter().zip(&known).map(|(a, b)| a - b).collect();
    // Start every searched hyper-parameter in the middle of its grid (or at its given value), then
    // sweep: per hyper-parameter a grid search and a golden-section refinement, the others held.
    let grids: Vec<Vec<(Vec<f64>, bool)>> = terms
        .iter()
        .map(|t| {
            (0..t.hyper.len())
                .map(|hi| {
                    let v = t.hyper[hi];
                    if v.is_finite() && t.shape.hypers[hi] == Hyper::Frequency {
                        // A given mode frequency is a starting value: ±5 % in 41 steps.
                        ((0..41).map(|k| v * (0.95 + 0.0025 * k as f64)).collect(), true)
                    } else if v.is_finite() {
                        (log_grid(v / 10.0, v * 10.0, 21), true)
                    } else if t.name == EffectName::InterpolationError {
                        // A signal period not stated: chosen from the data (`interpolation_periods`).
                        interpolation_periods(st, &r0, w)
                            .map(|(g, _)| (g, true))
                            .unwrap_or_else(|| hyper_grid(st, t.name, t.shape.hypers[hi]))
                    } else {
                        hyper_grid(st, t.name, t.shape.hypers[hi])
                    }
                })
                .collect()
        })
        .collect();
    for (t, g) in terms.iter_mut().zip(&grids) {
        for (hi, (grid, _)) in g.iter().enumerate() {
            if t.hyper[hi].is_nan() {
                // An empty grid: no period these positions resolve; 0 makes the columns vanish.
                t.hyper[hi] = grid.get(grid.len() / 2).copied().unwrap_or(0.0);
                t.searched[hi] &= !grid.is_empty();
            }
        }
    }
    let n_searched: usize = terms.iter().map(|t| t.searched.iter().filter(|s| **s).count()).sum();
    // Coordinate-wise sweeps until no searched value moves (relative 1e-9), at most
    // [`HYPER_SWEEPS_MAX`]: coupled values (a closed loop's kv and the play the loop drives
    // through) were left apart after two sweeps — a play 12 % under its coefficient, whose
    // take-up then missed the data by 0.9 µm at a reversal (an independent encoder draw, seed 2007).
    let sweeps = if n_searched > 1 { HYPER_SWEEPS_MAX } else { 1 };
    // A large design (flexible shapes on time series): the columns that no search changes (offsets,
    // shapes, terms without a searched hyper-parameter) are factored once, and each evaluation
    // projects only the searched terms' columns (variable projection, `OrthoBase`).
    let moving = |t: &FitTerm| t.searched.iter().any(|s| *s);
    // Accelerometer passes are always searched so (a mode's columns are its response to the
    // excitation; the shapes' columns, evaluated at every sample, do not change with it).
    let accel = st.chans.iter().any(|c| c.is_accel());
    let by_projection =
        n_searched > 0 && (accel || st.n > LARGE_SAMPLES || large_design(st.n, design(st, &terms).len()));
    // Searched so, the columns of the terms no search moves, per term (None for a moving one, and
    // for every term otherwise): the fixed base's, and the final design's as they are.
    let held_cols: Vec<Option<Vec<Vec<f64>>>> =
        terms.iter().map(|t| (by_projection && !moving(t)).then(|| columns(st, t.name, &t.shape, &t.hyper))).collect();
    let fixed_base = if by_projection {
        let fixed: Vec<Vec<f64>> =
            st.offsets().into_iter().chain(held_cols.iter().flatten().flatten().cloned()).collect();
        let base = OrthoBase::new(&fixed, w)?;
        let target = base.project_vector(&r0, w);
        Some((base, target))
    } else {
        None
    };
    for _ in 0..sweeps {
        let before: Vec<Vec<f64>> = terms.iter().map(|t| t.hyper.clone()).collect();
        for ti in 0..terms.len() {
            for hi in 0..terms[ti].hyper.len() {
                if !terms[ti].searched[hi] {
                    continue;
                }
                let (grid, refine) = &grids[ti][hi];
                let eval = |v: f64, terms: &mut Vec<FitTerm>| -> f64 {
                    terms[ti].hyper[hi] = v;
                    if let Some((base, target)) = &fixed_base {
                        let cols: Vec<Vec<f64>> = terms
                            .iter()
                            .filter(|t| moving(t))
                            .flat_map(|t| columns(st, t.name, &t.shape, &t.hyper))
                            .collect();
                        return base.residual_ss(target, &cols, w);
                    }
                    match solve(&r0, &design(st, terms), sigma) {
                        Ok((_, r)) => weighted_ss(&r, w),
                        Err(_) => f64::INFINITY,
                    }
                };
                // The grid in parallel (rayon), the best taken in grid order: the same on any
                // number of threads.
                let values: Vec<f64> = grid
                    .par_iter()
                    .map(|&g| {
                        let mut tt = terms.clone();
                        eval(g, &mut tt)
                    })
                    .collect();
                let mut best = (f64::INFINITY, grid[0]);
                for (&g, &s) in grid.iter().zip(&values) {
                    if s < best.0 {
                        best = (s, g);
                    }
                }
                let mut v = best.1;
                if *refine && grid.len() > 1 {
                    let k = grid.iter().position(|g| *g == best.1).unwrap_or(0);
                    let a = grid[k.saturating_sub(1)];
                    let b = grid[(k + 1).min(grid.len() - 1)];
                    let mut tt = terms.clone();
                    v = line_minimum(a, b, 42, &mut |x| eval(x, &mut tt));
                    if eval(v, &mut terms) > best.0 {
                        v = best.1;
                    }
                }
                terms[ti].hyper[hi] = v;
            }
        }
        let moved =
            terms.iter().zip(&before).any(|(t, b)| t.hyper.iter().zip(b).any(|(x, y)| (x - y).abs() > 1e-9 * y.abs()));
        if !moved {
            break;
        }
    }
    if accel {
        refine_jointly(st, &mut terms, &grids, &r0, sigma, w, fixed_base.as_ref());
    }
    // A searched, refined value at an end of its grid is a bound, not an estimate.
    for (t, g) in terms.iter_mut().zip(&grids) {
        t.at_bound =
            (0..t.hyper.len()).map(|hi| t.searched[hi] && g[hi].1 && at_grid_end(&g[hi].0, t.hyper[hi])).collect();
    }
    // The design ([`design`]) with the held columns as they are.
    let mut cols = st.offsets();
    for (t, held) in terms.iter().zip(held_cols) {
        cols.extend(held.unwrap_or_else(|| columns(st, t.name, &t.shape, &t.hyper)));
    }
    let (coefs, residual) = solve_blocks(st, &r0, &cols, sigma)?;
    let shapes = terms
        .iter()
        .filter(|t| t.name.is_error_motion())
        .map(|t| {
            let given = model.effects[t.index].order.is_some();
            let order = t.shape.basis.user_order(t.shape.order);
            ShapeChoice {
                name: t.name,
                order,
                best: order,
                given,
                max: None,
                pinned: false,
                basis: t.shape.basis,
                terms: t.shape.select.as_ref().map(Vec::len),
                lead_cap: None,
            }
        })
        .collect();
    Ok(FitState { terms, cols, coefs, residual, n_offsets: st.n_groups, target: r0, shapes })
}

/// Joint refinement of the searched, refinable hyper-parameters of a fit on accelerometer data (a
/// fitted resonance's frequency and damping) after the coordinate-wise grid and golden-section
/// sweeps: Levenberg–Marquardt over variable projection (`refine_projected`, the solver `diagnose`
/// refines its candidates with), inside the box between the grid neighbours of each current value,
/// so that `compare` (and `compare` after `add`) reports the same kind of optimum as `diagnose`.
/// The projected residual is P⊥(θ)·W·r0: with `fixed` (the factored unchanging columns and the
/// projected target) only the moving terms' columns are projected, else the whole design is solved.
/// Kept only when it lowers the weighted RSS.
fn refine_jointly(
    st: &Stack,
    terms: &mut [FitTerm],
    grids: &[Vec<(Vec<f64>, bool)>],
    r0: &[f64],
    sigma: &Sigma,
    w: &[f64],
    fixed: Option<&(OrthoBase, Vec<f64>)>,
) {
    let free: Vec<(usize, usize)> = terms
        .iter()
        .enumerate()
        .flat_map(|(ti, t)| {
            (0..t.hyper.len())
                .filter(move |&hi| t.searched[hi] && grids[ti][hi].1 && grids[ti][hi].0.len() > 1)
                .map(move |hi| (ti, hi))
        })
        .collect();
    if free.is_empty() {
        return;
    }
    let bracket = |ti: usize, hi: usize, x: f64| -> (f64, f64) {
        let mut g = grids[ti][hi].0.clone();
        g.sort_by(f64::total_cmp);
        let i = g.partition_point(|v| *v < x).min(g.len() - 1);
        (g[i.saturating_sub(1)].min(x), g[(i + 1).min(g.len() - 1)].max(x))
    };
    let start: Vec<f64> = free.iter().map(|&(ti, hi)| terms[ti].hyper[hi]).collect();
    let (lo, hi): (Vec<f64>, Vec<f64>) = free.iter().zip(&start).map(|(&(ti, h), &x)| bracket(ti, h, x)).unzip();
    let base_terms: Vec<FitTerm> = terms.to_vec();
    let ones = vec![1.0; w.len()];
    let resid = |x: &[f64]| -> Result<Vec<f64>, ModelCheckError> {
        let mut tt = base_terms.clone();
        for (&(ti, hi), v) in free.iter().zip(x) {
            tt[ti].hyper[hi] = *v;
        }
        match fixed {
            Some((base, target)) => {
                let moving: Vec<Vec<f64>> = tt
                    .iter()
                    .filter(|t| t.searched.iter().any(|s| *s))
                    .flat_map(|t| columns(st, t.name, &t.shape, &t.hyper))
                    .collect();
                let pc = base.project_columns(&moving, w);
                let ob = OrthoBase::new(&pc, &ones)?;
                Ok(ob.project_vector(target, &ones))
            }
            None => {
                let (_, r) = solve(r0, &design(st, &tt), sigma)?;
                Ok(r.iter().zip(w).map(|(r, w)| r * w).collect())
            }
        }
    };
    if let Some((theta, _)) = refine_projected_point(&resid, None, &start, (&lo, &hi), 40, DIFFERENCE_STEP) {
        for (&(ti, hi), v) in free.iter().zip(&theta) {
            terms[ti].hyper[hi] = *v;
        }
    }
}

/// The linear coefficients of term `ti` of a fit (they follow the offsets, term by term).
pub(crate) fn term_coefs(fs: &FitState, ti: usize) -> &[f64] {
    let start = fs.n_offsets + fs.terms[..ti].iter().map(|t| t.shape.coefs.len()).sum::<usize>();
    &fs.coefs[start..start + fs.terms[ti].shape.coefs.len()]
}

/// The mode excitations of `st` plus, on every accelerometer channel, one input per fitted
/// translation error motion (EXX, EYX, EZX) of the fit `fs` (`Excitation::of_fitted`): a
/// structural mode is driven by the guideway the data show. None when no fitted translation
/// gives an input.
pub(crate) fn fitted_excitation(st: &Stack, fs: &FitState) -> Option<Vec<Vec<Excitation>>> {
    let translation = EffectName::is_translational;
    // A channel's tables depend on its times, positions and speeds only: the sensors of one pass
    // share them, and the first of each such group computes them for all.
    let same = |a: &Channel, b: &Channel| a.is_accel() && b.is_accel() && a.t == b.t && a.x == b.x && a.v == b.v;
    let first_of: Vec<usize> =
        (0..st.chans.len()).map(|j| (0..j).find(|&k| same(&st.chans[k], &st.chans[j])).unwrap_or(j)).collect();
    // The groups' tables in parallel (each is ≈ 10⁴ evaluations of the shapes' slopes per second of
    // record, `mode_steps`), collected in channel order.
    let fitted: Vec<Vec<Excitation>> = (0..st.chans.len())
        .into_par_iter()
        .map(|j| {
            if first_of[j] != j {
                return Vec::new();
            }
            fs.terms
                .iter()
                .enumerate()
                .filter(|(_, t)| translation(t.name))
                .filter_map(|(ti, t)| Excitation::of_fitted(&st.chans[j], &t.shape, term_coefs(fs, ti)))
                .collect()
        })
        .collect();
    let added = fitted.iter().any(|f| !f.is_empty());
    added.then(|| {
        st.excitation
            .iter()
            .take(fitted.len())
            .enumerate()
            // index: first_of[j] ≤ j < the channel count.
            .map(|(j, given)| given.iter().chain(&fitted[first_of[j]]).cloned().collect())
            .collect()
    })
}

/// The fitted parameters of each term as effect parameters (FORMAT.md §2 keys).
pub(crate) fn term_params(fs: &FitState, model: &Model) -> EffectMap<BTreeMap<String, f64>> {
    let mut out = EffectMap::new();
    let mut j = fs.n_offsets;
    for t in &fs.terms {
        let k = t.shape.coefs.len();
        let c = &fs.coefs[j..j + k];
        j += k;
        let me = &model.effects[t.index];
        out.insert(t.name, describe(t.name, &t.shape, c, &t.hyper, &me.effect.params));
    }
    // A Stribeck term without its own Fc rides on the model's Coulomb level: fs = Fc + (Fs − Fc).
    if let Some(t) = fs.terms.iter().find(|t| t.name == EffectName::Stribeck && !t.shape.with_fc) {
        let own = model.effects[t.index].effect.params.get("fc").unwrap_or(0.0);
        let fc = coulomb_level(model, &out) - own;
        if let Some(v) = out.get_mut(EffectName::Stribeck).and_then(|m| m.get_mut("fs")) {
            *v += fc;
        }
    }
    out
}

/// Highest Legendre degree whose series is also written as monomials c_j·x^j: above it the
/// conversion's rounding (binomial sums of (2/(b − a))^j) swamps the coefficients.
pub(crate) const MONOMIAL_MAX_ORDER: u32 = 20;

/// Linear coefficients + hyper-parameters → the effect's parameters by FORMAT.md §2 key.
pub(crate) fn describe(
    name: EffectName,
    sh: &Shape,
    c: &[f64],
    h: &[f64],
    start: &EffectParams,
) -> BTreeMap<String, f64> {
    let mut m = BTreeMap::new();
    match name {
        n if n.is_error_motion() => {
            // The Legendre series as monomials c_j·x^j (FORMAT.md §2 keys); c0 is left out (the
            // per-channel offsets carry the constant).
            // index: `first_power` (0, 1 or 2) is a u32 widened to name a coefficient, not a size.
            match sh.basis {
                // The monomials c_j (rounding grows with the order: only up to
                // [`MONOMIAL_MAX_ORDER`]), and always the series itself, p_k on [x_lo, x_hi].
                ShapeBasis::Legendre => {
                    if sh.order <= MONOMIAL_MAX_ORDER {
                        for (j, v) in legendre_to_monomials(sh.first_power, c, sh.range).into_iter().enumerate().skip(1)
                        {
                            m.insert(format!("c{j}"), v);
                        }
                    }
                    for (i, v) in c.iter().enumerate() {
                        m.insert(format!("p{}", sh.first_power as usize + i), *v);
                    }
                    m.insert("x_lo".into(), sh.range.0);
                    m.insert("x_hi".into(), sh.range.1);
                }
                // Σ b_k·B_k(x) (k ≥ 1; b_0 = 0, the offsets carry the constant), knots over [x_lo, x_hi].
                ShapeBasis::Bspline => {
                    for (i, v) in c.iter().enumerate() {
                        m.insert(format!("b{}", sh.first_power as usize + i), *v);
                    }
                    m.insert("n_splines".into(), (sh.order + 1) as f64);
                    m.insert("x_lo".into(), sh.range.0);
                    m.insert("x_hi".into(), sh.range.1);
                }
                // FORMAT.md §2 `poly = [0, slope]` (about x_lo) and `harmonics` entries:
                // a_s·sin θ + a_c·cos θ = A·sin(θ + φ).
                ShapeBasis::Harmonics => {
                    m.insert("slope".into(), c.first().copied().unwrap_or(0.0));
                    m.insert("x_lo".into(), sh.range.0);
                    for (h, pair) in c.get(1..).unwrap_or(&[]).chunks(2).enumerate() {
                        let (a_s, a_c) = (pair[0], pair.get(1).copied().unwrap_or(0.0));
                        let k = h + 1;
                        m.insert(format!("h{k}_amplitude"), a_s.hypot(a_c));
                        m.insert(format!("h{k}_wavelength"), 2.0 * (sh.range.1 - sh.range.0) / k as f64);
                        m.insert(format!("h{k}_phase"), a_c.atan2(a_s));
                    }
                }
                // FORMAT.md §2 `table`: the value at each position (the first 0: offsets).
                ShapeBasis::Table => {
                    for (k, x) in sh.knots.iter().enumerate() {
                        m.insert(format!("x{k}"), *x);
                        m.insert(format!("v{k}"), if k == 0 { 0.0 } else { c.get(k - 1).copied().unwrap_or(0.0) });
                    }
                }
                // Σ cos_k·cos(kπ(x − x_lo)/(x_hi − x_lo)), m (no monomials: hundreds of terms).
                ShapeBasis::Cosine => {
                    // φ_1 = P_3, φ_2 = P_4 of u = (2x − x_lo − x_hi)/(x_hi − x_lo), then cosines.
                    for (v, k) in c.iter().zip(sh.ks()) {
                        let key = match k {
                            k @ (1 | 2) => format!("p{}", k + 2),
                            k if (k - 3) % 2 == 0 => format!("cos{}", (k - 3) / 2 + 1),
                            k => format!("sin{}", (k - 3) / 2 + 1),
                        };
                        m.insert(key, *v);
                    }
                    m.insert("x_lo".into(), sh.range.0);
                    m.insert("x_hi".into(), sh.range.1);
                }
            }
        }
        EffectName::CyclicLead | EffectName::InterpolationError => {
            m.insert("period".into(), h[0]);
            m.insert("amplitude".into(), c[0].hypot(c[1]));
            m.insert("phase".into(), c[1].atan2(c[0]));
        }
        EffectName::ThermalExpansion => {
            let alpha = start.get("alpha").filter(|a| *a != 0.0).unwrap_or(ALPHA_STEEL);
            m.insert("alpha".into(), alpha);
            m.insert("delta_t".into(), c[0] / alpha);
            m.insert("tau".into(), h[0]);
        }
        EffectName::ThermalDrift => {
            m.insert("value".into(), c[0]);
            m.insert("tau".into(), h[0]);
        }
        EffectName::Coulomb => {
            m.insert("fc".into(), c[0]);
        }
        EffectName::Viscous => {
            m.insert("fv".into(), c[0]);
        }
        EffectName::Stribeck => {
            // fs = Fc + (Fs − Fc); Fc is this fit's own (with_fc) or the model's coulomb level.
            let fc = if sh.with_fc { c[1] } else { start.get("fc").unwrap_or(0.0) };
            if sh.with_fc {
                m.insert("fc".into(), fc);
            }
            m.insert("fs".into(), fc + c[0]);
            m.insert("vs".into(), h[0]);
            m.insert("shape".into(), h[1]);
        }
        EffectName::Resonance => {
            // Frequency and damping; the forced response's gain per sensor (the mode shape φ at
            // the sensor, dimensionless); the RMS amplitude of the narrow-band segments, m/s².
            m.insert("frequency".into(), h[0]);
            m.insert("damping".into(), h[1]);
            let mut seg: Vec<f64> = Vec::new();
            for (k, v) in sh.coefs.iter().zip(c) {
                if k.starts_with("gain_") {
                    m.insert(k.clone(), *v);
                } else if k.starts_with("sin_") || k.starts_with("cos_") {
                    seg.push(*v);
                }
            }
            if !seg.is_empty() {
                let rms = (seg.iter().map(|v| v * v).sum::<f64>() / seg.len() as f64).sqrt();
                m.insert("amplitude_rms".into(), rms * std::f64::consts::SQRT_2 / 2.0);
            }
            let _ = start;
        }
        EffectName::ServoLag => {
            // Position-loop gain kv, 1/s; gain = 1 − velocity feed-forward fraction.
            m.insert("kv".into(), h[0]);
            m.insert("gain".into(), c[0]);
        }
        EffectName::GravityTilt => {
            // Tilt of each sensor's sensitive axis, rad: its Legendre series Σ_k p_k·P_k(u) on
            // [x_lo, x_hi] (`tilt_{sensor}_p{k}`), and the same as monomials Σ_j c_j·x^j, x in m
            // (`tilt_{sensor}_c{j}`, up to [`MONOMIAL_MAX_ORDER`]); the offsets carry the constant.
            // Each sensor's degree (its `{sensor}_p1..` coefficients, in order).
            let degrees: Vec<usize> = match sh.tilt_orders.as_slice() {
                [] => vec![sh.order as usize; sh.coefs.len() / (sh.order as usize).max(1)],
                own => own.iter().map(|&k| k as usize).collect(),
            };
            let mut at = 0;
            for n in degrees.into_iter().filter(|n| *n > 0) {
                let (Some(first), Some(own)) = (sh.coefs.get(at), c.get(at..at + n)) else { break };
                let sensor = first.strip_suffix("_p1").unwrap_or(first);
                for (k, v) in own.iter().enumerate() {
                    m.insert(format!("tilt_{sensor}_p{}", k + 1), *v);
                }
                if n as u32 <= MONOMIAL_MAX_ORDER {
                    for (j, v) in legendre_to_monomials(1, own, sh.range).into_iter().enumerate().skip(1) {
                        m.insert(format!("tilt_{sensor}_c{j}"), v);
                    }
                }
                at += n;
            }
            m.insert("tilt_x_lo".into(), sh.range.0);
            m.insert("tilt_x_hi".into(), sh.range.1);
        }
        no_own_signature!() | EffectName::Backlash | EffectName::ScaleError => {
            m.insert("value".into(), c[0]);
        }
    }
    m
}
