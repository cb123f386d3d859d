//! Squareness of a 3-axis machine (issue 3): scenarios/squareness_3axis.toml simulated through the chain
//! of rapier axes (vmt_sim::chain) and identified by laser_ls from the seed-001 laser line set.
//! The physics is simulated once per truth; the laser noise is redrawn per seed.

use crate::util::{root, vmt};
use std::path::PathBuf;
use vmt::measurement::{self, UnitChoice};
use vmt::scenario::Scenario;
use vmt::simulate::{chain_truths, read_chain};
use vmt::simulate::{to_measurement_set, truth_extras};
use vmt::workflow::run::identify_chain_lines;
use vmt_sim::chain::{LineTruth, SquarenessAngles};
use vmt_sim::procedures::RunData;
use vmt_sim::Axis;

/// `vmt simulate`'s output for the scenario: the set is written with truth.toml (carrying the three
/// squareness values) and truth_profiles.csv (x., y., z. columns), and reads back unchanged.
fn written_set_reads_back(sc: &Scenario, truths: &[(usize, LineTruth)]) {
    let runs = read_chain(sc, truths, sc.seed);
    let set = to_measurement_set(sc, &runs).unwrap();
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("set");
    measurement::write_with_extras(
        &set,
        &out,
        UnitChoice::Si,
        &truth_extras(sc, &vmt::simulate::physics(sc).unwrap(), UnitChoice::Si).unwrap(),
    )
    .unwrap();
    let back = measurement::read(&out).unwrap();
    assert_eq!(back.runs.len(), 16);
    let fxy = back.runs.iter().find(|r| r.name == "lines_fxy").unwrap();
    assert_eq!(fxy.axis, Axis::X);
    let RunData::PointTable { target, .. } = &fxy.data else { panic!("fxy is not a point table") };
    // 6 stops every 100 mm of x and y: the line coordinate of the last is 0.5·√2 m.
    assert_eq!(target.len(), 6);
    assert!((target[5] - 0.5 * 2f64.sqrt()).abs() < 1e-12);
    let orig = runs.iter().find(|r| r.name == "lines_fxy").unwrap();
    // Round trip of the laser column: the CSV prints the shortest round-trip digits.
    assert_eq!(fxy.data.column("fxy"), orig.data.column("fxy"));
    let laser = back.sensor("fxy").unwrap();
    assert!((laser.direction[0] - 0.5f64.sqrt()).abs() < 1e-15 && laser.axis == Axis::Z);
    let truth = std::fs::read_to_string(out.join("truth.toml")).unwrap();
    for v in [
        "[effects.squareness_xy]\nvalue = 2e-5",
        "[effects.squareness_xz]\nvalue = -1.5e-5",
        "[effects.squareness_yz]\nvalue = 1e-5",
    ] {
        assert!(truth.contains(v), "truth.toml lacks {v:?}:\n{truth}");
    }
    let profiles = measurement::read_profiles(&out.join("truth_profiles.csv")).unwrap();
    let names: Vec<String> = profiles.columns.iter().map(|c| c.column_name()).collect();
    assert!(names.contains(&"y.pitch".to_string()) && names.contains(&"z.yaw".to_string()), "{names:?}");
    // `vmt identify` on the written set alone (no scenario: geometry from the manifest and the x_cmd,
    // y_cmd, z_cmd columns) gives the scenario path's squareness, to the digits the CSV carries.
    let (n_lines, from_set) = vmt::byo::identify_axes_set(&back).unwrap().expect("a multi-axis line set");
    let from_scenario = identify_chain_lines(sc, &runs, "lines").unwrap();
    assert_eq!(n_lines, 16);
    for name in ["squareness_xy", "squareness_xz", "squareness_yz"] {
        let a = from_set.identification.squareness(name).unwrap();
        let b = from_scenario.identification.squareness(name).unwrap();
        // 1e-12 rad: the CSV round trip is exact; what is left is summation order in the solver.
        assert!((a.value - b.value).abs() < 1e-12 && a.std_error.is_some(), "{name}: {} vs {}", a.value, b.value);
    }
    let out = vmt().arg("identify").arg(dir.path().join("set")).output().unwrap();
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(out.status.success() && text.contains("EC0Y squareness_xy"), "{text}");
}

fn scenario_path() -> PathBuf {
    root().join("scenarios/squareness_3axis.toml")
}

fn scenario_text() -> String {
    std::fs::read_to_string(scenario_path()).unwrap()
}

/// The scenario's text with the three `[truth.effects.squareness_*]` tables removed.
fn without_squareness(text: &str) -> String {
    let mut out = Vec::new();
    let mut skip = false;
    for line in text.lines() {
        if line.starts_with("[truth.effects.squareness_") {
            skip = true;
            continue;
        }
        if skip && line.starts_with("value") {
            skip = false;
            continue;
        }
        out.push(line);
    }
    out.join("\n")
}

/// The scenario's text with no effect at all in the truth (a perfect machine).
fn perfect(text: &str) -> String {
    let start = text.find("[truth.effects.").unwrap();
    let end = text.find("# The laser line set").unwrap();
    format!("{}{}", &text[..start], &text[end..])
}

const K_SIGMA: f64 = 4.0;
/// Bias bound of the simulated composition: ≤ 3 nm over 0.5 m lines (sim/tests/chain.rs) ≈ 6 nrad.
const BIAS: f64 = 1e-8;

/// Recovered squareness [EC0Y, EB0Z, EA0Z] with 1σ, and the effective injected values, per seed.
/// Recovered squareness angles [EC0Y, EB0Z, EA0Z] and their standard errors, rad.
type AnglesAndErrors = ([f64; 3], [f64; 3]);

fn recover(sc: &Scenario, truths: &[(usize, LineTruth)], seeds: &[u64]) -> (Vec<AnglesAndErrors>, SquarenessAngles) {
    let mut out = Vec::new();
    let mut eff = SquarenessAngles::default();
    for &seed in seeds {
        let runs = read_chain(sc, truths, seed);
        let ci = identify_chain_lines(sc, &runs, "lines").unwrap();
        eff = sc.chain.as_ref().unwrap().effective_squareness(&ci.positions);
        let id = &ci.identification;
        println!(
            "seed {seed}: {} readings, rank {} of {} parameters, condition {:.3e}, variance factor {:.2}; \
             not observable: {}",
            id.n_readings,
            id.rank,
            id.params.len(),
            id.condition,
            id.variance_factor,
            id.unobservable.join("; ")
        );
        let mut v = [0.0; 3];
        let mut s = [0.0; 3];
        for (k, name) in ["EC0Y", "EB0Z", "EA0Z"].iter().enumerate() {
            let e = ci.identification.squareness(name).unwrap();
            v[k] = e.value;
            s[k] = e.std_error.expect("observable");
        }
        out.push((v, s));
    }
    (out, eff)
}

#[test]
fn squareness_is_recovered_over_three_seeds_and_vanishes_without_it() {
    let text = scenario_text();
    let sc = Scenario::parse(&text, &scenario_path(), scenario_path().parent()).unwrap();
    let raw = sc.chain.as_ref().unwrap().squareness.to_array();
    assert_eq!(raw, [20e-6, -15e-6, 10e-6]);
    let seeds = [1, 2, 3];
    let truths = chain_truths(&sc, 0.0);
    let (with, eff) = recover(&sc, &truths, &seeds);
    written_set_reads_back(&sc, &truths);
    let sc0 = Scenario::parse(&without_squareness(&text), &scenario_path(), scenario_path().parent()).unwrap();
    assert_eq!(sc0.chain.as_ref().unwrap().squareness.to_array(), [0.0; 3]);
    let (without, eff0) = recover(&sc0, &chain_truths(&sc0, 0.0), &seeds);
    // The lines see the injected angle plus the trend of the error motions (the same in both truths):
    // the difference of the effective values is the injected value (exact: both are linear in it).
    for ((e, e0), r) in eff.to_array().iter().zip(eff0.to_array()).zip(raw) {
        let d = e - e0;
        assert!((d - r).abs() < 1e-12, "effective difference {d:e} vs injected {r:e}");
    }
    for (i, seed) in seeds.iter().enumerate() {
        for (k, name) in ["EC0Y", "EB0Z", "EA0Z"].iter().enumerate() {
            let (v, s) = (with[i].0[k], with[i].1[k]);
            let (v0, s0) = (without[i].0[k], without[i].1[k]);
            println!(
                "seed {seed} {name}: injected {:+.3} µrad (effective {:+.3}), recovered {:+.3} ± {:.3} µrad; \
                 without squareness: effective {:+.3}, recovered {:+.3} ± {:.3}; difference {:+.3} µrad",
                raw[k] * 1e6,
                eff.to_array()[k] * 1e6,
                v * 1e6,
                s * 1e6,
                eff0.to_array()[k] * 1e6,
                v0 * 1e6,
                s0 * 1e6,
                (v - v0) * 1e6
            );
            // Tolerance K_SIGMA·σ + BIAS (σ from the identifier with the lines' 0.1 µm noise ≈ 0.4–0.6 µrad).
            assert!((v - eff.to_array()[k]).abs() <= K_SIGMA * s + BIAS, "seed {seed} {name}: {v:e} ± {s:e}");
            assert!((v0 - eff0.to_array()[k]).abs() <= K_SIGMA * s0 + BIAS, "seed {seed} {name} without");
            // The same noise realisation (same seed) reads both machines: the difference of the two
            // estimates recovers the injected angle almost free of noise; the design is the same, so the
            // noise cancels exactly and only the physics' bias remains (≤ 2·BIAS).
            assert!(((v - v0) - raw[k]).abs() <= 2.0 * BIAS, "seed {seed} {name}: difference {:e}", v - v0);
        }
    }
}

#[test]
fn a_perfect_machine_has_squareness_within_noise_of_zero() {
    let text = perfect(&scenario_text());
    let sc = Scenario::parse(&text, &scenario_path(), scenario_path().parent()).unwrap();
    let (est, eff) = recover(&sc, &chain_truths(&sc, 0.0), &[7, 8]);
    assert_eq!(eff.to_array(), [0.0; 3]);
    for (v, s) in est {
        for k in 0..3 {
            println!("perfect machine: recovered {:+.3} ± {:.3} µrad", v[k] * 1e6, s[k] * 1e6);
            // K_SIGMA·σ + BIAS (noise of 0.1 µm per reading; the bearings' sag is a constant offset that
            // the lines' zeros absorb: the merged masses sit centred over their blocks).
            assert!(v[k].abs() <= K_SIGMA * s[k] + BIAS, "{:e} ± {:e}", v[k], s[k]);
        }
    }
}

#[test]
fn bad_multi_axis_input_is_refused_with_the_place() {
    let text = scenario_text();
    let parse = |t: &str| Scenario::parse(t, &scenario_path(), scenario_path().parent()).unwrap_err();
    // unknown axis letter
    let e = parse(&text.replace("axes = [\"x\", \"y\", \"z\"]", "axes = [\"x\", \"w\", \"z\"]"));
    assert_eq!(e.exit_code(), 2);
    let m = e.to_string();
    assert!(m.contains("squareness_3axis.toml") && m.contains("axes[1]") && m.contains("unknown axis `w`"), "{m}");
    // an effect on an axis outside the chain
    let e = parse(&text.replace("axes = [\"x\", \"y\", \"z\"]", "axes = [\"x\", \"y\"]"));
    let m = e.to_string();
    assert!(m.contains("truth.effects.") && m.contains("effect on axis z, which is not in the chain"), "{m}");
    // squareness on a single-axis scenario
    let single = text.replace("axes = [\"x\", \"y\", \"z\"]\n", "").replace("tool = \"tool\"", "");
    let single = single[..single.find("[[chain_procedures]]").unwrap()].to_string();
    let e = parse(&single);
    assert_eq!(e.exit_code(), 2);
    let m = e.to_string();
    assert!(m.contains("truth.effects.squareness_") && m.contains("multi-axis"), "{m}");
    // a line outside the travel (Z travel 0..0.5 m)
    let e = parse(&text.replace("to = [0.0, 0.0, 0.5], n = 6 }", "to = [0.0, 0.0, 0.7], n = 6 }"));
    assert_eq!(e.exit_code(), 2);
    let m = e.to_string();
    assert!(m.contains("chain_procedures[0] (lines).lines[2] (l3_z).to") && m.contains("outside the travel"), "{m}");
    // a NaN in a line
    let e = parse(&text.replace("to = [0.5, 0.0, 0.0], n = 6 }", "to = [nan, 0.0, 0.0], n = 6 }"));
    assert_eq!(e.exit_code(), 2);
    // wrong number of joint positions
    let e = parse(&text.replace("to = [0.5, 0.0, 0.0], n = 6 }", "to = [0.5, 0.0], n = 6 }"));
    assert!(e.to_string().contains("expected 3 joint positions"), "{e}");
}
