//! Issue 17, "the same discipline for every estimator command": `iso230-2`, `identify`, `compensate`,
//! `ssi`, `friction` and `straightness` each print the uncertainty beside every estimate, refuse input
//! they cannot use with the file and the place named, and have a docs/methods.md entry giving the method,
//! its source, its assumptions and what it cannot see. The sets here are written by hand (not by vmt's
//! simulator), with their true values known in closed form.

use crate::util::{root, vmt};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, StandardNormal};
use std::path::{Path, PathBuf};

/// The estimator commands and what each must say about its uncertainty.
const COMMANDS: [&str; 6] = ["iso230-2", "identify", "compensate", "ssi", "friction", "straightness"];

/// docs/methods.md: every estimator command has a row in the table (with a source) whose linked sections
/// hold together an **Uncertainty.** paragraph, its assumptions and what it cannot see.
#[test]
fn every_estimator_command_has_a_method_entry_with_uncertainty_assumptions_and_blind_spots() {
    let doc = std::fs::read_to_string(root().join("docs/methods.md")).unwrap();
    // Sections by their GitHub anchor: lower case, punctuation dropped, spaces to hyphens.
    let anchor = |title: &str| -> String {
        title
            .to_lowercase()
            .chars()
            .filter(|c| c.is_alphanumeric() || *c == ' ' || *c == '-')
            .map(|c| if c == ' ' { '-' } else { c })
            .collect()
    };
    let mut sections: Vec<(String, String)> = Vec::new();
    for part in doc.split("\n## ").skip(1) {
        let (title, body) = part.split_once('\n').unwrap_or((part, ""));
        sections.push((anchor(title.trim()), body.to_string()));
    }
    for cmd in COMMANDS {
        let key = format!("`vmt {cmd}`");
        let row = doc
            .lines()
            .find(|l| l.starts_with('|') && l.split('|').nth(1).is_some_and(|c| c.contains(&key)))
            .unwrap_or_else(|| panic!("docs/methods.md: no table row for {key}"));
        let cells: Vec<&str> = row.split('|').map(str::trim).collect();
        assert!(cells.len() >= 4 && cells[3].len() > 3, "{key}: the row names no source: {row}");
        let mut text = String::new();
        for link in row.split("](#").skip(1) {
            let a = link.split(')').next().unwrap();
            let (_, body) = sections
                .iter()
                .find(|(s, _)| s == a)
                .unwrap_or_else(|| panic!("{key}: link #{a} to no section of docs/methods.md"));
            text += body;
        }
        for (what, needle) in
            [("uncertainty", "**Uncertainty.**"), ("assumptions", "ssumptions"), ("what it cannot see", "cannot see")]
        {
            assert!(text.contains(needle), "docs/methods.md: the entry of {key} has no {what} (`{needle}`)");
        }
    }
}

fn run(args: &[&str]) -> (Option<i32>, String, String) {
    let out = vmt().args(args).output().unwrap();
    (
        out.status.code(),
        String::from_utf8_lossy(&out.stdout).into_owned(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

/// A crawl set written by hand: one encoder, one crawl run sampled every `dt` at positions `x`.
fn crawl_set(dir: &Path, dt: f64, x: &[f64], feed: f64) -> PathBuf {
    std::fs::create_dir_all(dir).unwrap();
    let manifest = format!(
        "format = \"vmt-measurements/1\"\n[[sensors]]\nname = \"scale\"\nkind = \"encoder_linear\"\naxis = \"x\"\n\
         [[runs]]\nname = \"crawl\"\nfile = \"crawl.csv\"\nprocedure = \"crawl\"\naxis = \"x\"\nfeed = {feed:e}\ndirection = 1\n"
    );
    std::fs::write(dir.join("manifest.toml"), manifest).unwrap();
    let mut csv = String::from("t,scale\n");
    for (i, v) in x.iter().enumerate() {
        csv += &format!("{:e},{v:e}\n", i as f64 * dt);
    }
    std::fs::write(dir.join("crawl.csv"), csv).unwrap();
    dir.to_path_buf()
}

/// `vmt ssi` states the index's quantisation floor 2q/(Δt·v̄) beside it, with the encoder count q read
/// from the record (nobody states it in a measurement set): over 20 random crawls (q 1–100 nm with a random
/// zero, ripple 0–90 % at 0.5–20 Hz, 0.5–5 kHz, 1–100 mm/min) the count found equals q to 1e-6 and the
/// floor is the formula's; with noise of a tenth of a count on the positions there is no lattice and the
/// output says the floor is not known instead of printing a number.
#[test]
fn ssi_states_its_quantisation_floor_with_the_count_read_from_the_record() {
    let tmp = tempfile::tempdir().unwrap();
    for draw in 0..20u64 {
        let mut rng = ChaCha8Rng::seed_from_u64(4200 + draw);
        let lu = |rng: &mut ChaCha8Rng, lo: f64, hi: f64| rng.gen_range(f64::ln(lo)..f64::ln(hi)).exp();
        let q = lu(&mut rng, 1e-9, 1e-7);
        let zero = rng.gen_range(0.0..q);
        let v0 = lu(&mut rng, 1e-3, 0.1) / 60.0;
        let (r, f, phi) = (rng.gen_range(0.0..0.9), lu(&mut rng, 0.5, 20.0), rng.gen_range(0.0..6.0));
        let dt = 1.0 / lu(&mut rng, 500.0, 5000.0);
        let w = 2.0 * std::f64::consts::PI * f;
        let exact: Vec<f64> =
            (0..4000).map(|i| i as f64 * dt).map(|t| v0 * (t - r / w * ((w * t + phi).cos() - phi.cos()))).collect();
        let counts: Vec<f64> = exact.iter().map(|x| ((x + zero) / q).floor() * q).collect();
        let dir = crawl_set(&tmp.path().join(format!("q{draw}")), dt, &counts, v0);
        let (code, out, err) = run(&["ssi", dir.to_str().unwrap(), "--json"]);
        assert_eq!(code, Some(0), "{err}");
        let v: serde_json::Value = serde_json::from_str(&out).unwrap();
        let e = &v["runs"][0];
        let found = e["resolution"].as_f64().unwrap_or_else(|| panic!("draw {draw}: no count found: {e}"));
        assert!((found / q - 1.0).abs() < 1e-6, "draw {draw}: count {found:e} m, true {q:e} m");
        let n = counts.len();
        let mean = (counts[n - 1] - counts[0]) / ((n - 1) as f64 * dt);
        let floor = 2.0 * found / (dt * mean);
        let stated = e["quantisation_floor"].as_f64().unwrap();
        assert!((stated / floor - 1.0).abs() < 1e-9, "draw {draw}: floor {stated} against 2q/(Δt·v̄) = {floor}");
        // The exact motion's index is within the floor (the floor's meaning).
        let s_exact = {
            let s: Vec<f64> = exact.windows(2).map(|p| (p[1] - p[0]) / dt).collect();
            let m = (exact[n - 1] - exact[0]) / ((n - 1) as f64 * dt);
            (s.iter().cloned().fold(f64::MIN, f64::max) - s.iter().cloned().fold(f64::MAX, f64::min)) / m
        };
        let ssi = e["ssi"].as_f64().unwrap();
        let rounding = 2.0 * q / ((n - 1) as f64 * dt * mean) * ssi;
        assert!((ssi - s_exact).abs() <= stated + rounding, "draw {draw}: |{ssi} − {s_exact}| > floor {stated}");
        if draw == 0 {
            let (_, text, _) = run(&["ssi", dir.to_str().unwrap()]);
            assert!(text.contains("floor") && text.contains(&format!("{stated:.3}")), "{text}");
        }
        // Noise finer than a count: no lattice, no floor, and said so.
        let noisy: Vec<f64> = counts
            .iter()
            .map(|x| {
                let z: f64 = StandardNormal.sample(&mut rng);
                x + 0.1 * q * z
            })
            .collect();
        let dir = crawl_set(&tmp.path().join(format!("noisy{draw}")), dt, &noisy, v0);
        let (code, out, err) = run(&["ssi", dir.to_str().unwrap(), "--json"]);
        assert_eq!(code, Some(0), "{err}");
        let v: serde_json::Value = serde_json::from_str(&out).unwrap();
        let e = &v["runs"][0];
        assert!(e["resolution"].is_null() && e["quantisation_floor"].is_null(), "draw {draw}: {e}");
        assert!(e["resolution_source"].as_str().unwrap().starts_with("not found"), "{e}");
    }
}

/// `vmt friction` prints a standard error beside every Stribeck coefficient, and refuses a sweep point it
/// cannot place (no `feed`; no `direction` and no `x_cmd` to read it from) naming the run — before this,
/// such a run was skipped without a word, or taken as moving in + direction.
#[test]
fn friction_prints_a_standard_error_beside_every_coefficient_and_refuses_unplaced_points() {
    let tmp = tempfile::tempdir().unwrap();
    let set = crate::cli_contract::friction_set(tmp.path());
    let (code, out, err) = run(&["friction", set.to_str().unwrap()]);
    assert_eq!(code, Some(0), "{err}");
    for name in ["Fc ", "Fs ", "vs ", "δ ", "Fv "] {
        let line = out.lines().find(|l| l.trim_start().starts_with(name)).unwrap_or_else(|| panic!("{name}: {out}"));
        assert!(
            line.contains("± ") || line.contains("no standard error"),
            "`{name}` without a standard error or the reason it has none: {line}"
        );
    }
    let manifest = std::fs::read_to_string(set.join("manifest.toml")).unwrap();
    for (what, from, to, expect) in [
        ("no feed", "feed = 0.003\n", "", "missing `feed`"),
        ("no direction", "feed = 0.003\ndirection = -1\n", "feed = 0.003\n", "missing `direction`"),
    ] {
        assert!(manifest.contains(from), "test setup: {from:?}");
        std::fs::write(set.join("manifest.toml"), manifest.replacen(from, to, 1)).unwrap();
        let (code, _, err) = run(&["friction", set.to_str().unwrap()]);
        assert_eq!(code, Some(2), "{what}: {err}");
        assert!(err.contains(expect) && err.contains("runs[2] (s2)"), "{what}: {err}");
        assert!(err.contains(set.to_str().unwrap()), "{what}: the set is not named: {err}");
    }
}

/// `vmt iso230-2` gives the type-A standard uncertainty of E, M, B and B̄ beside the table (text) and in
/// `uncertainty` (JSON), equal to the formulas of docs/methods.md computed here from the raw readings.
#[test]
#[allow(
    clippy::needless_range_loop,
    reason = "r is both the run number written to the CSV and the third index of readings[dir][target][run]"
)]
fn iso230_2_states_the_uncertainty_of_its_axis_values() {
    let tmp = tempfile::tempdir().unwrap();
    let set = tmp.path().join("set");
    std::fs::create_dir_all(&set).unwrap();
    std::fs::write(
        set.join("manifest.toml"),
        "format = \"vmt-measurements/1\"\n[[sensors]]\nname = \"laser\"\nkind = \"laser_linear\"\naxis = \"x\"\n\
         position = [0.0, 0.0, 0.0]\ndirection = [1.0, 0.0, 0.0]\n\
         [[runs]]\nname = \"iso\"\nfile = \"iso.csv\"\nprocedure = \"positioning\"\naxis = \"x\"\n",
    )
    .unwrap();
    let mut rng = ChaCha8Rng::seed_from_u64(31);
    let targets = [0.0, 0.1, 0.2, 0.3, 0.4, 0.5];
    let runs = 5;
    // readings[dir][target][run]: a deviation of −6…+9 µm with a 3 µm reversal, noise 0.2–0.8 µm.
    let mut readings = vec![vec![vec![0.0; runs]; targets.len()]; 2];
    let mut csv = String::from("target,run,direction,laser\n");
    for r in 0..runs {
        for (d, dir) in [(0usize, 1i8), (1, -1)] {
            let order: Vec<usize> = if dir == 1 { (0..6).collect() } else { (0..6).rev().collect() };
            for i in order {
                let base = [-6e-6, 2e-6, 9e-6, 4e-6, 0.0, -3e-6][i] + if dir == 1 { 1.5e-6 } else { -1.5e-6 };
                let z: f64 = StandardNormal.sample(&mut rng);
                let v = base + rng.gen_range(0.2e-6..0.8e-6) * z;
                readings[d][i][r] = v;
                csv += &format!("{},{},{dir},{v:e}\n", targets[i], r + 1);
            }
        }
    }
    std::fs::write(set.join("iso.csv"), csv).unwrap();
    let stats = |v: &[f64]| {
        let n = v.len() as f64;
        let m = v.iter().sum::<f64>() / n;
        (m, (v.iter().map(|x| (x - m).powi(2)).sum::<f64>() / (n - 1.0)).sqrt() / n.sqrt())
    };
    let up: Vec<(f64, f64)> = readings[0].iter().map(|v| stats(v)).collect();
    let down: Vec<(f64, f64)> = readings[1].iter().map(|v| stats(v)).collect();
    let both: Vec<(f64, f64)> = up.iter().chain(&down).copied().collect();
    let top = both.iter().cloned().fold((f64::MIN, 0.0), |a, b| if b.0 > a.0 { b } else { a });
    let bottom = both.iter().cloned().fold((f64::MAX, 0.0), |a, b| if b.0 < a.0 { b } else { a });
    let u_e = top.1.hypot(bottom.1);
    let u_b: Vec<f64> = up.iter().zip(&down).map(|(a, b)| a.1.hypot(b.1)).collect();
    let u_b_mean = u_b.iter().map(|u| u * u).sum::<f64>().sqrt() / targets.len() as f64;
    let (code, out, err) = run(&["iso230-2", set.to_str().unwrap(), "--json"]);
    assert_eq!(code, Some(0), "{err}");
    let v: serde_json::Value = serde_json::from_str(&out).unwrap();
    let u = &v["uncertainty"];
    for (key, want) in [("e", u_e), ("b_mean", u_b_mean)] {
        let got = u[key].as_f64().unwrap();
        assert!((got / want - 1.0).abs() < 1e-9, "u({key}) {got:e} m against {want:e} m");
    }
    for key in ["e_up", "e_down", "m", "b"] {
        assert!(u[key].as_f64().is_some_and(|x| x > 0.0), "u({key}) missing: {u}");
    }
    let (code, text, err) = run(&["iso230-2", set.to_str().unwrap()]);
    assert_eq!(code, Some(0), "{err}");
    assert!(text.contains(&format!("u(E) {:.3}", u_e * 1e6)), "{text}");
}
