//! Issue 17: `vmt identify` and `vmt compensate` through the command line on laser line sets written by a
//! generator independent of vmt (tests/gen/laser.rs: the first-order volumetric model, random error
//! motions with several correlation lengths, random line layouts, some rank-deficient, Gaussian noise),
//! in the FORMAT.md §1 contract as a laser's software would write them: `manifest.toml` and one
//! positioning point table (`target[mm]`, `run`, `direction`, one column per line in µm; n runs each way).
//!
//! What is checked, per layout over many noise draws (each draw a fresh set and two runs of the binary):
//! - `vmt identify --json`: each reported value's σ against the spread of its estimates over the draws
//!   (pooled over the layout's values, within 20 %), and the error against the generator's own truth in
//!   the reporting gauge (value minus its value at the first target; straightness about its least-squares
//!   line), also in units of σ;
//! - a value has no σ (null) exactly where an independent rank test of the generator's design matrix
//!   says the lines cannot determine it, and its profile is then named as unobservable (the text output
//!   prints no number for it and `-o` writes no column for it);
//! - `vmt compensate --json`: the true deviation left at the targets after the table is applied,
//!   against what the noise allows there (the mean deviation's uncertainty u from the repeats, and the
//!   table's own residual x̄ − c(P) it reports), within 20 %.

use crate::gen::laser::{line_value, random_layout, LineLayout, Smooth, BEAMS};
use crate::util::vmt;
use faer::Mat;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, StandardNormal};
use rayon::prelude::*;
use std::fmt::Write as _;
use std::path::Path;

/// ISO 230-1 names of the six error motions of X, in the generator's order.
const NAMES: [&str; 6] = ["EXX", "EYX", "EZX", "EAX", "EBX", "ECX"];

/// One layout of a study: lines, error motions, repeats per direction, whether the manifest states σ.
struct Case {
    layout: LineLayout,
    motions: [Smooth; 6],
    runs: usize,
    stated: bool,
    what: String,
}

/// Six error motions each a sum of three squared-exponential processes of correlation lengths
/// 0.4, 0.12 and 0.04 × the travel (× a random factor 0.7–1.4): not harmonics of the travel.
fn motions_several(rng: &mut ChaCha8Rng, travel: f64) -> [Smooth; 6] {
    let mut m = |rms: f64| {
        let f = rng.gen_range(0.7..1.4);
        Smooth::several(rng, rms, &[0.4 * travel * f, 0.12 * travel * f, 0.04 * travel * f])
    };
    [m(10e-6), m(3e-6), m(3e-6), m(10e-6), m(10e-6), m(10e-6)]
}

/// Layout `i` of a study: random layouts ([`random_layout`]), every fifth replaced by one of two
/// deliberately rank-deficient ones (X beams only; one Y beam beside two X beams).
fn case(i: u64) -> Case {
    let mut rng = ChaCha8Rng::seed_from_u64(9000 + i);
    let mut layout = random_layout(&mut rng);
    let mut what = "random".to_string();
    if i % 5 == 3 {
        layout.lines = vec![([0.0, 0.0, 0.2], BEAMS[0]), ([0.2, 0.25, 0.8], BEAMS[0]), ([0.0, -0.25, 1.1], BEAMS[0])];
        what = "X beams only".into();
    } else if i % 5 == 4 {
        layout.lines = vec![([0.0, 0.1, 0.3], BEAMS[0]), ([0.1, -0.2, 0.9], BEAMS[0]), ([0.0, 0.0, 0.5], BEAMS[1])];
        what = "one Y beam, two X beams".into();
    }
    let travel = layout.targets[layout.targets.len() - 1];
    let motions = motions_several(&mut rng, travel);
    Case { layout, motions, runs: rng.gen_range(2..6), stated: rng.gen_bool(0.7), what }
}

/// The zero of line `l` (m): an arbitrary constant, as a laser zeroed anywhere.
fn zero(l: usize) -> f64 {
    1e-5 * l as f64 - 2e-5
}

/// Writes a FORMAT.md §1 set: `runs` runs each way over the targets, readings with noise from `rng`.
fn write_set(c: &Case, dir: &Path, rng: &mut ChaCha8Rng) {
    std::fs::create_dir_all(dir).unwrap();
    let l = &c.layout;
    let mut manifest =
        String::from("format = \"vmt-measurements/1\"\ndescription = \"laser lines written by tests/laser_cli.rs\"\n");
    for (i, (r, u)) in l.lines.iter().enumerate() {
        let kind = if u[0] == 1.0 { "laser_linear" } else { "laser_straightness" };
        writeln!(
            manifest,
            "\n[[sensors]]\nname = \"line{i}\"\nkind = \"{kind}\"\naxis = \"x\"\nposition = [{:?}, {:?}, {:?}]\n\
             direction = [{:?}, {:?}, {:?}]",
            r[0], r[1], r[2], u[0], u[1], u[2]
        )
        .unwrap();
        if c.stated {
            writeln!(manifest, "sigma = {:e}", l.sigma).unwrap();
        }
    }
    manifest += "\n[[runs]]\nname = \"lines\"\nfile = \"lines.csv\"\nprocedure = \"positioning\"\naxis = \"x\"\n";
    std::fs::write(dir.join("manifest.toml"), manifest).unwrap();
    let mut csv = String::from("# written by tests/laser_cli.rs\ntarget[mm],run,direction");
    for i in 0..l.lines.len() {
        write!(csv, ",line{i}[um]").unwrap();
    }
    csv.push('\n');
    for run in 1..=c.runs {
        for dir in [1i32, -1] {
            let order: Vec<f64> = if dir == 1 { l.targets.clone() } else { l.targets.iter().rev().copied().collect() };
            for q in order {
                write!(csv, "{:e},{run},{dir}", q * 1e3).unwrap();
                for (i, line) in l.lines.iter().enumerate() {
                    let n: f64 = StandardNormal.sample(rng);
                    write!(csv, ",{:e}", (line_value(&c.motions, line, q) + zero(i) + l.sigma * n) * 1e6).unwrap();
                }
                csv.push('\n');
            }
        }
    }
    std::fs::write(dir.join("lines.csv"), csv).unwrap();
}

/// The reporting-gauge functional of profile `k` at target `t` as coefficients on the motion's values at
/// the targets: value minus the value at the first target (positioning, angles), or minus the
/// least-squares line through all targets (straightness, k = 1, 2).
fn functional(targets: &[f64], k: usize, t: usize) -> Vec<f64> {
    let n = targets.len();
    let mut g = vec![0.0; n];
    g[t] += 1.0;
    if k == 1 || k == 2 {
        let qm = targets.iter().sum::<f64>() / n as f64;
        let sxx: f64 = targets.iter().map(|q| (q - qm) * (q - qm)).sum();
        for (s, c) in g.iter_mut().enumerate() {
            *c -= 1.0 / n as f64 + (targets[t] - qm) * (targets[s] - qm) / sxx;
        }
    } else {
        g[0] -= 1.0;
    }
    g
}

/// The generator's truth of every reported value: `truth[k][t]` (m or rad).
fn truth(c: &Case) -> Vec<Vec<f64>> {
    let q = &c.layout.targets;
    (0..6)
        .map(|k| {
            let v: Vec<f64> = q.iter().map(|&x| c.motions[k].at(x)).collect();
            (0..q.len()).map(|t| functional(q, k, t).iter().zip(&v).map(|(a, b)| a * b).sum()).collect()
        })
        .collect()
}

/// Independent observability: `observable[k][t]` is true when the functional of profile `k` at target `t`
/// lies in the row space of the design matrix of the readings (one row per line and target; columns:
/// the six motions' values at the targets, then one zero per line), i.e. has no component along its
/// null space (SVD, rank at 1e-9 of the largest singular value; component above 1e-6 of the norm).
fn observable(l: &LineLayout) -> Vec<Vec<bool>> {
    let n = l.targets.len();
    let cols = 6 * n + l.lines.len();
    let rows = (l.lines.len() * n).max(cols);
    let mut a = Mat::<f64>::zeros(rows, cols);
    for (li, (r, u)) in l.lines.iter().enumerate() {
        // u·(E + ε × r) = u·E + ε·(r × u)
        let ru = crate::gen::laser::cross(*r, *u);
        for t in 0..n {
            let row = li * n + t;
            for k in 0..3 {
                a[(row, k * n + t)] = u[k];
                a[(row, (3 + k) * n + t)] = ru[k];
            }
            a[(row, 6 * n + li)] = 1.0;
        }
    }
    let svd = a.thin_svd().unwrap();
    let s: Vec<f64> = (0..cols).map(|i| svd.S().column_vector()[i]).collect();
    let rank = s.iter().filter(|&&x| x > 1e-9 * s[0]).count();
    let v = svd.V();
    (0..6)
        .map(|k| {
            (0..n)
                .map(|t| {
                    let mut g = vec![0.0; cols];
                    g[k * n..(k + 1) * n].copy_from_slice(&functional(&l.targets, k, t));
                    let norm = g.iter().map(|x| x * x).sum::<f64>().sqrt();
                    let along_null: f64 =
                        (rank..cols).map(|j| (0..cols).map(|i| g[i] * v[(i, j)]).sum::<f64>().powi(2)).sum();
                    along_null.sqrt() <= 1e-6 * norm
                })
                .collect()
        })
        .collect()
}

/// The profile CSV column (FORMAT.md §5) of each error motion, in the generator's order.
const COLUMNS: [&str; 6] = ["positioning", "straightness_y", "straightness_z", "roll", "pitch", "yaw"];

/// Where a value is undetermined (`obs` from the rank test), neither the text output nor `-o` gives a
/// number for it: a profile undetermined everywhere is printed as unobservable with no digit on its line,
/// and a profile with any undetermined value has no column in the written CSV (the others have a σ column).
fn never_a_number(i: u64, dir: &Path, obs: &[Vec<bool>], tmp: &Path) {
    let est = tmp.join("estimate.csv");
    let out = vmt().arg("identify").arg(dir).arg("-o").arg(&est).output().unwrap();
    assert!(out.status.success(), "layout {i}: {}", String::from_utf8_lossy(&out.stderr));
    let text = String::from_utf8_lossy(&out.stdout);
    let header = std::fs::read_to_string(&est).unwrap().lines().find(|l| !l.starts_with('#')).unwrap().to_string();
    let cols: Vec<&str> = header.split(',').map(|c| c.split('[').next().unwrap()).collect();
    for k in 0..6 {
        let line = text.lines().find(|l| l.trim_start().starts_with(NAMES[k])).unwrap();
        if obs[k].iter().all(|o| !o) {
            assert!(line.contains("unobservable"), "layout {i}: {line}");
            assert!(!line.chars().any(|c| c.is_ascii_digit()), "layout {i}: a number for {}: {line}", NAMES[k]);
        }
        let written = cols.contains(&COLUMNS[k]);
        let determined = obs[k].iter().all(|o| *o);
        assert_eq!(written, determined, "layout {i}: {} written {written}, determined {determined}", COLUMNS[k]);
        if written {
            assert!(cols.contains(&format!("{}_sigma", COLUMNS[k]).as_str()), "layout {i}: no σ for {}", COLUMNS[k]);
        }
    }
}

fn numbers(v: &serde_json::Value) -> Vec<Option<f64>> {
    v.as_array().unwrap().iter().map(|x| x.as_f64()).collect()
}

/// What one layout gave over `draws` noise draws.
struct LayoutResult {
    what: String,
    lines: usize,
    /// Values with a σ.
    values: usize,
    /// √(mean over values of (spread over draws / RMS reported σ)²).
    spread_over_sigma: f64,
    /// Per value: spread over the draws / RMS reported σ.
    per_value: Vec<f64>,
    /// √(mean over values and draws of ((estimate − truth)/σ)²).
    error_over_sigma: f64,
    /// Values whose σ is null where the independent rank test says observable, or the reverse.
    observability_mismatches: usize,
    /// Values the independent rank test finds undetermined.
    undetermined: usize,
    /// A value without σ whose profile is not named in `unobservable_profiles`, or names without any.
    unnamed: usize,
    /// compensate: √(mean (true deviation − table)²) / √(mean (u² + table residual²)) at the targets, when
    /// the layout has a linear laser.
    compensation: Option<f64>,
}

fn run_layout(i: u64, draws: usize) -> LayoutResult {
    let c = case(i);
    let tmp = tempfile::tempdir().unwrap();
    let truth = truth(&c);
    let obs = observable(&c.layout);
    let n = c.layout.targets.len();
    // per (k, t): estimates and σ² over the draws
    let mut est: Vec<Vec<f64>> = vec![Vec::new(); 6 * n];
    let mut var: Vec<Vec<f64>> = vec![Vec::new(); 6 * n];
    let (mut mismatches, mut unnamed) = (0, 0);
    let linear = c.layout.lines.iter().position(|(_, u)| u[0] == 1.0);
    let (mut comp_err2, mut comp_allow2, mut comp_n) = (0.0, 0.0, 0usize);
    for d in 0..draws {
        let mut rng = ChaCha8Rng::seed_from_u64((9000 + i) * 1000 + d as u64);
        let dir = tmp.path().join(format!("d{d}"));
        write_set(&c, &dir, &mut rng);
        let out = vmt().arg("identify").arg(&dir).arg("--json").output().unwrap();
        assert!(out.status.success(), "layout {i} draw {d}: {}", String::from_utf8_lossy(&out.stderr));
        let j: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
        assert_eq!(j["format"], "vmt-identify/1");
        let named: Vec<&str> =
            j["unobservable_profiles"].as_array().unwrap().iter().map(|x| x.as_str().unwrap()).collect();
        let combos = j["unobservable"].as_array().unwrap().len();
        for p in j["profiles"].as_array().unwrap() {
            let k = NAMES.iter().position(|s| p["name"] == *s).unwrap();
            let pos = numbers(&p["positions"]);
            assert_eq!(pos.len(), n, "layout {i}: one value per target");
            let vals = numbers(&p["values"]);
            let sig = numbers(&p["std_errors"]);
            // A profile the lines determine only at its reference position (its zero by the reporting
            // convention) is reported unobservable as a whole: the datum is no observation.
            let datum_only = obs[k].iter().filter(|o| **o).count() <= 1;
            for t in 0..n {
                if sig[t].is_some() != (obs[k][t] && !datum_only) {
                    mismatches += 1;
                }
                match sig[t] {
                    Some(s) if s > 0.0 => {
                        est[k * n + t].push(vals[t].unwrap());
                        var[k * n + t].push(s * s);
                    }
                    Some(_) => {}
                    None => {
                        if !named.contains(&NAMES[k]) || combos == 0 {
                            unnamed += 1;
                        }
                    }
                }
            }
        }
        if d == 0 {
            never_a_number(i, &dir, &obs, tmp.path());
        }
        if let Some(li) = linear {
            let table = tmp.path().join(format!("table{d}.csv"));
            let out = vmt()
                .args(["compensate", dir.to_str().unwrap(), "--sensor", &format!("line{li}"), "--json", "-o"])
                .arg(&table)
                .output()
                .unwrap();
            assert!(out.status.success(), "layout {i} draw {d}: {}", String::from_utf8_lossy(&out.stderr));
            let j: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
            assert_eq!(j["format"], "vmt-compensate/1");
            for tg in j["targets"].as_array().unwrap() {
                let p = tg["position"].as_f64().unwrap();
                let mean = tg["mean_deviation"].as_f64().unwrap();
                let resid = tg["table_residual"].as_f64().unwrap();
                let u = tg["u"].as_f64().expect("two runs each way give u");
                // the table's correction at the target: x̄ − (x̄ − c(P))
                let correction = mean - resid;
                let true_dev = line_value(&c.motions, &c.layout.lines[li], p) + zero(li);
                comp_err2 += (true_dev - correction).powi(2);
                comp_allow2 += u * u + resid * resid;
                comp_n += 1;
            }
        }
    }
    let mut ratios = Vec::new();
    let mut z2 = Vec::new();
    for (idx, e) in est.iter().enumerate() {
        if e.len() != draws {
            continue;
        }
        let (k, t) = (idx / n, idx % n);
        let m = e.iter().sum::<f64>() / draws as f64;
        let spread = (e.iter().map(|x| (x - m).powi(2)).sum::<f64>() / (draws - 1) as f64).sqrt();
        let sigma = (var[idx].iter().sum::<f64>() / draws as f64).sqrt();
        ratios.push(spread / sigma);
        for (x, v) in e.iter().zip(&var[idx]) {
            z2.push((x - truth[k][t]).powi(2) / v);
        }
    }
    let rms = |v: &[f64]| (v.iter().map(|x| x * x).sum::<f64>() / v.len() as f64).sqrt();
    LayoutResult {
        what: c.what,
        lines: c.layout.lines.len(),
        values: ratios.len(),
        spread_over_sigma: if ratios.is_empty() { f64::NAN } else { rms(&ratios) },
        per_value: ratios.clone(),
        error_over_sigma: if z2.is_empty() { f64::NAN } else { (z2.iter().sum::<f64>() / z2.len() as f64).sqrt() },
        observability_mismatches: mismatches,
        undetermined: obs.iter().flatten().filter(|o| !**o).count(),
        unnamed,
        compensation: (comp_n > 0).then(|| (comp_err2 / comp_allow2).sqrt()),
    }
}

/// Runs `layouts` layouts × `draws` draws, prints a row per layout and the summary, and asserts: every
/// value's σ-or-null agrees with the independent rank test, every σ-less value's profile is named, and per
/// layout the pooled spread/σ, error/σ and the compensation ratio are within 20 % of 1.
///
/// Scatter: per layout the pooled ratio² averages ≥ `draws` χ²₁-like terms (fewer independent ones when
/// the values are correlated; at least one value's worth), so with 50 draws its 1σ scatter is ≤ 10 %; 20 %
/// is the limit. The same for the compensation ratio (targets × draws terms).
fn study(layouts: u64, draws: usize) {
    let t0 = std::time::Instant::now();
    let results: Vec<LayoutResult> = (0..layouts).into_par_iter().map(|i| run_layout(i, draws)).collect();
    let mut fails = Vec::new();
    for (i, r) in results.iter().enumerate() {
        println!(
            "layout {i} ({}, {} lines): {} values with σ, {} undetermined; spread/σ {:.3}, error/σ {:.3}; σ-null vs rank test \
             mismatches {}, unnamed {}; compensate: residual / allowed {}",
            r.what,
            r.lines,
            r.values,
            r.undetermined,
            r.spread_over_sigma,
            r.error_over_sigma,
            r.observability_mismatches,
            r.unnamed,
            r.compensation.map_or("- (no linear laser)".into(), |x| format!("{x:.3}"))
        );
        if r.observability_mismatches > 0 || r.unnamed > 0 {
            fails.push(format!("layout {i}: observability {} / naming {}", r.observability_mismatches, r.unnamed));
        }
        for (what, x) in [
            ("spread/σ", Some(r.spread_over_sigma)),
            ("error/σ", Some(r.error_over_sigma)),
            ("compensation", r.compensation),
        ] {
            if let Some(x) = x.filter(|x| !x.is_nan()) {
                if (x - 1.0).abs() > 0.2 {
                    fails.push(format!("layout {i}: {what} {x:.3} not within 20 %"));
                }
            }
        }
    }
    let summary = |name: &str, v: Vec<f64>| {
        let mut s = v.clone();
        s.sort_by(f64::total_cmp);
        if s.is_empty() {
            return;
        }
        println!(
            "{name}: {} layouts, mean {:.3}, min {:.3}, max {:.3}",
            s.len(),
            s.iter().sum::<f64>() / s.len() as f64,
            s[0],
            s[s.len() - 1]
        );
    };
    let mut all: Vec<f64> = results.iter().flat_map(|r| r.per_value.iter().copied()).collect();
    all.sort_by(f64::total_cmp);
    if !all.is_empty() {
        println!(
            "identify, per value: spread over {draws} draws / RMS reported σ over {} values: mean {:.3}, p5 {:.3}, p95 {:.3}, min {:.3}, max {:.3}",
            all.len(),
            all.iter().sum::<f64>() / all.len() as f64,
            all[all.len() / 20],
            all[all.len() * 19 / 20],
            all[0],
            all[all.len() - 1]
        );
    }
    summary("identify spread/σ", results.iter().map(|r| r.spread_over_sigma).filter(|x| !x.is_nan()).collect());
    summary("identify error/σ", results.iter().map(|r| r.error_over_sigma).filter(|x| !x.is_nan()).collect());
    summary("compensate residual/allowed", results.iter().filter_map(|r| r.compensation).collect());
    println!(
        "{layouts} layouts × {draws} draws; {} layouts leave values undetermined (named); {:.1} s",
        results.iter().filter(|r| r.undetermined > 0).count(),
        t0.elapsed().as_secs_f64()
    );
    assert!(fails.is_empty(), "{}", fails.join("\n"));
}

/// The always-on version: 10 layouts (four of them deliberately rank-deficient) × 50 draws (≈ 10 s).
#[test]
fn identify_and_compensate_on_independently_written_line_sets() {
    study(10, 50);
}

/// The rate study: 30 layouts × 60 draws (about 3 600 runs of the binary; minutes).
/// `cargo test --release --test tests laser_cli::identify_and_compensate_rate_study -- --ignored --nocapture`
#[test]
#[ignore]
fn identify_and_compensate_rate_study() {
    study(30, 60);
}
