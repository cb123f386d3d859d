//! The accelerometer straightness adapter: straightness (and, from a horizontal accelerometer across the motion, the
//! gravity-tilt / roll separation) from the constant-velocity passes of any measurement set (FORMAT.md §1),
//! whatever program wrote it (issue 17). The one adapter from a measurement set to the estimator of
//! `vmt_estimators::accel_straightness` (seed 000 and the SNR-weighted fusion of DESIGN.md §7): `vmt run`
//! goes through it too (`accel_straightness_check`), so both paths give the same estimate from the same data.
//!
//! What a pass must be (checked here, each refusal names the file and the run): a `constant_velocity`
//! time series with `t` uniformly spaced (within 1 %), an `x_cmd` column moving at the manifest's `feed`
//! (> 0, m/s) in every eighth of the pass (within 2 %: a speed that varies within a pass breaks the
//! position mapping `x = x0 + dir·v·t`), `direction` (if given) agreeing with `x_cmd`, and the sensor's
//! column. Equal sample counts are not needed: every pass is resampled onto the common position grid.
//! The seed's spatial-frequency continuity needs at least two distinct speeds, and so does the tilt
//! separation (the tilt is the part that does not scale with v²).
//!
//! A reading is taken as the mean acceleration over the sample interval before its time stamp (an
//! averaging anti-alias filter, as vmt's simulated accelerometer): it belongs half a sample, `v/(2·fs)`,
//! behind the commanded position.

use super::{display, profile_figure, Check, Quantity, TruthView};
use crate::error::VmtError;
use crate::measurement::{MeasurementSet, Procedure, ProfileColumn, ProfileTable, RunData, Sensor, SensorKind};
use serde::Serialize;
use std::path::Path;
use vmt_estimators::accel_straightness::{
    estimate_straightness, AccelRun, FusionMethod, InBandBounds, SpectralBasis, StraightnessConfig,
    StraightnessEstimate,
};
use vmt_report::{Figure, FigureKind, Series, SeriesStyle};
use vmt_sim::effects::EffectName;
use vmt_sim::Axis;

/// Relative tolerance on the uniformity of the time stamps of a pass.
const TIME_STEP_TOLERANCE: f64 = 0.01;
/// Relative tolerance on the speed of each eighth of a pass against the manifest's `feed`.
const SPEED_TOLERANCE: f64 = 0.02;
/// Speeds closer than this (relative) count as one speed.
const DISTINCT_SPEED: f64 = 0.01;

/// A straightness method name that is none of [`parse_method`]'s.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
#[error(
    "method: expected \"seed\" (the patent's spatial-frequency continuity) or \"fusion\" (SNR-weighted), got \"{0}\" \
     (docs/methods.md)"
)]
pub struct UnknownMethod(pub String);

/// The method, by the names a user types (`seed`, `fusion`) or a scenario uses (`spatial_continuity`,
/// `seed000`, `snr_weighted`).
pub fn parse_method(name: &str) -> Result<FusionMethod, UnknownMethod> {
    match name {
        "seed" | "spatial_continuity" | "seed000" => Ok(FusionMethod::SpatialContinuity),
        "fusion" | "snr_weighted" => Ok(FusionMethod::SnrWeighted),
        other => Err(UnknownMethod(other.to_string())),
    }
}

/// Which runs of a set are the passes: every `constant_velocity` run holding the sensor's column
/// (`vmt straightness`), or the runs a scenario's procedure recorded (`vmt run`).
#[derive(Clone, Copy, Debug)]
pub enum PassSelection<'a> {
    /// Every `constant_velocity` run holding the sensor's column.
    ConstantVelocity,
    /// The runs a scenario procedure recorded ([`crate::workflow::truth::TruthView::runs_of`]).
    Procedure {
        /// The procedure's name.
        name: &'a str,
        /// The names of its runs.
        runs: &'a [String],
    },
}

fn unit(d: [f64; 3]) -> [f64; 3] {
    let n = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt();
    [d[0] / n, d[1] / n, d[2] / n]
}

fn dot(a: [f64; 3], b: [f64; 3]) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

/// The estimator's passes of `sensor` from a measurement set: speed from `feed`, direction from the run
/// (or the sign of `x_cmd`'s motion), sample rate `(N − 1)/(t_last − t_0)`, first position half a sample
/// behind `x_cmd[0]` (module doc). Returns the passes with their run names.
pub fn accel_passes(
    set: &MeasurementSet,
    file: &Path,
    sensor: &str,
    selection: PassSelection<'_>,
) -> Result<Vec<(String, AccelRun)>, VmtError> {
    let mut passes = Vec::new();
    for (i, r) in set.runs.iter().enumerate() {
        let place = format!("runs[{i}] ({})", r.name);
        let bad = |m: String| VmtError::bad(file, place.clone(), m);
        let selected = match selection {
            PassSelection::ConstantVelocity => r.procedure == Procedure::ConstantVelocity,
            PassSelection::Procedure { runs, .. } => runs.contains(&r.name),
        };
        let (true, Some(a)) = (selected, r.data.column(sensor)) else { continue };
        let RunData::TimeSeries { t, .. } = &r.data else {
            return Err(bad("expected a time series (t, x_cmd, sensor columns) for a constant-velocity pass".into()));
        };
        let x = r.data.command().ok_or_else(|| bad("expected an `x_cmd` column (commanded position)".into()))?;
        let n = t.len();
        if n < 16 {
            return Err(bad(format!("expected at least 16 samples in a pass, got {n}")));
        }
        let feed = r.feed.ok_or_else(|| {
            bad("missing `feed`: the speed of a constant-velocity pass (m/s) maps time to position".into())
        })?;
        if !(feed.is_finite() && feed > 0.0) {
            return Err(bad(format!("expected `feed` > 0 (m/s), got {feed}")));
        }
        let span = t[n - 1] - t[0];
        let dt = span / (n - 1) as f64;
        if let Some((j, w)) =
            t.windows(2).enumerate().find(|(_, w)| ((w[1] - w[0]) - dt).abs() > TIME_STEP_TOLERANCE * dt)
        {
            return Err(bad(format!(
                "expected uniformly spaced time stamps (mean step {dt:.6e} s, within {:.0} %), got a step of \
                 {:.6e} s after sample {j}",
                TIME_STEP_TOLERANCE * 100.0,
                w[1] - w[0]
            )));
        }
        let moved = x[n - 1] - x[0];
        let dir = match r.direction {
            Some(d) => i32::from(d),
            None if moved < 0.0 => -1,
            None => 1,
        };
        if moved * f64::from(dir) <= 0.0 {
            return Err(bad(format!("`direction` = {dir} but x_cmd moves by {moved:.6e} m")));
        }
        // Speed of each eighth of the pass against the feed.
        let seg = (n - 1) / 8;
        for s in 0..8 {
            let (j0, j1) = (s * seg, if s == 7 { n - 1 } else { (s + 1) * seg });
            let v = (x[j1] - x[j0]) * f64::from(dir) / (t[j1] - t[j0]);
            if (v - feed).abs() > SPEED_TOLERANCE * feed {
                return Err(bad(format!(
                    "the speed varies within the pass: x_cmd moves at {v:.6e} m/s between t = {:.6} s and {:.6} s, \
                     `feed` is {feed:.6e} m/s (expected within {:.0} %: the method maps time to position at \
                     constant speed)",
                    t[j0],
                    t[j1],
                    SPEED_TOLERANCE * 100.0
                )));
            }
        }
        let rate = 1.0 / dt;
        passes.push((
            r.name.clone(),
            AccelRun {
                speed: feed,
                sample_rate: rate,
                start_position: x[0] - f64::from(dir) * feed / (2.0 * rate),
                direction: dir,
                acceleration: a.to_vec(),
            },
        ));
    }
    if passes.is_empty() {
        let which = match selection {
            PassSelection::ConstantVelocity => "constant_velocity runs".to_string(),
            PassSelection::Procedure { name, .. } => format!("runs of procedure `{name}`"),
        };
        return Err(VmtError::bad(file, "runs", format!("expected {which} with a `{sensor}` column, found none")));
    }
    Ok(passes)
}

/// Number of distinct speeds (relative difference > 1 %).
fn distinct_speeds(passes: &[(String, AccelRun)]) -> usize {
    let mut v: Vec<f64> = passes.iter().map(|p| p.1.speed).collect();
    v.sort_by(f64::total_cmp);
    1 + v.windows(2).filter(|w| w[1] - w[0] > DISTINCT_SPEED * w[1]).count()
}

/// The estimator settings for a sensor of a set: the method; the manifest's `noise_density` if given
/// (estimated from each record otherwise); its `highpass` undone; the cosine basis (no wrap-around
/// leakage on non-periodic profiles); the gravity tilt separated when the sensitive direction is
/// horizontal and across the motion (|d_z| < 0.5, |d·axis| < 0.5: a Y sensor on an X axis reads g·EAX).
pub fn accel_config(sensor: &Sensor, method: FusionMethod) -> StraightnessConfig {
    let d = unit(sensor.direction);
    let across_horizontal = d[2].abs() < 0.5 && dot(d, sensor.axis.unit()).abs() < 0.5;
    StraightnessConfig {
        method,
        noise_density: sensor.noise_density,
        basis: SpectralBasis::Cosine,
        ac_coupling_hz: sensor.highpass.unwrap_or(0.0),
        separate_gravity_tilt: across_horizontal && method == FusionMethod::SnrWeighted,
        ..Default::default()
    }
}

/// One pass as the report shows it.
#[derive(Clone, Debug, Serialize)]
pub struct PassReport {
    /// The run's name.
    pub run: String,
    /// m/s
    pub speed: f64,
    /// Hz
    pub sample_rate: f64,
    /// Number of samples in the pass.
    pub samples: usize,
    /// One-sided white-noise density used, m/s²/√Hz.
    pub noise_density: f64,
    /// `"manifest"` or `"estimated from the record"` (upper half of its spectrum).
    pub noise_density_source: &'static str,
}

/// The straightness of one sensor: estimate, band, bounds, and the profile columns it fills.
#[derive(Clone, Debug, Serialize)]
pub struct SensorStraightness {
    /// The accelerometer's name.
    pub sensor: String,
    /// The axis moved (JSON `"x"`, `"y"` or `"z"`).
    #[serde(with = "vmt_core::axis::letter")]
    pub axis: Axis,
    /// The error motion the sensor's direction reads (`straightness_y`/`straightness_z`: the first/second
    /// transverse direction of the axis), at the sensor's mounting point (Abbe terms ε×r included).
    pub effect: EffectName,
    /// +1 or −1: the sensor's direction along or against that transverse direction.
    pub sign: f64,
    /// The error motion the separated tilt is (`roll` when `direction × ẑ` lies along the axis), with its sign.
    pub tilt_effect: Option<(EffectName, f64)>,
    /// The passes used.
    pub passes: Vec<PassReport>,
    /// The passes as the estimator took them (not in the JSON: the data).
    #[serde(skip)]
    pub runs: Vec<AccelRun>,
    /// The estimated straightness (positions m, straightness m) and what the estimator did.
    pub estimate: StraightnessEstimate,
    /// Cramér–Rao bounds of the estimate within the recoverable band, m.
    pub bounds: InBandBounds,
}

/// The straightness (and tilt) of `sensor` from the passes of `set` (the one path of `vmt straightness`
/// and `vmt run`).
pub fn sensor_straightness(
    set: &MeasurementSet,
    file: &Path,
    sensor: &str,
    selection: PassSelection<'_>,
    method: FusionMethod,
) -> Result<SensorStraightness, VmtError> {
    let (si, s) = set
        .sensors
        .iter()
        .enumerate()
        .find(|(_, s)| s.name == sensor)
        .ok_or_else(|| VmtError::bad(file, "sensors", format!("no sensor `{sensor}` declared")))?;
    let place = format!("sensors[{si}] ({sensor})");
    if s.kind != SensorKind::Accelerometer {
        return Err(VmtError::bad(file, place, format!("expected an accelerometer, got kind `{}`", s.kind.as_str())));
    }
    let d = unit(s.direction);
    let others: Vec<usize> = (0..3).filter(|&c| s.axis.unit()[c] == 0.0).collect();
    let (slot, comp) = if d[others[0]].abs() >= d[others[1]].abs() { (0, others[0]) } else { (1, others[1]) };
    if d[comp].abs() < 0.9 {
        return Err(VmtError::bad(
            file,
            format!("{place}.direction"),
            format!(
                "expected a sensitive direction within 25° of a transverse direction of axis {}, got {:?}",
                s.axis, s.direction
            ),
        ));
    }
    let effect = [EffectName::StraightnessY, EffectName::StraightnessZ][slot];
    let passes = accel_passes(set, file, sensor, selection)?;
    let cfg = accel_config(s, method);
    let speeds = distinct_speeds(&passes);
    let need = match (method, cfg.separate_gravity_tilt) {
        (FusionMethod::SpatialContinuity, _) => Some("the seed's spatial-frequency continuity joins speeds"),
        (FusionMethod::SnrWeighted, true) => {
            Some("a horizontal sensor across the motion also reads g·tilt, separated by how it scales with v²")
        }
        (FusionMethod::SnrWeighted, false) => None,
    };
    if let (Some(why), true) = (need, speeds < 2) {
        return Err(VmtError::bad(
            file,
            "runs",
            format!("too few speeds for `{sensor}`: expected at least 2 distinct feeds ({why}), got {speeds}"),
        ));
    }
    let runs: Vec<AccelRun> = passes.iter().map(|p| p.1.clone()).collect();
    let estimate = estimate_straightness(&runs, &cfg).map_err(|e| VmtError::bad(file, "runs", e.to_string()))?;
    let bounds = estimate.in_band_bounds().map_err(|e| VmtError::bad(file, "runs", e.to_string()))?;
    // τ = ε·(d × ẑ): roll when d × ẑ lies along the axis.
    let dz = [d[1], -d[0], 0.0];
    let along = dot(dz, s.axis.unit());
    let tilt_effect = (estimate.tilt.is_some() && along.abs() >= 0.9).then(|| (EffectName::Roll, along.signum()));
    let passes = passes
        .iter()
        .zip(&estimate.runs)
        .map(|((name, r), diag)| PassReport {
            run: name.clone(),
            speed: r.speed,
            sample_rate: r.sample_rate,
            samples: r.acceleration.len(),
            noise_density: diag.noise_density,
            noise_density_source: if diag.noise_density_estimated { "estimated from the record" } else { "manifest" },
        })
        .collect();
    Ok(SensorStraightness {
        sensor: sensor.to_string(),
        axis: s.axis,
        effect,
        sign: d[comp].signum(),
        tilt_effect,
        passes,
        runs,
        estimate,
        bounds,
    })
}

/// The estimates as a FORMAT.md §5 profile table with `_sigma` columns (pointwise standard deviations
/// from the Cramér–Rao bounds of the in-band coefficients). Straightness about its least-squares line;
/// the tilt (roll) with its mean removed (its constant is not observable: it equals the sensor bias).
pub fn profile_table(results: &[SensorStraightness], file: &Path) -> Result<ProfileTable, VmtError> {
    let Some(first) = results.first() else {
        return Err(VmtError::Internal("profile_table: no estimate".into()));
    };
    let position = first.estimate.positions.clone();
    let mut columns: Vec<ProfileColumn> = Vec::new();
    for r in results {
        if r.estimate.positions != position {
            return Err(VmtError::bad(
                file,
                "runs",
                format!(
                    "sensors `{}` and `{}` were estimated on different position grids (different passes): \
                     write them to separate files (--sensor)",
                    first.sensor, r.sensor
                ),
            ));
        }
        let mut push = |effect: EffectName, values: Vec<f64>, sigma: Vec<f64>| {
            if columns.iter().any(|c| c.effect == effect) {
                return Err(VmtError::bad(
                    file,
                    "sensors",
                    format!("two sensors estimate `{}`: choose one with --sensor", effect.as_str()),
                ));
            }
            columns.push(ProfileColumn { axis: None, effect, values, sigma: Some(sigma) });
            Ok(())
        };
        let e = &r.estimate;
        push(r.effect, e.straightness.iter().map(|v| v * r.sign).collect(), r.bounds.straightness_std.clone())?;
        if let (Some((eff, sign)), Some(t), Some(ts)) = (r.tilt_effect, &e.tilt, &r.bounds.tilt_std) {
            push(eff, t.iter().map(|v| v * sign).collect(), ts.clone())?;
        }
    }
    Ok(ProfileTable { position, columns })
}

/// What [`band_geometry`] depends on, bit for bit: the estimate's grid, the band's wavelengths, the
/// harmonics' period and origin, and whether the DFT pipeline's high-pass and edge trim apply.
#[derive(Clone, PartialEq, Eq)]
struct GeometryKey {
    positions: Vec<u64>,
    band: [u64; 4],
    periodic: bool,
}

/// Per band harmonic, its wavelength (m) and per phase Σ(P φ_k)² with the number of points — the
/// post-processed basis function's mean square, which weights σ_k² in the Cramér–Rao bound of the
/// check's RMS difference.
type BandGeometry = std::sync::Arc<Vec<(f64, Vec<(f64, f64)>)>>;

/// The value of `key` in `cache`, computed by `compute` once and shared by later calls with an equal key (a
/// study's trials: the same grid and truth, a different noise). The cache holds the last [`MEMO_KEPT`]
/// keys; a value is a pure function of its key, so results do not depend on the cache or on thread
/// scheduling (two threads missing at once both compute the same value).
fn memo<K: PartialEq, V: Clone>(
    cache: &std::sync::Mutex<Vec<(K, V)>>,
    key: K,
    compute: impl FnOnce() -> Result<V, VmtError>,
) -> Result<V, VmtError> {
    use std::sync::PoisonError;
    let cached =
        cache.lock().unwrap_or_else(PoisonError::into_inner).iter().find(|(k, _)| *k == key).map(|e| e.1.clone());
    if let Some(v) = cached {
        return Ok(v);
    }
    let v = compute()?;
    let mut cache = cache.lock().unwrap_or_else(PoisonError::into_inner);
    if cache.len() >= MEMO_KEPT {
        cache.remove(0);
    }
    cache.push((key, v.clone()));
    Ok(v)
}

/// Keys a [`memo`] cache keeps (a study of many values computes each value's entry again when its trials
/// interleave with more than this many other values' trials: slower, never different).
const MEMO_KEPT: usize = 8;

/// The band geometry for `key`, computed by `compute` once and shared by later calls with the same key.
fn band_geometry(
    key: GeometryKey,
    compute: impl FnOnce() -> Result<Vec<(f64, Vec<(f64, f64)>)>, VmtError>,
) -> Result<BandGeometry, VmtError> {
    static CACHE: std::sync::Mutex<Vec<(GeometryKey, BandGeometry)>> = std::sync::Mutex::new(Vec::new());
    memo(&CACHE, key, || compute().map(std::sync::Arc::new))
}

/// What the band-limited truth of [`accel_straightness_check`] depends on, bit for bit: the estimate's
/// grid, the band's wavelengths, the sensor's point and direction, and the injected error motions.
#[derive(Clone, PartialEq)]
struct TruthKey {
    positions: Vec<u64>,
    band: [u64; 2],
    point: [u64; 3],
    direction: [u64; 3],
    motions: vmt_sim::geometry::ErrorMotions,
}

/// The injected curvature at the sensor's point integrated in the cosine basis over the band (the truth
/// the cosine-basis check compares with), computed once per [`TruthKey`] and shared (a study's trials).
fn band_limited_truth(
    key: TruthKey,
    compute: impl FnOnce() -> Result<Vec<f64>, VmtError>,
) -> Result<std::sync::Arc<Vec<f64>>, VmtError> {
    type Cache = Vec<(TruthKey, std::sync::Arc<Vec<f64>>)>;
    static CACHE: std::sync::Mutex<Cache> = std::sync::Mutex::new(Vec::new());
    memo(&CACHE, key, || compute().map(std::sync::Arc::new))
}

/// The accelerometer straightness check of one sensor (seed 000 / SNR-weighted fusion): the profile of
/// `sensor` from the passes of `procedure` by `method` (default `snr_weighted`), against the injected
/// deviation at the sensor's point band-limited the same way, within `tolerance` (m, RMS), with the
/// Cramér–Rao bound of the RMS difference from the simulated sensor's noise; the check's figure and the
/// pipeline's stage figures.
pub(super) fn accel_straightness_check(
    source: &Path,
    set: &MeasurementSet,
    truth: &TruthView<'_>,
    procedure: &str,
    sensor: &str,
    method: Option<&str>,
    tolerance: f64,
) -> Result<(Check, Figure, Vec<Figure>), VmtError> {
    use vmt_estimators::accel_straightness::{integrate_curvature_cosine, zero_phase_highpass};
    let bad = |m: String| VmtError::bad(source, format!("estimators ({procedure}/{sensor})"), m);
    let errors = truth.motions;
    let simulated = truth.sensor(sensor);
    let spec = set.sensor(sensor).ok_or_else(|| bad("sensor not declared".into()))?;
    // The same adapter as `vmt straightness` on the measurement set this recording is written as.
    let method = parse_method(method.unwrap_or("snr_weighted")).map_err(|e| bad(e.to_string()))?;
    let runs = truth.procedure_runs.get(procedure).map_or(&[][..], |v| v.as_slice());
    let selection = PassSelection::Procedure { name: procedure, runs };
    let result = sensor_straightness(set, source, sensor, selection, method)?;
    let (acc_runs, est) = (result.runs, result.estimate);
    let (r, u) = (spec.position, spec.direction);
    let n = est.positions.len();
    // index: the estimate is on the common grid of the runs, which has ≥ 16 positions
    // (accel_straightness::common_grid refuses fewer).
    let dx = (est.positions[n - 1] - est.positions[0]).abs() / (n - 1) as f64;
    // What the check does to a profile over the whole range before comparing (the same for truth, estimate
    // and, below, each basis function of the bound): the DFT pipeline applies the estimator's zero-phase
    // high-pass at the band's longest wavelength (the accelerometer cannot see longer ones) and keeps the
    // interior 80 % (edge transients of the filter); both then remove the least-squares line (ISO 230-1).
    let (i0, i1) = match est.basis {
        SpectralBasis::Cosine => (0, n),
        SpectralBasis::Periodic => (n / 10, n - n / 10),
    };
    let xs = &est.positions[i0..i1];
    let post = |p: &[f64]| -> Result<Vec<f64>, VmtError> {
        let p = match est.basis {
            SpectralBasis::Cosine => p.to_vec(),
            SpectralBasis::Periodic => {
                zero_phase_highpass(p, 1.0 / est.band.max_wavelength, 1.0 / dx).map_err(|e| bad(e.to_string()))?
            }
        };
        Ok(vmt_estimators::line::remove_line(xs, &p[i0..i1]))
    };
    let truth: Vec<f64> = match est.basis {
        // The truth band-limited by the estimator's own operator: the mount point's noise-free curvature
        // u·(E'' + ε''×r) integrated in the cosine basis over the recoverable band, over the whole range.
        // The same in every trial of a study (it depends on the grid, band, mount and truth, not on the noise).
        SpectralBasis::Cosine => {
            let (lo, hi) = (est.band.min_wavelength, est.band.max_wavelength);
            let bits = |v: [f64; 3]| v.map(f64::to_bits);
            let key = TruthKey {
                positions: est.positions.iter().map(|v| v.to_bits()).collect(),
                band: [lo.to_bits(), hi.to_bits()],
                point: bits(r),
                direction: bits(u),
                motions: errors.clone(),
            };
            let truth = band_limited_truth(key, || {
                let curvature: Vec<f64> = est.positions.iter().map(|&x| dot(u, errors.curvature_at(x, r))).collect();
                integrate_curvature_cosine(&est.positions, &curvature, lo, hi).map_err(|e| bad(e.to_string()))
            })?;
            truth.to_vec()
        }
        SpectralBasis::Periodic => est.positions.iter().map(|&x| dot(u, errors.deviation_at(x, r))).collect(),
    };
    let (truth, estimate) = (post(&truth)?, post(&est.straightness)?);
    // Cramér–Rao bound of the RMS difference as this check measures it. The estimate's error is a sum of
    // the band's basis functions φ_k (λ_k = P/k; P = L for the DFT with a cosine and a sine per k, P = 2L
    // for the cosine basis, φ_k = cos(π·k·(x − x₀ + Δx/2)/L)), each coefficient of an unbiased estimate
    // with variance ≥ σ_k², the bound per quadrature component (`cramer_rao_harmonic`: AC-coupling loss,
    // joint when the tilt is separated). The check compares P(estimate) with P(truth) for the linear
    // post-processing P above, so E[RMS²] ≥ Σ_k σ_k²·mean((P φ_k)²). P matters: the longest wavelengths
    // carry the largest σ_k (σ ∝ λ²) and are nearly a straight line over the range, which the reference
    // line removes.
    //
    // A bound follows from the true noise model, not from the data: σ_k uses the simulated sensor's white
    // noise density ρ (or σ/√(fs/2) for a sensor given by its per-sample σ), the same for any estimator.
    // The estimator's own ρ, estimated from the record's upper half-band (`estimate_noise_density`), also
    // holds the machine's high-frequency vibration; with it the "bound" stayed near 0.06 µm over a 100×
    // range of ρ and lay above the achieved error (issue 13).
    let rhos: Vec<f64> = est
        .runs
        .iter()
        .map(|r| match simulated {
            Some(s) if s.noise_density > 0.0 => s.noise_density,
            Some(s) => s.sigma / (r.sample_rate / 2.0).sqrt(),
            None => r.noise_density,
        })
        .collect();
    let speeds: Vec<f64> = est.runs.iter().map(|r| r.speed).collect();
    let spacings = est.spacings();
    let sigma_k = |lam: f64| {
        vmt_estimators::accel_straightness::cramer_rao_resolved(
            &rhos,
            &speeds,
            &spacings,
            est.travel,
            lam,
            est.ac_coupling_hz,
            est.gravity_tilt_separated,
        )
        .map(|b| b.straightness)
    };
    let (period, phases): (f64, &[f64]) = match est.basis {
        SpectralBasis::Periodic => (est.travel, &[0.0, std::f64::consts::FRAC_PI_2]),
        SpectralBasis::Cosine => (2.0 * est.travel, &[0.0]),
    };
    let x0 = est.positions[0]
        - match est.basis {
            SpectralBasis::Periodic => 0.0,
            SpectralBasis::Cosine => dx / 2.0,
        };
    // Σ(P φ_k)² per band harmonic and phase depends on the grid, band and basis only, not on the
    // noise: the trials of a study share it (`band_geometry`), each weighting it by its own σ_k².
    let key = GeometryKey {
        positions: est.positions.iter().map(|v| v.to_bits()).collect(),
        band: [est.band.min_wavelength.to_bits(), est.band.max_wavelength.to_bits(), period.to_bits(), x0.to_bits()],
        periodic: matches!(est.basis, SpectralBasis::Periodic),
    };
    let geometry = band_geometry(key, || {
        let mut g = Vec::new();
        for k in 1.. {
            let lam = period / k as f64;
            if lam < est.band.min_wavelength {
                break;
            }
            if lam > est.band.max_wavelength {
                continue;
            }
            let mut per_phase = Vec::with_capacity(phases.len());
            for &phase in phases {
                let phi: Vec<f64> = est
                    .positions
                    .iter()
                    .map(|&x| (2.0 * std::f64::consts::PI * (x - x0) / lam - phase).cos())
                    .collect();
                let p = post(&phi)?;
                per_phase.push((p.iter().map(|v| v * v).sum::<f64>(), p.len() as f64));
            }
            g.push((lam, per_phase));
        }
        Ok(g)
    })?;
    let mut var = 0.0;
    for (lam, per_phase) in geometry.iter() {
        let Ok(s) = sigma_k(*lam) else { continue };
        for (sum, len) in per_phase {
            var += s * s * sum / len;
        }
    }
    let bound = var.sqrt();
    let name = format!("straightness {sensor} (accelerometer)");
    let fig = profile_figure(
        format!(
            "{name}: injected vs recovered in the recoverable band {}–{} mm (Cramér–Rao bound of the RMS error {})",
            four_significant(est.band.min_wavelength * 1e3),
            four_significant(est.band.max_wavelength * 1e3),
            display(Quantity::Length, bound)
        ),
        Quantity::Length,
        xs,
        &[("injected (same band)", &truth, SeriesStyle::Line), ("recovered", &estimate, SeriesStyle::Dashed)],
    );
    let check = Check {
        bound: Some(bound),
        ..Check::profile(name, Quantity::Length, &truth, &estimate, tolerance)
            .with_id(format!("accel_straightness.{sensor}"))
            .with_note(format!(
                "both profiles band-limited to the recoverable wavelengths {}–{} mm; Cramér–Rao bound of the RMS difference {}",
                four_significant(est.band.min_wavelength * 1e3),
                four_significant(est.band.max_wavelength * 1e3),
                display(Quantity::Length, bound)
            ))
    };
    // The pipeline stage by stage (seed 000): raw acceleration per speed, then each speed's displacement
    // after Kalman filter, double integration and zero-phase high-pass; the fused result is `fig`.
    let mut raw = Figure {
        title: format!("{sensor}, stage 1: acceleration of each constant-velocity pass (mean removed)"),
        x_label: "position".into(),
        x_unit: "mm".into(),
        y_label: "acceleration".into(),
        y_unit: "mm/s²".into(),
        series: Vec::new(),
        kind: FigureKind::Line,
        log_x: false,
        log_y: false,
    };
    let mut disp = Figure {
        title: format!(
            "{sensor}, stage 2: displacement of each pass (Kalman, double integration, zero-phase high-pass)"
        ),
        y_label: "displacement".into(),
        y_unit: "µm".into(),
        ..raw.clone()
    };
    for (r, d) in acc_runs.iter().zip(&est.runs) {
        let x = vmt_estimators::accel_straightness::run_positions(r).map_err(|e| bad(e.to_string()))?;
        let mean = r.acceleration.iter().sum::<f64>() / r.acceleration.len() as f64;
        let label = format!("{:.0} mm/s", r.speed * 1e3);
        raw.series.push(Series {
            label: label.clone(),
            x: x.iter().map(|v| v * 1e3).collect(),
            y: r.acceleration.iter().map(|a| (a - mean) * 1e3).collect(),
            style: SeriesStyle::Line,
        });
        let cutoff = d.cutoff_wavelength.unwrap_or(est.band.max_wavelength);
        if let Ok((u, _)) = vmt_estimators::accel_straightness::seed_run_displacement(r, cutoff, true) {
            disp.series.push(Series {
                label,
                x: x.iter().map(|v| v * 1e3).collect(),
                y: u.iter().map(|v| v * 1e6).collect(),
                style: SeriesStyle::Line,
            });
        }
    }
    Ok((check, fig, vec![raw, disp]))
}

/// `x` with four significant digits and no trailing zeros (1.5, 399.9, 0.04): a band edge read literally
/// (whole millimetres showed 1.5 mm as "2").
fn four_significant(x: f64) -> String {
    if !(x.is_finite() && x != 0.0) {
        return format!("{x}");
    }
    // index: a count of decimals, not an index: x is finite and non-zero here, the casts saturate and max(0) keeps
    // it ≥ 0.
    let decimals = (3 - x.abs().log10().floor() as i32).max(0) as usize;
    let s = format!("{x:.decimals$}");
    if s.contains('.') {
        s.trim_end_matches('0').trim_end_matches('.').to_string()
    } else {
        s
    }
}
