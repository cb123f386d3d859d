//! Interrupted runs never lose or mix outputs (issue 14): `vmt run`, `vmt simulate` and `vmt study`
//! killed (SIGKILL) at random moments, 30 times each. The destination starts with a complete output
//! of one scenario (seed A); each trial runs the other seed and kills it at a uniformly random time in
//! [0, 1.2·T] (T: the duration of a full run), then checks that the destination holds exactly the
//! complete old output or exactly the complete new one (file names and bytes): never a mix, never
//! nothing. The leftovers of killed runs (`NAME.vmt-partial-PID`) are removed by the next run.

use crate::util::{small, vmt};
use rand::{Rng, SeedableRng};
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::{Duration, Instant};

const KILLS: usize = 30;

/// A tiny scenario: the small test scenario's positioning test only (3 targets, 2 runs), seed `seed`.
fn tiny(dir: &Path, seed: i64) -> PathBuf {
    let small = small();
    let mut t: toml::Table = toml::from_str(&std::fs::read_to_string(small).unwrap()).unwrap();
    t.insert("seed".into(), toml::Value::Integer(seed));
    let procs = t.get_mut("procedures").unwrap().as_array_mut().unwrap();
    procs.remove(0);
    let iso = procs[0].as_table_mut().unwrap();
    iso.insert("targets".into(), toml::Value::Array(vec![0.1.into(), 0.37.into(), 0.61.into()]));
    let ests = t.get_mut("estimators").unwrap().as_array_mut().unwrap();
    ests.truncate(1);
    let p = dir.join(format!("s{seed}.toml"));
    std::fs::write(&p, toml::to_string(&t).unwrap()).unwrap();
    p
}

/// Every file under `dir` with its bytes (None if `dir` is absent).
fn snapshot(dir: &Path) -> Option<BTreeMap<String, Vec<u8>>> {
    fn walk(root: &Path, d: &Path, out: &mut BTreeMap<String, Vec<u8>>) {
        for e in std::fs::read_dir(d).unwrap().flatten() {
            let p = e.path();
            if p.is_dir() {
                walk(root, &p, out);
            } else {
                out.insert(p.strip_prefix(root).unwrap().to_string_lossy().into_owned(), std::fs::read(&p).unwrap());
            }
        }
    }
    if !dir.is_dir() {
        return None;
    }
    let mut m = BTreeMap::new();
    walk(dir, dir, &mut m);
    Some(m)
}

fn command(kind: &str, scenario: &Path, out: &Path) -> Command {
    let mut c = vmt();
    match kind {
        "run" => c.arg("run").arg(scenario).arg("-o").arg(out),
        "simulate" => c.arg("simulate").arg(scenario).arg("-o").arg(out),
        _ => c
            .arg("study")
            .arg(scenario)
            .args(["--vary", "sensors.laser_x3.sigma=1e-8,2e-8", "--trials", "3", "-o"])
            .arg(out),
    };
    // The report header carries the date of the run; a fixed SOURCE_DATE_EPOCH makes two runs of one
    // scenario byte-identical, so a snapshot is either the old or the new output.
    c.env("RAYON_NUM_THREADS", "1")
        .env("SOURCE_DATE_EPOCH", "1700000000")
        .stdout(std::process::Stdio::null())
        .stderr(std::process::Stdio::null());
    c
}

/// Runs `kind` to completion with scenario `s` into `out`; returns the duration.
fn full(kind: &str, s: &Path, out: &Path) -> Duration {
    let t0 = Instant::now();
    let st = command(kind, s, out).status().unwrap();
    assert!(matches!(st.code(), Some(0 | 1)), "{kind} failed: {st:?}");
    t0.elapsed()
}

/// Returns (kills that left the old output, kills that left the new output).
fn kill_trials(kind: &str, seed: u64) -> (usize, usize) {
    let tmp = tempfile::tempdir().unwrap();
    let (a, b) = (tiny(tmp.path(), 1), tiny(tmp.path(), 2));
    let out = tmp.path().join("out");
    full(kind, &b, &out);
    let snap_b = snapshot(&out).unwrap();
    let t = full(kind, &a, &out);
    let snap_a = snapshot(&out).unwrap();
    assert_ne!(snap_a, snap_b, "{kind}: the two seeds must give different outputs");
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
    let mut current_is_a = true;
    let (mut old, mut new) = (0, 0);
    for k in 0..KILLS {
        let (next, next_snap, cur_snap) = if current_is_a { (&b, &snap_b, &snap_a) } else { (&a, &snap_a, &snap_b) };
        let wait = t.mul_f64(rng.gen_range(0.0..1.2));
        let mut child = command(kind, next, &out).spawn().unwrap();
        std::thread::sleep(wait);
        let _ = child.kill();
        let _ = child.wait();
        let now = snapshot(&out);
        match now {
            Some(ref s) if s == cur_snap => old += 1,
            Some(ref s) if s == next_snap => {
                new += 1;
                current_is_a = !current_is_a;
            }
            Some(s) => panic!("{kind}: kill {k} after {wait:?} left a mix: files {:?}", s.keys().collect::<Vec<_>>()),
            None => panic!("{kind}: kill {k} after {wait:?} left no output"),
        }
    }
    // A final complete run cleans the leftovers of the killed ones.
    full(kind, if current_is_a { &b } else { &a }, &out);
    let left: Vec<String> = std::fs::read_dir(tmp.path())
        .unwrap()
        .flatten()
        .map(|e| e.file_name().to_string_lossy().into_owned())
        .filter(|n| n.contains("vmt-partial"))
        .collect();
    assert!(left.is_empty(), "{kind}: leftovers not cleaned: {left:?}");
    (old, new)
}

#[test]
fn killed_run_simulate_and_study_leave_the_complete_old_or_new_output() {
    let kinds = ["run", "simulate", "study"];
    let results: Vec<(usize, usize)> = std::thread::scope(|s| {
        let hs: Vec<_> =
            kinds.iter().enumerate().map(|(i, k)| s.spawn(move || kill_trials(k, 14 + i as u64))).collect();
        hs.into_iter().map(|h| h.join().unwrap()).collect()
    });
    for (k, (old, new)) in kinds.iter().zip(&results) {
        eprintln!("{k}: {KILLS} kills: {old} left the old output, {new} the new one");
        assert_eq!(old + new, KILLS);
    }
}
