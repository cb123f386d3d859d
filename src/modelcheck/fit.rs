//! Fitting a model: linear parameters by weighted least squares, hyper-parameters searched.

use super::*;
use rayon::prelude::*;

// ------------------------------------------------------------------------------------------
// Fitting a model.

/// A fitted effect of the model: its shape, hyper-parameters and where its columns sit.
#[derive(Clone, Debug)]
pub(crate) struct FitTerm {
    pub(crate) index: usize,
    pub(crate) name: EffectName,
    pub(crate) shape: Shape,
    /// Hyper-parameter values and whether each is searched (not given).
    pub(crate) hyper: Vec<f64>,
    pub(crate) searched: Vec<bool>,
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

pub(crate) fn design(st: &Stack, terms: &[FitTerm]) -> Vec<Vec<f64>> {
    let mut cols = st.offsets();
    for t in terms {
        cols.extend(columns(st, t.name, &t.shape, &t.hyper));
    }
    cols
}

/// Drops columns that are all zero (an effect no channel sees) so the solver sees a clean design;
/// returns the kept indices. A design of more than [`LARGE_DESIGN`] columns (flexible shapes on
/// time series) is solved by pivoted QR (`lstsq_qr`, ≈ 2np² flops) instead of the SVD.
pub(crate) fn solve(r: &[f64], cols: &[Vec<f64>], sigma: &Sigma) -> Result<(Vec<f64>, Vec<f64>), String> {
    let keep: Vec<usize> = (0..cols.len()).filter(|&j| cols[j].iter().any(|v| *v != 0.0)).collect();
    let sub: Vec<Vec<f64>> = keep.iter().map(|&j| cols[j].clone()).collect();
    if sub.is_empty() {
        return Ok((vec![0.0; cols.len()], r.to_vec()));
    }
    let (coefficients, residual) = if sub.len() > LARGE_DESIGN {
        let w = sigma.weights(r.len()).map_err(|e| e.to_string())?;
        lstsq_qr(r, &sub, &w).map_err(|e| e.to_string())?
    } else {
        let fit = fit_signature(r, &sub, sigma).map_err(|e| e.to_string())?;
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
) -> Result<(Vec<f64>, Vec<f64>), String> {
    let starts: Vec<usize> = st.chans.iter().scan(0, |k, c| Some(std::mem::replace(k, *k + c.y.len()))).collect();
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
    if blocks.len() <= 1 || cols.len() <= LARGE_DESIGN {
        return solve(r, cols, sigma);
    }
    let per = sigma.weights(r.len()).map_err(|e| e.to_string())?;
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

pub(crate) fn weighted_ss(r: &[f64], w: &[f64]) -> f64 {
    r.iter().zip(w).map(|(a, b)| (a * b).powi(2)).sum()
}

/// Golden-section minimum of f on [a, b] searched on a log scale, `iters` iterations: the shared
/// line search (`vmt_estimators::modelcheck::golden_max`) on −f(eˡ), l ∈ [ln a, ln b].
pub(crate) fn golden(a: f64, b: f64, iters: usize, f: &mut dyn FnMut(f64) -> f64) -> f64 {
    golden_max(&mut |l: f64| -f(l.exp()), a.ln(), b.ln(), iters).0.exp()
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
    /// Highest order searched by BIC (what the data support, capped at [`MAX_ORDER`] or
    /// [`MAX_ACCEL_ORDER`]); None when the order was not searched.
    pub(crate) max: Option<u32>,
    /// Seen only through accelerometers: its constant and slope have no acceleration and are
    /// pinned at 0 (not fitted).
    pub(crate) pinned: bool,
    /// The series' basis.
    pub(crate) basis: ShapeBasis,
    /// A sparse series: the number of terms selected of 1..=order (None: all of them).
    pub(crate) terms: Option<usize>,
}

/// Highest Legendre order searched for a fitted error motion.
pub(crate) const MAX_ORDER: u32 = 30;

/// BIC of a weighted residual sum of squares `ss` over n samples with p linear parameters,
/// σ unknown (Schwarz 1978): n·ln(ss/n) + p·ln n. Free of the stated σ's scale, so a σ stated
/// too small or missing does not change the chosen order.
pub(crate) fn bic_unknown_sigma(ss: f64, n: usize, p: usize) -> f64 {
    let nf = n as f64;
    nf * (ss.max(1e-300) / nf).ln() + p as f64 * nf.ln()
}

/// Fits the model (see [`fit_model_fixed`]); each fitted error motion whose model gives no `order`
/// gets the Legendre order BIC (σ unknown, [`bic_unknown_sigma`]) prefers among 1..=max, where
/// max = min([`MAX_ORDER`], m − 1) with m the distinct sample positions: the data cannot support
/// more shape coefficients after the offsets. The orders are chosen with the hyper-parameters held
/// at a first fit's values (coordinate-wise, one order at a time, two sweeps when several
/// motions are fitted), then the model is refitted at the chosen orders with its searches. For a
/// given `order` the preferred one is still computed (a shape too stiff for the data is a finding).
/// Data with accelerometer channels keep the default order (their order choice is not implemented).
pub(crate) fn fit_model_on(st: &Stack, model: &Model, sigma: &Sigma, w: &[f64]) -> Result<FitState, String> {
    let default = |me: &ModelEffect| me.order.unwrap_or(DEFAULT_ORDER);
    let first = fit_model_fixed(st, model, sigma, w, &|_, me: &ModelEffect| (default(me), None))?;
    let m = distinct_positions(st).len() as u32;
    let max = MAX_ORDER.min(m.saturating_sub(1)).max(1);
    let motions: Vec<usize> = (0..first.terms.len()).filter(|&t| first.terms[t].name.is_error_motion()).collect();
    if motions.is_empty() {
        return Ok(first);
    }
    if st.chans.iter().any(|c| c.is_accel()) {
        return fit_orders_nested(st, model, sigma, w, first, &motions);
    }
    let n = st.n;
    let mut terms = first.terms.clone();
    let mut best: BTreeMap<usize, u32> = BTreeMap::new();
    let sweeps = if motions.len() > 1 { 2 } else { 1 };
    for _ in 0..sweeps {
        for &ti in &motions {
            let mut top = (f64::INFINITY, terms[ti].shape.order);
            for k in 1..=max {
                terms[ti].shape = shape(st, terms[ti].name, 1, k, false);
                let cols = design(st, &terms);
                let p = cols.iter().filter(|c| c.iter().any(|v| *v != 0.0)).count();
                if let Ok((_, r)) = solve(&first.target, &cols, sigma) {
                    let b = bic_unknown_sigma(weighted_ss(&r, w), n, p);
                    if b < top.0 {
                        top = (b, k);
                    }
                }
            }
            best.insert(ti, top.1);
            let me = &model.effects[terms[ti].index];
            terms[ti].shape = shape(st, terms[ti].name, 1, me.order.unwrap_or(top.1), false);
        }
    }
    let chosen: BTreeMap<usize, u32> = motions.iter().map(|&ti| (terms[ti].index, terms[ti].shape.order)).collect();
    let mut fs = fit_model_fixed(st, model, sigma, w, &|index: usize, me: &ModelEffect| {
        (chosen.get(&index).copied().unwrap_or(default(me)), None)
    })?;
    for c in fs.shapes.iter_mut() {
        if let Some((_, b)) = motions.iter().map(|&ti| (terms[ti].name, best[&ti])).find(|(nm, _)| *nm == c.name) {
            c.best = b;
            c.max = Some(max);
        }
    }
    Ok(fs)
}

/// The greedy selection of a cosine series ([`greedy_rss`]) stops after 20 terms in a row that
/// each explain less than this many times the residual mean square (BIC charges ln n ≥ 5 each).
pub(crate) const GREEDY_STOP: f64 = 1.0;

/// Largest number of values (columns × samples) of the series searched for one error motion
/// (memory: 8 bytes each, held about three times during the search).
pub(crate) const MAX_SERIES_VALUES: usize = 20_000_000;

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
/// Coordinate-wise over the motions, two sweeps when several share a channel; then the model is
/// refitted at the chosen orders with its searches.
fn fit_orders_nested(
    st: &Stack,
    model: &Model,
    sigma: &Sigma,
    w: &[f64],
    first: FitState,
    motions: &[usize],
) -> Result<FitState, String> {
    let mut terms = first.terms.clone();
    let mut best: BTreeMap<usize, (u32, u32)> = BTreeMap::new();
    // A second sweep only when two motions share a channel (else each choice is independent).
    let shared =
        st.chans.iter().any(|c| motions.iter().filter(|&&ti| c.s_motion(first.terms[ti].name) != 0.0).count() > 1);
    let sweeps = if motions.len() > 1 && shared { 2 } else { 1 };
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
    for _ in 0..sweeps {
        for &ti in motions {
            let name = terms[ti].name;
            let rows = rows_of(name);
            let range = shape(st, name, 1, 1, false).range;
            let top = resolvable_order(st, name, range);
            let series = columns(st, name, &shape(st, name, 1, top, false), &[]);
            let others: Vec<FitTerm> =
                terms.iter().enumerate().filter(|(i, _)| *i != ti).map(|(_, t)| t.clone()).collect();
            let pick = |v: &[f64]| rows.iter().map(|&i| v[i]).collect::<Vec<f64>>();
            let fixed: Vec<Vec<f64>> =
                design(st, &others).iter().map(|c| pick(c)).filter(|c| c.iter().any(|v| *v != 0.0)).collect();
            let (orders, nested): (Vec<u32>, Vec<Vec<f64>>) = series
                .iter()
                .enumerate()
                .map(|(k, c)| (k as u32 + 1, pick(c)))
                .filter(|(_, c)| c.iter().any(|v| *v != 0.0))
                .unzip();
            let wr = pick(w);
            let y = pick(&first.target);
            let base = OrthoBase::new(&fixed, &wr).map_err(|e| e.to_string())?;
            let me = &model.effects[terms[ti].index];
            let sparse = shape(st, name, 1, top, false).basis == ShapeBasis::Cosine && me.order.is_none();
            // The order in which the series enters: by degree (nested orders), or for a cosine series
            // greedily, each step the term that explains most of what is left (rail waviness puts the
            // signal at a few high orders, where nesting by degree would charge every order below
            // it; at the fast pass the short waves alias, so the terms are not orthogonal there).
            let nr = if sparse {
                greedy_rss(&y, &wr, &base, &nested, GREEDY_STOP).map_err(|e| e.to_string())?
            } else {
                nested_rss(&y, &wr, &base, &nested).map_err(|e| e.to_string())?
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
                best.insert(ti, (chosen, searched));
                terms[ti].shape = shape(st, name, 1, chosen, false).selected(sel);
            } else {
                // k series columns taken: the order of the k-th (1 when none is needed); the columns
                // the offsets span (P_2 per pass on accelerometers) are skipped but kept in the series.
                let chosen = if k == 0 { 1 } else { orders[nr.used[k - 1]] };
                best.insert(ti, (chosen, searched));
                terms[ti].shape = shape(st, name, 1, me.order.unwrap_or(chosen), false);
            }
        }
    }
    let chosen: BTreeMap<usize, (u32, Option<Vec<u32>>)> =
        motions.iter().map(|&ti| (terms[ti].index, (terms[ti].shape.order, terms[ti].shape.select.clone()))).collect();
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

/// Fits the model with each fitted error motion's Legendre order from `order_of(effect index, effect)`:
/// linear parameters by weighted least squares, hyper-parameters searched (module doc).
pub(crate) fn fit_model_fixed(
    st: &Stack,
    model: &Model,
    sigma: &Sigma,
    w: &[f64],
    order_of: &dyn Fn(usize, &ModelEffect) -> (u32, Option<Vec<u32>>),
) -> Result<FitState, String> {
    let mut known = vec![0.0; st.n];
    let mut terms: Vec<FitTerm> = Vec::new();
    for (index, me) in model.effects.iter().enumerate() {
        if me.effect.axis != model.axis || !predicts(me.effect.name) {
            continue;
        }
        if !me.fit {
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
            continue;
        }
        let (order, select) = order_of(index, me);
        let mut sh = shape(st, me.effect.name, 1, order, lacks_coulomb(model));
        if let Some(sel) = select {
            sh = sh.selected(sel);
        }
        let mut hyper = Vec::new();
        let mut searched = Vec::new();
        for h in &sh.hypers {
            let given = me.given.iter().any(|g| g == h);
            let start = me.effect.params.get(h).unwrap_or(1.0);
            // A given period (screw lead, signal period) is held; a given τ is a starting value.
            // A damping that these data cannot resolve (no predicted excitation) is held.
            let resolvable = *h != "damping" || hyper_grid(st, me.effect.name, h).1;
            hyper.push(if given || !resolvable { start } else { f64::NAN });
            // A given period or Stribeck shape exponent is held (the diagnosis searched it).
            searched.push(!(given && matches!(*h, "period" | "shape")) && resolvable);
        }
        terms.push(FitTerm { index, name: me.effect.name, shape: sh, hyper, searched });
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
                    if v.is_finite() && t.shape.hypers[hi] == "frequency" {
                        // A given mode frequency is a starting value: ±5 % in 41 steps.
                        ((0..41).map(|k| v * (0.95 + 0.0025 * k as f64)).collect(), true)
                    } else if v.is_finite() {
                        (log_grid(v / 10.0, v * 10.0, 21), true)
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
    let sweeps = if n_searched > 1 { 2 } else { 1 };
    // A large design (flexible shapes on time series): the columns that no search changes (offsets,
    // shapes, terms without a searched hyper-parameter) are factored once, and each evaluation
    // projects only the searched terms' columns (variable projection, `OrthoBase`).
    let moving = |t: &FitTerm| t.searched.iter().any(|s| *s);
    let fixed_base = if n_searched > 0 && design(st, &terms).len() > LARGE_DESIGN {
        let fixed: Vec<FitTerm> = terms.iter().filter(|t| !moving(t)).cloned().collect();
        let base = OrthoBase::new(&design(st, &fixed), w).map_err(|e| e.to_string())?;
        let target = base.project_vector(&r0, w);
        Some((base, target))
    } else {
        None
    };
    for _ in 0..sweeps {
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
                        let ss: f64 = target.iter().map(|v| v * v).sum();
                        return ss - base.explained(target, &cols, w);
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
                    v = golden(a, b, 40, &mut |x| eval(x, &mut tt));
                    if eval(v, &mut terms) > best.0 {
                        v = best.1;
                    }
                }
                terms[ti].hyper[hi] = v;
            }
        }
    }
    if st.chans.iter().any(|c| c.is_accel()) {
        refine_jointly(st, &mut terms, &grids, &r0, sigma, w, fixed_base.as_ref());
    }
    let cols = design(st, &terms);
    let (coefs, residual) = solve_blocks(st, &r0, &cols, sigma)?;
    let shapes = terms
        .iter()
        .filter(|t| t.name.is_error_motion())
        .map(|t| {
            let given = model.effects[t.index].order.is_some();
            ShapeChoice {
                name: t.name,
                order: t.shape.order,
                best: t.shape.order,
                given,
                max: None,
                pinned: false,
                basis: t.shape.basis,
                terms: t.shape.select.as_ref().map(Vec::len),
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
    let resid = |x: &[f64]| -> Result<Vec<f64>, String> {
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
                let ob = OrthoBase::new(&pc, &ones).map_err(|e| e.to_string())?;
                Ok(ob.project_vector(target, &ones))
            }
            None => {
                let (_, r) = solve(r0, &design(st, &tt), sigma)?;
                Ok(r.iter().zip(w).map(|(r, w)| r * w).collect())
            }
        }
    };
    if let Some(r) = refine_projected(&resid, &start, &lo, &hi, 40) {
        for (&(ti, hi), v) in free.iter().zip(&r.theta) {
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
    let translation =
        |n: EffectName| matches!(n, EffectName::Positioning | EffectName::StraightnessY | EffectName::StraightnessZ);
    let mut added = false;
    let ex = st
        .chans
        .iter()
        .zip(&st.excitation)
        .map(|(c, given)| {
            let mut list = given.clone();
            for (ti, t) in fs.terms.iter().enumerate().filter(|(_, t)| translation(t.name)) {
                if let Some(e) = Excitation::of_fitted(c, &t.shape, term_coefs(fs, ti)) {
                    list.push(e);
                    added = true;
                }
            }
            list
        })
        .collect();
    added.then_some(ex)
}

/// The fitted parameters of each term as effect parameters (FORMAT.md §2 keys).
pub(crate) fn term_params(fs: &FitState, model: &Model) -> BTreeMap<String, BTreeMap<String, f64>> {
    let mut out = BTreeMap::new();
    let mut j = fs.n_offsets;
    for t in &fs.terms {
        let k = t.shape.coefs.len();
        let c = &fs.coefs[j..j + k];
        j += k;
        let me = &model.effects[t.index];
        out.insert(t.name.as_str().to_string(), describe(t.name, &t.shape, c, &t.hyper, &me.effect.params));
    }
    // A Stribeck term without its own Fc rides on the model's Coulomb level: fs = Fc + (Fs − Fc).
    if let Some(t) = fs.terms.iter().find(|t| t.name == EffectName::Stribeck && !t.shape.with_fc) {
        let own = model.effects[t.index].effect.params.get("fc").unwrap_or(0.0);
        let fc = coulomb_level(model, &out) - own;
        if let Some(v) = out.get_mut("stribeck").and_then(|m| m.get_mut("fs")) {
            *v += fc;
        }
    }
    out
}

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
            match sh.basis {
                ShapeBasis::Legendre => {
                    for (j, v) in legendre_to_monomials(sh.first_power, c, sh.range).into_iter().enumerate().skip(1) {
                        m.insert(format!("c{j}"), v);
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
            // Tilt of each sensor's sensitive axis, rad: Σ_k c_k·x^k (x in m), by sensor.
            for (k, v) in sh.coefs.iter().zip(c) {
                m.insert(format!("tilt_{k}"), *v);
            }
        }
        _ => {
            m.insert("value".into(), c[0]);
        }
    }
    m
}
