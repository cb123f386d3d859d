//! Friction identification on real data: the rack-and-pinion axis of K. Mnich (Lodz University of
//! Technology), `shared/realdata/friction_rack_pinion/` (github KonradMnich/friction-identification
//! at 8b477df). Follows the processing of the README (the author's main.m and extraction.m):
//! - a3NI.csv (2 kHz): F [N] = −(V − mean(first 10 samples))·200 N/V; NI time shifted by +4 ms;
//! - a3MR.csv (0.667 ms): v [m/s] = −rpm·20 mm/rev/1000/60;
//! - force resampled (linearly) onto the servo timebase; 2nd-order Butterworth low-pass 30 Hz,
//!   causal, on force and velocity; a = dv/dt; F_friction = F − 24.7 kg·a;
//! - fit on the acceleration phase, 0 < v ≤ 0.55 m/s, lower bound dry ≥ 10 N (the author's
//!   c1 = 10.0000000001 N sits on that bound);
//! - the author's model F = c2·v + c1 + v·(c3 − c1)·e/c4·exp(−v/c4) is `StribeckShape::Mnich`.
//!
//! The CSV parsing lives in `tests/util/realdata.rs` (shared with the model-check loop on the same
//! files, `tests/model_check.rs`); the estimator only sees numbers.

use vmt_estimators::friction_id::{
    fit_stribeck, friction_from_motion, lugre_sigma0_from_presliding, stribeck_curve, FilterMode, FrictionIdError,
    StribeckFit, StribeckFitOptions, StribeckLaw, StribeckShape, SweepDirection,
};

use crate::realdata;

/// The fit window of the README: acceleration phase (from the start up to the velocity peak),
/// 0 < v ≤ 0.55 m/s.
fn window(v: &[f64], friction: &[f64]) -> (Vec<f64>, Vec<f64>) {
    let i_peak = v.iter().enumerate().fold((0, f64::MIN), |b, (i, &x)| if x > b.1 { (i, x) } else { b }).0;
    v[..i_peak].iter().zip(&friction[..i_peak]).filter(|(x, _)| **x > 0.0 && **x <= 0.55).map(|(a, b)| (*a, *b)).unzip()
}

const AUTHOR: StribeckLaw =
    StribeckLaw { fc: 10.0000000001, fs: 29.625596745, vs: 0.0135216268146, delta: 1.0, fv: 67.4406305914 };

fn fit_mnich(v: &[f64], f: &[f64], dry_lower: f64) -> StribeckFit {
    let mut o =
        StribeckFitOptions { shape: StribeckShape::Mnich, direction: SweepDirection::Positive, ..Default::default() };
    o.lower.fc = dry_lower;
    fit_stribeck(v, f, &o).unwrap()
}

fn rms_of(c: &StribeckLaw, shape: StribeckShape, v: &[f64], f: &[f64]) -> f64 {
    (v.iter().zip(f).map(|(&x, &y)| (stribeck_curve(shape, c, x) - y).powi(2)).sum::<f64>() / v.len() as f64).sqrt()
}

// The module is named `friction_realdata` (this file), so `cargo test --workspace --test tests friction`
// selects these tests.

#[test]
fn rack_pinion_author_processing_lands_within_15_percent_of_the_published_coefficients() {
    let Some(d) =
        realdata::rack_pinion("rack_pinion_author_processing_lands_within_15_percent_of_the_published_coefficients")
    else {
        return;
    };
    println!("{} samples on the servo timebase, dt = {} s", d.t.len(), d.dt);
    let mf = friction_from_motion(&d.v_raw, &d.force_raw, 24.7, d.dt, Some(30.0), FilterMode::Causal).unwrap();
    let (v, f) = window(&mf.v, &mf.friction);
    let fit = fit_mnich(&v, &f, 10.0);
    let c = fit.coefficients;
    println!("causal 30 Hz, dry >= 10 N: {}", serde_like(&fit));
    let author_rms = rms_of(&AUTHOR, StribeckShape::Mnich, &v, &f);
    println!("published coefficients on the same window: RMS {author_rms} N");
    // 15 % (brief): the optimisation script is missing from the repository, so the window and
    // weighting can only be reconstructed from the README; an independent re-processing
    // reported in the README lands within 6 % (dry 10.6, viscous 69.2, Fmax 29.4, vs 13.2 mm/s).
    for (name, est, auth) in [
        ("dry c1", c.fc, AUTHOR.fc),
        ("viscous c2", c.fv, AUTHOR.fv),
        ("peak c3", c.fs, AUTHOR.fs),
        ("Stribeck velocity c4", c.vs, AUTHOR.vs),
    ] {
        println!("{name}: {est:.4} vs author {auth:.4} ({:+.1} %)", 100.0 * (est / auth - 1.0));
        assert!((est / auth - 1.0).abs() < 0.15, "{name}: {est} vs {auth}");
    }
    // Our least-squares optimum must fit this window at least as well as the published curve
    // (which README says gives 4.0 N RMS), up to rounding.
    assert!(fit.residual_rms <= author_rms + 1e-9, "{} vs {author_rms}", fit.residual_rms);
    // The README's independent re-processing reports ≈3.9–4.0 N; the load-cell ringing visible
    // in summary.png (≈±5 N at 30–40 Hz) sets that floor. Accept 3–5 N.
    assert!(fit.residual_rms > 3.0 && fit.residual_rms < 5.0, "rms {}", fit.residual_rms);
}

#[test]
fn rack_pinion_variants_are_reported() {
    // Not tolerance tests of the author's numbers: how the answer moves with choices the README
    // leaves open. Printed for the report; only sanity bounds are asserted.
    let Some(d) = realdata::rack_pinion("rack_pinion_variants_are_reported") else { return };
    for (label, mode) in [("causal", FilterMode::Causal), ("zero-phase", FilterMode::ZeroPhase)] {
        let mf = friction_from_motion(&d.v_raw, &d.force_raw, 24.7, d.dt, Some(30.0), mode).unwrap();
        let (v, f) = window(&mf.v, &mf.friction);
        for lower in [10.0, 0.0] {
            let fit = fit_mnich(&v, &f, lower);
            println!("Mnich, {label} 30 Hz, dry >= {lower}: {}", serde_like(&fit));
            assert!(fit.coefficients.fv > 40.0 && fit.coefficients.fv < 100.0);
        }
        // The exponential Stribeck shape (falls from Fs to Fc) on the same window: this axis
        // shows friction RISING to a peak at ≈14 mm/s from a lower value near rest, which the
        // exponential shape cannot follow; report its residual for comparison.
        let o = StribeckFitOptions { direction: SweepDirection::Positive, ..Default::default() };
        let fit = fit_stribeck(&v, &f, &o).unwrap();
        println!("Exponential, {label} 30 Hz: {}", serde_like(&fit));
        assert!(fit.residual_rms < 10.0);
    }
}

#[test]
fn rack_pinion_lugre_sigma0_is_not_identifiable() {
    // Pre-sliding would show as force rising at (nearly) constant position before gross motion.
    // The servo speed is quantised (1 rpm = 0.33 mm/s; exactly 0 until the axis moves at
    // t ≈ 0.046 s) and the load-cell force does not rise before that (summary.png: force and
    // acceleration start together at ≈0.05 s), so the stick segment holds no pre-sliding ramp and
    // σ0 is not identifiable from these files. The estimator must say so.
    let Some(d) = realdata::rack_pinion("rack_pinion_lugre_sigma0_is_not_identifiable") else { return };
    let mut x = vec![0.0; d.v_raw.len()];
    for i in 1..x.len() {
        x[i] = x[i - 1] + 0.5 * (d.v_raw[i] + d.v_raw[i - 1]) * d.dt;
    }
    let i_move = d.v_raw.iter().position(|&v| v != 0.0).unwrap();
    println!("first nonzero servo speed at t = {} s", d.t[i_move]);
    let r = lugre_sigma0_from_presliding(&x[..i_move], &d.force_raw[..i_move], 29.6);
    println!("{r:?}");
    assert!(matches!(r, Err(FrictionIdError::NotIdentifiable(_))), "{r:?}");
}

fn serde_like(fit: &StribeckFit) -> String {
    format!(
        "{:?} se {:?} rms {:.3} N n {} at_bound {:?} converged {}",
        fit.coefficients, fit.std_errors, fit.residual_rms, fit.n_points, fit.at_bound, fit.converged
    )
}
