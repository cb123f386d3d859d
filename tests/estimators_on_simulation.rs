//! Estimators applied to simulated measurements (issue 4): friction identification from a simulated
//! friction sweep (through `vmt friction`), the stick-slip index of the crawl preset, the default
//! scenario's `vmt run`, and the model-check loop on a lesson.

use std::path::Path;

#[test]
fn crawl_preset_gives_seed_002_stick_slip_indices_through_the_workflow() {
    let sc = vmt::scenario::Scenario::load(&Path::new(env!("CARGO_MANIFEST_DIR")).join("scenarios/crawl_seed002.toml"))
        .unwrap();
    let ph = vmt::simulate::physics(&sc).unwrap();
    let truths = vmt::simulate::simulate_truth(&sc, &ph);
    let runs = vmt::simulate::read_all(&sc, &ph, &truths, sc.seed).unwrap();
    let checks = vmt::estimate::run_estimators(&sc, &ph, &runs).unwrap().checks;
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
    let out =
        std::process::Command::new(env!("CARGO_BIN_EXE_vmt")).args(["run", "--out"]).arg(tmp.path()).output().unwrap();
    let text = String::from_utf8_lossy(&out.stdout);
    assert_eq!(out.status.code(), Some(0), "{text}{}", String::from_utf8_lossy(&out.stderr));
    for row in ["ISO 230-2 E", "straightness acc_z", "EBX pitch", "E after compensation"] {
        assert!(text.contains(row), "table lacks `{row}`:\n{text}");
    }
    assert!(text.contains("all 13 estimates within tolerance"), "{text}");
}

#[test]
fn vmt_run_on_a_lesson_runs_the_model_check_loop_to_the_noise_floor() {
    let tmp = tempfile::tempdir().unwrap();
    let lesson = Path::new(env!("CARGO_MANIFEST_DIR")).join("scenarios/lessons/drift_and_lead/scenario.toml");
    let out = std::process::Command::new(env!("CARGO_BIN_EXE_vmt"))
        .arg("run")
        .arg(&lesson)
        .arg("--out")
        .arg(tmp.path())
        .output()
        .unwrap();
    let text = String::from_utf8_lossy(&out.stdout);
    // Two hidden effects found one after the other; tolerances in the lesson file (normalised RMS ≤ 1.3).
    assert_eq!(out.status.code(), Some(0), "{text}{}", String::from_utf8_lossy(&out.stderr));
    assert!(
        text.contains("model-check loop finds cyclic_lead") && text.contains("model-check loop finds thermal_drift"),
        "{text}"
    );
    let html = std::fs::read_to_string(tmp.path().join("report.html")).unwrap();
    assert!(html.contains("normalised residual RMS per iteration"));
}

#[test]
fn vmt_friction_identifies_the_stribeck_curve_of_the_friction_sweep_scenario() {
    let tmp = tempfile::tempdir().unwrap();
    let vmt = env!("CARGO_BIN_EXE_vmt");
    let scenario = Path::new(env!("CARGO_MANIFEST_DIR")).join("scenarios/friction_sweep.toml");
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

#[test]
fn diag_accel_default() {
    use vmt_estimators::accel_straightness::*;
    let mut sc =
        vmt::scenario::Scenario::load(&Path::new(env!("CARGO_MANIFEST_DIR")).join("scenarios/default.toml")).unwrap();
    sc.procedures.retain(|p| p.name() == "cv");
    let ph = vmt::simulate::physics(&sc).unwrap();
    let truths = vmt::simulate::simulate_truth(&sc, &ph);
    let runs = vmt::simulate::read_all(&sc, &ph, &truths, sc.seed).unwrap();
    for sensor in ["acc_z", "acc_y"] {
        let acc = vmt::estimate::accel_runs(&runs, "cv", sensor).unwrap();
        let spec = sc.sensors.iter().find(|s| s.name == sensor).unwrap();
        let best = vmt::estimate::accel_config(spec, &sc.axis, None).unwrap();
        for (label, cfg) in [
            ("old", StraightnessConfig::default()),
            ("cos", StraightnessConfig { basis: SpectralBasis::Cosine, ..Default::default() }),
            (
                "cos+ac",
                StraightnessConfig {
                    basis: SpectralBasis::Cosine,
                    ac_coupling_hz: best.ac_coupling_hz,
                    ..Default::default()
                },
            ),
            ("best", best.clone()),
        ] {
            let est = estimate_straightness(&acc, &cfg).unwrap();
            let rr = rapier3d_f64::glamx::DVec3::from_array(spec.axis_position(&sc.axis).unwrap());
            let u = spec.unit_direction();
            let m = &ph.truth.motions;
            let curv: Vec<f64> = est
                .positions
                .iter()
                .map(|&x| {
                    let e = rapier3d_f64::glamx::DVec3::new(
                        m.positioning.eval3(x)[2],
                        m.straightness_y.eval3(x)[2],
                        m.straightness_z.eval3(x)[2],
                    );
                    let r = rapier3d_f64::glamx::DVec3::new(m.roll.eval3(x)[2], m.pitch.eval3(x)[2], m.yaw.eval3(x)[2]);
                    u.dot(e + r.cross(rr))
                })
                .collect();
            let tb =
                integrate_curvature_cosine(&est.positions, &curv, est.band.min_wavelength, est.band.max_wavelength)
                    .unwrap();
            let err: Vec<f64> = est.straightness.iter().zip(&tb).map(|(a, b)| a - b).collect();
            let err = vmt_estimators::line::remove_line(&est.positions, &err);
            let rms = (err.iter().map(|e| e * e).sum::<f64>() / err.len() as f64).sqrt();
            eprintln!(
                "{sensor} {label} band {:.4}..{:.4} rms {rms:.3e} rhos {:?}",
                est.band.min_wavelength,
                est.band.max_wavelength,
                est.runs.iter().map(|r| r.noise_density / 9.80665e-6).collect::<Vec<_>>()
            );
            for wl in [0.08, 0.1, 0.25, 0.3, 0.35] {
                let x = &est.positions;
                let h = fit_harmonic_amplitude(x, &err.iter().map(|e| -e).collect::<Vec<_>>(), 1.0, wl).unwrap();
                let k = 2.0 * std::f64::consts::PI / wl;
                let amp = h.amplitude * k * k;
                let cr = est.harmonic_std(wl).unwrap();
                eprintln!(
                    "  λ={wl}: |err| {amp:.3e} CR {cr:.3e} ratio {:.2} (sin {:.2} cos {:.2})",
                    amp / cr,
                    h.sin * k * k / cr,
                    h.cos * k * k / cr
                );
            }
            if let Some(t) = &est.tilt {
                let roll: Vec<f64> = est.positions.iter().map(|&x| m.roll.value(x)).collect();
                let rb = band_limit_cosine(
                    &est.positions,
                    &roll,
                    est.band.min_wavelength,
                    est.tilt_max_wavelength.unwrap(),
                    false,
                )
                .unwrap();
                let d: Vec<f64> = t.iter().zip(&rb).map(|(a, b)| a - b).collect();
                let d = vmt_estimators::line::remove_line(&est.positions, &d);
                let rr_ = (d.iter().map(|e| e * e).sum::<f64>() / d.len() as f64).sqrt();
                let rt = (rb.iter().map(|e| e * e).sum::<f64>() / d.len() as f64).sqrt();
                eprintln!(
                    "  tilt vs roll: rms diff {rr_:.3e} rad (roll rms {rt:.3e}); CR at 0.35 {:?}",
                    est.tilt_std(0.35).unwrap()
                );
            }
        }
    }
}
