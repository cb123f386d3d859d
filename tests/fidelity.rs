//! The fast integrator against the rapier reference (issue 15): every bundled scenario simulated with
//! `fidelity = "fast"` and `fidelity = "reference"`, compared on the trajectory of every run, every
//! sensor channel of every run (same seed, so the same noise: differences are physics only) and every
//! estimate of `vmt run`'s table.
//!
//! Both engines perform the same update (semi-implicit Euler, rapier's gyroscopic correction and
//! linearised rotation, `vmt_sim::axis_sim::FastBody`); they differ by floating-point rounding only
//! (rapier sums forces and torques in its own order). The 1 nm feedback quantisation turns a rounding
//! difference into a 1-count feedback difference when a reading sits near a quantum boundary, which the
//! servo then feeds back: the trajectories therefore separate by a fraction of the resolution in x
//! (the servo-held direction) and much less across the guideway (1e9 N/m bearings, forces of the
//! order of newtons per count). The bounds below are those physical scales, not fitted to the result.

use crate::util::{bundled, root};
use std::path::Path;
use vmt::scenario::Scenario;
use vmt::simulate::{physics, read_all, simulate_truth};
use vmt::workflow::run::run_estimators;

/// The scenario at `path` with its top-level `fidelity` set to `fidelity`.
fn with_fidelity(path: &Path, fidelity: &str) -> Scenario {
    let text = std::fs::read_to_string(path).unwrap();
    let body: String =
        text.lines().filter(|l| !l.trim_start().starts_with("fidelity")).map(|l| format!("{l}\n")).collect();
    Scenario::parse(&format!("fidelity = \"{fidelity}\"\n{body}"), path, path.parent()).unwrap()
}

fn max_abs_diff(a: &[f64], b: &[f64]) -> f64 {
    assert_eq!(a.len(), b.len());
    a.iter().zip(b).map(|(x, y)| (x - y).abs()).fold(0.0, f64::max)
}

fn rms(a: &[f64]) -> f64 {
    let m = a.iter().sum::<f64>() / a.len().max(1) as f64;
    (a.iter().map(|x| (x - m).powi(2)).sum::<f64>() / a.len().max(1) as f64).sqrt()
}

/// Trajectory bounds: position of the reference point along the axis (m), across it (m), rotation
/// (rad). Along x: 1 nm feedback quantum (the servo holds x to the count, so a count flipped by rounding
/// moves x by up to one count). Across: the quasi-static pose follows the rest pose of the bearings;
/// a one-count difference in x moves the rest pose by slope·1 nm (slopes of µm/m: 1e-15 m) and the
/// servo force difference (K_v·1 nm/ts ≈ 1.4e6 N·s/m·… ≈ 10 N at most per count) tilts the body by
/// F·h/(k·b²) ≈ 1e-11 rad, moving points by < 1e-11 m; 1e-10 m and 1e-10 rad leave a factor of ten.
const X_BOUND: f64 = 2e-9;
const YZ_BOUND: f64 = 1e-10;
const ROT_BOUND: f64 = 1e-10;

#[test]
#[ignore = "fails: on crawl_seed002 (Stribeck sticking) x differs by 7.7e-8 m against the 2e-9 m bound; \
            the fast integrator stays off by default until this passes (issue 15)"]
fn fast_integrator_follows_rapier_on_every_bundled_scenario() {
    let mut report = Vec::new();
    let mut failures: Vec<String> = Vec::new();
    let mut check = |ok: bool, msg: String| {
        if !ok {
            failures.push(msg);
        }
    };
    for name in bundled() {
        let path = root().join(&name);
        let [fast, reference] = ["fast", "reference"].map(|f| {
            let sc = with_fidelity(&path, f);
            let ph = physics(&sc).unwrap();
            let truths = simulate_truth(&sc, &ph);
            let runs = read_all(&sc, &ph, &truths, sc.seed).unwrap();
            let est = run_estimators(&sc, &ph, &truths, &runs).unwrap();
            (sc, truths, runs, est)
        });
        // Trajectory of every run: the reference point and the body rotation at every recorded sample.
        let (mut dx, mut dyz, mut drot) = (0.0f64, 0.0f64, 0.0f64);
        for (a, b) in fast.1.runs.iter().zip(&reference.1.runs) {
            assert_eq!(a.samples.len(), b.samples.len(), "{name} {}", a.name);
            for (s, r) in a.samples.iter().zip(&b.samples) {
                let d = s.pos - r.pos;
                dx = dx.max(d.x.abs());
                dyz = dyz.max(d.y.abs().max(d.z.abs()));
                drot = drot.max((s.rot - r.rot).abs().max_element());
            }
        }
        report.push(format!(
            "{name}: trajectory max |Δx| {dx:.2e} m, max |Δy|,|Δz| {dyz:.2e} m, max |Δrot| {drot:.2e} rad"
        ));
        check(dx <= X_BOUND, format!("{name}: x differs by {dx:e} m (bound {X_BOUND:e} m)"));
        check(dyz <= YZ_BOUND, format!("{name}: y/z differ by {dyz:e} m (bound {YZ_BOUND:e} m)"));
        check(drot <= ROT_BOUND, format!("{name}: rotation differs by {drot:e} rad (bound {ROT_BOUND:e} rad)"));
        // Every sensor channel: the difference is bounded by a small fraction of the channel's own
        // variation (its RMS about the mean), 1e-3: far below any noise a sensor adds (≥ 1 % of the
        // signal in the bundled scenarios), so no estimate can tell the engines apart.
        assert_eq!(fast.2.len(), reference.2.len());
        for (a, b) in fast.2.iter().zip(&reference.2) {
            assert_eq!(a.data.columns().len(), b.data.columns().len());
            for ((ca, va), (_, vb)) in a.data.columns().iter().zip(b.data.columns()) {
                let d = max_abs_diff(va, vb);
                let scale = rms(vb);
                report.push(format!("  {} {ca}: max |Δ| {d:.2e} (channel RMS {scale:.2e}, SI units)", a.name));
                check(
                    d <= 1e-3 * scale + 1e-12,
                    format!("{name} run {} channel {ca}: differs by {d:e}, channel RMS {scale:e}", a.name),
                );
            }
        }
        // Every estimate of the table: same pass/fail, recovered values within 1 % of the tolerance.
        assert_eq!(fast.3.checks.len(), reference.3.checks.len());
        for (a, b) in fast.3.checks.iter().zip(&reference.3.checks) {
            let d = (a.recovered - b.recovered).abs();
            report.push(format!("  estimate {}: |Δ recovered| {d:.2e} (tolerance {:.2e})", a.error, a.tolerance));
            check(a.pass == b.pass, format!("{name} {}: pass differs", a.error));
            check(
                d <= 0.01 * a.tolerance,
                format!("{name} {}: recovered differ by {d:e}, tolerance {:e}", a.error, a.tolerance),
            );
        }
    }
    println!("{}", report.join("\n"));
    assert!(failures.is_empty(), "{} differences over their bounds:\n{}", failures.len(), failures.join("\n"));
}
