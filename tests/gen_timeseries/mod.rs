//! Independent generators of time-series measurement sets for the model-check loop (issue 19).
//!
//! Written from the physics, not from vmt's simulator, defaults or bases: the files are written by
//! hand in the FORMAT.md §1 contract (manifest + CSV) with a starting model in FORMAT.md §2, and the
//! truth of each draw goes to `truth.json` beside them for the assertions.
//!
//! **Accelerometer passes** ([`accel_set`]): a carriage driven at constant speed v along x over a
//! guideway whose straightness E_y(x), E_z(x) is a random smooth profile (a Gaussian process of
//! squared-exponential covariance, drawn by random Fourier features, several correlation lengths
//! 40–400 mm) plus short-wave rail waviness (λ 4–40 mm). An accelerometer with sensitive direction
//! u reads the mean over its sample interval Δt of the proper acceleration of its mounting point
//! (a boxcar anti-alias filter, as an integrating ADC):
//!
//! ```text
//! a_i = [v_u(t_i) − v_u(t_{i−1})]/Δt + g·u_y·EAX(x_i) + (u·m)·[q̇(t_i) − q̇(t_{i−1})]/Δt + b_u + n_i
//! v_u(t) = v·E_u'(x(t))                         (velocity of the point across the axis)
//! q̈ + 2ζω q̇ + ω² q = −m·a_base(t)             (one structural mode, shape m in the y–z plane)
//! ```
//!
//! with g·EAX the gravity seen through the roll (a y accelerometer tilted by EAX about x reads
//! g·sin EAX), n white with one-sided density ρ (σ = ρ·√(f_s/2) after the boxcar), b a bias. The
//! mode is integrated exactly (zero-order hold of a_base on 1/(40 f_s) steps, matrix exponential of
//! the damped oscillator in closed form).
//!
//! **Encoder logs** ([`encoder_set`]): a ball-screw axis under a discrete P position loop at the
//! servo rate (kv, optional velocity feed-forward), fed back from the motor's rotary encoder
//! (semi-closed loop) or from the linear scale (closed loop). Per servo tick h:
//!
//! ```text
//! ẋ_m = ff·ẋ_cmd + kv·(x_cmd − feedback)        (motor, linear equivalent θ·lead/2π)
//! nut = x_m + P(x_m) + A_l·sin(2π x_m/p_l + φ_l)  (screw: smooth lead error + cyclic lead)
//! table: stands while |nut − x_t| ≤ b/2, else is pushed (play: backlash b)
//! scale = x_t + A_i·sin(2π x_t/p_i + φ_i) + noise  (interpolation error at the table's position)
//! motor = x_m + noise
//! ```
//!
//! Runs: constant-velocity passes both ways (cruise only, logged after the transient settled),
//! crawls at 5–80 mm/min and a slow reversal (a `free` run), logged at a divisor of the servo rate.

#![allow(dead_code)]

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::StandardNormal;
use std::fmt::Write as _;
use std::path::Path;

/// Standard gravity, m/s² (as DESIGN.md §2).
pub const G: f64 = 9.80665;

/// A seeded source of the draws.
pub struct Draw(ChaCha8Rng);

impl Draw {
    pub fn new(seed: u64) -> Draw {
        Draw(ChaCha8Rng::seed_from_u64(seed))
    }
    pub fn uniform(&mut self, a: f64, b: f64) -> f64 {
        a + (b - a) * self.0.gen::<f64>()
    }
    pub fn log_uniform(&mut self, a: f64, b: f64) -> f64 {
        self.uniform(a.ln(), b.ln()).exp()
    }
    pub fn normal(&mut self) -> f64 {
        self.0.sample(StandardNormal)
    }
    pub fn sign(&mut self) -> f64 {
        if self.0.gen::<bool>() {
            1.0
        } else {
            -1.0
        }
    }
    pub fn chance(&mut self, p: f64) -> bool {
        self.0.gen::<f64>() < p
    }
}

/// A profile f(x) = Σ a_j·cos(k_j·x + φ_j), m (or rad), with analytic derivatives.
#[derive(Clone, Debug, Default)]
pub struct Waves {
    pub k: Vec<f64>,
    pub a: Vec<f64>,
    pub phi: Vec<f64>,
}

impl Waves {
    /// A Gaussian process of standard deviation `rms` and squared-exponential correlation length
    /// `ell` (m) by `n` random Fourier features (Rahimi & Recht 2007): k ~ N(0, 1/ℓ²), φ uniform,
    /// amplitude rms·√(2/n).
    pub fn smooth(d: &mut Draw, rms: f64, ell: f64, n: usize) -> Waves {
        let mut w = Waves::default();
        for _ in 0..n {
            w.k.push(d.normal() / ell);
            w.a.push(rms * (2.0 / n as f64).sqrt());
            w.phi.push(d.uniform(0.0, std::f64::consts::TAU));
        }
        w
    }
    /// Rail waviness: `n` sinusoids of wavelengths log-uniform in [lo, hi] m, total RMS `rms`.
    pub fn waviness(d: &mut Draw, rms: f64, lo: f64, hi: f64, n: usize) -> Waves {
        let mut w = Waves::default();
        for _ in 0..n {
            w.k.push(std::f64::consts::TAU / d.log_uniform(lo, hi));
            w.a.push(rms * (2.0 / n as f64).sqrt() * d.uniform(0.5, 1.5));
            w.phi.push(d.uniform(0.0, std::f64::consts::TAU));
        }
        w
    }
    pub fn plus(mut self, o: &Waves) -> Waves {
        self.k.extend(&o.k);
        self.a.extend(&o.a);
        self.phi.extend(&o.phi);
        self
    }
    pub fn value(&self, x: f64) -> f64 {
        (0..self.k.len()).map(|j| self.a[j] * (self.k[j] * x + self.phi[j]).cos()).sum()
    }
    pub fn d1(&self, x: f64) -> f64 {
        (0..self.k.len()).map(|j| -self.a[j] * self.k[j] * (self.k[j] * x + self.phi[j]).sin()).sum()
    }
    pub fn d2(&self, x: f64) -> f64 {
        (0..self.k.len()).map(|j| -self.a[j] * self.k[j] * self.k[j] * (self.k[j] * x + self.phi[j]).cos()).sum()
    }
}

/// One sensor line of a manifest.
pub struct SensorSpec {
    pub name: String,
    pub kind: &'static str,
    pub position: [f64; 3],
    pub direction: [f64; 3],
    pub sigma: f64,
    /// Extra manifest lines (optional keys).
    pub extra: String,
}

/// One run: manifest keys and columns (name with unit suffix, values).
pub struct RunSpec {
    pub name: String,
    pub procedure: &'static str,
    pub feed: Option<f64>,
    pub direction: Option<i8>,
    pub start_time: f64,
    pub columns: Vec<(String, Vec<f64>)>,
}

/// Writes a FORMAT.md §1 measurement set (manifest.toml + one CSV per run) to `dir`.
pub fn write_set(dir: &Path, description: &str, sensors: &[SensorSpec], runs: &[RunSpec]) {
    std::fs::create_dir_all(dir).unwrap();
    let mut m = String::new();
    writeln!(m, "format = \"vmt-measurements/1\"\ndescription = \"{description}\"\n").unwrap();
    for s in sensors {
        writeln!(
            m,
            "[[sensors]]\nname = \"{}\"\nkind = \"{}\"\naxis = \"x\"\nposition = [{:?}, {:?}, {:?}]\n\
             direction = [{:?}, {:?}, {:?}]\nsigma = {:e}\n{}",
            s.name,
            s.kind,
            s.position[0],
            s.position[1],
            s.position[2],
            s.direction[0],
            s.direction[1],
            s.direction[2],
            s.sigma,
            s.extra
        )
        .unwrap();
    }
    for r in runs {
        write!(
            m,
            "[[runs]]\nname = \"{}\"\nfile = \"{}.csv\"\nprocedure = \"{}\"\naxis = \"x\"\nstart_time = {:?}\n",
            r.name, r.name, r.procedure, r.start_time
        )
        .unwrap();
        if let Some(f) = r.feed {
            writeln!(m, "feed = {f:?}").unwrap();
        }
        if let Some(d) = r.direction {
            writeln!(m, "direction = {d}").unwrap();
        }
        m.push('\n');
        let mut csv = String::new();
        let header: Vec<&str> = r.columns.iter().map(|c| c.0.as_str()).collect();
        writeln!(csv, "{}", header.join(",")).unwrap();
        let n = r.columns[0].1.len();
        for i in 0..n {
            let row: Vec<String> = r.columns.iter().map(|c| format!("{:?}", c.1[i])).collect();
            writeln!(csv, "{}", row.join(",")).unwrap();
        }
        std::fs::write(dir.join(format!("{}.csv", r.name)), csv).unwrap();
    }
    std::fs::write(dir.join("manifest.toml"), m).unwrap();
}

/// Writes a FORMAT.md §2 starting model: `effects` as `[effects.NAME]` tables with `fit = true`.
pub fn write_model(path: &Path, effects: &[&str]) {
    let mut m = String::from("format = \"vmt-model/1\"\naxis = \"x\"\n");
    for e in effects {
        writeln!(m, "[effects.{e}]\nfit = true").unwrap();
    }
    std::fs::write(path, m).unwrap();
}

// ------------------------------------------------------------------------------------------
// Accelerometer passes.

/// The clock that stamps an accelerometer draw's samples.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Clock {
    /// t_i = i/f_s exactly (to rounding).
    Even,
    /// A logger's: each instant i/f_s moved by Gaussian jitter of σ `jitter` (s), then rounded to
    /// the stamp's `resolution` (s). The samples are taken at the stamped instants (the data are
    /// exact at the times the file gives), so every interval is its own. Each sample is then lost
    /// with probability `lost` (a wireless or USB logger dropping packets): its row is not written,
    /// and the next sample is still the mean over its own interval.
    Logger { jitter: f64, resolution: f64, lost: f64 },
}

/// What an accelerometer draw hides from its starting model (straightness_y + straightness_z).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum AccelHidden {
    None,
    Resonance,
    Roll,
    ResonanceAndRoll,
}

/// The truth of an accelerometer draw.
#[derive(Clone, Debug)]
pub struct AccelTruth {
    pub hidden: AccelHidden,
    /// Mode frequency, Hz, and damping ratio (when present).
    pub mode: Option<(f64, f64)>,
    /// The mode's shape on (y, z): its input is the guideway's acceleration projected on it and
    /// each accelerometer reads its projection (a unit vector; present with `mode`).
    pub mode_shape: [f64; 2],
    /// Roll profile EAX(x), rad (when present).
    pub roll: Option<Waves>,
    /// Noise density, m/s²/√Hz, and the per-sample σ of each pass, m/s².
    pub density: f64,
    pub sigmas: Vec<f64>,
    /// Speeds, m/s, and sample rates, Hz, of the passes.
    pub speeds: Vec<f64>,
    pub rates: Vec<f64>,
    /// Total number of samples (all passes, both channels).
    pub samples: usize,
    /// χ² of the weakest hidden effect's contribution (Σ((h − mean h)/σ)² over all samples, the
    /// mean per pass and channel): each of two hidden effects must be visible on its own.
    pub hidden_chi2: f64,
    /// Cramér–Rao bound (σ_f Hz, σ_ζ) of the mode's frequency and damping from these samples
    /// (when a mode is present): (JᵀJ/σ²)⁻¹ with J = ∂(mode response)/∂(f, ζ) by central
    /// differences, with each pass's offset per channel, the mode's gain per channel and the
    /// straightness in its true family (every wave's amplitude and phase) profiled out
    /// ([`mode_crb`]): an error of a few of these is the best any estimator can do.
    pub mode_crb: Option<(f64, f64)>,
    /// The travel the passes cover, (x_lo, x_hi) in m.
    pub travel: (f64, f64),
    /// Cramér–Rao bound of the roll seen through gravity (when a roll is hidden and no mode): the
    /// RMS over the travel of the error of any unbiased estimate of the roll profile, its mean
    /// removed (an offset per pass hides it), rad ([`roll_crb`]).
    pub roll_crb: Option<f64>,
    /// χ² of the roll left after each pass's offset and the straightness in its true family are
    /// profiled out (when a roll is hidden; [`roll_profiled_chi2`]).
    pub roll_chi2_profiled: Option<f64>,
}

/// Exact one-step map of q̈ + 2ζω q̇ + ω² q = −a (a constant over the step h): state (q, q̇).
struct Oscillator {
    phi: [[f64; 2]; 2],
    gam: [f64; 2],
}

impl Oscillator {
    /// Underdamped closed form: q(t) = e^{−ζωt}(A cos ω_d t + B sin ω_d t) − a/ω².
    fn new(f: f64, zeta: f64, h: f64) -> Oscillator {
        let w = std::f64::consts::TAU * f;
        let wd = w * (1.0 - zeta * zeta).sqrt();
        let e = (-zeta * w * h).exp();
        let (c, s) = ((wd * h).cos(), (wd * h).sin());
        let zw = zeta * w;
        // Homogeneous solution from (q0, v0).
        let phi = [[e * (c + zw / wd * s), e * s / wd], [-e * w * w / wd * s, e * (c - zw / wd * s)]];
        // Particular part for a unit constant input −1: q_p = −1/ω²; deviation decays homogeneously.
        let qp = -1.0 / (w * w);
        let gam = [qp - (phi[0][0] * qp), -(phi[1][0] * qp)];
        Oscillator { phi, gam }
    }
    fn step(&self, x: [f64; 2], a: f64) -> [f64; 2] {
        [
            self.phi[0][0] * x[0] + self.phi[0][1] * x[1] + self.gam[0] * a,
            self.phi[1][0] * x[0] + self.phi[1][1] * x[1] + self.gam[1] * a,
        ]
    }
}

/// The cos and sin of every wave of `w`: (κ rad/m, is the sine).
fn wave_list(w: &Waves) -> Vec<(f64, bool)> {
    w.k.iter().flat_map(|&k| [(k, false), (k, true)]).collect()
}

/// The positions of the y channel's samples over passes `(v, dir, x₀, Δt, n)`, and an orthonormal
/// basis of what hides a roll seen through gravity there: each pass's offset and the guideway
/// acceleration of every wave of the straightness `straight_y` (amplitude and phase free).
fn roll_nuisance(passes: &[ModePass], straight_y: &Waves) -> (Vec<f64>, Vec<Vec<f64>>) {
    let total: usize = passes.iter().map(|p| p.4).sum();
    let xs: Vec<f64> =
        passes.iter().flat_map(|&(v, dirn, x0, dt, n)| (0..n).map(move |i| x0 + dirn * v * i as f64 * dt)).collect();
    let nuis_waves = wave_list(straight_y);
    let mut nuisance: Vec<Vec<f64>> = Vec::new();
    let mut at = 0;
    for &(_, _, _, _, n) in passes {
        nuisance.push((0..total).map(|i| if (at..at + n).contains(&i) { 1.0 } else { 0.0 }).collect());
        at += n;
    }
    // Geometric acceleration of each straightness wave: dir·v·(e'(x_i) − e'(x_{i−1}))/Δt.
    let e1 = |k: f64, sin: bool, x: f64| if sin { k * (k * x).cos() } else { -k * (k * x).sin() };
    for &(k, sin) in &nuis_waves {
        nuisance.push(
            passes
                .iter()
                .flat_map(|&(v, dirn, x0, dt, n)| {
                    (0..n).map(move |i| {
                        let (x, xp) = (x0 + dirn * v * i as f64 * dt, x0 + dirn * v * (i as f64 - 1.0) * dt);
                        dirn * v * (e1(k, sin, x) - e1(k, sin, xp)) / dt
                    })
                })
                .collect(),
        );
    }
    (xs, orthonormal(nuisance))
}

/// χ² of the roll seen through gravity on the y channel (G·roll(x)/σ, Σ over the samples) left
/// after what [`roll_nuisance`] spans is projected out: what of the roll no pass offset and no
/// straightness in its true family can take up.
fn roll_profiled_chi2(roll: &Waves, passes: &[ModePass], straight_y: &Waves, sigma: f64) -> f64 {
    let (xs, ortho) = roll_nuisance(passes, straight_y);
    let mut c: Vec<f64> = xs.iter().map(|&x| G * roll.value(x)).collect();
    project_out(&mut c, &ortho);
    c.iter().map(|v| (v / sigma).powi(2)).sum()
}

/// Cramér–Rao bound of a roll profile `roll` seen through gravity by the y accelerometer
/// ([`AccelTruth::roll_crb`]): the RMS over the travel `(x_lo, x_hi)` of the error of an unbiased
/// estimate of the roll profile, its mean removed, for passes `(v, dir, x₀, Δt, n)` and noise σ.
///
/// The y channel reads μ_i = G·roll(x_i) + geo(E_y)_i + b_p. The roll is in its true family (the
/// waves of `roll`, a cos and a sin coefficient each: θ); each pass's offset b_p and the straightness
/// E_y in its true family (every wave of `straight_y` with amplitude and phase free) are profiled out.
/// With D the roll columns left after the nuisance is projected out (D = U·S·Vᵀ), Cov(θ̂) ≥
/// σ²·V·S⁻²·Vᵀ, and the mean-square error of the de-meaned profile is tr(Cov·M̃), M̃ the Gram matrix
/// of the de-meaned basis over the travel (400 points). Directions with s below 1e-10 of the
/// largest are left out (a wave the offsets absorb: its de-meaned profile is nil).
fn roll_crb(roll: &Waves, passes: &[ModePass], straight_y: &Waves, travel: (f64, f64), sigma: f64) -> f64 {
    let total: usize = passes.iter().map(|p| p.4).sum();
    let (xs, ortho) = roll_nuisance(passes, straight_y);
    let basis = |k: f64, sin: bool, x: f64| if sin { (k * x).sin() } else { (k * x).cos() };
    let theta = wave_list(roll);
    let d: Vec<Vec<f64>> = theta
        .iter()
        .map(|&(k, sin)| {
            let mut c: Vec<f64> = xs.iter().map(|&x| G * basis(k, sin, x)).collect();
            project_out(&mut c, &ortho);
            c
        })
        .collect();
    let m = theta.len();
    let jm = faer::Mat::<f64>::from_fn(total, m, |i, j| d[j][i] / sigma);
    let svd = jm.thin_svd().expect("roll_crb: SVD of the projected roll columns");
    let (vv, sv) = (svd.V(), svd.S().column_vector());
    let s_max = (0..m).map(|j| sv[j]).fold(0.0, f64::max);
    // De-meaned basis over the travel.
    let grid: Vec<f64> = (0..400).map(|g| travel.0 + (travel.1 - travel.0) * (g as f64 + 0.5) / 400.0).collect();
    let phi: Vec<Vec<f64>> = theta
        .iter()
        .map(|&(k, sin)| {
            let col: Vec<f64> = grid.iter().map(|&x| basis(k, sin, x)).collect();
            let mean = col.iter().sum::<f64>() / col.len() as f64;
            col.iter().map(|v| v - mean).collect()
        })
        .collect();
    // tr(V S⁻² Vᵀ M̃) = Σ_m s_m⁻²·mean_g (Σ_j V_jm φ̃_j(x_g))².
    let mut mse = 0.0;
    for mm in 0..m {
        if sv[mm] <= 1e-10 * s_max {
            continue;
        }
        let prof: f64 =
            (0..grid.len()).map(|g| (0..m).map(|j| vv[(j, mm)] * phi[j][g]).sum::<f64>().powi(2)).sum::<f64>()
                / grid.len() as f64;
        mse += prof / (sv[mm] * sv[mm]);
    }
    mse.sqrt()
}

/// One accelerometer draw, written to `dir` (manifest.toml, pass_k.csv, model.toml). Hidden effects
/// are drawn large enough to be seen: the χ² of their contribution (mean removed per channel) is at
/// least `min_chi2`, redrawn otherwise (an effect below the noise cannot be diagnosed by anyone).
/// The interval-mean mode acceleration q̈̄ at each sample of one pass (the generator's own
/// integration: 40 exact sub-steps per sample, the base acceleration `a(τ)` from 1 s before the
/// first sample), for a mode of frequency `f` (Hz) and damping `z`.
fn mode_series(f: f64, z: f64, dt: f64, n: usize, a: &dyn Fn(f64) -> f64) -> Vec<f64> {
    let sub = 40usize;
    let h = dt / sub as f64;
    let o = Oscillator::new(f, z, h);
    let lead = (1.0 / dt).ceil() as usize;
    let mut q = [0.0, 0.0];
    let mut qd_prev = 0.0;
    let mut out = Vec::with_capacity(n);
    for i in 0..(lead + n) as i64 {
        let ti = (i - lead as i64) as f64 * dt;
        for s in 0..sub {
            q = o.step(q, a(ti - dt + (s as f64 + 0.5) * h));
        }
        let qdd_mean = (q[1] - qd_prev) / dt;
        qd_prev = q[1];
        if i >= lead as i64 {
            out.push(qdd_mean);
        }
    }
    out
}

/// Σ aᵢ·bᵢ.
fn dot(a: &[f64], b: &[f64]) -> f64 {
    a.iter().zip(b).map(|(x, y)| x * y).sum()
}

/// `v` minus its projections on the orthonormal columns `ortho`, twice (classical Gram–Schmidt
/// repeated: the nearly dependent long waves of a profile would otherwise leave rounding behind).
fn project_out(v: &mut [f64], ortho: &[Vec<f64>]) {
    for _ in 0..2 {
        for q in ortho {
            let c = dot(v, q);
            v.iter_mut().zip(q).for_each(|(x, y)| *x -= c * y);
        }
    }
}

/// An orthonormal basis of the span of `cols` (Gram–Schmidt in order, [`project_out`]); a column
/// left with less than 1e-9 of its norm is dependent on the earlier ones and dropped. Projecting a
/// parameter's column off this basis profiles the nuisance out of its Fisher information.
fn orthonormal(cols: Vec<Vec<f64>>) -> Vec<Vec<f64>> {
    let mut ortho: Vec<Vec<f64>> = Vec::new();
    for mut v in cols {
        let before = dot(&v, &v).sqrt();
        project_out(&mut v, &ortho);
        let norm = dot(&v, &v).sqrt();
        if norm > 1e-9 * before {
            v.iter_mut().for_each(|x| *x /= norm);
            ortho.push(v);
        }
    }
    ortho
}

/// One pass for [`mode_crb`]: speed v (m/s), direction (±1), position of the first sample x₀ (m),
/// sample interval Δt (s) and number of samples.
type ModePass = (f64, f64, f64, f64, usize);

/// Cramér–Rao bound of (f, ζ) ([`AccelTruth::mode_crb`]) for passes `(v, dir, x₀, Δt, n)` seen by
/// two channels (y, z) with mode-shape components `shape`, straightness profiles `straight` (y, z)
/// and noise σ `sigma`.
///
/// The mean reading of channel c at sample i is μ_c,i = geo(E_c)_i + shape_c·q̈̄_i + b_c,p, with the
/// mode driven by a(τ) = Σ_c shape_c·v²·E_c''(x(τ)). Unknown besides (f, ζ), and profiled out: each
/// pass's offset per channel, the mode's gain per channel, and the straightness itself in its true
/// family — every wave of `straight` with its amplitude and phase free (a cos and a sin coefficient
/// per wave number), each such column holding its geometric acceleration on its own channel and the
/// mode's response to it on both. The straightness is profiled out because no estimator knows it: the
/// mode's excitation is the same guideway curvature a model fits beside the mode, so a fitted shape
/// can take up part of the mode's decay. (A model's own shapes are a more flexible family than these
/// waves, so its bound is larger still: this is a lower bound for any estimator.)
fn mode_crb(f: f64, z: f64, passes: &[ModePass], straight: &[Waves], shape: [f64; 2], sigma: f64) -> (f64, f64) {
    let (df, dz) = (f * 1e-4, z * 1e-3);
    let total: usize = passes.iter().map(|p| 2 * p.4).sum();
    // Row of (pass p, channel c, sample i): pass by pass, y then z.
    let mut first = Vec::new();
    let mut acc = 0;
    for p in passes {
        first.push(acc);
        acc += 2 * p.4;
    }
    let row = |p: usize, c: usize, i: usize| first[p] + c * passes[p].4 + i;
    // The straightness nuisance: (channel, wave number, cos or sin) of every wave.
    let mut waves: Vec<(usize, f64, bool)> = Vec::new();
    for (c, w) in straight.iter().enumerate() {
        for &k in &w.k {
            waves.push((c, k, false));
            waves.push((c, k, true));
        }
    }
    let e1 = |k: f64, sin: bool, x: f64| if sin { k * (k * x).cos() } else { -k * (k * x).sin() };
    let e2 = |k: f64, sin: bool, x: f64| if sin { -k * k * (k * x).sin() } else { -k * k * (k * x).cos() };
    let mut d = [vec![0.0; total], vec![0.0; total]];
    let mut nuisance: Vec<Vec<f64>> = Vec::new();
    // Offsets per (pass, channel).
    for (p, ps) in passes.iter().enumerate() {
        for c in 0..2 {
            let mut col = vec![0.0; total];
            (0..ps.4).for_each(|i| col[row(p, c, i)] = 1.0);
            nuisance.push(col);
        }
    }
    let mut gains = [vec![0.0; total], vec![0.0; total]];
    let mut wave_cols = vec![vec![0.0; total]; waves.len()];
    for (p, &(v, dirn, x0, dt, n)) in passes.iter().enumerate() {
        let x_at = |tm: f64| x0 + dirn * v * tm;
        let base = |tm: f64| {
            let x = x_at(tm);
            v * v * (0..2).map(|c| shape[c] * straight[c].d2(x)).sum::<f64>()
        };
        let m0 = mode_series(f, z, dt, n, &base);
        let fp = mode_series(f + df, z, dt, n, &base);
        let fm = mode_series(f - df, z, dt, n, &base);
        let zp = mode_series(f, z + dz, dt, n, &base);
        let zm = mode_series(f, z - dz, dt, n, &base);
        for (c, g) in shape.iter().enumerate() {
            for i in 0..n {
                d[0][row(p, c, i)] = g * (fp[i] - fm[i]) / (2.0 * df);
                d[1][row(p, c, i)] = g * (zp[i] - zm[i]) / (2.0 * dz);
                gains[c][row(p, c, i)] = m0[i];
            }
        }
        for (col, &(c, k, sin)) in wave_cols.iter_mut().zip(&waves) {
            let resp = mode_series(f, z, dt, n, &|tm: f64| shape[c] * v * v * e2(k, sin, x_at(tm)));
            for i in 0..n {
                let (x, xp) = (x_at(i as f64 * dt), x_at((i as f64 - 1.0) * dt));
                col[row(p, c, i)] += dirn * v * (e1(k, sin, x) - e1(k, sin, xp)) / dt;
                for (cc, g) in shape.iter().enumerate() {
                    col[row(p, cc, i)] += g * resp[i];
                }
            }
        }
    }
    nuisance.extend(gains);
    nuisance.extend(wave_cols);
    // Profile out the nuisance, then the 2 × 2 information of what the derivatives have left (the
    // Schur complement).
    let ortho = orthonormal(nuisance);
    for v in d.iter_mut() {
        project_out(v, &ortho);
    }
    let s2 = sigma * sigma;
    let (a, b, c) = (dot(&d[0], &d[0]) / s2, dot(&d[0], &d[1]) / s2, dot(&d[1], &d[1]) / s2);
    let det = a * c - b * b;
    if det > 0.0 {
        ((c / det).sqrt(), (a / det).sqrt())
    } else {
        (f64::INFINITY, f64::INFINITY)
    }
}

pub fn accel_set(dir: &Path, seed: u64, hidden: AccelHidden, min_chi2: f64) -> AccelTruth {
    accel_set_sized(dir, seed, hidden, min_chi2, None)
}

/// [`accel_set`] with about `samples` samples in all (both channels, three passes) when given: the
/// sample rate is set to give that count instead of its draw of 250–600 Hz (the benchmark's sizes).
pub fn accel_set_sized(
    dir: &Path,
    seed: u64,
    hidden: AccelHidden,
    min_chi2: f64,
    samples: Option<usize>,
) -> AccelTruth {
    accel_set_clocked(dir, seed, hidden, min_chi2, samples, Clock::Even)
}

/// [`accel_set_sized`] with its samples stamped by `clock` (the same draw otherwise: the clock's
/// jitter comes from its own stream).
pub fn accel_set_clocked(
    dir: &Path,
    seed: u64,
    hidden: AccelHidden,
    min_chi2: f64,
    samples: Option<usize>,
    clock: Clock,
) -> AccelTruth {
    let mut attempt = 0u64;
    loop {
        let t = accel_try(dir, seed.wrapping_mul(1_000_003).wrapping_add(attempt), hidden, samples, clock);
        // Each hidden effect visible (χ² ≥ min_chi2) and worth adding by diagnose's own floor: it
        // must explain ≥ 1 % of the residual (`explained_floor`), whose χ² is about the sample
        // count, so the generator asks 2 % of the samples (a margin for what the offsets, the
        // flexible shapes and a candidate's own family do not take up).
        let floor = min_chi2.max(0.02 * t.samples as f64);
        // A mode whose frequency its own samples do not fix to 10 % at 3σ (`mode_crb`, the
        // straightness profiled out) is one the shapes take up: a 73.9 Hz mode driven far below
        // its frequency (σ_f 10.7 Hz) left a complete model at the noise. Not a hidden mode.
        let identifiable = t.mode.zip(t.mode_crb).is_none_or(|((f, _), (sf, _))| 3.0 * sf <= 0.1 * f);
        if hidden == AccelHidden::None || (t.hidden_chi2 >= floor && identifiable) || attempt > 200 {
            return t;
        }
        attempt += 1;
    }
}

fn accel_try(dir: &Path, seed: u64, hidden: AccelHidden, samples: Option<usize>, clock: Clock) -> AccelTruth {
    let mut d = Draw::new(seed);
    let mut jitter = Draw::new(seed ^ 0x6c6f_6767_6572);
    let travel = d.uniform(0.25, 0.6);
    let x_lo = d.uniform(-0.1, 0.3);
    // Straightness: two or three smooth components of different correlation lengths + waviness.
    let mut straight = Vec::new();
    for _ in 0..2 {
        let mut w = Waves::default();
        let ncomp = if d.chance(0.5) { 2 } else { 3 };
        for _ in 0..ncomp {
            let ell = d.log_uniform(0.04, 0.4);
            let rms = d.log_uniform(0.3e-6, 4e-6) * (ell / 0.2).sqrt();
            w = w.plus(&Waves::smooth(&mut d, rms, ell, 8));
        }
        let wav_rms = d.log_uniform(0.01e-6, 0.08e-6);
        let wav = Waves::waviness(&mut d, wav_rms, 0.004, 0.04, 4);
        straight.push(w.plus(&wav));
    }
    let roll = matches!(hidden, AccelHidden::Roll | AccelHidden::ResonanceAndRoll).then(|| {
        let ell = d.log_uniform(0.15, 0.6);
        let rms = d.log_uniform(2e-6, 20e-6);
        Waves::smooth(&mut d, rms, ell, 8)
    });
    let mode = matches!(hidden, AccelHidden::Resonance | AccelHidden::ResonanceAndRoll)
        .then(|| (d.uniform(20.0, 80.0), d.log_uniform(0.005, 0.05)));
    let theta = d.uniform(0.0, std::f64::consts::TAU);
    let m_shape = [0.0, theta.cos(), theta.sin()];
    // Noise density from a seismic piezo part (0.1 µg/√Hz) to a MEMS part (25 µg/√Hz).
    let density = d.log_uniform(0.1e-6, 25e-6) * G;
    let v_max = d.uniform(0.25, 0.5);
    let speeds = [v_max * d.uniform(0.3, 0.45), v_max * d.uniform(0.55, 0.75), v_max];
    // One rate for the three passes (so one σ per sensor holds), 250–600 Hz: above 2× the highest
    // mode frequency, few enough samples for the low pass.
    let rate = d.uniform(250.0, 600.0);
    // Σ 2·travel/v seconds of samples over the passes (two channels each).
    let seconds: f64 = speeds.iter().map(|v| 2.0 * travel / v).sum();
    let rate = samples.map_or(rate, |n| n as f64 / seconds);
    let sigma = density * (rate / 2.0).sqrt();
    let sensors: Vec<SensorSpec> = [("acc_y", [0.0, 1.0, 0.0]), ("acc_z", [0.0, 0.0, 1.0])]
        .iter()
        .map(|(n, u)| SensorSpec {
            name: n.to_string(),
            kind: "accelerometer",
            position: [d.uniform(-0.1, 0.1), d.uniform(-0.1, 0.1), d.uniform(0.02, 0.1)],
            direction: *u,
            sigma: 0.0,
            extra: String::new(),
        })
        .collect();
    let bias: Vec<f64> = (0..2).map(|_| d.normal() * 0.02).collect();
    let mut runs = Vec::new();
    let mut sigmas = Vec::new();
    let mut rates = Vec::new();
    let mut samples = 0;
    let (mut chi2_roll, mut chi2_mode) = (0.0, 0.0);
    let mut t0 = 0.0;
    let mut layout: Vec<ModePass> = Vec::new();
    for (k, &v) in speeds.iter().enumerate() {
        let dt = 1.0 / rate;
        let dirn = if d.chance(0.5) { 1.0 } else { -1.0 };
        let n = (travel / v * rate).floor() as usize;
        let x0 = if dirn > 0.0 { x_lo } else { x_lo + travel };
        layout.push((v, dirn, x0, dt, n));
        // Mode state integrated from well before the first sample (a settled cruise: the transient
        // from the start of motion has decayed, 1 s lead-in).
        let sub = 40usize;
        let h = dt / sub as f64;
        let osc = mode.map(|(f, z)| Oscillator::new(f, z, h));
        let lead = (1.0 / dt).ceil() as usize;
        let mut q = [0.0, 0.0];
        let x_at = |tt: f64| x0 + dirn * v * tt;
        let base = |x: f64| [0.0, v * v * straight[0].d2(x), v * v * straight[1].d2(x)];
        let mut tcol = Vec::with_capacity(n);
        let mut xcol = Vec::with_capacity(n);
        let mut ay = Vec::with_capacity(n);
        let mut az = Vec::with_capacity(n);
        let mut hy = Vec::with_capacity(n);
        let mut hz = Vec::with_capacity(n);
        let mut qd_prev = 0.0;
        // The stamped instant of the sample before (a logger's clock; the lead-in is even).
        let mut t_prev = -dt;
        for i in 0..(lead + n) as i64 {
            let even = (i - lead as i64) as f64 * dt;
            // This interval (t_{i−1}, t_i]: its ends and length.
            let (ti, tp, dt) = match clock {
                Clock::Logger { jitter: sj, resolution, .. } if i >= lead as i64 => {
                    let at = ((even + sj * jitter.normal()) / resolution).round() * resolution;
                    // A stamp that does not advance (jitter beyond half an interval) is not kept.
                    let at = at.max(t_prev + resolution);
                    (at, t_prev, at - t_prev)
                }
                Clock::Even | Clock::Logger { .. } => (even, even - dt, dt),
            };
            t_prev = ti;
            let own = match clock {
                Clock::Logger { .. } => mode.map(|(f, z)| Oscillator::new(f, z, dt / sub as f64)),
                Clock::Even => None,
            };
            let h = dt / sub as f64;
            // Integrate the mode over (t_{i−1}, t_i].
            if let Some(o) = own.as_ref().or(osc.as_ref()) {
                for s in 0..sub {
                    let tm = tp + (s as f64 + 0.5) * h;
                    let b = base(x_at(tm));
                    let a = m_shape[1] * b[1] + m_shape[2] * b[2];
                    q = o.step(q, a);
                }
            }
            let qdd_mean = (q[1] - qd_prev) / dt;
            qd_prev = q[1];
            if i < lead as i64 {
                continue;
            }
            // A lost sample (drawn from the clock's own stream, and only when samples are lost:
            // the draws of a clock that loses none are unchanged).
            if let Clock::Logger { lost, .. } = clock {
                if lost > 0.0 && jitter.uniform(0.0, 1.0) < lost {
                    continue;
                }
            }
            let x = x_at(ti);
            let xp = x_at(tp);
            tcol.push(t0 + ti);
            xcol.push(x);
            // Interval mean of the guideway acceleration: (v·E'(x_i) − v·E'(x_{i−1}))/Δt, signed
            // by the direction of travel (d/dt E(x(t)) = ẋ·E'(x)).
            let geo = |w: &Waves| dirn * v * (w.d1(x) - w.d1(xp)) / dt;
            let gy = roll.as_ref().map_or(0.0, |r| G * r.value(x));
            let my = m_shape[1] * qdd_mean;
            let mz = m_shape[2] * qdd_mean;
            hy.push(gy + my);
            hz.push(mz);
            ay.push(geo(&straight[0]) + gy + my + bias[0] + sigma * d.normal());
            az.push(geo(&straight[1]) + mz + bias[1] + sigma * d.normal());
        }
        // Each hidden effect's own χ² (its signal, less the pass's mean, over the noise): the roll's
        // on y, the mode's on y and z.
        let demeaned_chi2 = |col: &[f64]| {
            let mean = col.iter().sum::<f64>() / col.len() as f64;
            col.iter().map(|v| ((v - mean) / sigma).powi(2)).sum::<f64>()
        };
        let roll_y: Vec<f64> = xcol.iter().map(|&x| roll.as_ref().map_or(0.0, |r| G * r.value(x))).collect();
        let mode_y: Vec<f64> = hy.iter().zip(&roll_y).map(|(h, r)| h - r).collect();
        chi2_roll += demeaned_chi2(&roll_y);
        chi2_mode += demeaned_chi2(&mode_y);
        chi2_mode += demeaned_chi2(&hz);
        samples += 2 * tcol.len();
        let dur = n as f64 * dt;
        runs.push(RunSpec {
            name: format!("pass_{}", k + 1),
            procedure: "constant_velocity",
            feed: Some(v),
            direction: Some(dirn as i8),
            start_time: 0.0,
            columns: vec![
                ("t".into(), tcol.iter().map(|v| v - t0).collect()),
                ("x_cmd[mm]".into(), xcol.iter().map(|v| v * 1e3).collect()),
                ("acc_y".into(), ay),
                ("acc_z".into(), az),
            ],
        });
        runs.last_mut().unwrap().start_time = t0;
        t0 += dur + 5.0;
        sigmas.push(sigma);
        rates.push(rate);
    }
    let mode_crb = mode.map(|(f, z)| mode_crb(f, z, &layout, &straight, [m_shape[1], m_shape[2]], sigma));
    let roll_crb = match (&roll, mode) {
        (Some(r), None) => Some(roll_crb(r, &layout, &straight[0], (x_lo, x_lo + travel), sigma)),
        _ => None,
    };
    let sensors: Vec<SensorSpec> = sensors.into_iter().map(|s| SensorSpec { sigma, ..s }).collect();
    let has_roll = roll.is_some();
    let roll_chi2_profiled = roll.as_ref().map(|r| roll_profiled_chi2(r, &layout, &straight[0], sigma));
    let _ = std::fs::remove_dir_all(dir);
    write_set(dir, "independent accelerometer passes (issue 19 generator)", &sensors, &runs);
    write_model(&dir.join("model.toml"), &["straightness_y", "straightness_z"]);
    AccelTruth {
        hidden,
        mode,
        mode_shape: [m_shape[1], m_shape[2]],
        roll,
        density,
        sigmas,
        speeds: speeds.to_vec(),
        rates,
        samples,
        hidden_chi2: match (has_roll, mode.is_some()) {
            (true, true) => chi2_roll.min(chi2_mode),
            (true, false) => chi2_roll,
            (false, true) => chi2_mode,
            (false, false) => 0.0,
        },
        mode_crb,
        travel: (x_lo, x_lo + travel),
        roll_crb,
        roll_chi2_profiled,
    }
}

// ------------------------------------------------------------------------------------------
// Encoder logs.

/// What an encoder draw hides from its starting model.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum EncoderHidden {
    /// The model holds everything present (positioning + servo_lag fitted).
    None,
    InterpolationError,
    CyclicLead,
    Backlash,
    /// The model is `positioning` alone; the following error is missing.
    ServoLag,
    /// Cyclic lead and backlash together.
    CyclicLeadAndBacklash,
}

/// How an encoder draw's controller trace writes its rows.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Trace {
    /// Each row at its servo tick, the time as computed.
    Exact,
    /// The readings still at their servo ticks, the times written to a decimal resolution q (the
    /// coarsest of 1 ms, 0.1 ms, 10 µs and 1 µs at most a quarter of the draw's shortest log
    /// interval: a CSV export that prints its seconds to 3–6 decimals), and each row after the
    /// first lost with probability `lost` (drawn from the trace's own stream, and only when rows
    /// are lost: the rest of the draw is the exact trace's).
    Rounded { lost: f64 },
    /// The readings still at their servo ticks, each time stamped by a host clock with Gaussian
    /// jitter (σ drawn log-uniform from 0.3 µs to the smaller of 30 µs and 1/40 of the draw's
    /// shortest log interval, from the trace's own stream), written as computed (a PC that stamps
    /// the controller's rows as they arrive); rows lost as in [`Trace::Rounded`].
    Jittered { lost: f64 },
    /// Each row at its servo tick, the time as computed, the command written in mm to `decimals`
    /// decimals (3: 1 µm, 4: 0.1 µm; as a controller's export prints it). The loop follows the
    /// exact command: only the written column is rounded.
    CoarseCommand { decimals: usize },
}

/// Feedback of the position loop.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Loop {
    SemiClosed,
    Closed,
}

/// The truth of an encoder draw.
#[derive(Clone, Debug)]
pub struct EncoderTruth {
    pub hidden: EncoderHidden,
    pub feedback: Loop,
    pub kv: f64,
    pub lead: f64,
    /// Cyclic lead amplitude, m (0 when absent).
    pub cyclic_amplitude: f64,
    /// Interpolation period, m, and amplitude, m (0 when absent).
    pub interp_period: f64,
    pub interp_amplitude: f64,
    pub backlash: f64,
    pub sigma_scale: f64,
    pub sigma_motor: f64,
    /// The controller's servo rate, Hz (its loop runs and its log samples on these ticks).
    pub servo_rate: f64,
    pub samples: usize,
    /// The times' resolution, s ([`Trace::Rounded`]; None for an exact or jittered trace).
    pub stamp_resolution: Option<f64>,
    /// The σ of the stamps' jitter, s ([`Trace::Jittered`]; 0 otherwise).
    pub stamp_jitter: f64,
}

/// One encoder draw, written to `dir` (manifest.toml, runs, model.toml).
pub fn encoder_set(dir: &Path, seed: u64, hidden: EncoderHidden) -> EncoderTruth {
    encoder_set_sized(dir, seed, hidden, None)
}

/// [`encoder_set`] with each of the two passes logged at about `samples`/5 rows when given (the two
/// passes' two channels then hold ≈ 80 % of the samples; the crawls and the reversal keep their
/// drawn log rate), instead of its draw of 1500–3000 rows (the benchmark's sizes). A pass cannot
/// log more rows than its cruise has servo ticks.
pub fn encoder_set_sized(dir: &Path, seed: u64, hidden: EncoderHidden, samples: Option<usize>) -> EncoderTruth {
    encoder_set_traced(dir, seed, hidden, samples, Trace::Exact)
}

/// [`encoder_set_sized`] with its rows written by `trace` (the same draw otherwise).
pub fn encoder_set_traced(
    dir: &Path,
    seed: u64,
    hidden: EncoderHidden,
    samples: Option<usize>,
    trace: Trace,
) -> EncoderTruth {
    let mut d = Draw::new(seed ^ 0x9e37_79b9_7f4a_7c15);
    let mut lose = Draw::new(seed ^ 0x7472_6163_6521);
    let feedback = if d.chance(0.5) { Loop::SemiClosed } else { Loop::Closed };
    let kv = d.uniform(15.0, 60.0);
    let lead = d.log_uniform(4e-3, 25e-3);
    let travel = d.uniform(0.2, 0.6);
    let x_lo = d.uniform(-0.05, 0.2);
    let ell = d.log_uniform(0.08, 0.5);
    let pos_rms = d.log_uniform(1e-6, 8e-6);
    let pos_err = Waves::smooth(&mut d, pos_rms, ell, 10);
    let slope = d.uniform(-20e-6, 20e-6);
    let has_cyclic = matches!(hidden, EncoderHidden::CyclicLead | EncoderHidden::CyclicLeadAndBacklash);
    let cyc_a = if has_cyclic { d.log_uniform(0.3e-6, 3e-6) } else { 0.0 };
    let cyc_phi = d.uniform(0.0, std::f64::consts::TAU);
    let has_interp = hidden == EncoderHidden::InterpolationError;
    let ip = d.log_uniform(8e-6, 60e-6);
    let ia = if has_interp { d.log_uniform(30e-9, 300e-9) } else { 0.0 };
    let iphi = d.uniform(0.0, std::f64::consts::TAU);
    let has_backlash = matches!(hidden, EncoderHidden::Backlash | EncoderHidden::CyclicLeadAndBacklash);
    let b = if has_backlash { d.log_uniform(2e-6, 20e-6) } else { 0.0 };
    let servo_rate: f64 = [1000.0, 2000.0, 4000.0][(d.uniform(0.0, 2.999)) as usize];
    let h = 1.0 / servo_rate;
    let sigma_scale = d.log_uniform(3e-9, 20e-9);
    let sigma_motor = d.log_uniform(3e-9, 20e-9);
    let lead_err =
        |xm: f64| pos_err.value(xm) + slope * xm + cyc_a * (std::f64::consts::TAU * xm / lead + cyc_phi).sin();
    let interp = |xt: f64| ia * (std::f64::consts::TAU * xt / ip + iphi).sin();
    // Command profiles: (time, position, velocity) per servo tick, with the logged window.
    struct Plan {
        name: String,
        procedure: &'static str,
        feed: Option<f64>,
        direction: Option<i8>,
        cmd: Vec<(f64, f64)>,
        log_from: usize,
        log_to: usize,
        every: usize,
    }
    let mut plans: Vec<Plan> = Vec::new();
    let v_pass = d.uniform(0.02, 0.12);
    let acc = d.uniform(0.5, 2.0);
    let log_rate: f64 = [250.0_f64, 500.0, 1000.0][(d.uniform(0.0, 2.999)) as usize].min(servo_rate);
    let every = (servo_rate / log_rate).round() as usize;
    // A trapezoidal move from a to b at speed v (acceleration acc), 0.3 s still before and after.
    let trapezoid = |a: f64, b: f64, v: f64| -> (Vec<(f64, f64)>, usize, usize) {
        let dist = (b - a).abs();
        let s = (b - a).signum();
        let ta = v / acc;
        let tc = (dist - v * ta) / v;
        let total = 0.3 + 2.0 * ta + tc + 0.3;
        let n = (total / h).ceil() as usize;
        let mut c = Vec::with_capacity(n);
        for i in 0..n {
            let t = i as f64 * h - 0.3;
            let (p, vel) = if t < 0.0 {
                (0.0, 0.0)
            } else if t < ta {
                (0.5 * acc * t * t, acc * t)
            } else if t < ta + tc {
                (0.5 * v * ta + v * (t - ta), v)
            } else if t < 2.0 * ta + tc {
                let u = 2.0 * ta + tc - t;
                (dist - 0.5 * acc * u * u, acc * u)
            } else {
                (dist, 0.0)
            };
            c.push((a + s * p, s * vel));
        }
        // Cruise logged after five loop time constants of settling.
        let from = ((0.3 + ta + 5.0 / kv) / h).ceil() as usize;
        let to = ((0.3 + ta + tc) / h).floor() as usize;
        (c, from, to.max(from + 1))
    };
    let pass_samples = d.uniform(1500.0, 3000.0);
    let pass_samples = samples.map_or(pass_samples, |n| n as f64 / 5.0);
    let first_dir = d.sign();
    for (k, dirn) in [first_dir, -first_dir].into_iter().enumerate() {
        let (a, bb) = if dirn > 0.0 { (x_lo, x_lo + travel) } else { (x_lo + travel, x_lo) };
        let (cmd, from, to) = trapezoid(a, bb, v_pass);
        plans.push(Plan {
            name: format!("pass_{}", k + 1),
            procedure: "constant_velocity",
            feed: Some(v_pass),
            direction: Some(dirn as i8),
            cmd,
            log_from: from,
            log_to: to,
            // A controller trace of 1500–3000 samples per pass (a divisor of the servo rate).
            every: ((to - from) as f64 / pass_samples).round().max(1.0) as usize,
        });
    }
    // Crawls: 5–80 mm/min over 1–2 s, approached in the direction of travel.
    for k in 0..2 {
        let v = d.log_uniform(5.0, 80.0) / 60e3;
        let dirn = d.sign();
        let dur = d.uniform(1.0, 2.0);
        let start = x_lo + d.uniform(0.2, 0.8) * travel;
        let mut cmd = Vec::new();
        let lead_in = 0.5 + 5.0 / kv;
        let n = ((lead_in + dur) / h).ceil() as usize;
        for i in 0..n {
            let t = i as f64 * h;
            cmd.push((start + dirn * v * t, dirn * v));
        }
        plans.push(Plan {
            name: format!("crawl_{}", k + 1),
            procedure: "crawl",
            feed: Some(v),
            direction: Some(dirn as i8),
            cmd,
            log_from: (lead_in / h).ceil() as usize,
            log_to: n,
            every,
        });
    }
    // A slow reversal: x = c + D·sin(πt/T), D 0.5–3 mm, T 1–4 s, after a lead-in at its start speed.
    {
        let dd = d.uniform(0.5e-3, 3e-3);
        let tt = d.uniform(1.0, 4.0);
        let c0 = x_lo + 0.5 * travel;
        let v0 = dd * std::f64::consts::PI / tt;
        let lead_in = 0.5 + 5.0 / kv;
        let n = ((lead_in + tt) / h).ceil() as usize;
        let mut cmd = Vec::new();
        for i in 0..n {
            let t = i as f64 * h - lead_in;
            if t < 0.0 {
                cmd.push((c0 + v0 * t, v0));
            } else {
                let w = std::f64::consts::PI / tt;
                cmd.push((c0 + dd * (w * t).sin(), dd * w * (w * t).cos()));
            }
        }
        plans.push(Plan {
            name: "reversal".into(),
            procedure: "free",
            feed: None,
            direction: None,
            log_from: (lead_in / h).ceil() as usize,
            log_to: n,
            cmd,
            every,
        });
    }
    // Simulate each plan from a settled state (motor at the command, the table pushed from the
    // side of the first motion).
    let mut runs = Vec::new();
    let mut samples = 0;
    let mut t0 = 0.0;
    let loop_key = match feedback {
        Loop::SemiClosed => "motor",
        Loop::Closed => "scale",
    };
    let shortest = plans.iter().map(|p| p.every as f64 * h).fold(f64::INFINITY, f64::min);
    let stamp_resolution = match trace {
        Trace::Exact | Trace::Jittered { .. } | Trace::CoarseCommand { .. } => None,
        Trace::Rounded { .. } => [1e-3, 1e-4, 1e-5, 1e-6].into_iter().find(|q| *q <= shortest / 4.0),
    };
    let stamp_jitter = match trace {
        Trace::Exact | Trace::Rounded { .. } | Trace::CoarseCommand { .. } => 0.0,
        Trace::Jittered { .. } => lose.log_uniform(0.3e-6, (30e-6f64).min(shortest / 40.0)),
    };
    let stamp = |lose: &mut Draw, t: f64| {
        let t = if stamp_jitter > 0.0 { t + stamp_jitter * lose.normal() } else { t };
        stamp_resolution.map_or(t, |q| (t / q).round() * q)
    };
    // The command column as the trace writes it, mm.
    let written_command = |mm: f64| match trace {
        Trace::CoarseCommand { decimals } => format!("{mm:.decimals$}").parse::<f64>().unwrap(),
        Trace::Exact | Trace::Rounded { .. } | Trace::Jittered { .. } => mm,
    };
    for p in &plans {
        let (x_start, v_start) = p.cmd[0];
        let first_v = p.cmd.iter().map(|c| c.1).find(|v| *v != 0.0).unwrap_or(1.0);
        let mut xm = x_start - v_start / kv;
        let mut xt = xm + lead_err(xm) - first_v.signum() * b / 2.0;
        let (mut tc, mut xc, mut sc, mut mc) = (Vec::new(), Vec::new(), Vec::new(), Vec::new());
        for (i, &(xcmd, vcmd)) in p.cmd.iter().enumerate() {
            // Readings at the tick (before the loop's output acts over the next period).
            let scale = xt + interp(xt);
            if i >= p.log_from && i < p.log_to && (i - p.log_from) % p.every == 0 {
                let (s_read, m_read) = (scale + sigma_scale * d.normal(), xm + sigma_motor * d.normal());
                let lost = match trace {
                    Trace::Rounded { lost } | Trace::Jittered { lost } => {
                        lost > 0.0 && !tc.is_empty() && lose.chance(lost)
                    }
                    Trace::Exact | Trace::CoarseCommand { .. } => false,
                };
                if !lost {
                    tc.push(i as f64 * h);
                    xc.push(xcmd);
                    sc.push(s_read);
                    mc.push(m_read);
                }
            }
            let fb = match feedback {
                Loop::SemiClosed => xm,
                Loop::Closed => scale,
            };
            let vel = kv * (xcmd - fb);
            // The motor moves at `vel` over the tick; the table follows the nut through the play.
            let sub = 8;
            for _ in 0..sub {
                xm += vel * h / sub as f64;
                let nut = xm + lead_err(xm);
                if nut - xt > b / 2.0 {
                    xt = nut - b / 2.0;
                } else if nut - xt < -b / 2.0 {
                    xt = nut + b / 2.0;
                }
            }
            let _ = vcmd;
        }
        let t_first = tc[0];
        samples += 2 * tc.len();
        let dur = tc.last().unwrap() - t_first;
        runs.push(RunSpec {
            name: p.name.clone(),
            procedure: p.procedure,
            feed: p.feed,
            direction: p.direction,
            start_time: t0,
            columns: vec![
                ("t".into(), tc.iter().map(|t| stamp(&mut lose, t - t_first)).collect()),
                ("x_cmd[mm]".into(), xc.iter().map(|v| written_command(v * 1e3)).collect()),
                ("scale[um]".into(), sc.iter().map(|v| v * 1e6).collect()),
                ("motor[um]".into(), mc.iter().map(|v| v * 1e6).collect()),
            ],
        });
        t0 += dur + 2.0;
    }
    let encoder = |name: &str, kind, sigma| SensorSpec {
        name: name.into(),
        kind,
        position: [0.0; 3],
        direction: [1.0, 0.0, 0.0],
        sigma,
        extra: if loop_key == name { "closes_loop = true\n".into() } else { String::new() },
    };
    let sensors =
        vec![encoder("scale", "encoder_linear", sigma_scale), encoder("motor", "encoder_rotary", sigma_motor)];
    let _ = std::fs::remove_dir_all(dir);
    write_set(dir, "independent encoder logs of a ball-screw axis (issue 19 generator)", &sensors, &runs);
    let model: &[&str] = match hidden {
        EncoderHidden::ServoLag => &["positioning"],
        _ => &["positioning", "servo_lag"],
    };
    write_model(&dir.join("model.toml"), model);
    EncoderTruth {
        hidden,
        feedback,
        kv,
        lead,
        cyclic_amplitude: cyc_a,
        interp_period: ip,
        interp_amplitude: ia,
        backlash: b,
        sigma_scale,
        sigma_motor,
        servo_rate,
        samples,
        stamp_resolution,
        stamp_jitter,
    }
}

/// The closed-form step map of the generator's mode against a fine RK4 of the same oscillator
/// under a constant input, over 0.5 s (relative error ≤ 1e-8: RK4 at h/1000 is ~1e-12 accurate).
#[test]
fn oscillator_step_map_matches_rk4() {
    let (f, zeta, h) = (37.3, 0.021, 1.3e-4);
    let o = Oscillator::new(f, zeta, h);
    let w = std::f64::consts::TAU * f;
    let a = 0.7;
    let mut x = [1e-4, -2e-3];
    let mut y = x;
    let n = 1000;
    let hs = h / n as f64;
    for _ in 0..(0.5 / h) as usize {
        x = o.step(x, a);
        for _ in 0..n {
            let dv = |s: [f64; 2]| [s[1], -a - 2.0 * zeta * w * s[1] - w * w * s[0]];
            let k1 = dv(y);
            let k2 = dv([y[0] + 0.5 * hs * k1[0], y[1] + 0.5 * hs * k1[1]]);
            let k3 = dv([y[0] + 0.5 * hs * k2[0], y[1] + 0.5 * hs * k2[1]]);
            let k4 = dv([y[0] + hs * k3[0], y[1] + hs * k3[1]]);
            for j in 0..2 {
                y[j] += hs / 6.0 * (k1[j] + 2.0 * k2[j] + 2.0 * k3[j] + k4[j]);
            }
        }
    }
    for j in 0..2 {
        let scale = if j == 0 { 1e-4 } else { 1e-4 * w };
        assert!((x[j] - y[j]).abs() <= 1e-8 * scale, "component {j}: {} vs {}", x[j], y[j]);
    }
}
