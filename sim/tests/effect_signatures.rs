//! Signatures of feedback-chain, screw and sensor effects where physics puts them (issue 3): each effect
//! is injected alone into the slide_column X axis and read by a noise-free laser at the axis reference
//! point (or an accelerometer), and its signature is recovered from the readings.

use crate::util;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use vmt_sim::air::Air;
use vmt_sim::axis_sim::{simulate, AxisTruth, GRAVITY};
use vmt_sim::drive::{BallScrewConfig, DriveConfig, FeedbackKind};
use vmt_sim::effects::ThermalExpansion;
use vmt_sim::feedback::FeedbackErrors;
use vmt_sim::machine::AxisModel;
use vmt_sim::motion::MotionPlan;
use vmt_sim::procedures::{read_run, simulate_procedure, PositioningSpec, ProcedureSpec, RunData};
use vmt_sim::profile::{Harmonic, Profile};
use vmt_sim::rng::source_rng;
use vmt_sim::sensors::{apply_errors, true_readings, SensorKind, SensorSpec};
use vmt_sim::truth::Adjustments;

/// Noise-free linear laser at the axis reference point, along x.
fn laser() -> SensorSpec {
    SensorSpec { position: Some([0.0, 0.0, 0.0]), ..SensorSpec::new("laser", SensorKind::LaserLinear) }
}

/// A point table read by the laser: (target, direction, t of the reading, deviation), SI.
struct Table {
    target: Vec<f64>,
    t: Vec<f64>,
    dev: Vec<f64>,
}

/// One bidirectional ISO 230-2 cycle (`runs` runs) over `targets`; dwell 0.3 s, readings averaged over the
/// last `average` s at 500 Hz.
fn positioning(model: &AxisModel, truth: &AxisTruth, targets: Vec<f64>, runs: u32, feed: f64, average: f64) -> Table {
    let spec = ProcedureSpec::Positioning(PositioningSpec {
        name: "iso".into(),
        start: targets[0],
        end: targets[targets.len() - 1],
        n_targets: targets.len(),
        targets: Some(targets),
        runs,
        feed,
        dwell: 0.3,
        average,
        rate: 500.0,
        overrun: 0.002,
        accel: None,
        sensors: vec!["laser".into()],
    });
    let t = simulate_procedure(model, truth, &spec, 11);
    let rec = read_run(model, truth, &t[0], &[laser()], 11).unwrap();
    let RunData::PointTable { target, t, columns, .. } = rec.data else { panic!("positioning is a point table") };
    Table { target, t: t.expect("point tables from the simulator carry t"), dev: columns[0].1.clone() }
}

/// Least squares y ≈ Σ c_j·f_j(x) by the normal equations (a handful of well-conditioned columns).
fn lstsq(x: &[f64], y: &[f64], f: &dyn Fn(f64) -> Vec<f64>) -> Vec<f64> {
    let n = f(x[0]).len();
    let mut a = vec![vec![0.0; n + 1]; n];
    for (&xi, &yi) in x.iter().zip(y) {
        let r = f(xi);
        for j in 0..n {
            for k in 0..n {
                a[j][k] += r[j] * r[k];
            }
            a[j][n] += r[j] * yi;
        }
    }
    for p in 0..n {
        let piv = (p..n).max_by(|&i, &j| a[i][p].abs().total_cmp(&a[j][p].abs())).unwrap();
        a.swap(p, piv);
        let pivot = a[p].clone();
        for (i, row) in a.iter_mut().enumerate() {
            if i != p {
                let m = row[p] / pivot[p];
                for (x, y) in row[p..].iter_mut().zip(&pivot[p..]) {
                    *x -= m * y;
                }
            }
        }
    }
    (0..n).map(|j| a[j][n] / a[j][j]).collect()
}

const LEAD: f64 = 0.016;

/// Amplitude of the sinusoid of period `LEAD` in the deviations, with an offset and a slope fitted along.
fn lead_amplitude(tab: &Table) -> f64 {
    let k = std::f64::consts::TAU / LEAD;
    let c = lstsq(&tab.target, &tab.dev, &|x| vec![1.0, x, (k * x).sin(), (k * x).cos()]);
    c[2].hypot(c[3])
}

fn screw_model(feedback: FeedbackKind) -> AxisModel {
    let mut m = util::slide_column();
    m.drive = DriveConfig::BallScrew(BallScrewConfig { lead: LEAD, feedback, ..Default::default() });
    m
}

#[test]
fn cyclic_lead_error_shows_at_the_screw_period_in_semi_closed_loop_and_vanishes_in_closed_loop() {
    let amplitude = 1.5e-6;
    let truth = AxisTruth {
        lead_error: Profile::harmonics(vec![Harmonic { amplitude, wavelength: LEAD, phase: 0.7 }]),
        ..Default::default()
    };
    // Dense targets: every 1.5 mm (≈ 10.7 per lead) over four leads, 0.3 … 0.366 m.
    let targets: Vec<f64> = (0..=44).map(|i| 0.3 + 0.0015 * i as f64).collect();
    let semi = lead_amplitude(&positioning(&screw_model(FeedbackKind::Rotary), &truth, targets.clone(), 1, 0.05, 0.1));
    let closed = lead_amplitude(&positioning(&screw_model(FeedbackKind::Linear), &truth, targets, 1, 0.05, 0.1));
    println!("cyclic lead amplitude: semi-closed {semi:e} m, closed {closed:e} m (injected {amplitude:e} m)");
    // Issue 3: recovered within 10 %. The rotary encoder sees the motor, so the table carries lead(u) in full
    // (no guideway friction, so no screw wind-up adds to it).
    assert!((semi / amplitude - 1.0).abs() < 0.1, "semi-closed amplitude {semi:e} vs {amplitude:e}");
    // The linear scale sees the table, so the loop takes the lead error out: more than 10× smaller.
    assert!(closed < semi / 10.0, "closed-loop amplitude {closed:e} vs semi-closed {semi:e}");
}

#[test]
fn thermal_expansion_grows_with_position_and_time_as_alpha_x_delta_t() {
    let model = util::slide_column();
    // τ = 10 s instead of a real machine's ~1200 s: the 24 s cycle (two runs, starting the session at
    // t = 0) then sees ΔT(t) rise from 0 to 91 % of ΔT∞ — the same law
    // δ = α·x·ΔT∞·(1 − e^(−t/τ)) at a time scale the test can afford.
    let th = ThermalExpansion { alpha: 11.5e-6, delta_t: 3.0, tau: 10.0 };
    let truth = AxisTruth {
        feedback: FeedbackErrors { thermal_expansion: Some(th.clone()), ..Default::default() },
        ..Default::default()
    };
    let average = 0.1;
    let tab = positioning(&model, &truth, vec![0.1, 0.3, 0.5, 0.7, 0.9], 2, 0.2, average);
    let rise = |t: f64| 1.0 - (-t / th.tau).exp();
    let mut worst = 0.0f64;
    for ((&x, &t), &d) in tab.target.iter().zip(&tab.t).zip(&tab.dev) {
        // The scale reads x − α·x·ΔT(t) and the loop holds that at the target T, so the table sits at
        // x = T/(1 − α·ΔT); the reading is the mean over the 50 samples of the averaging window ending at t.
        let n = (average * 500.0_f64).round() as usize;
        let expect = (0..n)
            .map(|k| {
                let dt = th.alpha * th.delta_t * rise(t - k as f64 / 500.0);
                x * dt / (1.0 - dt)
            })
            .sum::<f64>()
            / n as f64;
        worst = worst.max((d - expect).abs());
        println!("T {x:.1} m  t {t:6.2} s  deviation {d:.4e} m  α·x·ΔT(t) {expect:.4e} m");
    }
    println!("thermal expansion: worst |deviation − α·x·ΔT(t)| = {worst:e} m");
    // 3 nm: the 1 nm feedback quantisation, plus the loop's following of the drifting scale reading
    // (ė ≤ α·x·ΔT∞/τ = 3.1 µm/s at 0.9 m, rejected by the PI velocity loop to well under a nanometre),
    // against deviations of up to 31 µm.
    assert!(worst < 3e-9, "deviation differs from α·x·ΔT(t) by up to {worst:e} m");
    // The growth itself. With time: the readings at 0.1 m (t = 0.7, 12.3, 12.7, 24.3 s) increase.
    let at_01: Vec<f64> = tab.target.iter().zip(&tab.dev).filter(|(x, _)| **x == 0.1).map(|(_, d)| *d).collect();
    assert!(at_01.len() == 4 && at_01.windows(2).all(|w| w[1] > w[0]), "readings at 0.1 m {at_01:?}");
    // With position: in the last downward pass (t = 18.7 … 24.3 s, where ΔT changes by only 6 % of ΔT∞)
    // the deviation falls with every step down in position.
    let last_down = &tab.dev[15..20];
    assert!(tab.target[15] == 0.9 && last_down.windows(2).all(|w| w[1] < w[0]), "last pass {last_down:?}");
}

/// The session clock: two positioning tests one after the other. A thermal drift
/// d(t) = d∞·(1 − e^(−t/τ)) keeps growing across them: the second test starts where the first ended
/// (its start time is the first's duration) and its readings follow d at session time start + t.
#[test]
fn thermal_drift_carries_over_from_one_run_to_the_next_on_the_session_clock() {
    use vmt_sim::effects::ThermalDrift;
    use vmt_sim::procedures::{plan_procedure, session_schedule, simulate_run};
    let model = util::slide_column();
    let drift = ThermalDrift { value: 5e-6, tau: 20.0 };
    let truth = AxisTruth {
        feedback: FeedbackErrors { thermal_drift: Some(drift.clone()), ..Default::default() },
        ..Default::default()
    };
    let spec = |name: &str| {
        ProcedureSpec::Positioning(PositioningSpec {
            name: name.into(),
            start: 0.2,
            end: 0.8,
            n_targets: 3,
            targets: Some(vec![0.2, 0.5, 0.8]),
            runs: 1,
            feed: 0.2,
            dwell: 0.3,
            average: 0.1,
            rate: 500.0,
            overrun: 0.002,
            accel: None,
            sensors: vec!["laser".into()],
        })
    };
    let plans: Vec<_> = ["first", "second"].iter().flat_map(|n| plan_procedure(&model, &spec(n), 1)).collect();
    let starts = session_schedule(&plans, 0.0);
    // Back to back: the second starts when the first has ended.
    assert_eq!(starts[0], 0.0);
    assert!((starts[1] - plans[0].duration()).abs() < 1e-12 && starts[1] > 5.0, "{starts:?}");
    let read = |i: usize, t0: f64| {
        let truth_run = simulate_run(&model, &truth, &plans[i], t0);
        let rec = read_run(&model, &truth, &truth_run, &[laser()], 1).unwrap();
        let RunData::PointTable { t, columns, .. } = rec.data else { panic!("positioning is a point table") };
        (t.unwrap(), columns[0].1.clone())
    };
    let (t, dev) = read(1, starts[1]);
    let mut worst = 0.0f64;
    for (&ti, &d) in t.iter().zip(&dev) {
        // Mean of d over the 0.1 s averaging window (50 samples at 500 Hz) ending at session time start + t.
        let expect = (0..50).map(|k| drift.value_at(starts[1] + ti - k as f64 / 500.0)).sum::<f64>() / 50.0;
        worst = worst.max((d - expect).abs());
    }
    println!("session clock: second test starts at {:.2} s; worst |reading − d(start + t)| = {worst:e} m", starts[1]);
    // 3 nm: feedback quantisation (1 nm) and the loop's following of the drifting scale, as above,
    // against a drift that has reached several µm.
    assert!(worst < 3e-9, "{worst:e}");
    // Had the second test restarted the clock, its first reading would be the first test's first one.
    let (_, restarted) = read(1, 0.0);
    assert!(dev[0] - restarted[0] > 1e-6, "{} vs {}", dev[0], restarted[0]);
}

#[test]
fn scale_error_gives_a_deviation_linear_in_position_with_the_scale_slope() {
    let model = util::slide_column();
    let s = 20e-6;
    let truth = AxisTruth {
        feedback: FeedbackErrors { along: Profile::poly(vec![0.0, s]), ..Default::default() },
        ..Default::default()
    };
    let tab = positioning(&model, &truth, vec![0.1, 0.3, 0.5, 0.7, 0.9], 1, 0.2, 0.1);
    let c = lstsq(&tab.target, &tab.dev, &|x| vec![1.0, x]);
    let resid = tab.dev.iter().zip(&tab.target).map(|(d, x)| (d - c[0] - c[1] * x).abs()).fold(0.0, f64::max);
    println!("scale error: slope {:e} (injected {s:e}), offset {:e} m, worst residual {resid:e} m", c[1], c[0]);
    // Issue 3: slope within 1 % (the exact slope is s/(1 − s), 2e-5 relative above s).
    assert!((c[1] / s - 1.0).abs() < 0.01, "slope {:e} vs {s:e}", c[1]);
    // Linear: residuals at the 1 nm quantisation of the feedback.
    assert!(resid < 2e-9, "residual from a straight line {resid:e} m");
}

#[test]
fn tilted_accelerometer_at_rest_reads_gravity_times_sine_of_the_tilt() {
    let model = util::slide_column();
    let truth = AxisTruth::default();
    let theta = 1e-3;
    let acc = SensorSpec {
        direction: [0.0, 1.0, 0.0],
        tilt: [theta, 0.0, 0.0],
        ..SensorSpec::new("acc", SensorKind::Accelerometer)
    };
    let mut plan = MotionPlan::starting_at(0.5);
    plan.dwell(2.0);
    let times: Vec<f64> = (0..=100).map(|k| 1.0 + 0.01 * k as f64).collect();
    let s = simulate(&model, &truth, &plan, &times).samples;
    // The sensor chain with every error term zero: apply_errors must pass the truth through unchanged.
    let clean = true_readings(&acc, &model, None, &s).unwrap();
    let r = apply_errors(&acc, &clean, 100.0, &mut source_rng(5, "rest/acc"));
    let expect = GRAVITY * theta.sin();
    let worst = r[1..].iter().map(|a| (a / expect - 1.0).abs()).fold(0.0, f64::max);
    let roll = s.iter().map(|x| x.rot.x.abs()).fold(0.0, f64::max);
    println!(
        "tilted accelerometer: reading {:e} m/s², g·sin θ = {expect:e}, worst relative {worst:e}, \
         body roll ≤ {roll:e} rad",
        r[1]
    );
    // 1e-9 relative (issue 3). A tilt θ about x turns the sensitive y axis towards +z, so it sees +g·sin θ.
    // At rest the finite-difference acceleration is only numerical residue (≲ 1e-13 m/s²) and the
    // symmetric body does not roll on its bearings; a roll φ would read g·sin(θ + φ), so this also bounds
    // the body's roll at rest by 1e-12 rad.
    assert!(worst < 1e-9, "reading differs from g·sin θ by {worst:e} relative");
}

/// Change of a laser's (error-applied, noise-free) reading over a 0.8 m move, 0.1 → 0.9 m, m.
fn laser_reading_over_move(spec: &SensorSpec) -> f64 {
    let model = util::slide_column();
    let mut plan = MotionPlan::starting_at(0.1);
    plan.dwell(0.2);
    plan.move_to(0.9, 0.4, 2.0);
    plan.dwell(0.5);
    let times: Vec<f64> = (0..=10).map(|k| plan.end_time() * k as f64 / 10.0).collect();
    let s = simulate(&model, &AxisTruth::default(), &plan, &times).samples;
    let r = apply_errors(spec, &true_readings(spec, &model, None, &s).unwrap(), 10.0, &mut source_rng(3, "laser"));
    r[r.len() - 1] - r[0]
}

#[test]
fn laser_material_normalisation_with_a_wrong_part_temperature_reads_alpha_times_delta_t_more() {
    let clean = laser_reading_over_move(&laser());
    // Part at 21 °C, the laser's material sensor says 20 °C: the laser leaves the part's 1 K of expansion in.
    let alpha = 11.5e-6;
    let warm = SensorSpec { material_temperature: 21.0, assumed_material_temperature: Some(20.0), ..laser() };
    let e_mat = laser_reading_over_move(&warm) - clean;
    println!("material: clean move {clean:.9} m, error {e_mat:e} m (0.8 m·α·1 K = {:e} m)", 0.8 * alpha);
    // Issue 3: 0.8 m·11.5e-6/K·1 K = 9.2 µm within 1 nm. With T_a = 20 °C the error α·(T − T_a)·L is exact;
    // L differs from 0.8 m only by the loop's nanometre-level positioning, which times α is ~1e-14 m.
    assert!((e_mat - 0.8 * alpha).abs() < 1e-9, "material error {e_mat:e} m vs 9.2 µm");
    // Away from 20 °C (part at 25 °C, sensed 24 °C) the exact error α·ΔT·L/(1 + α·(T_a − 20)) is smaller than
    // the first-order α·ΔT·L by α·4 K relative (4.2e-10 m here): first order still holds within 1 nm, and
    // the exact form to rounding (1e-15 m on the 9 µm error).
    let hot = SensorSpec { material_temperature: 25.0, assumed_material_temperature: Some(24.0), ..laser() };
    let e_hot = laser_reading_over_move(&hot) - clean;
    let exact = clean * alpha / (1.0 + alpha * 4.0);
    println!("material at 25/24 °C: error {e_hot:e} m, exact {exact:e} m, first order {:e} m", clean * alpha);
    assert!((e_hot - exact).abs() < 1e-13, "error {e_hot:e} m vs exact {exact:e} m");
    assert!((e_hot - 0.8 * alpha).abs() < 1e-9, "error {e_hot:e} m vs first order 9.2 µm");
    // Unset fields: no change (defaults 20 °C, assumed = true), even for a part that is evenly at 25 °C.
    let even = SensorSpec { material_temperature: 25.0, ..laser() };
    assert_eq!(laser_reading_over_move(&even), clean, "a correctly sensed part temperature must not change");

    // Combined with an Edlén air error (air at 21 °C, compensation assuming 20 °C): independent scale factors,
    // so the errors add to first order; the product leaves a cross term L·e_air·e_mat ≈ 0.8·1e-6·1.15e-5
    // ≈ 1e-11 m, hence 1e-10 m.
    let air = Air { temperature: 21.0, ..Air::REFERENCE };
    let air_only = SensorSpec { air: Some(air), assumed_air: Some(Air::REFERENCE), ..laser() };
    let both = SensorSpec { air: Some(air), assumed_air: Some(Air::REFERENCE), ..warm.clone() };
    let e_air = laser_reading_over_move(&air_only) - clean;
    let e_both = laser_reading_over_move(&both) - clean;
    println!("air error {e_air:e} m, air + material {e_both:e} m, sum of the two {:e} m", e_air + e_mat);
    // The air term itself: warmer air has a lower index, so the laser under-reads by ≈ 0.93–0.95 ppm/K (the
    // textbook Edlén temperature sensitivity near 20 °C): about 0.75 µm on 0.8 m.
    assert!((-0.97e-6..-0.90e-6).contains(&(e_air / clean)), "air error {:e} relative", e_air / clean);
    assert!((e_both - e_air - e_mat).abs() < 1e-10, "combined {e_both:e} vs {e_air:e} + {e_mat:e}");
    // And the remainder is that cross term: the factors multiply, (1 + e_air)·(1 + e_mat). 1e-14 m: rounding of
    // the 0.8 m readings (1e-16 each) plus the nanometre-level difference between the runs' L (×1e-5).
    let cross = e_both - e_air - e_mat - e_air * e_mat / clean;
    assert!(cross.abs() < 1e-14, "combined error leaves {cross:e} m beyond the product of the factors");
}

#[test]
fn servo_lag_gives_a_following_error_of_velocity_over_kv_at_constant_velocity() {
    let kv = 30.0;
    let v = 0.1;
    let following = |model: &AxisModel| -> (f64, f64) {
        let mut plan = MotionPlan::starting_at(0.1);
        plan.dwell(0.2);
        let (t0, t1) = plan.move_to(0.5, v, 1.0);
        plan.dwell(0.2);
        // After the transient: from 1 s into the move (the 0.1 s ramp plus > 25 loop time constants of 33 ms)
        // to 0.5 s before its end.
        let times: Vec<f64> = (0..=50).map(|k| t0 + 1.0 + (t1 - t0 - 1.5) * k as f64 / 50.0).collect();
        let s = simulate(model, &AxisTruth::default(), &plan, &times).samples;
        let e: Vec<f64> = s.iter().map(|x| x.cmd.pos - model.axis.dot(x.pos - model.home.translation)).collect();
        let mean = e.iter().sum::<f64>() / e.len() as f64;
        let spread = e.iter().map(|x| (x - mean).abs()).fold(0.0, f64::max);
        (mean, spread)
    };
    let mut lag = util::slide_column();
    Adjustments { servo_kv: Some(kv), ..Default::default() }.apply(&mut lag);
    let (e, spread) = following(&lag);
    let (e_ff, _) = following(&util::slide_column());
    println!(
        "servo lag: following error {e:e} m (v/kv = {:e} m), spread {spread:e} m; with feed-forward {e_ff:e} m",
        v / kv
    );
    // Issue 3: v/kv within 2 %. A P position loop around a velocity loop with integral action is type 1:
    // at constant velocity the velocity loop delivers v = kv·e exactly, so e = v/kv = 3.33 mm; the 0.2 ms
    // servo period shifts it by at most v·T_s = 20 µm (0.6 %).
    assert!((e / (v / kv) - 1.0).abs() < 0.02, "following error {e:e} m vs v/kv = {:e} m", v / kv);
    // Constant after the transient: the spread is bounded by the 1 nm feedback quantisation (2 nm peak to peak).
    assert!(spread < 2e-9, "following error varies by {spread:e} m at constant velocity");
    // The default servo (kv = 50 with velocity feed-forward) follows far closer: the lag is the servo lag's.
    assert!(e_ff.abs() < 0.01 * v / kv, "following error with feed-forward {e_ff:e} m");
}

#[test]
fn accelerometer_bias_drift_is_a_random_walk_whose_variance_grows_as_rate_squared_times_time() {
    let rate = 1e-3;
    let fs = 100.0;
    let acc = SensorSpec { bias_drift: rate, ..SensorSpec::new("acc", SensorKind::Accelerometer) };
    let zero = vec![0.0; 1000];
    let seeds = 2000;
    // Sample k carries k + 1 increments of variance rate²/fs: t = (k + 1)/fs.
    let checks = [99usize, 399, 999];
    let mut sum2 = [0.0; 3];
    let mut sum = [0.0; 3];
    for seed in 0..seeds {
        let r = apply_errors(&acc, &zero, fs, &mut ChaCha8Rng::seed_from_u64(seed));
        for (j, &k) in checks.iter().enumerate() {
            sum[j] += r[k];
            sum2[j] += r[k] * r[k];
        }
    }
    let n = seeds as f64;
    // The mean is known (0), so n·var̂/σ² is χ² with n degrees of freedom: relative sd √(2/n) = 3.2 %;
    // 4 sd (12.6 %) makes a false alarm ~1e-4 per check.
    let tol = 4.0 * (2.0 / n).sqrt();
    for (j, &k) in checks.iter().enumerate() {
        let t = (k + 1) as f64 / fs;
        let var = sum2[j] / n;
        let ratio = var / (rate * rate * t);
        let mean = sum[j] / n;
        println!(
            "bias drift at t = {t:4.1} s: var {var:e} (m/s²)², rate²·t {:e}, ratio {ratio:.4}, mean {mean:e}",
            rate * rate * t
        );
        assert!((ratio - 1.0).abs() < tol, "variance ratio {ratio} at t = {t} s (tolerance {tol})");
        // Zero mean: within 4 standard errors σ/√n.
        assert!(mean.abs() < 4.0 * rate * t.sqrt() / n.sqrt(), "mean drift {mean:e} at t = {t} s");
    }
}
