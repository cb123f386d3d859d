//! Estimators applied to simulated measurements (issue 4): friction identification from a simulated
//! friction sweep (through `vmt friction`), the stick-slip index of the crawl preset, the default
//! scenario's `vmt run`, and the model-check loop on a lesson.

use crate::util::{rms, root, vmt};

#[test]
fn crawl_preset_gives_seed_002_stick_slip_indices_through_the_workflow() {
    let sc = vmt::scenario::Scenario::load(&root().join("scenarios/crawl_seed002.toml")).unwrap();
    let ph = vmt::simulate::physics(&sc).unwrap();
    let truths = vmt::simulate::simulate_truth(&sc, &ph);
    let runs = vmt::simulate::read_all(&sc, &ph, &truths, sc.seed).unwrap();
    let checks = vmt::workflow::run::run_estimators(&sc, &ph, &truths, &runs).unwrap().checks;
    assert_eq!(checks.len(), 3);
    for c in &checks {
        println!("{}: {:.3} (expected {} ± {})", c.error, c.recovered, c.injected, c.tolerance);
        // Tolerances are seed 002's table as issue 3 states them (scenario file).
        assert!(c.pass, "{} = {}", c.error, c.recovered);
    }
}

#[test]
fn default_run_exits_zero_with_every_estimate_within_tolerance() {
    let tmp = tempfile::tempdir().unwrap();
    let out = vmt().args(["run", "--out"]).arg(tmp.path()).output().unwrap();
    let text = String::from_utf8_lossy(&out.stdout);
    assert_eq!(out.status.code(), Some(0), "{text}{}", String::from_utf8_lossy(&out.stderr));
    for row in ["ISO 230-2 E", "straightness acc_z", "EBX pitch", "E after compensation"] {
        assert!(text.contains(row), "table lacks `{row}`:\n{text}");
    }
    assert!(text.contains("all 13 estimates within tolerance"), "{text}");
}

/// Lessons through `vmt run`: `drift_and_lead` (two hidden effects found one after the other) and
/// `warm_up` (a thermal expansion found from a cold and a warm test on the session clock); the
/// tolerances are in the lesson files (normalised RMS ≤ 1.3).
#[test]
fn vmt_run_on_a_lesson_runs_the_model_check_loop_to_the_noise_floor() {
    for (lesson, hidden) in
        [("drift_and_lead", &["cyclic_lead", "thermal_drift"][..]), ("warm_up", &["thermal_expansion"][..])]
    {
        let tmp = tempfile::tempdir().unwrap();
        let path = root().join("scenarios/lessons").join(lesson).join("scenario.toml");
        let out = vmt().arg("run").arg(&path).arg("--out").arg(tmp.path()).output().unwrap();
        let text = String::from_utf8_lossy(&out.stdout);
        assert_eq!(out.status.code(), Some(0), "{lesson}: {text}{}", String::from_utf8_lossy(&out.stderr));
        for h in hidden {
            assert!(text.contains(&format!("model-check loop finds {h}")), "{lesson}: {text}");
        }
        let html = std::fs::read_to_string(tmp.path().join("report.html")).unwrap();
        assert!(html.contains("normalised residual RMS per iteration"));
    }
}

#[test]
fn vmt_friction_identifies_the_stribeck_curve_of_the_friction_sweep_scenario() {
    let tmp = tempfile::tempdir().unwrap();
    let vmt = env!("CARGO_BIN_EXE_vmt");
    let scenario = root().join("scenarios/friction_sweep.toml");
    let data = tmp.path().join("sweep");
    assert!(std::process::Command::new(vmt)
        .arg("simulate")
        .arg(&scenario)
        .arg("-o")
        .arg(&data)
        .status()
        .unwrap()
        .success());
    let out = std::process::Command::new(vmt).arg("friction").arg(&data).arg("--json").output().unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let fit: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    let c = &fit["coefficients"];
    // Issue 4: the injected Stribeck parameters within 5 % (scenario truth: 150 N, 250 N, 2 mm/s, 1.5, 1000 N·s/m).
    for (key, want) in [("fc", 150.0), ("fs", 250.0), ("vs", 2e-3), ("delta", 1.5), ("fv", 1000.0)] {
        let got = c[key].as_f64().unwrap();
        assert!((got / want - 1.0).abs() < 0.05, "{key}: {got} vs {want}");
    }
}

/// Per-harmonic quadrature components (m or rad) of an error profile at wavelength `wl`: the error
/// restricted to the octaves around λ (cosine band-limit to [λ/2, 2λ], so the large long-wave noise
/// coefficients, whose bound grows as λ², do not leak into the fit), then the least-squares fit of
/// [1, sin κx, cos κx] (the wavelengths here are not integer fractions of the range).
fn components(x: &[f64], e: &[f64], wl: f64) -> (f64, f64) {
    use vmt_estimators::accel_straightness::{band_limit_cosine, fit_harmonic_amplitude};
    // fit_harmonic_amplitude fits a = c0 + c1 sin + c2 cos and returns −c/(v²κ²): undo with v = 1.
    let k = 2.0 * std::f64::consts::PI / wl;
    let e = band_limit_cosine(x, e, wl / 2.0, 2.0 * wl, true).unwrap();
    let h = fit_harmonic_amplitude(x, &e, 1.0, wl).unwrap();
    (-h.sin * k * k, -h.cos * k * k)
}

/// One accelerometer on the default scenario's `cv` procedure: the estimate `vmt run` makes and the
/// truth band-limited by the same operator (the mount point's noise-free curvature u·(E'' + ε''×r)
/// integrated in the cosine basis over the estimate's band: see `integrate_curvature_cosine`).
struct AccelOutcome {
    est: vmt_estimators::accel_straightness::StraightnessEstimate,
    err: Vec<f64>,
    roll_band: Vec<f64>,
}

/// Noise seeds `None` → the scenario's own seed; the physics is simulated once for all of them.
fn default_cv(preset: vmt_sim::sensors::AccelPreset, seeds: &[Option<u64>]) -> Vec<Vec<(&'static str, AccelOutcome)>> {
    use rapier3d_f64::glamx::DVec3;
    use vmt_estimators::accel_straightness::*;
    let mut sc = vmt::scenario::Scenario::load(&root().join("scenarios/default.toml")).unwrap();
    sc.procedures.retain(|p| p.name() == "cv");
    for s in sc.sensors.iter_mut().filter(|s| s.name.starts_with("acc_")) {
        s.preset = Some(preset);
    }
    let ph = vmt::simulate::physics(&sc).unwrap();
    let truths = vmt::simulate::simulate_truth(&sc, &ph);
    let m = &ph.truth.motions;
    let mut all = Vec::new();
    for seed in seeds {
        let runs = vmt::simulate::read_all(&sc, &ph, &truths, seed.unwrap_or(sc.seed)).unwrap();
        let mut out = Vec::new();
        for sensor in ["acc_y", "acc_z"] {
            let spec = sc.sensors.iter().find(|s| s.name == sensor).unwrap();
            let set = vmt::simulate::to_measurement_set(&sc, &runs).unwrap();
            let names = vmt::simulate::procedure_run_names(&sc, &ph.model).remove("cv").unwrap();
            let cv = vmt::straightness::PassSelection::Procedure { name: "cv", runs: &names };
            let est = vmt::straightness::sensor_straightness(&set, &sc.source, sensor, cv, FusionMethod::SnrWeighted)
                .unwrap()
                .estimate;
            let r = DVec3::from_array(spec.axis_position(&sc.axis).unwrap());
            let u = spec.unit_direction();
            let curv: Vec<f64> = est
                .positions
                .iter()
                .map(|&x| {
                    let e = DVec3::new(
                        m.positioning.eval3(x)[2],
                        m.straightness_y.eval3(x)[2],
                        m.straightness_z.eval3(x)[2],
                    );
                    let a = DVec3::new(m.roll.eval3(x)[2], m.pitch.eval3(x)[2], m.yaw.eval3(x)[2]);
                    u.dot(e + a.cross(r))
                })
                .collect();
            let truth =
                integrate_curvature_cosine(&est.positions, &curv, est.band.min_wavelength, est.band.max_wavelength)
                    .unwrap();
            let err: Vec<f64> = est.straightness.iter().zip(&truth).map(|(a, b)| a - b).collect();
            let roll: Vec<f64> = est.positions.iter().map(|&x| m.roll.value(x)).collect();
            let tmax = est.tilt_max_wavelength.unwrap_or(2.0 * est.travel);
            let tmin = est.tilt_min_wavelength.unwrap_or(est.band.min_wavelength);
            let roll_band = band_limit_cosine(&est.positions, &roll, tmin, tmax, false).unwrap();
            out.push((sensor, AccelOutcome { est, err, roll_band }));
        }
        all.push(out);
    }
    all
}

/// Issue 4, "the achieved error within 3× the Cramér–Rao bound at each injected harmonic", as the
/// statistical statement it is: over the scenario's own noise seed and 16 others (same physics), each
/// quadrature component of each injected harmonic inside the recoverable band, in units of its bound.
/// For an efficient unbiased estimator these are unit Gaussians: (a) their RMS over the 17 seeds exceeds
/// 1.40 with probability 1 % (χ with 17 degrees of freedom), so RMS ≤ 1.5 allows that plus a small bias;
/// (b) |component| > 3 happens with probability 0.27 % per component, 0.37 expected among the 136 draws,
/// so at most 2 may exceed 3 (P(≥ 3) ≈ 0.6 %) and none may exceed 4.
/// Measured: one draw above 3 (acc_y, 250 mm, cos, 3.12 at the scenario's seed; the 16 other seeds at
/// most 2.16 there); RMS per component 0.64–1.37, means within ±0.8. Before the readings were placed at
/// the middle of their averaging interval (half a sample behind x_cmd, `vmt::straightness::accel_passes`)
/// acc_y at 80 mm sat at −3.2 on average (a 0.19 mm shift at 0.45 m/s).
#[test]
fn default_scenario_accelerometer_harmonics_are_efficient_over_noise_seeds() {
    let mut seeds = vec![None];
    seeds.extend((1..=16).map(Some));
    let all = default_cv(vmt_sim::sensors::AccelPreset::Piezo, &seeds);
    // (sensor, λ, component) → ratios over seeds
    let mut ratios: std::collections::BTreeMap<(&str, String, &str), Vec<f64>> = Default::default();
    for per_seed in &all {
        for (sensor, o) in per_seed {
            let injected = if *sensor == "acc_y" { INJECTED_Y } else { INJECTED_Z };
            for &wl in injected.iter().filter(|&&w| w >= o.est.band.min_wavelength && w <= o.est.band.max_wavelength) {
                let (s, c) = components(&o.est.positions, &o.err, wl);
                let cr = o.est.harmonic_std(wl).unwrap();
                ratios.entry((sensor, format!("{wl}"), "sin")).or_default().push(s / cr);
                ratios.entry((sensor, format!("{wl}"), "cos")).or_default().push(c / cr);
            }
        }
    }
    assert_eq!(ratios.len(), 8, "two in-band harmonics per sensor, two components each: {:?}", ratios.keys());
    let mut above3 = 0;
    for ((sensor, wl, comp), r) in &ratios {
        let mean = r.iter().sum::<f64>() / r.len() as f64;
        let rms_r = rms(r);
        let max = r.iter().fold(0.0f64, |m, v| m.max(v.abs()));
        above3 += r.iter().filter(|v| v.abs() > 3.0).count();
        eprintln!("{sensor} λ={wl} m {comp}: error/CR mean {mean:+.2}, RMS {rms_r:.2}, max |·| {max:.2}, scenario seed {:+.2}", r[0]);
        assert!(rms_r <= 1.5, "{sensor} λ={wl} {comp}: RMS {rms_r}");
        assert!(max <= 4.0, "{sensor} λ={wl} {comp}: max {max}");
    }
    assert!(above3 <= 2, "{above3} components above 3× CR");
}

/// Injected straightness harmonics of the default scenario (m): EYX and EZX wavelengths.
const INJECTED_Y: [f64; 3] = [0.9, 0.25, 0.08];
const INJECTED_Z: [f64; 3] = [1.2, 0.3, 0.1];

#[test]
fn default_scenario_accelerometers_meet_rms_and_cramer_rao_piezo_then_mems() {
    use vmt_sim::sensors::AccelPreset;
    let piezo = default_cv(AccelPreset::Piezo, &[None]).remove(0);
    let mems = default_cv(AccelPreset::Mems, &[None]).remove(0);
    for ((sensor, p), (_, q)) in piezo.iter().zip(&mems) {
        let injected = if *sensor == "acc_y" { INJECTED_Y } else { INJECTED_Z };
        for (label, o) in [("piezo", p), ("mems", q)] {
            let x = &o.est.positions;
            let e_rms = rms(&o.err);
            eprintln!(
                "{sensor} {label}: band {:.4}…{:.4} m ({}), ρ̂ {:?} µg/√Hz, RMS error {:.4} µm, tilt separated {}",
                o.est.band.min_wavelength,
                o.est.band.max_wavelength,
                o.est.band.max_wavelength_limited_by,
                o.est.runs.iter().map(|r| (r.noise_density / 9.80665e-6 * 100.0).round() / 100.0).collect::<Vec<_>>(),
                e_rms * 1e6,
                o.est.gravity_tilt_separated
            );
            for &wl in &injected {
                let inside = wl >= o.est.band.min_wavelength && wl <= o.est.band.max_wavelength;
                let (s, c) = components(x, &o.err, wl);
                let cr = o.est.harmonic_std(wl).unwrap();
                eprintln!(
                    "  λ={wl} m {}: error ({:.2e}, {:.2e}) m, CR {cr:.2e} m, ratios ({:.2}, {:.2})",
                    if inside { "in band" } else { "out of band" },
                    s,
                    c,
                    s.abs() / cr,
                    c.abs() / cr
                );
            }
            if label == "piezo" {
                // Issue 4: 0.3 µm RMS against the band-limited truth.
                assert!(e_rms < 0.3e-6, "{sensor}: RMS {e_rms}");
                // The per-harmonic Cramér–Rao check is statistical: see
                // `default_scenario_accelerometer_harmonics_are_efficient_over_noise_seeds`.
            }
            if let Some(t) = &o.est.tilt {
                let d: Vec<f64> = t.iter().zip(&o.roll_band).map(|(a, b)| a - b).collect();
                eprintln!(
                    "  tilt vs roll (same band): RMS difference {:.3} µrad, roll RMS {:.3} µrad",
                    rms(&d) * 1e6,
                    rms(&o.roll_band) * 1e6
                );
                for wl in [1.1, 0.35] {
                    let (s, c) = components(x, &d, wl);
                    let cr = o.est.tilt_std(wl).unwrap().unwrap();
                    eprintln!(
                        "    roll λ={wl}: error ({s:.2e}, {c:.2e}) rad, CR {cr:.2e}, ratios ({:.2}, {:.2})",
                        s.abs() / cr,
                        c.abs() / cr
                    );
                    // The tilt of the Y sensor is the roll (g·EAX): its harmonics (12 µrad at 1.1 m, 4 µrad
                    // at 0.35 m) recovered within 3× the joint-model tilt bound per component.
                    assert!(s.abs() <= 3.0 * cr && c.abs() <= 3.0 * cr, "roll λ={wl}: ({s}, {c}) vs {cr}");
                }
            }
        }
        // MEMS against piezo (same band-independent wavelength 50 mm, inside both bands): the bound scales
        // with the noise density, nominally 25/0.3 = 83; the piezo densities estimated from the records are
        // 0.28–0.55 µg/√Hz (the simulated Z channel carries extra high-frequency motion) and the piezo's AC
        // loss is < 1 % at 50 mm, so the ratio must lie in 40…100.
        let ratio = q.est.harmonic_std(0.05).unwrap() / p.est.harmonic_std(0.05).unwrap();
        // The noise limit of the band moves as ρ^(−1/2) (σ ∝ λ²·ρ): nominally √83 = 9.1 shorter.
        let nl = p.est.band.noise_limit_wavelength / q.est.band.noise_limit_wavelength;
        // RMS bound of the MEMS estimate: one cosine coefficient per λ_k = 2L/k in the band, mean square σ_k²/2.
        let mut var = 0.0;
        for k in 1.. {
            let wl = 2.0 * q.est.travel / k as f64;
            if wl < q.est.band.min_wavelength {
                break;
            }
            if wl <= q.est.band.max_wavelength {
                var += 0.5 * q.est.harmonic_std(wl).unwrap().powi(2);
            }
        }
        let (rp, rq) = (rms(&p.err), rms(&q.err));
        eprintln!(
            "{sensor}: MEMS/piezo bound ratio at 50 mm {ratio:.1}, noise-limit ratio {nl:.2}, MEMS band max {:.4} m \
             vs piezo {:.4} m; RMS error MEMS {:.3} µm (RMS bound {:.3} µm) vs piezo {:.3} µm (×{:.1})",
            q.est.band.max_wavelength,
            p.est.band.max_wavelength,
            rq * 1e6,
            var.sqrt() * 1e6,
            rp * 1e6,
            rq / rp
        );
        assert!(ratio > 40.0 && ratio < 100.0, "bound ratio {ratio}");
        assert!(nl > 6.0 && nl < 13.0, "noise-limit ratio {nl}");
        assert!(
            q.est.band.max_wavelength_limited_by == "noise" && q.est.band.max_wavelength < p.est.band.max_wavelength
        );
        // The MEMS error is noise: its RMS matches the RMS bound within ±30 % (≈ 100 coefficients in the
        // band: the mean square scatters by √(2/100) = 14 %, the RMS by 7 %; ρ̂ adds ±3 %).
        assert!(rq > 0.7 * var.sqrt() && rq < 1.3 * var.sqrt(), "MEMS RMS {rq} vs bound {}", var.sqrt());
        // And it exceeds the piezo error (which is below 0.08 µm): at least 2×.
        assert!(rq > 2.0 * rp);
    }
}

/// The ISO 230-2 check of a semi-closed ball-screw axis with backlash and guideway friction (the backlash
/// lesson's machine with an `iso230_2` estimator): E, M and B̄ are compared with the evaluation of the
/// noise-free table — what the simulated table did at rest — not with the error motions alone, which
/// miss the lost motion. The lost motion is not b: with Coulomb friction Fc the screw stays wound up by
/// about Fc/k (k = 2e8 N/m) after the stop, and without friction the table floats in the clearance, so
/// B̄ moves with Fc (this test found, at Fc = 0 / 100 / 200 N, noise-free B̄ −2.25 / −4.19 / −1.71 µm for
/// b = 3 µm). Before the fix the check FAILed: injected B̄ 0 against −4.2 µm measured. Tolerance 0.15 µm:
/// a reading is a 50 ms mean with σ = 50 nm, E and M are differences of extremes of 3-run means
/// (σ ≈ 41 nm), B̄ a mean of 11 such differences; 0.15 µm is ≥ 3.6 σ of each.
#[test]
fn iso_check_of_a_backlash_axis_compares_with_the_noise_free_table() {
    let lesson = std::fs::read_to_string(root().join("scenarios/lessons/backlash/scenario.toml")).unwrap();
    let head = &lesson[..lesson.find("[[estimators]]").expect("the lesson has estimators")];
    let tmp = tempfile::tempdir().unwrap();
    let mut off_by_more_than_b = 0;
    for fc in ["0.0", "100.0", "200.0"] {
        let text = head.replace("runs = 2", "runs = 3").replace("fc = 100.0", &format!("fc = {fc}"))
            + "[[estimators]]\nkind = \"iso230_2\"\nrun = \"iso\"\nsensor = \"laser_low\"\ntolerance = 0.15e-6\n";
        let path = tmp.path().join(format!("backlash_fc{fc}.toml"));
        std::fs::write(&path, text).unwrap();
        let sc = vmt::scenario::Scenario::load(&path).unwrap();
        let ph = vmt::simulate::physics(&sc).unwrap();
        let truths = vmt::simulate::simulate_truth(&sc, &ph);
        let runs = vmt::simulate::read_all(&sc, &ph, &truths, sc.seed).unwrap();
        let checks = vmt::workflow::run::run_estimators(&sc, &ph, &truths, &runs).unwrap().checks;
        assert_eq!(checks.len(), 3, "fc = {fc}: E, M and B̄");
        for c in &checks {
            println!(
                "fc = {fc} N: {} injected {:.3} µm, recovered {:.3} µm",
                c.error,
                c.injected * 1e6,
                c.recovered * 1e6
            );
            assert!(c.pass, "fc = {fc} N: {} injected {} recovered {}", c.error, c.injected, c.recovered);
        }
        let b_mean = checks.iter().find(|c| c.id.ends_with(".b_mean")).unwrap();
        if (b_mean.injected + 3e-6).abs() > 0.5e-6 {
            off_by_more_than_b += 1;
        }
    }
    // The truth is the table's, not a formula in b: at least the frictionless and the 200 N axis lose a
    // motion more than 0.5 µm away from b (the 100 N one is b + 2·Fc/k ≈ 4 µm, also away).
    assert!(off_by_more_than_b >= 2, "lost motion equals the backlash in {} of 3 axes", 3 - off_by_more_than_b);
}
