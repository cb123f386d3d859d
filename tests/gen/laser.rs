//! Laser line sets of one X axis from the first-order volumetric model (DESIGN.md §2, ISO 230-1), written
//! from the physics and not from vmt's library (issue 17): a line with measuring point `r` (m, on the
//! carriage) and unit beam direction `u` reads, at axis position `q`,
//!
//! ```text
//! reading = u · (E(q) + ε(q) × r) + zero of the line + N(0, σ²)
//! E = (EXX, EYX, EZX) (m),  ε = (EAX, EBX, ECX) (rad)
//! ```
//!
//! The error motions are random smooth profiles (random Fourier features of a squared-exponential
//! process, Rahimi & Recht 2007), the layouts random: irregular targets, 3–9 lines with points anywhere in
//! a 0.6 × 0.6 × 1.2 m box and beams along X, Y or Z. Users: tests/laser_independent.rs (the library) and
//! tests/laser_cli.rs (the `vmt identify` / `vmt compensate` commands on written sets).

use rand::Rng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, StandardNormal};

/// A smooth random profile: `Σ a_j cos(k_j q + φ_j)` (value in m or rad at position q in m).
#[derive(Clone, Debug)]
pub struct Smooth(pub Vec<(f64, f64, f64)>);

impl Smooth {
    /// 12 features of a squared-exponential process of RMS `rms` and correlation length `ell` (m):
    /// `k ~ N(0, 1/ℓ²)`, amplitudes `rms·√(2/12)·N(0, 1)`, phases uniform.
    // A phase range, not 2π: replacing 6.283 by TAU would move every fixed-seed draw of the tests.
    #[allow(clippy::approx_constant)]
    pub fn random(rng: &mut ChaCha8Rng, rms: f64, ell: f64) -> Smooth {
        let n = 12;
        Smooth(
            (0..n)
                .map(|_| {
                    let z: f64 = StandardNormal.sample(rng);
                    let w: f64 = StandardNormal.sample(rng);
                    (rms * (2.0 / n as f64).sqrt() * w, z / ell, rng.gen::<f64>() * 6.283)
                })
                .collect(),
        )
    }

    /// A sum of [`Smooth::random`] profiles, one per correlation length in `ells` (m), each of RMS
    /// `rms/√(ells.len())`: several length scales in one error motion.
    pub fn several(rng: &mut ChaCha8Rng, rms: f64, ells: &[f64]) -> Smooth {
        let each = rms / (ells.len() as f64).sqrt();
        Smooth(ells.iter().flat_map(|&ell| Smooth::random(rng, each, ell).0).collect())
    }

    /// The profile's value at `q` (m).
    pub fn at(&self, q: f64) -> f64 {
        self.0.iter().map(|(a, k, p)| a * (k * q + p).cos()).sum()
    }
}

/// `a × b`.
pub fn cross(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]]
}

/// A line: measuring point (m, axis frame) and unit beam direction.
pub type Line = ([f64; 3], [f64; 3]);

/// Targets (m, increasing, first at 0), lines and the 1σ noise of one reading (m).
#[derive(Clone, Debug)]
pub struct LineLayout {
    /// Axis positions of the readings, m.
    pub targets: Vec<f64>,
    /// The laser lines.
    pub lines: Vec<Line>,
    /// 1σ noise of one reading, m.
    pub sigma: f64,
}

/// Beams along X, Y and Z.
pub const BEAMS: [[f64; 3]; 3] = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]];

/// A random layout: travel 0.3–1.5 m, 6–15 targets (interior ones jittered ±30 % of the step), 3–9 lines
/// (points in [−0.3, 0.3] × [−0.3, 0.3] × [0, 1.2] m, beams along X, Y or Z), σ log-uniform in
/// 10 nm … 316 nm. Nothing keeps it observable: some layouts are rank-deficient.
pub fn random_layout(rng: &mut ChaCha8Rng) -> LineLayout {
    let travel = rng.gen_range(0.3..1.5);
    let n = rng.gen_range(6..16);
    let step = travel / (n - 1) as f64;
    let targets: Vec<f64> = (0..n)
        .map(|i| {
            let jitter = if i == 0 || i == n - 1 { 0.0 } else { rng.gen_range(-0.3..0.3) * step };
            i as f64 * step + jitter
        })
        .collect();
    let n_lines = rng.gen_range(3..10);
    let lines = (0..n_lines)
        .map(|_| {
            let p = [rng.gen_range(-0.3..0.3), rng.gen_range(-0.3..0.3), rng.gen_range(0.0..1.2)];
            (p, BEAMS[rng.gen_range(0..3)])
        })
        .collect();
    LineLayout { targets, lines, sigma: 10f64.powf(rng.gen_range(-8.0..-6.5)) }
}

/// Six random error motions (EXX, EYX, EZX, EAX, EBX, ECX) of RMS 10 µm, 3 µm, 3 µm, 10 µrad ×3, each with
/// one correlation length of 0.15–0.6 × `travel` (m).
pub fn random_motions(rng: &mut ChaCha8Rng, travel: f64) -> [Smooth; 6] {
    let mut m = |rms: f64| {
        let ell = travel * rng.gen_range(0.15..0.6);
        Smooth::random(rng, rms, ell)
    };
    [m(10e-6), m(3e-6), m(3e-6), m(10e-6), m(10e-6), m(10e-6)]
}

/// The error-free reading (m) of the line `(r, u)` at axis position `q` (m): `u·(E(q) + ε(q) × r)`.
pub fn line_value(motions: &[Smooth; 6], (r, u): &Line, q: f64) -> f64 {
    let e = [motions[0].at(q), motions[1].at(q), motions[2].at(q)];
    let eps = [motions[3].at(q), motions[4].at(q), motions[5].at(q)];
    let c = cross(eps, *r);
    u[0] * (e[0] + c[0]) + u[1] * (e[1] + c[1]) + u[2] * (e[2] + c[2])
}
