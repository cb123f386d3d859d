//! Fitting a model: linear parameters by weighted least squares, hyper-parameters searched.

use super::*;

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
}

pub(crate) fn design(st: &Stack, terms: &[FitTerm]) -> Vec<Vec<f64>> {
    let mut cols = st.offsets();
    for t in terms {
        cols.extend(columns(st, t.name, &t.shape, &t.hyper));
    }
    cols
}

/// Drops columns that are all zero (an effect no channel sees) so the solver sees a clean design;
/// returns the kept indices.
pub(crate) fn solve(r: &[f64], cols: &[Vec<f64>], sigma: &Sigma) -> Result<(Vec<f64>, Vec<f64>), String> {
    let keep: Vec<usize> = (0..cols.len()).filter(|&j| cols[j].iter().any(|v| *v != 0.0)).collect();
    let sub: Vec<Vec<f64>> = keep.iter().map(|&j| cols[j].clone()).collect();
    if sub.is_empty() {
        return Ok((vec![0.0; cols.len()], r.to_vec()));
    }
    let fit = fit_signature(r, &sub, sigma).map_err(|e| e.to_string())?;
    let mut beta = vec![0.0; cols.len()];
    for (k, &j) in keep.iter().enumerate() {
        beta[j] = if fit.coefficients[k].is_finite() { fit.coefficients[k] } else { 0.0 };
    }
    Ok((beta, fit.residual))
}

pub(crate) fn weighted_ss(r: &[f64], w: &[f64]) -> f64 {
    r.iter().zip(w).map(|(a, b)| (a * b).powi(2)).sum()
}

/// Golden-section minimum of f on [a, b] searched on a log scale, `iters` iterations: the shared
/// line search (`vmt_estimators::modelcheck::golden_max`) on −f(eˡ), l ∈ [ln a, ln b].
pub(crate) fn golden(a: f64, b: f64, iters: usize, f: &mut dyn FnMut(f64) -> f64) -> f64 {
    golden_max(&mut |l: f64| -f(l.exp()), a.ln(), b.ln(), iters).0.exp()
}

pub(crate) fn fit_model_on(st: &Stack, model: &Model, sigma: &Sigma, w: &[f64]) -> Result<FitState, String> {
    let mut known = vec![0.0; st.n];
    let mut terms: Vec<FitTerm> = Vec::new();
    for (index, me) in model.effects.iter().enumerate() {
        if me.effect.axis != model.axis || !predicts(me.effect.name) {
            continue;
        }
        if !me.fit {
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
        let sh = shape(st, me.effect.name, 1, me.order.unwrap_or(DEFAULT_ORDER), lacks_coulomb(model));
        let mut hyper = Vec::new();
        let mut searched = Vec::new();
        for h in &sh.hypers {
            let given = me.given.iter().any(|g| g == h);
            let start = me.effect.params.get(h).unwrap_or(1.0);
            // A given period (screw lead, signal period) is held; a given τ is a starting value.
            // A damping that these data cannot resolve (no predicted excitation) is held.
            let resolvable = *h != "damping" || hyper_grid(st, me.effect.name, h).1;
            hyper.push(if given || !resolvable { start } else { f64::NAN });
            searched.push(!(given && *h == "period") && resolvable);
            let _ = st;
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
    for _ in 0..sweeps {
        for ti in 0..terms.len() {
            for hi in 0..terms[ti].hyper.len() {
                if !terms[ti].searched[hi] {
                    continue;
                }
                let (grid, refine) = &grids[ti][hi];
                let eval = |v: f64, terms: &mut Vec<FitTerm>| -> f64 {
                    terms[ti].hyper[hi] = v;
                    match solve(&r0, &design(st, terms), sigma) {
                        Ok((_, r)) => weighted_ss(&r, w),
                        Err(_) => f64::INFINITY,
                    }
                };
                let mut best = (f64::INFINITY, grid[0]);
                for &g in grid {
                    let s = eval(g, &mut terms);
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
    let cols = design(st, &terms);
    let (coefs, residual) = solve(&r0, &cols, sigma)?;
    Ok(FitState { terms, cols, coefs, residual, n_offsets: st.n_groups })
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
pub(crate) fn describe(name: EffectName, sh: &Shape, c: &[f64], h: &[f64], start: &EffectParams) -> BTreeMap<String, f64> {
    let mut m = BTreeMap::new();
    match name {
        n if n.is_error_motion() => {
            for (k, v) in c.iter().enumerate() {
                m.insert(format!("c{}", sh.first_power as usize + k), *v);
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
            m.insert("shape".into(), 2.0);
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
