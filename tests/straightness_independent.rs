//! Issue 17: the accelerometer straightness estimator (seed 000 and the SNR-weighted fusion) on passes made
//! by a generator independent of vmt's simulator, and `vmt straightness` on a set written by that
//! generator and on one written by `vmt simulate`.
//!
//! The generator (here, not vmt's): random smooth straightness profiles `E(x)` as random Fourier features
//! of a squared-exponential and a Matérn-5/2 kernel at three correlation lengths (L/3, L/8, L/20 scaled
//! by a random factor: not harmonics of the travel), a random smooth gravity tilt `τ(x)` (correlation
//! L/2 … L/5), three speeds with random ratios, random sample rates (equal spacing as in seed 000 in half
//! the draws, independent rates and unequal sample counts in the other half), a random constant offset
//! per pass, and white Gaussian noise of one-sided density `ρ` drawn log-uniformly from 0.1 µg/√Hz
//! (piezo) to 30 µg/√Hz (MEMS). A reading is the mean acceleration over the sample interval before its
//! time stamp (an averaging ADC), computed exactly from the analytic slope `E'` and the antiderivative
//! of `τ`: `a_j = dir·v·(E'(x_j) − E'(x_{j−1}))/Δt + g·(T(x_j) − T(x_{j−1}))/(x_j − x_{j−1}) + b + n_j`.

use crate::util::{rms, vmt};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, StandardNormal, StudentT};
use rayon::prelude::*;
use std::f64::consts::PI;
use std::path::Path;
use vmt::measurement::{self, MeasurementSet, Procedure, Run, RunData, Sensor, SensorKind, UnitChoice};
use vmt::straightness::{accel_config, sensor_straightness, PassSelection};
use vmt_estimators::accel_straightness::{
    band_limit_cosine, dct2, estimate_straightness, integrate_curvature_cosine, AccelRun, FusionMethod,
    STANDARD_GRAVITY,
};
use vmt_estimators::line::remove_line;
use vmt_sim::Axis;

/// A sum of random Fourier features `f(x) = Σ a_j·cos(k_j·x + φ_j)`, with value, slope, curvature and
/// antiderivative in closed form.
#[derive(Clone, Debug)]
struct Features {
    a: Vec<f64>,
    k: Vec<f64>,
    phi: Vec<f64>,
}

impl Features {
    /// `n` features of a stationary process of RMS `rms` and correlation length `ell` (m): squared-exponential
    /// kernel (k ~ N(0, 1/ℓ²)) or Matérn-5/2 (k ~ Student-t₅/ℓ·…), amplitudes `rms·√(2/n)·N(0,1)`.
    fn random(rng: &mut ChaCha8Rng, n: usize, rms: f64, ell: f64, matern: bool) -> Features {
        let mut f = Features { a: Vec::new(), k: Vec::new(), phi: Vec::new() };
        let t5 = StudentT::new(5.0).unwrap();
        for _ in 0..n {
            let z: f64 = if matern { t5.sample(rng) } else { StandardNormal.sample(rng) };
            let w: f64 = StandardNormal.sample(rng);
            f.k.push(z / ell);
            f.a.push(rms * (2.0 / n as f64).sqrt() * w);
            f.phi.push(rng.gen::<f64>() * 2.0 * PI);
        }
        f
    }
    fn extend(&mut self, o: Features) {
        self.a.extend(o.a);
        self.k.extend(o.k);
        self.phi.extend(o.phi);
    }
    fn value(&self, x: f64) -> f64 {
        (0..self.a.len()).map(|j| self.a[j] * (self.k[j] * x + self.phi[j]).cos()).sum()
    }
    fn slope(&self, x: f64) -> f64 {
        (0..self.a.len()).map(|j| -self.a[j] * self.k[j] * (self.k[j] * x + self.phi[j]).sin()).sum()
    }
    fn curvature(&self, x: f64) -> f64 {
        (0..self.a.len()).map(|j| -self.a[j] * self.k[j] * self.k[j] * (self.k[j] * x + self.phi[j]).cos()).sum()
    }
    /// ∫ f dx (a constant aside); features with |k| < 1e-9 rad/m contribute a·cos φ·x.
    fn antiderivative(&self, x: f64) -> f64 {
        (0..self.a.len())
            .map(|j| {
                let k = self.k[j];
                if k.abs() < 1e-9 {
                    self.a[j] * self.phi[j].cos() * x
                } else {
                    self.a[j] * (k * x + self.phi[j]).sin() / k
                }
            })
            .sum()
    }
}

/// One generated draw: passes, the truth, the noise density.
struct Draw {
    profile: Features,
    tilt: Option<Features>,
    rho: f64,
    /// Per pass: run, and the commanded position of each sample (x_cmd: the end of its interval).
    passes: Vec<(AccelRun, Vec<f64>)>,
}

fn ug(x: f64) -> f64 {
    x * STANDARD_GRAVITY * 1e-6
}

/// A random measurement (seeded): `with_tilt` adds a gravity tilt (a horizontal sensor across the motion).
fn generate(seed: u64, with_tilt: bool) -> Draw {
    generate_scaled(seed, with_tilt, 1.0, 1.0, None)
}

/// [`generate`] with the signal (straightness and tilt) scaled by `signal` and the noise by `noise` (the
/// same random numbers: a draw's error splits into its signal and noise parts), or the profile replaced
/// by `single` (one feature) when given.
fn generate_scaled(seed: u64, with_tilt: bool, signal: f64, noise_scale: f64, single: Option<Features>) -> Draw {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let travel = rng.gen_range(0.4..1.2);
    let start = rng.gen_range(-0.1..0.3);
    let rms = rng.gen_range(0.5e-6..5e-6);
    let mut profile = Features { a: vec![], k: vec![], phi: vec![] };
    for (i, frac) in [3.0, 8.0, 20.0].iter().enumerate() {
        let ell = travel / frac * rng.gen_range(0.7..1.4);
        let share = rng.gen_range(0.2..1.0);
        profile.extend(Features::random(&mut rng, 24, rms * share, ell, i == 1));
    }
    if let Some(f) = single {
        profile = f;
    }
    let tilt = with_tilt.then(|| {
        let ell = travel / rng.gen_range(2.0..5.0);
        let rms = rng.gen_range(2e-6..20e-6);
        Features::random(&mut rng, 24, rms, ell, false)
    });
    let rho = ug(10f64.powf(rng.gen_range(-1.0..(30f64).log10())));
    let v_hi = rng.gen_range(0.2..0.5);
    let speeds = [v_hi, v_hi * rng.gen_range(0.35..0.7), v_hi * rng.gen_range(0.1..0.3)];
    let fs_hi = rng.gen_range(800.0..2000.0);
    let equal_spacing = rng.gen_bool(0.5);
    let mut passes = Vec::new();
    for (i, &v) in speeds.iter().enumerate() {
        let fs = if equal_spacing { fs_hi * v / v_hi } else { rng.gen_range(300.0..2000.0) };
        let dir: i32 = if i % 2 == 0 { 1 } else { -1 };
        let dt = 1.0 / fs;
        // The pass covers the travel plus a little margin; x_cmd at the end of each interval.
        let n = ((travel + 0.004) / (v * dt)).ceil() as usize;
        let x_first = if dir == 1 { start - 0.002 } else { start + travel + 0.002 };
        let bias = rng.gen_range(-1e-3..1e-3);
        let sigma = rho * (fs / 2.0).sqrt();
        let mut x_cmd = Vec::with_capacity(n);
        let mut acc = Vec::with_capacity(n);
        for j in 0..n {
            let x1 = x_first + f64::from(dir) * v * dt * (j as f64 + 1.0);
            let x0 = x1 - f64::from(dir) * v * dt;
            let lateral = f64::from(dir) * v * (profile.slope(x1) - profile.slope(x0)) / dt;
            let g_tilt = tilt
                .as_ref()
                .map_or(0.0, |t| STANDARD_GRAVITY * (t.antiderivative(x1) - t.antiderivative(x0)) / (x1 - x0));
            let noise: f64 = StandardNormal.sample(&mut rng);
            x_cmd.push(x1);
            acc.push(signal * (lateral + g_tilt) + bias + noise_scale * sigma * noise);
        }
        let run = AccelRun {
            speed: v,
            sample_rate: fs,
            // reading j belongs to the middle of its interval, half a sample behind x_cmd
            start_position: x_cmd[0] - f64::from(dir) * v * dt / 2.0,
            direction: dir,
            acceleration: acc,
        };
        passes.push((run, x_cmd));
    }
    Draw { profile, tilt, rho, passes }
}

/// What one method did on one draw.
#[derive(Clone, Debug)]
struct Outcome {
    /// In-band RMS error (m) / Cramér–Rao bound of the in-band RMS (m).
    ratio: f64,
    /// Effective number of independent in-band coefficients (for the χ² scatter of `ratio²`).
    dof: f64,
    /// Error of each in-band cosine coefficient / its bound.
    harmonics: Vec<f64>,
    /// Tilt: in-band RMS error (rad) / bound.
    tilt_ratio: Option<f64>,
    /// Every pass has the same sample spacing `v/fs` (the seed's layout): the grid takes the passes'
    /// samples without interpolating across spacings.
    equal_spacing: bool,
    rho_ug: f64,
}

/// The sensor of a generated set, as a manifest declares it: a Y (horizontal, across X) accelerometer when
/// the draw has a tilt, a Z one otherwise.
fn sensor(with_tilt: bool, rho: Option<f64>) -> Sensor {
    Sensor {
        name: if with_tilt { "acc_y".into() } else { "acc_z".into() },
        kind: SensorKind::Accelerometer,
        axis: Axis::X,
        position: [0.0, 0.0, 0.0],
        direction: if with_tilt { [0.0, 1.0, 0.0] } else { [0.0, 0.0, 1.0] },
        sigma: None,
        closes_loop: false,
        noise_density: rho,
        highpass: None,
    }
}

fn evaluate(d: &Draw, method: FusionMethod) -> Option<Outcome> {
    let s = sensor(d.tilt.is_some(), Some(d.rho));
    let cfg = accel_config(&s, method);
    let runs: Vec<AccelRun> = d.passes.iter().map(|p| p.0.clone()).collect();
    let est = estimate_straightness(&runs, &cfg).unwrap();
    if est.band.empty {
        return None;
    }
    let b = est.in_band_bounds().unwrap();
    let xs = &est.positions;
    let curv: Vec<f64> = xs.iter().map(|&x| d.profile.curvature(x)).collect();
    let truth = integrate_curvature_cosine(xs, &curv, est.band.min_wavelength, est.band.max_wavelength).unwrap();
    let err: Vec<f64> = remove_line(xs, &est.straightness).iter().zip(&truth).map(|(a, t)| a - t).collect();
    let m = xs.len();
    let c = dct2(&err);
    let mut harmonics = Vec::new();
    let (mut sw, mut sw2) = (0.0, 0.0);
    for bin in &b.bins {
        if let Some(sk) = bin.straightness {
            harmonics.push(2.0 / m as f64 * c[bin.k] / sk);
            sw += sk * sk;
            sw2 += sk.powi(4);
        }
    }
    let tilt_ratio = match (&d.tilt, &est.tilt, b.tilt_rms) {
        (Some(t), Some(te), Some(tb)) => {
            let tv: Vec<f64> = xs.iter().map(|&x| t.value(x)).collect();
            let (lo, hi) = (est.tilt_min_wavelength.unwrap(), est.tilt_max_wavelength.unwrap());
            let band = band_limit_cosine(xs, &tv, lo, hi, false).unwrap();
            let mean = band.iter().sum::<f64>() / m as f64;
            let e: Vec<f64> = te.iter().zip(&band).map(|(a, t)| a - (t - mean)).collect();
            Some(rms(&e) / tb)
        }
        _ => None,
    };
    Some(Outcome {
        ratio: rms(&err) / b.straightness_rms,
        dof: sw * sw / sw2,
        harmonics,
        tilt_ratio,
        rho_ug: d.rho / ug(1.0),
        equal_spacing: equal_spacing(d),
    })
}

/// Whether every pass of a draw has the same sample spacing `v/fs` (to 1e-9 relative).
fn equal_spacing(d: &Draw) -> bool {
    let steps: Vec<f64> = d.passes.iter().map(|p| p.0.speed / p.0.sample_rate).collect();
    steps.iter().all(|s| (s / steps[0] - 1.0).abs() < 1e-9)
}

fn mean(v: &[f64]) -> f64 {
    v.iter().sum::<f64>() / v.len() as f64
}

fn p95(v: &[f64]) -> f64 {
    let mut s = v.to_vec();
    s.sort_by(f64::total_cmp);
    s[((s.len() as f64 * 0.95).ceil() as usize).min(s.len()) - 1]
}

const DRAWS: u64 = 200;

/// The `t > 1` with `(t·e^{1−t})^{dof/2} = p`: the Chernoff bound `P(χ²_dof ≥ dof·t) ≤ (t·e^{1−t})^{dof/2}`
/// (for the weighted χ² of the in-band error, Satterthwaite's effective dof), by bisection.
fn chi2_upper_chernoff(dof: f64, p: f64) -> f64 {
    let excess = |t: f64| 0.5 * dof * (t.ln() + 1.0 - t) - p.ln();
    let (mut lo, mut hi) = (1.0, 2.0);
    while excess(hi) > 0.0 {
        hi *= 2.0;
    }
    for _ in 0..100 {
        let mid = 0.5 * (lo + hi);
        if excess(mid) > 0.0 {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    hi
}

/// Issue 17, must show: over 200 independent draws per sensor orientation (a Z sensor: straightness
/// only; a Y sensor: straightness and gravity tilt = roll separated jointly), the SNR-weighted fusion's
/// in-band RMS error is within 1.5× the in-band Cramér–Rao bound on average and not below it beyond
/// Monte-Carlo scatter; per-coefficient error/bound RMS ≤ 1.5; the roll within 2× its bound on average.
///
/// Tolerances: for an efficient unbiased estimator `ratio²` is a weighted χ² with mean 1 and relative
/// spread `√(2/dof)` (dof = the effective number of in-band coefficients, `(Σσ²)²/Σσ⁴`); "below the bound
/// beyond scatter" is `ratio² < 1 − 4·√(2/dof)` (probability < 1e-4 per draw for dof ≥ 8; for smaller
/// dof the χ² lower tail cannot reach it) and must not happen; the mean of 200 ratios must exceed
/// `1 − 3·SE` (SE from the draws). No heavy tail: a draw above the Chernoff bound of the χ² upper tail at
/// probability 1e-6, `ratio² ≤ t` with `(t·e^{1−t})^{dof/2} = 1e-6`, fails (an out-of-band rounding once
/// dropped the k = 4 mode and gave 64× the bound in 6 of 200 draws). The 1.5 and 2 are the limits for model mismatch (resampling,
/// averaging, the least-squares line). The seed method's numbers are printed beside the fusion's (its
/// `harmonic_std` is a guide, not a bound: the Kalman filter and high-pass shrink the signal).
#[test]
fn fusion_attains_cramer_rao_on_independently_generated_passes() {
    let t0 = std::time::Instant::now();
    for with_tilt in [false, true] {
        let results: Vec<(Option<Outcome>, Option<Outcome>)> = (0..DRAWS)
            .into_par_iter()
            .map(|i| {
                let d = generate(1000 + i + if with_tilt { 500 } else { 0 }, with_tilt);
                // The seed method is reported beside the fusion, not asserted (its σ is a guide, not a bound):
                // every second draw keeps the test within the CI budget.
                let seed = if i % 2 == 0 { evaluate(&d, FusionMethod::SpatialContinuity) } else { None };
                (evaluate(&d, FusionMethod::SnrWeighted), seed)
            })
            .collect();
        let fusion: Vec<&Outcome> = results.iter().filter_map(|r| r.0.as_ref()).collect();
        let seed: Vec<&Outcome> = results.iter().filter_map(|r| r.1.as_ref()).collect();
        let label = if with_tilt { "Y sensor (tilt separated)" } else { "Z sensor" };
        let ratios: Vec<f64> = fusion.iter().map(|o| o.ratio).collect();
        let harm: Vec<f64> = fusion.iter().flat_map(|o| o.harmonics.iter().copied()).collect();
        let harm_rms = rms(&harm);
        let (eq, uneq): (Vec<&&Outcome>, Vec<&&Outcome>) = fusion.iter().partition(|o| o.equal_spacing);
        let harm_eq: Vec<f64> = eq.iter().flat_map(|o| o.harmonics.iter().copied()).collect();
        let harm_uneq: Vec<f64> = uneq.iter().flat_map(|o| o.harmonics.iter().copied()).collect();
        // Scatter of the RMS of n coefficients, each error/CR ~ N(0, 1) if efficient: √(1/(2n)); the
        // coefficients of one draw are not independent (they share the noise of the interpolated passes),
        // so per draw: the RMS's scatter is taken from the spread of the per-draw mean squares.
        let se_of_rms = |set: &[&&Outcome]| {
            let ms: Vec<f64> =
                set.iter().map(|o| mean(&o.harmonics.iter().map(|h| h * h).collect::<Vec<_>>())).collect();
            let w: Vec<f64> = set.iter().map(|o| o.harmonics.len() as f64).collect();
            let tot: f64 = w.iter().sum();
            let m = ms.iter().zip(&w).map(|(a, b)| a * b).sum::<f64>() / tot;
            let var = ms.iter().zip(&w).map(|(a, b)| b * b * (a - m) * (a - m)).sum::<f64>() / (tot * tot);
            (m.sqrt(), var.sqrt() / (2.0 * m.sqrt()))
        };
        let (rms_eq, se_eq) = se_of_rms(&eq);
        let (rms_uneq, se_uneq) = se_of_rms(&uneq);
        println!(
            "{label}: per-coefficient error/CR RMS {rms_eq:.3} ± {se_eq:.3} (1 SE) on {} equal-spacing draws \
             ({} coefficients), {rms_uneq:.3} ± {se_uneq:.3} on {} draws of unequal spacings ({} coefficients)",
            eq.len(),
            harm_eq.len(),
            uneq.len(),
            harm_uneq.len()
        );
        let seed_ratios: Vec<f64> = seed.iter().map(|o| o.ratio).collect();
        println!(
            "{label}: fusion {} of {DRAWS} draws with a band: in-band RMS error / CR bound mean {:.3}, p95 {:.3}, \
             min {:.3}, max {:.3}; per-coefficient error/CR RMS {:.3} over {} coefficients; ρ {:.2}–{:.2} µg/√Hz",
            fusion.len(),
            mean(&ratios),
            p95(&ratios),
            ratios.iter().cloned().fold(f64::INFINITY, f64::min),
            ratios.iter().cloned().fold(0.0, f64::max),
            harm_rms,
            harm.len(),
            fusion.iter().map(|o| o.rho_ug).fold(f64::INFINITY, f64::min),
            fusion.iter().map(|o| o.rho_ug).fold(0.0, f64::max),
        );
        println!(
            "{label}: seed 000 {} draws: in-band RMS error / its guide bound mean {:.3}, p95 {:.3}, max {:.3}",
            seed.len(),
            mean(&seed_ratios),
            p95(&seed_ratios),
            seed_ratios.iter().cloned().fold(0.0, f64::max)
        );
        assert_eq!(fusion.len() as u64, DRAWS, "{label}: every draw has a recoverable band");
        let m = mean(&ratios);
        let se = (ratios.iter().map(|r| (r - m) * (r - m)).sum::<f64>() / (ratios.len() - 1) as f64).sqrt()
            / (ratios.len() as f64).sqrt();
        assert!(m <= 1.5, "{label}: mean in-band error / CR bound {m:.3} > 1.5");
        assert!(m >= 1.0 - 3.0 * se, "{label}: mean ratio {m:.3} below the bound by more than 3 SE ({se:.3})");
        for o in &fusion {
            let ceiling = chi2_upper_chernoff(o.dof, 1e-6);
            assert!(
                o.ratio * o.ratio <= ceiling,
                "{label}: ratio {:.3} above the χ² tail bound {:.3} at probability 1e-6 (dof {:.1})",
                o.ratio,
                ceiling.sqrt(),
                o.dof
            );
            let floor = 1.0 - 4.0 * (2.0 / o.dof).sqrt();
            assert!(
                o.ratio * o.ratio >= floor,
                "{label}: ratio {:.3} below the bound beyond scatter (dof {:.1})",
                o.ratio,
                o.dof
            );
        }
        assert!(harm_rms <= 1.5, "{label}: per-coefficient error/CR RMS {harm_rms:.3} > 1.5");
        // Not below the bound beyond Monte-Carlo scatter (the criterion), on either layout. Until each
        // pass was resampled by a band-limited kernel (`resampling_kernel`) it was linearly interpolated onto
        // the common grid, with gain |(1 − u) + u·e^{iω}| ≤ 1 on signal and noise alike: 200 draws gave Z 0.991 ±
        // 0.002 on equal spacings and 0.914 ± 0.003 on unequal ones, Y 0.999 ± 0.002 and 0.936 ± 0.001.
        assert!(
            rms_eq >= 1.0 - 3.0 * se_eq,
            "{label}: per-coefficient error/CR RMS {rms_eq:.3} on equal spacings below 1 by more than 3 SE ({se_eq:.3})"
        );
        assert!(
            rms_uneq >= 1.0 - 3.0 * se_uneq,
            "{label}: per-coefficient error/CR RMS {rms_uneq:.3} on unequal spacings below 1 by more than 3 SE ({se_uneq:.3})"
        );
        if with_tilt {
            let tr: Vec<f64> = fusion.iter().filter_map(|o| o.tilt_ratio).collect();
            println!(
                "{label}: roll in-band RMS error / CR bound over {} draws: mean {:.3}, p95 {:.3}, max {:.3}",
                tr.len(),
                mean(&tr),
                p95(&tr),
                tr.iter().cloned().fold(0.0, f64::max)
            );
            assert_eq!(tr.len(), fusion.len(), "every Y draw separates the tilt");
            assert!(mean(&tr) <= 2.0, "roll: mean error / bound {:.3} > 2", mean(&tr));
        }
    }
    println!("took {:.1} s", t0.elapsed().as_secs_f64());
}

/// A generated draw written as a FORMAT.md §1 measurement set (x_cmd at full precision, noise density in
/// the manifest when `stated`).
fn write_set(d: &Draw, dir: &Path, stated: bool) {
    let s = sensor(d.tilt.is_some(), stated.then_some(d.rho));
    let runs = d
        .passes
        .iter()
        .enumerate()
        .map(|(i, (r, x))| Run {
            name: format!("pass{i}"),
            file: format!("pass{i}.csv"),
            procedure: Procedure::ConstantVelocity,
            axis: Axis::X,
            start_time: None,
            feed: Some(r.speed),
            direction: Some(r.direction as i8),
            data: RunData::TimeSeries {
                t: (0..x.len()).map(|j| (j as f64 + 1.0) / r.sample_rate).collect(),
                columns: vec![("x_cmd".into(), x.clone()), (s.name.clone(), r.acceleration.clone())],
            },
        })
        .collect();
    let set = MeasurementSet {
        description: Some("generated by tests/straightness_independent.rs".into()),
        machine: None,
        seed: None,
        sensors: vec![s],
        runs,
    };
    measurement::write(&set, dir, UnitChoice::Si).unwrap();
}

fn max_rel_diff(a: &[f64], b: &[f64]) -> f64 {
    assert_eq!(a.len(), b.len());
    let scale = a.iter().fold(0.0f64, |m, v| m.max(v.abs()));
    a.iter().zip(b).map(|(x, y)| (x - y).abs()).fold(0.0, f64::max) / scale
}

/// The same data through the library (the generator's passes straight into `estimate_straightness`) and
/// through `vmt straightness` (written as a measurement set, read back, the binary's JSON): the same
/// estimate to 1e-12 relative on the same numbers (the generator's own passes differ from the written set
/// by an ulp of the sample rate recomputed from `t`; that moves the estimate by up to 2e-8, see below). Also with the noise density left out of the manifest:
/// then estimated from the records, and the JSON says so.
#[test]
fn vmt_straightness_on_a_generated_set_matches_the_library() {
    let tmp = tempfile::tempdir().unwrap();
    for (seed, with_tilt) in [(7u64, true), (8, false)] {
        let d = generate(seed, with_tilt);
        let dir = tmp.path().join(format!("set{seed}"));
        write_set(&d, &dir, true);
        let s = sensor(with_tilt, Some(d.rho));
        let exact: Vec<AccelRun> = d.passes.iter().map(|p| p.0.clone()).collect();
        // The generator's passes with the sample rate as the written time stamps define it, (N − 1)/(t_N − t_1)
        // (a few ulp from the drawn rate) and the first position accordingly.
        let runs: Vec<AccelRun> = d
            .passes
            .iter()
            .map(|(r, x)| {
                let n = x.len();
                let t = |j: usize| (j as f64 + 1.0) / r.sample_rate;
                let rate = (n - 1) as f64 / (t(n - 1) - t(0));
                let start_position = x[0] - f64::from(r.direction) * r.speed / (2.0 * rate);
                AccelRun { sample_rate: rate, start_position, ..r.clone() }
            })
            .collect();
        for method in [FusionMethod::SnrWeighted, FusionMethod::SpatialContinuity] {
            let lib = estimate_straightness(&runs, &accel_config(&s, method)).unwrap();
            let drawn = estimate_straightness(&exact, &accel_config(&s, method)).unwrap();
            println!(
                "seed {seed} {method:?}: the drawn rate instead (a few ulp away) moves the estimate by {:.2e} relative",
                max_rel_diff(&lib.straightness, &drawn.straightness)
            );
            let set = measurement::read(&dir).unwrap();
            let via = sensor_straightness(&set, &dir, &s.name, PassSelection::ConstantVelocity, method).unwrap();
            // The library on exactly the numbers the set holds: identical.
            let same = estimate_straightness(&via.runs, &accel_config(&s, method)).unwrap();
            let d_same = max_rel_diff(&same.straightness, &via.estimate.straightness);
            assert!(d_same <= 1e-12, "{method:?}: {d_same:e}");
            let diff = max_rel_diff(&lib.straightness, &via.estimate.straightness);
            println!(
                "seed {seed} {method:?}: library on the set's numbers vs the set path {d_same:.2e}; on the \
                 generator's passes (sample rate 1–2 ulp from the one the written time stamps give) {diff:.2e}"
            );
            // Measured 3.5e-15 (fusion) and 3.0e-13 (seed method: Kalman filter and high-pass carry the ulp
            // further). It was 1.9e-8 while band membership was decided by a different rounding in each
            // function (`in_band`): an ulp of the sample rate moved a band-edge bin in or out. 1e-11 leaves
            // 30× over the seed method's propagation; a unit or half-sample mistake gives > 1e-3.
            assert!(diff <= 1e-11, "{method:?}: {diff:e}");
            if let (Some(a), Some(b)) = (&lib.tilt, &via.estimate.tilt) {
                assert!(max_rel_diff(a, b) <= 1e-12);
            }
        }
        // The binary: JSON and the profile CSV.
        let csv = dir.join("estimate.csv");
        let out = vmt()
            .args(["straightness", dir.to_str().unwrap(), "--json", "-o", csv.to_str().unwrap()])
            .output()
            .unwrap();
        assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
        let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
        assert_eq!(v["format"], "vmt-straightness/1");
        let e = &v["sensors"][0];
        let from_json: Vec<f64> =
            e["estimate"]["straightness"].as_array().unwrap().iter().map(|x| x.as_f64().unwrap()).collect();
        let set = measurement::read(&dir).unwrap();
        let cv = PassSelection::ConstantVelocity;
        let via = sensor_straightness(&set, &dir, &s.name, cv, FusionMethod::SnrWeighted).unwrap();
        let lib = estimate_straightness(&via.runs, &accel_config(&s, FusionMethod::SnrWeighted)).unwrap();
        assert!(max_rel_diff(&lib.straightness, &from_json) <= 1e-12);
        assert_eq!(e["passes"][0]["noise_density_source"], "manifest");
        assert!(e["bounds"]["straightness_rms"].as_f64().unwrap() > 0.0);
        let table = measurement::read_profiles(&csv).unwrap();
        let effect = if with_tilt { "straightness_y" } else { "straightness_z" };
        let col = table.columns.iter().find(|c| c.effect.as_str() == effect).unwrap();
        assert!(col.sigma.as_ref().unwrap().iter().all(|&s| s > 0.0));
        assert_eq!(table.columns.iter().any(|c| c.effect.as_str() == "roll"), with_tilt);
        // Without a stated density: estimated per record, and said so.
        let dir2 = tmp.path().join(format!("unstated{seed}"));
        write_set(&d, &dir2, false);
        let set = measurement::read(&dir2).unwrap();
        let via = sensor_straightness(&set, &dir2, &s.name, PassSelection::ConstantVelocity, FusionMethod::SnrWeighted)
            .unwrap();
        for p in &via.passes {
            assert_eq!(p.noise_density_source, "estimated from the record");
            // Estimated from the upper half of ~1000+ periodogram bins: within 15 % of the true density.
            assert!((p.noise_density / d.rho - 1.0).abs() < 0.15, "{} vs {}", p.noise_density, d.rho);
        }
    }
}

/// Passes the method cannot use are refused with exit code 2, naming the file and the run.
#[test]
fn vmt_straightness_refuses_unusable_passes() {
    let tmp = tempfile::tempdir().unwrap();
    let d = generate(11, true);
    let run = |dir: &Path, extra: &[&str]| {
        let mut args = vec!["straightness", dir.to_str().unwrap()];
        args.extend_from_slice(extra);
        vmt().args(&args).output().unwrap()
    };
    let edit = |name: &str, f: &dyn Fn(&mut MeasurementSet)| {
        let dir = tmp.path().join(name);
        write_set(&d, &dir, true);
        let mut set = measurement::read(&dir).unwrap();
        f(&mut set);
        let dir2 = tmp.path().join(format!("{name}-edited"));
        measurement::write(&set, &dir2, UnitChoice::Si).unwrap();
        dir2
    };
    let cases: Vec<(&str, std::path::PathBuf, &str)> = vec![
        ("missing feed", edit("nofeed", &|s| s.runs[1].feed = None), "missing `feed`"),
        (
            "speed varying within a pass",
            edit("ramp", &|s| {
                if let RunData::TimeSeries { columns, .. } = &mut s.runs[0].data {
                    let x = &mut columns[0].1;
                    let (x0, n) = (x[0], x.len() as f64);
                    for (j, v) in x.iter_mut().enumerate() {
                        // the second half 10 % faster
                        let u = j as f64 / n;
                        *v = x0 + (*v - x0) * if u > 0.5 { 1.0 + 0.2 * (u - 0.5) } else { 1.0 };
                    }
                }
            }),
            "the speed varies within the pass",
        ),
        ("too few speeds", edit("onespeed", &|s| s.runs.truncate(1)), "too few speeds"),
        (
            "non-uniform time stamps",
            edit("jitter", &|s| {
                if let RunData::TimeSeries { t, .. } = &mut s.runs[2].data {
                    // one sample 40 % of a step late
                    let dt = t[1] - t[0];
                    t[100] += 0.4 * dt;
                }
            }),
            "expected uniformly spaced time stamps",
        ),
        (
            "direction disagreeing with x_cmd",
            edit("backwards", &|s| s.runs[0].direction = Some(-1)),
            "`direction` = -1",
        ),
    ];
    for (what, dir, expect) in cases {
        let out = run(&dir, &[]);
        let err = String::from_utf8_lossy(&out.stderr);
        println!("{what}: {err}");
        assert_eq!(out.status.code(), Some(2), "{what}: {err}");
        assert!(err.contains(expect), "{what}: {err}");
        assert!(err.contains(dir.to_str().unwrap()), "{what}: the message names the set: {err}");
        if what != "too few speeds" {
            assert!(err.contains("runs["), "{what}: the message names the run: {err}");
        }
    }
    // Unequal sample counts are not refused: every pass is resampled onto the common grid (half of the
    // generator's draws have them; both methods run on this one).
    let unequal = (0..40u64)
        .map(|seed| generate(seed, false))
        .find(|d| d.passes.iter().map(|p| p.1.len()).collect::<std::collections::BTreeSet<_>>().len() > 1)
        .expect("a draw with unequal sample counts");
    let dir = tmp.path().join("unequal");
    write_set(&unequal, &dir, true);
    let counts: Vec<usize> = unequal.passes.iter().map(|p| p.1.len()).collect();
    for method in ["seed", "fusion"] {
        let out = run(&dir, &["--method", method]);
        assert!(
            out.status.success(),
            "{method} on unequal counts {counts:?}: {}",
            String::from_utf8_lossy(&out.stderr)
        );
    }
}

/// Issue 17: the same numbers through `vmt straightness` on a set written by `vmt simulate` as through the
/// library on the simulated set in memory (what `vmt simulate` wrote, SI, read back bit for bit): profile,
/// in-band bounds and tilt to 1e-12 relative, with the manifest's noise density used (not estimated).
#[test]
fn vmt_straightness_on_a_simulated_set_matches_the_library() {
    let tmp = tempfile::tempdir().unwrap();
    let scenario = crate::util::root().join("scenarios/study_accel.toml");
    let dir = tmp.path().join("sim");
    let out = vmt().arg("simulate").arg(&scenario).arg("-o").arg(&dir).output().unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let sc = vmt::cli::load_scenario(Some(&scenario)).unwrap();
    let set = vmt::cli::simulate_set(&sc).unwrap();
    let out = vmt().arg("straightness").arg(&dir).arg("--json").output().unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    let nums =
        |x: &serde_json::Value| -> Vec<f64> { x.as_array().unwrap().iter().map(|v| v.as_f64().unwrap()).collect() };
    let sensors = v["sensors"].as_array().unwrap();
    assert!(!sensors.is_empty());
    for e in sensors {
        let name = e["sensor"].as_str().unwrap();
        let lib =
            sensor_straightness(&set, &dir, name, PassSelection::ConstantVelocity, FusionMethod::SnrWeighted).unwrap();
        let d = max_rel_diff(&lib.estimate.straightness, &nums(&e["estimate"]["straightness"]));
        let b = (lib.bounds.straightness_rms / e["bounds"]["straightness_rms"].as_f64().unwrap() - 1.0).abs();
        println!(
            "{name}: CLI on the written set against the library in memory: profile {d:.1e}, bound {b:.1e} relative"
        );
        assert!(d <= 1e-12 && b <= 1e-12, "{name}: profile {d:e}, bound {b:e}");
        if let Some(t) = &lib.estimate.tilt {
            assert!(max_rel_diff(t, &nums(&e["estimate"]["tilt"])) <= 1e-12, "{name}: tilt");
        }
        for p in e["passes"].as_array().unwrap() {
            assert_eq!(p["noise_density_source"], "manifest", "{name}: {p}");
        }
    }
}

/// Where the per-coefficient error/CR ratio falls below 1 (issue 17's doubt, 0.60/0.68 before runs were
/// kept out of wavelengths they cannot resolve): over 40 draws per orientation, the noise-only error of
/// each in-band cosine coefficient / its bound, by wavelength in units of the band's shortest (all draws |
/// equal spacings), and the estimator's gain on a noise-free single cosine at 1–8 × the shortest
/// wavelength (a gain below 1 is a shrinkage: the estimator is biased there).
/// `cargo test --release --test tests straightness_independent::per_harmonic_diagnosis -- --ignored --nocapture`
#[test]
#[ignore]
fn per_harmonic_diagnosis() {
    for with_tilt in [false, true] {
        // noise only: per coefficient error / bound, bucketed by λ_k / λ_min
        let mut buckets: Vec<Vec<f64>> = vec![Vec::new(); 6];
        let mut eq_b: Vec<Vec<f64>> = vec![Vec::new(); 6];
        let edges = [1.0, 1.5, 2.0, 4.0, 8.0, 32.0];
        let mut gains: Vec<(f64, f64, bool)> = Vec::new();
        for i in 0..40u64 {
            let seed = 1000 + i + if with_tilt { 500 } else { 0 };
            let d = generate_scaled(seed, with_tilt, 0.0, 1.0, None);
            let equal = equal_spacing(&d);
            let s = sensor(with_tilt, Some(d.rho));
            let cfg = accel_config(&s, FusionMethod::SnrWeighted);
            let runs: Vec<AccelRun> = d.passes.iter().map(|p| p.0.clone()).collect();
            let est = estimate_straightness(&runs, &cfg).unwrap();
            let b = est.in_band_bounds().unwrap();
            let xs = &est.positions;
            let m = xs.len();
            let c = dct2(&est.straightness);
            for bin in &b.bins {
                if let Some(sk) = bin.straightness {
                    let r = 2.0 / m as f64 * c[bin.k] / sk;
                    let rel = bin.wavelength / est.band.min_wavelength;
                    let j = edges.iter().rposition(|&e| rel >= e).unwrap_or(0);
                    buckets[j].push(r);
                    if equal {
                        eq_b[j].push(r);
                    }
                }
            }
            // transfer of single cosines at λ = f·λ_min
            for f in [1.0, 1.5, 2.0, 4.0, 8.0] {
                let lam = f * est.band.min_wavelength;
                if lam > est.band.max_wavelength {
                    continue;
                }
                let kap = 2.0 * PI / lam;
                let feat = Features { a: vec![1e-6], k: vec![kap], phi: vec![0.3] };
                let d1 = generate_scaled(seed, with_tilt, 1.0, 0.0, Some(feat.clone()));
                let runs: Vec<AccelRun> = d1.passes.iter().map(|p| p.0.clone()).collect();
                let e1 = estimate_straightness(&runs, &cfg).unwrap();
                // LS fit of cos, sin at κ to the estimate (interior half to avoid ends)
                let (mut scc, mut sss, mut scs, mut syc, mut sys) = (0.0, 0.0, 0.0, 0.0, 0.0);
                let n = e1.positions.len();
                for j in n / 4..3 * n / 4 {
                    let x = e1.positions[j];
                    let (co, si) = ((kap * x + 0.3).cos(), (kap * x + 0.3).sin());
                    scc += co * co;
                    sss += si * si;
                    scs += co * si;
                    syc += e1.straightness[j] * co;
                    sys += e1.straightness[j] * si;
                }
                let det = scc * sss - scs * scs;
                let a = (syc * sss - sys * scs) / det;
                let bq = (sys * scc - syc * scs) / det;
                gains.push((f, a.hypot(bq) / 1e-6, equal));
            }
        }
        println!("with_tilt {with_tilt}: noise-only error/CR RMS by λ/λ_min bucket (all | equal spacing):");
        for j in 0..6 {
            if !buckets[j].is_empty() {
                println!(
                    "  λ/λmin ≥ {:>4}: {:.3} (n {}) | {:.3} (n {})",
                    edges[j],
                    rms(&buckets[j]),
                    buckets[j].len(),
                    if eq_b[j].is_empty() { f64::NAN } else { rms(&eq_b[j]) },
                    eq_b[j].len()
                );
            }
        }
        for f in [1.0, 1.5, 2.0, 4.0, 8.0] {
            let g: Vec<f64> = gains.iter().filter(|x| x.0 == f).map(|x| x.1).collect();
            let ge: Vec<f64> = gains.iter().filter(|x| x.0 == f && x.2).map(|x| x.1).collect();
            let gu: Vec<f64> = gains.iter().filter(|x| x.0 == f && !x.2).map(|x| x.1).collect();
            println!(
                "  gain at λ = {f}·λmin: mean {:.3} (equal spacing {:.3}, unequal {:.3}; n {})",
                mean(&g),
                mean(&ge),
                mean(&gu),
                g.len()
            );
        }
    }
}
