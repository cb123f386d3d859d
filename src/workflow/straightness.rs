//! Workflow `straightness`: straightness (and, from a horizontal accelerometer across the motion, the
//! gravity-tilt / roll separation) from the constant-velocity passes of any measurement set (FORMAT.md §1),
//! whatever program wrote it (issue 17). The one adapter from a measurement set to the estimator of
//! `vmt_estimators::accel_straightness` (seed 000 and the SNR-weighted fusion of DESIGN.md §7): `vmt run`
//! goes through it too (`crate::estimate`), so both paths give the same estimate from the same data.
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

use crate::error::VmtError;
use crate::measurement::{self, MeasurementSet, Procedure, ProfileColumn, ProfileTable, RunData, Sensor, SensorKind};
use serde::Serialize;
use std::path::Path;
use vmt_estimators::accel_straightness::{
    estimate_straightness, AccelRun, FusionMethod, InBandBounds, SpectralBasis, StraightnessConfig,
    StraightnessEstimate,
};
use vmt_sim::effects::EffectName;

/// Relative tolerance on the uniformity of the time stamps of a pass.
const TIME_STEP_TOLERANCE: f64 = 0.01;
/// Relative tolerance on the speed of each eighth of a pass against the manifest's `feed`.
const SPEED_TOLERANCE: f64 = 0.02;
/// Speeds closer than this (relative) count as one speed.
const DISTINCT_SPEED: f64 = 0.01;

/// The method, by the names a user types (`seed`, `fusion`) or a scenario uses (`spatial_continuity`,
/// `seed000`, `snr_weighted`).
pub fn parse_method(name: &str) -> Result<FusionMethod, String> {
    match name {
        "seed" | "spatial_continuity" | "seed000" => Ok(FusionMethod::SpatialContinuity),
        "fusion" | "snr_weighted" => Ok(FusionMethod::SnrWeighted),
        other => Err(format!(
            "method: expected \"seed\" (seed 000, spatial-frequency continuity) or \"fusion\" (SNR-weighted), got \"{other}\""
        )),
    }
}

/// Which runs of a set are the passes: every `constant_velocity` run holding the sensor's column
/// (`vmt straightness`), or the runs named `<procedure>_*` (a scenario's procedure, `vmt run`).
#[derive(Clone, Copy, Debug)]
pub enum PassSelection<'a> {
    ConstantVelocity,
    Procedure(&'a str),
}

/// A unit vector of an axis letter (validated manifests hold x, y or z only).
fn axis_unit(axis: char) -> [f64; 3] {
    match axis {
        'y' => [0.0, 1.0, 0.0],
        'z' => [0.0, 0.0, 1.0],
        _ => [1.0, 0.0, 0.0],
    }
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
            PassSelection::Procedure(p) => r.name.starts_with(&format!("{p}_")),
        };
        let (true, Some(a)) = (selected, r.data.column(sensor)) else { continue };
        let RunData::TimeSeries { t, .. } = &r.data else {
            return Err(bad("expected a time series (t, x_cmd, sensor columns) for a constant-velocity pass".into()));
        };
        let x = r.data.column("x_cmd").ok_or_else(|| bad("expected an `x_cmd` column (commanded position)".into()))?;
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
            PassSelection::Procedure(p) => format!("runs named `{p}_*`"),
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
    let across_horizontal = d[2].abs() < 0.5 && dot(d, axis_unit(sensor.axis)).abs() < 0.5;
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
    pub run: String,
    /// m/s
    pub speed: f64,
    /// Hz
    pub sample_rate: f64,
    pub samples: usize,
    /// One-sided white-noise density used, m/s²/√Hz.
    pub noise_density: f64,
    /// `"manifest"` or `"estimated from the record"` (upper half of its spectrum).
    pub noise_density_source: &'static str,
}

/// The straightness of one sensor: estimate, band, bounds, and the profile columns it fills.
#[derive(Clone, Debug, Serialize)]
pub struct SensorStraightness {
    pub sensor: String,
    pub axis: char,
    /// The error motion the sensor's direction reads (`straightness_y`/`straightness_z`: the first/second
    /// transverse direction of the axis), at the sensor's mounting point (Abbe terms ε×r included).
    pub effect: EffectName,
    /// +1 or −1: the sensor's direction along or against that transverse direction.
    pub sign: f64,
    /// The error motion the separated tilt is (`roll` when `direction × ẑ` lies along the axis), with its sign.
    pub tilt_effect: Option<(EffectName, f64)>,
    pub passes: Vec<PassReport>,
    /// The passes as the estimator took them (not in the JSON: the data).
    #[serde(skip)]
    pub runs: Vec<AccelRun>,
    pub estimate: StraightnessEstimate,
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
    let others: Vec<usize> = (0..3).filter(|&c| axis_unit(s.axis)[c] == 0.0).collect();
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
    let along = dot(dz, axis_unit(s.axis));
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

/// `vmt straightness DIR [-o EST.csv] [--method seed|fusion] [--sensor NAME…] [--json]`.
pub fn command(path: &Path, out: Option<&Path>, method: &str, sensors: &[String], json: bool) -> Result<i32, VmtError> {
    let method = parse_method(method).map_err(VmtError::Usage)?;
    let set = measurement::read(path)?;
    let names: Vec<String> = if sensors.is_empty() {
        set.sensors
            .iter()
            .filter(|s| {
                s.kind == SensorKind::Accelerometer
                    && set
                        .runs
                        .iter()
                        .any(|r| r.procedure == Procedure::ConstantVelocity && r.data.column(&s.name).is_some())
            })
            .map(|s| s.name.clone())
            .collect()
    } else {
        sensors.to_vec()
    };
    if names.is_empty() {
        return Err(VmtError::bad(
            path,
            "sensors",
            "expected an accelerometer with a column in a constant_velocity run, found none",
        ));
    }
    let results = names
        .iter()
        .map(|n| sensor_straightness(&set, path, n, PassSelection::ConstantVelocity, method))
        .collect::<Result<Vec<_>, _>>()?;
    let table = match out {
        Some(o) => Some((o, profile_table(&results, o)?)),
        None => None,
    };
    if json {
        let v = serde_json::json!({
            "data": path,
            "method": method,
            "sensors": results,
        });
        crate::cli::print_json("vmt-straightness/1", &v)?;
    } else {
        print_text(path, &results);
    }
    if let Some((o, t)) = table {
        measurement::write_profiles(&t, o, measurement::UnitChoice::Si)?;
        eprintln!("wrote {}", o.display());
    }
    Ok(0)
}

fn rms(v: &[f64]) -> f64 {
    (v.iter().map(|x| x * x).sum::<f64>() / v.len().max(1) as f64).sqrt()
}

fn print_text(path: &Path, results: &[SensorStraightness]) {
    println!("vmt straightness: {}", path.display());
    for r in results {
        let e = &r.estimate;
        println!(
            "\n{} → {} ({:?}), {} passes, travel {:.1} mm",
            r.sensor,
            r.effect.as_str(),
            e.method,
            r.passes.len(),
            e.travel * 1e3
        );
        for p in &r.passes {
            println!(
                "  {:<16} {:>8.1} mm/s {:>8.1} Hz {:>7} samples  noise density {:.3} µg/√Hz ({})",
                p.run,
                p.speed * 1e3,
                p.sample_rate,
                p.samples,
                p.noise_density / vmt_estimators::accel_straightness::STANDARD_GRAVITY * 1e6,
                p.noise_density_source
            );
        }
        println!("  band: {}", e.band.note);
        println!(
            "  straightness: RMS {:.4} µm, peak-to-valley {:.4} µm; Cramér–Rao bound of the in-band RMS error {:.4} µm",
            rms(&e.straightness) * 1e6,
            (e.straightness.iter().cloned().fold(f64::NEG_INFINITY, f64::max)
                - e.straightness.iter().cloned().fold(f64::INFINITY, f64::min))
                * 1e6,
            r.bounds.straightness_rms * 1e6
        );
        if let (Some(t), Some(tb)) = (&e.tilt, r.bounds.tilt_rms) {
            let what = r.tilt_effect.map_or("gravity tilt of the sensitive axis", |(eff, _)| eff.as_str());
            println!(
                "  {what} (mean removed): RMS {:.4} µrad; Cramér–Rao bound of the in-band RMS error {:.4} µrad",
                rms(t) * 1e6,
                tb * 1e6
            );
        }
        println!("  Cramér–Rao bound per harmonic (1σ per quadrature component), a selection:");
        println!("  {:>12} {:>16} {:>16}", "λ mm", "straightness µm", "tilt µrad");
        let n = r.bounds.bins.len();
        let step = (n / 8).max(1);
        for b in r.bounds.bins.iter().step_by(step) {
            let s = b.straightness.map_or("-".to_string(), |v| format!("{:.5}", v * 1e6));
            let t = b.tilt.map_or("-".to_string(), |v| format!("{:.5}", v * 1e6));
            println!("  {:>12.1} {:>16} {:>16}", b.wavelength * 1e3, s, t);
        }
    }
}
