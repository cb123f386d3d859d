//! The command line's contract with people and programs (issue 13): every `--json` output is one JSON
//! object whose first key is `format` (`vmt-NAME/VERSION`); `run --json` gives the paths of the data and
//! the report; `--trials 0` is refused; an external estimator (examples/my_estimator.py) is judged by the
//! `--tolerance` it is given — exit code and table differ between a tolerance it meets and one it misses.

use crate::util::{root, small, vmt};
use std::path::{Path, PathBuf};
use std::process::{Command, Output};

fn ok(out: Output, what: &str) -> String {
    assert!(out.status.success(), "{what}: {}", String::from_utf8_lossy(&out.stderr));
    String::from_utf8(out.stdout).unwrap()
}

/// The small test scenario with the six laser lines of the nine-line layout read in its positioning run.
fn lines_scenario(dir: &Path) -> PathBuf {
    let text = std::fs::read_to_string(small()).unwrap();
    let from = "sensors = [\"scale\", \"laser_x3\", \"laser_y1\"]";
    assert!(text.contains(from), "test setup: `{from}` not in tests/data/small.toml");
    let p = dir.join("lines.toml");
    let to = "sensors = [\"laser_x1\", \"laser_x2\", \"laser_x3\", \"laser_y1\", \"laser_y2\", \"laser_z1\"]";
    std::fs::write(&p, text.replacen(from, to, 1)).unwrap();
    p
}

/// A friction-sweep set written by hand: 8 runs of constant motor force at ±1, 3, 10, 30 mm/s.
pub(crate) fn friction_set(dir: &Path) -> PathBuf {
    let set = dir.join("friction");
    std::fs::create_dir_all(&set).unwrap();
    let mut manifest = String::from(
        "format = \"vmt-measurements/1\"\n[[sensors]]\nname = \"force\"\nkind = \"motor_force\"\naxis = \"x\"\n",
    );
    for (i, v) in [-0.03, -0.01, -0.003, -0.001, 0.001, 0.003, 0.01, 0.03].into_iter().enumerate() {
        let f = f64::signum(v) * (150.0 + 100.0 * (-(f64::abs(v) / 0.002)).exp()) + 800.0 * v;
        manifest += &format!(
            "[[runs]]\nname = \"s{i}\"\nfile = \"s{i}.csv\"\nprocedure = \"friction_sweep\"\naxis = \"x\"\nfeed = {}\ndirection = {}\n",
            v.abs(),
            if v > 0.0 { 1 } else { -1 }
        );
        let rows: String =
            (0..20).map(|k| format!("{},{}\n", k as f64 * 0.01, f + 0.5 * ((k % 3) as f64 - 1.0))).collect();
        std::fs::write(set.join(format!("s{i}.csv")), format!("t,force\n{rows}")).unwrap();
    }
    std::fs::write(set.join("manifest.toml"), manifest).unwrap();
    set
}

/// `vmt --help` and the commands it lists (without `help`), so that a new command is covered.
fn help_and_commands() -> (String, Vec<String>) {
    let help = ok(vmt().arg("--help").output().unwrap(), "vmt --help");
    let commands: Vec<String> = help
        .lines()
        .skip_while(|l| !l.starts_with("Commands:"))
        .skip(1)
        .take_while(|l| l.starts_with("  "))
        .filter_map(|l| l.split_whitespace().next().map(str::to_string))
        .filter(|c| c != "help")
        .collect();
    assert!(commands.len() >= 10, "{help}");
    (help, commands)
}

/// The commands whose help offers `--json`, from `vmt help` (so a new command with `--json` is covered).
fn commands_with_json() -> Vec<String> {
    let (_, commands) = help_and_commands();
    commands
        .into_iter()
        .filter(|c| ok(vmt().args([c.as_str(), "--help"]).output().unwrap(), c).contains("--json"))
        .collect()
}

#[test]
fn every_json_output_is_an_object_whose_first_key_is_a_versioned_format() {
    let tmp = tempfile::tempdir().unwrap();
    let t = tmp.path();
    let data = t.join("data");
    ok(vmt().arg("simulate").arg(lines_scenario(t)).arg("-o").arg(&data).output().unwrap(), "simulate");
    let model = t.join("model.toml");
    std::fs::write(&model, "format = \"vmt-model/1\"\naxis = \"x\"\n[effects.positioning]\nfit = true\n").unwrap();
    let friction = friction_set(t);
    let (d, m) = (data.to_str().unwrap(), model.to_str().unwrap());
    let truth = data.join("truth_profiles.csv");
    let est = t.join("estimate.csv");
    ok(vmt().args(["identify", d, "-o"]).arg(&est).output().unwrap(), "identify -o");
    let passes = t.join("passes");
    let accel = root().join("scenarios/study_accel.toml");
    ok(vmt().arg("simulate").arg(&accel).arg("-o").arg(&passes).output().unwrap(), "simulate study_accel");
    let run_out = t.join("run");
    let small = small();
    let cases: Vec<(&str, Vec<String>, &str)> = vec![
        (
            "run",
            vec!["run".into(), small.display().to_string(), "--out".into(), run_out.display().to_string()],
            "vmt-run/1",
        ),
        ("compare", vec!["compare".into(), "--model".into(), m.into(), "--data".into(), d.into()], "vmt-compare/1"),
        ("diagnose", vec!["diagnose".into(), "--model".into(), m.into(), "--data".into(), d.into()], "vmt-diagnose/1"),
        ("identify", vec!["identify".into(), d.into()], "vmt-identify/1"),
        ("iso230-2", vec!["iso230-2".into(), d.into()], "vmt-iso230-2/1"),
        ("ssi", vec!["ssi".into(), d.into()], "vmt-ssi/1"),
        ("straightness", vec!["straightness".into(), passes.display().to_string()], "vmt-straightness/1"),
        ("friction", vec!["friction".into(), friction.display().to_string()], "vmt-friction/1"),
        (
            "compensate",
            vec!["compensate".into(), d.into(), "-o".into(), t.join("table.csv").display().to_string()],
            "vmt-compensate/1",
        ),
        (
            "score",
            vec![
                "score".into(),
                "--truth".into(),
                truth.display().to_string(),
                "--estimate".into(),
                est.display().to_string(),
            ],
            "vmt-score/1",
        ),
    ];
    let covered: Vec<&str> = cases.iter().map(|c| c.0).collect();
    for c in commands_with_json() {
        assert!(covered.contains(&c.as_str()), "`vmt {c}` offers --json but this test does not check it");
    }
    for (name, args, format) in &cases {
        let out = vmt().args(args).arg("--json").output().unwrap();
        // `run` exits 1 when an estimate misses its tolerance; its JSON must still be well formed.
        assert!(matches!(out.status.code(), Some(0 | 1)), "{name}: {}", String::from_utf8_lossy(&out.stderr));
        let text = String::from_utf8(out.stdout).unwrap();
        let v: serde_json::Value =
            serde_json::from_str(&text).unwrap_or_else(|e| panic!("{name}: not one JSON value ({e}):\n{text}"));
        assert!(v.is_object(), "{name}: top level is not an object");
        assert_eq!(v["format"], *format, "{name}");
        let first_key = text.trim_start().trim_start_matches('{').trim_start();
        assert!(first_key.starts_with("\"format\""), "{name}: `format` is not the first key:\n{text}");
        if *name == "run" {
            assert!(Path::new(v["data"].as_str().unwrap()).join("manifest.toml").is_file(), "{text}");
            assert!(Path::new(v["report"].as_str().unwrap()).is_file(), "{text}");
        }
    }
}

#[test]
fn a_study_refuses_zero_trials() {
    let out = vmt()
        .args(["study"])
        .arg(root().join("scenarios/study_accel.toml"))
        .args(["--vary", "sensors.acc_z.noise_density=1e-7", "--trials", "0", "-o"])
        .arg(std::env::temp_dir().join("vmt-never-written"))
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(2), "{}", String::from_utf8_lossy(&out.stderr));
    assert!(String::from_utf8_lossy(&out.stderr).contains("--trials"));
}

#[test]
fn run_outputs_of_two_scenarios_with_the_same_file_name_do_not_overwrite_each_other() {
    let out = |p: &str| vmt::cli::default_out(Path::new(p));
    assert_eq!(out("scenarios/default.toml"), Path::new("vmt-out/default"));
    assert_ne!(out("scenarios/lessons/backlash/scenario.toml"), out("scenarios/lessons/stribeck/scenario.toml"));
    assert_eq!(out("scenarios/lessons/backlash/scenario.toml"), Path::new("vmt-out/lessons/backlash/scenario"));
    assert_eq!(out("/tmp/../x/my.toml"), Path::new("vmt-out/tmp/x/my"));
}

/// The README's bring-your-own-estimator example, examples/my_estimator.py (stdlib Python ≥ 3.11 for
/// tomllib), run in every trial of a study. With 20 nm laser noise it recovers the six error motions to
/// about 0.02–0.05 µm / µrad RMS (mean of 10 readings per target and laser, lever arms ≈ 1 m), so:
/// - 0.2e-6 (0.2 µm, 0.2 µrad) is met in every trial: exit 0, pass 100 %;
/// - 1e-9 (1 nm) is below the noise of the estimate (≈ 10 nm): trials miss it, exit 1.
#[test]
fn the_python_example_estimator_passes_a_tolerance_it_meets_and_fails_one_it_misses() {
    let python = Command::new("python3").args(["-c", "import sys, tomllib; print(sys.version)"]).output();
    if !python.as_ref().is_ok_and(|o| o.status.success()) {
        use std::io::Write;
        let line = "SKIPPED (python3 >= 3.11 not found): the_python_example_estimator_passes_a_tolerance_it_meets_and_fails_one_it_misses\n";
        let _ = std::io::stderr().lock().write_all(line.as_bytes());
        return;
    }
    let tmp = tempfile::tempdir().unwrap();
    let scenario = lines_scenario(tmp.path());
    let example = root().join("examples/my_estimator.py");
    let cmd = format!("python3 '{}' {{data}} {{out}}", example.display());
    let study = |tolerance: &str, out: &str| {
        vmt()
            .arg("study")
            .arg(&scenario)
            .args(["--vary", "sensors.laser_x1.sigma=2e-8", "--trials", "3", "--estimator-cmd", &cmd])
            .args(["--tolerance", tolerance, "-o"])
            .arg(tmp.path().join(out))
            .output()
            .unwrap()
    };
    let met = study("0.2e-6", "met");
    let missed = study("1e-9", "missed");
    let (met_text, missed_text) = (String::from_utf8_lossy(&met.stdout), String::from_utf8_lossy(&missed.stdout));
    assert_eq!(met.status.code(), Some(0), "{met_text}\n{}", String::from_utf8_lossy(&met.stderr));
    assert_eq!(missed.status.code(), Some(1), "{missed_text}\n{}", String::from_utf8_lossy(&missed.stderr));
    let motions = ["positioning", "straightness_y", "straightness_z", "roll", "pitch", "yaw"];
    let pass_rate = |text: &str, m: &str| -> f64 {
        let row = text.lines().find(|l| l.contains(&format!("{m} RMS"))).unwrap_or_else(|| panic!("{m}: {text}"));
        let cells: Vec<&str> = row.split_whitespace().collect();
        assert_eq!(cells.last(), Some(&"%"), "{row}");
        cells[cells.len() - 2].parse().unwrap()
    };
    for m in motions {
        assert_eq!(pass_rate(&met_text, m), 100.0, "{m}: {met_text}");
        // 1 nm is passed only by chance: straightness over 4 positions about its least-squares line rests
        // on 2 degrees of freedom and fell below 1 nm in 1 of 18 rows when this test was written.
        assert!(pass_rate(&missed_text, m) < 50.0, "{m}: {missed_text}");
    }
    // Without a tolerance no pass/fail is claimed.
    let none = vmt()
        .arg("study")
        .arg(&scenario)
        .args(["--vary", "sensors.laser_x1.sigma=2e-8", "--trials", "1", "--estimator-cmd", &cmd, "-o"])
        .arg(tmp.path().join("none"))
        .output()
        .unwrap();
    let text = ok(none, "study without --tolerance");
    assert!(!text.contains('%'), "{text}");
}

/// The arguments of the call that starts at `text` (just after `.clamp(`), split at top-level commas;
/// None when the parenthesis does not close on the line.
fn call_args(text: &str) -> Option<Vec<String>> {
    let (mut depth, mut cur, mut args) = (0usize, String::new(), Vec::new());
    for ch in text.chars() {
        match ch {
            '(' | '[' => depth += 1,
            ')' if depth == 0 => {
                args.push(cur.trim().to_string());
                return Some(args);
            }
            ')' | ']' => depth -= 1,
            ',' if depth == 0 => {
                args.push(cur.trim().to_string());
                cur.clear();
                continue;
            }
            _ => {}
        }
        cur.push(ch);
    }
    None
}

/// Issue 14: `f64::clamp` panics when a bound is NaN or min > max, `Ord::clamp` when min > max. Every
/// `.clamp(` in the non-test code of the four crates has literal bounds, or says on its line or in the
/// comment block above (`// clamp:`) why its bounds are ordered and finite — where they come from input, which check
/// makes them so. A new clamp without that fails here (it failed on its first run: 13 unexplained; reviewing
/// them found each bound ordered by an existing check, named in its comment).
#[test]
fn every_clamp_has_literal_bounds_or_says_why_they_are_ordered() {
    let literal = |a: &str| a.trim_start_matches('-').replace('_', "").parse::<f64>().is_ok();
    let mut files = Vec::new();
    for dir in ["src", "sim/src", "estimators/src", "report/src"] {
        crate::util::rust_files(&root().join(dir), &mut files);
    }
    files.sort();
    let (mut seen, mut unexplained) = (0, Vec::new());
    for f in &files {
        let text = std::fs::read_to_string(f).unwrap();
        let lines: Vec<&str> = text.lines().collect();
        // The unit tests sit at the end of a file, after `#[cfg(test)]`: not release code.
        let end = lines.iter().position(|l| l.trim() == "#[cfg(test)]").unwrap_or(lines.len());
        for i in 0..end {
            let Some(at) = lines[i].find(".clamp(") else { continue };
            if lines[i].trim_start().starts_with("//") {
                continue;
            }
            seen += 1;
            let args = call_args(&lines[i][at + ".clamp(".len()..]);
            if args.as_ref().is_some_and(|a| a.len() == 2 && a.iter().all(|x| literal(x))) {
                continue;
            }
            // The reason sits on the line or in the comment block right above it.
            let above = lines[..i].iter().rev().take_while(|l| l.trim_start().starts_with("//"));
            let said =
                lines[i].contains("// clamp:") || above.into_iter().any(|l| l.trim_start().starts_with("// clamp:"));
            if !said {
                unexplained.push(format!(
                    "{}:{}: {}",
                    f.strip_prefix(root()).unwrap().display(),
                    i + 1,
                    lines[i].trim()
                ));
            }
        }
    }
    assert!(seen > 10, "the scan found only {seen} clamps: is it reading the sources?");
    assert!(
        unexplained.is_empty(),
        "{} clamp(s) on non-literal bounds without a `// clamp:` reason:\n{}",
        unexplained.len(),
        unexplained.join("\n")
    );
}

/// Issue 13: `vmt identify` prints "unobservable", never a number, for an error motion it calls
/// unobservable. Three x beams (laser_x1..3 of the nine-line layout) see EXX, EBX and ECX; EYX, EZX and
/// EAX are not observable (EAX only at its reference position, where it is zero by convention). Text:
/// their lines say "unobservable" and carry no digit. JSON: their values and standard errors are `null`
/// and `unobservable_profiles` names them, while EXX has numbers. `-o`: their columns are not written
/// (a note names them), the observable ones are, each with its σ.
#[test]
fn identify_prints_unobservable_never_a_number() {
    let tmp = tempfile::tempdir().unwrap();
    let text = std::fs::read_to_string(small()).unwrap();
    let from = "sensors = [\"scale\", \"laser_x3\", \"laser_y1\"]";
    assert!(text.contains(from), "test setup: `{from}` not in tests/data/small.toml");
    let sc = tmp.path().join("x_only.toml");
    std::fs::write(&sc, text.replacen(from, "sensors = [\"laser_x1\", \"laser_x2\", \"laser_x3\"]", 1)).unwrap();
    let set = tmp.path().join("set");
    ok(vmt().arg("simulate").arg(&sc).arg("-o").arg(&set).output().unwrap(), "simulate");
    let unobservable = ["EYX", "EZX", "EAX"];

    let out = ok(vmt().arg("identify").arg(&set).output().unwrap(), "identify");
    for name in unobservable {
        let line =
            out.lines().find(|l| l.trim_start().starts_with(&format!("{name} "))).unwrap_or_else(|| panic!("{out}"));
        assert!(line.contains("unobservable"), "{line}");
        assert!(!line[line.find(name).unwrap() + 3..].contains(|c: char| c.is_ascii_digit()), "a number: {line}");
    }
    let exx = out.lines().find(|l| l.trim_start().starts_with("EXX ")).unwrap();
    assert!(exx.contains("standard error (1σ)") && !exx.contains("unobservable"), "{exx}");

    let json: serde_json::Value =
        serde_json::from_str(&ok(vmt().args(["identify", "--json"]).arg(&set).output().unwrap(), "identify --json"))
            .unwrap();
    let flagged: Vec<&str> =
        json["unobservable_profiles"].as_array().unwrap().iter().map(|v| v.as_str().unwrap()).collect();
    assert_eq!(flagged, unobservable);
    for p in json["profiles"].as_array().unwrap() {
        let name = p["name"].as_str().unwrap();
        let (values, sigmas) = (p["values"].as_array().unwrap(), p["std_errors"].as_array().unwrap());
        if unobservable.contains(&name) {
            assert!(values.iter().chain(sigmas).all(serde_json::Value::is_null), "{name}: {p}");
        } else {
            assert!(values.iter().chain(sigmas).all(serde_json::Value::is_f64), "{name}: {p}");
            assert!(sigmas.iter().skip(1).all(|s| s.as_f64().unwrap() > 0.0), "{name}: {p}");
        }
    }
    // The parameter list: a number only where it has a standard error.
    let (params, sigmas) = (json["params"].as_array().unwrap(), json["std_errors"].as_array().unwrap());
    assert!(sigmas.iter().any(serde_json::Value::is_null));
    for (x, s) in params.iter().zip(sigmas) {
        assert_eq!(x.is_null(), s.is_null(), "{x} ± {s}");
    }

    let csv = tmp.path().join("profiles.csv");
    let o = vmt().arg("identify").arg(&set).arg("-o").arg(&csv).output().unwrap();
    assert_eq!(o.status.code(), Some(0), "{}", String::from_utf8_lossy(&o.stderr));
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(err.contains("not observable from these lines): EYX, EZX, EAX"), "{err}");
    let header = std::fs::read_to_string(&csv).unwrap().lines().next().unwrap().to_string();
    assert_eq!(header, "position,positioning,positioning_sigma,pitch,pitch_sigma,yaw,yaw_sigma");
}

/// Issue 13/14: exit codes. `--help` documents 1 (a missed tolerance), 2 (bad input) and 3 (an I/O
/// failure of the machine); a missing input is 2; a write the machine refuses is 3, never 1 or 2, and
/// leaves nothing under the destination's name: (a) a file-size limit (`ulimit -f`, SIGXFSZ ignored so
/// that the write fails with EFBIG, as on a full disk), (b) a directory the kernel will not create
/// (under /proc; this works for root too, for whom a read-only directory is writable).
#[cfg(target_os = "linux")]
#[test]
fn an_io_failure_of_the_machine_exits_3() {
    let help = ok(vmt().arg("--help").output().unwrap(), "vmt --help");
    for code in ["1 an estimate missed its tolerance", "2 bad input", "3 an I/O failure of the machine"] {
        assert!(help.contains(code), "--help does not document `{code}`: {help}");
    }
    let tmp = tempfile::tempdir().unwrap();
    let missing = vmt().arg("simulate").arg(tmp.path().join("nope.toml")).arg("-o").arg(tmp.path().join("o")).output();
    assert_eq!(missing.unwrap().status.code(), Some(2), "a missing input is bad input");

    let dest = tmp.path().join("out");
    let o = Command::new("sh")
        .args(["-c", "trap '' XFSZ; ulimit -f 8; exec \"$0\" \"$@\""])
        .arg(env!("CARGO_BIN_EXE_vmt"))
        .arg("simulate")
        .arg(small())
        .arg("-o")
        .arg(&dest)
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(3), "a write over the file-size limit: {err}");
    assert!(err.contains("writing") && err.contains("File too large"), "{err}");
    assert!(!dest.exists(), "a failed write left {}", dest.display());
    let left: Vec<_> = std::fs::read_dir(tmp.path()).unwrap().map(|e| e.unwrap().file_name()).collect();
    assert!(left.is_empty(), "leftovers beside the destination: {left:?}");

    let o = vmt().arg("simulate").arg(small()).arg("-o").arg("/proc/vmt-test-output").output().unwrap();
    assert_eq!(o.status.code(), Some(3), "{}", String::from_utf8_lossy(&o.stderr));
}

/// Issue 13: `--effect` lists the effect names, in `vmt add --help` and in the error for an unknown name
/// (exit 2); every name of the effect catalogue is listed.
#[test]
fn add_lists_the_effect_names_in_help_and_in_the_error() {
    let help = ok(vmt().args(["add", "--help"]).output().unwrap(), "vmt add --help");
    let o = vmt().args(["add", "--model", "m.toml", "--effect", "backlsh", "-o", "out.toml"]).output().unwrap();
    assert_eq!(o.status.code(), Some(2));
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(err.contains("backlsh"), "{err}");
    for name in vmt_sim::effects::EffectName::ALL {
        let listed = |text: &str| {
            text.contains(&format!(" {},", name.as_str())) || text.contains(&format!(" {}]", name.as_str()))
        };
        assert!(listed(&help), "`{}` not listed in vmt add --help:\n{help}", name.as_str());
        assert!(listed(&err), "`{}` not listed in the error:\n{err}", name.as_str());
    }
}

/// Issue 13: what a person reads cites no document that is not in the repository (FORMAT.md,
/// DESIGN.md, the seed texts as "seed 00N"): methods are named by their source and the formats and
/// methods by docs/formats.md and docs/methods.md. Read: `vmt --help` and every command's help, the
/// README, docs/, the bundled scenarios (comments and descriptions: `vmt run` prints the description),
/// the golden `vmt run` outputs, and every string literal of the release code (messages, report text).
#[test]
fn no_user_facing_text_cites_a_document_outside_the_repository() {
    const OUTSIDE: [&str; 5] = ["FORMAT.md", "DESIGN.md", "seed 00", "seed-00", "seeds/"];
    let mut texts: Vec<(String, String)> = Vec::new();
    let (help, commands) = help_and_commands();
    for c in &commands {
        texts.push((format!("vmt {c} --help"), ok(vmt().args([c.as_str(), "--help"]).output().unwrap(), c)));
    }
    texts.push(("vmt --help".into(), help));
    let mut files = vec![root().join("README.md"), root().join("scenarios/lessons/README.md")];
    for dir in ["docs", "scenarios", "tests/golden/run", "examples"] {
        let mut stack = vec![root().join(dir)];
        while let Some(d) = stack.pop() {
            for e in std::fs::read_dir(&d).unwrap().flatten() {
                let p = e.path();
                if p.is_dir() {
                    stack.push(p);
                } else if p.extension().is_some_and(|x| ["md", "toml", "txt", "py"].contains(&x.to_str().unwrap_or("")))
                {
                    files.push(p);
                }
            }
        }
    }
    for p in files {
        texts.push((p.display().to_string(), std::fs::read_to_string(&p).unwrap()));
    }
    // String literals of the release code: lines that are not comments and hold a quote.
    let mut sources = Vec::new();
    for dir in ["src", "sim/src", "estimators/src", "report/src", "core/src"] {
        crate::util::rust_files(&root().join(dir), &mut sources);
    }
    for p in sources {
        let code: String = std::fs::read_to_string(&p)
            .unwrap()
            .lines()
            .filter(|l| !l.trim_start().starts_with("//") && l.contains('"'))
            .map(|l| format!("{l}\n"))
            .collect();
        texts.push((p.display().to_string(), code));
    }
    let mut found = Vec::new();
    for (what, text) in &texts {
        for (i, line) in text.lines().enumerate() {
            if let Some(w) = OUTSIDE.iter().find(|w| line.contains(*w)) {
                found.push(format!("{what}, line {}: `{w}` in {}", i + 1, line.trim()));
            }
        }
    }
    assert!(found.is_empty(), "{} lines cite a document outside the repository:\n{}", found.len(), found.join("\n"));
}
