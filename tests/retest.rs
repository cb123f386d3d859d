//! The compensation check's re-test derived from the uncompensated re-test (`Retest::Derived`, what a
//! study's trials use, issue 12) against the re-test simulated with the table in the CNC
//! (`Retest::Simulated`, what `vmt run` uses), on every bundled scenario, lesson and the README's
//! physical study that has a positioning test read by a laser (the default scenario's own compensation
//! check; the others with one added): a linear motor, and semi-closed ball screws with backlash, Coulomb
//! friction, lead error and thermal drift. Two trials each, the tables estimated from each trial's own
//! noisy ISO 230-2 test.
//!
//! The bound (`vmt_sim::retest` module docs): the derivation neglects where inside one feedback count
//! the loop settles, up to one count r of the servo's resolution per reading (the table rests anywhere in
//! the count the loop holds, a deterministic offset that does not average out over a dwell), carried to
//! the table by the positioning chain (1 + E' with |E'| < 1e-3); the other neglected terms (the settling
//! state's change over a correction of tens of µm) are below 1e-14 m. So a noise-free reading may move by
//! at most d = r·(1 + 1e-3) + 1e-12 m. E and A are extremes of x̄ ± 2s over targets and directions, and a
//! change of at most d per reading moves a mean by at most d and a standard deviation of n ≥ 2 readings by
//! at most d·√(n/(n − 1)) ≤ d·√2 (Minkowski), so E and A move by at most 2·d·(1 + 2·√2) ≈ 7.7·d, plus,
//! with noise, one count of the laser's resolution per reading in d.

use crate::util::{bundled, root};
use std::path::PathBuf;
use vmt::estimate::{estimate_recording, RemeasureError};
use vmt::measurement::Run;
use vmt::scenario::{EstimatorSpec, Scenario};
use vmt::simulate::{
    physics, read_all, remeasure, simulate_truth, to_measurement_set, truth_view, uncompensated_retests, Physics,
    Retest,
};

/// Every scenario with a positioning procedure read by a laser: the bundled ones, the lessons and the
/// README's physical study (linear motor; semi-closed ball screws with backlash, friction, lead error and
/// thermal drift), each with its compensation check or, where it has none, a compensation check of each
/// positioning procedure's laser added (default settings), so that every drive and time-dependent effect is
/// compared.
fn scenarios_with_compensation() -> Vec<Scenario> {
    let mut all: Vec<PathBuf> = bundled().iter().map(|p| root().join(p)).collect();
    all.push(root().join("benches/study_physical.toml"));
    let mut out = Vec::new();
    for path in all {
        let sc = Scenario::load(&path).unwrap();
        if sc.estimators.iter().any(|e| matches!(e, EstimatorSpec::Compensation { .. })) {
            out.push(sc);
            continue;
        }
        let mut added = String::new();
        for p in &sc.procedures {
            let vmt_sim::procedures::ProcedureSpec::Positioning(q) = p else { continue };
            let laser = q.sensors.iter().find(|n| {
                sc.sensors.iter().any(|s| &s.name == *n && s.kind == vmt::measurement::SensorKind::LaserLinear)
            });
            if let Some(laser) = laser {
                added += &format!("\n[[estimators]]\nkind = \"compensation\"\nrun = \"{}\"\nsensor = \"{laser}\"\n", q.name);
            }
        }
        if !added.is_empty() {
            let text = std::fs::read_to_string(&path).unwrap() + &added;
            out.push(Scenario::parse(&text, &path, path.parent()).unwrap());
        }
    }
    assert!(out.len() >= 5, "expected at least 5 scenarios with a laser-read positioning test, found {}", out.len());
    out
}

/// The physics with noise-free sensors (no white noise, quantisation, bias or drift): the readings are
/// the visits' noise-free means, so two re-tests differ by their physics only.
fn noise_free(ph: &Physics) -> Physics {
    let mut p = ph.clone();
    for s in p.sensors.iter_mut() {
        *s = s.resolved();
        s.preset = None;
        (s.sigma, s.noise_density, s.resolution, s.bias, s.bias_drift) = (0.0, 0.0, 0.0, 0.0, 0.0);
    }
    p
}

fn max_abs_diff(a: &Run, b: &Run) -> f64 {
    let (ca, cb) = (a.data.columns(), b.data.columns());
    assert_eq!(ca.len(), cb.len());
    let mut m = 0.0f64;
    for ((na, va), (nb, vb)) in ca.iter().zip(cb) {
        assert_eq!((na, va.len()), (nb, vb.len()));
        m = va.iter().zip(vb).map(|(x, y)| (x - y).abs()).fold(m, f64::max);
    }
    m
}

#[test]
fn derived_retest_matches_the_simulated_one_on_every_scenario_with_a_compensation_check() {
    const TRIALS: usize = 2;
    let mut report = Vec::new();
    for sc in scenarios_with_compensation() {
        let name = sc.source.strip_prefix(root()).unwrap_or(&sc.source).display().to_string();
        let ph = physics(&sc).unwrap();
        let quiet = noise_free(&ph);
        let truths = simulate_truth(&sc, &ph);
        let retests = uncompensated_retests(&sc, &ph, truths.end).unwrap();
        let d = sc.axis.servo.resolution * (1.0 + 1e-3) + 1e-12;
        let laser_count = ph.sensors.iter().map(|s| s.resolved().resolution).fold(0.0, f64::max);
        let bound_ea = 2.0 * (d + laser_count) * (1.0 + 2.0 * 2f64.sqrt());
        let (mut worst_row, mut worst_noisy, mut worst_ea) = (0.0f64, 0.0f64, 0.0f64);
        for k in 0..TRIALS {
            let seed = vmt_sim::rng::derive_seed(sc.seed, &format!("study/0/{k}"));
            let runs = read_all(&sc, &ph, &truths, seed).unwrap();
            let set = to_measurement_set(&sc, &runs).unwrap();
            // Each trial's own table (from its noisy ISO test) reaches the callback: compare the two
            // re-tests there, noise-free and with the check's noise, and answer with the simulated one.
            let compared = std::sync::Mutex::new(Vec::new());
            let again = |run: &str, x: &[f64], y: &[f64]| -> Result<Run, RemeasureError> {
                let both = |p: &Physics| -> Result<(Run, Run), RemeasureError> {
                    Ok((
                        remeasure(&sc, p, Retest::Simulated, sc.seed, truths.end, run, x, y)?,
                        remeasure(&sc, p, Retest::Derived(&retests), sc.seed, truths.end, run, x, y)?,
                    ))
                };
                let (sim_quiet, der_quiet) = both(&quiet)?;
                let (sim, der) = both(&ph)?;
                compared.lock().unwrap().push((max_abs_diff(&sim_quiet, &der_quiet), max_abs_diff(&sim, &der)));
                Ok(sim)
            };
            let view = truth_view(&sc, &ph, &truths);
            let simulated = estimate_recording(&sc.source, &sc.estimators, &view, &set, &again).unwrap();
            let compared = compared.into_inner().unwrap();
            assert!(!compared.is_empty(), "{name}: the compensation check did not re-measure");
            for (quiet_diff, noisy_diff) in compared {
                worst_row = worst_row.max(quiet_diff);
                worst_noisy = worst_noisy.max(noisy_diff);
            }
            // The checks' E and A after compensation, derived against simulated.
            let derived =
                vmt::workflow::run::estimate_session(&sc, &ph, &truths, &set, Retest::Derived(&retests)).unwrap();
            let after = |e: &vmt::estimate::Estimates| -> Vec<(String, f64)> {
                e.checks.iter().filter(|c| c.id.starts_with("compensation.")).map(|c| (c.id.clone(), c.recovered)).collect()
            };
            let (sim, der) = (after(&simulated), after(&derived));
            assert!(!sim.is_empty() && sim.len() == der.len(), "{name}: {sim:?} {der:?}");
            for ((id, a), (_, b)) in sim.iter().zip(&der) {
                worst_ea = worst_ea.max((a - b).abs());
                assert!((a - b).abs() <= bound_ea, "{name} trial {k} {id}: |{a} − {b}| > {bound_ea} m");
            }
        }
        report.push(format!(
            "{name}: largest |derived − simulated| of a noise-free reading {worst_row:.3e} m (bound {d:.3e} m), \
             of a noisy reading {worst_noisy:.3e} m (bound {:.3e} m), of E or A after {worst_ea:.3e} m (bound {bound_ea:.3e} m)",
            d + laser_count
        ));
        println!("{}", report.last().unwrap());
        assert!(worst_row <= d, "{name}: a noise-free reading differs by {worst_row} m > {d} m");
        assert!(worst_noisy <= d + laser_count, "{name}: a noisy reading differs by {worst_noisy} m > {} m", d + laser_count);
    }
}
