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
