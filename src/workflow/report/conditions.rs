//! The header of test conditions on every report (issue 16): what a calibration engineer reads before
//! any number (as in the test conditions block of laser-calibration software): the program and its
//! version, when and how it was run, the scenario, machine and seed; per procedure its feed, dwell,
//! runs, targets and overrun; per sensor its noise, mounting point and Abbe offsets; per laser the air
//! and material conditions, α, and the Edlén and material corrections it applied.

use crate::scenario::Scenario;
use vmt_report::{Section, Table};
use vmt_sim::air::{edlen_index, Air, HENE_WAVELENGTH_UM};
use vmt_sim::chain::ChainProcedureSpec;
use vmt_sim::procedures::ProcedureSpec;
use vmt_sim::sensors::{SensorKind, SensorSpec};

/// vmt's version, with the git commit it was built from when built in a git checkout (build.rs).
pub fn version() -> String {
    match option_env!("VMT_GIT_COMMIT") {
        Some(c) if !c.is_empty() => format!("vmt {} (git {c})", env!("CARGO_PKG_VERSION")),
        _ => format!("vmt {}", env!("CARGO_PKG_VERSION")),
    }
}

/// The date of the report, UTC, ISO 8601 (`2026-11-26T03:12:45Z`). `SOURCE_DATE_EPOCH` (seconds since
/// 1970, the reproducible-builds convention) replaces the clock, so that a report can be made
/// bit-identical for the same input.
pub fn report_date() -> String {
    let secs: i64 =
        std::env::var("SOURCE_DATE_EPOCH").ok().and_then(|s| s.trim().parse::<i64>().ok()).unwrap_or_else(|| {
            std::time::SystemTime::now().duration_since(std::time::UNIX_EPOCH).map_or(0, |d| d.as_secs() as i64)
        });
    let (days, rem) = (secs.div_euclid(86_400), secs.rem_euclid(86_400));
    let (y, m, d) = civil_from_days(days);
    format!("{y:04}-{m:02}-{d:02}T{:02}:{:02}:{:02}Z", rem / 3600, rem % 3600 / 60, rem % 60)
}

/// Proleptic Gregorian date of a day count since 1970-01-01 (H. Hinnant's `civil_from_days`).
fn civil_from_days(z: i64) -> (i64, u32, u32) {
    let z = z + 719_468;
    let era = z.div_euclid(146_097);
    let doe = z.rem_euclid(146_097);
    let yoe = (doe - doe / 1460 + doe / 36_524 - doe / 146_096) / 365;
    let doy = doe - (365 * yoe + yoe / 4 - yoe / 100);
    let mp = (5 * doy + 2) / 153;
    let d = (doy - (153 * mp + 2) / 5 + 1) as u32;
    let m = if mp < 10 { mp + 3 } else { mp - 9 } as u32;
    (yoe + era * 400 + i64::from(m <= 2), m, d)
}

/// The command line this process was started with, each argument quoted when it holds a space.
pub fn command_line() -> String {
    std::env::args()
        .map(|a| if a.contains(char::is_whitespace) || a.is_empty() { format!("'{a}'") } else { a })
        .collect::<Vec<_>>()
        .join(" ")
}

fn row(item: &str, value: String) -> Vec<String> {
    vec![item.to_string(), value]
}

/// The run table: program, date, command, and what was given to it.
fn run_table(rows: Vec<Vec<String>>) -> Table {
    let mut all =
        vec![row("program", version()), row("date (UTC)", report_date()), row("command line", command_line())];
    all.extend(rows);
    Table { caption: "Run".into(), header: vec!["item".into(), "value".into()], rows: all, highlight: Vec::new() }
}

/// The test-conditions section of a report made without a scenario (`vmt compare --report` on a
/// user's own data): program, date, command line, and the given `(item, value)` rows.
pub fn conditions_for_data(rows: Vec<Vec<String>>) -> Section {
    Section {
        heading: "Test conditions".into(),
        text: vec!["How this report was made: read these before any number.".into()],
        figures: Vec::new(),
        tables: vec![run_table(rows)],
    }
}

fn mm(v: f64) -> String {
    format!("{:.1} mm", v * 1e3)
}

fn list(values: &[f64], scale: f64, unit: &str) -> String {
    let parts: Vec<String> = values.iter().map(|v| format!("{}", (v * scale * 1e3).round() / 1e3)).collect();
    format!("{} {unit}", parts.join(", "))
}

/// One row per procedure: kind, feed, dwell, runs, targets, overrun, sensors.
fn procedure_rows(sc: &Scenario) -> Vec<Vec<String>> {
    let dash = || "—".to_string();
    let mut rows: Vec<Vec<String>> = Vec::new();
    for p in &sc.procedures {
        let r: Vec<String> = match p {
            ProcedureSpec::ConstantVelocity { name, speeds, start, end, sensors, .. } => vec![
                name.clone(),
                "constant velocity".into(),
                list(speeds, 1e3, "mm/s"),
                dash(),
                format!("{} passes", speeds.len()),
                format!("sampled {}–{}", mm(*start), mm(*end)),
                dash(),
                sensors.join(", "),
            ],
            ProcedureSpec::Positioning(q) => vec![
                q.name.clone(),
                "ISO 230-2 positioning".into(),
                format!("{:.0} mm/s", q.feed * 1e3),
                format!("{} s (mean of last {} s)", q.dwell, q.average),
                format!("{} ↑ + {} ↓", q.runs, q.runs),
                match &q.targets {
                    Some(t) => format!(
                        "{} given, {}–{}",
                        t.len(),
                        mm(t.iter().copied().fold(f64::INFINITY, f64::min)),
                        mm(t.iter().copied().fold(f64::NEG_INFINITY, f64::max))
                    ),
                    None => format!("{} irregular, {}–{}", q.n_targets, mm(q.start), mm(q.end)),
                },
                mm(q.overrun),
                q.sensors.join(", "),
            ],
            ProcedureSpec::Crawl { name, feeds, duration, rate, sensors, .. } => vec![
                name.clone(),
                "crawl".into(),
                list(feeds, 60e3, "mm/min"),
                dash(),
                format!("{} feeds, {duration} s at {rate} Hz each", feeds.len()),
                dash(),
                dash(),
                sensors.join(", "),
            ],
            ProcedureSpec::NineLine { name, start, end, step, feed, dwell, average, overrun, sensors, .. } => vec![
                name.clone(),
                "9-line laser (k-means patent 2022, docs/methods.md)".into(),
                format!("{:.0} mm/s", feed * 1e3),
                format!("{dwell} s (mean of last {average} s)"),
                "1 ↑ + 1 ↓".into(),
                format!("every {} from {} to {}", mm(*step), mm(*start), mm(*end)),
                mm(*overrun),
                sensors.join(", "),
            ],
            ProcedureSpec::FrictionSweep { name, speeds, v_min, v_max, per_decade, sensors, .. } => vec![
                name.clone(),
                "friction sweep".into(),
                match speeds {
                    Some(s) => list(s, 1e3, "mm/s"),
                    None => format!("{} to {} mm/s, {per_decade} per decade", v_min * 1e3, v_max * 1e3),
                },
                dash(),
                "each speed ↑ and ↓".into(),
                dash(),
                dash(),
                sensors.join(", "),
            ],
            ProcedureSpec::Pause { name, duration } => vec![
                if name.is_empty() { "(pause)".into() } else { name.clone() },
                "pause (machine stands)".into(),
                dash(),
                format!("{duration} s"),
                dash(),
                dash(),
                dash(),
                dash(),
            ],
        };
        rows.push(r);
    }
    for c in &sc.chain_procedures {
        rows.push(match c {
            ChainProcedureSpec::LaserLines(s) => vec![
                s.name.clone(),
                "laser line set (Gan, Liu, Zhao; docs/methods.md)".into(),
                format!("{:.0} mm/s path", s.feed * 1e3),
                format!("{} s (mean of last {} s)", s.dwell, s.average),
                format!("{} lines", s.lines.len()),
                format!("{} points", s.lines.iter().map(|l| l.n).sum::<usize>()),
                dash(),
                format!("laser σ {:.3} µm", s.sigma * 1e6),
            ],
        });
    }
    rows
}

/// Noise of one reading as the scenario states it, in the channel's unit.
fn noise(s: &SensorSpec) -> String {
    let s = s.resolved();
    let (scale, unit): (f64, &str) = match s.kind {
        SensorKind::Command
        | SensorKind::EncoderLinear
        | SensorKind::LaserLinear
        | SensorKind::LaserStraightness
        | SensorKind::LaserVector => (1e6, "µm"),
        SensorKind::EncoderRotary | SensorKind::LaserAngular => (1e6, "µrad"),
        SensorKind::Accelerometer => {
            return if s.noise_density > 0.0 {
                format!("{:.3} µg/√Hz", s.noise_density / vmt_sim::axis_sim::GRAVITY * 1e6)
            } else {
                format!("σ {:.3e} m/s²", s.sigma)
            }
        }
        SensorKind::MotorForce => (1.0, "N"),
        SensorKind::Velocity => (1e3, "mm/s"),
        SensorKind::Temperature => (1.0, "K"),
        SensorKind::Pressure => (1.0, "Pa"),
        SensorKind::Humidity => (100.0, "% RH"),
    };
    let mut text = format!("σ {} {unit}", sig(s.sigma * scale));
    if s.resolution > 0.0 {
        text += &format!(", step {} {unit}", sig(s.resolution * scale));
    }
    text
}

/// Four significant digits without float noise.
fn sig(v: f64) -> String {
    if v == 0.0 {
        return "0".into();
    }
    // index: a count of digits, not an index: v ≠ 0 here, NaN casts to 0, ±∞ saturate and max(0) keeps it ≥ 0.
    let digits = (3 - v.abs().log10().floor() as i32).max(0) as usize;
    format!("{v:.digits$}")
}

/// One row per sensor: kind, noise, mounting point, sensitive direction, Abbe offset.
fn sensor_rows(sc: &Scenario) -> Vec<Vec<String>> {
    sc.sensors
        .iter()
        .map(|s| {
            // The mounting point in the axis frame: as written, or the origin of the link it is mounted on
            // (the scenario checked that the link exists), or the axis origin.
            let (p, place) = match (s.position, &s.link) {
                (Some(p), _) => (Some(p), String::new()),
                (None, Some(l)) => (s.axis_position(&sc.axis).ok(), format!("link {l} at ")),
                (None, None) => (Some([0.0; 3]), "axis origin ".into()),
            };
            let (mount, abbe) = match p {
                Some(p) => {
                    // Abbe offset: the distance of the mounting point from the line through the axis
                    // reference point along the sensing direction d, |p − (p·d)d| (ISO 230-1 §3.4.17).
                    let n = s.direction.iter().map(|v| v * v).sum::<f64>().sqrt().max(f64::MIN_POSITIVE);
                    let d = s.direction.map(|v| v / n);
                    let along = p[0] * d[0] + p[1] * d[1] + p[2] * d[2];
                    let off = [p[0] - along * d[0], p[1] - along * d[1], p[2] - along * d[2]];
                    let len = off.iter().map(|v| v * v).sum::<f64>().sqrt();
                    // Whole mm, and a value that rounds to zero written 0, not -0.
                    let mm = |v: f64| format!("{}", (v * 1e3).round() + 0.0);
                    (
                        format!("{place}({}, {}, {}) mm", mm(p[0]), mm(p[1]), mm(p[2])),
                        format!("{} mm ({}, {}, {})", mm(len), mm(off[0]), mm(off[1]), mm(off[2])),
                    )
                }
                None => (
                    s.link.clone().map_or("—".into(), |l| format!("link {l} (not in the machine)")),
                    "— (no mounting point)".into(),
                ),
            };
            vec![
                s.name.clone(),
                s.kind.as_str().into(),
                noise(s),
                mount,
                format!("({}, {}, {})", sig(s.direction[0]), sig(s.direction[1]), sig(s.direction[2])),
                abbe,
            ]
        })
        .collect()
}

fn air_text(a: &Air) -> String {
    format!("{:.2} °C, {:.2} kPa, {:.0} % RH", a.temperature, a.pressure / 1e3, a.humidity)
}

/// One row per laser: the actual and assumed air, the Edlén index the laser converts with, the
/// remaining air error, the material temperature, α and the normalisation error.
fn environment_rows(sc: &Scenario) -> Vec<Vec<String>> {
    sc.sensors
        .iter()
        .filter(|s| {
            matches!(
                s.kind,
                SensorKind::LaserLinear
                    | SensorKind::LaserStraightness
                    | SensorKind::LaserAngular
                    | SensorKind::LaserVector
            )
        })
        .map(|s| {
            let actual = s.air.unwrap_or(Air::REFERENCE);
            let assumed = s.assumed_air.unwrap_or(actual);
            let n = edlen_index(&assumed, HENE_WAVELENGTH_UM);
            vec![
                s.name.clone(),
                air_text(&actual),
                air_text(&assumed),
                format!("{:.3} ppm", (n - 1.0) * 1e6),
                format!("{:.3} ppm", s.air_scale_error() * 1e6),
                format!("{:.2} °C", s.material_temperature),
                format!("{:.2} °C", s.assumed_material_temperature.unwrap_or(s.material_temperature)),
                format!("{:.2} µm/(m·K)", s.material_alpha * 1e6),
                format!("{:.3} ppm", s.material_scale_error() * 1e6),
            ]
        })
        .collect()
}

/// The test-conditions section of a scenario's report.
pub fn conditions(sc: &Scenario) -> Section {
    let mut tables = vec![run_table(vec![
        row("scenario", sc.source.display().to_string()),
        row("description", if sc.description.is_empty() { "—".into() } else { sc.description.clone() }),
        row("machine", sc.machine_name.clone()),
        row("seed", format!("{} (random seed of the sensor noise and procedures)", sc.seed)),
    ])];
    let procedures = procedure_rows(sc);
    if !procedures.is_empty() {
        tables.push(Table {
            caption: "Procedures, in the order they ran on the session clock".into(),
            header: ["procedure", "kind", "feed", "dwell", "runs", "targets", "overrun", "sensors"]
                .map(String::from)
                .to_vec(),
            rows: procedures,
            highlight: Vec::new(),
        });
    }
    let sensors = sensor_rows(sc);
    if !sensors.is_empty() {
        tables.push(Table {
            caption:
                "Sensors: noise of one reading, mounting point and Abbe offset (axis frame at the reference point)"
                    .into(),
            header: ["sensor", "kind", "noise", "mounting point", "direction (unit vector)", "Abbe offset"]
                .map(String::from)
                .to_vec(),
            rows: sensors,
            highlight: Vec::new(),
        });
    }
    let env = environment_rows(sc);
    if !env.is_empty() {
        tables.push(Table {
            caption: "Lasers: air (Edlén, Birch & Downs 1994) and material temperature (normalised to 20 °C, ISO 1)"
                .into(),
            header: [
                "laser",
                "air at the beam",
                "air the laser assumes",
                "Edlén n − 1 applied",
                "remaining air error",
                "material temperature",
                "material temperature assumed",
                "α",
                "normalisation error",
            ]
            .map(String::from)
            .to_vec(),
            rows: env,
            highlight: Vec::new(),
        });
    }
    Section {
        heading: "Test conditions".into(),
        text: vec![
            "How this report was made: read these before any number. Lengths in the axis frame, at the axis reference point.".into(),
        ],
        figures: Vec::new(),
        tables,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn dates_hand_worked() {
        assert_eq!(civil_from_days(0), (1970, 1, 1));
        // 2000-03-01 is day 11 017 = 30·365 + 7 leap days + 60 (Jan + Feb of a leap year); 2026-11-26 is
        // day 20 783 = 56·365 + 14 leap days + 329 (day of the year − 1).
        assert_eq!(civil_from_days(11_017), (2000, 3, 1));
        assert_eq!(civil_from_days(20_783), (2026, 11, 26));
        assert_eq!(civil_from_days(-1), (1969, 12, 31));
    }

    #[test]
    fn significant_digits_without_float_noise() {
        assert_eq!(sig(0.1 * 3.0), "0.3000");
        assert_eq!(sig(50e-9 * 1e6), "0.05000");
        assert_eq!(sig(1.0), "1.000");
    }
}
