//! The model-check loop measured on an independent generator (issue 11): `tests/gen/mod.rs` writes
//! laser point tables and friction sweeps from its own physics (not vmt's simulator, defaults or
//! fitting basis); this harness runs the command line on them (`vmt diagnose --json`, `vmt add
//! --from-diagnosis`, `vmt compare --json`, FORMAT.md §4) and states the results as rates over
//! many draws.
//!
//! Draw counts: `VMT_GEN_DRAWS` (a number) replaces every family's default count (e.g.
//! `VMT_GEN_DRAWS=20` for a quick look). The default suite runs small fixed-seed versions of the
//! rate studies (`complete_models_have_at_most_2_percent_false_alarms`, `hidden_effects_in_ci`);
//! the full studies are `#[ignore]`d tools:
//! `cargo test --release --test tests gen_diagnose:: -- --ignored --nocapture`.
//!
//! The normalised RMS the harness judges ("NRMS vs true σ") is the residual RMS over all channels
//! (`channels[].rms`, weighted by each channel's reading count) divided by the generator's true σ,
//! so it does not depend on how vmt treats a manifest σ that is understated or missing. vmt's own
//! `normalized_rms` is printed beside it.

use crate::gen;

use gen::{draw, Draw, Effect, Family};
use rayon::prelude::*;
use serde_json::Value;
use std::path::Path;

/// The threshold on the normalised RMS after `add`: 1.3 (noise level plus room for the
/// χ² scatter of a few hundred readings, ≈ ±0.1 at 2σ, and a fitted shape's small bias).
const NRMS_AFTER_ADD: f64 = 1.3;
/// Relative parameter error allowed after `add` (issue 11: backlash, τ, α·ΔT, period, vs within 10 %).
const PARAM_REL: f64 = 0.10;
/// A thermal parameter's Cramér–Rao bound (relative sd) below which 10 % is ≥ 3.3 bounds away.
const CRB_TIGHT: f64 = 0.03;

fn draws_for(default: u64) -> u64 {
    std::env::var("VMT_GEN_DRAWS").ok().and_then(|v| v.parse().ok()).unwrap_or(default)
}

/// Run the CLI; the JSON on success, or the stderr (and exit code) on failure.
fn vmt(args: &[&str]) -> Result<Value, String> {
    let out = crate::util::vmt().args(args).output().map_err(|e| e.to_string())?;
    if !out.status.success() {
        return Err(format!("exit {:?}: {}", out.status.code(), String::from_utf8_lossy(&out.stderr).trim()));
    }
    if out.stdout.is_empty() {
        return Ok(Value::Null);
    }
    serde_json::from_slice(&out.stdout).map_err(|e| format!("bad JSON ({e}): {}", String::from_utf8_lossy(&out.stdout)))
}

fn compare(dir: &Path, model: &str) -> Result<Value, String> {
    let m = dir.join(model);
    let d = dir.join("data");
    vmt(&["compare", "--model", m.to_str().unwrap(), "--data", d.to_str().unwrap(), "--json"])
}

fn diagnose(dir: &Path, model: &str) -> Result<Value, String> {
    let m = dir.join(model);
    let d = dir.join("data");
    vmt(&["diagnose", "--model", m.to_str().unwrap(), "--data", d.to_str().unwrap(), "--json"])
}

fn add(dir: &Path, model: &str, effect: &str, out: &str) -> Result<(), String> {
    let m = dir.join(model);
    let d = dir.join("data");
    let o = dir.join(out);
    let args = ["add", "--model", m.to_str().unwrap(), "--effect", effect, "--from-diagnosis"];
    vmt(&[&args[..], &["--data", d.to_str().unwrap(), "-o", o.to_str().unwrap()]].concat()).map(|_| ())
}

/// Residual RMS over all channels of a compare JSON divided by the true σ (module doc).
fn nrms_true(d: &Draw, c: &Value) -> f64 {
    let (mut ss, mut n) = (0.0, 0usize);
    for ch in c["channels"].as_array().into_iter().flatten() {
        let key = (ch["run"].as_str().unwrap_or("").to_string(), ch["sensor"].as_str().unwrap_or("").to_string());
        let count = d.channel_counts.iter().find(|(k, _)| *k == key).map_or(0, |c| c.1);
        let rms = ch["rms"].as_f64().unwrap_or(f64::NAN);
        ss += rms * rms * count as f64;
        n += count;
    }
    (ss / n as f64).sqrt() / d.sigma_true
}

/// A significant ranking entry: (effect, period if any).
#[derive(Clone, Debug)]
struct Claim {
    effect: String,
    period: Option<f64>,
}

impl std::fmt::Display for Claim {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self.period {
            Some(p) => write!(f, "{}@{:.3}mm", self.effect, p * 1e3),
            None => write!(f, "{}", self.effect),
        }
    }
}

fn claims(diag: &Value) -> Vec<Claim> {
    diag["ranking"]
        .as_array()
        .into_iter()
        .flatten()
        .filter(|e| e["verdict"] == "significant")
        .map(|e| Claim {
            effect: e["effect"].as_str().unwrap_or("?").to_string(),
            period: e["params"]["period"].as_f64(),
        })
        .collect()
}

/// Run `f` on draws 0..n of `family` in parallel (each in its own temporary directory); results
/// in index order, so the output does not depend on the number of threads.
fn over_draws<T: Send>(family: &Family, n: u64, f: impl Fn(&Draw, &Path) -> T + Sync) -> Vec<(Draw, T)> {
    (0..n)
        .into_par_iter()
        .map(|i| {
            let d = draw(family, i);
            let tmp = tempfile::tempdir().unwrap();
            d.write(tmp.path()).unwrap();
            let r = f(&d, tmp.path());
            (d, r)
        })
        .collect()
}

/// Number of complete point tables the default suite diagnoses (the first, by index).
const CI_TABLES: u64 = 24;

/// `diagnose` of `complete.toml` on the first `n` complete point tables; the default suite's `n`
/// ([`CI_TABLES`]) is computed once per test process and shared by the tests that read it (the σ
/// check and the false-alarm rate read the same diagnoses).
fn complete_table_diagnoses(n: u64) -> std::borrow::Cow<'static, [(Draw, Result<Value, String>)]> {
    static CI: std::sync::OnceLock<Vec<(Draw, Result<Value, String>)>> = std::sync::OnceLock::new();
    let run = |n| over_draws(&Family::CompletePointTable, n, |_, dir| diagnose(dir, "complete.toml"));
    if n == CI_TABLES {
        std::borrow::Cow::Borrowed(CI.get_or_init(|| run(n)))
    } else {
        std::borrow::Cow::Owned(run(n))
    }
}

fn rate(k: usize, n: usize) -> String {
    format!("{k}/{n} ({:.1} %)", 100.0 * k as f64 / n.max(1) as f64)
}

// ------------------------------------------------------------------------------------------
// The generator itself (not ignored).

/// The generator's files parse, and its physics agrees with vmt's stated conventions: `vmt
/// compare` with the truth model (every effect given with the generator's own parameters,
/// profiles as tables at the targets; only the per-channel offsets are fitted) leaves a residual
/// at the noise level. The residual sum of squares is σ²·χ²(N − k) for N readings and k offsets,
/// so the residual RMS / σ has mean ≈ √((N − k)/N) and a standard deviation ≈ 1/√(2N); the
/// assertion allows 5 of those (a 1-in-10⁶ event per draw) plus 0.5 % for the profiles' 1-nm
/// rounding in the CSVs. A wrong sign (backlash, Abbe arm, thermal) or unit would leave the
/// effect's full size in the residual (≥ 6σ signatures in hidden draws). Also: the same index
/// gives the same files (determinism).
#[test]
fn generator_sanity_truth_model_leaves_noise() {
    let mut families: Vec<(Family, u64)> = vec![(Family::CompletePointTable, 8), (Family::CompleteFriction, 3)];
    for e in Effect::ALL {
        families.push((Family::Hidden(vec![e]), 3));
    }
    families.push((Family::UnresolvedCyclic, 2));
    let mut rows: Vec<String> = Vec::new();
    // Pooled over all draws: Σ RSS/σ² against Σ (N − k), a χ² with Σ (N − k) degrees of freedom
    // (mean 1 for the ratio, sd √(2/Σ(N − k)) ≈ 0.005 here): catches a small systematic misfit
    // (e.g. a 2 % unit or sign slip in an effect) that single small draws cannot.
    let (mut chi2, mut dof) = (0.0, 0.0);
    for (fam, n) in &families {
        for (d, r) in over_draws(fam, *n, |d, dir| compare(dir, "truth.toml").map(|c| nrms_true(d, &c))) {
            let x = r.unwrap_or_else(|e| panic!("{}: vmt compare on the truth failed: {e}", d.describe()));
            let n: usize = d.channel_counts.iter().map(|c| c.1).sum();
            let k = d.channel_counts.len();
            let expect = ((n - k) as f64 / n as f64).sqrt();
            let tol = 5.0 / (2.0 * n as f64).sqrt() + 0.005;
            chi2 += x * x * n as f64;
            dof += (n - k) as f64;
            rows.push(format!("{:<40} NRMS vs true σ {x:.3} (expected {expect:.3} ± {tol:.3})", d.describe()));
            assert!(
                (x - expect).abs() <= tol,
                "{}: truth model residual / σ = {x:.4}, expected {expect:.4} ± {tol:.4}",
                d.describe()
            );
        }
    }
    eprintln!("{}", rows.join("\n"));
    let pooled = chi2 / dof;
    let tol = 5.0 * (2.0 / dof).sqrt();
    eprintln!("pooled RSS/σ² per degree of freedom: {pooled:.4} (expected 1 ± {tol:.4}, 5 sd)");
    assert!((pooled - 1.0).abs() <= tol, "pooled χ²/dof {pooled:.4}");
    // Determinism: a draw is a function of its index only.
    for fam in [Family::CompletePointTable, Family::CompleteFriction, Family::Hidden(vec![Effect::ThermalDrift])] {
        let (a, b) = (draw(&fam, 7), draw(&fam, 7));
        assert_eq!(a.data_files, b.data_files);
        assert_eq!(a.model_files, b.model_files);
        assert_ne!(draw(&fam, 8).data_files, a.data_files);
    }
    // Unresolved cyclic draws: every target spacing exceeds the period (no layout can show it).
    for i in 0..20 {
        let d = draw(&Family::UnresolvedCyclic, i);
        let p = d.truth.cyclic.unwrap().0;
        assert!(d.min_spacing > p, "{}: period {p}", d.describe());
    }
}

/// The catalogue's form of a friction law, `coulomb` (fc) + `stribeck` (fs, vs, shape, no fc) +
/// `viscous`, all given, is the simulator's law F = Fc·sgn v + Fv·v + (Fs − Fc)·sgn v·e^{−|v/vs|^δ}
/// (`vmt_sim::effects::EffectSet::friction`: stribeck.fc unset takes the coulomb level). `vmt
/// compare` on it should leave the noise, as it does for the same law written with stribeck.fc
/// (the sanity test above). On main it leaves ≈ Fc·(1 − e^{−|v/vs|^δ}) per sample: the given
/// Stribeck term fills its fc from coulomb and the coulomb term is added again (Fc counted twice).
#[test]
fn given_coulomb_and_stribeck_predict_the_simulators_law() {
    for (d, r) in
        over_draws(&Family::CompleteFriction, 3, |d, dir| compare(dir, "truth_split.toml").map(|c| nrms_true(d, &c)))
    {
        let x = r.unwrap();
        let n: usize = d.channel_counts.iter().map(|c| c.1).sum();
        // Same bound as the sanity test: 5 standard deviations of the residual RMS / σ.
        let tol = 5.0 / (2.0 * n as f64).sqrt() + 0.005;
        assert!((x - 1.0).abs() <= tol, "{}: residual / σ {x:.3} with coulomb + stribeck given", d.describe());
    }
}

/// The manifest's σ is checked against the repeated readings (issue 11 item 5): `diagnose` reports
/// `sigma` = {stated, from_repeats, dof, p_value, used} on every point table with repeats.
/// - σ stated 3× too small: the repeats' scatter is 9× the stated variance, T/dof ≈ 9 at ≥ 10
///   degrees of freedom, so p < 10⁻⁶ in every draw: `used` = `from_repeats` in all of them.
/// - σ stated correctly: the test rejects at its 1 % level (p < 0.01) by chance only; over the
///   ~15 such draws of 24, two or more rejections have probability ≈ 1 %, so at most one is allowed.
/// - σ missing: `used` = `estimated`, `stated` absent.
/// - `from_repeats` is the pooled within-group standard deviation: within 35 % of the true σ in every
///   draw (its relative standard error is 1/√(2·dof) ≤ 22 % at dof ≥ 10; 35 % is 1.6 of those at the
///   smallest dof, and the draws have far more).
#[test]
fn stated_sigma_is_checked_against_the_repeats() {
    let (mut correct, mut rejected) = (0, 0);
    for (d, r) in complete_table_diagnoses(draws_for(CI_TABLES)).iter() {
        let diag = r.as_ref().unwrap_or_else(|e| panic!("{}: {e}", d.describe()));
        let sc = &diag["sigma"];
        assert!(sc.is_object(), "{}: no `sigma` check although the tables repeat every target", d.describe());
        let from = sc["from_repeats"].as_f64().unwrap();
        assert!(rel(from, d.sigma_true) < 0.35, "{}: σ from repeats {from:e} vs true {:e}", d.describe(), d.sigma_true);
        let used = sc["used"].as_str().unwrap_or("?");
        match d.sigma_stated {
            gen::SigmaStated::Understated => {
                let p = sc["p_value"].as_f64().unwrap();
                // The significance then uses the stated σ × scale, the repeats' upper 95 % bound: at
                // least σ̂/σ_stated ≥ 3·(1 − 0.35).
                let k = sc["scale"].as_f64().unwrap_or(0.0);
                assert!(
                    p < 1e-6 && used == "from_repeats" && k >= 1.95,
                    "{}: understated σ not caught (p {p:e}, used {used}, scale {k})",
                    d.describe()
                );
            }
            gen::SigmaStated::Correct => {
                correct += 1;
                rejected += usize::from(used != "stated");
            }
            gen::SigmaStated::Missing => {
                assert!(used == "estimated" && sc["stated"].is_null(), "{}: missing σ reported as {sc}", d.describe())
            }
        }
    }
    eprintln!("correct σ rejected by the χ² test: {}", rate(rejected, correct));
    assert!(rejected <= 1, "a correctly stated σ was rejected in {} draws", rate(rejected, correct));
}

// ------------------------------------------------------------------------------------------
// Rates (issue 11's thresholds).

/// Complete models (nothing hidden): the fraction of data sets where `diagnose` reports any
/// `significant` candidate. Issue 11: at most 2 % over ≥ 200 draws (goal 1 %). The default suite
/// runs the first 24 point tables + 6 friction sweeps (the draws are fixed by their index, so this
/// is a fixed set of 30 data sets, about 30 s): 2 % of 30 allows no alarm. Measured over 160 + 40
/// draws (the ignored tool below): 0/200 in session 6 (1/200 at the session-5 merge: a `cyclic_lead` at
/// 60.000 mm, the end of the periods searched, now `inseparable` from the shapes: `at_bound`).
#[test]
fn complete_models_have_at_most_2_percent_false_alarms() {
    false_alarm_study(CI_TABLES, 6);
}

/// The full study of [`complete_models_have_at_most_2_percent_false_alarms`]: 160 point tables +
/// 40 friction sweeps (`VMT_GEN_DRAWS` replaces both counts).
#[test]
#[ignore = "a tool: the 200-draw false-alarm study (0/200 in session 6)"]
fn complete_models_false_alarm_study() {
    false_alarm_study(draws_for(160), draws_for(40));
}

fn false_alarm_study(n_table: u64, n_fric: u64) {
    let mut alarms = 0;
    let mut errors = Vec::new();
    let mut total = 0;
    let mut by_effect: std::collections::BTreeMap<String, usize> = Default::default();
    // (alarms, draws) by layout and by how the manifest states σ.
    let mut by_kind: std::collections::BTreeMap<String, (usize, usize)> = Default::default();
    let mut lines = Vec::new();
    let tables = complete_table_diagnoses(n_table);
    let sweeps = over_draws(&Family::CompleteFriction, n_fric, |_, dir| diagnose(dir, "complete.toml"));
    for part in [&tables[..], &sweeps[..]] {
        for (d, r) in part {
            total += 1;
            match r {
                Err(e) => errors.push(format!("{}: {e}", d.describe())),
                Ok(diag) => {
                    let c = claims(diag);
                    let layout = d.layout.map_or("friction sweep".to_string(), |l| format!("layout {l:?}"));
                    for k in [layout, format!("σ {:?}", d.sigma_stated)] {
                        let e = by_kind.entry(k).or_default();
                        e.0 += usize::from(!c.is_empty());
                        e.1 += 1;
                    }
                    if !c.is_empty() {
                        alarms += 1;
                        for cl in &c {
                            *by_effect.entry(cl.effect.clone()).or_default() += 1;
                        }
                        lines.push(format!(
                            "  {}: {}",
                            d.describe(),
                            c.iter().map(ToString::to_string).collect::<Vec<_>>().join(", ")
                        ));
                    }
                }
            }
        }
    }
    eprintln!("{}", lines.join("\n"));
    eprintln!("false alarms (any `significant` claim): {} complete models", rate(alarms, total));
    eprintln!("  claims by effect (significant entries): {by_effect:?}");
    for (k, (a, n)) in &by_kind {
        eprintln!("  false alarms, {k}: {}", rate(*a, *n));
    }
    eprintln!("  command failures: {}", rate(errors.len(), total));
    for e in &errors {
        eprintln!("  {e}");
    }
    assert!(errors.is_empty(), "diagnose failed on {} draws", errors.len());
    // Issue 11: ≤ 2 % with any significant claim.
    assert!(alarms as f64 <= 0.02 * total as f64, "false alarms {}", rate(alarms, total));
}

/// Outcome of the loop on one hidden-effect draw.
#[derive(Debug, Default)]
struct LoopOutcome {
    /// The first-ranked entry is a hidden effect and `significant`.
    named_first: bool,
    /// What was ranked first (effect, verdict).
    first: String,
    /// NRMS vs true σ after adding what diagnose named (one add per hidden effect).
    nrms_after: f64,
    /// vmt's own normalized_rms after the adds.
    vmt_nrms_after: f64,
    /// Relative parameter errors after the adds (name, error).
    params: Vec<(String, f64)>,
    /// Cramér–Rao bounds of the thermal parameters (name as in `params`, relative standard
    /// deviation), [`thermal_bounds`].
    bounds: Vec<(String, f64)>,
    /// Effects added by following the advice that are not hidden.
    wrong_adds: Vec<String>,
    /// The loop added exactly the hidden effects (the final model is complete).
    completed: bool,
    /// Significant claims on the final model when the loop added exactly the hidden effects (the
    /// model is then complete: any claim is a false alarm).
    final_claims: Vec<String>,
}

fn rel(a: f64, b: f64) -> f64 {
    ((a - b) / b).abs()
}

/// Effects no data set of one axis can tell apart from hidden effect `e`, physically: a thermal
/// expansion that settled before the test (τ short against the reading interval) is α·ΔT∞·x, a
/// scale error. For these an `inseparable` verdict naming only them counts as naming `e`.
fn physically_equivalent(e: Effect) -> &'static [&'static str] {
    match e {
        Effect::ScaleError => &["thermal_expansion"],
        Effect::Backlash
        | Effect::CyclicLead
        | Effect::ThermalExpansion
        | Effect::ThermalDrift
        | Effect::Pitch
        | Effect::Yaw
        | Effect::Stribeck
        | Effect::Viscous => &[],
    }
}

/// The ranking entry names a hidden effect as `inseparable` only from its physical equivalents.
fn equivalent_inseparable(d: &Draw, entry: &Value) -> bool {
    let Some(h) = d.hidden.iter().find(|h| entry["effect"] == h.name()) else { return false };
    let eq = physically_equivalent(*h);
    entry["verdict"] == "inseparable"
        && !eq.is_empty()
        && entry["confused_with"].as_array().is_some_and(|c| c.iter().all(|n| eq.iter().any(|e| n == e)))
}

/// Follow the advice: diagnose, add the first-ranked significant effect, once per hidden effect;
/// then compare and diagnose the final model.
fn follow_loop(d: &Draw, dir: &Path) -> Result<LoopOutcome, String> {
    let mut out = LoopOutcome::default();
    let mut model = "start.toml".to_string();
    let mut added = 0;
    for step in 0..d.hidden.len() {
        let diag = diagnose(dir, &model)?;
        let top = &diag["ranking"][0];
        let eff = top["effect"].as_str().unwrap_or("").to_string();
        let sig = top["verdict"] == "significant" || equivalent_inseparable(d, top);
        if step == 0 {
            out.first = format!("{eff} ({})", top["verdict"].as_str().unwrap_or("?"));
            out.named_first = sig && d.hidden.iter().any(|h| h.name() == eff);
        }
        if !sig {
            break;
        }
        if !d.hidden.iter().any(|h| h.name() == eff) {
            out.wrong_adds.push(eff.clone());
        }
        let next = format!("m{}.toml", step + 1);
        add(dir, &model, &eff, &next)?;
        added += 1;
        model = next;
    }
    let c = compare(dir, &model)?;
    out.nrms_after = nrms_true(d, &c);
    out.vmt_nrms_after = c["normalized_rms"].as_f64().unwrap_or(f64::NAN);
    let f = &c["fitted"];
    let tr = &d.truth;
    for h in &d.hidden {
        let get = |e: &str, k: &str| f[e][k].as_f64();
        let mut push = |name: &str, v: Option<f64>, truth: f64| {
            out.params.push((name.to_string(), v.map_or(f64::INFINITY, |v| rel(v, truth))));
        };
        match h {
            Effect::Backlash => push("backlash b", get("backlash", "value"), tr.backlash.unwrap()),
            Effect::CyclicLead => push("cyclic period", get("cyclic_lead", "period"), tr.cyclic.unwrap().0),
            Effect::ScaleError => push("scale k", get("scale_error", "value"), tr.scale.unwrap()),
            Effect::ThermalExpansion => {
                let (a, dt, tau) = tr.expansion.unwrap();
                let prod =
                    get("thermal_expansion", "alpha").zip(get("thermal_expansion", "delta_t")).map(|(a, t)| a * t);
                push("expansion α·ΔT", prod, a * dt);
                push("expansion τ", get("thermal_expansion", "tau"), tau);
            }
            Effect::ThermalDrift => {
                let (v, tau) = tr.drift.unwrap();
                push("drift d∞", get("thermal_drift", "value"), v);
                push("drift τ", get("thermal_drift", "tau"), tau);
            }
            Effect::Pitch | Effect::Yaw => {}
            Effect::Stribeck => push("stribeck vs", get("stribeck", "vs"), tr.friction.unwrap().vs),
            Effect::Viscous => push("viscous fv", get("viscous", "fv"), tr.friction.unwrap().fv),
        }
    }
    out.bounds = thermal_bounds(d, &c);
    // Every hidden effect added and nothing else: the model is now complete.
    out.completed = out.wrong_adds.is_empty() && added == d.hidden.len();
    if out.completed {
        out.final_claims = claims(&diagnose(dir, &model)?).iter().map(ToString::to_string).collect();
    }
    Ok(out)
}

/// Legendre polynomial P_k(u) (Bonnet: (k+1)·P_{k+1} = (2k+1)·u·P_k − k·P_{k−1}).
fn legendre(k: u32, u: f64) -> f64 {
    let (mut p0, mut p1) = (1.0, u);
    if k == 0 {
        return p0;
    }
    for j in 1..k {
        let j = f64::from(j);
        (p0, p1) = (p1, ((2.0 * j + 1.0) * u * p1 - j * p0) / (j + 1.0));
    }
    p1
}

/// Cramér–Rao bounds of the thermal parameters of draw `d` (expansion α·ΔT and τ_e, drift d∞ and
/// τ_d), as relative standard deviations: the smallest scatter any unbiased estimator can reach
/// on this design and noise. From the generator's own model (tests/gen/mod.rs module doc) at the
/// true parameters with the true σ: Fisher information F = JᵀJ/σ², J the Jacobian of the readings
/// with respect to every parameter the fitted model (`c`, a `vmt compare --json` after the loop)
/// estimates — an offset per channel, each fitted error motion as vmt has it (`shapes`: Legendre
/// degrees 1..order in x, times the laser's arm for pitch z and yaw −y), backlash −d/2, scale x,
/// cyclic lead (amplitude, phase, period), and the thermal terms
///   ∂/∂(α·ΔT) = x·(1 − e^{−t/τ_e}),  ∂/∂τ_e = −α·ΔT·x·(t/τ_e²)·e^{−t/τ_e},
///   ∂/∂d∞ = 1 − e^{−t/τ_d},           ∂/∂τ_d = −d∞·(t/τ_d²)·e^{−t/τ_d};
/// the bound is √(F⁻¹)_ii / |θ_i| (the nuisance parameters profiled out by the inverse). Effects
/// fitted but absent from the truth are left out (their nonlinear parameters are undefined at a
/// zero amplitude). Infinite when F is singular (a singular value ≤ 1e-12 of the largest, columns scaled to unit
/// norm). Empty for draws without thermal effects.
fn thermal_bounds(d: &Draw, c: &Value) -> Vec<(String, f64)> {
    let tr = &d.truth;
    if d.design.is_empty() || (tr.expansion.is_none() && tr.drift.is_none()) {
        return Vec::new();
    }
    let fitted = |e: &str| c["fitted"].get(e).is_some_and(|v| !v.is_null());
    let xs = d.design.iter().map(|s| s.x);
    let x_lo = xs.clone().fold(f64::INFINITY, f64::min);
    let x_hi = xs.fold(f64::NEG_INFINITY, f64::max);
    let u = |x: f64| 2.0 * (x - x_lo) / (x_hi - x_lo) - 1.0;
    // Columns: (parameter of interest: name and true value, or None for a nuisance; column).
    type Col = (Option<(String, f64)>, Vec<f64>);
    let mut cols: Vec<Col> = Vec::new();
    let mut col = |name: Option<(&str, f64)>, f: &dyn Fn(&gen::Sample) -> f64| {
        cols.push((name.map(|(n, v)| (n.to_string(), v)), d.design.iter().map(f).collect()));
    };
    for ch in 0..d.channel_counts.len() {
        col(None, &|s| f64::from(u8::from(s.channel == ch)));
    }
    for (name, r) in c["shapes"].as_object().into_iter().flatten() {
        let arm: fn(&gen::Sample) -> f64 = match name.as_str() {
            "positioning" => |_| 1.0,
            "pitch" => |s| s.z,
            "yaw" => |s| -s.y,
            other => panic!("thermal_bounds: a fitted shape {other} the generator does not make"),
        };
        let order = r["order"].as_u64().expect("compare JSON: shapes.*.order") as u32;
        for k in 1..=order {
            col(None, &|s| arm(s) * legendre(k, u(s.x)));
        }
    }
    if fitted("backlash") && tr.backlash.is_some() {
        col(None, &|s| -s.d / 2.0);
    }
    if fitted("scale_error") && tr.scale.is_some() {
        col(None, &|s| s.x);
    }
    if let Some((p, a, phi)) = tr.cyclic.filter(|_| fitted("cyclic_lead")) {
        let w = std::f64::consts::TAU / p;
        col(None, &|s| (w * s.x + phi).sin());
        col(None, &|s| a * (w * s.x + phi).cos());
        col(None, &|s| -a * (w * s.x + phi).cos() * w * s.x / p);
    }
    if let Some((alpha, dt, tau)) = tr.expansion.filter(|_| fitted("thermal_expansion")) {
        let k = alpha * dt;
        col(Some(("expansion α·ΔT", k)), &|s| s.x * (1.0 - (-s.t / tau).exp()));
        col(Some(("expansion τ", tau)), &|s| -k * s.x * s.t / (tau * tau) * (-s.t / tau).exp());
    }
    if let Some((v, tau)) = tr.drift.filter(|_| fitted("thermal_drift")) {
        col(Some(("drift d∞", v)), &|s| 1.0 - (-s.t / tau).exp());
        col(Some(("drift τ", tau)), &|s| -v * s.t / (tau * tau) * (-s.t / tau).exp());
    }
    // Columns scaled to unit norm before the inverse (they span many orders of magnitude).
    let norms: Vec<f64> = cols.iter().map(|c| c.1.iter().map(|v| v * v).sum::<f64>().sqrt()).collect();
    // Var(θ̂_k) ≥ σ²·(JᵀJ)⁻¹_kk = σ²·Σ_m (V_km/s_m)²/norm_k² (thin SVD of the scaled J = U S Vᵀ).
    let j = faer::Mat::<f64>::from_fn(d.design.len(), cols.len(), |i, k| cols[k].1[i] / norms[k]);
    let svd = j.thin_svd().expect("thermal_bounds: SVD of the Jacobian");
    let (v, sv) = (svd.V(), svd.S().column_vector());
    let s_max = (0..cols.len()).map(|m| sv[m]).fold(0.0, f64::max);
    let singular = (0..cols.len()).any(|m| sv[m] <= 1e-12 * s_max);
    cols.iter()
        .enumerate()
        .filter_map(|(k, c)| c.0.clone().map(|nv| (k, nv)))
        .map(|(k, (name, truth))| {
            let var: f64 = (0..cols.len()).map(|m| (v[(k, m)] / sv[m]).powi(2)).sum();
            let sd = if singular { f64::INFINITY } else { d.sigma_true * var.sqrt() / norms[k] };
            (name, sd / truth.abs())
        })
        .collect()
}

/// The families of hidden-effect draws: each hideable effect alone, and two together.
fn hidden_families() -> Vec<Family> {
    let mut v: Vec<Family> = Effect::ALL.iter().map(|e| Family::Hidden(vec![*e])).collect();
    for pair in [
        [Effect::Backlash, Effect::ThermalDrift],
        [Effect::CyclicLead, Effect::Backlash],
        [Effect::ThermalExpansion, Effect::Backlash],
        [Effect::Pitch, Effect::Backlash],
    ] {
        v.push(Family::Hidden(pair.to_vec()));
    }
    v
}

/// Hidden effects: per family, named first and significant, NRMS ≤ 1.3 after `add`, parameter
/// errors ≤ 10 %. Issue 11: each rate ≥ 95 % over ≥ 30 draws (30 per family by default). The
/// thermal parameters (α·ΔT, τ_e, d∞, τ_d) are judged against their Cramér–Rao bound on each
/// draw ([`thermal_bounds`]): within 3 bounds, and within 10 % wherever the bound is below 3 %
/// (measured: every 10 % miss of the 30-draw study is a draw whose bound exceeds 3.3 %).
/// "Named first": the first-ranked entry is a hidden effect with verdict `significant`, or
/// `inseparable` from its physical equivalents only ([`physically_equivalent`]: a scale error from
/// a settled thermal expansion). The loop then adds that entry (`vmt add --from-diagnosis`), once
/// per hidden effect, following the first-ranked significant entry each time (a wrong add is
/// counted). `VMT_GEN_FAMILY=LABEL[,LABEL]` restricts the run to some families.
#[test]
#[ignore = "a tool: the 30-draw study of every family (about 18 min); the default suite runs `hidden_effects_in_ci`"]
fn hidden_effects_are_named_first_and_adding_them_reaches_the_noise() {
    hidden_study(draws_for(30), false);
}

/// The hidden-effect study in the default suite: the first `VMT_GEN_DRAWS` (default 1) draws of
/// every family (15 loops in all, in parallel), with issue 11's thresholds applied to the rates
/// pooled over the families (≥ 95 % named first and significant, ≥ 95 % at NRMS ≤ 1.3 after `add`,
/// parameters as in the study, ≤ 2 % claims on the completed models): with 15 draws, ≥ 95 % means
/// all 15. Fixed seeds: a change of the method that loses one family's first draw fails here; the
/// 30-draw rates per family are the ignored study's.
#[test]
fn hidden_effects_in_ci() {
    hidden_study(draws_for(1), true);
}

/// The hidden-effect study: `n` draws per family; thresholds per family, or (`pooled`) on the
/// rates pooled over all families.
fn hidden_study(n: u64, pooled: bool) {
    let mut failures = Vec::new();
    // Pooled over families: (draws whose loop made the model complete, those with a claim after).
    let (mut completed, mut claimed_after) = (0usize, 0usize);
    eprintln!(
        "Columns, as draws out of the family's count: named first = first-ranked entry is hidden and \
         significant; NRMS≤1.3 = residual RMS / true σ after the adds; wrong adds = following the advice \
         added an effect that was not hidden; new claims = the model the loop made complete gets a \
         significant claim; parameter errors = draws within 10 % of the truth (median relative error; \
         inf: the effect was never added)."
    );
    eprintln!(
        "{:<38} {:>14} {:>14} {:>14} {:>12}  parameter errors ≤ 10 % (median rel. error)",
        "family", "named first", "NRMS≤1.3", "wrong adds", "new claims"
    );
    let only: Option<Vec<String>> =
        std::env::var("VMT_GEN_FAMILY").ok().map(|v| v.split(',').map(|s| s.trim().to_string()).collect());
    let families: Vec<Family> =
        hidden_families().into_iter().filter(|f| only.as_ref().is_none_or(|o| o.contains(&f.label()))).collect();
    // Pooled mode: every family's draws at once (parallel over all), thresholds on the pooled rates.
    let all: Vec<(Family, Vec<(Draw, Result<LoopOutcome, String>)>)> = if pooled {
        let jobs: Vec<(usize, u64)> = (0..families.len()).flat_map(|f| (0..n).map(move |i| (f, i))).collect();
        let mut out: Vec<Vec<(Draw, Result<LoopOutcome, String>)>> = families.iter().map(|_| Vec::new()).collect();
        let done: Vec<(usize, Draw, Result<LoopOutcome, String>)> = jobs
            .par_iter()
            .map(|&(f, i)| {
                let d = draw(&families[f], i);
                let tmp = tempfile::tempdir().unwrap();
                d.write(tmp.path()).unwrap();
                let r = follow_loop(&d, tmp.path());
                (f, d, r)
            })
            .collect();
        for (f, d, r) in done {
            out[f].push((d, r));
        }
        families.iter().cloned().zip(out).collect()
    } else {
        families.iter().map(|f| (f.clone(), Vec::new())).collect()
    };
    let (mut p_first, mut p_nrms, mut p_total) = (0usize, 0usize, 0usize);
    let mut p_params: std::collections::BTreeMap<String, Vec<f64>> = Default::default();
    let mut p_bounded: std::collections::BTreeMap<String, Vec<(f64, f64)>> = Default::default();
    for (fam, done) in all {
        let res = if pooled { done } else { over_draws(&fam, n, follow_loop) };
        let total = res.len();
        let mut first = 0;
        let mut nrms = 0;
        let mut wrong = 0;
        let mut new_claims = 0;
        let mut params: std::collections::BTreeMap<String, Vec<f64>> = Default::default();
        // Thermal parameters: (relative error, relative Cramér–Rao bound) per draw.
        let mut bounded: std::collections::BTreeMap<String, Vec<(f64, f64)>> = Default::default();
        let mut detail = Vec::new();
        for (d, r) in &res {
            match r {
                Err(e) => detail.push(format!("  {}: command failed: {e}", d.describe())),
                Ok(o) => {
                    first += usize::from(o.named_first);
                    nrms += usize::from(o.nrms_after <= NRMS_AFTER_ADD);
                    wrong += usize::from(!o.wrong_adds.is_empty());
                    new_claims += usize::from(!o.final_claims.is_empty());
                    completed += usize::from(o.completed);
                    claimed_after += usize::from(!o.final_claims.is_empty());
                    for (k, v) in &o.params {
                        params.entry(k.clone()).or_default().push(*v);
                    }
                    for (k, b) in &o.bounds {
                        let e = o.params.iter().find(|p| p.0 == *k).map_or(f64::INFINITY, |p| p.1);
                        bounded.entry(k.clone()).or_default().push((e, *b));
                    }
                    if !o.named_first || o.nrms_after > NRMS_AFTER_ADD || o.params.iter().any(|p| p.1 > PARAM_REL) {
                        detail.push(format!(
                            "  {}: first {}, NRMS vs true σ {:.2} (vmt {:.2}), params {:?}, CRB {:?}, wrong adds {:?}, claims after {:?}",
                            d.describe(),
                            o.first,
                            o.nrms_after,
                            o.vmt_nrms_after,
                            o.params.iter().map(|(k, v)| format!("{k} {:.1} %", v * 100.0)).collect::<Vec<_>>(),
                            o.bounds
                                .iter()
                                .map(|(k, b)| {
                                    let e = o.params.iter().find(|p| p.0 == *k).map_or(f64::INFINITY, |p| p.1);
                                    format!("{k} bound {:.1} %, error/bound {:.2}", b * 100.0, e / b)
                                })
                                .collect::<Vec<_>>(),
                            o.wrong_adds,
                            o.final_claims
                        ));
                    }
                }
            }
        }
        let ptxt: Vec<String> = params
            .iter()
            .map(|(k, v)| {
                let mut s = v.clone();
                s.sort_by(f64::total_cmp);
                let ok = v.iter().filter(|e| **e <= PARAM_REL).count();
                format!("{k}: {} (median {:.1} %)", rate(ok, v.len()), 100.0 * s[s.len() / 2])
            })
            .collect();
        eprintln!(
            "{:<38} {:>14} {:>14} {:>14} {:>12}  {}",
            fam.label(),
            rate(first, total),
            rate(nrms, total),
            rate(wrong, total),
            rate(new_claims, total),
            ptxt.join("; ")
        );
        for (k, v) in &bounded {
            let mut ratio: Vec<f64> = v.iter().map(|(e, b)| e / b).collect();
            ratio.sort_by(f64::total_cmp);
            let mut b: Vec<f64> = v.iter().map(|p| p.1).collect();
            b.sort_by(f64::total_cmp);
            let tight: Vec<&(f64, f64)> = v.iter().filter(|p| p.1 < CRB_TIGHT).collect();
            eprintln!(
                "    {k}: Cramér–Rao bound (relative sd) median {:.1} %, max {:.1} %, > 10 %/3 in {}; \
                 error ≤ 3 bounds {}; median error/bound {:.2}, max {:.2}; where the bound < 3 %: within 10 % {}",
                100.0 * b[b.len() / 2],
                100.0 * b[b.len() - 1],
                rate(v.iter().filter(|p| p.1 > PARAM_REL / 3.0).count(), v.len()),
                rate(v.iter().filter(|p| p.0 <= 3.0 * p.1).count(), v.len()),
                ratio[ratio.len() / 2],
                ratio[ratio.len() - 1],
                rate(tight.iter().filter(|p| p.0 <= PARAM_REL).count(), tight.len()),
            );
        }
        for l in &detail {
            eprintln!("{l}");
        }
        p_first += first;
        p_nrms += nrms;
        p_total += total;
        for (k, v) in &params {
            p_params.entry(k.clone()).or_default().extend(v);
        }
        for (k, v) in &bounded {
            p_bounded.entry(k.clone()).or_default().extend(v);
        }
        if !pooled {
            failures.extend(thresholds(&fam.label(), first, nrms, total, &params, &bounded));
        }
    }
    if pooled {
        eprintln!(
            "pooled over {} families: named first {}, NRMS ≤ 1.3 {}",
            families.len(),
            rate(p_first, p_total),
            rate(p_nrms, p_total)
        );
        failures.extend(thresholds("all families", p_first, p_nrms, p_total, &p_params, &p_bounded));
    }
    // A model the loop made complete is a complete model: issue 11's ≤ 2 % false alarms, pooled
    // over all families (per family, 30 draws cannot resolve 2 %).
    eprintln!("complete after the loop, then a significant claim: {}", rate(claimed_after, completed));
    if claimed_after as f64 > 0.02 * completed as f64 {
        failures.push(format!("claims on models the loop made complete {}", rate(claimed_after, completed)));
    }
    assert!(failures.is_empty(), "issue 11 thresholds not met:\n{}", failures.join("\n"));
}

/// Issue 11's thresholds on one family's (or the pooled) outcome: draws named first, draws at NRMS
/// ≤ 1.3 after `add`, out of `total`; parameter errors by name; thermal (error, Cramér–Rao bound).
fn thresholds(
    label: &str,
    first: usize,
    nrms: usize,
    total: usize,
    params: &std::collections::BTreeMap<String, Vec<f64>>,
    bounded: &std::collections::BTreeMap<String, Vec<(f64, f64)>>,
) -> Vec<String> {
    let mut failures = Vec::new();
    // Issue 11: ≥ 95 % named first and significant; ≥ 95 % at NRMS ≤ 1.3 after add; parameter
    // errors within 10 % (here: in ≥ 95 % of draws, the same rate as the other criteria; the
    // thermal parameters against their Cramér–Rao bounds, below).
    let need = (0.95 * total as f64).ceil() as usize;
    if first < need {
        failures.push(format!("{}: named first {}", label, rate(first, total)));
    }
    if nrms < need {
        failures.push(format!("{}: NRMS ≤ 1.3 after add {}", label, rate(nrms, total)));
    }
    for (k, v) in params {
        // The draws that report this parameter (pooled: only the families hiding it).
        let need = (0.95 * v.len() as f64).ceil() as usize;
        match bounded.get(k) {
            // Thermal parameters: their Cramér–Rao bound on a draw's design reaches 10–60 %
            // (τ long against the record, few time samples: only d∞/τ or α·ΔT/τ is then seen),
            // so "within 10 %" is asked only where the data support it. Asserted instead: (a) the
            // error within 3 bounds (an efficient estimator leaves 3 bounds in 0.3 % of draws;
            // 95 % leaves room for the linearised bound understating the spread where it is
            // large, > 30 %), and (b) within 10 % wherever the bound is below 3 % (10 % is then
            // ≥ 3.3 bounds away).
            Some(b) => {
                let ok = b.iter().filter(|p| p.0 <= 3.0 * p.1).count();
                if ok < need {
                    failures.push(format!("{}: {k} error ≤ 3 Cramér–Rao bounds {}", label, rate(ok, b.len())));
                }
                let tight: Vec<&(f64, f64)> = b.iter().filter(|p| p.1 < CRB_TIGHT).collect();
                let ok = tight.iter().filter(|p| p.0 <= PARAM_REL).count();
                if ok < (0.95 * tight.len() as f64).ceil() as usize {
                    failures.push(format!(
                        "{}: {k} within 10 % where the bound < 3 %: {}",
                        label,
                        rate(ok, tight.len())
                    ));
                }
            }
            None => {
                let ok = v.iter().filter(|e| **e <= PARAM_REL).count();
                if ok < need {
                    failures.push(format!("{}: {k} within 10 % {}", label, rate(ok, v.len())));
                }
            }
        }
    }
    failures
}

/// A cyclic lead error on regular or sparse targets whose spacing exceeds its period (it cannot be
/// resolved there): `diagnose` must never make a significant claim of a periodic effect at a wrong
/// period (not within 10 % of the truth). Issue 11: 0 in ≥ 50 draws. Also counted: any
/// significant claim. The cyclic_lead entry must name its aliases or say why it cannot be seen
/// (FORMAT.md §4 `aliases`, `note`). The default suite runs the first 25 draws (fixed by their
/// index); the 50-draw count of the issue is the ignored study below.
#[test]
fn unresolvable_cyclic_error_is_never_claimed_at_a_wrong_period() {
    unresolvable_study(draws_for(25));
}

/// The full study of [`unresolvable_cyclic_error_is_never_claimed_at_a_wrong_period`]: 50 draws
/// (issue 11: 0 wrong-period claims in ≥ 50).
#[test]
#[ignore = "a tool: the 50-draw unresolvable-cyclic-error study"]
fn unresolvable_cyclic_error_study() {
    unresolvable_study(draws_for(50));
}

fn unresolvable_study(n: u64) {
    let res = over_draws(&Family::UnresolvedCyclic, n, |_, dir| diagnose(dir, "start.toml"));
    let (mut wrong, mut any, mut aliases, mut errors) = (0, 0, 0, 0);
    let mut lines = Vec::new();
    for (d, r) in &res {
        let p = d.truth.cyclic.unwrap().0;
        match r {
            Err(e) => {
                errors += 1;
                lines.push(format!("  {}: {e}", d.describe()));
            }
            Ok(diag) => {
                let c = claims(diag);
                let bad: Vec<&Claim> = c.iter().filter(|cl| cl.period.is_some_and(|q| rel(q, p) > 0.1)).collect();
                any += usize::from(!c.is_empty());
                wrong += usize::from(!bad.is_empty());
                // FORMAT.md §4: `aliases` (periods that fit equally well here) or `note` (why the
                // candidate cannot be seen in this data) on the cyclic_lead entry.
                let nonempty = |v: Option<&Value>| {
                    v.is_some_and(|v| {
                        v.as_array().is_some_and(|a| !a.is_empty()) || v.as_str().is_some_and(|s| !s.is_empty())
                    })
                };
                let named =
                    diag["ranking"].as_array().into_iter().flatten().any(|e| {
                        e["effect"] == "cyclic_lead" && (nonempty(e.get("aliases")) || nonempty(e.get("note")))
                    });
                aliases += usize::from(named);
                if !c.is_empty() {
                    lines.push(format!(
                        "  {} (true period {:.3} mm): {}",
                        d.describe(),
                        p * 1e3,
                        c.iter().map(ToString::to_string).collect::<Vec<_>>().join(", ")
                    ));
                }
            }
        }
    }
    let total = res.len();
    eprintln!("{}", lines.join("\n"));
    eprintln!("unresolvable cyclic lead: significant claim at a wrong period: {}", rate(wrong, total));
    eprintln!("  any significant claim: {}", rate(any, total));
    eprintln!("  cyclic_lead entry names its aliases or why it cannot be seen: {}", rate(aliases, total));
    eprintln!("  command failures: {}", rate(errors, total));
    assert_eq!(errors, 0);
    // Issue 11: never a significant claim at a wrong period.
    assert_eq!(wrong, 0, "wrong-period claims {}", rate(wrong, total));
    // Issue 11: "the output names the aliases and the spacing that would resolve it" (every draw).
    assert_eq!(aliases, total, "cyclic_lead entry with `aliases` or `note`: {}", rate(aliases, total));
}

/// Write one draw for inspection: `VMT_GEN_DUMP="LABEL INDEX DIR"` (LABEL as the tables print it,
/// e.g. `complete_table`, `hidden_backlash`, `hidden_cyclic_lead+backlash`, `unresolved_cyclic`),
/// then `cargo test --release --test tests gen_diagnose::dump_draw -- --ignored`. Writes DIR/data/ and
/// DIR/{truth,complete,start}.toml.
#[test]
#[ignore = "a tool: writes the draw named by VMT_GEN_DUMP"]
fn dump_draw() {
    let spec = std::env::var("VMT_GEN_DUMP").expect("set VMT_GEN_DUMP=\"LABEL INDEX DIR\"");
    let parts: Vec<&str> = spec.split_whitespace().collect();
    assert_eq!(parts.len(), 3, "VMT_GEN_DUMP: expected \"LABEL INDEX DIR\", got {spec:?}");
    let mut all = vec![Family::CompletePointTable, Family::CompleteFriction, Family::UnresolvedCyclic];
    all.extend(hidden_families());
    let fam = all
        .into_iter()
        .find(|f| f.label() == parts[0])
        .unwrap_or_else(|| panic!("VMT_GEN_DUMP: unknown family label {:?}", parts[0]));
    let d = draw(&fam, parts[1].parse().expect("VMT_GEN_DUMP: INDEX must be a number"));
    d.write(Path::new(parts[2])).unwrap();
    eprintln!("{}\n{:#?}", d.describe(), d.truth);
}

/// Every `basis` of FORMAT.md §2 on fitted positioning (issue 11), on complete point tables of the
/// generator whose positioning is fitted (random smooth profiles, correlation lengths 30–300 mm,
/// not vmt's basis): with `bspline`, `harmonics` and `table` and no `order`, `vmt compare` reports
/// that basis and an order BIC chose (the table: one value per distinct target) and leaves a
/// residual at the noise: NRMS against the true σ ≤ 1.3 (the hidden-effect study's threshold:
/// noise plus the χ² scatter and a fitted shape's small bias) in every draw (the Legendre series
/// meets it in every draw of the same set), except harmonics at their largest order (complete
/// sine–cosine pairs cannot use every coefficient the targets determine), in at most 1 of 8. A smooth profile is what all three represent: a
/// B-spline or harmonic series of enough terms, a table exactly at its targets. With `order`
/// given, that order is used and reported as the model's.
#[test]
fn every_basis_fits_smooth_positioning_profiles_to_the_noise() {
    let fam = Family::CompletePointTable;
    let draws: Vec<Draw> = (0..40).map(|i| draw(&fam, i)).filter(|d| !d.truth.positioning_known).take(8).collect();
    assert_eq!(draws.len(), 8, "the generator gave fewer than 8 draws with fitted positioning in 40");
    let results: Vec<(String, Result<(f64, String, u64, String), String>)> = draws
        .par_iter()
        .flat_map(|d| {
            let tmp = tempfile::tempdir().unwrap();
            d.write(tmp.path()).unwrap();
            let text = std::fs::read_to_string(tmp.path().join("complete.toml")).unwrap();
            let mut out = Vec::new();
            // Fixed orders on the first three draws (the order respected is not a rate).
            let fixed: &[(&str, Option<u32>)] =
                if d.index < 3 { &[("bspline", Some(6)), ("harmonics", Some(3))] } else { &[] };
            let free = [("poly", None), ("bspline", None), ("harmonics", None), ("table", None)];
            for &(basis, order) in free.iter().chain(fixed) {
                let key = match order {
                    Some(o) => format!("basis = \"{basis}\"\norder = {o}\n"),
                    None => format!("basis = \"{basis}\"\n"),
                };
                let model = text.replace(
                    "[effects.positioning]\nfit = true\n",
                    &format!("[effects.positioning]\nfit = true\n{key}"),
                );
                let name = format!("m_{basis}_{}.toml", order.unwrap_or(0));
                std::fs::write(tmp.path().join(&name), model).unwrap();
                let r = compare(tmp.path(), &name).map(|c| {
                    let s = &c["shapes"]["positioning"];
                    (
                        nrms_true(d, &c),
                        s["basis"].as_str().unwrap_or("?").to_string(),
                        s["order"].as_u64().unwrap_or(0),
                        s["chosen_by"].as_str().unwrap_or("?").to_string(),
                    )
                });
                out.push((format!("{} {basis} order {order:?}", d.describe()), r));
            }
            out
        })
        .collect();
    let mut failures = Vec::new();
    // "BIC over 1..N" with the order at N: the basis's largest order on these targets.
    let at_max = |chosen_by: &str, order: u64| {
        chosen_by
            .strip_prefix("BIC over 1..")
            .and_then(|r| r.split(|c: char| !c.is_ascii_digit()).next()?.parse::<u64>().ok())
            == Some(order)
    };
    let mut harmonics_at_max = 0;
    for (what, r) in &results {
        match r {
            Err(e) => failures.push(format!("{what}: {e}")),
            Ok((nrms, basis, order, chosen_by)) => {
                eprintln!("{what}: NRMS vs true σ {nrms:.3}, basis {basis}, order {order} ({chosen_by})");
                let want =
                    if what.contains(" poly ") { "legendre" } else { what.split(' ').rev().nth(2).unwrap_or("") };
                if basis != want {
                    failures.push(format!("{what}: basis reported {basis}"));
                }
                if let Some(o) =
                    what.strip_suffix(')').and_then(|w| w.rsplit("Some(").next()).and_then(|o| o.parse::<u64>().ok())
                {
                    if *order != o || chosen_by != "model" {
                        failures.push(format!("{what}: order {order} chosen by {chosen_by}, the model gave {o}"));
                    }
                } else if *nrms > NRMS_AFTER_ADD && at_max(chosen_by, *order) && basis == "harmonics" {
                    // Complete pairs: at its largest order the series has 2H + 1 ≤ m − 1 of the m − 1
                    // coefficients the targets determine; a profile that needs them all is beyond it.
                    harmonics_at_max += 1;
                } else if *nrms > NRMS_AFTER_ADD {
                    failures.push(format!("{what}: NRMS vs true σ {nrms:.3} > {NRMS_AFTER_ADD}"));
                }
            }
        }
    }
    // Harmonics above NRMS 1.3 at their largest order: at most 1 of 8 (measured: draw 9, 17
    // targets, 7 harmonics + slope = 15 of the 16 coefficients, NRMS 1.375).
    assert!(harmonics_at_max <= 1, "harmonics above NRMS 1.3 at their largest order in {harmonics_at_max} of 8 draws");
    assert!(failures.is_empty(), "{}", failures.join("\n"));
}

/// A bad `order` is a clear error (exit 2 naming the file and `effects.positioning.order`): 0, more
/// coefficients than the distinct targets determine, and a `table` on a time series is refused by
/// its meaning (checked in tests/model_check.rs where time series are built).
#[test]
fn a_bad_basis_order_is_a_clear_error() {
    let d = (0..40).map(|i| draw(&Family::CompletePointTable, i)).find(|d| !d.truth.positioning_known).unwrap();
    let tmp = tempfile::tempdir().unwrap();
    d.write(tmp.path()).unwrap();
    let text = std::fs::read_to_string(tmp.path().join("complete.toml")).unwrap();
    for (basis, order) in
        [("poly", 0), ("poly", 100000), ("bspline", 1), ("bspline", 100000), ("harmonics", 100000), ("table", 100000)]
    {
        let model = text.replace(
            "[effects.positioning]\nfit = true\n",
            &format!("[effects.positioning]\nfit = true\nbasis = \"{basis}\"\norder = {order}\n"),
        );
        std::fs::write(tmp.path().join("bad.toml"), model).unwrap();
        let out = crate::util::vmt()
            .args(["compare", "--model", tmp.path().join("bad.toml").to_str().unwrap(), "--data"])
            .arg(tmp.path().join("data"))
            .output()
            .unwrap();
        let err = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(2), "{basis} order {order}: {err}");
        assert!(err.contains("bad.toml") && err.contains("effects.positioning.order"), "{basis} order {order}: {err}");
    }
}
