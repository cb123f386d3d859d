//! The model-check loop on time series (issue 19), tested on data from independent generators
//! (`tests/gen_timeseries`): accelerometer passes and encoder logs of a ball-screw axis, written in
//! the FORMAT.md contract and run through the `vmt` binary (`diagnose --json`, `add`,
//! `compare --json`) over many draws in parallel; results are rates over draws.

use crate::gen_timeseries::*;
use rayon::prelude::*;
use std::path::{Path, PathBuf};

fn vmt(args: &[&str]) -> Result<serde_json::Value, String> {
    let out = crate::util::vmt().args(args).output().map_err(|e| e.to_string())?;
    if !out.status.success() {
        return Err(format!("exit {:?}: {}", out.status.code(), String::from_utf8_lossy(&out.stderr).trim()));
    }
    serde_json::from_slice(&out.stdout).map_err(|e| e.to_string())
}

fn s(p: &Path) -> &str {
    p.to_str().unwrap()
}

/// The outcome of one draw through the loop: diagnose the starting model, add the first candidate
/// (when one is significant), compare again.
#[derive(Debug, Clone)]
pub struct Outcome {
    pub nrms_before: f64,
    /// First entry: (effect, verdict, params).
    pub first: Option<(String, String, serde_json::Value)>,
    pub any_significant: bool,
    pub nrms_after: Option<f64>,
    /// Fitted parameters of the added effect after `add` + `compare`.
    pub fitted_after: Option<serde_json::Value>,
    pub seconds: f64,
    pub error: Option<String>,
}

/// Runs the loop on the set in `dir` (with `dir/model.toml`): diagnose; when `add` and the first
/// candidate is significant, `vmt add --from-diagnosis` then compare.
pub fn run_loop(dir: &Path, add: bool) -> Outcome {
    let t0 = std::time::Instant::now();
    let model = dir.join("model.toml");
    let mut o = Outcome {
        nrms_before: f64::NAN,
        first: None,
        any_significant: false,
        nrms_after: None,
        fitted_after: None,
        seconds: 0.0,
        error: None,
    };
    let diag_path = dir.join("diagnosis.json");
    let d = match vmt(&["diagnose", "--model", s(&model), "--data", s(dir), "--json"]) {
        Ok(d) => d,
        Err(e) => {
            o.error = Some(e);
            o.seconds = t0.elapsed().as_secs_f64();
            return o;
        }
    };
    std::fs::write(&diag_path, d.to_string()).unwrap();
    o.nrms_before = d["normalized_rms"].as_f64().unwrap_or(f64::NAN);
    let ranking = d["ranking"].as_array().cloned().unwrap_or_default();
    o.any_significant = ranking.iter().any(|r| r["verdict"] == "significant");
    if let Some(r) = ranking.first() {
        o.first = Some((
            r["effect"].as_str().unwrap_or("").to_string(),
            r["verdict"].as_str().unwrap_or("").to_string(),
            r["params"].clone(),
        ));
    }
    if add {
        if let Some((eff, verdict, _)) = &o.first {
            if verdict == "significant" {
                // Outside the data directory: vmt refuses to write into its input.
                let m2 = dir.with_extension("models").join("model2.toml");
                std::fs::create_dir_all(m2.parent().unwrap()).unwrap();
                let added = crate::util::vmt()
                    .args(["add", "--model", s(&model), "--effect", eff, "--from-diagnosis", "--data", s(dir)])
                    .args(["-o", s(&m2)])
                    .output()
                    .unwrap();
                if added.status.success() {
                    match vmt(&["compare", "--model", s(&m2), "--data", s(dir), "--json"]) {
                        Ok(c) => {
                            o.nrms_after = c["normalized_rms"].as_f64();
                            o.fitted_after = Some(c["fitted"][eff.as_str()].clone());
                        }
                        Err(e) => o.error = Some(e),
                    }
                } else {
                    o.error = Some(String::from_utf8_lossy(&added.stderr).to_string());
                }
            }
        }
    }
    o.seconds = t0.elapsed().as_secs_f64();
    o
}

fn workdir(tag: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("vmt_ts_{tag}_{}", std::process::id()));
    std::fs::create_dir_all(&d).unwrap();
    d
}

/// Percentage helper.
fn rate(k: usize, n: usize) -> f64 {
    100.0 * k as f64 / n.max(1) as f64
}

// ------------------------------------------------------------------------------------------
// The generators themselves (fast, always run).

/// The encoder generator's physics, checked on its own files: in a semi-closed loop without
/// feed-forward the motor lags the command by v/kv in a settled cruise (P loop: ẋ = kv·e), and the
/// scale shows the same lag plus the screw's error (no play in a one-way cruise).
#[test]
fn encoder_generator_following_error_is_v_over_kv() {
    let tmp = tempfile::tempdir().unwrap();
    let mut checked = 0;
    for seed in 0..8u64 {
        let dir = tmp.path().join(format!("e{seed}"));
        let t = encoder_set(&dir, seed, EncoderHidden::None);
        let text = std::fs::read_to_string(dir.join("pass_1.csv")).unwrap();
        let rows: Vec<Vec<f64>> =
            text.lines().skip(1).map(|l| l.split(',').map(|c| c.parse().unwrap()).collect()).collect();
        let man = std::fs::read_to_string(dir.join("manifest.toml")).unwrap();
        let feed: f64 = man.lines().find(|l| l.starts_with("feed")).unwrap()[7..].trim().parse().unwrap();
        // Motor − command, µm: mean over the cruise.
        let lag: f64 = rows.iter().map(|r| r[3] - r[1] * 1e3).sum::<f64>() / rows.len() as f64;
        let dirn = if rows.last().unwrap()[1] > rows[0][1] { 1.0 } else { -1.0 };
        let expect = -dirn * feed / t.kv * 1e6;
        if t.feedback == Loop::SemiClosed {
            // 0.5 %: the discrete loop's lag differs from the continuous v/kv by kv·h/2 ≤ 3 %·… at
            // 1 kHz and kv 60 (half a tick of velocity): v·h/2 against v/kv.
            let tol = 0.5e-2 * expect.abs() + 0.5 * feed * 1e-3 * 1e6;
            assert!((lag - expect).abs() <= tol, "seed {seed}: lag {lag:.3} µm, v/kv {expect:.3} µm");
            checked += 1;
        }
    }
    assert!(checked >= 2, "semi-closed draws checked: {checked}");
}

/// A complete encoder model on controller traces whose seconds are written to 3–4 decimals
/// ([`ROUNDED_TRACE`]: draws 2000, 2005 and 2011 have a 4 kHz servo, so their 5.75, 1.25 and
/// 8.25 ms log intervals are rounded by up to half of 1 ms, 0.1 ms and 1 ms, and 2 % of rows are
/// lost) fits to the noise: normalised RMS ≤ 1.1 (the manifest states the true σ, and a right
/// model leaves ≤ 1). Read at the stamps, the following error's input moved with them and the
/// three gave 188, 363 and 268; vmt now reads the stamps as the regular clock they round
/// (`vmt::modelcheck::regular_clock`) and says so in a note.
#[test]
fn encoder_complete_model_on_a_rounded_trace_fits_to_the_noise() {
    complete_encoder_on(ROUNDED_TRACE, &[2000, 2005, 2011], "regular clock of period");
}

/// The same on traces whose stamps a host wrote with jitter ([`JITTERED_TRACE`]: σ 18.9, 1.0 and
/// 1.9 µs on draws 2000, 2001 and 2005, 2 % of rows lost). Read at the stamps they gave normalised
/// RMS 39.4, 10.8 and 26.8; vmt now reads them at the regular clock the command follows
/// (`vmt::modelcheck::ticked_clock`) and says so in a note.
#[test]
fn encoder_complete_model_on_a_jittered_trace_fits_to_the_noise() {
    complete_encoder_on(JITTERED_TRACE, &[2000, 2001, 2005], "its command follows the clock's ticks");
}

/// A jittered trace (draw 2001: σ 1.0 µs, closed loop, 1 kHz servo) whose command is written to
/// 0.1 µm (4 decimals of mm, as controller exports print it): the passes' commands (v·σ ≈ 50 nm)
/// cannot tell the clock from the stamps, the crawls' can, and the passes follow them because
/// their stamps scatter alike (`vmt::modelcheck::TICKED_ALIKE`). Read at the stamps the passes
/// left normalised RMS 10.9; now 1.08 (the same draw with exact stamps and the same command gives
/// 1.08: the command's rounding, not the clock).
#[test]
fn encoder_complete_model_on_a_jittered_trace_with_a_coarse_command() {
    let (nrms, followed) = rewritten(2001, JITTERED_TRACE, 1, 4, "its own command cannot tell");
    assert!(nrms <= 1.1 && followed >= 2, "normalised RMS {nrms:.3}, runs that followed the set's clocks {followed}");
}

/// Complete models on encoder draws 2000 and 2011 (closed and semi-closed loop) whose command is
/// written as a controller's export prints it: the rounding reaches every predicted reading
/// through the following error's lag, at 3–20 nm of noise. Read as written, normalised RMS 1.149
/// and 1.323 at 0.1 µm (4 decimals of mm), 6.13 and 10.7 at 1 µm (3 decimals). Read as the smooth
/// profile the values round (`vmt::modelcheck` `smooth_command`, said in a note in every run):
/// 0.987 and 0.991 at 0.1 µm, 0.980 and 0.989 at 1 µm, each held to ≤ 1.1. And draw 2071 at 1 µm
/// (closed loop, a slow reversal of 537 rows whose ends the rows leave open by 0.1–0.2 q): 1.429
/// before the profile's reading uncertainty was counted in the following channel's σ (the fit
/// bent kv and 52 shape orders to those ends), 0.996 since.
#[test]
fn encoder_complete_model_on_a_command_written_as_an_export_prints_it() {
    for (seed, decimals, limit) in [(2000, 4, 1.1), (2011, 4, 1.1), (2000, 3, 1.1), (2011, 3, 1.1), (2071, 3, 1.1)] {
        let (nrms, read) = rewritten(seed, Trace::Exact, 1, decimals, "is read as the smooth profile");
        assert!(
            nrms <= limit && read >= 5,
            "draw {seed}, {decimals} decimals: normalised RMS {nrms:.3}, runs read smooth {read}"
        );
    }
}

/// A jittered trace (draw 2005: σ 1.9 µs, 1.25 ms rows) whose stamps are written to 10 µs (5
/// decimals): most stamps are then exact and about 1 % are 10 µs off, which no rounded clock
/// admits and the median of the command's roughness does not see. Read at the stamps a complete
/// model gave normalised RMS 12.7; the mean of the roughness sees them, and it is ≤ 1.1 with the
/// clock noted.
#[test]
fn encoder_complete_model_on_a_jittered_trace_with_coarse_stamps() {
    let (nrms, on_clock) = rewritten(2005, JITTERED_TRACE, 0, 5, "scatter about a regular clock");
    assert!(nrms <= 1.1 && on_clock >= 2, "normalised RMS {nrms:.3}, runs read at a clock {on_clock}");
}

/// A complete model on encoder draw 2005 (a 4 kHz servo, 1.25 ms rows) whose clock counts Unix
/// epoch seconds (1.7 × 10⁹ s, where an f64 steps by 0.24 µs): the stamps written to 1 µs in
/// the `t` column (start times 0), and the run starts in the manifest (`t` from each start).
/// Normalised RMS ≤ 1.1 both ways, as with its own stamps (0.998); before the reader counted
/// such times from their first whole second, 1.381 both ways (the rows' intervals off by up to
/// 0.24 µs, v·δ up to 24 nm against 3–20 nm of noise).
#[test]
fn encoder_complete_model_on_epoch_second_stamps_fits_to_the_noise() {
    const EPOCH: f64 = 1_733_400_000.0;
    for in_manifest in [false, true] {
        let tmp = tempfile::tempdir().unwrap();
        let dir = tmp.path().join("e2005");
        encoder_set_traced(&dir, 2005, EncoderHidden::None, None, Trace::Exact);
        let manifest = std::fs::read_to_string(dir.join("manifest.toml")).unwrap();
        let mut out = String::new();
        let (mut start, mut file) = (0.0, String::new());
        for line in manifest.lines() {
            if let Some(f) = line.strip_prefix("file = ") {
                file = f.trim_matches('"').to_string();
            }
            if let Some(v) = line.strip_prefix("start_time = ") {
                // The generator writes each run's `file` before its `start_time`.
                start = v.parse::<f64>().unwrap();
                let text = std::fs::read_to_string(dir.join(&file)).unwrap();
                let mut lines = text.lines();
                let mut csv = format!("{}\n", lines.next().unwrap());
                for row in lines {
                    let (t, rest) = row.split_once(',').unwrap();
                    let t = t.parse::<f64>().unwrap() + if in_manifest { 0.0 } else { EPOCH + start };
                    csv.push_str(&format!("{t:.6},{rest}\n"));
                }
                std::fs::write(dir.join(&file), csv).unwrap();
                let shown = if in_manifest { EPOCH + start } else { 0.0 };
                out.push_str(&format!("start_time = {shown:?}\n"));
            } else {
                out.push_str(&format!("{line}\n"));
            }
        }
        assert!(start > 0.0, "the draw's runs have start times");
        std::fs::write(dir.join("manifest.toml"), out).unwrap();
        let c = vmt(&["compare", "--model", s(&dir.join("model.toml")), "--data", s(&dir), "--json"]).unwrap();
        let nrms = c["normalized_rms"].as_f64().unwrap_or(f64::NAN);
        assert!(nrms <= 1.1, "epoch stamps (in the manifest: {in_manifest}): normalised RMS {nrms:.4}");
    }
}

/// `vmt compare` of the complete model of encoder draw `seed` written by `trace` with column `col`
/// of every CSV rewritten with `decimals` decimals (as an export that prints fewer digits writes
/// it): the normalised RMS and the number of notes that contain `noted`.
fn rewritten(seed: u64, trace: Trace, col: usize, decimals: usize, noted: &str) -> (f64, usize) {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join(format!("e{seed}"));
    encoder_set_traced(&dir, seed, EncoderHidden::None, None, trace);
    for entry in std::fs::read_dir(&dir).unwrap() {
        let path = entry.unwrap().path();
        if path.extension().is_some_and(|e| e == "csv") {
            let text = std::fs::read_to_string(&path).unwrap();
            let mut lines = text.lines();
            let mut out = format!("{}\n", lines.next().unwrap());
            for line in lines {
                let mut cells: Vec<String> = line.split(',').map(str::to_string).collect();
                cells[col] = format!("{:.*}", decimals, cells[col].parse::<f64>().unwrap());
                out.push_str(&format!("{}\n", cells.join(",")));
            }
            std::fs::write(&path, out).unwrap();
        }
    }
    let c = vmt(&["compare", "--model", s(&dir.join("model.toml")), "--data", s(&dir), "--json"]).unwrap();
    let notes = c["notes"].as_array().unwrap().iter().filter_map(|v| v.as_str()).filter(|n| n.contains(noted)).count();
    (c["normalized_rms"].as_f64().unwrap_or(f64::NAN), notes)
}

/// `vmt compare` of the complete model of encoder draws `seeds` written by `trace`: normalised RMS
/// ≤ 1.1 and a note containing `noted` in each.
fn complete_encoder_on(trace: Trace, seeds: &[u64], noted: &str) {
    let tmp = tempfile::tempdir().unwrap();
    let out: Vec<(u64, EncoderTruth, Result<serde_json::Value, String>)> = seeds
        .par_iter()
        .map(|&seed| {
            let dir = tmp.path().join(format!("e{seed}"));
            let t = encoder_set_traced(&dir, seed, EncoderHidden::None, None, trace);
            (seed, t, vmt(&["compare", "--model", s(&dir.join("model.toml")), "--data", s(&dir), "--json"]))
        })
        .collect();
    for (seed, t, r) in out {
        let c = r.unwrap_or_else(|e| panic!("draw {seed}: {e}"));
        let nrms = c["normalized_rms"].as_f64().unwrap_or(f64::NAN);
        let note =
            c["notes"].as_array().is_some_and(|n| n.iter().any(|v| v.as_str().is_some_and(|s| s.contains(noted))));
        assert!(
            nrms <= 1.1 && note,
            "draw {seed} (stamps to {:?} s, jitter {:e} s): normalised RMS {nrms:.3}, clock noted {note}",
            t.stamp_resolution,
            t.stamp_jitter
        );
    }
}

/// An accelerometer set of the generator is read by vmt (FORMAT.md §1) and its hidden effects are
/// drawn visible (χ² of their contribution ≥ 200).
#[test]
fn accelerometer_generator_writes_a_readable_set() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("a");
    let t = accel_set(&dir, 3, AccelHidden::ResonanceAndRoll, 200.0);
    assert!(t.hidden_chi2 >= 200.0, "hidden effects visible: χ² {}", t.hidden_chi2);
    // vmt reads the set (FORMAT.md §1): compare runs on it.
    let c = vmt(&["compare", "--model", s(&dir.join("model.toml")), "--data", s(&dir), "--json"]);
    assert!(c.is_ok(), "{c:?}");
}

// ------------------------------------------------------------------------------------------
// Rates over draws (the "must show"). Each prints its rates; run with
// `cargo test --release --test tests model_check_timeseries:: -- --ignored --nocapture`.

/// The loop on `draws` sets of a generator (`make(dir, draw)` writes one into `dir` and returns its
/// truth) below the work folder `tag`, in parallel, one line per draw printed:
/// `{label} draw {seed}: {describe(truth)}; …`.
fn loop_rates<T: Send>(
    tag: &str,
    label: &str,
    draws: u64,
    add: bool,
    make: impl Fn(&Path, u64) -> T + Sync,
    describe: impl Fn(&T) -> String + Sync,
) -> Vec<(T, Outcome)> {
    let root = workdir(tag);
    draw_range(draws)
        .into_par_iter()
        .map(|seed| {
            let dir = root.join(format!("d{seed}"));
            let t = make(&dir, seed);
            let o = run_loop(&dir, add);
            eprintln!(
                "{label} draw {seed}: {}; nrms {:.2} first {:?} after {:?} ({:.1} s) fitted after {} {}",
                describe(&t),
                o.nrms_before,
                o.first.as_ref().map(|f| (&f.0, &f.1)),
                o.nrms_after,
                o.seconds,
                o.fitted_after.as_ref().map_or("-".to_string(), |v| v.to_string()),
                o.error.clone().unwrap_or_default()
            );
            (t, o)
        })
        .collect()
}

/// A logger's clock ([`Clock::Logger`]): 0.5 µs of jitter on each sampling instant, stamps of 1 µs.
const LOGGER: Clock = Clock::Logger { jitter: 0.5e-6, resolution: 1e-6, lost: 0.0 };

/// [`LOGGER`] losing 2 % of its samples (a wireless or USB logger dropping packets): the gaps of
/// one, two, … sample intervals that the model check must not read as longer averages.
const LOSSY_LOGGER: Clock = Clock::Logger { jitter: 0.5e-6, resolution: 1e-6, lost: 0.02 };

/// [`LOGGER`] stamping to the nanosecond: no two intervals alike, so every interval's mode map is
/// had from a built one's Taylor tables (the benchmark's `res15000_jitter`); at 1 µs a few
/// interval lengths recur and their maps are kept.
const NS_LOGGER: Clock = Clock::Logger { jitter: 0.5e-6, resolution: 1e-9, lost: 0.0 };

fn accel_rates(hidden: AccelHidden, draws: u64, add: bool, clock: Clock) -> Vec<(AccelTruth, Outcome)> {
    let on = match clock {
        Clock::Even => "",
        Clock::Logger { lost, .. } if lost > 0.0 => "LossyLogger",
        Clock::Logger { resolution, .. } if resolution < 1e-6 => "NsLogger",
        Clock::Logger { .. } => "Logger",
    };
    loop_rates(
        &format!("acc{hidden:?}{on}"),
        &format!("{hidden:?}{on}"),
        draws,
        add,
        |dir, seed| accel_set_clocked(dir, 1000 + seed, hidden, 200.0, None, clock),
        |t| format!("{} samples, ρ {:.2} µg/√Hz, mode {:?}", t.samples, t.density / G * 1e6, t.mode),
    )
}

/// A controller trace exported with its seconds rounded to 3–6 decimals ([`Trace::Rounded`]: at
/// most a quarter of the shortest log interval) and 2 % of its rows lost.
const ROUNDED_TRACE: Trace = Trace::Rounded { lost: 0.02 };

/// A controller trace whose rows a host stamps with jitter of 0.3–30 µs ([`Trace::Jittered`]: the
/// readings at the servo's ticks, the stamps off them) and 2 % of its rows lost.
const JITTERED_TRACE: Trace = Trace::Jittered { lost: 0.02 };

/// A controller trace whose command column is written in mm to 4 decimals (0.1 µm,
/// [`Trace::CoarseCommand`]), rows and times exact.
const COARSE_COMMAND: Trace = Trace::CoarseCommand { decimals: 4 };

/// A trace whose command is written to 1 µm (3 decimals of mm).
const MICROMETRE_COMMAND: Trace = Trace::CoarseCommand { decimals: 3 };

fn encoder_rates(hidden: EncoderHidden, draws: u64, add: bool, trace: Trace) -> Vec<(EncoderTruth, Outcome)> {
    let on = match trace {
        Trace::Exact => "",
        Trace::Rounded { .. } => "RoundedTrace",
        Trace::Jittered { .. } => "JitteredTrace",
        Trace::CoarseCommand { .. } => "CoarseCommand",
    };
    loop_rates(
        &format!("enc{hidden:?}{on}"),
        &format!("{hidden:?}{on}"),
        draws,
        add,
        |dir, seed| encoder_set_traced(dir, 2000 + seed, hidden, None, trace),
        |t| {
            format!(
                "{} samples, {:?}, backlash {:.4e} m, lead {:.4e} m, interpolation period {:.4e} m",
                t.samples, t.feedback, t.backlash, t.lead, t.interp_period
            )
        },
    )
}

/// The complete accelerometer model (straightness y and z fitted, nothing else present) on 3
/// fixed draws of the generator (3 passes, 5 000–9 000 samples, waviness of 4–40 mm that only a
/// flexible shape fits): normalised RMS ≤ 1.1 × the ideal, which is ≤ 1 here (the manifest states
/// the generator's true σ, and a right model leaves √(1 − p/n) of it), so ≤ 1.1 on every draw.
/// Before the flexible shapes (a cubic) the first draw gave 14.7. The rate over 20 draws is in the
/// report of issue 19 (`accel_complete_model_false_alarms`, ignored).
#[test]
fn accel_complete_model_fits_to_the_noise() {
    let tmp = tempfile::tempdir().unwrap();
    let out: Vec<(u64, Result<f64, String>)> = (0..3u64)
        .into_par_iter()
        .map(|k| {
            let dir = tmp.path().join(format!("a{k}"));
            accel_set(&dir, 1000 + k, AccelHidden::None, 0.0);
            let c = vmt(&["compare", "--model", s(&dir.join("model.toml")), "--data", s(&dir), "--json"]);
            (k, c.map(|c| c["normalized_rms"].as_f64().unwrap_or(f64::NAN)))
        })
        .collect();
    for (k, r) in out {
        let nrms = r.unwrap_or_else(|e| panic!("draw {k}: {e}"));
        assert!(nrms <= 1.1, "draw {k}: normalised RMS {nrms:.3} of the complete model (≤ 1.1 × ideal ≤ 1)");
    }
}

/// One draw of the joint mode-fit test: its seed, the true (frequency Hz, damping), and the diagnose JSON or
/// why it failed.
type DrawOutcome = (u64, (f64, f64), Result<serde_json::Value, String>);

/// A mode fitted together with the shapes that drive it (src/modelcheck/coupled.rs), on 2 draws
/// of the generator with a hidden structural mode (frequency 20–80 Hz, damping 0.5–5 %, random
/// mode shape in the y–z plane), the model given `resonance` with a starting frequency 25 % off and
/// damping 2 % (as a wrong diagnosis would): `compare` must find the frequency within 1 % and the
/// damping within 10 % (the thresholds) and leave normalised RMS ≤ 1.3 (the manifest states
/// the true σ). The sequential fit (shapes first, then the mode driven by them) missed all four
/// draws of the last report (52.2 Hz for 38.13, 84.5 for 72.22). The rate over many draws is
/// `accel_hidden_resonance` (ignored).
#[test]
fn accel_mode_fitted_with_its_shapes() {
    let tmp = tempfile::tempdir().unwrap();
    let out: Vec<DrawOutcome> = [1001u64, 1002]
        .into_par_iter()
        .map(|seed| {
            let dir = tmp.path().join(format!("r{seed}"));
            let t = accel_set(&dir, seed, AccelHidden::Resonance, 200.0);
            let (f, z) = t.mode.unwrap();
            let model = dir.with_extension("toml");
            let text = std::fs::read_to_string(dir.join("model.toml")).unwrap();
            std::fs::write(
                &model,
                format!("{text}[effects.resonance]\nfit = true\nfrequency = {:?}\ndamping = 0.02\n", f * 1.25),
            )
            .unwrap();
            (seed, (f, z), vmt(&["compare", "--model", s(&model), "--data", s(&dir), "--json"]))
        })
        .collect();
    for (seed, (f, z), r) in out {
        let c = r.unwrap_or_else(|e| panic!("seed {seed}: {e}"));
        let nrms = c["normalized_rms"].as_f64().unwrap_or(f64::NAN);
        let fa = c["fitted"]["resonance"]["frequency"].as_f64().unwrap_or(f64::NAN);
        let za = c["fitted"]["resonance"]["damping"].as_f64().unwrap_or(f64::NAN);
        assert!(
            (fa / f - 1.0).abs() <= 0.01 && (za / z - 1.0).abs() <= 0.10 && nrms <= 1.3,
            "seed {seed}: mode {f:.3} Hz ζ {z:.4}, fitted {fa:.3} Hz ζ {za:.4}, normalised RMS {nrms:.3}"
        );
    }
}

/// Complete accelerometer models: the share of draws with any `significant` claim (goal ≤ 2 %).
#[test]
#[ignore = "rate study; prints the measured rates (see the report of issue 19)"]
fn accel_complete_model_false_alarms() {
    complete_accel(Clock::Even);
}

/// [`accel_complete_model_false_alarms`] on a logger's clock ([`LOGGER`]: every interval its own).
#[test]
#[ignore = "rate study; prints the measured rates (see the report of issue 19)"]
fn accel_complete_model_false_alarms_on_a_loggers_clock() {
    complete_accel(LOGGER);
}

/// [`accel_complete_model_false_alarms`] on a logger that loses 2 % of its samples
/// ([`LOSSY_LOGGER`]).
#[test]
#[ignore = "rate study; prints the measured rates (see the report of issue 19)"]
fn accel_complete_model_false_alarms_on_a_lossy_logger() {
    complete_accel(LOSSY_LOGGER);
}

/// [`accel_complete_model_false_alarms`] on a logger that stamps to the nanosecond ([`NS_LOGGER`]).
#[test]
#[ignore = "rate study; prints the measured rates (see the report of issue 19)"]
fn accel_complete_model_false_alarms_on_a_nanosecond_logger() {
    complete_accel(NS_LOGGER);
}

/// Complete accelerometer models that state a tilt: the draws of `accel_hidden_roll` (a roll of
/// 2–20 µrad RMS and correlation length 0.15–0.6 m, seen through gravity), with `gravity_tilt` in
/// the model beside the two straightness shapes. Nothing is missing, so any `significant` claim is
/// a false alarm (at most 2 %), and the complete model's normalised RMS is ≤ 1.1 (the manifest
/// states the true σ). A tilt that cannot follow the roll leaves a misfit for a candidate to claim.
#[test]
#[ignore = "rate study; prints the measured rates (see the report of issue 19)"]
fn accel_complete_model_with_a_roll_false_alarms() {
    let r = loop_rates(
        "accRollStated",
        "RollStated",
        draws(100),
        false,
        |dir, seed| {
            let t = accel_set_clocked(dir, 1000 + seed, AccelHidden::Roll, 200.0, None, Clock::Even);
            write_model(&dir.join("model.toml"), &["straightness_y", "straightness_z", "gravity_tilt"]);
            t
        },
        |t| format!("{} samples, ρ {:.2} µg/√Hz", t.samples, t.density / G * 1e6),
    );
    assert_complete_rates("accelerometer complete with a stated tilt", r.iter().map(|x| &x.1).collect());
}

fn complete_accel(clock: Clock) {
    let r = accel_rates(AccelHidden::None, draws(100), false, clock);
    assert_complete_rates(&format!("accelerometer complete, clock {clock:?}"), r.iter().map(|x| &x.1).collect());
}

/// Complete models' outcomes: the share with any `significant` claim (at most 2 %, the issue's
/// rate) and no errors; printed with the normalised RMS of each complete model (its mean, its
/// largest, and how many exceed 1.1, the 1.1 × an ideal that is ≤ 1 here).
fn assert_complete_rates(what: &str, r: Vec<&Outcome>) {
    let n = r.len();
    let errors = r.iter().filter(|o| o.error.is_some()).count();
    let fa = r.iter().filter(|o| o.any_significant).count();
    let nrms: Vec<f64> = r.iter().map(|o| o.nrms_before).collect();
    let high = nrms.iter().filter(|v| **v > 1.1).count();
    eprintln!(
        "{what}: {fa}/{n} with a significant claim ({:.1} %), {errors} errors; normalised RMS mean {:.3}, largest \
         {:.3}, {high}/{n} above 1.1",
        rate(fa, n),
        nrms.iter().sum::<f64>() / n.max(1) as f64,
        nrms.iter().copied().fold(0.0, f64::max)
    );
    assert_eq!(errors, 0);
    assert!(rate(fa, n) <= 2.0);
}

/// The number of draws of a rate study: `VMT_DRAWS`, else `default`.
fn draws(default: u64) -> u64 {
    std::env::var("VMT_DRAWS").ok().and_then(|v| v.parse().ok()).unwrap_or(default)
}

/// The draw numbers of a rate study of `n` draws: `VMT_DRAW_FROM..VMT_DRAW_FROM + n` (from 0 unless
/// set), so that a long study can be finished in parts with the same draws (each draw's seed is
/// fixed by its number).
fn draw_range(n: u64) -> std::ops::Range<u64> {
    let from: u64 = std::env::var("VMT_DRAW_FROM").ok().and_then(|v| v.parse().ok()).unwrap_or(0);
    from..from + n
}

fn hidden_accel(h: AccelHidden, expect: &str, clock: Clock) {
    let n = draws(30);
    let r = accel_rates(h, n, true, clock);
    let named = r.iter().filter(|x| x.1.first.as_ref().is_some_and(|f| f.0 == expect && f.1 == "significant")).count();
    let low = r.iter().filter(|x| x.1.nrms_after.is_some_and(|v| v <= 1.3)).count();
    // The mode fitted after `add` (compare's refined values) against the generator's: frequency
    // within 1 %, damping within 10 % (the thresholds). Each is met only where the data
    // determine it that well: the frequency of a draw is *resolvable* when 3× its Cramér–Rao bound
    // (`AccelTruth::mode_crb`, with the straightness profiled out) is inside 1 %, the damping when 3×
    // its bound is inside 10 %. Each assertion is on its resolvable draws; the rates over all draws
    // and each error in units of its bound are printed.
    let got = |o: &Outcome, k: &str| o.fitted_after.as_ref().and_then(|v| v[k].as_f64()).unwrap_or(f64::NAN);
    let f_ok = |t: &AccelTruth, o: &Outcome| t.mode.is_none_or(|(f, _)| (got(o, "frequency") / f - 1.0).abs() <= 0.01);
    let z_ok = |t: &AccelTruth, o: &Outcome| t.mode.is_none_or(|(_, z)| (got(o, "damping") / z - 1.0).abs() <= 0.10);
    let within = |t: &AccelTruth, o: &Outcome| f_ok(t, o) && z_ok(t, o);
    let f_res = |t: &AccelTruth| t.mode.zip(t.mode_crb).is_none_or(|((f, _), (sf, _))| 3.0 * sf <= 0.01 * f);
    let z_res = |t: &AccelTruth| t.mode.zip(t.mode_crb).is_none_or(|((_, z), (_, sz))| 3.0 * sz <= 0.10 * z);
    let fitted = r.iter().filter(|x| within(&x.0, &x.1)).count();
    let (n_f, n_z) = (r.iter().filter(|x| f_res(&x.0)).count(), r.iter().filter(|x| z_res(&x.0)).count());
    let f_fit = r.iter().filter(|x| f_res(&x.0) && f_ok(&x.0, &x.1)).count();
    let z_fit = r.iter().filter(|x| z_res(&x.0) && z_ok(&x.0, &x.1)).count();
    for (t, o) in &r {
        if let (Some((f, z)), Some((sf, sz))) = (t.mode, t.mode_crb) {
            let (fa, za) = (got(o, "frequency"), got(o, "damping"));
            eprintln!(
                "  mode {f:.2} Hz, ζ {z:.4} (CRB σ_f {:.3} %, σ_ζ {:.1} %{}): fitted {fa:.2} Hz, ζ {za:.4}; \
                 error {:+.2} σ_f, {:+.2} σ_ζ",
                100.0 * sf / f,
                100.0 * sz / z,
                match (f_res(t), z_res(t)) {
                    (true, true) => "",
                    (true, false) => ", ζ not resolvable to 10 %",
                    (false, true) => ", f not resolvable to 1 %",
                    (false, false) => ", f and ζ not resolvable to 1 % / 10 %",
                },
                (fa - f) / sf,
                (za - z) / sz
            );
        }
    }
    // The roll after `add` + `compare` against its bound (`AccelTruth::roll_crb`): the RMS over the
    // travel of the fitted tilt of acc_y minus the true roll, both with their mean removed (an offset
    // per pass hides it), within 2× the bound (the threshold).
    let roll_err = |t: &AccelTruth, o: &Outcome| -> Option<(f64, f64)> {
        let (roll, bound) = (t.roll.as_ref()?, t.roll_crb?);
        // The fitted tilt is the Legendre series Σ p_k·P_k(u), u = (2x − a − b)/(b − a) on
        // [tilt_x_lo, tilt_x_hi] (k from 1; P_k by Bonnet's recurrence, written here anew).
        let fitted = o.fitted_after.as_ref();
        let key = |k: &str| fitted.and_then(|v| v[k].as_f64());
        let coefs: Vec<f64> = (1..).map_while(|k| key(&format!("tilt_acc_y_p{k}"))).collect();
        let (a, b) = (key("tilt_x_lo").unwrap_or(0.0), key("tilt_x_hi").unwrap_or(1.0));
        let series = |x: f64| {
            let u = (2.0 * x - a - b) / (b - a);
            let (mut p0, mut p1, mut sum) = (1.0, u, 0.0);
            for (k, ck) in coefs.iter().enumerate() {
                sum += ck * p1;
                let n = (k + 1) as f64;
                (p0, p1) = (p1, ((2.0 * n + 1.0) * u * p1 - n * p0) / (n + 1.0));
            }
            sum
        };
        let (lo, hi) = t.travel;
        let xs: Vec<f64> = (0..400).map(|g| lo + (hi - lo) * (g as f64 + 0.5) / 400.0).collect();
        let diff: Vec<f64> = xs.iter().map(|&x| series(x) - roll.value(x)).collect();
        let mean = diff.iter().sum::<f64>() / diff.len() as f64;
        let rms = (diff.iter().map(|d| (d - mean).powi(2)).sum::<f64>() / diff.len() as f64).sqrt();
        Some((if coefs.is_empty() { f64::INFINITY } else { rms }, bound))
    };
    let rolls: Vec<(f64, f64)> = r.iter().filter_map(|(t, o)| roll_err(t, o)).collect();
    for (e, b) in &rolls {
        eprintln!("  roll: RMS error {:.3} µrad, bound {:.3} µrad ({:.2} × the bound)", e * 1e6, b * 1e6, e / b);
    }
    let roll_in = rolls.iter().filter(|(e, b)| e <= &(2.0 * b)).count();
    eprintln!(
        "accelerometer {h:?}, clock {clock:?}: `{expect}` first & significant {named}/{n} ({:.0} %), nrms ≤ 1.3 after add {low}/{n}, \
         mode within 1 % / 10 % {fitted}/{n}; f within 1 % on {f_fit} of the {n_f} draws whose bound allows it, ζ \
         within 10 % on {z_fit} of {n_z}; roll within 2 × its bound {roll_in}/{}",
        rate(named, n as usize),
        rolls.len()
    );
    assert!(rate(named, n as usize) >= 95.0 && rate(low, n as usize) >= 95.0);
    assert!(rate(f_fit, n_f) >= 95.0 && rate(z_fit, n_z) >= 95.0);
    assert!(rolls.is_empty() || rate(roll_in, rolls.len()) >= 95.0);
}

/// Complete encoder models (positioning + servo_lag): share with any `significant` claim.
#[test]
#[ignore = "rate study; prints the measured rates (see the report of issue 19)"]
fn encoder_complete_model_false_alarms() {
    complete_encoder(Trace::Exact);
}

/// [`encoder_complete_model_false_alarms`] on a rounded, lossy trace ([`ROUNDED_TRACE`]), with the
/// normalised RMS of each complete model (≤ 1.1 × its ideal, ≤ 1 here: the manifest states the
/// true σ).
#[test]
#[ignore = "rate study; prints the measured rates (see the report of issue 19)"]
fn encoder_complete_model_false_alarms_on_a_rounded_trace() {
    complete_encoder(ROUNDED_TRACE);
}

/// [`encoder_complete_model_false_alarms_on_a_rounded_trace`] on a jittered, lossy trace
/// ([`JITTERED_TRACE`]).
#[test]
#[ignore = "rate study; prints the measured rates (see the report of issue 19)"]
fn encoder_complete_model_false_alarms_on_a_jittered_trace() {
    complete_encoder(JITTERED_TRACE);
}

/// [`encoder_complete_model_false_alarms`] on a trace whose command is written to 0.1 µm
/// ([`COARSE_COMMAND`]).
#[test]
#[ignore = "rate study; prints the measured rates (see the report of issue 19)"]
fn encoder_complete_model_false_alarms_on_a_coarse_command() {
    complete_encoder(COARSE_COMMAND);
}

/// The same with the command written to 1 µm (3 decimals of mm, [`MICROMETRE_COMMAND`]). A command
/// rounded to 1 µm is known only to what its rows tell of the profile: a slow reversal's ends to
/// 0.1–0.2 q, against 3–20 nm of noise. Each value read carries that uncertainty into the
/// following channel's σ; before it did, 9 of 100 draws claimed a significant effect (all closed
/// loops: cyclic lead 6, backlash 3), with normalised RMS up to 1.69.
#[test]
#[ignore = "rate study; prints the measured rates (see the report of issue 19)"]
fn encoder_complete_model_false_alarms_on_a_micrometre_command() {
    complete_encoder(MICROMETRE_COMMAND);
}

fn complete_encoder(trace: Trace) {
    let r = encoder_rates(EncoderHidden::None, draws(100), false, trace);
    assert_complete_rates(&format!("encoder complete, trace {trace:?}"), r.iter().map(|x| &x.1).collect());
}

/// The value an encoder draw's hidden effect must be fitted to after `add` + `compare`, and the
/// relative error allowed (the thresholds: periods within 1 %, backlash within 10 %): (key
/// in `fitted`, true value, tolerance). None where the issue sets none (servo lag).
fn encoder_truth_value(t: &EncoderTruth, effect: &str) -> Option<(&'static str, f64, f64)> {
    match effect {
        "cyclic_lead" => Some(("period", t.lead, 0.01)),
        "interpolation_error" => Some(("period", t.interp_period, 0.01)),
        "backlash" => Some(("value", t.backlash, 0.10)),
        _ => None,
    }
}

fn hidden_encoder(h: EncoderHidden, expect: &str, trace: Trace) {
    let n = draws(30);
    let r = encoder_rates(h, n, true, trace);
    let errors = r.iter().filter(|x| x.1.error.is_some()).count();
    let named = r.iter().filter(|x| x.1.first.as_ref().is_some_and(|f| f.0 == expect && f.1 == "significant")).count();
    let low = r.iter().filter(|x| x.1.nrms_after.is_some_and(|v| v <= 1.3)).count();
    // The added effect's value against the generator's.
    let within = r
        .iter()
        .filter(|(t, o)| match encoder_truth_value(t, expect) {
            None => true,
            Some((key, truth, tol)) => {
                let got = o.fitted_after.as_ref().and_then(|v| v[key].as_f64()).unwrap_or(f64::NAN);
                eprintln!(
                    "  {expect} {key}: true {truth:.6e}, fitted {got:.6e} ({:+.2} %)",
                    100.0 * (got / truth - 1.0)
                );
                (got / truth - 1.0).abs() <= tol
            }
        })
        .count();
    eprintln!(
        "encoder {h:?}, trace {trace:?}: `{expect}` first & significant {named}/{n}, nrms ≤ 1.3 after add {low}/{n}, value within its \
         tolerance {within}/{n}, {errors} errors"
    );
    assert!(rate(named, n as usize) >= 95.0 && rate(low, n as usize) >= 95.0 && rate(within, n as usize) >= 95.0);
}

/// Two rounds of the loop: the effects added in order, the normalised RMS at the end, the final
/// compare's `fitted`, and an error.
type TwoRounds = (Vec<String>, Option<f64>, Option<serde_json::Value>, Option<String>);

/// Two hidden effects through the loop twice (diagnose → add the first significant candidate →
/// diagnose again → add → compare).
fn run_loop_twice(dir: &Path) -> TwoRounds {
    let mut model = dir.join("model.toml");
    let mut added: Vec<String> = Vec::new();
    for step in 0..2 {
        let d = match vmt(&["diagnose", "--model", s(&model), "--data", s(dir), "--json"]) {
            Ok(d) => d,
            Err(e) => return (added, None, None, Some(e)),
        };
        let first = d["ranking"].as_array().and_then(|a| a.first().cloned());
        let Some(first) = first.filter(|f| f["verdict"] == "significant") else { break };
        let eff = first["effect"].as_str().unwrap_or("").to_string();
        let next = dir.with_extension("models").join(format!("model{}.toml", step + 2));
        std::fs::create_dir_all(next.parent().unwrap()).unwrap();
        let out = crate::util::vmt()
            .args(["add", "--model", s(&model), "--effect", &eff, "--from-diagnosis", "--data", s(dir)])
            .args(["-o", s(&next)])
            .output()
            .unwrap();
        if !out.status.success() {
            return (added, None, None, Some(String::from_utf8_lossy(&out.stderr).to_string()));
        }
        added.push(eff);
        model = next;
    }
    match vmt(&["compare", "--model", s(&model), "--data", s(dir), "--json"]) {
        Ok(c) => (added, c["normalized_rms"].as_f64(), Some(c["fitted"].clone()), None),
        Err(e) => (added, None, None, Some(e)),
    }
}

/// Two hidden effects together: both named, one per round of the loop (in either order), and
/// normalised RMS ≤ 1.3 after both are added, each in ≥ 95 % of the draws (the rates).
fn hidden_pair<T: Send>(
    n: u64,
    make: impl Fn(&Path, u64) -> T + Sync,
    expect: [&str; 2],
    what: &str,
) -> Vec<(T, bool)> {
    let root = workdir(what);
    let r: Vec<(T, TwoRounds)> = draw_range(n)
        .into_par_iter()
        .map(|seed| {
            let dir = root.join(format!("d{seed}"));
            let t = make(&dir, seed);
            let o = run_loop_twice(&dir);
            eprintln!("{what} draw {seed}: added {:?}, nrms after {:?} {}", o.0, o.1, o.3.clone().unwrap_or_default());
            (t, o)
        })
        .collect();
    let both = |a: &[String]| a.len() == 2 && expect.iter().all(|e| a.iter().any(|x| x == e));
    let named = r.iter().filter(|x| both(&x.1 .0)).count();
    let low = r.iter().filter(|x| both(&x.1 .0) && x.1 .1.is_some_and(|v| v <= 1.3)).count();
    eprintln!("{what}: both named, one per round, {named}/{n}; nrms ≤ 1.3 after both {low}/{n}");
    assert!(rate(named, n as usize) >= 95.0 && rate(low, n as usize) >= 95.0);
    r.into_iter().map(|(t, o)| (t, both(&o.0))).collect()
}

#[test]
#[ignore = "rate study; prints the measured rates (see the report of issue 19)"]
fn accel_hidden_resonance_and_roll() {
    hidden_pair(
        draws(30),
        |dir, seed| accel_set(dir, 1000 + seed, AccelHidden::ResonanceAndRoll, 200.0),
        ["resonance", "gravity_tilt"],
        "accel_resonance_and_roll",
    );
}

/// [`accel_hidden_resonance_and_roll`] on a logger's clock ([`LOGGER`]).
#[test]
#[ignore = "rate study; prints the measured rates (see the report of issue 19)"]
fn accel_hidden_resonance_and_roll_on_a_loggers_clock() {
    hidden_pair(
        draws(30),
        |dir, seed| accel_set_clocked(dir, 1000 + seed, AccelHidden::ResonanceAndRoll, 200.0, None, LOGGER),
        ["resonance", "gravity_tilt"],
        "accel_resonance_and_roll_logger",
    );
}

#[test]
#[ignore = "rate study; prints the measured rates (see the report of issue 19)"]
fn encoder_hidden_cyclic_lead_and_backlash() {
    hidden_pair(
        draws(30),
        |dir, seed| encoder_set(dir, 2000 + seed, EncoderHidden::CyclicLeadAndBacklash),
        ["cyclic_lead", "backlash"],
        "encoder_cyclic_lead_and_backlash",
    );
}

/// Rate studies of one hidden effect, ignored by default (each prints its measured rates; see the report
/// of issue 19): `NAME => BODY;` is `#[test] #[ignore] fn NAME() { BODY; }`.
macro_rules! rate_studies {
    ($($name:ident => $body:expr;)*) => {$(
        #[test]
        #[ignore = "rate study; prints the measured rates (see the report of issue 19)"]
        fn $name() {
            $body;
        }
    )*};
}

rate_studies! {
    accel_hidden_resonance => hidden_accel(AccelHidden::Resonance, "resonance", Clock::Even);
    accel_hidden_resonance_on_a_loggers_clock => hidden_accel(AccelHidden::Resonance, "resonance", LOGGER);
    accel_hidden_roll => hidden_accel(AccelHidden::Roll, "gravity_tilt", Clock::Even);
    accel_hidden_roll_on_a_loggers_clock => hidden_accel(AccelHidden::Roll, "gravity_tilt", LOGGER);
    accel_hidden_resonance_on_a_lossy_logger => hidden_accel(AccelHidden::Resonance, "resonance", LOSSY_LOGGER);
    accel_hidden_resonance_on_a_nanosecond_logger => hidden_accel(AccelHidden::Resonance, "resonance", NS_LOGGER);
    accel_hidden_roll_on_a_lossy_logger => hidden_accel(AccelHidden::Roll, "gravity_tilt", LOSSY_LOGGER);
    encoder_hidden_interpolation_error => hidden_encoder(EncoderHidden::InterpolationError, "interpolation_error", Trace::Exact);
    encoder_hidden_cyclic_lead => hidden_encoder(EncoderHidden::CyclicLead, "cyclic_lead", Trace::Exact);
    encoder_hidden_backlash => hidden_encoder(EncoderHidden::Backlash, "backlash", Trace::Exact);
    encoder_hidden_servo_lag => hidden_encoder(EncoderHidden::ServoLag, "servo_lag", Trace::Exact);
    encoder_hidden_interpolation_error_on_a_rounded_trace =>
        hidden_encoder(EncoderHidden::InterpolationError, "interpolation_error", ROUNDED_TRACE);
    encoder_hidden_cyclic_lead_on_a_rounded_trace => hidden_encoder(EncoderHidden::CyclicLead, "cyclic_lead", ROUNDED_TRACE);
    encoder_hidden_backlash_on_a_rounded_trace => hidden_encoder(EncoderHidden::Backlash, "backlash", ROUNDED_TRACE);
    encoder_hidden_servo_lag_on_a_rounded_trace => hidden_encoder(EncoderHidden::ServoLag, "servo_lag", ROUNDED_TRACE);
    encoder_hidden_interpolation_error_on_a_jittered_trace =>
        hidden_encoder(EncoderHidden::InterpolationError, "interpolation_error", JITTERED_TRACE);
    encoder_hidden_cyclic_lead_on_a_jittered_trace => hidden_encoder(EncoderHidden::CyclicLead, "cyclic_lead", JITTERED_TRACE);
    encoder_hidden_backlash_on_a_jittered_trace => hidden_encoder(EncoderHidden::Backlash, "backlash", JITTERED_TRACE);
    encoder_hidden_servo_lag_on_a_jittered_trace => hidden_encoder(EncoderHidden::ServoLag, "servo_lag", JITTERED_TRACE);
    encoder_hidden_interpolation_error_on_a_coarse_command =>
        hidden_encoder(EncoderHidden::InterpolationError, "interpolation_error", COARSE_COMMAND);
    encoder_hidden_cyclic_lead_on_a_coarse_command => hidden_encoder(EncoderHidden::CyclicLead, "cyclic_lead", COARSE_COMMAND);
    encoder_hidden_backlash_on_a_coarse_command => hidden_encoder(EncoderHidden::Backlash, "backlash", COARSE_COMMAND);
    encoder_hidden_servo_lag_on_a_coarse_command => hidden_encoder(EncoderHidden::ServoLag, "servo_lag", COARSE_COMMAND);
    encoder_hidden_interpolation_error_on_a_micrometre_command =>
        hidden_encoder(EncoderHidden::InterpolationError, "interpolation_error", MICROMETRE_COMMAND);
    encoder_hidden_cyclic_lead_on_a_micrometre_command =>
        hidden_encoder(EncoderHidden::CyclicLead, "cyclic_lead", MICROMETRE_COMMAND);
    encoder_hidden_backlash_on_a_micrometre_command => hidden_encoder(EncoderHidden::Backlash, "backlash", MICROMETRE_COMMAND);
    encoder_hidden_servo_lag_on_a_micrometre_command =>
        hidden_encoder(EncoderHidden::ServoLag, "servo_lag", MICROMETRE_COMMAND);
}

/// Wall time of one `vmt diagnose` on accelerometer sets of `VMT_SAMPLES` samples (default 15 000;
/// the generator's rate set for the size, `accel_set_sized`), printed; the criterion benchmark
/// `benches/modelcheck.rs` runs the same on 15 000 and 100 000 samples.
#[test]
#[ignore = "timing tool; prints the wall time (see the report of issue 19)"]
fn accel_diagnose_wall_time() {
    let n: usize = std::env::var("VMT_SAMPLES").ok().and_then(|v| v.parse().ok()).unwrap_or(15_000);
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("sized");
    let t = accel_set_sized(&dir, 11, AccelHidden::None, 0.0, Some(n));
    let t0 = std::time::Instant::now();
    let d = vmt(&["diagnose", "--model", s(&dir.join("model.toml")), "--data", s(&dir), "--json"]).unwrap();
    eprintln!(
        "diagnose of {} samples: {:.1} s wall, normalised RMS {:.3}, first {}",
        t.samples,
        t0.elapsed().as_secs_f64(),
        d["normalized_rms"].as_f64().unwrap_or(f64::NAN),
        d["ranking"][0]
    );
}

/// Writes one encoder draw to `VMT_OUT` (seed `VMT_SEED`, hidden effect `VMT_HIDDEN` =
/// none|interp|cyclic|backlash|lag|cyclic+backlash, its trace rounded and lossy with
/// `VMT_TRACE=rounded`, jittered and lossy with `VMT_TRACE=jittered`; its two passes logged for
/// `VMT_SAMPLES`/5 rows each when set, as the benchmark's sized sets) and prints its truth: a tool for looking at one draw with
/// `vmt compare`/`diagnose` by hand.
#[test]
#[ignore = "tool: writes one encoder draw (see the doc comment)"]
fn write_encoder_draw() {
    let out = PathBuf::from(std::env::var("VMT_OUT").expect("VMT_OUT"));
    let seed: u64 = std::env::var("VMT_SEED").ok().and_then(|v| v.parse().ok()).unwrap_or(2000);
    let hidden = match std::env::var("VMT_HIDDEN").as_deref().unwrap_or("none") {
        "interp" => EncoderHidden::InterpolationError,
        "cyclic" => EncoderHidden::CyclicLead,
        "backlash" => EncoderHidden::Backlash,
        "lag" => EncoderHidden::ServoLag,
        "cyclic+backlash" => EncoderHidden::CyclicLeadAndBacklash,
        _ => EncoderHidden::None,
    };
    // `VMT_TRACE=rounded|jittered`: the trace of [`ROUNDED_TRACE`] or [`JITTERED_TRACE`].
    let trace = match std::env::var("VMT_TRACE").as_deref() {
        Ok("rounded") => ROUNDED_TRACE,
        Ok("jittered") => JITTERED_TRACE,
        Ok("coarse") => COARSE_COMMAND,
        Ok("micrometre") => MICROMETRE_COMMAND,
        _ => Trace::Exact,
    };
    let samples = std::env::var("VMT_SAMPLES").ok().and_then(|v| v.parse().ok());
    let t = encoder_set_traced(&out, seed, hidden, samples, trace);
    eprintln!("{t:?}");
}

/// Writes one accelerometer draw to `VMT_OUT` (seed `VMT_SEED`, e.g. 1000 + k for the k-th draw of
/// a hidden-mode study; hidden effect `VMT_HIDDEN` = none|mode|roll|mode+roll; about `VMT_SAMPLES`
/// samples when set, the benchmark's sizes; its clock a logger's with `VMT_CLOCK=logger|lossy|ns`) and prints its truth: the accelerometer twin of
/// [`write_encoder_draw`].
#[test]
#[ignore = "tool: writes one accelerometer draw (see the doc comment)"]
fn write_accel_draw() {
    let out = PathBuf::from(std::env::var("VMT_OUT").expect("VMT_OUT"));
    let seed: u64 = std::env::var("VMT_SEED").ok().and_then(|v| v.parse().ok()).unwrap_or(1000);
    let hidden = match std::env::var("VMT_HIDDEN").as_deref().unwrap_or("none") {
        "mode" => AccelHidden::Resonance,
        "roll" => AccelHidden::Roll,
        "mode+roll" => AccelHidden::ResonanceAndRoll,
        _ => AccelHidden::None,
    };
    let samples = std::env::var("VMT_SAMPLES").ok().and_then(|v| v.parse().ok());
    // `VMT_CLOCK=logger|lossy|ns`: the clock of [`LOGGER`], [`LOSSY_LOGGER`] or [`NS_LOGGER`].
    let clock = match std::env::var("VMT_CLOCK").as_deref() {
        Ok("logger") => LOGGER,
        Ok("lossy") => LOSSY_LOGGER,
        Ok("ns") => NS_LOGGER,
        _ => Clock::Even,
    };
    let t = accel_set_clocked(&out, seed, hidden, 200.0, samples, clock);
    eprintln!("{t:?}");
}

/// The mode studies' draws without the loop: each draw's mode and its Cramér–Rao bound
/// (`AccelTruth::mode_crb`), and whether 3× the bound is inside 1 % in f and 10 % in ζ (a
/// *resolvable* draw of `accel_hidden_resonance`), for `VMT_DRAWS` draws (default 30) from seed 1000.
#[test]
#[ignore = "tool: prints the mode bound of each study draw"]
fn print_mode_bounds() {
    let tmp = tempfile::tempdir().unwrap();
    let mut resolvable = 0;
    let n = draws(30);
    for k in 0..n {
        let t = accel_set(&tmp.path().join(format!("d{k}")), 1000 + k, AccelHidden::Resonance, 200.0);
        let (Some((f, z)), Some((sf, sz))) = (t.mode, t.mode_crb) else { continue };
        let ok = 3.0 * sf <= 0.01 * f && 3.0 * sz <= 0.10 * z;
        resolvable += usize::from(ok);
        eprintln!(
            "draw {k}: mode {f:.3} Hz, ζ {z:.5}; CRB σ_f {:.4} %, σ_ζ {:.2} %{}",
            100.0 * sf / f,
            100.0 * sz / z,
            if ok { "" } else { " (not resolvable to 1 % / 10 % at 3σ)" }
        );
    }
    eprintln!("{resolvable} of {n} draws resolvable");
}

/// The benchmark's sets written to `VMT_OUT` (a directory) for timing and profiling `vmt diagnose`
/// and `compare` by hand (`perf record`): accelerometer sets complete (`acc_none_N`) and with a
/// hidden mode (`acc_res_N`, its model also as `model_res.toml` with `resonance` fitted from 25 % off),
/// and encoder logs (`enc_N`), at N ≈ 15 000 and 100 000 samples; the truth printed.
#[test]
#[ignore = "timing tool: writes the benchmark's sets to VMT_OUT"]
fn write_timing_sets() {
    let Some(out) = std::env::var_os("VMT_OUT").map(PathBuf::from) else { return };
    for n in [15_000usize, 100_000] {
        let t = accel_set_sized(&out.join(format!("acc_none_{n}")), 11, AccelHidden::None, 0.0, Some(n));
        eprintln!("acc_none_{n}: {} samples", t.samples);
        let dir = out.join(format!("acc_res_{n}"));
        let t = accel_set_sized(&dir, 12, AccelHidden::Resonance, 200.0, Some(n));
        let (f, z) = t.mode.unwrap();
        let text = std::fs::read_to_string(dir.join("model.toml")).unwrap();
        let with_mode = format!("{text}[effects.resonance]\nfit = true\nfrequency = {:?}\ndamping = 0.02\n", f * 1.25);
        std::fs::write(out.join(format!("acc_res_{n}.model_res.toml")), with_mode).unwrap();
        eprintln!("acc_res_{n}: {} samples, mode {f:.3} Hz ζ {z:.4}", t.samples);
        let t = encoder_set_sized(&out.join(format!("enc_{n}")), 13, EncoderHidden::None, Some(n));
        eprintln!("enc_{n}: {} samples, {:?}", t.samples, t.feedback);
    }
}

/// A weak, sharp mode under heavy noise (generator draw 1005: 52.82 Hz, ζ 0.0060, 19.6 µg/√Hz,
/// 4 076 samples), through the whole loop (diagnose → add → compare): last stop's joint fit ended
/// at ζ = 0.0010, the lower limit of its damping range, and reported it as an estimate. A value
/// within 1 % of the range's log-width of a limit (ζ ≤ 0.00106, coupled.rs `box_limits`) must be
/// flagged: `compare --json` lists it in `at_bound` with a note, and so does the diagnose entry;
/// a damping that is not flagged must be an estimate, away from the limit.
#[test]
#[ignore = "90–160 s on 2 loaded cores (diagnose → add → compare with the joint mode fit on 4 076 samples) \
            against CI's ~10 min; the flag's logic is the unit test values_at_the_ends_of_the_joint_box_are_bounds"]
fn accel_mode_at_its_damping_limit_is_flagged() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("d5");
    let t = accel_set(&dir, 1005, AccelHidden::Resonance, 200.0);
    let o = run_loop(&dir, true);
    assert!(o.error.is_none(), "{:?}", o.error);
    let (f, z) = t.mode.unwrap();
    let d: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("diagnosis.json")).unwrap()).unwrap();
    let entry = d["ranking"].as_array().unwrap().iter().find(|r| r["effect"] == "resonance").cloned().unwrap();
    let flagged = |v: &serde_json::Value| v.as_array().is_some_and(|a| a.iter().any(|x| x == "damping"));
    let zd = entry["params"]["damping"].as_f64().unwrap_or(f64::NAN);
    eprintln!("mode {f:.3} Hz ζ {z:.4}: diagnose ζ {zd:.5} at_bound {}", entry["at_bound"]);
    assert!(zd > 0.00106 || flagged(&entry["at_bound"]), "diagnose: ζ {zd} at the limit, not flagged: {entry}");
    if let Some(fitted) = &o.fitted_after {
        let za = fitted["damping"].as_f64().unwrap_or(f64::NAN);
        let m2 = dir.with_extension("models").join("model2.toml");
        let c = vmt(&["compare", "--model", s(&m2), "--data", s(&dir), "--json"]).unwrap();
        eprintln!("compare after add: ζ {za:.5}, at_bound {}", c["at_bound"]);
        let is_flagged = flagged(&c["at_bound"]["resonance"]);
        assert!(za > 0.00106 || is_flagged, "compare: ζ {za} at the limit, not flagged: {}", c["at_bound"]);
        if is_flagged {
            let notes = c["notes"].as_array().unwrap();
            assert!(notes.iter().any(|n| n.as_str().unwrap_or("").contains("`damping` ended at a limit")), "{notes:?}");
        }
    }
}

/// A given mode (`fit = false`, frequency and damping stated) is part of the prediction: its mode
/// shape and free vibration are linear parts no model states, so `compare` fits them with the
/// stated frequency and damping held (a note says so). Generator draws 1001 and 1012 with a hidden
/// mode; the model given the true mode must fit to the noise (normalised RMS ≤ 1.3, the issue's
/// threshold after `add`) and report the stated frequency unchanged, where the model without it
/// leaves the mode in the residual (> 1.3 on these draws). Until session 12 a given resonance was
/// predicted as zero: the two compares gave the same RMS. Until session 20 a given mode's gains
/// came from four alternations of gains and shapes alone, which creep (`SCAN_GAIN_STEPS`): draw
/// 1012 given its true mode (35.92 Hz, ζ 0.0136) ended at normalised RMS 11.07; with
/// Gauss–Newton gains after them, 0.977.
#[test]
fn a_given_resonance_is_predicted_with_its_stated_frequency() {
    let tmp = tempfile::tempdir().unwrap();
    let fails: Vec<String> = [1001, 1012]
        .into_par_iter()
        .filter_map(|seed| {
            let dir = tmp.path().join(format!("r{seed}"));
            let t = accel_set(&dir, seed, AccelHidden::Resonance, 200.0);
            let (f, z) = t.mode.unwrap();
            let text = std::fs::read_to_string(dir.join("model.toml")).unwrap();
            let given = dir.with_extension("given.toml");
            std::fs::write(
                &given,
                format!("{text}[effects.resonance]\nfit = false\nfrequency = {f:?}\ndamping = {z:?}\n"),
            )
            .unwrap();
            let without = vmt(&["compare", "--model", s(&dir.join("model.toml")), "--data", s(&dir), "--json"]);
            let without = without.unwrap()["normalized_rms"].as_f64().unwrap_or(f64::NAN);
            let c = vmt(&["compare", "--model", s(&given), "--data", s(&dir), "--json"]).unwrap();
            let with = c["normalized_rms"].as_f64().unwrap_or(f64::NAN);
            let line = format!(
                "draw {seed}, mode {f:.3} Hz ζ {z:.4}: normalised RMS without {without:.3}, with the given mode {with:.3}"
            );
            eprintln!("{line}");
            let notes = c["notes"].as_array().unwrap();
            let noted = notes.iter().any(|n| n.as_str().unwrap_or("").contains("`resonance` is given"));
            let fa = c["fitted"]["resonance"]["frequency"].as_f64();
            let held = fa.is_none() || fa == Some(f);
            (!(without > 1.3 && with <= 1.3 && noted && held)).then(|| format!("{line}; noted {noted}, frequency {fa:?}"))
        })
        .collect();
    assert!(fails.is_empty(), "{fails:#?}");
}

/// A fitted mode whose model states its frequency and damping (as `add --from-diagnosis` writes
/// them) is refined from there: `compare` holds the mode at the stated values while its gains and
/// the shapes around it are fitted, then frees (f, ζ) and refines them with the shapes re-chosen in
/// turn (`polish`). Generator draw 1012 of the mode + roll pair (38.04 Hz, ζ 0.0144, roll through
/// gravity), with `gravity_tilt` in the model and the mode stated 1.8 % above and 1.5 % below its
/// frequency (damping 18 % above, 15 % below): `compare` must end within 1 % of the frequency and
/// 10 % of the damping (the tolerances) and at normalised RMS ≤ 1.1 (the complete model's
/// ideal is 1; the threshold after `add` is 1.3). Session 20's `compare` ended at 39.14 Hz,
/// normalised RMS 9.66–11.2, from either start and from the true values: its scan began from
/// shapes that had absorbed the mode's response, and a stated start was scanned from there too.
#[test]
fn a_stated_mode_is_refined_from_where_the_model_states_it() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("pair1012");
    let t = accel_set(&dir, 1012, AccelHidden::ResonanceAndRoll, 200.0);
    let (f, z) = t.mode.unwrap();
    let fails: Vec<String> = [(1.018, 1.18), (0.985, 0.85)]
        .into_par_iter()
        .filter_map(|(kf, kz)| {
            let (fs, zs) = (f * kf, z * kz);
            let tilt = "\n[effects.gravity_tilt]\nfit = true\n";
            let (fa, za, nrms) = compare_with_stated_mode(&dir, &format!("{kf}"), fs, zs, tilt);
            let line = format!(
                "draw 1012 (mode {f:.3} Hz, ζ {z:.4}) stated {fs:.3} Hz ζ {zs:.4}: fitted {fa:.3} Hz ζ {za:.4}, \
                 normalised RMS {nrms:.3}"
            );
            eprintln!("{line}");
            (!((fa / f - 1.0).abs() <= 0.01 && (za / z - 1.0).abs() <= 0.10 && nrms <= 1.1)).then_some(line)
        })
        .collect();
    assert!(fails.is_empty(), "{fails:#?}");
}

/// A scale reads its interpolation error at the table's position: s = x_t + I(x_t). Read at the
/// scale's reading instead, the model carries a second harmonic (πA²/p)·sin 2θ that the data do
/// not; and in a closed loop the motor follows the wave through the loop's transient where a
/// reversal sweeps the speed. Generator draws 2008 (closed loop, A 249 nm, p 11.12 µm: the
/// spurious harmonic 17.5 nm, 4.6 σ of the scale) and 2011 (semi-closed, A 193 nm, p 10.1 µm:
/// 11.7 nm, 1.6 σ), each with the interpolation error stated at its true period and fitted
/// (`fit = true`, as `add --from-diagnosis` writes it), must fit to normalised RMS ≤ 1.1 (the
/// complete model's ideal is 1; the threshold after `add` is 1.3). Session 19's `compare`
/// gave 1.536 on draw 2008.
#[test]
fn an_interpolation_error_is_read_at_the_table_position() {
    let tmp = tempfile::tempdir().unwrap();
    let fails: Vec<String> = [2008, 2011]
        .into_par_iter()
        .filter_map(|seed| {
            let dir = tmp.path().join(format!("i{seed}"));
            let t = encoder_set(&dir, seed, EncoderHidden::InterpolationError);
            let text = std::fs::read_to_string(dir.join("model.toml")).unwrap();
            let stated = dir.with_extension("stated.toml");
            let period = t.interp_period;
            std::fs::write(&stated, format!("{text}[effects.interpolation_error]\nfit = true\nperiod = {period:?}\n"))
                .unwrap();
            let c = vmt(&["compare", "--model", s(&stated), "--data", s(&dir), "--json"]).unwrap();
            let nrms = c["normalized_rms"].as_f64().unwrap_or(f64::NAN);
            let amp = c["fitted"]["interpolation_error"]["amplitude"].as_f64().unwrap_or(f64::NAN);
            let line = format!(
                "draw {seed} ({:?}): A {:.1} nm fitted {:.1} nm, normalised RMS {nrms:.3}",
                t.feedback,
                t.interp_amplitude * 1e9,
                amp * 1e9
            );
            eprintln!("{line}");
            (nrms.is_nan() || nrms > 1.1).then_some(line)
        })
        .collect();
    assert!(fails.is_empty(), "{fails:#?}");
}

/// A controller's loop samples its scale: at speed an interpolation error is far above the
/// servo's Nyquist rate and reaches the motor at its alias. Generator draw 2000 (closed loop, a
/// 10.08 µm, 76 nm interpolation error at 21.3 mm/s: 2 115 Hz, 1 kHz servo): with the error in
/// the model (its true period stated, `fit = true`), `diagnose` must name nothing significant —
/// before the servo's sampling was modelled it claimed a 5.79 mm `cyclic_lead` (ΔBIC −418), the
/// alias (115 Hz, seen by the 111 Hz pass log at 3.7 Hz) — and its fit must name the generator's
/// servo period.
#[test]
fn a_sampled_servo_aliases_the_interpolation_error_and_nothing_else_is_claimed() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("i2000");
    let t = encoder_set(&dir, 2000, EncoderHidden::InterpolationError);
    let text = std::fs::read_to_string(dir.join("model.toml")).unwrap();
    let stated = dir.with_extension("stated.toml");
    let period = t.interp_period;
    std::fs::write(&stated, format!("{text}[effects.interpolation_error]\nfit = true\nperiod = {period:?}\n")).unwrap();
    let d = vmt(&["diagnose", "--model", s(&stated), "--data", s(&dir), "--json"]).unwrap();
    let first = &d["ranking"][0];
    let notes: Vec<&str> = d["notes"].as_array().unwrap().iter().filter_map(|n| n.as_str()).collect();
    let servo = format!("the servo samples the scale every {:.4} ms", 1e3 / t.servo_rate);
    eprintln!(
        "servo {} Hz; first {} {} (ΔBIC {})",
        t.servo_rate, first["effect"], first["verdict"], first["delta_bic"]
    );
    assert!(first["verdict"] != "significant", "{first}");
    assert!(notes.iter().any(|n| n.contains(&servo)), "no `{servo}` in {notes:#?}");
}

/// A strong cyclic lead on an encoder log (generator draw 2003: semi-closed loop, lead 6.861 mm,
/// 0.70 µm against 12 nm of scale noise, 87 leads over the travel) is named first and significant at
/// its period within 1 % (the threshold). Last stop's lead scan refined only the grid's best
/// point: at this signal-to-noise a lead's dip in BIC is narrower than the grid's 0.25 % step
/// (its phase drifts by 2π·87·0.00125 rad over the travel), so the grid point beside the truth
/// scored worse than a 2 mm period where the free shape (order 205) had absorbed the lead, and the
/// lead was never ranked (0 of 4 draws of `encoder_hidden_cyclic_lead`). The scan now also refines
/// the periodogram's peaks over the capped shapes.
#[test]
fn a_strong_cyclic_lead_on_an_encoder_log_is_found_at_its_period() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("c2003");
    let t = encoder_set(&dir, 2003, EncoderHidden::CyclicLead);
    let d = vmt(&["diagnose", "--model", s(&dir.join("model.toml")), "--data", s(&dir), "--json"]).unwrap();
    let first = &d["ranking"][0];
    let period = first["params"]["period"].as_f64().unwrap_or(f64::NAN);
    eprintln!("lead {:.6} mm: first {} {} at {:.6} mm", t.lead * 1e3, first["effect"], first["verdict"], period * 1e3);
    assert!(first["effect"] == "cyclic_lead" && first["verdict"] == "significant", "{first}");
    assert!((period / t.lead - 1.0).abs() <= 0.01, "period {period} for a lead of {}", t.lead);
}

/// `compare` of the set in `dir` with its model plus a fitted resonance stated at (`f` Hz, `z`)
/// and the effects of `extra` (model text), written beside the set as `<dir>.<tag>.toml`: the
/// fitted (frequency Hz, damping ratio, normalised RMS).
fn compare_with_stated_mode(dir: &Path, tag: &str, f: f64, z: f64, extra: &str) -> (f64, f64, f64) {
    let text = std::fs::read_to_string(dir.join("model.toml")).unwrap();
    let stated = dir.with_extension(format!("{tag}.toml"));
    std::fs::write(
        &stated,
        format!("{text}[effects.resonance]\nfit = true\nfrequency = {f:?}\ndamping = {z:?}\n{extra}"),
    )
    .unwrap();
    let c = vmt(&["compare", "--model", s(&stated), "--data", s(dir), "--json"]).unwrap();
    let got = |k: &str| c["fitted"]["resonance"][k].as_f64().unwrap_or(f64::NAN);
    (got("frequency"), got("damping"), c["normalized_rms"].as_f64().unwrap_or(f64::NAN))
}

/// A fitted resonance whose model states (f, ζ) — what `add --from-diagnosis` writes — is refitted
/// from those values, not only from a ±5 % grid with shapes that do not carry the mode's
/// coupling. Generator draw 1006 (58.669 Hz, ζ 0.0307, normalised RMS 39.9 without the mode), the
/// model stating diagnose's joint optimum (58.6726 Hz, ζ 0.03065): before the fix `compare` ended
/// at 60.22 Hz with normalised RMS 5.34; now within 1 % / 10 % and ≤ 1.1 (11 s).
#[test]
fn a_stated_mode_is_refitted_from_its_stated_values() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("r1006");
    let t = accel_set(&dir, 1006, AccelHidden::Resonance, 200.0);
    let (f, z) = t.mode.unwrap();
    let (fa, za, nrms) = compare_with_stated_mode(&dir, "stated", 58.67257751247297, 0.030651361098053595, "");
    eprintln!("mode {f:.3} Hz ζ {z:.4}: fitted {fa:.3} Hz ζ {za:.4}, normalised RMS {nrms:.3}");
    assert!((fa / f - 1.0).abs() <= 0.01 && (za / z - 1.0).abs() <= 0.10 && nrms <= 1.1);
}

/// `diagnose_with` tells its stages in the order it runs them, and telling them changes nothing:
/// on a draw of the generator with a hidden mode (seed 1001, as `accel_mode_fitted_with_its_shapes`)
/// the stages are the model's fit, the ranking, then the joint mode fit's two scans each followed by
/// the shapes re-chosen, then at least one polishing round numbered from 1; the report is the one
/// `diagnose` gives, to the byte of its JSON.
#[test]
fn diagnose_tells_its_stages_in_order_and_they_change_nothing() {
    use vmt::modelcheck::Stage;
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("r1001");
    accel_set(&dir, 1001, AccelHidden::Resonance, 200.0);
    let model = vmt::model::read_model(&dir.join("model.toml")).unwrap();
    let set = vmt::measurement::read(&dir).unwrap();
    let seen = std::sync::Mutex::new(Vec::new());
    let told = vmt::modelcheck::diagnose_with(&model, &set, &dir, &|s| seen.lock().unwrap().push(s)).unwrap();
    let plain = vmt::modelcheck::diagnose(&model, &set, &dir).unwrap();
    assert_eq!(serde_json::to_string(&told).unwrap(), serde_json::to_string(&plain).unwrap());
    let seen = seen.into_inner().unwrap();
    let head = [
        Stage::FittingModel,
        Stage::RankingCandidates,
        Stage::ModeScan { round: 1, rounds: 2 },
        Stage::ModeShapes { round: 1 },
        Stage::ModeScan { round: 2, rounds: 2 },
        Stage::ModeShapes { round: 2 },
    ];
    assert!(seen.len() > head.len() && seen[..head.len()] == head, "{seen:?}");
    for (k, s) in seen[head.len()..].iter().enumerate() {
        assert!(matches!(s, Stage::ModePolish { round, most: 6 } if *round == k + 1), "{seen:?}");
    }
}
