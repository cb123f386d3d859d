//! An independent generator of measurement sets for testing `vmt diagnose` / `add` / `compare`
//! (issue 11). Nothing here calls vmt's library: the physics below is written from the catalogue
//! (FORMAT.md §2) and the first-order laser model of DESIGN.md §2, and the files are written in the
//! FORMAT.md §1/§2 contract as another program (a laser's software, a data logger) would write them.
//!
//! A draw is a pure function of (family, index): ChaCha8 seeded from both, so every draw is
//! reproducible from its index alone, whatever the number of threads.
//!
//! Point tables (laser deviations actual − target, µm, at target x, approach direction d = ±1,
//! session time t = run start_time + the table's `t`), for a laser with measuring point (0, y, z) in
//! the axis frame (sensitive direction +x):
//!
//! ```text
//! y_i = o_ch + EXX(x) + z·EBX(x) − y·ECX(x)          (u·(ε × r) with ε = (0, EBX, ECX), r = (0, y, z))
//!       − d·b/2                                    (backlash b: the ISO reversal value B = x̄↑ − x̄↓ = −b,
//!                                                   the sign src/modelcheck.rs documents)
//!       + A·sin(2πx/p + φ)                          (cyclic lead, period p)
//!       + k·x                                      (scale error k, m/m)
//!       + α·ΔT∞·x·(1 − e^{−t/τ_e})                  (thermal expansion)
//!       + d∞·(1 − e^{−t/τ_d})                       (thermal drift)
//!       + N(0, σ²)
//! ```
//!
//! EXX, EBX, ECX are random smooth profiles: a slope, a bow, a wave (wavelength 0.2–0.6 m) and a
//! squared-exponential Gaussian process (correlation length 30–300 mm, drawn by random Fourier
//! features: f(x) = √(2/K)·Σ cos(ω_k·x + b_k), ω_k ~ N(0, 1/ℓ²), b_k ~ U(0, 2π); Rahimi & Recht
//! 2007), scaled to a peak-to-valley of 5–50 µm (positioning) or 5–40 µrad (angles).
//!
//! Friction sweeps (motor force, N, in constant-velocity cruises at v = feed·direction):
//! F = o + Fc·sgn v + Fv·v + (Fs − Fc)·sgn v·exp(−|v/vs|^δ) + N(0, σ_F²), the Stribeck law with a
//! shape exponent δ ∈ [1, 2] (Armstrong-Hélouvry 1994; δ = 1 Tustin, δ = 2 Gaussian).

#![allow(dead_code)]

/// Laser line sets of one X axis from the first-order volumetric model (tests/laser_independent.rs,
/// tests/laser_cli.rs).
pub mod laser;

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, Normal};
use std::fmt::Write as _;
use std::path::Path;

/// Steel's expansion coefficient, 1/K (the order of a machine's scale or screw).
const ALPHA_STEEL: f64 = 11.5e-6;
/// Minimum ratio of a hidden effect's peak signature to the per-reading noise σ: an effect that
/// is a few σ per reading is seen on tens of readings; below that no method can be asked to name it
/// in 95 % of draws with 10 % parameter error. (Backlash b/2 ≥ 6σ on ≥ 70 readings gives a 1σ
/// error of b below ≈ 2σ/√70/(b) ≈ 4 %.)
pub const MIN_SNR: f64 = 6.0;

/// An effect the generator can hide (the catalogue's name is [`Effect::name`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum Effect {
    Backlash,
    CyclicLead,
    ScaleError,
    ThermalExpansion,
    ThermalDrift,
    Pitch,
    Yaw,
    Stribeck,
    Viscous,
}

impl Effect {
    /// The catalogue name (FORMAT.md §2).
    pub fn name(self) -> &'static str {
        match self {
            Effect::Backlash => "backlash",
            Effect::CyclicLead => "cyclic_lead",
            Effect::ScaleError => "scale_error",
            Effect::ThermalExpansion => "thermal_expansion",
            Effect::ThermalDrift => "thermal_drift",
            Effect::Pitch => "pitch",
            Effect::Yaw => "yaw",
            Effect::Stribeck => "stribeck",
            Effect::Viscous => "viscous",
        }
    }

    /// Every hideable effect.
    pub const ALL: [Effect; 9] = [
        Effect::Backlash,
        Effect::CyclicLead,
        Effect::ScaleError,
        Effect::ThermalExpansion,
        Effect::ThermalDrift,
        Effect::Pitch,
        Effect::Yaw,
        Effect::Stribeck,
        Effect::Viscous,
    ];

    fn is_friction(self) -> bool {
        matches!(self, Effect::Stribeck | Effect::Viscous)
    }
}

/// What a family of draws tests.
#[derive(Clone, Debug, PartialEq)]
pub enum Family {
    /// Point table or friction sweep, nothing missing from the model.
    CompletePointTable,
    CompleteFriction,
    /// These effects are in the truth, absent from the starting model.
    Hidden(Vec<Effect>),
    /// A cyclic lead error on a regular or sparse layout whose spacing cannot resolve it; the
    /// starting model lacks it.
    UnresolvedCyclic,
}

impl Family {
    /// A short label (also the seed's salt).
    pub fn label(&self) -> String {
        match self {
            Family::CompletePointTable => "complete_table".into(),
            Family::CompleteFriction => "complete_friction".into(),
            Family::Hidden(e) => format!("hidden_{}", e.iter().map(|e| e.name()).collect::<Vec<_>>().join("+")),
            Family::UnresolvedCyclic => "unresolved_cyclic".into(),
        }
    }
}

/// How the manifest states the noise.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SigmaStated {
    /// The true σ.
    Correct,
    /// σ/3 (a data sheet's figure for ideal conditions).
    Understated,
    /// No `sigma` key.
    Missing,
}

/// Target layouts.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Layout {
    /// ISO 230-2: 7–25 targets over the travel, spacing irregular (±30 % of nominal).
    IsoIrregular,
    /// A regular grid, spacing 5–50 mm (whole mm).
    Regular,
    /// 5–8 targets, regularly spaced.
    Sparse,
    /// A dense run, spacing 1–4 mm over 0.1–0.4 m.
    Dense,
}

/// A random smooth profile (slope + bow + wave + Gaussian process), scaled to a peak-to-valley.
#[derive(Clone, Debug)]
pub struct Profile {
    x_lo: f64,
    x_hi: f64,
    slope: f64,
    bow: f64,
    wave: (f64, f64, f64),
    gp_weight: f64,
    gp: Vec<(f64, f64)>,
    scale: f64,
    offset: f64,
    /// Correlation length of the GP part, m (for the record).
    pub corr_length: f64,
}

impl Profile {
    fn raw(&self, x: f64) -> f64 {
        let u = 2.0 * (x - self.x_lo) / (self.x_hi - self.x_lo) - 1.0;
        let (a, lambda, phi) = self.wave;
        let k = self.gp.len() as f64;
        let gp: f64 = self.gp.iter().map(|(w, b)| (w * x + b).cos()).sum::<f64>() * (2.0 / k).sqrt();
        self.slope * u + self.bow * u * u + a * (std::f64::consts::TAU * x / lambda + phi).sin() + self.gp_weight * gp
    }

    /// Value at x (m): metres for positioning, radians for angles.
    pub fn value(&self, x: f64) -> f64 {
        self.scale * (self.raw(x) - self.offset)
    }

    fn random(rng: &mut ChaCha8Rng, x_lo: f64, x_hi: f64, peak_to_valley: f64) -> Profile {
        let corr_length = log_uniform(rng, 0.03, 0.3);
        let normal = Normal::new(0.0, 1.0 / corr_length).unwrap();
        let gp = (0..40).map(|_| (normal.sample(rng), rng.gen_range(0.0..std::f64::consts::TAU))).collect();
        let wave = if rng.gen_bool(0.6) {
            (rng.gen_range(0.1..0.6), rng.gen_range(0.2..0.6), rng.gen_range(0.0..std::f64::consts::TAU))
        } else {
            (0.0, 0.4, 0.0)
        };
        let mut p = Profile {
            x_lo,
            x_hi,
            slope: rng.gen_range(-1.0..1.0),
            bow: rng.gen_range(-0.8..0.8),
            wave,
            gp_weight: rng.gen_range(0.2..1.0),
            gp,
            scale: 1.0,
            offset: 0.0,
            corr_length,
        };
        let grid: Vec<f64> = (0..=400).map(|i| p.raw(x_lo + (x_hi - x_lo) * i as f64 / 400.0)).collect();
        let lo = grid.iter().cloned().fold(f64::INFINITY, f64::min);
        let hi = grid.iter().cloned().fold(f64::NEG_INFINITY, f64::max);
        p.offset = lo;
        p.scale = peak_to_valley / (hi - lo);
        p
    }
}

/// Friction law parameters (SI).
#[derive(Clone, Copy, Debug)]
pub struct Friction {
    pub offset: f64,
    pub fc: f64,
    pub fs: f64,
    pub vs: f64,
    pub shape: f64,
    pub fv: f64,
}

impl Friction {
    /// F(v) = o + Fc·sgn v + Fv·v + (Fs − Fc)·sgn v·exp(−|v/vs|^δ), N.
    pub fn force(&self, v: f64) -> f64 {
        let s = v.signum();
        self.offset
            + self.fc * s
            + self.fv * v
            + (self.fs - self.fc) * s * (-(v / self.vs).abs().powf(self.shape)).exp()
    }
}

/// The truth of a draw: every effect present and its parameters (SI).
#[derive(Clone, Debug, Default)]
pub struct Truth {
    pub positioning: Option<Profile>,
    pub pitch: Option<Profile>,
    pub yaw: Option<Profile>,
    /// Backlash b, m.
    pub backlash: Option<f64>,
    /// Cyclic lead (period m, amplitude m, phase rad).
    pub cyclic: Option<(f64, f64, f64)>,
    /// Scale error k, m/m.
    pub scale: Option<f64>,
    /// Thermal expansion (α 1/K, ΔT∞ K, τ s).
    pub expansion: Option<(f64, f64, f64)>,
    /// Thermal drift (d∞ m, τ s).
    pub drift: Option<(f64, f64)>,
    pub friction: Option<Friction>,
    /// Whether the model is told the positioning profile (as a table) rather than fitting it.
    pub positioning_known: bool,
}

/// One generated draw: files to write and what was hidden.
#[derive(Clone, Debug)]
pub struct Draw {
    pub family: Family,
    pub index: u64,
    pub hidden: Vec<Effect>,
    pub truth: Truth,
    pub layout: Option<Layout>,
    /// True per-reading noise σ (m for lasers, N for the motor force).
    pub sigma_true: f64,
    pub sigma_stated: SigmaStated,
    /// Minimum spacing of the targets within a `[[runs]]` block, m (point tables).
    pub min_spacing: f64,
    /// Readings per (run, sensor) channel.
    pub channel_counts: Vec<((String, String), usize)>,
    /// Files of the measurement set (relative path, text), manifest.toml first.
    pub data_files: Vec<(String, String)>,
    /// Files of the models: truth.toml, complete.toml, start.toml and their tables.
    pub model_files: Vec<(String, String)>,
    /// Where and when each laser reading of a point table was taken (empty for friction sweeps):
    /// the design a Cramér–Rao bound needs.
    pub design: Vec<Sample>,
}

/// One laser reading's design: channel (block × laser, in `channel_counts` order), target x (m),
/// approach direction d = ±1, session time t (s), the laser's measuring point (y, z) (m).
#[derive(Clone, Copy, Debug)]
pub struct Sample {
    pub channel: usize,
    pub x: f64,
    pub d: f64,
    pub t: f64,
    pub y: f64,
    pub z: f64,
}

fn log_uniform(rng: &mut ChaCha8Rng, lo: f64, hi: f64) -> f64 {
    rng.gen_range(lo.ln()..hi.ln()).exp()
}

fn seed(family: &Family, index: u64) -> u64 {
    // FNV-1a of the label, then the index: stable across platforms and runs.
    let mut h: u64 = 0xcbf2_9ce4_8422_2325;
    for b in family.label().bytes().chain(index.to_le_bytes()) {
        h ^= u64::from(b);
        h = h.wrapping_mul(0x0100_0000_01b3);
    }
    h
}

/// One block of a point table: a `[[runs]]` entry.
struct Block {
    name: String,
    targets: Vec<f64>,
    cycles: u32,
    start_time: f64,
}

/// One laser: name and measuring point (y, z) in the axis frame, m.
struct Laser {
    name: String,
    y: f64,
    z: f64,
}

fn layout_targets(rng: &mut ChaCha8Rng, layout: Layout) -> Vec<f64> {
    let x0 = rng.gen_range(0.02..0.1);
    let round = |x: f64| (x * 1e5).round() / 1e5; // 0.01 mm, as a laser program lists targets
    match layout {
        Layout::IsoIrregular => {
            let travel = rng.gen_range(0.3..2.0);
            let m = ((travel * rng.gen_range(6.0_f64..15.0)).round() as usize).clamp(7, 25);
            let s = travel / (m - 1) as f64;
            (0..m)
                .map(|k| {
                    let jitter = if k == 0 || k == m - 1 { 0.0 } else { rng.gen_range(-0.3..0.3) * s };
                    round(x0 + k as f64 * s + jitter)
                })
                .collect()
        }
        Layout::Regular => {
            let s = rng.gen_range(5.0_f64..50.0).round() * 1e-3;
            let m = rng.gen_range(9..=41usize);
            (0..m).map(|k| round(x0 + k as f64 * s)).collect()
        }
        Layout::Sparse => {
            let travel = rng.gen_range(0.3..2.0);
            let m = rng.gen_range(5..=8usize);
            let s = (travel / (m - 1) as f64 * 1e3).round() * 1e-3;
            (0..m).map(|k| round(x0 + k as f64 * s)).collect()
        }
        Layout::Dense => {
            let span = rng.gen_range(0.1..0.4);
            let s = rng.gen_range(1.0..4.0) * 1e-3;
            let m = ((span / s) as usize).min(200);
            (0..m).map(|k| round(x0 + k as f64 * s + rng.gen_range(-0.1..0.1) * s)).collect()
        }
    }
}

fn draw_cycles(rng: &mut ChaCha8Rng, targets: usize) -> u32 {
    let n = if rng.gen_bool(0.7) { 5 } else { rng.gen_range(3..=10) };
    // Keep a table under ≈ 1200 readings per laser (a long day's dense run).
    n.min((600 / targets.max(1)) as u32).max(3)
}

/// Generate draw `index` of `family`.
pub fn draw(family: &Family, index: u64) -> Draw {
    let mut rng = ChaCha8Rng::seed_from_u64(seed(family, index));
    match family {
        Family::CompleteFriction => friction_draw(&mut rng, family, index, &[]),
        Family::Hidden(h) if h.iter().all(|e| e.is_friction()) => friction_draw(&mut rng, family, index, h),
        Family::CompletePointTable | Family::Hidden(_) | Family::UnresolvedCyclic => {
            table_draw(&mut rng, family, index)
        }
    }
}

fn sigma_stated(rng: &mut ChaCha8Rng) -> SigmaStated {
    match rng.gen_range(0..10) {
        0..=5 => SigmaStated::Correct,
        6 | 7 => SigmaStated::Understated,
        _ => SigmaStated::Missing,
    }
}

fn stated_value(s: SigmaStated, sigma: f64) -> Option<f64> {
    match s {
        SigmaStated::Correct => Some(sigma),
        SigmaStated::Understated => Some(sigma / 3.0),
        SigmaStated::Missing => None,
    }
}

fn table_draw(rng: &mut ChaCha8Rng, family: &Family, index: u64) -> Draw {
    let hidden: Vec<Effect> = match family {
        Family::Hidden(h) => h.clone(),
        Family::UnresolvedCyclic => vec![Effect::CyclicLead],
        Family::CompletePointTable | Family::CompleteFriction => vec![],
    };
    let hides = |e: Effect| hidden.contains(&e);
    let complete = matches!(family, Family::CompletePointTable);
    let unresolved = matches!(family, Family::UnresolvedCyclic);

    // Layout of the main block.
    let layout = if unresolved {
        if rng.gen_bool(0.7) {
            Layout::Regular
        } else {
            Layout::Sparse
        }
    } else {
        match rng.gen_range(0..10) {
            0..=4 => Layout::IsoIrregular,
            5..=6 => Layout::Regular,
            7 => Layout::Sparse,
            _ => Layout::Dense,
        }
    };
    let mut main = layout_targets(rng, layout);
    let spacing = |t: &[f64]| t.windows(2).map(|w| w[1] - w[0]).fold(f64::INFINITY, f64::min);
    let mut truth = Truth::default();

    // Cyclic lead: present when hidden, or in some complete draws; resolvable only with a dense
    // block of spacing p/8–p/5 over 12–25 periods; unresolved draws use a period below the spacing.
    let want_cyclic = hides(Effect::CyclicLead) || (complete && rng.gen_bool(0.2));
    let mut dense_block: Option<Vec<f64>> = None;
    if want_cyclic {
        if unresolved {
            let s = spacing(&main);
            // Any period shorter than the spacing (4–40 mm, at least 1.2× below it).
            let p_hi = (s / 1.2).min(0.040);
            let p = log_uniform(rng, 0.004, p_hi.max(0.0041));
            truth.cyclic = Some((p, rng.gen_range(1.0e-6..5.0e-6), rng.gen_range(0.0..std::f64::consts::TAU)));
        } else {
            let p = log_uniform(rng, 0.004, 0.040);
            let s = p / rng.gen_range(5.0..8.0);
            let span = p * rng.gen_range(12.0..25.0);
            let x0 = rng.gen_range(main[0]..main[0] + 0.5 * (main[main.len() - 1] - main[0]));
            let m = (span / s) as usize;
            let t: Vec<f64> =
                (0..m).map(|k| ((x0 + k as f64 * s + rng.gen_range(-0.1..0.1) * s) * 1e5).round() / 1e5).collect();
            dense_block = Some(t);
            truth.cyclic = Some((p, rng.gen_range(1.0e-6..5.0e-6), rng.gen_range(0.0..std::f64::consts::TAU)));
        }
    }
    let all_targets: Vec<f64> = {
        let mut v: Vec<f64> = main.iter().chain(dense_block.iter().flatten()).cloned().collect();
        v.sort_by(f64::total_cmp);
        v.dedup();
        v
    };
    let (x_lo, x_hi) = (all_targets[0], all_targets[all_targets.len() - 1]);

    // Scale error: separable from a fitted positioning profile only if the profile is known (a
    // compensation table from an earlier calibration): then the model is told it. Its laser is on
    // the scale's line (y = z = 0, Abbe-free as ISO 230-2 recommends): at an Abbe offset an
    // unmodelled pitch or yaw of the carriage would give the same slope (z·EBX = k·x), and no
    // method could tell them apart.
    let want_scale = hides(Effect::ScaleError) || (complete && rng.gen_bool(0.1));
    // Sensors: one laser, or two at different heights (pitch) or lateral offsets (yaw).
    let want_pitch = !want_scale && (hides(Effect::Pitch) || (complete && rng.gen_bool(0.25)));
    let want_yaw = !want_scale && !want_pitch && (hides(Effect::Yaw) || (complete && rng.gen_bool(0.15)));
    let (y0, z0) = if want_scale { (0.0, 0.0) } else { (rng.gen_range(-0.1..0.1), rng.gen_range(0.05..0.3)) };
    let mut lasers = vec![Laser { name: "laser_a".into(), y: y0, z: z0 }];
    if want_pitch {
        lasers.push(Laser { name: "laser_b".into(), y: y0, z: z0 + rng.gen_range(0.1..0.4) });
        truth.pitch = Some({
            let a = rng.gen_range(5e-6..40e-6);
            Profile::random(rng, x_lo, x_hi, a)
        });
    }
    if want_yaw {
        lasers.push(Laser { name: "laser_b".into(), y: y0 + rng.gen_range(0.1..0.4), z: z0 });
        truth.yaw = Some({
            let a = rng.gen_range(5e-6..40e-6);
            Profile::random(rng, x_lo, x_hi, a)
        });
    }
    truth.positioning = Some({
        let a = rng.gen_range(5e-6..50e-6);
        Profile::random(rng, x_lo, x_hi, a)
    });

    if want_scale {
        let k = rng.gen_range(5e-6..100e-6) * if rng.gen_bool(0.5) { 1.0 } else { -1.0 };
        truth.scale = Some(k);
        truth.positioning_known = true;
    }
    if hides(Effect::Backlash) || (complete && rng.gen_bool(0.5)) {
        truth.backlash = Some(rng.gen_range(0.5e-6..10e-6));
    }

    // Times: readings every dt (move + settle), ISO order (forward then backward per cycle); a
    // `t` column when thermal effects act (always then) or at random.
    let want_expansion = hides(Effect::ThermalExpansion) || (complete && rng.gen_bool(0.15));
    let want_drift = hides(Effect::ThermalDrift) || (complete && rng.gen_bool(0.2));
    let has_t = want_expansion || want_drift || rng.gen_bool(0.5);
    let dt = rng.gen_range(3.0..10.0);
    let cycles_main = draw_cycles(rng, main.len());
    let mut blocks =
        vec![Block { name: "iso".into(), targets: std::mem::take(&mut main), cycles: cycles_main, start_time: 0.0 }];
    let dur = |b: &Block| 2.0 * b.targets.len() as f64 * b.cycles as f64 * dt;
    if let Some(d) = dense_block {
        let cycles = rng.gen_range(2..=3);
        let start = dur(&blocks[0]) + rng.gen_range(60.0..1800.0);
        blocks.push(Block { name: "dense".into(), targets: d, cycles, start_time: start });
    }
    // A warm repeat of the test (thermal draws, sometimes): the same targets later.
    if (want_expansion || want_drift) && rng.gen_bool(0.4) {
        let b0 = &blocks[0];
        let start = blocks.iter().map(|b| b.start_time + dur(b)).fold(0.0, f64::max) + rng.gen_range(600.0..3600.0);
        blocks.push(Block { name: "warm".into(), targets: b0.targets.clone(), cycles: b0.cycles, start_time: start });
    }
    let t_end = blocks.iter().map(|b| b.start_time + dur(b)).fold(0.0, f64::max);
    if want_expansion {
        let tau = t_end * rng.gen_range(0.1..0.7);
        truth.expansion = Some((ALPHA_STEEL * rng.gen_range(0.9..1.1), rng.gen_range(0.5..3.0), tau));
    }
    if want_drift {
        let tau = t_end * rng.gen_range(0.1..0.7);
        let v = rng.gen_range(2e-6..15e-6) * if rng.gen_bool(0.5) { 1.0 } else { -1.0 };
        truth.drift = Some((v, tau));
    }

    // Noise: σ 0.05–1 µm (log-uniform), capped for hidden effects at signature/MIN_SNR.
    let mut sigma = log_uniform(rng, 0.05e-6, 1e-6);
    for e in &hidden {
        let sig = signature(&truth, *e, &lasers, &Reach { x_lo, x_hi, t_end, v_max: 0.0 });
        if !unresolved {
            sigma = sigma.min(sig / MIN_SNR);
        }
    }
    let stated = sigma_stated(rng);

    // Readings.
    let noise = Normal::new(0.0, sigma).unwrap();
    let mut data_files = Vec::new();
    let mut counts = Vec::new();
    let mut runs_toml = String::new();
    let mut design = Vec::new();
    for (bi, b) in blocks.iter().enumerate() {
        let mut csv = String::from("target[mm],run,direction");
        if has_t {
            csv.push_str(",t[s]");
        }
        for l in &lasers {
            write!(csv, ",{}[um]", l.name).unwrap();
        }
        csv.push('\n');
        let offsets: Vec<f64> = lasers.iter().map(|_| rng.gen_range(-5e-6..5e-6)).collect();
        let mut t = 0.0;
        let mut n = 0;
        for c in 1..=b.cycles {
            for d in [1.0, -1.0] {
                let order: Vec<f64> =
                    if d > 0.0 { b.targets.clone() } else { b.targets.iter().rev().cloned().collect() };
                for x in order {
                    t += dt * rng.gen_range(0.9..1.1);
                    let ts = b.start_time + t;
                    write!(csv, "{:.5},{c},{}", x * 1e3, d as i32).unwrap();
                    if has_t {
                        write!(csv, ",{t:.3}").unwrap();
                    }
                    for (li, (l, o)) in lasers.iter().zip(&offsets).enumerate() {
                        let channel = bi * lasers.len() + li;
                        design.push(Sample { channel, x, d, t: ts, y: l.y, z: l.z });
                        let y = o + reading(&truth, l, x, d, ts) + noise.sample(rng);
                        write!(csv, ",{:.6}", y * 1e6).unwrap();
                    }
                    csv.push('\n');
                    n += 1;
                }
            }
        }
        for l in &lasers {
            counts.push(((b.name.clone(), l.name.clone()), n));
        }
        let file = format!("{}.csv", b.name);
        write!(
            runs_toml,
            "\n[[runs]]\nname = \"{}\"\nfile = \"{file}\"\nprocedure = \"positioning\"\naxis = \"x\"\n",
            b.name
        )
        .unwrap();
        if has_t {
            writeln!(runs_toml, "start_time = {:.3}", b.start_time).unwrap();
        }
        data_files.push((file, csv));
    }
    let mut manifest = format!(
        "format = \"vmt-measurements/1\"\ndescription = \"independent generator: {} draw {index}\"\n",
        family.label()
    );
    for l in &lasers {
        write!(
            manifest,
            "\n[[sensors]]\nname = \"{}\"\nkind = \"laser_linear\"\naxis = \"x\"\nposition = [0.0, {:.4}, {:.4}]\ndirection = [1.0, 0.0, 0.0]\n",
            l.name, l.y, l.z
        )
        .unwrap();
        if let Some(s) = stated_value(stated, sigma) {
            writeln!(manifest, "sigma = {s:e}").unwrap();
        }
    }
    manifest.push_str(&runs_toml);
    data_files.insert(0, ("manifest.toml".into(), manifest));

    let model_files = table_models(&truth, &all_targets, &hidden);
    // Within each block (blocks may interleave: their targets are not one layout).
    let min_spacing = blocks.iter().map(|b| spacing(&b.targets)).fold(f64::INFINITY, f64::min);
    Draw {
        family: family.clone(),
        index,
        hidden,
        truth,
        layout: Some(layout),
        sigma_true: sigma,
        sigma_stated: stated,
        min_spacing,
        channel_counts: counts,
        data_files,
        model_files,
        design,
    }
}

/// The true deviation (m) a laser reads at target x, direction d, session time t (module doc).
fn reading(tr: &Truth, l: &Laser, x: f64, d: f64, t: f64) -> f64 {
    let mut y = 0.0;
    if let Some(p) = &tr.positioning {
        y += p.value(x);
    }
    if let Some(p) = &tr.pitch {
        y += l.z * p.value(x);
    }
    if let Some(p) = &tr.yaw {
        y -= l.y * p.value(x);
    }
    if let Some(b) = tr.backlash {
        y -= d * b / 2.0;
    }
    if let Some((p, a, phi)) = tr.cyclic {
        y += a * (std::f64::consts::TAU * x / p + phi).sin();
    }
    if let Some(k) = tr.scale {
        y += k * x;
    }
    if let Some((alpha, dt, tau)) = tr.expansion {
        y += alpha * dt * x * (1.0 - (-t / tau).exp());
    }
    if let Some((v, tau)) = tr.drift {
        y += v * (1.0 - (-t / tau).exp());
    }
    y
}

/// What a data set spans: positions (m), the session's end (s), the fastest feed (m/s).
#[derive(Clone, Copy)]
struct Reach {
    x_lo: f64,
    x_hi: f64,
    t_end: f64,
    v_max: f64,
}

/// Peak signature of effect `e` in the readings (m for lasers, N for the motor force): what a
/// method has to see above the noise.
fn signature(tr: &Truth, e: Effect, lasers: &[Laser], r: &Reach) -> f64 {
    let Reach { x_lo, x_hi, t_end, v_max } = *r;
    let arm = |f: &dyn Fn(&Laser) -> f64| {
        let v: Vec<f64> = lasers.iter().map(f).collect();
        v.iter().cloned().fold(f64::NEG_INFINITY, f64::max) - v.iter().cloned().fold(f64::INFINITY, f64::min)
    };
    let p2p = |p: &Profile| {
        let g: Vec<f64> = (0..=200).map(|i| p.value(x_lo + (x_hi - x_lo) * i as f64 / 200.0)).collect();
        g.iter().cloned().fold(f64::NEG_INFINITY, f64::max) - g.iter().cloned().fold(f64::INFINITY, f64::min)
    };
    match e {
        Effect::Backlash => tr.backlash.unwrap_or(0.0) / 2.0,
        Effect::CyclicLead => tr.cyclic.map_or(0.0, |c| c.1),
        Effect::ScaleError => tr.scale.map_or(0.0, |k| k.abs() * (x_hi - x_lo) / 2.0),
        Effect::ThermalExpansion => {
            tr.expansion.map_or(0.0, |(a, dt, tau)| a * dt * x_hi * (1.0 - (-t_end / tau).exp()) / 2.0)
        }
        Effect::ThermalDrift => tr.drift.map_or(0.0, |(v, tau)| v.abs() * (1.0 - (-t_end / tau).exp()) / 2.0),
        Effect::Pitch => tr.pitch.as_ref().map_or(0.0, |p| p2p(p) * arm(&|l| l.z) / 2.0),
        Effect::Yaw => tr.yaw.as_ref().map_or(0.0, |p| p2p(p) * arm(&|l| l.y) / 2.0),
        Effect::Stribeck => tr.friction.map_or(0.0, |f| f.fs - f.fc),
        Effect::Viscous => tr.friction.map_or(0.0, |f| f.fv * v_max),
    }
}

/// A profile as a FORMAT.md §2 table (position, value) at the given positions.
fn profile_table(p: &Profile, xs: &[f64], unit: &str, scale: f64, name: &str) -> String {
    let mut s = format!("position[mm],{name}[{unit}]\n");
    for x in xs {
        writeln!(s, "{:.5},{:.9}", x * 1e3, p.value(*x) * scale).unwrap();
    }
    s
}

/// truth.toml (every effect given, profiles as tables at the targets), complete.toml (every effect
/// of the truth, `fit = true`; a known positioning profile given as its table) and start.toml (the
/// complete model minus the hidden effects).
fn table_models(tr: &Truth, targets: &[f64], hidden: &[Effect]) -> Vec<(String, String)> {
    let head = "format = \"vmt-model/1\"\naxis = \"x\"\n";
    let mut files = Vec::new();
    let mut truth = String::from(head);
    let mut fitted: Vec<(Option<Effect>, String)> = Vec::new(); // (hideable effect, TOML) of complete.toml
    if let Some(p) = &tr.positioning {
        files.push(("truth_positioning.csv".to_string(), profile_table(p, targets, "um", 1e6, "positioning")));
        truth.push_str("\n[effects.positioning]\ntable = \"truth_positioning.csv\"\n");
        fitted.push((
            None,
            if tr.positioning_known {
                "[effects.positioning]\ntable = \"truth_positioning.csv\"\n".into()
            } else {
                "[effects.positioning]\nfit = true\n".into()
            },
        ));
    }
    for (e, p) in [(Effect::Pitch, &tr.pitch), (Effect::Yaw, &tr.yaw)] {
        if let Some(p) = p {
            let f = format!("truth_{}.csv", e.name());
            files.push((f.clone(), profile_table(p, targets, "urad", 1e6, e.name())));
            write!(truth, "\n[effects.{}]\ntable = \"{f}\"\n", e.name()).unwrap();
            fitted.push((Some(e), format!("[effects.{}]\nfit = true\n", e.name())));
        }
    }
    if let Some(b) = tr.backlash {
        write!(truth, "\n[effects.backlash]\nvalue = {b:e}\n").unwrap();
        fitted.push((Some(Effect::Backlash), "[effects.backlash]\nfit = true\n".into()));
    }
    if let Some((p, a, phi)) = tr.cyclic {
        write!(truth, "\n[effects.cyclic_lead]\nperiod = {p:e}\namplitude = {a:e}\nphase = {phi}\n").unwrap();
        // The user knows the screw's lead: the period is given as the starting value.
        fitted.push((Some(Effect::CyclicLead), format!("[effects.cyclic_lead]\nfit = true\nperiod = {p:e}\n")));
    }
    if let Some(k) = tr.scale {
        write!(truth, "\n[effects.scale_error]\nvalue = {k:e}\n").unwrap();
        fitted.push((Some(Effect::ScaleError), "[effects.scale_error]\nfit = true\n".into()));
    }
    if let Some((alpha, dt, tau)) = tr.expansion {
        write!(truth, "\n[effects.thermal_expansion]\nalpha = {alpha:e}\ndelta_t = {dt}\ntau = {tau}\n").unwrap();
        fitted.push((Some(Effect::ThermalExpansion), "[effects.thermal_expansion]\nfit = true\n".into()));
    }
    if let Some((v, tau)) = tr.drift {
        write!(truth, "\n[effects.thermal_drift]\nvalue = {v:e}\ntau = {tau}\n").unwrap();
        fitted.push((Some(Effect::ThermalDrift), "[effects.thermal_drift]\nfit = true\n".into()));
    }
    files.push(("truth.toml".into(), truth));
    files.extend(complete_and_start(head, &fitted, hidden));
    files
}

fn complete_and_start(head: &str, fitted: &[(Option<Effect>, String)], hidden: &[Effect]) -> Vec<(String, String)> {
    let mut complete = String::from(head);
    let mut start = String::from(head);
    for (e, text) in fitted {
        complete.push('\n');
        complete.push_str(text);
        if !e.is_some_and(|e| hidden.contains(&e)) {
            start.push('\n');
            start.push_str(text);
        }
    }
    vec![("complete.toml".into(), complete), ("start.toml".into(), start)]
}

fn friction_draw(rng: &mut ChaCha8Rng, family: &Family, index: u64, hidden: &[Effect]) -> Draw {
    let fc = rng.gen_range(20.0..300.0);
    let shape = match rng.gen_range(0..3) {
        0 => 1.0,
        1 => 2.0,
        _ => rng.gen_range(1.0..2.0),
    };
    let f = Friction {
        offset: rng.gen_range(-20.0..20.0),
        fc,
        fs: fc * rng.gen_range(1.15..2.0),
        vs: log_uniform(rng, 0.5e-3, 10e-3),
        shape,
        fv: log_uniform(rng, 100.0, 3000.0),
    };
    let per_dir = rng.gen_range(12..=18usize);
    let v_min = log_uniform(rng, 5e-5, 2e-4).min(f.vs / rng.gen_range(5.0..10.0));
    let v_max = log_uniform(rng, 0.05, 0.3);
    let rate = rng.gen_range(200.0..1000.0);
    let mut sigma = rng.gen_range(0.5..5.0);
    let tr = Truth { friction: Some(f), ..Truth::default() };
    for e in hidden {
        sigma = f64::min(sigma, signature(&tr, *e, &[], &Reach { x_lo: 0.0, x_hi: 0.0, t_end: 0.0, v_max }) / MIN_SNR);
    }
    let stated = sigma_stated(rng);
    let noise = Normal::new(0.0, sigma).unwrap();
    let mut manifest = format!(
        "format = \"vmt-measurements/1\"\ndescription = \"independent generator: {} draw {index}\"\n\n[[sensors]]\nname = \"force\"\nkind = \"motor_force\"\naxis = \"x\"\n",
        family.label()
    );
    if let Some(s) = stated_value(stated, sigma) {
        writeln!(manifest, "sigma = {s:e}").unwrap();
    }
    let mut data_files = Vec::new();
    let mut counts = Vec::new();
    let mut t0 = 0.0;
    let mut k = 0;
    for i in 0..per_dir {
        let frac = (i as f64 + rng.gen_range(-0.3..0.3)).clamp(0.0, (per_dir - 1) as f64) / (per_dir - 1) as f64;
        let speed = (v_min.ln() + frac * (v_max / v_min).ln()).exp();
        for dir in [1.0, -1.0] {
            k += 1;
            let v = speed * dir;
            let duration = rng.gen_range(0.2..0.5_f64).min(0.5 / speed);
            let n = ((duration * rate) as usize).max(20);
            let x_start = if dir > 0.0 { 0.2 } else { 0.8 };
            let mut csv = String::from("t[s],x_cmd[mm],force[N]\n");
            for j in 0..n {
                let t = j as f64 / rate;
                writeln!(csv, "{t:.5},{:.6},{:.5}", (x_start + v * t) * 1e3, f.force(v) + noise.sample(rng)).unwrap();
            }
            let name = format!("v{k:02}");
            write!(
                manifest,
                "\n[[runs]]\nname = \"{name}\"\nfile = \"{name}.csv\"\nprocedure = \"friction_sweep\"\naxis = \"x\"\nstart_time = {t0:.3}\nfeed = {speed:e}\ndirection = {}\n",
                dir as i32
            )
            .unwrap();
            t0 += duration + rng.gen_range(1.0..3.0);
            counts.push(((name.clone(), "force".to_string()), n));
            data_files.push((format!("{name}.csv"), csv));
        }
    }
    data_files.insert(0, ("manifest.toml".into(), manifest));
    let head = "format = \"vmt-model/1\"\naxis = \"x\"\n";
    // truth.toml carries the Coulomb level inside the Stribeck law (stribeck.fc), the form `vmt
    // compare` predicts correctly when everything is given; truth_split.toml is the catalogue's
    // coulomb + stribeck form of the same law (the simulator reads both the same way).
    let truth = format!(
        "{head}\n[effects.viscous]\nfv = {}\n\n[effects.stribeck]\nfc = {}\nfs = {}\nvs = {:e}\nshape = {}\n",
        f.fv, f.fc, f.fs, f.vs, f.shape
    );
    let truth_split = format!(
        "{head}\n[effects.coulomb]\nfc = {}\n\n[effects.viscous]\nfv = {}\n\n[effects.stribeck]\nfs = {}\nvs = {:e}\nshape = {}\n",
        f.fc, f.fv, f.fs, f.vs, f.shape
    );
    // The force offset o is every motor-force channel's own offset in vmt's model (not an effect).
    let fitted = vec![
        (None, "[effects.coulomb]\nfit = true\n".to_string()),
        (Some(Effect::Viscous), "[effects.viscous]\nfit = true\n".to_string()),
        (Some(Effect::Stribeck), "[effects.stribeck]\nfit = true\n".to_string()),
    ];
    let mut model_files = vec![("truth.toml".to_string(), truth), ("truth_split.toml".to_string(), truth_split)];
    model_files.extend(complete_and_start(head, &fitted, hidden));
    Draw {
        family: family.clone(),
        index,
        hidden: hidden.to_vec(),
        truth: tr,
        layout: None,
        sigma_true: sigma,
        sigma_stated: stated,
        min_spacing: f64::NAN,
        channel_counts: counts,
        data_files,
        model_files,
        design: Vec::new(),
    }
}

impl Draw {
    /// Write the draw under `dir`: `dir/data/` (the measurement set) and `dir/*.toml` (models).
    pub fn write(&self, dir: &Path) -> std::io::Result<()> {
        std::fs::create_dir_all(dir.join("data"))?;
        for (name, text) in &self.data_files {
            std::fs::write(dir.join("data").join(name), text)?;
        }
        for (name, text) in &self.model_files {
            std::fs::write(dir.join(name), text)?;
        }
        Ok(())
    }

    /// A one-line description for tables and failure messages.
    pub fn describe(&self) -> String {
        let readings: usize = self.channel_counts.iter().map(|c| c.1).sum();
        format!(
            "{} #{}: layout {:?}, {} channels, {} readings, σ {:.3e} ({:?}), min spacing {:.1} mm",
            self.family.label(),
            self.index,
            self.layout,
            self.channel_counts.len(),
            readings,
            self.sigma_true,
            self.sigma_stated,
            self.min_spacing * 1e3
        )
    }
}
