//! The model-check loop (DESIGN.md §8) end to end: an effect hidden in the truth of a simulated
//! positioning test and left out of the model is ranked first and significant by `diagnose`; after
//! `add` and `compare` the normalised RMS is back near the noise level. Plus: two hidden effects found
//! one after the other, a complete model (nothing significant), an inseparable pair, real ISO 230-2
//! data, the JSON contract (FORMAT.md §4) and bad input (exit 2).
//!
//! Each scenario is simulated once (the physics is deterministic); the seeds vary the sensor noise
//! (`vmt::simulate::read_all` with another seed), which is what a verdict must be robust to.

use std::path::{Path, PathBuf};
use std::process::Command;
use vmt::measurement::{MeasurementSet, RunData};
use vmt::model::{read_model, Model, ModelEffect};
use vmt::modelcheck::{add_effect, compare, diagnose};
use vmt::scenario::Scenario;
use vmt::simulate::{physics, read_all, simulate_truth, to_measurement_set};
use vmt_estimators::modelcheck::Verdict;
use vmt_sim::effects::{Effect, EffectName, EffectParams};
use vmt_sim::Axis;

use crate::util::realdata;

/// After adding the hidden effect the residual must be at the noise level: normalised RMS ≤ 1.3.
/// (1.0 is the noise floor, and with ~90 samples its scatter is about ±0.1; the simulator adds some
/// nm of unmodelled servo settling to the 50 nm laser noise.)
const NOISE_LEVEL_NRMS: f64 = 1.3;

/// A lesson-style scenario: semi-closed ball-screw X axis, two lasers along X at heights 0.1 and
/// 0.9 m (σ 50 nm), one positioning cycle with `n` irregular targets over [start, end] and `runs`
/// bidirectional runs; `truth` holds `[truth.effects.*]` tables.
fn scenario_text(truth: &str, n: usize, start: f64, end: f64, runs: u32) -> String {
    // With backlash, a guideway friction of 100 N (μ ≈ 0.008, as in the lessons) holds the table
    // against the nut; a frictionless table floats inside the clearance after each stop, which the
    // simulator shows as ≈ 45 nm of extra scatter (normalised RMS 1.2–1.4 instead of ≈ 1.0).
    let friction = if truth.contains("backlash") { "[truth.effects.coulomb]\nfc = 100.0\n" } else { "" };
    let truth = format!("{friction}{truth}");
    let lesson = std::fs::read_to_string(lesson("backlash").join("scenario.toml")).unwrap();
    let head = lesson.split("[truth]").next().unwrap();
    format!(
        "{head}[truth]\nmachine = \"slide_column\"\naxis = \"x\"\n{truth}\n\
         [[sensors]]\nname = \"laser_low\"\nkind = \"laser_linear\"\nposition = [0.3, 0.0, 0.1]\n\
         direction = [1.0, 0.0, 0.0]\nsigma = 50e-9\n\
         [[sensors]]\nname = \"laser_high\"\nkind = \"laser_linear\"\nposition = [0.3, 0.0, 0.9]\n\
         direction = [1.0, 0.0, 0.0]\nsigma = 50e-9\n\
         [[procedures]]\nkind = \"positioning\"\nname = \"iso\"\nn_targets = {n}\nstart = {start}\nend = {end}\n\
         runs = {runs}\nfeed = 0.4\ndwell = 0.15\naverage = 0.05\nsensors = [\"laser_low\", \"laser_high\"]\n"
    )
}

fn lesson(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("scenarios/lessons").join(name)
}

/// Simulates a scenario once and returns its measurement set for each noise seed.
fn sets(sc: &Scenario, seeds: &[u64]) -> Vec<MeasurementSet> {
    let ph = physics(sc).unwrap();
    let truths = simulate_truth(sc, &ph);
    seeds.iter().map(|&s| to_measurement_set(sc, &read_all(sc, &ph, &truths, s).unwrap()).unwrap()).collect()
}

/// A model of axis x with the named effects, each `fit = true` with no starting values.
fn model_fitting(names: &[EffectName]) -> Model {
    Model {
        machine: None,
        axis: Axis::X,
        effects: names
            .iter()
            .map(|&n| ModelEffect {
                effect: Effect { name: n, axis: Axis::X, params: EffectParams::default_for(n) },
                fit: true,
                basis: None,
                order: None,
                given: Vec::new(),
            })
            .collect(),
        source: PathBuf::from("test_model.toml"),
    }
}

/// One loop step: diagnose must rank `hidden` first and significant; add it from the diagnosis;
/// return (diagnosed normalised RMS, normalised RMS after add + compare, new model).
fn step(model: &Model, set: &MeasurementSet, hidden: EffectName, label: &str) -> (f64, f64, Model) {
    let data = Path::new("sim");
    let d = diagnose(model, set, data).unwrap();
    let first = &d.ranking[0];
    assert_eq!(first.effect, hidden, "{label}: ranking {:#?}", d.ranking);
    assert_eq!(first.verdict, Verdict::Significant, "{label}: {first:?}");
    let m2 = add_effect(model, hidden, Some(first)).unwrap();
    let c = compare(&m2, set, data).unwrap();
    (d.normalized_rms, c.normalized_rms, m2)
}

/// For each hidden effect: truth = base + hidden, model = base (fitted). Five noise seeds each.
#[test]
fn each_hidden_effect_is_found_first_and_adding_it_reaches_the_noise_level() {
    let wide = (11usize, 0.02, 0.98);
    let dense = (41usize, 0.30, 0.46); // 4 mm spacing: finer than the 16 mm screw lead
    let cases: Vec<(EffectName, &str, EffectName, &str, (usize, f64, f64), u32)> = vec![
        (
            EffectName::Backlash,
            "[truth.effects.backlash]\nvalue = 3e-6\n",
            EffectName::ScaleError,
            "[truth.effects.scale_error]\nvalue = 8e-6\n",
            wide,
            2,
        ),
        (
            EffectName::ScaleError,
            "[truth.effects.scale_error]\nvalue = 8e-6\n",
            EffectName::Backlash,
            "[truth.effects.backlash]\nvalue = 2e-6\n",
            wide,
            2,
        ),
        (
            EffectName::CyclicLead,
            "[truth.effects.cyclic_lead]\nperiod = 0.016\namplitude = 0.8e-6\nphase = 0.4\n",
            EffectName::Backlash,
            "[truth.effects.backlash]\nvalue = 2e-6\n",
            dense,
            2,
        ),
        (
            EffectName::ThermalExpansion,
            "[truth.effects.thermal_expansion]\nalpha = 11.5e-6\ndelta_t = 1.0\ntau = 15.0\n",
            EffectName::Backlash,
            "[truth.effects.backlash]\nvalue = 2e-6\n",
            wide,
            3,
        ),
        (
            EffectName::ThermalDrift,
            "[truth.effects.thermal_drift]\nvalue = 1.5e-6\ntau = 15.0\n",
            EffectName::Backlash,
            "[truth.effects.backlash]\nvalue = 2e-6\n",
            wide,
            3,
        ),
        (
            EffectName::Pitch,
            "[truth.effects.pitch]\npoly = [0.0, 15e-6, -12e-6]\n",
            EffectName::ScaleError,
            "[truth.effects.scale_error]\nvalue = 8e-6\n",
            wide,
            2,
        ),
    ];
    let seeds: [u64; 5] = [1, 2, 3, 4, 5];
    for (hidden, htoml, base, btoml, (n, a, b), runs) in cases {
        let text = scenario_text(&format!("{btoml}{htoml}"), n, a, b, runs);
        let sc = Scenario::parse(&text, Path::new("hidden.toml"), None).unwrap();
        let model = model_fitting(&[base]);
        for (seed, set) in seeds.iter().zip(sets(&sc, &seeds)) {
            let label = format!("hidden {hidden}, seed {seed}");
            let (before, after, _) = step(&model, &set, hidden, &label);
            eprintln!("{label}: normalised RMS {before:.2} → {after:.3}");
            assert!(after <= NOISE_LEVEL_NRMS, "{label}: normalised RMS after add {after:.3}");
            assert!(after < before, "{label}");
        }
    }
}

/// Lesson `drift_and_lead`: two hidden effects (cyclic lead, thermal drift) found one after the
/// other from the lesson's own files, the error falling at each step, then nothing significant.
#[test]
fn lesson_two_hidden_effects_are_found_one_after_the_other() {
    let sc = Scenario::load(&lesson("drift_and_lead").join("scenario.toml")).unwrap();
    let m0 = read_model(&lesson("drift_and_lead").join("start_model.toml")).unwrap();
    let set = &sets(&sc, &[sc.seed])[0];
    let data = Path::new("sim");
    let d0 = diagnose(&m0, set, data).unwrap();
    let first = d0.ranking[0].effect;
    assert!(matches!(first, EffectName::CyclicLead | EffectName::ThermalDrift), "{:#?}", d0.ranking);
    let second = if first == EffectName::CyclicLead { EffectName::ThermalDrift } else { EffectName::CyclicLead };
    let (n0, n1, m1) = step(&m0, set, first, "drift_and_lead step 1");
    let (n1b, n2, m2) = step(&m1, set, second, "drift_and_lead step 2");
    eprintln!("drift_and_lead: normalised RMS {n0:.2} → {n1:.2} ({n1b:.2}) → {n2:.3}");
    assert!((n1 - n1b).abs() < 1e-9 * n1, "compare and diagnose agree on the residual");
    assert!(n1 < n0 && n2 < n1 && n2 <= NOISE_LEVEL_NRMS);
    let d2 = diagnose(&m2, set, data).unwrap();
    assert!(d2.ranking.iter().all(|r| r.verdict != Verdict::Significant), "{:#?}", d2.ranking);
    assert!(d2.advice.contains("no missing effect is significant"), "{}", d2.advice);
    // The fitted lead is the screw's 16 mm; 1 % covers the period's scatter at 50 nm noise on a
    // 0.8 µm amplitude over ten leads (measured 0.02 %).
    let c = compare(&m2, set, data).unwrap();
    let p = c.fitted[EffectName::CyclicLead]["period"];
    assert!((p - 0.016).abs() < 0.016 * 0.01, "period {p}");
}

/// The other two lessons: their hidden effect is found first and adding it reaches the noise level.
#[test]
fn lessons_backlash_and_abbe_pitch_work_as_written() {
    for (name, hidden) in [("backlash", EffectName::Backlash), ("abbe_pitch", EffectName::Pitch)] {
        let sc = Scenario::load(&lesson(name).join("scenario.toml")).unwrap();
        let m0 = read_model(&lesson(name).join("start_model.toml")).unwrap();
        let set = &sets(&sc, &[sc.seed])[0];
        let (before, after, _) = step(&m0, set, hidden, name);
        eprintln!("lesson {name}: normalised RMS {before:.2} → {after:.3}");
        assert!(after <= NOISE_LEVEL_NRMS);
    }
}

/// A complete model (every effect of the truth fitted): no candidate may be significant. The
/// false-alarm rate the ΔBIC < −10 threshold allows is far below 1/20 per candidate set
/// (estimators' modelcheck docs), so 20 noise seeds with no significant candidate is the test.
#[test]
fn a_complete_model_has_no_significant_candidate_over_20_seeds() {
    let truth = "[truth.effects.backlash]\nvalue = 2e-6\n[truth.effects.scale_error]\nvalue = 8e-6\n\
                 [truth.effects.cyclic_lead]\nperiod = 0.016\namplitude = 0.8e-6\nphase = 0.4\n";
    let sc = Scenario::parse(&scenario_text(truth, 41, 0.30, 0.46, 2), Path::new("complete.toml"), None).unwrap();
    let model = model_fitting(&[EffectName::Backlash, EffectName::ScaleError, EffectName::CyclicLead]);
    let seeds: Vec<u64> = (100..120).collect();
    let mut worst: f64 = f64::INFINITY;
    for (seed, set) in seeds.iter().zip(sets(&sc, &seeds)) {
        let d = diagnose(&model, &set, Path::new("sim")).unwrap();
        let sig: Vec<&str> =
            d.ranking.iter().filter(|r| r.verdict != Verdict::Noise).map(|r| r.effect.as_str()).collect();
        assert!(sig.is_empty(), "seed {seed}: {sig:?} {:#?}", d.ranking);
        assert!(d.advice.contains("no missing effect is significant"));
        worst = worst.min(d.ranking[0].delta_bic);
        assert!(d.normalized_rms <= NOISE_LEVEL_NRMS, "seed {seed}: {}", d.normalized_rms);
    }
    eprintln!("complete model: best candidate ΔBIC over 20 seeds {worst:.1} (threshold −10)");
}

/// Thermal expansion and scale error with every reading at the same time (no `t`, one start
/// time): the two signatures are both α·ΔT·x and x, so diagnose must call them inseparable and say
/// that a test when the machine is warm separates them.
#[test]
fn thermal_expansion_and_scale_error_at_one_time_are_inseparable() {
    let truth = "[truth.effects.backlash]\nvalue = 2e-6\n[truth.effects.scale_error]\nvalue = 8e-6\n";
    let sc = Scenario::parse(&scenario_text(truth, 11, 0.02, 0.98, 2), Path::new("one_time.toml"), None).unwrap();
    let model = model_fitting(&[EffectName::Backlash]);
    for mut set in sets(&sc, &[7, 8, 9]) {
        for r in &mut set.runs {
            r.start_time = Some(600.0);
            if let RunData::PointTable { t, .. } = &mut r.data {
                *t = None;
            }
        }
        let d = diagnose(&model, &set, Path::new("sim")).unwrap();
        let get = |e: EffectName| d.ranking.iter().find(|r| r.effect == e).unwrap();
        let (s, th) = (get(EffectName::ScaleError), get(EffectName::ThermalExpansion));
        assert_eq!(s.verdict, Verdict::Inseparable, "{:#?}", d.ranking);
        assert_eq!(th.verdict, Verdict::Inseparable);
        assert!(s.confused_with.contains(&EffectName::ThermalExpansion));
        assert!(d.advice.contains("warm"), "{}", d.advice);
    }
}

/// Issue 11: a 20 µm interpolation error read at 41 targets ≈ 24 mm apart is not observable (its
/// phase at each target depends on the target's position to far better than 20 µm, and the
/// readings resolve no period shorter than ≈ 2 × the gap). Before issue 11 this case was expected
/// to be found (by fitting the exact catalogue period to per-target scatter); now diagnose does
/// not search it, lists it with a note saying why, and claims nothing periodic below the spacing.
#[test]
fn interpolation_error_between_sparse_targets_is_not_searched() {
    let truth = "[truth.effects.scale_error]\nvalue = 2e-6\n[truth.effects.interpolation_error]\nperiod = 20e-6\namplitude = 0.5e-6\nphase = 1.0\n";
    let sc = Scenario::parse(&scenario_text(truth, 41, 0.02, 0.98, 2), Path::new("hidden.toml"), None).unwrap();
    let model = model_fitting(&[EffectName::ScaleError]);
    let set = &sets(&sc, &[1])[0];
    let d = diagnose(&model, set, Path::new("sim")).unwrap();
    let e = d.ranking.iter().find(|r| r.effect == EffectName::InterpolationError).expect("listed");
    assert_eq!(e.verdict, Verdict::Noise, "{e:?}");
    assert!(e.note.as_deref().is_some_and(|n| n.contains("not searched")), "{e:?}");
    for r in d.ranking.iter().filter(|r| r.verdict == Verdict::Significant) {
        assert!(r.params.get("period").is_none_or(|p| *p > 20e-3), "{r:?}");
    }
}

/// Real data: ISO 230-2 tests of ESS/PSI axes (ecmc `.dat` files, one reference sensor, no σ).
/// The raw deviations (offset only) → diagnose → add the first significant effect → compare:
/// the residual RMS must fall. A positioning profile (cubic) must also reduce it.
#[test]
fn real_iso230_2_data_the_loop_reduces_the_residual() {
    let Some(dir) = realdata::realdata("ecmc_iso230_2", "real_iso230_2_data_the_loop_reduces_the_residual") else {
        return;
    };
    // Minimum number of effects the loop adds. mcu1025 (raw normalised RMS 1.51): its only
    // significant candidate is a cyclic lead at 35.6 mm that, on its regular targets, fits exactly
    // as well at eight aliases from 2.2 to 7.9 mm (issue 11): `inseparable`, nothing to add; before
    // issue 11 the loop added that unidentified period.
    for (file, min_added) in [
        ("ess_target_muts_logger/b02_x_target_x.md_ISO230.dat", 1),
        ("ess_target_muts_logger/b02_y_report_target_y.md_ISO230.dat", 1),
        ("psi_ecmccfg/mcu1025_fat_sat_report.md_ISO230.dat", 0),
    ] {
        let path = dir.join(file);
        let text = std::fs::read_to_string(&path).unwrap();
        let dat = vmt_estimators::iso230_2::dat::parse_dat(&text).unwrap();
        let set = vmt::measurement::from_iso230_2_dat(&dat);
        let m0 = model_fitting(&[]);
        let c0 = compare(&m0, &set, &path).unwrap();
        // The loop: add the best significant candidate until none is left (at most 4 steps); the
        // residual RMS must fall at every step.
        let (mut model, mut rms) = (m0.clone(), c0.channels[0].rms);
        let mut steps: Vec<String> = vec![format!("raw {:.3} µm (nrms {:.2})", rms * 1e6, c0.normalized_rms)];
        for _ in 0..4 {
            let d = diagnose(&model, &set, &path).unwrap();
            let Some(best) = d.ranking.iter().find(|r| r.verdict == Verdict::Significant) else {
                steps.push(format!("stop: {}", d.advice));
                break;
            };
            let name: EffectName = best.effect;
            model = add_effect(&model, name, Some(best)).unwrap();
            let c = compare(&model, &set, &path).unwrap();
            steps.push(format!(
                "+ {name} (ΔBIC {:.0}): {:.3} µm (nrms {:.2})",
                best.delta_bic,
                c.channels[0].rms * 1e6,
                c.normalized_rms
            ));
            assert!(c.channels[0].rms < rms, "{file}: {steps:?}");
            rms = c.channels[0].rms;
        }
        assert!(steps.len() >= 2 + min_added, "{file}: the loop must add at least {min_added} effects: {steps:?}");
        if min_added == 0 {
            assert!(steps.last().is_some_and(|s| s.contains("not identified")), "{file}: {steps:?}");
        }
        eprintln!("{file}: {}", steps.join(" → "));
        assert!(c0.notes.iter().any(|n| n.contains("estimated")), "σ estimated and said so");
    }
}

/// Real data, issue 11: b02_x has 9 targets regularly 5 mm apart, so no period below 2 × 5 = 10 mm
/// can be told from its aliases (1/p' = |1/p − k/5 mm| fit the targets equally well). With a fitted
/// positioning profile and backlash (the model a user starts from), `diagnose` must claim no
/// cyclic lead or interpolation error shorter than 10 mm (before the fix: a 23.7 µm cyclic lead at
/// 3.97 mm, ΔBIC −2050) and must say why such periods are not searched.
#[test]
fn real_b02_x_no_cyclic_lead_shorter_than_the_targets_resolve() {
    let Some(dir) = realdata::realdata("ecmc_iso230_2", "real_b02_x_no_cyclic_lead_shorter_than_the_targets_resolve")
    else {
        return;
    };
    let path = dir.join("ess_target_muts_logger/b02_x_target_x.md_ISO230.dat");
    let text = std::fs::read_to_string(&path).unwrap();
    let dat = vmt_estimators::iso230_2::dat::parse_dat(&text).unwrap();
    let set = vmt::measurement::from_iso230_2_dat(&dat);
    let model = model_fitting(&[EffectName::Positioning, EffectName::Backlash]);
    let d = diagnose(&model, &set, &path).unwrap();
    for r in &d.ranking {
        let period = r.params.get("period").copied();
        eprintln!("b02_x: {} {:?} ΔBIC {:.1} period {:?}", r.effect, r.verdict, r.delta_bic, period);
        if let Some(p) = period {
            assert!(p >= 10e-3, "{} at a {:.3} mm period, below 2 × the 5 mm target spacing", r.effect, p * 1e3);
        }
    }
    assert!(
        d.notes.iter().any(|n| n.contains("interpolation_error not searched"))
            && d.notes.iter().any(|n| n.contains("cyclic_lead searched only at periods ≥ 10")),
        "{:?}",
        d.notes
    );
}

/// Every ISO 230-2 `.dat` file of `realdata/ecmc_iso230_2` (12), sorted; None (skipped, visibly)
/// without the real data.
fn real_dat_files(test: &str) -> Option<Vec<PathBuf>> {
    let root = realdata::realdata("ecmc_iso230_2", test)?;
    let mut files: Vec<PathBuf> = std::fs::read_dir(&root)
        .unwrap()
        .flat_map(|d| std::fs::read_dir(d.unwrap().path()).into_iter().flatten())
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|e| e == "dat"))
        .collect();
    files.sort();
    Some(files)
}

/// The loop on one real `.dat` file from an empty model (offsets only): diagnose, add the first
/// `significant` entry, up to 5 times. Returns the set, the final model and every diagnosis.
fn real_loop(path: &Path) -> (MeasurementSet, Model, Vec<vmt::modelcheck::DiagnoseReport>) {
    let text = std::fs::read_to_string(path).unwrap();
    let dat = vmt_estimators::iso230_2::dat::parse_dat(&text).unwrap();
    let set = vmt::measurement::from_iso230_2_dat(&dat);
    let mut model = model_fitting(&[]);
    let mut steps = Vec::new();
    for _ in 0..5 {
        let d = diagnose(&model, &set, path).unwrap();
        let top = d.ranking.iter().find(|r| r.verdict == Verdict::Significant).cloned();
        steps.push(d);
        let Some(top) = top else { break };
        model = add_effect(&model, top.effect, Some(&top)).unwrap();
    }
    (set, model, steps)
}

/// Real data, issue 11: on every ISO 230-2 file, at every step of the loop, no `significant` claim
/// of a periodic effect at a period the targets cannot resolve: P ≥ 2 × the smallest gap between
/// neighbouring targets (the Nyquist limit of the layout; shorter periods have aliases that fit
/// the targets equally well).
#[test]
fn real_iso230_2_no_claim_at_an_unresolvable_period() {
    let Some(files) = real_dat_files("real_iso230_2_no_claim_at_an_unresolvable_period") else { return };
    assert_eq!(files.len(), 12, "{files:?}");
    for path in files {
        let text = std::fs::read_to_string(&path).unwrap();
        let dat = vmt_estimators::iso230_2::dat::parse_dat(&text).unwrap();
        let mut t: Vec<f64> = dat.targets.clone();
        t.sort_by(f64::total_cmp);
        let gap = t.windows(2).map(|w| w[1] - w[0]).fold(f64::INFINITY, f64::min);
        let (_, _, steps) = real_loop(&path);
        for (k, d) in steps.iter().enumerate() {
            for r in d.ranking.iter().filter(|r| r.verdict == Verdict::Significant) {
                if let Some(p) = r.params.get("period") {
                    assert!(
                        *p >= 2.0 * gap,
                        "{}: step {k}: {} at {:.3} mm, below 2 × the {:.3} mm target gap",
                        path.display(),
                        r.effect,
                        p * 1e3,
                        gap * 1e3
                    );
                }
            }
        }
    }
}

/// A tool (issue 11's real-data table): the loop on every ISO 230-2 `.dat` file of
/// `realdata/ecmc_iso230_2`, from an empty model (offsets only): diagnose, add the first-ranked
/// `significant` effect from the diagnosis, up to 5 times. Prints per file the normalised RMS before
/// and after (against σ from the repeats: the files state none), the σ check, what was added and
/// every other claim (inseparable entries with their aliases). Run with
/// `cargo test --release --test tests model_check::real_data_loop_table -- --ignored --nocapture`.
#[test]
#[ignore = "a tool: prints the real-data loop table of issue 11"]
fn real_data_loop_table() {
    let Some(files) = real_dat_files("real_data_loop_table") else { return };
    println!(
        "| file | targets | RMS start → end (µm) | σ from repeats (µm, dof) | NRMS vs σ_rep start → end | vmt NRMS end | \
         added (in order) | other claims at the end |"
    );
    println!("|---|---|---|---|---|---|---|---|");
    for path in files {
        let (set, model, steps) = real_loop(&path);
        let start = steps[0].normalized_rms;
        let added: Vec<String> = steps
            .iter()
            .filter_map(|d| d.ranking.iter().find(|r| r.verdict == Verdict::Significant))
            .map(|top| {
                let p = top.params.get("period").map_or(String::new(), |p| format!(" {:.2} mm", p * 1e3));
                format!("{}{p}", top.effect)
            })
            .collect();
        let others: Vec<String> = steps[steps.len() - 1]
            .ranking
            .iter()
            .filter(|r| r.verdict != Verdict::Noise)
            .map(|r| {
                let p = r.params.get("period").map_or(String::new(), |p| format!(" at {:.2} mm", p * 1e3));
                let al = if r.aliases.is_empty() { String::new() } else { format!(", {} aliases", r.aliases.len()) };
                format!("{}{p} {:?}{al}", r.effect, r.verdict)
            })
            .collect();
        let c0 = compare(&model_fitting(&[]), &set, &path).unwrap();
        let c = compare(&model, &set, &path).unwrap();
        let rms = |c: &vmt::modelcheck::CompareReport| {
            (c.channels.iter().map(|h| h.rms * h.rms).sum::<f64>() / c.channels.len() as f64).sqrt()
        };
        let s_rep = c.sigma.as_ref().map_or(f64::NAN, |s| s.from_repeats);
        let sc = c.sigma.as_ref().map_or("-".to_string(), |s| format!("{:.3} ({})", s.from_repeats * 1e6, s.dof));
        let mut t: Vec<u64> = set
            .runs
            .iter()
            .flat_map(|r| match &r.data {
                vmt::measurement::RunData::PointTable { target, .. } => target.iter().map(|x| x.to_bits()).collect(),
                vmt::measurement::RunData::TimeSeries { .. } => Vec::new(),
            })
            .collect();
        t.sort_unstable();
        t.dedup();
        println!(
            "| {} | {} | {:.2} → {:.2} | {sc} | {:.2} → {:.2} | {:.2} (start {start:.2}) | {} | {} |",
            path.file_name().unwrap().to_string_lossy(),
            t.len(),
            rms(&c0) * 1e6,
            rms(&c) * 1e6,
            rms(&c0) / s_rep,
            rms(&c) / s_rep,
            c.normalized_rms,
            added.join(", "),
            others.join("; ")
        );
    }
}

fn vmt_bin() -> Command {
    crate::util::vmt()
}

/// The command line: simulate a lesson, compare/diagnose with --json (FORMAT.md §4 keys), add with
/// --from-diagnosis (history.json), and bad input exits 2 with a message.
#[test]
fn cli_json_contract_history_and_bad_input() {
    let tmp = tempfile::tempdir().unwrap();
    let data = tmp.path().join("data");
    let st = vmt_bin()
        .args(["simulate", lesson("backlash").join("scenario.toml").to_str().unwrap(), "-o", data.to_str().unwrap()])
        .status()
        .unwrap();
    assert!(st.success());
    let m0 = lesson("backlash").join("start_model.toml");
    let run_json = |args: &[&str]| -> serde_json::Value {
        let out = vmt_bin().args(args).output().unwrap();
        assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
        serde_json::from_slice(&out.stdout).unwrap()
    };
    let c = run_json(&["compare", "--model", m0.to_str().unwrap(), "--data", data.to_str().unwrap(), "--json"]);
    for k in ["model", "data", "channels", "normalized_rms", "fitted"] {
        assert!(c.get(k).is_some(), "compare JSON lacks `{k}`");
    }
    for k in ["run", "sensor", "rms", "normalized_rms", "fit_percent"] {
        assert!(c["channels"][0].get(k).is_some(), "channel lacks `{k}`");
    }
    assert!(c["fitted"]["scale_error"]["value"].is_f64());
    let d = run_json(&["diagnose", "--model", m0.to_str().unwrap(), "--data", data.to_str().unwrap(), "--json"]);
    assert!(d["normalized_rms"].is_f64() && d["advice"].is_string());
    let first = &d["ranking"][0];
    for k in ["effect", "delta_bic", "explained", "verdict", "params", "confused_with"] {
        assert!(first.get(k).is_some(), "ranking entry lacks `{k}`");
    }
    assert_eq!(first["effect"], "backlash");
    assert_eq!(first["verdict"], "significant");
    let m1 = tmp.path().join("it/m1.toml");
    let st = vmt_bin()
        .args(["add", "--model", m0.to_str().unwrap(), "--effect", "backlash", "--from-diagnosis"])
        .args(["--data", data.to_str().unwrap(), "-o", m1.to_str().unwrap()])
        .status()
        .unwrap();
    assert!(st.success());
    let h: Vec<serde_json::Value> =
        serde_json::from_str(&std::fs::read_to_string(tmp.path().join("it/history.json")).unwrap()).unwrap();
    assert_eq!(h.len(), 2);
    assert!(h[1]["normalized_rms"].as_f64().unwrap() < h[0]["normalized_rms"].as_f64().unwrap());
    let c1 = run_json(&["compare", "--model", m1.to_str().unwrap(), "--data", data.to_str().unwrap(), "--json"]);
    assert_eq!(c1["history"].as_array().unwrap().len(), 2);
    assert!(c1["normalized_rms"].as_f64().unwrap() <= NOISE_LEVEL_NRMS);
    // The diagnosis printed above given as a file (`--diagnosis`, not computed again): the same
    // model written. A diagnosis of other data, or a file that is not one, exits 2 naming it.
    let dfile = tmp.path().join("diagnosis.json");
    std::fs::write(&dfile, serde_json::to_string_pretty(&d).unwrap()).unwrap();
    let add_with = |file: &Path, out: &Path| {
        vmt_bin()
            .args([
                "add",
                "--model",
                m0.to_str().unwrap(),
                "--effect",
                "backlash",
                "--diagnosis",
                file.to_str().unwrap(),
            ])
            .args(["--data", data.to_str().unwrap(), "-o", out.to_str().unwrap()])
            .output()
            .unwrap()
    };
    let m1f = tmp.path().join("it_file/m1.toml");
    let out = add_with(&dfile, &m1f);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let model_text = |p: &Path| {
        std::fs::read_to_string(p).unwrap().lines().filter(|l| !l.starts_with('#')).collect::<Vec<_>>().join("\n")
    };
    assert_eq!(model_text(&m1f), model_text(&m1));
    let mut other = d.clone();
    other["normalized_rms"] = serde_json::json!(d["normalized_rms"].as_f64().unwrap() * 1.001);
    let ofile = tmp.path().join("other.json");
    std::fs::write(&ofile, serde_json::to_string(&other).unwrap()).unwrap();
    let cfile = tmp.path().join("compare.json");
    std::fs::write(&cfile, serde_json::to_string(&c).unwrap()).unwrap();
    for (file, expect) in [(&ofile, "was not made for this model"), (&cfile, "vmt-diagnose/1")] {
        let out = add_with(file, &tmp.path().join("it_bad/m1.toml"));
        let err = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(2), "{err}");
        assert!(err.contains(expect) && err.contains(file.file_name().unwrap().to_str().unwrap()), "{err}");
    }
    assert!(!tmp.path().join("it_bad/m1.toml").exists());

    // Bad input: exit 2 and a message naming the problem.
    let bad = |model_text: &str, data_dir: &Path, expect: &str| {
        let mp = tmp.path().join("bad.toml");
        std::fs::write(&mp, model_text).unwrap();
        let out = vmt_bin()
            .args(["compare", "--model", mp.to_str().unwrap(), "--data", data_dir.to_str().unwrap()])
            .output()
            .unwrap();
        let err = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(2), "{err}");
        assert!(err.contains(expect), "expected `{expect}` in: {err}");
    };
    bad("format = \"vmt-model/1\"\n[effects.warp_drive]\nfit = true\n", &data, "unknown effect `warp_drive`");
    bad("format = \"vmt-model/1\"\n[effects.straightness_y]\nfit = true\n", &data, "no channel of the data sees it");
    // Fitted error motions: a Legendre series whose order BIC chooses, reported as `shapes`; the
    // a bad order of a basis is refused.
    let mp = tmp.path().join("shape.toml");
    std::fs::write(&mp, "format = \"vmt-model/1\"\naxis = \"x\"\n[effects.positioning]\nfit = true\n").unwrap();
    let c2 = run_json(&["compare", "--model", mp.to_str().unwrap(), "--data", data.to_str().unwrap(), "--json"]);
    let sh = &c2["shapes"]["positioning"];
    assert_eq!(sh["basis"], "legendre", "{c2}");
    assert!(sh["order"].as_u64().is_some_and(|o| o >= 1), "{c2}");
    assert!(sh["chosen_by"].as_str().is_some_and(|s| s.starts_with("BIC over 1..")), "{c2}");
    // Every basis is fitted now (tests/gen_diagnose.rs); a bad order is refused.
    bad(
        "format = \"vmt-model/1\"\naxis = \"x\"\n[effects.positioning]\nfit = true\nbasis = \"bspline\"\norder = 1\n",
        &data,
        "effects.positioning.order",
    );
    // Too few readings without σ: a 2-target, 1-run table (4 readings) with sigma removed.
    let small = tmp.path().join("small");
    let mut set = vmt::measurement::read(&data).unwrap();
    for s in &mut set.sensors {
        s.sigma = None;
    }
    for r in &mut set.runs {
        if let RunData::PointTable { target, run, direction, t, columns } = &mut r.data {
            let keep: Vec<usize> = (0..target.len()).filter(|&i| i % 11 < 2 && run[i] == 1).collect();
            let pick = |v: &Vec<f64>| keep.iter().map(|&i| v[i]).collect::<Vec<f64>>();
            *target = pick(target);
            *direction = keep.iter().map(|&i| direction[i]).collect();
            *run = keep.iter().map(|&i| run[i]).collect();
            *t = t.as_ref().map(pick);
            for (_, v) in columns.iter_mut() {
                *v = pick(v);
            }
        }
    }
    vmt::measurement::write(&set, &small, vmt::measurement::UnitChoice::Si).unwrap();
    bad("format = \"vmt-model/1\"\n[effects.backlash]\nfit = true\n", &small, "no sigma");
}

/// Phase 2, friction from the motor force of a friction sweep (lesson `stribeck`): the hidden
/// Stribeck effect is found first and significant over five noise seeds, adding it reaches the
/// noise level, and the fitted law matches the truth. Then the same sweep with a model holding
/// only Coulomb friction: the hidden viscous friction (the truth without Stribeck) is found.
#[test]
fn friction_sweep_hidden_stribeck_and_viscous_are_found() {
    let text = std::fs::read_to_string(lesson("stribeck").join("scenario.toml")).unwrap();
    let sc = Scenario::parse(&text, Path::new("stribeck.toml"), None).unwrap();
    let m0 = read_model(&lesson("stribeck").join("start_model.toml")).unwrap();
    for (seed, set) in [1u64, 2, 3, 4, 5].iter().zip(sets(&sc, &[1, 2, 3, 4, 5])) {
        let label = format!("hidden stribeck, seed {seed}");
        let (before, after, m1) = step(&m0, &set, EffectName::Stribeck, &label);
        eprintln!("{label}: normalised RMS {before:.2} → {after:.3}");
        assert!(after <= NOISE_LEVEL_NRMS, "{label}: {after}");
        let f = compare(&m1, &set, Path::new("sim")).unwrap().fitted;
        // 2 N noise on 14 × 150 samples: the levels are determined to ≈ 0.1 N; 1 % (1.5–2.6 N)
        // leaves room for the simulator's small servo ripple in the cruise windows (measured
        // fc 150.1, fs 260.3, fv 798 against 150, 260, 800); vs to 5 % (measured 1.99 mm/s).
        let near = |v: f64, t: f64, rel: f64| (v - t).abs() <= rel * t;
        assert!(near(f[EffectName::Coulomb]["fc"], 150.0, 0.01), "{f:?}");
        assert!(near(f[EffectName::Stribeck]["fs"], 260.0, 0.01), "{f:?}");
        assert!(near(f[EffectName::Viscous]["fv"], 800.0, 0.01), "{f:?}");
        assert!(near(f[EffectName::Stribeck]["vs"], 2e-3, 0.05), "{f:?}");
    }
    let text = text.replace("[truth.effects.stribeck]", "#").replace("fs = 260.0", "").replace("vs = 2e-3", "");
    let sc = Scenario::parse(&text, Path::new("viscous.toml"), None).unwrap();
    let m0 = model_fitting(&[EffectName::Coulomb]);
    for (seed, set) in [1u64, 2, 3, 4, 5].iter().zip(sets(&sc, &[1, 2, 3, 4, 5])) {
        let label = format!("hidden viscous, seed {seed}");
        let (before, after, _) = step(&m0, &set, EffectName::Viscous, &label);
        eprintln!("{label}: normalised RMS {before:.2} → {after:.3}");
        assert!(after <= NOISE_LEVEL_NRMS, "{label}: {after}");
    }
}

/// A constant-velocity scenario on the lesson machine: runs at `speeds` (m/s) over [0.3, 0.7] m,
/// `high_rate` Hz at the highest speed (equal sample counts), one accelerometer `acc` mounted at
/// `mount` (a `link = ...` or `position = [...]` line) sensing along `direction`, σ per sample
/// `sigma` (m/s²); `truth` holds `[truth.effects.*]` tables.
fn accel_scenario(truth: &str, mount: &str, direction: &str, sigma: f64, speeds: &str, high_rate: f64) -> String {
    let lesson = std::fs::read_to_string(lesson("backlash").join("scenario.toml")).unwrap();
    let head = lesson.split("[truth]").next().unwrap();
    format!(
        "{head}[truth]\nmachine = \"slide_column\"\naxis = \"x\"\n{truth}\n\
         [[sensors]]\nname = \"x_cmd\"\nkind = \"command\"\n\
         [[sensors]]\nname = \"acc\"\nkind = \"accelerometer\"\n{mount}\ndirection = {direction}\nsigma = {sigma:e}\n\
         [[procedures]]\nkind = \"constant_velocity\"\nname = \"cv\"\nspeeds = {speeds}\nstart = 0.3\nend = 0.7\n\
         settle = 0.3\nhigh_rate = {high_rate}\nsensors = [\"x_cmd\", \"acc\"]\n"
    )
}

/// The guideway of the accelerometer tests below: a random straightness EYX (0.3 µm rms, Gaussian
/// correlation, length 2 mm: fine waviness of a ground rail), seen by a y accelerometer at the
/// column top (link mp3, σ 1 mm/s² per sample) in runs at 0.1 and 0.2 m/s (600 and 1200 Hz), on
/// bearing blocks of 1e10 N/m (preloaded roller guides); `extra` holds further `[truth.effects.*]`
/// tables.
///
/// Why this guideway: the random profile's wavenumbers are N(0, 1/ℓ²), so at speed v its
/// acceleration spans temporal frequencies up to ≈ 3v/(2πℓ) = 48 Hz at 0.2 m/s. The carriage rides
/// on its bearing blocks, a mode of its own (≈ 320 Hz here, ≈ 100 Hz with the lesson's 1e9 N/m)
/// that phase 3 does not predict: the carriage follows the geometry only quasi-statically, with a
/// relative error ≈ (f/f_b)² at frequency f. The band must stay well below f_b for the given
/// straightness to predict the readings to the noise level. Measured (normalised RMS of the model
/// with the straightness given, no column mode, 0.2 m/s run): 1e9 N/m, ℓ = 1 mm (band to 95 Hz):
/// 18.6; 1e10 N/m, ℓ = 1 mm: 1.39, and diagnose then finds the carriage's dynamics as a `resonance`
/// at 110 Hz (ΔBIC −2150); ℓ = 1.5 mm (64 Hz, (64/320)² = 4 %): 1.02, still a `resonance` at 62 Hz
/// (ΔBIC −43 to −57); ℓ = 2 mm ((48/320)² = 2 %): 1.00 and no significant candidate. Stiffer blocks
/// (1e11 N/m) are beyond the simulator's 0.1 ms step (unstable).
fn guideway_scenario(extra: &str) -> Scenario {
    let truth = format!(
        "[truth.effects.straightness_y]\nrandom = {{ rms = 0.3e-6, correlation_length = 0.002, seed = 5 }}\n{extra}"
    );
    let text = accel_scenario(&truth, "link = \"mp3\"", "[0.0, 1.0, 0.0]", 1e-3, "[0.1, 0.2]", 1200.0);
    let text =
        text.replace("stiffness_y = 1e9", "stiffness_y = 1e10").replace("stiffness_z = 1e9", "stiffness_z = 1e10");
    Scenario::parse(&text, Path::new("guideway.toml"), None).unwrap()
}

/// The truth of a scenario as a model whose effects are all given (`fit = false`), without `drop`:
/// the user knows the guideway (e.g. from a straightness measurement with a laser).
fn known_truth(sc: &Scenario, drop: &[EffectName]) -> Model {
    let mut m = sc.truth.clone();
    m.effects.retain(|e| !drop.contains(&e.effect.name));
    for e in &mut m.effects {
        e.fit = false;
    }
    m
}

/// Phase 3 predicts the guideway's own acceleration v²·u·E''(x) of an accelerometer from a given
/// straightness (no resonance in the truth): the residual is then the 1 mm/s² noise and diagnose
/// finds nothing. Without the straightness the same data sit far above the noise (so the
/// prediction is what brings it down).
#[test]
fn accelerometer_guideway_acceleration_is_predicted_from_a_given_straightness() {
    let sc = guideway_scenario("");
    let model = known_truth(&sc, &[]);
    let empty = known_truth(&sc, &[EffectName::StraightnessY]);
    for (seed, set) in [1u64, 2].iter().zip(sets(&sc, &[1, 2])) {
        let c0 = compare(&empty, &set, Path::new("sim")).unwrap().normalized_rms;
        let c = compare(&model, &set, Path::new("sim")).unwrap();
        let per: Vec<String> = c.channels.iter().map(|ch| format!("{} {:.3}", ch.run, ch.normalized_rms)).collect();
        eprintln!(
            "guideway seed {seed}: normalised RMS without EYX {c0:.2}, with EYX given {:.3} {per:?}",
            c.normalized_rms
        );
        // Without EYX the guideway acceleration is many σ (measured normalised RMS 3.6).
        assert!(c0 > 2.0, "seed {seed}: {c0}");
        // Noise level (NOISE_LEVEL_NRMS); measured 1.00–1.01 (the carriage's quasi-static
        // following error, ≈ 2 % at the band's top, is below the noise here).
        assert!(c.normalized_rms <= NOISE_LEVEL_NRMS, "seed {seed}: {per:?}");
        // And nothing is left to find: no candidate significant (a guideway band closer to the
        // carriage's bearing mode shows its dynamics as a `resonance`, see `guideway_scenario`).
        let d = diagnose(&model, &set, Path::new("sim")).unwrap();
        let sig: Vec<&str> =
            d.ranking.iter().filter(|r| r.verdict != Verdict::Noise).map(|r| r.effect.as_str()).collect();
        eprintln!("guideway seed {seed}: best candidate {} ΔBIC {:.1}", d.ranking[0].effect, d.ranking[0].delta_bic);
        assert!(sig.is_empty(), "seed {seed}: {:#?}", d.ranking);
    }
}

/// Issue 16: the report draws the residual's spectrum where a resonance lives, in time. With the
/// 30 Hz column mode of [`accelerometer_hidden_resonance_is_found_at_its_frequency`] missing from the
/// model, each accelerometer channel's whole periodogram (`ChannelReport::spectrum`) has its peak fall
/// below a third once the mode is given (measured 12× and 105×); on the fast pass the peak lies where the
/// mode magnifies the base motion ≥ 4×; the compare report draws it over time (Hz, linear axis), thinned
/// to ≤ 1000 points without losing that peak, and draws no accelerometer spectrum over position.
#[test]
fn the_residual_time_spectrum_of_an_accelerometer_peaks_at_a_missing_mode() {
    let sc = guideway_scenario("[truth.effects.resonance]\nfrequency = 30.0\ndamping = 0.02\n");
    let data = Path::new("sim");
    let set = &sets(&sc, &[1])[0];
    let without = compare(&known_truth(&sc, &[EffectName::Resonance]), set, data).unwrap();
    let with = compare(&known_truth(&sc, &[]), set, data).unwrap();
    let peak = |s: &[(f64, f64)]| s.iter().copied().max_by(|a, b| a.1.total_cmp(&b.1)).unwrap();
    let mut checked = 0;
    let mut peaks: Vec<(String, f64)> = Vec::new();
    for (a, b) in without.channels.iter().zip(&with.channels) {
        assert!(a.spectrum.len() > 100, "{} / {}: {} spectrum bins", a.run, a.sensor, a.spectrum.len());
        let (f, amp) = peak(&a.spectrum);
        let after = b.spectrum.iter().find(|p| p.0 == f).expect("the same frequency grid").1;
        eprintln!(
            "{} / {}: residual spectrum peak {f:.2} Hz, amplitude {:.3} mm/s² without the mode, {:.3} mm/s² with it",
            a.run,
            a.sensor,
            amp * 1e3,
            after * 1e3
        );
        peaks.push((a.run.clone(), f));
        assert!(after < amp / 3.0, "{} / {}: {after} vs {amp}", a.run, a.sensor);
        checked += 1;
    }
    assert!(checked >= 2 && peaks.iter().any(|p| p.0 == "cv_2"), "{checked} channels: {peaks:?}");
    // The mode magnifies the base acceleration by |H − 1| = r²/|1 − r² + 2iζr| (r = f/30 Hz, ζ = 0.02): at
    // least 4× between 26.8 and 34.6 Hz. On the fast pass (0.2 m/s, where the guideway excites 30 Hz) the
    // residual's strongest line lies in that band (32.01 Hz on seed 1: one guideway realisation, whose
    // lines near 30 Hz are at 27.7, 32.0 and 33.8 Hz); the slow pass (0.1 m/s) barely excites the mode,
    // its residual is the mode's quasi-static r² part below resonance (peak 19.8 Hz).
    let magnification = |f: f64| {
        let r: f64 = f / 30.0;
        r * r / ((1.0 - r * r).powi(2) + (0.04 * r).powi(2)).sqrt()
    };
    for (run, f) in &peaks {
        if run == "cv_2" {
            assert!(
                magnification(*f) >= 4.0,
                "{run}: peak at {f} Hz, where the mode magnifies {:.2}×",
                magnification(*f)
            );
        }
    }
    let report = vmt::report::model_check_report(Path::new("model.toml"), data, set, &without, None);
    let fig = report
        .sections
        .iter()
        .flat_map(|s| &s.figures)
        .find(|f| f.title.contains("spectrum of the residual over time"))
        .expect("a time spectrum figure");
    assert!(fig.x_unit == "Hz" && !fig.log_x && fig.y_unit == "m/s²", "{} {} {}", fig.x_unit, fig.log_x, fig.y_unit);
    assert!(
        fig.series.iter().any(|s| s.label.contains("cv_2")),
        "{:?}",
        fig.series.iter().map(|s| &s.label).collect::<Vec<_>>()
    );
    for s in &fig.series {
        assert!(s.x.len() <= 1000, "{}: {} points", s.label, s.x.len());
        let top = s.x.iter().zip(&s.y).max_by(|a, b| a.1.total_cmp(b.1)).unwrap();
        eprintln!("{}: drawn peak at {:.2} Hz", s.label, top.0);
        if s.label.contains("cv_2") {
            assert!(magnification(*top.0) >= 4.0, "{}: drawn peak at {} Hz", s.label, top.0);
        }
    }
    assert!(
        !report
            .sections
            .iter()
            .flat_map(|s| &s.figures)
            .any(|f| f.title.contains("over position") && f.y_unit == "m/s²"),
        "an accelerometer's spectrum drawn over position"
    );
}

/// Accelerometers, resonance: a 30 Hz column mode (ζ = 0.02: the first bending mode of a tall
/// column; inside the guideway's band, which reaches 48 Hz at 0.2 m/s, see [`guideway_scenario`])
/// excited by the random guideway; the model knows the straightness (given) and has nothing for
/// the mode. Over five noise seeds diagnose ranks `resonance` first and significant, at a frequency
/// inside the mode's half-power band (30 ± ζ·30 Hz), and after `add --from-diagnosis` the normalised RMS is
/// at the noise level: phase 3 predicts the mode as the forced response to the predicted base
/// acceleration (module doc). Then the complete model (straightness + resonance) leaves nothing
/// significant.
#[test]
fn accelerometer_hidden_resonance_is_found_at_its_frequency() {
    let sc = guideway_scenario("[truth.effects.resonance]\nfrequency = 30.0\ndamping = 0.02\n");
    let model = known_truth(&sc, &[EffectName::Resonance]);
    let data = Path::new("sim");
    let seeds = [1u64, 2, 3, 4, 5];
    let sets = sets(&sc, &seeds);
    let mut complete: Option<Model> = None;
    for (seed, set) in seeds.iter().zip(&sets) {
        let label = format!("hidden resonance, seed {seed}");
        let t0 = std::time::Instant::now();
        let d = diagnose(&model, set, data).unwrap();
        let first = &d.ranking[0];
        assert_eq!(first.effect, EffectName::Resonance, "{label}: {:#?}", d.ranking);
        assert_eq!(first.verdict, Verdict::Significant, "{label}: {first:?}");
        let m1 = add_effect(&model, EffectName::Resonance, Some(first)).unwrap();
        let c = compare(&m1, set, data).unwrap();
        let fitted = &c.fitted[EffectName::Resonance];
        let (f, f1, z1, g1) = (first.params["frequency"], fitted["frequency"], fitted["damping"], fitted["gain_acc"]);
        eprintln!(
            "{label}: frequency {f:.3} Hz (after add {f1:.3} Hz, ζ {z1:.4}, gain {g1:.4}), normalised RMS {:.2} → \
             {:.3} ({:.1} s)",
            d.normalized_rms,
            c.normalized_rms,
            t0.elapsed().as_secs_f64()
        );
        // Inside the half-power band, 2ζf = 1.2 Hz wide (measured 29.995–30.003 Hz).
        assert!((f - 30.0).abs() < 0.02 * 30.0 && (f1 - 30.0).abs() < 0.02 * 30.0, "{label}: {f} {f1}");
        // The damping sets the peak gain 1/(2ζ) of the forced response: 10 % (measured 0.0197–0.0198).
        assert!((z1 - 0.02).abs() < 0.002, "{label}: ζ {z1}");
        // The gain is the mode shape at the sensor, φ = z/h: mp3 sits 1.20 m above the slide's
        // reference point, the column's top link (head) 1.32 m (slide_column.urdf). 2 % for the
        // carriage's quasi-static following error at the mode, (30/320)² ≈ 1 % (measured 0.908–0.911).
        assert!((g1 - 1.20 / 1.32).abs() < 0.02 * 1.20 / 1.32, "{label}: gain {g1}");
        assert!(c.normalized_rms <= NOISE_LEVEL_NRMS, "{label}: {}", c.normalized_rms);
        assert!(c.normalized_rms < d.normalized_rms, "{label}");
        complete.get_or_insert(m1);
    }
    // The complete model: nothing significant left (two seeds; the 20-seed false-alarm test covers
    // the threshold itself).
    let m1 = complete.unwrap();
    for (seed, set) in seeds.iter().zip(&sets).take(2) {
        let d = diagnose(&m1, set, data).unwrap();
        let sig: Vec<&str> =
            d.ranking.iter().filter(|r| r.verdict != Verdict::Noise).map(|r| r.effect.as_str()).collect();
        eprintln!(
            "complete model, seed {seed}: normalised RMS {:.3}, best ΔBIC {:.1}",
            d.normalized_rms, d.ranking[0].delta_bic
        );
        assert!(sig.is_empty(), "seed {seed}: {:#?}", d.ranking);
        assert!(d.normalized_rms <= NOISE_LEVEL_NRMS);
    }
}

/// Accelerometers, gravity through tilt: a roll EAX(x) = 20 µrad·sin(2πx/0.5 m) tilts a
/// y-sensitive accelerometer on the axis line (no Abbe offset, so the roll moves it by nothing and
/// only g·EAX ≈ 0.2 mm/s² shows), at 0.1, 0.2 and 0.4 m/s; the model has nothing for it. Diagnose
/// must rank `gravity_tilt` first and significant, and adding it must lower the normalised RMS.
#[test]
fn accelerometer_hidden_gravity_tilt_is_found() {
    let truth = "[truth.effects.roll]\nharmonics = [{ amplitude = 20e-6, wavelength = 0.5, phase = 0.3 }]\n";
    let text = accel_scenario(truth, "position = [0.0, 0.0, 0.0]", "[0.0, 1.0, 0.0]", 1e-4, "[0.1, 0.2, 0.4]", 300.0);
    let sc = Scenario::parse(&text, Path::new("gravity.toml"), None).unwrap();
    let model = model_fitting(&[]);
    for (seed, set) in [1u64, 2, 3, 4, 5].iter().zip(sets(&sc, &[1, 2, 3, 4, 5])) {
        let label = format!("hidden gravity_tilt, seed {seed}");
        let d = diagnose(&model, &set, Path::new("sim")).unwrap();
        eprintln!("{label}: {:?}", d.ranking.iter().map(|r| (&r.effect, r.delta_bic)).collect::<Vec<_>>());
        let (before, after, m1) = step(&model, &set, EffectName::GravityTilt, &label);
        // The fitted tilt of the y accelerometer is the roll EAX (reading g·EAX to first order), up
        // to a constant (the offsets carry it): compared relative to x = 0.5 m over the range.
        let f = &compare(&m1, &set, Path::new("sim")).unwrap().fitted[EffectName::GravityTilt];
        let c: Vec<f64> = (1..).map_while(|k| f.get(&format!("tilt_acc_c{k}")).copied()).collect();
        let tau = |x: f64| c.iter().zip(1..).map(|(ck, k)| ck * x.powi(k)).sum::<f64>();
        let roll = |x: f64| 20e-6 * (std::f64::consts::TAU * x / 0.5 + 0.3).sin();
        let err = (0..=40)
            .map(|i| 0.3 + 0.01 * i as f64)
            .map(|x| ((tau(x) - tau(0.5)) - (roll(x) - roll(0.5))).abs())
            .fold(0.0, f64::max);
        eprintln!("{label}: normalised RMS {before:.2} → {after:.3}; tilt error {:.2} µrad", err * 1e6);
        assert!(after < before, "{label}");
        // No guideway acceleration reaches this sensor (no straightness, no offset from the roll
        // axis), so after the add the residual is the 0.1 mm/s² noise: the noise-level bound.
        assert!(after <= NOISE_LEVEL_NRMS, "{label}: {after}");
        // The tilt's degree is chosen by BIC (at least the cubic's freedom where the data ask for
        // it): the best cubic through the true roll (least squares on the same grid, relative to
        // x = 0.5 m) misses it by `floor`; the fit may add 1 µrad (5 % of the roll) for the noise
        // (0.1 mm/s² per sample ≈ 10 µrad, averaged over 900 samples).
        let floor = cubic_misfit(&|x| roll(x) - roll(0.5));
        eprintln!("{label}: best-cubic floor {:.2} µrad", floor * 1e6);
        assert!(err < floor + 1e-6, "{label}: {err} (floor {floor})");
    }
}

/// Max |f(x) − p(x)| over x = 0.3, 0.31, …, 0.7 m of the least-squares cubic p through f on that
/// grid with p(0.5) = f(0.5) (normal equations in u = x − 0.5, Gaussian elimination).
fn cubic_misfit(f: &dyn Fn(f64) -> f64) -> f64 {
    let xs: Vec<f64> = (0..=40).map(|i| 0.3 + 0.01 * i as f64).collect();
    let mut a = [[0.0f64; 4]; 3];
    for &x in &xs {
        let u = x - 0.5;
        let row = [u, u * u, u * u * u];
        let y = f(x) - f(0.5);
        for i in 0..3 {
            for j in 0..3 {
                a[i][j] += row[i] * row[j];
            }
            a[i][3] += row[i] * y;
        }
    }
    for k in 0..3 {
        for i in k + 1..3 {
            let m = a[i][k] / a[k][k];
            for j in k..4 {
                a[i][j] -= m * a[k][j];
            }
        }
    }
    let mut c = [0.0f64; 3];
    for i in (0..3).rev() {
        c[i] = (a[i][3] - (i + 1..3).map(|j| a[i][j] * c[j]).sum::<f64>()) / a[i][i];
    }
    xs.iter()
        .map(|&x| {
            let u = x - 0.5;
            ((f(x) - f(0.5)) - (c[0] * u + c[1] * u * u + c[2] * u * u * u)).abs()
        })
        .fold(0.0, f64::max)
}

/// The rack-and-pinion move of `realdata/friction_rack_pinion` (one trapezoidal move, 0.15 m,
/// ±3 m/s², peak 0.65 m/s; no constant-velocity part worth the name: ≈ 15 ms at the peak) turned
/// into a friction sweep (FORMAT.md §1, `friction_sweep` runs) for the model-check loop:
/// - the README's processing ([`realdata::rack_pinion`]), then force and velocity through the same
///   30 Hz Butterworth low-pass, zero-phase (no lag between them), a = dv/dt, friction F − m·a with
///   m = 24.7 kg (README);
/// - one sample every 1/(2·30 Hz) ≈ 17 ms (25 servo samples): the filter's bandwidth leaves about
///   that many independent values, so the loop does not count correlated samples as evidence;
/// - only while moving (v > 2 mm/s, 6 servo speed quanta), acceleration and deceleration phases;
/// - the deceleration passes the velocities of the acceleration phase again: each decelerating
///   sample is paired with the accelerating sample nearest in velocity (within 10 mm/s) into one
///   run at their mean velocity (`feed`); unpaired samples are runs of their own;
/// - σ of one value from those repeats, σ² = Σ(F_acc − F_dec)²/(2·pairs), stated in the manifest.
///
/// Returns the pairs and σ (N). One direction only: a Coulomb level is a constant force there, the
/// same column as the force channel's offset, so the loop cannot see it (said in the table).
fn rack_pinion_sweep(d: &realdata::RackPinion, dir: &Path) -> (usize, f64) {
    use vmt_estimators::friction_id::{friction_from_motion, FilterMode};
    let mf = friction_from_motion(&d.v_raw, &d.force_raw, 24.7, d.dt, Some(30.0), FilterMode::ZeroPhase).unwrap();
    let stride = (1.0 / (2.0 * 30.0 * d.dt)).round() as usize;
    let mut x = vec![0.0; mf.v.len()];
    for i in 1..x.len() {
        x[i] = x[i - 1] + 0.5 * (mf.v[i] + mf.v[i - 1]) * d.dt;
    }
    let peak = mf.v.iter().enumerate().fold((0, f64::MIN), |b, (i, &v)| if v > b.1 { (i, v) } else { b }).0;
    let moving: Vec<usize> = (0..mf.v.len()).step_by(stride).filter(|&i| mf.v[i] > 2e-3).collect();
    let (acc, dec): (Vec<usize>, Vec<usize>) = moving.iter().partition(|&&i| i <= peak);
    let mut used = vec![false; acc.len()];
    let mut runs: Vec<Vec<usize>> = Vec::new();
    let mut pairs = Vec::new();
    for &j in &dec {
        let near = (0..acc.len())
            .filter(|&k| !used[k])
            .min_by(|a, b| (mf.v[acc[*a]] - mf.v[j]).abs().total_cmp(&(mf.v[acc[*b]] - mf.v[j]).abs()));
        match near.filter(|&k| (mf.v[acc[k]] - mf.v[j]).abs() < 10e-3) {
            Some(k) => {
                used[k] = true;
                pairs.push(mf.friction[acc[k]] - mf.friction[j]);
                runs.push(vec![acc[k], j]);
            }
            None => runs.push(vec![j]),
        }
    }
    runs.extend((0..acc.len()).filter(|k| !used[*k]).map(|k| vec![acc[k]]));
    runs.sort_by(|a, b| mf.v[a[0]].total_cmp(&mf.v[b[0]]));
    let sigma = (pairs.iter().map(|p| p * p).sum::<f64>() / (2.0 * pairs.len() as f64)).sqrt();
    let mut manifest = format!(
        "format = \"vmt-measurements/1\"\ndescription = \"rack-and-pinion move (K. Mnich) as a friction sweep\"\n\n\
         [[sensors]]\nname = \"force\"\nkind = \"motor_force\"\naxis = \"x\"\nsigma = {sigma:e}\n"
    );
    std::fs::create_dir_all(dir).unwrap();
    for (k, run) in runs.iter().enumerate() {
        let feed = run.iter().map(|&i| mf.v[i]).sum::<f64>() / run.len() as f64;
        let name = format!("v{k:02}");
        let mut csv = String::from("t[s],x_cmd[mm],force[N]\n");
        for &i in run {
            csv += &format!("{:.5},{:.4},{:.4}\n", d.t[i], x[i] * 1e3, mf.friction[i]);
        }
        std::fs::write(dir.join(format!("{name}.csv")), csv).unwrap();
        manifest += &format!(
            "\n[[runs]]\nname = \"{name}\"\nfile = \"{name}.csv\"\nprocedure = \"friction_sweep\"\naxis = \"x\"\n\
             start_time = {:.5}\nfeed = {feed:e}\ndirection = 1\n",
            d.t[run[0]]
        );
    }
    std::fs::write(dir.join("manifest.toml"), manifest).unwrap();
    (pairs.len(), sigma)
}

/// Real data, issue 11: the model-check loop on the rack-and-pinion friction sweep
/// ([`rack_pinion_sweep`]) from an empty model (the force offset only): diagnose, add the first
/// significant effect, up to 4 times. Asserted: every step lowers the residual; no periodic claim;
/// viscous friction is found (≈ 67 N·s/m published, 37 N over the 0.55 m/s window, ≈ 9 σ per
/// sample) with fv within 40–100 N·s/m (the sanity band of the friction-identification tests on
/// the same file: the published value depends on the window and law). Prints the table row.
#[test]
fn real_rack_pinion_sweep_loop() {
    let Some(d) = realdata::rack_pinion("real_rack_pinion_sweep_loop") else { return };
    let tmp = tempfile::tempdir().unwrap();
    let (pairs, sigma) = rack_pinion_sweep(&d, tmp.path());
    let set = vmt::measurement::read(tmp.path()).unwrap();
    let path = tmp.path().join("manifest.toml");
    let mut model = model_fitting(&[]);
    let c0 = compare(&model, &set, &path).unwrap();
    let mut rms = c0.channels.iter().map(|c| c.rms.powi(2)).sum::<f64>();
    let mut steps = vec![format!(
        "{} runs, σ from {pairs} accel/decel repeats {sigma:.2} N; start nrms {:.2}",
        set.runs.len(),
        c0.normalized_rms
    )];
    let mut added = Vec::new();
    for _ in 0..4 {
        let d = diagnose(&model, &set, &path).unwrap();
        for r in d.ranking.iter().filter(|r| r.verdict != Verdict::Noise) {
            assert!(!r.params.contains_key("period"), "a periodic claim on a friction sweep: {r:?}");
        }
        let claims: Vec<String> = d
            .ranking
            .iter()
            .filter(|r| r.verdict != Verdict::Noise)
            .map(|r| format!("{} {:?} ΔBIC {:.0}", r.effect, r.verdict, r.delta_bic))
            .collect();
        steps.push(format!("claims [{}]", claims.join("; ")));
        let Some(best) = d.ranking.iter().find(|r| r.verdict == Verdict::Significant) else { break };
        let name: EffectName = best.effect;
        model = add_effect(&model, name, Some(best)).unwrap();
        let c = compare(&model, &set, &path).unwrap();
        let now = c.channels.iter().map(|c| c.rms.powi(2)).sum::<f64>();
        steps.push(format!("+ {name}: nrms {:.2}", c.normalized_rms));
        assert!(now < rms, "{steps:?}");
        rms = now;
        added.push((name, c));
    }
    eprintln!("rack-and-pinion: {}", steps.join(" → "));
    let viscous = added.iter().find(|(n, _)| *n == EffectName::Viscous);
    assert!(viscous.is_some(), "viscous friction not found: {steps:?}");
    let fv = added.last().and_then(|(_, c)| c.fitted.get(EffectName::Viscous)?.get("fv").copied());
    eprintln!("final fv {fv:?} N·s/m");
    assert!(fv.is_some_and(|f| f > 40.0 && f < 100.0), "fv {fv:?}: {steps:?}");
}

/// A ranking entry carries its names as types (the effect, those it is confused with, the
/// hyper-parameters at a bound, the shapes' orders) and writes them as the files always had them:
/// the same keys and names, `shape_orders` in the order of the names (pitch before roll, though
/// the catalogue has roll first); and it reads back to the same entry.
#[test]
fn ranking_entry_writes_names() {
    use vmt::modelcheck::{Hyper, RankedEffect};
    let e = RankedEffect {
        effect: EffectName::CyclicLead,
        delta_bic: -12.5,
        explained: 0.25,
        verdict: Verdict::Inseparable,
        params: [("period".to_string(), 0.01)].into_iter().collect(),
        confused_with: vec![EffectName::Roll, EffectName::Pitch],
        note: None,
        aliases: vec![],
        p_value: Some(1e-4),
        searched: Some(40),
        at_bound: vec![Hyper::Period, Hyper::Vs],
        shape_orders: [(EffectName::Roll, 3), (EffectName::Pitch, 2)].into_iter().collect(),
    };
    let json = serde_json::to_string(&e).unwrap();
    assert_eq!(
        json,
        "{\"effect\":\"cyclic_lead\",\"delta_bic\":-12.5,\"explained\":0.25,\"verdict\":\"inseparable\",\
         \"params\":{\"period\":0.01},\"confused_with\":[\"roll\",\"pitch\"],\"p_value\":0.0001,\"searched\":40,\
         \"at_bound\":[\"period\",\"vs\"],\"shape_orders\":{\"pitch\":2,\"roll\":3}}"
    );
    assert_eq!(serde_json::from_str::<RankedEffect>(&json).unwrap(), e);
    for h in Hyper::ALL {
        assert_eq!(serde_json::to_string(&h).unwrap(), format!("\"{}\"", h.as_str()));
        assert_eq!(Hyper::named(h.as_str()), Some(h));
    }
}
