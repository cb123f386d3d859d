//! Straightness from accelerometers (seed 000 + DESIGN.md §7) on synthetic runs with known truth.
//!
//! Truth: E(x) = Σ A_h·sin(2πx/λ_h + φ_h) over L = 1 m with λ = 20, 50, 125, 250 mm (integer numbers of
//! cycles over the travel, so the band-limited truth is exact) and A = 1…3 µm. Runs per seed 000: speeds
//! 0.05 / 0.15 / 0.4 m/s (10–80 % of a 0.5 m/s max feed), 1200 Hz at the high speed and fs ∝ v below, so
//! every run has N = 3000 samples at the same 1/3 mm spacing; the mid-speed run goes backwards. Each run
//! reads a = v²·E''(x) + offset + white noise with one-sided density ρ (per-sample σ = ρ·√(fs/2)).
//! Run with `--nocapture` to see the numbers quoted in the report.

use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, Normal};
use std::f64::consts::PI;
use vmt_estimators::accel_straightness::*;

const UG: f64 = 9.80665e-6; // 1 µg in m/s²
const L: f64 = 1.0;
const SPEEDS: [f64; 3] = [0.05, 0.15, 0.4];
const HARMONICS: [(f64, f64, f64); 4] =
    [(0.020, 1.0e-6, 0.3), (0.050, 2.0e-6, 1.1), (0.125, 1.5e-6, 2.0), (0.250, 3.0e-6, -0.7)];

fn truth(x: f64) -> f64 {
    HARMONICS.iter().map(|(wl, a, ph)| a * (2.0 * PI * x / wl + ph).sin()).sum()
}

fn truth_curvature(x: f64) -> f64 {
    HARMONICS
        .iter()
        .map(|(wl, a, ph)| {
            let k = 2.0 * PI / wl;
            -a * k * k * (2.0 * PI * x / wl + ph).sin()
        })
        .sum()
}

/// One seed-000 run: fs = 1200·v/0.4, N = 3000, direction ±1 covering [0, L).
fn make_run(v: f64, dir: i32, rho: f64, offset: f64, rng: &mut ChaCha8Rng) -> AccelRun {
    let fs = 1200.0 * v / 0.4;
    let n = (1200.0 * L / 0.4_f64).round() as usize;
    let dx = v / fs;
    let x0 = if dir > 0 { 0.0 } else { (n - 1) as f64 * dx };
    let noise = Normal::new(0.0, rho * (fs / 2.0).sqrt()).unwrap();
    let acceleration = (0..n)
        .map(|j| {
            let x = x0 + dir as f64 * dx * j as f64;
            v * v * truth_curvature(x) + offset + noise.sample(rng)
        })
        .collect();
    AccelRun { speed: v, sample_rate: fs, start_position: x0, direction: dir, acceleration }
}

fn make_runs(rho: f64, seed: u64) -> Vec<AccelRun> {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    // Offsets: gravity through a 1–3 mrad mount tilt plus bias, different per run.
    vec![
        make_run(SPEEDS[0], 1, rho, 0.012, &mut rng),
        make_run(SPEEDS[1], -1, rho, 0.021, &mut rng),
        make_run(SPEEDS[2], 1, rho, 0.030, &mut rng),
    ]
}

fn rms(a: &[f64]) -> f64 {
    (a.iter().map(|v| v * v).sum::<f64>() / a.len() as f64).sqrt()
}

/// Error of an estimate against the truth band-limited to [min_wl, max_wl].
fn error_vs_band_limited(est: &StraightnessEstimate, min_wl: f64, max_wl: f64) -> Vec<f64> {
    let t: Vec<f64> = est.positions.iter().map(|&x| truth(x)).collect();
    let tb = band_limit_profile(&est.positions, &t, min_wl, max_wl).unwrap();
    est.straightness.iter().zip(&tb).map(|(e, t)| e - t).collect()
}

/// Undoes the least-squares reference line of an error profile whose periodic part has no content at
/// the first DFT bin (λ = L lies outside the recoverable band): the reported profiles are about their
/// least-squares line, whose slope is random (set by the noisy long wavelengths) and would leak into every
/// harmonic's projection as ∝ 1/k. With w = e^{−2πi/N}, a unit slope has bin-1 DFT Δx·Σ j·w^j =
/// −N·Δx/(1 − w); e = D − a − b·x with D periodic and D_1 = 0 gives E_1 = b·N·Δx/(1 − w), so
/// b = Re(E_1·(1 − w))/(N·Δx), and e + b·x is periodic again.
fn undo_reference_line(x: &[f64], e: &[f64]) -> Vec<f64> {
    let n = e.len() as f64;
    let dx = x[1] - x[0];
    let (mut re, mut im) = (0.0, 0.0);
    for (j, v) in e.iter().enumerate() {
        let ph = -2.0 * PI * j as f64 / n;
        re += v * ph.cos();
        im += v * ph.sin();
    }
    // (1 − w) with w = cos(−2π/N) + i·sin(−2π/N)
    let (wr, wi) = (1.0 - (-2.0 * PI / n).cos(), -(-2.0 * PI / n).sin());
    let prod_re = re * wr - im * wi;
    let b = prod_re / (n * dx);
    e.iter().zip(x).map(|(v, xi)| v + b * xi).collect()
}

/// Amplitude components of a (periodic) error profile at one harmonic: the DFT projection
/// (2/N)·Σ e·sin κx and (2/N)·Σ e·cos κx, after [`undo_reference_line`].
fn project(x: &[f64], e: &[f64], wl: f64) -> (f64, f64) {
    let y = undo_reference_line(x, e);
    let n = x.len() as f64;
    let k = 2.0 * PI / wl;
    let s = 2.0 / n * x.iter().zip(&y).map(|(x, y)| y * (k * x).sin()).sum::<f64>();
    let c = 2.0 / n * x.iter().zip(&y).map(|(x, y)| y * (k * x).cos()).sum::<f64>();
    (s, c)
}

fn snr_config(rho: Option<f64>) -> StraightnessConfig {
    StraightnessConfig { method: FusionMethod::SnrWeighted, noise_density: rho, ..StraightnessConfig::default() }
}

#[test]
fn cramer_rao_bound_matches_monte_carlo_std_of_least_squares_amplitude() {
    // LS fit of [1, sin κx, cos κx] to the raw acceleration (offset free), 400 noise draws. The std of
    // A_s and A_c must equal ρ/(κ²v^{3/2}√L) within 10 %: with 400 draws the sample std has a relative
    // standard error 1/√800 = 3.5 %, so 10 % is ~3σ. Two cases with different fs show the bound does not
    // depend on the sample rate (one-sided ρ, per-sample σ = ρ√(fs/2)).
    let rho = 25.0 * UG;
    for (case, &(v, fs, wl)) in [(0.15, 450.0, 0.1), (0.4, 2400.0, 0.25)].iter().enumerate() {
        let n = (fs * L / v).round() as usize;
        let x: Vec<f64> = (0..n).map(|j| v * j as f64 / fs).collect();
        let k = 2.0 * PI / wl;
        let amp = 2e-6;
        let clean: Vec<f64> = x.iter().map(|&x| -v * v * k * k * amp * (k * x).sin() + 0.02).collect();
        let noise = Normal::new(0.0, rho * (fs / 2.0).sqrt()).unwrap();
        let mut rng = ChaCha8Rng::seed_from_u64(1000 + case as u64);
        let draws = 400;
        let (mut ss, mut sc, mut ms) = (0.0, 0.0, 0.0);
        for _ in 0..draws {
            let a: Vec<f64> = clean.iter().map(|c| c + noise.sample(&mut rng)).collect();
            let h = fit_harmonic_amplitude(&x, &a, v, wl).unwrap();
            ss += (h.sin - amp).powi(2);
            sc += h.cos.powi(2);
            ms += h.sin - amp;
        }
        let std_s = (ss / draws as f64).sqrt();
        let std_c = (sc / draws as f64).sqrt();
        let bound = cramer_rao_amplitude(rho, wl, v, L).unwrap();
        eprintln!(
            "CR check v={v} fs={fs} λ={wl}: bound {bound:.4e} m, MC std sin {std_s:.4e} cos {std_c:.4e} \
             (ratios {:.3}, {:.3}), mean bias {:.2e}",
            std_s / bound,
            std_c / bound,
            ms / draws as f64
        );
        assert!((std_s / bound - 1.0).abs() < 0.10, "sin: {std_s} vs {bound}");
        assert!((std_c / bound - 1.0).abs() < 0.10, "cos: {std_c} vs {bound}");
        // Unbiased: |mean error| < 4 standard errors of the mean (bound/√400).
        assert!((ms / draws as f64).abs() < 4.0 * bound / (draws as f64).sqrt());
    }
}

#[test]
fn noise_density_is_estimated_from_the_upper_spectrum() {
    // Per run ~750 periodogram bins in fs/4..fs/2 (Hann leaves ~1/2.7 of them independent): the mean PSD
    // has ~6 % relative standard error, ρ half that; 10 % is > 3σ. The straightness signal lies below
    // fs/60 and does not leak up there.
    for (rho, seed) in [(0.5 * UG, 11u64), (25.0 * UG, 12)] {
        for r in make_runs(rho, seed) {
            let est = estimate_noise_density(&r.acceleration, r.sample_rate).unwrap();
            eprintln!("ρ true {:.3} µg/√Hz, estimated {:.3} at v={}", rho / UG, est / UG, r.speed);
            assert!((est / rho - 1.0).abs() < 0.10, "{est} vs {rho}");
        }
    }
}

#[test]
fn piezo_snr_fusion_meets_rms_and_per_harmonic_cramer_rao() {
    // ρ = 0.5 µg/√Hz, ρ estimated from the data. The band (threshold 0.1 µm) must contain all injected
    // wavelengths; error vs band-limited truth ≤ 0.3 µm RMS (brief); each quadrature component of the error
    // at each injected harmonic ≤ 3× its combined Cramér–Rao bound (3σ: 0.27 % per component).
    let runs = make_runs(0.5 * UG, 21);
    let est = estimate_straightness(&runs, &snr_config(None)).unwrap();
    let band = &est.band;
    eprintln!("piezo SNR band: {}", band.note);
    for r in &est.runs {
        eprintln!("  run v={} ρ̂={:.3} µg/√Hz share {:.4}", r.speed, r.noise_density / UG, r.snr_share.unwrap());
        assert!((r.noise_density / (0.5 * UG) - 1.0).abs() < 0.10);
    }
    assert!(band.max_wavelength > 0.25 && band.min_wavelength < 0.02);
    let err = error_vs_band_limited(&est, band.min_wavelength, band.max_wavelength);
    let e_rms = rms(&err);
    eprintln!("piezo SNR: RMS error vs band-limited truth {:.4e} m", e_rms);
    assert!(e_rms < 0.3e-6, "RMS {e_rms}");
    for &(wl, _, _) in &HARMONICS {
        let (s, c) = project(&est.positions, &err, wl);
        let cr = est.harmonic_std(wl).unwrap();
        eprintln!(
            "  λ={wl}: error components ({s:.3e}, {c:.3e}) m, CR {cr:.3e} m, ratios {:.2} {:.2}",
            s.abs() / cr,
            c.abs() / cr
        );
        assert!(s.abs() < 3.0 * cr && c.abs() < 3.0 * cr);
    }
}

#[test]
fn snr_fusion_is_efficient_over_noise_draws() {
    // 100 draws at ρ = 0.5 µg/√Hz (ρ given): the std of the per-harmonic error components (200 samples
    // per harmonic, relative standard error 5 %) must lie within 0.8…1.25 of the combined Cramér–Rao bound
    // (±4σ of that scatter): the fusion is efficient, not just below a loose tolerance.
    let rho = 0.5 * UG;
    let draws = 100;
    let mut sq = [0.0f64; 4];
    let mut cr = [0.0f64; 4];
    for d in 0..draws {
        let runs = make_runs(rho, 5000 + d);
        let est = estimate_straightness(&runs, &snr_config(Some(rho))).unwrap();
        let err = error_vs_band_limited(&est, est.band.min_wavelength, est.band.max_wavelength);
        for (h, &(wl, _, _)) in HARMONICS.iter().enumerate() {
            let (s, c) = project(&est.positions, &err, wl);
            sq[h] += s * s + c * c;
            cr[h] = est.harmonic_std(wl).unwrap();
        }
    }
    for (h, &(wl, _, _)) in HARMONICS.iter().enumerate() {
        let std = (sq[h] / (2 * draws) as f64).sqrt();
        eprintln!("efficiency λ={wl}: MC std {std:.3e} m, CR {:.3e} m, ratio {:.3}", cr[h], std / cr[h]);
    }
    for (h, _) in HARMONICS.iter().enumerate() {
        let std = (sq[h] / (2 * draws) as f64).sqrt();
        assert!(std / cr[h] > 0.8 && std / cr[h] < 1.25);
    }
}

/// SNR-weighted fusion at noise density `rho` over the fixed band [4Δx, 0.3 m] (amplitude threshold so
/// high that the noise does not move the band).
fn fixed_band_config(rho: f64) -> StraightnessConfig {
    StraightnessConfig {
        method: FusionMethod::SnrWeighted,
        noise_density: Some(rho),
        amplitude_threshold: 1.0,
        min_wavelength: None,
        max_wavelength: Some(0.3),
        seed_kalman: true,
        ..StraightnessConfig::default()
    }
}

#[test]
fn mems_noise_grows_bound_and_error_in_proportion() {
    // Same fixed band [4Δx, 0.3 m] for both sensors (threshold huge so noise does not move it). 20 draws
    // each, different seeds. The CR bound scales exactly with ρ (×50); the achieved RMS error must grow by
    // 25…100 (×50 within a factor 2: the RMS is dominated by a few long-wavelength bins, so each sensor's
    // 20-draw RMS scatters by roughly ±15 %).
    let cfg = fixed_band_config;
    let mut res = Vec::new();
    for (rho, seed0) in [(0.5 * UG, 100u64), (25.0 * UG, 200u64)] {
        let mut ms = 0.0;
        let mut bound = 0.0;
        let draws = 20;
        for d in 0..draws {
            let est = estimate_straightness(&make_runs(rho, seed0 + d), &cfg(rho)).unwrap();
            let err = error_vs_band_limited(&est, est.band.min_wavelength, est.band.max_wavelength);
            ms += rms(&err).powi(2);
            bound = est.harmonic_std(0.25).unwrap();
        }
        let e = (ms / draws as f64).sqrt();
        eprintln!("ρ={:.1} µg/√Hz: RMS error {e:.3e} m, CR at 250 mm {bound:.3e} m", rho / UG);
        res.push((e, bound));
    }
    let err_ratio = res[1].0 / res[0].0;
    let bound_ratio = res[1].1 / res[0].1;
    eprintln!("MEMS/piezo: error ratio {err_ratio:.1}, bound ratio {bound_ratio:.1}");
    assert!((bound_ratio - 50.0).abs() < 1e-9);
    assert!(err_ratio > 25.0 && err_ratio < 100.0);
    // With the default 0.1 µm threshold the MEMS band shrinks and says so.
    let est = estimate_straightness(&make_runs(25.0 * UG, 300), &snr_config(Some(25.0 * UG))).unwrap();
    eprintln!("MEMS band: {}", est.band.note);
    assert_eq!(est.band.max_wavelength_limited_by, "noise");
    assert!(est.band.max_wavelength < 0.125);
    assert!(est.band.note.contains("out of reach"));
}

#[test]
fn fusion_beats_every_single_speed_alone() {
    // Same data, same band [4Δx, 0.3 m], 200 draws at ρ = 0.5 µg/√Hz. Expected MSE ratio fused/fastest =
    // share of the fastest run = 0.4³/(0.05³+0.15³+0.4³) = 0.948 (RMS −2.6 %): the v³ law makes the
    // fastest pass dominate. The draw-to-draw fluctuation of that difference (~6 effective degrees of
    // freedom per draw, 1200 in all) is ~1/4 of the expected gain, so "fused < each single" is a 4σ test.
    let rho = 0.5 * UG;
    let cfg = fixed_band_config(rho);
    let mut ms_fused = 0.0;
    let mut ms_single = [0.0f64; 3];
    let draws = 200;
    for d in 0..draws {
        let runs = make_runs(rho, 7000 + d);
        let est = estimate_straightness(&runs, &cfg).unwrap();
        ms_fused += rms(&error_vs_band_limited(&est, est.band.min_wavelength, 0.3)).powi(2);
        for (i, r) in runs.iter().enumerate() {
            let e1 = estimate_straightness(std::slice::from_ref(r), &cfg).unwrap();
            ms_single[i] += rms(&error_vs_band_limited(&e1, e1.band.min_wavelength, 0.3)).powi(2);
        }
    }
    let f = (ms_fused / draws as f64).sqrt();
    eprintln!("fused RMS error {f:.4e} m");
    for (i, m) in ms_single.iter().enumerate() {
        let s = (m / draws as f64).sqrt();
        eprintln!("  v={} alone: {s:.4e} m (fused/single {:.3})", SPEEDS[i], f / s);
        assert!(f < s);
    }
}

#[test]
fn snr_fusion_is_no_worse_than_seed_continuity_fusion() {
    // Both methods on the same runs, compared with the truth band-limited to the SNR method's band. The
    // seed method's numbers are reported, not bounded: its Kalman filter is a causal shrinkage filter and
    // its time-domain high-pass has edge transients (see the report). Interior = 10 %…90 % of travel.
    for (rho, seed) in [(0.5 * UG, 31u64), (25.0 * UG, 32u64)] {
        let runs = make_runs(rho, seed);
        let snr = estimate_straightness(&runs, &snr_config(Some(rho))).unwrap();
        let seed_cfg = StraightnessConfig { method: FusionMethod::SpatialContinuity, ..snr_config(Some(rho)) };
        let sd = estimate_straightness(&runs, &seed_cfg).unwrap();
        let (lo, hi) = (snr.band.min_wavelength, snr.band.max_wavelength);
        let e_snr = error_vs_band_limited(&snr, lo, hi);
        let e_seed = error_vs_band_limited(&sd, lo, hi);
        let m = e_snr.len();
        let inner = m / 10..m - m / 10;
        eprintln!(
            "ρ={:.1} µg/√Hz band {lo:.4}…{hi:.4} m: SNR RMS {:.3e} (interior {:.3e}); seed RMS {:.3e} \
             (interior {:.3e}); seed cut-offs {:?} m, crossovers {:?} rad/m",
            rho / UG,
            rms(&e_snr),
            rms(&e_snr[inner.clone()]),
            rms(&e_seed),
            rms(&e_seed[inner]),
            sd.runs.iter().map(|r| r.cutoff_wavelength.unwrap()).collect::<Vec<_>>(),
            sd.crossover_wavenumbers
        );
        for r in &sd.runs {
            eprintln!("  seed Kalman v={}: {:?}", r.speed, r.kalman);
        }
        for &(wl, _, _) in &HARMONICS {
            let (s1, c1) = project(&snr.positions, &e_snr, wl);
            let (s2, c2) = project(&sd.positions, &e_seed, wl);
            eprintln!("  λ={wl}: |error| SNR {:.3e}, seed {:.3e} m", s1.hypot(c1), s2.hypot(c2));
        }
        assert!(rms(&e_snr) <= rms(&e_seed));
    }
}

#[test]
fn both_methods_return_the_same_grid_and_json_serialises() {
    let runs = make_runs(0.5 * UG, 41);
    let a = estimate_straightness(&runs, &snr_config(Some(0.5 * UG))).unwrap();
    let b = estimate_straightness(
        &runs,
        &StraightnessConfig { method: FusionMethod::SpatialContinuity, ..snr_config(Some(0.5 * UG)) },
    )
    .unwrap();
    assert_eq!(a.positions, b.positions);
    // Seed sampling maps all runs onto one grid of 3000 points at 1/3 mm: L = 1 m exactly.
    assert_eq!(a.positions.len(), 3000);
    assert!((a.travel - 1.0).abs() < 1e-9);
    let json = serde_json::to_string(&b).unwrap();
    assert!(json.contains("\"SpatialContinuity\"") && json.contains("out of reach"));
    let back: StraightnessEstimate = serde_json::from_str(&json).unwrap();
    assert_eq!(back.straightness.len(), 3000);
}

#[test]
fn seed_pipeline_without_kalman_matches_its_predicted_transfer() {
    // Checks the seed's integration, high-pass and crossover steps against their predicted gain
    // G(κ) (StraightnessEstimate::transfer): at ρ = 0.5 µg/√Hz the noise is ≤ 3e-8 m per harmonic, so the
    // error at each injected harmonic must be A·(G − 1) in phase with it (zero-phase filters). Tolerance:
    // 3× (predicted noise std + level of the high-pass edge transients, which the periodic model of G
    // ignores and which spread over all bins: measured at the neighbouring bins) plus 10 % of the bias. Then the same with the Kalman filter, reported: its bias is
    // what makes the seed lose against the SNR fusion.
    let rho = 0.5 * UG;
    let runs = make_runs(rho, 51);
    for kalman in [false, true] {
        let cfg = StraightnessConfig {
            method: FusionMethod::SpatialContinuity,
            noise_density: Some(rho),
            seed_kalman: kalman,
            ..StraightnessConfig::default()
        };
        let est = estimate_straightness(&runs, &cfg).unwrap();
        let (lo, hi) = (est.band.min_wavelength, est.band.max_wavelength);
        let err = error_vs_band_limited(&est, lo, hi);
        let m = err.len();
        eprintln!(
            "seed kalman={kalman}: RMS error {:.3e} m, interior 20–80 % {:.3e} m, first/last 5 %: {:.3e} / {:.3e} m",
            rms(&err),
            rms(&err[m / 5..m - m / 5]),
            rms(&err[..m / 20]),
            rms(&err[m - m / 20..])
        );
        for &(wl, a, ph) in &HARMONICS {
            let (s, c) = project(&est.positions, &err, wl);
            // Truth component: a·sin(κx + φ) = a·cos φ·sin κx + a·sin φ·cos κx.
            let g = est.transfer(wl).unwrap();
            let (ps, pc) = (a * ph.cos() * (g - 1.0), a * ph.sin() * (g - 1.0));
            let sd = est.harmonic_std(wl).unwrap();
            let dev = (s - ps).hypot(c - pc);
            // Edge transients spread over all bins: their level here is the mean error magnitude at the
            // neighbouring bins k ± 1, k ± 2 (no injected harmonic there).
            let k = (1.0 / wl).round() as i64;
            let leak = [-2i64, -1, 1, 2]
                .iter()
                .map(|d| {
                    let (s, c) = project(&est.positions, &err, 1.0 / (k + d) as f64);
                    s.hypot(c)
                })
                .sum::<f64>()
                / 4.0;
            eprintln!(
                "  λ={wl}: G={g:.4}, predicted error {:.3e}, measured {:.3e}, deviation {dev:.3e} m, \
                 neighbouring-bin level {leak:.3e} m",
                ps.hypot(pc),
                s.hypot(c)
            );
            if !kalman {
                let tol = 3.0 * (sd + leak) + 0.1 * ps.hypot(pc);
                assert!(dev < tol, "λ={wl}: deviation {dev} > {tol}");
            }
        }
    }
}

#[test]
fn non_periodic_profile_interior_error_both_methods() {
    // The profile gets an extra 1.5 µm harmonic of 90 mm (11.1 cycles over the travel), so it is not
    // periodic over L and the DFT's wrap-around matters. The band-limited DFT truth is not meaningful
    // then; instead compare on the interior 20–80 % after removing a least-squares quadratic from the
    // difference (the quadratic is unobservable; longer wavelengths are out of band anyway). Asserted:
    // SNR ≤ seed, and SNR within the brief's 0.3 µm RMS. Numbers in the report.
    let extra = |x: f64| 1.5e-6 * (2.0 * PI * x / 0.09 + 0.4).sin();
    let extra_curv = |x: f64| -1.5e-6 * (2.0 * PI / 0.09f64).powi(2) * (2.0 * PI * x / 0.09 + 0.4).sin();
    let rho = 0.5 * UG;
    let mut runs = make_runs(rho, 77);
    for r in runs.iter_mut() {
        let dx = r.speed / r.sample_rate;
        let (x0, dir, v) = (r.start_position, r.direction as f64, r.speed);
        for (j, a) in r.acceleration.iter_mut().enumerate() {
            *a += v * v * extra_curv(x0 + dir * dx * j as f64);
        }
    }
    let mut out = Vec::new();
    for method in [FusionMethod::SnrWeighted, FusionMethod::SpatialContinuity] {
        let cfg = StraightnessConfig { method, noise_density: Some(rho), ..StraightnessConfig::default() };
        let est = estimate_straightness(&runs, &cfg).unwrap();
        let m = est.positions.len();
        let xs = &est.positions[m / 5..m - m / 5];
        let d: Vec<f64> =
            xs.iter().zip(&est.straightness[m / 5..m - m / 5]).map(|(&x, e)| e - truth(x) - extra(x)).collect();
        let res = remove_quadratic(xs, &d);
        eprintln!(
            "non-periodic {method:?}: interior RMS error {:.3e} m (quadratic removed; {:.3e} m without)",
            rms(&res),
            rms(&d)
        );
        out.push(rms(&res));
    }
    assert!(out[0] <= out[1]);
    assert!(out[0] < 0.3e-6);
}

/// y minus its least-squares quadratic in x (normal equations on centred x; well conditioned here).
fn remove_quadratic(x: &[f64], y: &[f64]) -> Vec<f64> {
    let xm = x.iter().sum::<f64>() / x.len() as f64;
    let mut m = [[0.0f64; 3]; 3];
    let mut r = [0.0f64; 3];
    for (&xi, &yi) in x.iter().zip(y) {
        let u = xi - xm;
        let row = [1.0, u, u * u];
        for i in 0..3 {
            r[i] += row[i] * yi;
            for j in 0..3 {
                m[i][j] += row[i] * row[j];
            }
        }
    }
    for c in 0..3 {
        for row in c + 1..3 {
            let pivot = m[c];
            let f = m[row][c] / pivot[c];
            for (x, y) in m[row][c..].iter_mut().zip(&pivot[c..]) {
                *x -= f * y;
            }
            r[row] -= f * r[c];
        }
    }
    let mut s = [0.0f64; 3];
    for i in (0..3).rev() {
        let t: f64 = (i + 1..3).map(|j| m[i][j] * s[j]).sum();
        s[i] = (r[i] - t) / m[i][i];
    }
    x.iter()
        .zip(y)
        .map(|(&xi, &yi)| {
            let u = xi - xm;
            yi - s[0] - s[1] * u - s[2] * u * u
        })
        .collect()
}

#[test]
fn gravity_tilt_separation_recovers_straightness_and_roll() {
    // Same truth and seed-000 runs, plus a Y-sensor roll τ(x) = 10 µrad·sin(2πx/0.2 + 0.5) + 5 µrad·sin(2πx/0.125 + 1)
    // read as g·τ. Cosine basis, ρ = 0.5 µg/√Hz given. With separation: each quadrature component of the
    // error at every straightness and roll harmonic ≤ 3× its joint-model Cramér–Rao bound (3σ). Without:
    // the tilt leaks into the curvature as K = … + g·T·S₂/S₄, so the straightness error at the roll
    // harmonics is g·T·(S₂/S₄)/κ² (predicted, asserted within 10 % + 3σ).
    let g = STANDARD_GRAVITY;
    let roll = |x: f64| 10e-6 * (2.0 * PI * x / 0.2 + 0.5).sin() + 5e-6 * (2.0 * PI * x / 0.125 + 1.0).sin();
    let rho = 0.5 * UG;
    let mut runs = make_runs(rho, 91);
    for r in runs.iter_mut() {
        let dx = r.speed / r.sample_rate;
        for (j, a) in r.acceleration.iter_mut().enumerate() {
            *a += g * roll(r.start_position + r.direction as f64 * dx * j as f64);
        }
    }
    let cfg = |sep: bool| StraightnessConfig {
        noise_density: Some(rho),
        basis: SpectralBasis::Cosine,
        separate_gravity_tilt: sep,
        ..snr_config(Some(rho))
    };
    let sep = estimate_straightness(&runs, &cfg(true)).unwrap();
    let plain = estimate_straightness(&runs, &cfg(false)).unwrap();
    let x = &sep.positions;
    let curv: Vec<f64> = x.iter().map(|&x| truth_curvature(x)).collect();
    let tb = integrate_curvature_cosine(x, &curv, sep.band.min_wavelength, sep.band.max_wavelength).unwrap();
    // Components at λ: the error restricted to the octaves around λ (cosine band-limit to [λ/2, 2λ]),
    // then the LS fit of [1, sin, cos]. Restricting first keeps the large long-wave noise coefficients
    // (their bound grows as λ²) from leaking into the fit over a range that is not a whole number of
    // their half-cycles; the noise at λ itself is kept.
    let comp = |e: &[f64], wl: f64| {
        let k = 2.0 * PI / wl;
        let e = band_limit_cosine(x, e, wl / 2.0, 2.0 * wl, true).unwrap();
        let h = fit_harmonic_amplitude(x, &e, 1.0, wl).unwrap();
        (-h.sin * k * k, -h.cos * k * k)
    };
    let err: Vec<f64> = sep.straightness.iter().zip(&tb).map(|(a, b)| a - b).collect();
    for &(wl, _, _) in HARMONICS.iter().chain(&[(0.2, 0.0, 0.0)]) {
        let (s, c) = comp(&err, wl);
        let b = cramer_rao_harmonic(&[rho; 3], &SPEEDS, sep.travel, wl, 0.0, true).unwrap();
        assert_eq!(sep.harmonic_std(wl).unwrap(), b.straightness);
        eprintln!(
            "separated λ={wl}: error ({s:.2e}, {c:.2e}) m, joint CR {:.2e} (T known {:.2e}), ratios ({:.2}, {:.2})",
            b.straightness,
            b.straightness_tilt_known,
            s.abs() / b.straightness,
            c.abs() / b.straightness
        );
        assert!(b.straightness > b.straightness_tilt_known);
        assert!(s.abs() <= 3.0 * b.straightness && c.abs() <= 3.0 * b.straightness);
    }
    let tilt = sep.tilt.as_ref().unwrap();
    let rt: Vec<f64> = x.iter().map(|&x| roll(x)).collect();
    let rb =
        band_limit_cosine(x, &rt, sep.tilt_min_wavelength.unwrap(), sep.tilt_max_wavelength.unwrap(), false).unwrap();
    let d: Vec<f64> = tilt.iter().zip(&rb).map(|(a, b)| a - b).collect();
    eprintln!("tilt: RMS difference {:.3e} rad of roll RMS {:.3e}", rms(&d), rms(&rb));
    for wl in [0.2, 0.125] {
        let (s, c) = comp(&d, wl);
        let ct = sep.tilt_std(wl).unwrap().unwrap();
        eprintln!("  roll λ={wl}: error ({s:.2e}, {c:.2e}) rad, CR {ct:.2e}");
        assert!(s.abs() <= 3.0 * ct && c.abs() <= 3.0 * ct);
    }
    // Without separation: biased at the roll harmonics by the predicted leak.
    let err: Vec<f64> = plain.straightness.iter().zip(&tb).map(|(a, b)| a - b).collect();
    let (mut s0, mut s2, mut s4) = (0.0, 0.0, 0.0);
    for v in SPEEDS {
        let q = 1.0 / v; // ∝ L/(v ρ²), common factors cancel in S₂/S₄
        s0 += q;
        s2 += q * v * v;
        s4 += q * v.powi(4);
    }
    let _ = s0;
    for (wl, amp, ph) in [(0.2, 10e-6, 0.5f64), (0.125, 5e-6, 1.0)] {
        let k = 2.0 * PI / wl;
        let pred = g * amp * (s2 / s4) / (k * k);
        let (s, c) = comp(&err, wl);
        let cr = plain.harmonic_std(wl).unwrap();
        // The leak is +g·τ/… in curvature, i.e. −g·τ·(S₂/S₄)/κ² in E: sign −, in phase with τ.
        let (ps, pc) = (-pred * ph.cos(), -pred * ph.sin());
        eprintln!("not separated λ={wl}: error ({s:.2e}, {c:.2e}) m, predicted ({ps:.2e}, {pc:.2e}), CR {cr:.2e}");
        assert!((s - ps).hypot(c - pc) <= 0.1 * pred + 3.0 * cr);
        assert!(s.hypot(c) > 10.0 * cr);
    }
}
