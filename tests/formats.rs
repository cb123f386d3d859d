//! File formats of FORMAT.md: measurement sets (§1), models (§2), profile CSVs (§5), and the bad
//! input rules of DESIGN.md §2 (every error names the file, the place and what was expected).

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use std::path::{Path, PathBuf};
use vmt::error::VmtError;
use vmt::measurement::{
    self, MeasurementSet, Procedure, ProfileColumn, ProfileTable, Run, RunData, Sensor, SensorKind, UnitChoice,
};
use vmt::model::{self, Basis, Model, ModelEffect};
use vmt_sim::effects::{
    AccelBiasDrift, Backlash, Coulomb, CyclicLead, Effect, EffectName, EffectParams, InterpolationError, LeadHarmonic,
    Lugre, Resonance, ScaleError, ServoLag, Squareness, Stribeck, ThermalDrift, ThermalExpansion, Viscous,
};
use vmt_sim::profile::{Harmonic, Profile, RandomProfile, Term};
use vmt_sim::Axis;

fn sensor(name: &str, kind: SensorKind, sigma: Option<f64>) -> Sensor {
    Sensor {
        name: name.to_string(),
        kind,
        axis: Axis::X,
        position: [0.0, 0.25, 1.1],
        direction: [1.0, 0.0, 0.0],
        sigma,
        closes_loop: false,
        noise_density: None,
        highpass: None,
    }
}

/// Random f64 values spread over many magnitudes and signs (all bits of the mantissa used), plus
/// awkward ones (−0, subnormal, huge), so that a bit-exact round trip means something.
fn awkward_values(rng: &mut ChaCha8Rng, n: usize) -> Vec<f64> {
    let mut v: Vec<f64> = (0..n)
        .map(|_| {
            let m: f64 = rng.gen_range(-1.0..1.0);
            let e: i32 = rng.gen_range(-300..300);
            m * 10f64.powi(e)
        })
        .collect();
    v[0] = -0.0;
    v[1] = 5e-324;
    v[2] = 1.7976931348623157e308;
    v[3] = 0.1 + 0.2;
    v
}

/// A set with one time series and one point table, values drawn with a fixed seed.
fn sample_set(seed: u64) -> MeasurementSet {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let n = 200;
    let t: Vec<f64> = (0..n).map(|i| i as f64 / 1200.0 + 1e-9 * rng.gen::<f64>()).collect();
    let x_cmd: Vec<f64> = t.iter().map(|ti| 0.05 * ti).collect();
    let laser = awkward_values(&mut rng, n);
    let acc: Vec<f64> = (0..n).map(|_| rng.gen_range(-1e-3..1e-3)).collect();
    let targets = [0.0, 0.1234567, 0.25, 0.5010101, 0.75, 1.0];
    let (mut target, mut run, mut direction, mut tt, mut dev) =
        (Vec::new(), Vec::new(), Vec::new(), Vec::new(), Vec::new());
    for r in 1..=5u32 {
        for (d, order) in [(1i8, false), (-1i8, true)] {
            let mut ts: Vec<f64> = targets.to_vec();
            if order {
                ts.reverse();
            }
            for x in ts {
                target.push(x);
                run.push(r);
                direction.push(d);
                tt.push(tt.len() as f64 * 7.5);
                dev.push(rng.gen_range(-5e-6..5e-6));
            }
        }
    }
    MeasurementSet {
        description: Some("ISO 230-2 test of X, \"laser\" on the column top".to_string()),
        machine: Some("slide_column".to_string()),
        seed: Some(42),
        sensors: vec![
            sensor("x_cmd", SensorKind::Command, None),
            sensor("laser_p1", SensorKind::LaserLinear, Some(5e-9)),
            sensor("acc_y", SensorKind::Accelerometer, Some(2.5e-4)),
        ],
        runs: vec![
            Run {
                name: "cv_fast".to_string(),
                file: "cv_fast.csv".to_string(),
                procedure: Procedure::ConstantVelocity,
                axis: Axis::X,
                start_time: Some(12.5),
                feed: Some(0.05),
                direction: Some(1),
                data: RunData::TimeSeries {
                    t,
                    columns: vec![
                        ("x_cmd".to_string(), x_cmd),
                        ("laser_p1".to_string(), laser),
                        ("acc_y".to_string(), acc),
                    ],
                },
            },
            Run {
                name: "iso".to_string(),
                file: "iso.csv".to_string(),
                procedure: Procedure::Positioning,
                axis: Axis::X,
                start_time: None,
                feed: None,
                direction: None,
                data: RunData::PointTable {
                    target,
                    run,
                    direction,
                    t: Some(tt),
                    columns: vec![("laser_p1".to_string(), dev)],
                },
            },
        ],
    }
}

/// Bit patterns of every number of a set, in a fixed order: equal vectors mean a bit-exact
/// round trip (PartialEq alone would accept −0 for +0).
fn bits(set: &MeasurementSet) -> Vec<u64> {
    let mut b: Vec<u64> = Vec::new();
    for s in &set.sensors {
        b.extend(s.position.iter().chain(&s.direction).map(|x| x.to_bits()));
        b.extend(s.sigma.map(f64::to_bits));
    }
    for r in &set.runs {
        b.extend(r.start_time.map(f64::to_bits));
        b.extend(r.feed.map(f64::to_bits));
        if let Some(t) = r.data.t() {
            b.extend(t.iter().map(|x| x.to_bits()));
        }
        if let RunData::PointTable { target, .. } = &r.data {
            b.extend(target.iter().map(|x| x.to_bits()));
        }
        for (_, v) in r.data.columns() {
            b.extend(v.iter().map(|x| x.to_bits()));
        }
    }
    b
}

#[test]
fn measurement_set_round_trips_bit_exactly_for_both_csv_shapes() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("set");
    let set = sample_set(1);
    measurement::write(&set, &dir, UnitChoice::Si).unwrap();
    let back = measurement::read(&dir).unwrap();
    assert_eq!(back, set);
    assert_eq!(bits(&back), bits(&set));
    assert!(matches!(back.runs[0].data, RunData::TimeSeries { .. }));
    assert!(matches!(back.runs[1].data, RunData::PointTable { .. }));
    // The first CSV line is the header, SI: no unit suffixes.
    let head = std::fs::read_to_string(dir.join("cv_fast.csv")).unwrap();
    assert_eq!(head.lines().next().unwrap(), "t,x_cmd,laser_p1,acc_y");
    let head = std::fs::read_to_string(dir.join("iso.csv")).unwrap();
    assert_eq!(head.lines().next().unwrap(), "target,run,direction,t,laser_p1");
}

#[test]
fn metrology_units_are_written_in_headers_and_read_back_to_within_two_ulp() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("set");
    let mut set = sample_set(2);
    // 1.8e308 m would overflow in um: the writer refuses that (tested below); use 1e300.
    if let RunData::TimeSeries { columns, .. } = &mut set.runs[0].data {
        columns[1].1[2] = 1e300;
    }
    measurement::write(&set, &dir, UnitChoice::Metrology).unwrap();
    let head = std::fs::read_to_string(dir.join("cv_fast.csv")).unwrap();
    assert_eq!(head.lines().next().unwrap(), "t[s],x_cmd[mm],laser_p1[um],acc_y[m/s^2]");
    let back = measurement::read(&dir).unwrap();
    let mut worst = 0.0f64;
    for (a, b) in back.runs.iter().zip(&set.runs) {
        for ((_, va), (_, vb)) in a.data.columns().iter().zip(b.data.columns()) {
            for (x, y) in va.iter().zip(vb) {
                if *y != 0.0 && y.abs() > 1e-290 {
                    worst = worst.max((x / y - 1.0).abs());
                }
            }
        }
    }
    // Written as the shortest round-trip digits of v·1e6 (one rounding), read back and divided
    // by 1e6 (one rounding): at most 2 ulp = 4.4e-16 relative, away from the subnormal range.
    assert!(worst <= 2.0 * f64::EPSILON, "worst relative error {worst:e}");
    // 1.8e308 m overflows in um: refused, and nothing is written.
    let huge = tmp.path().join("huge");
    let e = measurement::write(&sample_set(2), &huge, UnitChoice::Metrology).unwrap_err();
    assert!(e.to_string().contains("column laser_p1[um], row 3: 1.7976931348623157e308 (SI) overflows"), "{e}");
    assert!(!huge.exists());
}

fn write_file(dir: &Path, name: &str, text: &str) -> PathBuf {
    std::fs::create_dir_all(dir).unwrap();
    let p = dir.join(name);
    std::fs::write(&p, text).unwrap();
    p
}

const MANIFEST: &str = r#"format = "vmt-measurements/1"
[[sensors]]
name = "x_cmd"
kind = "command"
axis = "x"
[[sensors]]
name = "laser_p1"
kind = "laser_linear"
axis = "x"
position = [0.0, 0.25, 1.10]
direction = [1.0, 0.0, 0.0]
sigma = 5e-9
[[sensors]]
name = "acc_z"
kind = "accelerometer"
axis = "x"
[[sensors]]
name = "temp"
kind = "temperature"
axis = "x"
[[sensors]]
name = "roll_l"
kind = "laser_angular"
axis = "x"
[[runs]]
name = "cv"
file = "cv.csv"
procedure = "constant_velocity"
axis = "x"
feed = 0.05
"#;

#[test]
fn headers_in_mm_um_ms_g_degc_urad_read_the_same_numbers_as_si() {
    let tmp = tempfile::tempdir().unwrap();
    let si = tmp.path().join("si");
    let un = tmp.path().join("units");
    write_file(&si, "manifest.toml", MANIFEST);
    write_file(&un, "manifest.toml", MANIFEST);
    write_file(
        &si,
        "cv.csv",
        "# SI reference\nt,x_cmd,laser_p1,acc_z,temp,roll_l\n\
         0.0,0.0123456789,1.234e-6,9.80665,293.15,1.7e-5\n\
         0.00083,0.0251,-3.21e-7,-0.0490332500,293.65,-2.3e-6\n\
         0.00167,0.98765,0.0,19.6133,294.0,0.0\n",
    );
    write_file(
        &un,
        "cv.csv",
        "t[ms],x_cmd[mm],laser_p1[um],acc_z[g],temp[degC],roll_l[urad]\n\
         0,12.3456789,1.234,1,20,17\n\
         0.83,25.1,-0.321,-0.005,20.5,-2.3\n\
         1.67,987.65,0,2,20.85,0\n",
    );
    let a = measurement::read(&si).unwrap();
    let b = measurement::read(&un).unwrap();
    let (RunData::TimeSeries { t: ta, columns: ca }, RunData::TimeSeries { t: tb, columns: cb }) =
        (&a.runs[0].data, &b.runs[0].data)
    else {
        panic!("expected time series");
    };
    let close = |x: f64, y: f64, what: &str| {
        // Both are correctly rounded parses, plus one exact-factor division (or one product
        // by 9.80665 for g): at most 2 ulp apart, i.e. ≤ 4.4e-16 relative (brief: 1e-15).
        assert!((x - y).abs() <= 2.0 * f64::EPSILON * y.abs(), "{what}: {x:e} vs {y:e}");
    };
    for (x, y) in ta.iter().zip(tb) {
        close(*y, *x, "t");
    }
    for ((na, va), (nb, vb)) in ca.iter().zip(cb) {
        assert_eq!(na, nb);
        for (x, y) in va.iter().zip(vb) {
            if na == "temp" {
                // degC → K adds 273.15: exact to the ulp of ~293 K (5.7e-14), not relative.
                assert!((x - y).abs() <= 5.7e-14, "temp: {x} vs {y}");
            } else {
                close(*y, *x, na);
            }
        }
    }
}

/// Writes a set directory with `manifest` and one CSV `cv.csv`, reads it, returns the error.
fn read_err(manifest: &str, csv: &str) -> (String, VmtError) {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("set");
    write_file(&dir, "manifest.toml", manifest);
    write_file(&dir, "cv.csv", csv);
    let e = measurement::read(&dir).expect_err("bad input must be rejected");
    assert_eq!(e.exit_code(), 2, "bad input exits with 2: {e}");
    (e.to_string(), e)
}

const GOOD_CSV: &str = "t,x_cmd,laser_p1\n0,0,0\n0.001,1e-5,1e-9\n";

#[test]
fn malformed_toml_names_the_manifest_line_and_column() {
    let bad = MANIFEST.replace("feed = 0.05", "feed = 0.05.1");
    let (m, _) = read_err(&bad, GOOD_CSV);
    assert!(m.contains("manifest.toml: line 30, column"), "{m}");
    assert!(m.contains("malformed TOML"), "{m}");
}

#[test]
fn unknown_manifest_key_names_its_key_path() {
    let bad = MANIFEST.replace("sigma = 5e-9", "sigma = 5e-9\ngain = 2.0");
    let (m, _) = read_err(&bad, GOOD_CSV);
    assert!(m.contains("manifest.toml: sensors[1].gain: unknown key `gain`"), "{m}");
}

#[test]
fn out_of_range_manifest_value_names_its_key_path() {
    let bad = MANIFEST.replace("sigma = 5e-9", "sigma = -5e-9");
    let (m, _) = read_err(&bad, GOOD_CSV);
    assert!(m.contains("manifest.toml: sensors[1].sigma: expected"), "{m}");
    assert!(m.contains("≥ 0, got -5e-9"), "{m}");
    let bad = MANIFEST.replace("kind = \"command\"", "kind = \"laser\"");
    let (m, _) = read_err(&bad, GOOD_CSV);
    assert!(m.contains("sensors[0].kind: unknown sensor kind \"laser\"; expected one of command"), "{m}");
}

#[test]
fn csv_missing_t_column_is_named() {
    let (m, _) = read_err(MANIFEST, "x_cmd,laser_p1\n0,0\n1e-5,1e-9\n");
    assert!(m.contains("cv.csv: line 1 (header): missing column `t`"), "{m}");
}

#[test]
fn point_table_missing_direction_column_is_named() {
    let (m, _) = read_err(MANIFEST, "target,run,laser_p1\n0,1,0\n0.1,1,1e-9\n");
    assert!(m.contains("cv.csv: line 1 (header): missing column `direction`"), "{m}");
}

#[test]
fn nan_names_line_and_column() {
    // Comment lines count: the NaN is on line 4 of the file.
    let (m, _) = read_err(MANIFEST, "# written by a DAQ\nt,x_cmd,laser_p1\n0,0,0\n0.001,1e-5,NaN\n");
    assert!(m.contains("cv.csv: line 4, column laser_p1: expected a finite number, got `NaN`"), "{m}");
}

#[test]
fn non_monotonic_t_names_the_line() {
    let (m, _) = read_err(MANIFEST, "t,x_cmd\n0,0\n0.002,1e-5\n0.001,2e-5\n0.003,3e-5\n");
    assert!(m.contains("cv.csv: line 4, column t: `t` must increase strictly, got 0.001 after 0.002"), "{m}");
}

#[test]
fn unknown_unit_names_column_unit_and_expected_dimension() {
    let (m, _) = read_err(MANIFEST, "t,laser_p1[furlong]\n0,0\n0.001,1\n");
    assert!(m.contains("cv.csv: column laser_p1: unknown unit `furlong`: expected a length (m, mm, um, nm"), "{m}");
}

#[test]
fn unit_of_the_wrong_dimension_names_column_and_expected_dimension() {
    let (m, _) = read_err(MANIFEST, "t,laser_p1[deg]\n0,0\n0.001,1\n");
    assert!(m.contains("cv.csv: column laser_p1: unit `deg` is an angle"), "{m}");
    assert!(m.contains("expected a length"), "{m}");
    let (m, _) = read_err(MANIFEST, "t[mm],x_cmd\n0,0\n1,1\n");
    assert!(m.contains("column t: unit `mm` is a length"), "{m}");
    assert!(m.contains("expected a time"), "{m}");
}

#[test]
fn unknown_column_bad_run_number_and_bad_direction_are_named() {
    let (m, _) = read_err(MANIFEST, "t,laser_p9\n0,0\n0.001,1\n");
    assert!(m.contains("cv.csv: column laser_p9: unknown column `laser_p9`: expected a sensor"), "{m}");
    let (m, _) = read_err(MANIFEST, "target,run,direction,laser_p1\n0,1,1,0\n0.1,0,1,0\n");
    assert!(m.contains("cv.csv: line 3, column run: expected a run number 1, 2, 3, ..., got 0"), "{m}");
    let (m, _) = read_err(MANIFEST, "target,run,direction,laser_p1\n0,1,2,0\n");
    assert!(m.contains("cv.csv: line 2, column direction: expected +1 or -1, got 2"), "{m}");
    let (m, _) = read_err(MANIFEST, "t,x_cmd\n0,0\n0.001\n");
    assert!(m.contains("cv.csv: line 3: expected 2 cells like the header, got 1"), "{m}");
}

#[test]
fn a_run_may_carry_only_some_of_the_sensors() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("set");
    write_file(&dir, "manifest.toml", MANIFEST);
    // With a byte-order mark and CRLF line ends, as spreadsheets export.
    write_file(&dir, "cv.csv", "\u{feff}t,acc_z\r\n0,0.1\r\n0.001,0.2\r\n");
    let set = measurement::read(&dir).unwrap();
    assert_eq!(set.runs[0].data.column("acc_z"), Some(&[0.1, 0.2][..]));
    assert_eq!(set.runs[0].data.column("laser_p1"), None);
}

#[test]
fn writing_replaces_a_previous_set_atomically_but_never_a_foreign_directory() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("set");
    measurement::write(&sample_set(3), &dir, UnitChoice::Si).unwrap();
    let second = sample_set(4);
    measurement::write_with_extras(
        &second,
        &dir,
        UnitChoice::Si,
        &[("truth.toml".to_string(), b"format = \"vmt-model/1\"\n".to_vec())],
    )
    .unwrap();
    assert_eq!(measurement::read(&dir).unwrap(), second);
    assert!(dir.join("truth.toml").is_file());
    // No temporary or old directories are left beside it.
    let names: Vec<String> =
        std::fs::read_dir(tmp.path()).unwrap().map(|e| e.unwrap().file_name().to_string_lossy().into_owned()).collect();
    assert_eq!(names, vec!["set".to_string()]);
    // A directory that is not a measurement set is not replaced.
    let foreign = tmp.path().join("photos");
    write_file(&foreign, "holiday.jpg", "not a set");
    let e = measurement::write(&second, &foreign, UnitChoice::Si).unwrap_err();
    assert!(e.to_string().contains("refusing to replace"), "{e}");
    assert!(foreign.join("holiday.jpg").is_file());
    // An invalid set is not written at all.
    let mut bad = second.clone();
    if let RunData::TimeSeries { t, .. } = &mut bad.runs[0].data {
        t[5] = f64::NAN;
    }
    let out = tmp.path().join("never");
    let e = measurement::write(&bad, &out, UnitChoice::Si).unwrap_err();
    assert!(e.to_string().contains("runs[0] (cv_fast): column t, row 6"), "{e}");
    assert!(!out.exists());
}

// ------------------------------------------------------------------------------------------
// Profiles (§5).

#[test]
fn profile_csv_round_trips_with_axis_prefix_sigma_and_units() {
    let tmp = tempfile::tempdir().unwrap();
    let mut rng = ChaCha8Rng::seed_from_u64(5);
    let position: Vec<f64> = (0..41).map(|i| i as f64 * 0.025).collect();
    let mut col = |axis: Option<Axis>, effect: EffectName, scale: f64, sigma: bool| ProfileColumn {
        axis,
        effect,
        values: (0..41).map(|_| scale * rng.gen_range(-1.0..1.0)).collect(),
        sigma: sigma.then(|| (0..41).map(|_| scale * rng.gen_range(0.0..0.1)).collect()),
    };
    let table = ProfileTable {
        position: position.clone(),
        columns: vec![
            col(None, EffectName::Positioning, 1e-5, true),
            col(None, EffectName::StraightnessY, 3e-6, false),
            col(Some(Axis::Y), EffectName::Pitch, 2e-5, true),
        ],
    };
    let p = tmp.path().join("truth_profiles.csv");
    measurement::write_profiles(&table, &p, UnitChoice::Si).unwrap();
    let head = std::fs::read_to_string(&p).unwrap();
    assert_eq!(
        head.lines().next().unwrap(),
        "position,positioning,positioning_sigma,straightness_y,y.pitch,y.pitch_sigma"
    );
    assert_eq!(measurement::read_profiles(&p).unwrap(), table);
    let q = tmp.path().join("estimate.csv");
    measurement::write_profiles(&table, &q, UnitChoice::Metrology).unwrap();
    let head = std::fs::read_to_string(&q).unwrap();
    assert!(head.starts_with("position[mm],positioning[um],positioning_sigma[um],"));
    assert!(head.contains("y.pitch[urad]"));
    let back = measurement::read_profiles(&q).unwrap();
    let c = back.get(EffectName::Pitch, Axis::Y).unwrap();
    // urad: ×1e6 when writing, ÷1e6 when reading: ≤ 2 ulp.
    for (a, b) in c.values.iter().zip(&table.columns[2].values) {
        assert!((a - b).abs() <= 2.0 * f64::EPSILON * b.abs());
    }
    // Bad profile column.
    let r = write_file(tmp.path(), "bad.csv", "position,backlash\n0,0\n1,1\n");
    let e = measurement::read_profiles(&r).unwrap_err().to_string();
    assert!(e.contains("bad.csv: column backlash: unknown column `backlash`"), "{e}");
    let r = write_file(tmp.path(), "bad2.csv", "position,pitch[mm]\n0,0\n1,1\n");
    let e = measurement::read_profiles(&r).unwrap_err().to_string();
    assert!(e.contains("column pitch: unit `mm` is a length"), "{e}");
}

// ------------------------------------------------------------------------------------------
// Models (§2).

fn scalar(name: EffectName, params: EffectParams) -> ModelEffect {
    ModelEffect::new(Effect { name, axis: Axis::X, params }, false)
}

/// A model holding every effect of the catalogue with non-default values, error motions with
/// every profile shape, fitted effects with and without starting values, and an effect on a
/// second axis.
fn every_effect_model() -> Model {
    let mut effects: Vec<ModelEffect> = Vec::new();
    let table = Term::Table { x: vec![0.0, 0.3, 0.7, 1.0], y: vec![0.0, 1.1e-6, -0.4e-6, 0.2e-6] };
    for (i, name) in EffectName::ERROR_MOTIONS.iter().enumerate() {
        let k = if name.is_translational() { 1e-6 } else { 1e-5 };
        let profile = Profile {
            terms: vec![
                Term::Poly(vec![0.1 * k, 2.8 * k, -2.4 * k]),
                Term::Harmonics(vec![
                    Harmonic { amplitude: 2.5 * k, wavelength: 0.32, phase: 0.7 },
                    Harmonic { amplitude: 0.3 * k, wavelength: 0.08, phase: 0.4 },
                ]),
                Term::random(RandomProfile { rms: 0.5 * k, correlation_length: 0.05, seed: 7 + i as u64 }),
                table.clone(),
            ],
        };
        effects.push(ModelEffect::new(Effect::error_motion(*name, Axis::X, profile), false));
    }
    // A fitted error motion with a basis, no profile given.
    let mut pitch_y = ModelEffect::new(Effect::error_motion(EffectName::Pitch, Axis::Y, Profile::zero()), true);
    pitch_y.basis = Some(Basis::Bspline);
    pitch_y.order = Some(8);
    effects.push(pitch_y);
    for name in [EffectName::SquarenessXy, EffectName::SquarenessXz, EffectName::SquarenessYz] {
        effects.push(scalar(name, EffectParams::Squareness(Squareness { value: -12e-6 })));
    }
    effects.push(scalar(EffectName::Backlash, EffectParams::Backlash(Backlash { value: 4e-6 })));
    effects.push(scalar(
        EffectName::CyclicLead,
        EffectParams::CyclicLead(CyclicLead {
            period: 0.010,
            amplitude: 1.5e-6,
            phase: 0.3,
            harmonics: vec![LeadHarmonic { order: 2, amplitude: 0.4e-6, phase: 1.1 }],
        }),
    ));
    effects.push(scalar(EffectName::ScaleError, EffectParams::ScaleError(ScaleError { value: 22e-6 })));
    effects.push(scalar(
        EffectName::ThermalExpansion,
        EffectParams::ThermalExpansion(ThermalExpansion { alpha: 11.5e-6, delta_t: 2.5, tau: 1800.0 }),
    ));
    effects
        .push(scalar(EffectName::ThermalDrift, EffectParams::ThermalDrift(ThermalDrift { value: 3e-6, tau: 900.0 })));
    effects.push(scalar(
        EffectName::InterpolationError,
        EffectParams::InterpolationError(InterpolationError { period: 20e-6, amplitude: 5e-8, phase: 0.0 }),
    ));
    effects.push(scalar(EffectName::Coulomb, EffectParams::Coulomb(Coulomb { fc: 1.0 })));
    effects.push(scalar(EffectName::Viscous, EffectParams::Viscous(Viscous { fv: 0.4 })));
    effects.push(scalar(
        EffectName::Stribeck,
        EffectParams::Stribeck(Stribeck { fc: None, fs: 1.5, vs: 1e-3, shape: 2.0 }),
    ));
    effects.push(scalar(
        EffectName::Lugre,
        EffectParams::Lugre(Lugre {
            sigma0: 1e5,
            sigma1: 1e5f64.sqrt(),
            sigma2: 0.4,
            fc: 1.0,
            fs: 1.5,
            vs: 1e-3,
            shape: 2.0,
        }),
    ));
    effects.push(scalar(
        EffectName::ServoLag,
        EffectParams::ServoLag(ServoLag { kv: 2000.0, kp: Some(50.0), ki: Some(4e5) }),
    ));
    // A fitted effect with only one starting value given: the other stays a default.
    let mut res = ModelEffect::new(
        Effect {
            name: EffectName::Resonance,
            axis: Axis::X,
            params: EffectParams::Resonance(Resonance { frequency: 180.0, damping: 0.02 }),
        },
        true,
    );
    res.given = vec!["frequency".to_string()];
    effects.push(res);
    effects.push(ModelEffect::new(
        Effect { name: EffectName::GravityTilt, axis: Axis::X, params: EffectParams::GravityTilt },
        false,
    ));
    effects.push(scalar(EffectName::AccelBiasDrift, EffectParams::AccelBiasDrift(AccelBiasDrift { rate: 1e-5 })));
    // Backlash on a second axis: written as [[effects.backlash]].
    let mut bl_y = scalar(EffectName::Backlash, EffectParams::Backlash(Backlash { value: 2e-6 }));
    bl_y.effect.axis = Axis::Y;
    effects.push(bl_y);
    // Every catalogue effect not written out above (one added later) round-trips too, from its starting
    // values with each scalar moved off its default (×1.5, or 1e-6 where the default is 0: inside
    // every parameter's range and physical bounds).
    for name in EffectName::ALL {
        if !effects.iter().any(|e| e.effect.name == name) {
            let mut params = EffectParams::default_for(name);
            for s in vmt_sim::effects::param_specs(name) {
                params.set(s.key, if s.default != 0.0 { 1.5 * s.default } else { 1e-6 });
            }
            effects.push(scalar(name, params));
        }
    }
    let mut m = Model { machine: Some("slide_column".to_string()), axis: Axis::X, effects, source: PathBuf::new() };
    m.sort();
    m
}

#[test]
fn a_model_with_every_effect_round_trips() {
    let tmp = tempfile::tempdir().unwrap();
    let path = tmp.path().join("model.toml");
    // Every catalogue effect is in the model by construction (`every_effect_model` adds any not written
    // out by hand), and each one is compared after the round trip below.
    let m = every_effect_model();
    let written = model::write_model(&m, &path).unwrap();
    // Six table sidecars (one per error motion of x) and the model.
    assert_eq!(written.len(), 7, "{written:?}");
    let mut back = model::read_model(&path).unwrap();
    assert_eq!(back.source, path);
    back.source = PathBuf::new();
    assert_eq!(back.effects.len(), m.effects.len());
    for (a, b) in back.effects.iter().zip(&m.effects) {
        assert_eq!(a, b, "{} on {}", b.effect.name, b.effect.axis);
    }
    assert_eq!(back, m);
    // Writing what was read gives the same text (the format is stable).
    let path2 = tmp.path().join("again").join("model.toml");
    model::write_model(&back, &path2).unwrap();
    assert_eq!(std::fs::read_to_string(&path).unwrap(), std::fs::read_to_string(&path2).unwrap());
    // The fitted resonance is written with its given key only.
    let text = std::fs::read_to_string(&path).unwrap();
    let res = &text[text.find("[effects.resonance]").unwrap()..];
    let res = &res[..res.find("\n\n").unwrap_or(res.len())];
    assert!(res.contains("frequency = 180.0") && !res.contains("damping"), "{res}");
}

#[test]
fn format_md_example_model_reads() {
    let tmp = tempfile::tempdir().unwrap();
    let p = write_file(
        tmp.path(),
        "model.toml",
        r#"format = "vmt-model/1"
machine = "slide_column"           # bundled name or URDF path relative to this file
axis = "x"                         # default axis for effects below

[effects.positioning]              # EXX
fit = true
[effects.pitch]                    # EBX
fit = true
[effects.backlash]
value = 4e-6                       # m
[effects.cyclic_lead]
period = 0.010                     # m (screw lead)
amplitude = 1.5e-6                 # m
phase = 0.0                        # rad
"#,
    );
    let m = model::read_model(&p).unwrap();
    assert_eq!(m.effects.len(), 4);
    let pos = m.get(EffectName::Positioning, Axis::X).unwrap();
    assert!(pos.fit && pos.given.is_empty());
    let bl = m.get(EffectName::Backlash, Axis::X).unwrap();
    assert_eq!(bl.effect.params.get("value"), Some(4e-6));
    assert!(!bl.fit);
    let set = m.effect_set();
    assert!(set.validate().is_empty());
}

#[test]
fn unknown_effect_name_is_an_error_listing_the_known_effects() {
    let tmp = tempfile::tempdir().unwrap();
    let p =
        write_file(tmp.path(), "model.toml", "format = \"vmt-model/1\"\naxis = \"x\"\n[effects.foo]\nvalue = 1.0\n");
    let e = model::read_model(&p).unwrap_err();
    let m = e.to_string();
    assert_eq!(e.exit_code(), 2);
    assert!(m.contains("model.toml: effects.foo: unknown effect `foo`"), "{m}");
    assert!(m.contains("known effects: positioning, straightness_y"), "{m}");
}

#[test]
fn model_value_out_of_range_unknown_key_and_missing_key_are_named() {
    let tmp = tempfile::tempdir().unwrap();
    let read = |text: &str| {
        let p = write_file(tmp.path(), "model.toml", text);
        model::read_model(&p).unwrap_err().to_string()
    };
    let head = "format = \"vmt-model/1\"\naxis = \"x\"\n";
    let m = read(&format!("{head}[effects.backlash]\nvalue = -4e-6\n"));
    assert!(m.ends_with("model.toml: effects.backlash.value: expected a length in metres ≥ 0, got -4e-6"), "{m}");
    let m = read(&format!("{head}[effects.resonance]\nfrequency = 100.0\ndamping = 1.0\n"));
    assert!(m.contains("effects.resonance.damping: expected a damping ratio in [0, 1), got 1"), "{m}");
    let m = read(&format!("{head}[effects.backlash]\nvalu = 4e-6\n"));
    assert!(m.contains("model.toml: effects.backlash.value: missing key"), "{m}");
    let m = read(&format!("{head}[effects.backlash]\nvalue = 4e-6\nvalu = 4e-6\n"));
    assert!(m.contains("model.toml: effects.backlash.valu: unknown key `valu`"), "{m}");
    let m = read(&format!("{head}[effects.pitch]\nharmonics = [{{ amplitude = 1e-6, wavelength = 0.0 }}]\n"));
    assert!(
        m.contains(
            "effects.pitch.harmonics[0].wavelength: expected a wavelength in metres between 1e-9 and 100, got 0"
        ),
        "{m}"
    );
    let m = read(&format!("{head}[effects.pitch]\n"));
    assert!(m.contains("effects.pitch: expected a profile"), "{m}");
    let m = read(&format!("{head}[effects.pitch]\npoly = [0.0]\nbasis = \"bspline\"\n"));
    assert!(m.contains("effects.pitch.basis: `basis` only applies to a fitted"), "{m}");
    let m = read("format = \"vmt-model/2\"\n");
    assert!(m.contains("model.toml: format: expected \"vmt-model/1\""), "{m}");
    let m = read(&format!("{head}[effects.pitch]\ntable = \"missing.csv\"\n"));
    assert!(m.contains("missing.csv: no such file"), "{m}");
}

#[test]
fn inline_truth_of_a_scenario_parses_with_the_key_path_prefix_and_tables_relative_to_it() {
    let tmp = tempfile::tempdir().unwrap();
    write_file(
        tmp.path(),
        "eyx.csv",
        "# straightness from a laser, um\nposition[mm],value[um]\n0,0\n500,1.5\n1000,-0.5\n",
    );
    let text = r#"format = "vmt-scenario/1"
[truth]
machine = "slide_column"
axis = "x"
[truth.effects.positioning]
poly = [0.0, 2.8e-5, -2.4e-5]
harmonics = [{ amplitude = 2.5e-6, wavelength = 0.32, phase = 0.7 }]
[truth.effects.straightness_y]
table = "eyx.csv"
[truth.effects.backlash]
value = 4e-6
"#;
    let file = tmp.path().join("scenario.toml");
    let table = vmt::error::parse_toml(&file, text).unwrap();
    let truth = table["truth"].as_table().unwrap();
    let m = model::parse_model(truth, &file, tmp.path(), "truth").unwrap();
    let eyx = m.effect_set().error_motion(EffectName::StraightnessY, Axis::X).unwrap().clone();
    // 1.5 um at 0.5 m, linear in between: 0.75 um at 0.25 m (to rounding of the unit division).
    assert!((eyx.value(0.25) - 0.75e-6).abs() < 1e-21);
    assert!((eyx.value(1.0) + 0.5e-6).abs() < 1e-21);
    let exx = m.effect_set().error_motion(EffectName::Positioning, Axis::X).unwrap().clone();
    let want = 2.8e-5 * 0.5 - 2.4e-5 * 0.25 + 2.5e-6 * (std::f64::consts::TAU * 0.5 / 0.32 + 0.7).sin();
    assert!((exx.value(0.5) - want).abs() < 1e-18);
    let bad = text.replace("value = 4e-6", "value = -4e-6");
    let table = vmt::error::parse_toml(&file, &bad).unwrap();
    let e = model::parse_model(table["truth"].as_table().unwrap(), &file, tmp.path(), "truth").unwrap_err();
    assert!(
        e.to_string()
            .ends_with("scenario.toml: truth.effects.backlash.value: expected a length in metres ≥ 0, got -4e-6"),
        "{e}"
    );
}

/// Issue 13: a converted value is written with the fewest digits that read back to within one ulp of
/// its SI value. A 0.001 µm-resolution reading stored as −5.372e-6 m has no µm decimal whose division by
/// 10⁶ is that very double; demanding equality wrote −5.372000000000001 (a quarter of the default
/// scenario's laser cells under `--units human`). Positions keep their exact short forms.
#[test]
fn human_units_write_readings_without_conversion_noise() {
    use vmt::measurement::fmt_in_unit;
    let unit = |s: &str| vmt::units::unit(s).unwrap();
    for (si, symbol, text) in [
        (-5.372e-6, "um", "-5.372"),
        (-3.463e-6, "um", "-3.463"),
        (0.33595, "mm", "335.95"),
        (1e-7, "um", "0.1"),
        (2e-7, "urad", "0.2"),
        (0.116794, "mm", "116.794"),
        (1.5, "m", "1.5"),
    ] {
        let u = unit(symbol);
        assert_eq!(fmt_in_unit(&u, si), text, "{si:e} m in {symbol}");
        let back = u.to_si(text.parse().unwrap());
        let ulp = si.abs().next_up() - si.abs();
        assert!((back - si).abs() <= ulp, "{text} {symbol} reads back as {back:e}, not within 1 ulp of {si:e}");
    }
    // A value with no short form keeps its digits (17 at most) and still reads back within one ulp.
    let x = std::f64::consts::PI * 1e-6;
    let t = fmt_in_unit(&unit("um"), x);
    assert!((unit("um").to_si(t.parse().unwrap()) - x).abs() <= x.next_up() - x, "{t}");
    assert!(t.starts_with("3.14159265358979"), "{t}");
}
