//! The model-check loop (DESIGN.md §8): `vmt compare`, `vmt diagnose`, `vmt add`.
//!
//! Phase 1 predicts the deviation columns of positioning point tables (FORMAT.md §1: `target`,
//! `run`, `direction`, optional `t`, then deviations actual − target) from a model (FORMAT.md §2).
//! For a sensor with unit direction u and measuring point r (axis frame, m), at target x, approach
//! direction d = ±1 and time t (run `start_time` + the table's `t`, s), the first-order model is
//!
//! ```text
//! ŷ = o_ch + u·(E(x) + ε(x) × r)                           (error motions, ISO 230-1, axis frame)
//!          + s_drive·[ −d·b/2 + A_l·sin(2πx/p_l + φ_l) ]        (backlash b, cyclic lead)
//!          + s_chain·[ k·x + α·ΔT∞·x·(1 − e^{−t/τ}) + d∞·(1 − e^{−t/τ}) + A_i·sin(2πx/p_i + φ_i) ]
//! ```
//!
//! with E = (EXX, EYX, EZX), ε = (EAX, EBX, ECX) and o_ch an offset per channel (run, sensor) for
//! the zeroing of the instrument. Signs follow the simulator (`vmt_sim::axis_sim`): the table
//! lands at command + EXX + e(x, t) (feedback-chain error e: scale error k, thermal, interpolation);
//! in a semi-closed loop the screw's lead error adds to it and backlash makes the table lag the
//! motor by b/2, so the ISO 230-2 reversal value is B = x̄↑ − x̄↓ = −b. For a laser
//! s_drive = s_chain = u·axis; a linear scale (`encoder_linear`, reading x − EXX − e) sees only the
//! drive terms (s_drive = 1, s_chain = 0, no error motions); a rotary encoder only its offset.
//!
//! Everything is linear in the unknowns except periods and time constants, which are searched on
//! a grid and refined by golden-section search on the weighted residual sum of squares with the
//! linear parameters eliminated (variable projection; Golub & Pereyra 1973). The statistics and
//! the candidate ranking come from `vmt_estimators::modelcheck`.
//!
//! Phase 2 (friction): the `motor_force` column of a `friction_sweep` or `constant_velocity` time
//! series, every sample at the run's steady velocity v = feed·direction, is predicted by
//! F = o + Fc·sgn v + Fv·v + (Fs − Fc)·sgn v·exp(−|v/vs|^δ) (Coulomb, viscous, Stribeck with the
//! catalogue's default shape δ = 2; the simulator's law, `vmt_sim::effects::EffectSet::friction`),
//! with one force offset o per sensor; vs is searched like a period.
//!
//! Phase 3 (accelerometers): the readings of an `accelerometer` (body-frame sensitive direction u,
//! measuring point r) in a `constant_velocity` run with a `feed` (time t, position from `x_cmd`,
//! velocity v = feed·direction) are predicted by
//!
//! ```text
//! a_i = o_ch + v²·u·[Ē''(x_{i−1}, x_i) + ε̄''(x_{i−1}, x_i) × r] + g·τ_s(x_i) + a_mode,i
//! ```
//!
//! - o_ch: an offset per (run, sensor) (bias, gravity through the mounting tilt).
//! - The guideway's own acceleration of the measuring point, d²/dt² u·(E + ε × r) at constant v:
//!   the error motions' second derivatives averaged over the sample interval, Ē''(a, b) =
//!   (E'(b) − E'(a))/(b − a) with x_{i−1} = x_i − v·Δt_i, because the simulator's reading is the
//!   difference of the point velocities at successive samples over Δt (`vmt_sim::sensors`). The
//!   sensitivities are a laser's (u_i for translations, (r × u)_i for angles) times v². Given error
//!   motions use their profiles' slopes (Ē'' as `Profile::mean_second_derivative` computes it:
//!   polynomials, harmonics and random profiles by their analytic slopes, a table by its
//!   piecewise-constant slope, i.e. the slope jumps at its knots); fitted ones (a series Σ c_k·φ_k,
//!   below) give the columns v²·s·(φ'_k(x_i) − φ'_k(x_{i−1}))/(x_i − x_{i−1}), with the same
//!   coefficients c_k as the lasers' columns (one unknown per coefficient shared by lasers and
//!   accelerometers). A motion seen only by accelerometers is P_3, P_4 and pairs cos, sin of
//!   jπ(x − a)/(b − a) (`ShapeBasis::Cosine`: an overcomplete family in which a wave of any
//!   wavelength and phase, as rail waviness is, takes a few neighbouring pairs; Legendre columns of
//!   the accelerations become dependent near order 270 on 3 500 samples), its terms chosen by a
//!   greedy forward selection (`greedy_rss`) and BIC; its constant and slope have no acceleration
//!   and are pinned at 0 (said in `shapes`).
//! - g·τ_s(x): gravity seen through the tilt of sensor s's sensitive axis (`gravity_tilt`; the
//!   simulator's reading (R·u)·(a + g ẑ) gives τ = u_y·EAX(x) − u_x·EBX(x) to first order; fitted
//!   per sensor, shared by its runs, as a Legendre series Σ p_k·P_k(u), k = 1..K_s, over the
//!   positions' range, K_s chosen by BIC over 3..20 (`choose_tilt_orders`; 3 as a `diagnose`
//!   candidate) and written as monomials c_j·x^j too). The error-motion columns leave gravity out: a
//!   given roll or pitch does not predict its g·τ (add `gravity_tilt`).
//! - a_mode: a `resonance`, a structural mode q̈ + 2ζω·q̇ + ω²·q = −u·a_ref(t) driven by the
//!   acceleration of the axis reference point (the simulator's base excitation, `StructuralMode`),
//!   read as φ·q̈ (φ the mode shape at the sensor). Where the model predicts that excitation on a
//!   channel (given translation error motions: a_ref = v²·E''(x(t)), x between samples at v), the
//!   mode is the forced response to it (integrated exactly with the input held at its mean over
//!   0.1 ms steps) from rest at the sample before the first, with a gain φ per sensor, plus the free
//!   vibration from the unknown state at that instant (two columns per channel); f (5–200 Hz, 1 Hz grid,
//!   below 0.4× the slowest sampling rate) and ζ (0.5–10 %) are searched. Where it does not
//!   (no given straightness: the excitation is an unknown random profile), the mode is a narrow-band
//!   random process: sin/cos of 2πf·t with amplitude and phase free per segment of
//!   [`RESONANCE_SEGMENT`] s of each channel; ζ is then not resolved (held at its start, 2 %).
//!   Fitted translations (flexible shapes) do enter the excitation: a first fit without the mode
//!   gives Ê(x), and each fitted translation's v²·Ê''(x(τ)) is an input of its own, with a gain
//!   per (sensor, input) (the mode is driven by every component of the reference point's
//!   acceleration, read along each sensor's direction), plus the free vibration per channel
//!   (`fitted_excitation`; in diagnose for the candidate, in compare and after add for a fitted
//!   `resonance`). The diagnose search over (f, ζ) is then screened (`Candidate::with_screen`).
//!   That sequential fit takes the excitation from shapes that have absorbed part of the mode's
//!   response; `compare` (and `diagnose` for a significant mode) then fit the mode jointly with
//!   the shapes that drive it (`coupled.rs`: each shape column carries its closed-form steady mode
//!   response, (f, ζ, gains) refined by variable projection after a scan of f, the shapes
//!   re-chosen with the mode in the model, then refined and re-chosen in turn until (f, ζ) holds;
//!   a model's stated (f, ζ) is a second start, the mode first held there).
//!
//! Not predicted in phase 3: the carriage's own dynamics on its bearing blocks (it follows the
//! geometry only quasi-statically, with a relative error ≈ (f/f_b)² at frequency f below its
//! bearing mode f_b: a normalised RMS far above 1 when the guideway's band reaches f_b, and when it
//! comes within ≈ f_b/5 diagnose already reports these dynamics as a `resonance` near the band's
//! top, see tests/model_check.rs `guideway_scenario`), the servo's ripple, the excitation by fitted error motions, gravity through given
//! angles, and a guideway that the model does not give (its broadband acceleration stays in the
//! residual, normalised by the manifest's σ or σ estimated from successive differences; a strong
//! line of it can then win the resonance search).
//!
//! Phase 4 (encoder logs, [`encoder`]): in a time series with `x_cmd`, a linear scale and a motor
//! encoder give the channels scale − motor (the transmission: lead error, cyclic lead, backlash as
//! play, the scale's interpolation error, all at the scale's reading) and motor − command (the
//! following error of a first-order loop, `servo_lag`); one encoder alone gives encoder − command.
//!
//! Not predicted: LuGre, squareness (needs two axes), servo lag on point tables (no effect on
//! settled readings).
//! They are listed in the report's `notes`. Error motions fitted with `basis = "poly"` (or none)
//! are Legendre series Σ_{k=1..K} c_k·P_k(u), u = (2x − a − b)/(b − a) over the range [a, b] of
//! the sample positions, without P_0 (the offsets carry it); K is the model's `order`, else the
//! order BIC (σ unknown) prefers among 1..m − 1 for m distinct positions, re-chosen for every fit
//! (compare, diagnose, after add); reported as `shapes` (FORMAT.md §4). `bspline`, `harmonics`
//! and `table` are the other series of [`ShapeBasis`] (one column generator each in
//! [`Shape::basis_at`], orders chosen by [`order_curve`]). The fitted parameters are written back
//! in the basis itself (Legendre `p_k` with `x_lo`, `x_hi`; monomials c_j·x^j too up to degree 20).
//! A shape's order and a cyclic lead are decided jointly ([`LeadCap`], docs/formats.md). On data
//! with accelerometer channels the order is
//! chosen per motion by BIC (σ unknown) on the samples of the channels that see it, over 1..N
//! with N what the passes resolve (P_N's shortest wavelength ≈ π(b − a)/N spans two sample
//! spacings |v|·Δt of the finest pass; at most [`MAX_ACCEL_ORDER`]), from the nested residual
//! sums of squares of one QR (`vmt_estimators::modelcheck::nested_rss`); large designs are solved
//! by QR block by block and the hyper-parameter searches factor the unchanging columns once
//! (variable projection, `OrthoBase`). A motion seen only by accelerometers is not nested by
//! degree: its terms enter greedily, each step the one that explains most of what is left
//! (orthogonal matching pursuit, `greedy_rss`), and BIC says how many (`shapes.terms`): rail
//! waviness puts the signal at a few short wavelengths, where nesting by degree charged every
//! term below it and left the whole motion unfitted (a misfit the mode search then claimed).

use crate::error::{fmt_num, VmtError};
use crate::measurement::{write_file_atomic, MeasurementSet, Procedure, RunData, SensorKind};
use crate::model::{Basis, Model, ModelEffect};
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;
use std::f64::consts::TAU as TWO_PI;
use std::path::{Path, PathBuf};
use vmt_estimators::modelcheck::diagnose::at_grid_end;
use vmt_estimators::modelcheck::{
    autocorrelation, bin_by_edges, bin_by_label, brent_min_each, estimate_noise_sigma, fit_percent, fit_signature,
    frequency_grid, greedy_rss, ljung_box, ls_periodogram, lstsq_qr, nested_rss, rank_candidates,
    refine_projected_point, sparse_frequency_scan, uniform_edges, Candidate, DiagnoseConfig, HyperParameter,
    ModelCheckError, NestedSeries, OrthoBase, RankingEntry, Sigma, SparseColumn, Verdict, DIFFERENCE_STEP,
};
use vmt_sim::axis_sim::GRAVITY;
use vmt_sim::effects::{Effect, EffectName, EffectParams};
use vmt_sim::profile::{Profile, Term};

/// Legendre order of a fitted error motion when neither the model nor BIC sets it (accelerometer
/// data; the diagnose candidates' error motions), FORMAT.md §2 `order`.
pub const DEFAULT_ORDER: u32 = 3;
/// Starting α of a thermal expansion when the model gives none, 1/K (steel).
const ALPHA_STEEL: f64 = 11.5e-6;

mod add;
mod channels;
mod command;
mod coupled;
mod encoder;
mod fit;
mod report;
mod signatures;
mod text;

pub use add::*;
pub use channels::*;
pub(crate) use coupled::*;
pub use encoder::*;
pub(crate) use fit::*;
pub use report::*;
pub use signatures::*;
pub use text::*;

/// True for a positioning procedure (used by callers that build sets).
pub fn is_positioning(p: Procedure) -> bool {
    p == Procedure::Positioning
}

#[cfg(test)]
pub(crate) mod tests {
    /// The advice for two effects the data cannot tell apart names a measurement of the recording's
    /// own kind: another speed or a second accelerometer for accelerometer passes, a reversal or a
    /// longer travel for encoder logs, a second laser offset for point tables (last stop an
    /// accelerometer user was told to mount a second laser).
    #[test]
    fn separating_advice_fits_the_recording() {
        use super::report::{separating_measurement as sep, Recording};
        use vmt_sim::effects::EffectName::{Backlash, CyclicLead, GravityTilt, Positioning, Resonance, Roll};
        use vmt_sim::effects::EffectName::{StraightnessY, Yaw};
        assert!(sep(GravityTilt, Roll, Recording::Accelerometer).contains("two or more speeds"));
        assert!(sep(Resonance, StraightnessY, Recording::Accelerometer).contains("another speed"));
        assert!(sep(Roll, StraightnessY, Recording::Accelerometer).contains("second accelerometer"));
        assert!(sep(Roll, StraightnessY, Recording::PointTable).contains("second laser"));
        assert!(sep(Backlash, Positioning, Recording::EncoderLog).contains("slow reversal"));
        assert!(sep(CyclicLead, Positioning, Recording::EncoderLog).contains("longer travel"));
        assert!(sep(CyclicLead, Positioning, Recording::PointTable).contains("dense runs"));
        assert!(!sep(Roll, Yaw, Recording::Accelerometer).contains("laser"), "a laser advised for accelerometers");
    }

    use super::*;

    /// An accelerometer channel of `m` samples at 100 Hz from t = 0, x = 0.1·t.
    pub(crate) fn accel(run: &str, m: usize) -> Channel {
        let t: Vec<f64> = (0..m).map(|i| i as f64 / 100.0).collect();
        Channel {
            run: run.into(),
            sensor: "acc".into(),
            kind: SensorKind::Accelerometer,
            u: [0.0, 1.0, 0.0],
            r: [0.0; 3],
            x: t.iter().map(|t| 0.1 * t).collect(),
            d: vec![1.0; m],
            cycle: vec![1; m],
            t: t.clone(),
            v: vec![0.1; m],
            y: vec![0.0; m],
            sigma: Some(1e-3),
            encoder: None,
        }
    }

    /// 100 samples over 0.99 s → ⌈0.99/0.2⌉ = 5 segments; every sample falls in exactly one, and
    /// each resonance column pair is non-zero only on its own segment.
    #[test]
    fn resonance_segments_cover_every_sample_once() {
        let chans = vec![accel("a", 100), accel("b", 20)];
        let st = Stack::new(&chans);
        let segs = resonance_segments(&st);
        // Run b: 20 samples over 0.19 s → 1 segment.
        assert_eq!(segs.iter().filter(|s| s.0 == 0).count(), 5);
        assert_eq!(segs.iter().filter(|s| s.0 == 1).count(), 1);
        let sh = shape(&st, EffectName::Resonance, 1, DEFAULT_ORDER, false);
        assert_eq!(sh.coefs.len(), 12);
        let cols = columns(&st, EffectName::Resonance, &sh, &[45.0, 0.02]);
        for k in 0..st.n {
            // sin² + cos² = 1 on the one segment holding sample k, 0 elsewhere.
            let s: f64 = cols.iter().map(|c| c[k] * c[k]).sum();
            assert!((s - 1.0).abs() < 1e-12, "sample {k}: {s}");
        }
    }

    /// A y accelerometer at 0.1 m/s sampled at 100 Hz over a straightness EYX = 3e-6·x² (1/m):
    /// E'' = 6e-6 /m everywhere, so each reading is v²·E'' = 0.01·6e-6 = 6e-8 m/s², and a pitch
    /// (r = 0: r × u = 0) gives nothing. A laser sees the profile itself.
    #[test]
    fn guideway_acceleration_of_a_parabola_is_v2_times_its_curvature() {
        let c = accel("a", 10);
        let p = Profile::poly(vec![0.0, 0.0, 3e-6]);
        for i in 0..10 {
            let a = c.motion_response(i, EffectName::StraightnessY, |x| p.value(x), |x| p.eval3(x)[1]);
            assert!((a - 6e-8).abs() < 1e-20, "sample {i}: {a}");
            assert_eq!(c.motion_response(i, EffectName::Pitch, |x| p.value(x), |x| p.eval3(x)[1]), 0.0);
        }
        let mut l = accel("l", 3);
        l.kind = SensorKind::LaserStraightness;
        assert_eq!(l.motion_response(2, EffectName::StraightnessY, |x| p.value(x), |x| p.eval3(x)[1]), p.value(0.002));
    }

    /// Fitted straightness c_k·P_k(u) on an accelerometer (u = y, v = 0.1 m/s, Δt = 0.01 s, so
    /// x_{i−1} = x_i − 1 mm; positions over [a, b], u = (2x − a − b)/(b − a)): the P_1 column is 0
    /// (a slope has no acceleration), P_2 = (3u² − 1)/2 has the constant curvature 3·(2/(b − a))²,
    /// so its column is v²·3·(2/(b − a))² m/s² per unit c_2.
    #[test]
    fn fitted_straightness_columns_on_an_accelerometer_are_mean_curvatures_times_v2() {
        let chans = vec![accel("a", 10)];
        let st = Stack::new(&chans);
        let mut sh = shape(&st, EffectName::StraightnessY, 1, 3, false);
        // Only accelerometers see it: a cosine series; the Legendre columns checked first.
        assert_eq!(sh.basis, ShapeBasis::Cosine);
        sh.basis = ShapeBasis::Legendre;
        let cols = columns(&st, EffectName::StraightnessY, &sh, &[]);
        let (a, b) = sh.range;
        let want = 0.01 * 3.0 * (2.0 / (b - a)).powi(2);
        for i in 0..10 {
            assert!(cols[0][i].abs() < 1e-9 * want, "{}", cols[0][i]);
            assert!((cols[1][i] - want).abs() < 1e-9 * want, "{} vs {want}", cols[1][i]);
        }
        // Pairs cos(kπ(x − a)/L), sin(kπ(x − a)/L) after P_3, P_4: the column is v² times the
        // interval mean of E'' = −(kπ/L)²·cos(kπ(x − a)/L) (or ·sin), which is E'' at the interval's
        // middle to (kπh/L)²/24 (h = 1 mm, L = 9 mm: 0.5 % at k = 1, 1.9 % at k = 2, 4.3 % at k = 3);
        // checked to 1.2× that.
        sh.basis = ShapeBasis::Cosine;
        let l = b - a;
        // cols[0], cols[1] are P_3, P_4 (as above); then cos 1, sin 1, cos 2, sin 2, cos 3.
        sh.order = 7;
        let cols = columns(&st, EffectName::StraightnessY, &sh, &[]);
        for (j, col) in cols.iter().enumerate().skip(2) {
            let k = ((j - 2) / 2 + 1) as f64;
            let wave = |t: f64| if (j - 2) % 2 == 0 { t.cos() } else { t.sin() };
            let kx = std::f64::consts::PI * k / l;
            let tol = 1.2 * (kx * 1e-3).powi(2) / 24.0 * kx * kx * 0.01;
            for (i, v) in col.iter().enumerate().skip(1) {
                let mid = chans[0].x[i] - 0.5e-3;
                let want = -0.01 * kx * kx * wave(kx * (mid - a));
                assert!((v - want).abs() <= tol, "k {k}, sample {i}: {v} vs {want}");
            }
        }
        let mut laser = accel("l", 3);
        laser.kind = SensorKind::LaserStraightness;
        let both = [accel("a", 10), laser];
        assert_eq!(shape(&Stack::new(&both), EffectName::StraightnessY, 1, 3, false).basis, ShapeBasis::Legendre);
    }

    /// The Legendre series written as monomials reproduces it: Σ c_k·P_k(u(x)) = Σ m_j·x^j at
    /// positions over a 0.2–0.9 m range (order 7, random-ish coefficients), to 1e-9 relative.
    #[test]
    fn legendre_series_as_monomials_matches_it() {
        let c = [0.3, -1.2, 0.7, 0.05, -0.4, 0.9, 0.2];
        let range = (0.2, 0.9);
        let m = legendre_to_monomials(1, &c, range);
        for i in 0..=20 {
            let x = 0.2 + 0.7 * i as f64 / 20.0;
            let u = (2.0 * x - 1.1) / 0.7;
            let (p, _) = legendre(u, 7);
            let want: f64 = c.iter().enumerate().map(|(k, ck)| ck * p[k + 1]).sum();
            let got: f64 = m.iter().enumerate().map(|(j, mj)| mj * x.powi(j as i32)).sum();
            assert!((got - want).abs() < 1e-9 * (1.0 + want.abs()), "x {x}: {got} vs {want}");
        }
    }

    /// Free vibration from (q, q̇) = (1, 0): q̇(t) = −(ω²/ω_d)·e^{−ζωt}·sin(ω_d·t), ω_d = ω·√(1 − ζ²);
    /// the reading is (q̇_i − q̇_{i−1})/Δt from t_{−1} = −Δt (the sample times start at 0 and t_{−1}
    /// is the integration's zero). Agreement to 1e-9 of ω² (the step map's RK4 error is ≈ 1e-14).
    #[test]
    fn free_mode_response_matches_the_damped_oscillator() {
        let c = accel("a", 100);
        let (f, z): (f64, f64) = (12.0, 0.05);
        let w = TWO_PI * f;
        let wd = w * (1.0 - z * z).sqrt();
        let qd = |t: f64| -(w * w / wd) * (-z * w * t).exp() * (wd * t).sin();
        let r = mode_response(&c, None, f, z, (1.0, 0.0));
        for i in 0..100 {
            let (t1, t0) = (c.t[i] + 0.01, c.t[i]);
            let want = (qd(t1) - qd(t0)) / 0.01;
            assert!((r[i] - want).abs() < 1e-9 * w * w, "sample {i}: {} {want}", r[i]);
        }
    }

    /// A clock at a round rate gives every interval the same number of mode steps: over 100 000
    /// samples t_i = i/f_s (each interval a few ulps either side of a whole number of steps at
    /// 500 Hz – 10 kHz), one count per rate, the whole number; and an interval 10⁻⁶ above a whole
    /// number takes one step more.
    #[test]
    fn intervals_of_a_round_clock_take_one_number_of_mode_steps() {
        for (fs, whole) in [(500.0, 20), (1000.0, 10), (2000.0, 5), (2500.0, 4), (5000.0, 4), (10_000.0, 4)] {
            let t: Vec<f64> = (0..100_000).map(|i| i as f64 / fs).collect();
            let counts: std::collections::BTreeSet<usize> = t.windows(2).map(|p| mode_steps(p[1] - p[0])).collect();
            assert_eq!(counts.into_iter().collect::<Vec<_>>(), vec![whole], "{fs} Hz");
        }
        assert_eq!(mode_steps(1e-3 * (1.0 + 1e-6)), 11);
        assert_eq!(mode_steps(6.653345189819e-4), 7);
    }

    /// Forced at resonance by a(τ) = A·sin(ωτ) with ζ = 0.2: after the transient (e^{−ζω·2 s} ≈
    /// e^{−25}) q̈ = −A·cos(ωτ)/(2ζ) (|H| = 1/(2ζω²) at ω, q = A·cos(ωτ)/(2ζω²)), read as the mean
    /// of q̈ over each 10 ms interval: the exact mean of that cosine, to 1e-5 of A/(2ζ) (the input
    /// is held at its mean over 0.1 ms steps, which shrinks a sinusoid by ≈ (ωh)²/24 = 1.6e-6 at
    /// 10 Hz).
    #[test]
    fn forced_mode_response_at_resonance_has_gain_one_over_two_zeta() {
        assert_steady_resonance_on((0..300).map(|i| i as f64 / 100.0).collect(), 200, None);
    }

    /// The forced response at resonance of a 10 Hz mode with ζ = 0.2 driven by a(t) = A·sin(ωt) on
    /// the clock `t`, against its steady state from sample `from` on (after the transient, at
    /// t ≥ 2 s: e^{−ζω·t} ≤ e^{−25}): the exact means of −A·cos(ωt)/(2ζ) over the time each sample
    /// truly averages (the logger's own interval `own`, s, when given, else the interval from the
    /// sample before), to 1e-5 of A/(2ζ); the input tabulated over the steps of [`sample_span`].
    fn assert_steady_resonance_on(t: Vec<f64>, from: usize, own: Option<f64>) {
        let n = t.len();
        let mut c = accel("a", n);
        c.t = t;
        let (f, z, amp): (f64, f64, f64) = (10.0, 0.2, 1.0);
        let w = TWO_PI * f;
        let (steps, input): (Vec<usize>, Vec<Vec<f64>>) = (0..n)
            .map(|i| {
                let dt = sample_interval(&c, i);
                let span = sample_span(&c, i);
                // The step boundaries: the lost stretch's (at a gap), then the window's.
                let mut tk = vec![c.t[i] - dt];
                if let Some((len, m)) = span.lost {
                    tk.extend((1..=m).map(|k| c.t[i] - dt + len * k as f64 / m as f64));
                }
                let (win, m) = span.window;
                tk.extend((1..=m).map(|k| c.t[i] - win + win * k as f64 / m as f64));
                // The mean of A·sin(ωt) over each step.
                let vals = tk.windows(2).map(|p| amp * ((w * p[0]).cos() - (w * p[1]).cos()) / (w * (p[1] - p[0])));
                (tk.len() - 1, vals.collect())
            })
            .unzip();
        let ex = Excitation::new(steps, input);
        let r = mode_response(&c, Some(&ex), f, z, (0.0, 0.0));
        assert!(c.t[from] >= 2.0);
        for i in from..n {
            let (a, b) = (c.t[i] - own.unwrap_or_else(|| sample_interval(&c, i)), c.t[i]);
            let want = -amp / (2.0 * z) * ((w * b).sin() - (w * a).sin()) / (w * (b - a));
            assert!((r[i] - want).abs() < 1e-5 * amp / (2.0 * z), "sample {i}: {} {want}", r[i]);
        }
    }

    /// [`assert_steady_resonance_on`] a clock that rounds its times to 1 µs (intervals of 665 and
    /// 666 µs in turn, each with its own step map, kept and reused). A map reused for the other
    /// interval advances the state by 1 µs too much or too little: an error of about 10⁻³ of
    /// A/(2ζ) (it fails).
    #[test]
    fn forced_mode_response_on_a_rounded_clock_uses_each_intervals_map() {
        let t: Vec<f64> = (0..4000).map(|i| (i as f64 / 1503.0 * 1e6).round() / 1e6).collect();
        let distinct: std::collections::BTreeSet<u64> =
            t.windows(2).map(|p| ((p[1] - p[0]) * 1e6).round() as u64).collect();
        assert_eq!(distinct.into_iter().collect::<Vec<_>>(), vec![665, 666]);
        assert_steady_resonance_on(t, 3100, None);
    }

    /// [`assert_steady_resonance_on`] a clock that loses 3 % of its samples (a logger dropping
    /// packets: gaps of two, three … intervals): each sample is the mean over its own interval,
    /// not over the gap before it. Averaged over the whole gap (before [`sample_window`]), sample
    /// 2971 reads 1.370 where its own interval's mean is 1.414 (A/(2ζ) = 2.5): it fails.
    #[test]
    fn forced_mode_response_across_lost_samples_is_each_windows_mean() {
        use rand::{Rng, SeedableRng};
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(30);
        let t: Vec<f64> = (0..4300).map(|i| i as f64 * 665e-6).filter(|_| rng.gen::<f64>() >= 0.03).collect();
        let gaps = t.windows(2).filter(|p| p[1] - p[0] > 1.5 * 665e-6).count();
        assert!(gaps >= 80, "{gaps} gaps");
        let from = t.iter().position(|&x| x >= 2.0).unwrap();
        assert_steady_resonance_on(t, from, Some(665e-6));
    }

    /// The averaging window of a sample ([`sample_window`]) and where an accelerometer's sample
    /// reads a motion's slopes ([`Channel::interval_ends`]): the interval, but after lost samples
    /// the neighbouring interval (the first sample too when the second was lost); a jittered
    /// interval (+20 %) stays its own.
    #[test]
    fn a_sample_after_lost_samples_averages_over_its_own_interval() {
        let mut c = accel("a", 7);
        c.t = vec![0.0, 0.02, 0.03, 0.04, 0.07, 0.08, 0.092];
        let windows: Vec<f64> = (0..7).map(|i| sample_window(&c, i)).collect();
        let want = [0.01, 0.01, 0.01, 0.01, 0.01, 0.01, 0.012];
        for (i, (got, want)) in windows.iter().zip(want).enumerate() {
            assert!((got - want).abs() < 1e-12, "sample {i}: window {got}, not {want}");
        }
        let (xb, xa, v, dt) = c.interval_ends(4).unwrap();
        assert_eq!((xb, v), (c.x[4], 0.1));
        assert!((dt - 0.01).abs() < 1e-12 && (xb - xa - 0.1 * 0.01).abs() < 1e-12);
        assert_eq!(sample_span(&c, 3).lost, None);
        let span = sample_span(&c, 4);
        let (lost, m) = span.lost.unwrap();
        assert!((lost - 0.02).abs() < 1e-12 && m == mode_steps(lost) && span.window.1 == mode_steps(0.01));
    }

    /// [`assert_steady_resonance_on`] a jittered clock (each interval 665 µs with Gaussian jitter
    /// of 0.3 µs, none alike): most interval maps are had from a built one's Taylor tables
    /// (`BaseMap::interval_at`).
    #[test]
    fn forced_mode_response_on_a_jittered_clock_is_exact() {
        use rand::SeedableRng;
        use rand_distr::Distribution;
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(29);
        let jitter = rand_distr::Normal::new(0.0, 0.3e-6).unwrap();
        assert_steady_resonance_on(
            (0..4000).map(|i| i as f64 * 665e-6 + if i > 0 { jitter.sample(&mut rng) } else { 0.0 }).collect(),
            3100,
            None,
        );
    }

    /// Responses run side by side are those run alone, to the bit: six inputs with the same steps
    /// (two groups of lanes, 4 + 2) against one call each, and the two free vibrations against
    /// their starts run alone; with a jittered clock (the step map rebuilt at every sample).
    #[test]
    fn mode_responses_side_by_side_are_each_alone() {
        use rand::SeedableRng;
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(7);
        let mut c = accel("a", 400);
        for i in 1..c.t.len() {
            c.t[i] = c.t[i - 1] + 0.01 * (1.0 + 0.02 * rand::Rng::gen_range(&mut rng, -1.0..1.0));
        }
        let steps: Vec<usize> = (0..c.t.len()).map(|i| mode_steps(sample_interval(&c, i))).collect();
        let exs: Vec<Excitation> = (0..6)
            .map(|_| {
                let input = steps.iter().map(|&m| (0..m).map(|_| rand::Rng::gen_range(&mut rng, -1.0..1.0)).collect());
                Excitation::new(steps.clone(), input.collect())
            })
            .collect();
        let bits = |v: &[f64]| v.iter().map(|x| x.to_bits()).collect::<Vec<u64>>();
        for (f, z) in [(23.7, 0.013), (61.0, 0.4)] {
            let together = mode_responses(&c, &exs, f, z);
            assert_eq!(together.len(), 6);
            for (e, r) in exs.iter().zip(&together) {
                assert_eq!(bits(r), bits(&mode_response(&c, Some(e), f, z, (0.0, 0.0))));
            }
            let w = TWO_PI * f;
            let [f0, f1] = free_vibration(&c, f, z);
            assert_eq!(bits(&f0), bits(&mode_response(&c, None, f, z, (1.0 / (w * w), 0.0))));
            assert_eq!(bits(&f1), bits(&mode_response(&c, None, f, z, (0.0, 1.0 / w))));
        }
    }

    /// The gravity-tilt column of degree k on an accelerometer is g·P_k(u), u = (2x − a − b)/(b − a)
    /// over the positions' range [a, b] (g = 9.80665 m/s²), shared by the sensor's runs; a laser
    /// channel gets 0; a sensor's own degree (`with_tilt_orders`) sets its columns and names.
    #[test]
    fn gravity_tilt_columns_are_g_times_legendre_of_x() {
        let mut laser = accel("c", 3);
        laser.kind = SensorKind::LaserLinear;
        laser.sensor = "laser".into();
        let chans = vec![accel("a", 10), accel("b", 10), laser];
        let st = Stack::new(&chans);
        let sh = shape(&st, EffectName::GravityTilt, 1, 3, false);
        assert_eq!(sh.coefs, vec!["acc_p1", "acc_p2", "acc_p3"]);
        let cols = columns(&st, EffectName::GravityTilt, &sh, &[]);
        // Sample 5 of run b: x = 0.1·0.05 = 0.005 m on [0, 0.009]: u = 1/9, P_2 = (3u² − 1)/2.
        let u = 1.0 / 9.0;
        assert!((cols[1][15] - GRAVITY * (3.0 * u * u - 1.0) / 2.0).abs() < 1e-14);
        assert!(cols.iter().all(|c| c[20..].iter().all(|v| *v == 0.0)));
        let two = sh.with_tilt_orders(&["acc".to_string()], vec![2]);
        assert_eq!((two.coefs.clone(), two.order), (vec!["acc_p1".to_string(), "acc_p2".to_string()], 2));
        assert_eq!(columns(&st, EffectName::GravityTilt, &two, &[]), cols[..2].to_vec());
        assert!(cols.iter().all(|c| c[20..].iter().all(|v| *v == 0.0)));
    }
}
