//! Seed 002 (crawl monitoring from the built-in encoder): the preset `presets::crawl_seed002` makes the
//! slide_column X axis crawl from physics (Stribeck guideway friction destabilising the ball-screw axial
//! mode), and the stick-slip index SSI = (s_max − s_min)/s_mean of the differentiated 2 kHz scale
//! reading, s(n) = (x(n) − x(n−1))/Δt over 1 s, follows the seed's table:
//!
//! | feed       | seed 002 | simulated (this preset) |
//! |------------|----------|-------------------------|
//! | 5 mm/min   | 2.51     | 2.22                    |
//! | 20 mm/min  | 1.07     | 1.17                    |
//! | 80 mm/min  | 0.15     | 0.007                   |
//!
//! and the same axis with Coulomb + viscous friction (Fs = Fc) does not crawl.

use vmt_sim::axis_sim::{AxisTruth, GuideFriction};
use vmt_sim::machine::AxisModel;
use vmt_sim::presets::{crawl_seed002, CrawlPreset, SEED002_SCALE_RESOLUTION};
use vmt_sim::procedures::{read_run, simulate_procedure, ProcedureSpec, RunData};
use vmt_sim::urdf::parse_urdf;

const MM_PER_MIN: f64 = 1.0 / 60_000.0;
const RATE: f64 = 2000.0;

fn model(p: &CrawlPreset) -> AxisModel {
    let text = std::fs::read_to_string(concat!(env!("CARGO_MANIFEST_DIR"), "/../urdf/slide_column.urdf")).unwrap();
    AxisModel::build(&parse_urdf(&text).unwrap(), &p.axis).unwrap()
}

/// SSI of seed 002 from positions sampled at `RATE`: s(n) = (x(n) − x(n−1))·RATE, (max − min)/mean.
fn ssi(x: &[f64]) -> f64 {
    let s: Vec<f64> = x.windows(2).map(|w| (w[1] - w[0]) * RATE).collect();
    let mean = s.iter().sum::<f64>() / s.len() as f64;
    let max = s.iter().cloned().fold(f64::MIN, f64::max);
    let min = s.iter().cloned().fold(f64::MAX, f64::min);
    (max - min) / mean
}

/// SSI at each feed (mm/min) of the crawl procedure with the procedure's defaults (1 s at 2 kHz after
/// 2 s of settling).
fn crawl_ssi(p: &CrawlPreset, truth: &AxisTruth, feeds_mm_min: &[f64]) -> Vec<f64> {
    let m = model(p);
    let spec = ProcedureSpec::Crawl {
        name: "crawl".into(),
        feeds: feeds_mm_min.iter().map(|f| f * MM_PER_MIN).collect(),
        start: 0.5,
        duration: 1.0,
        rate: RATE,
        settle: 2.0,
        direction: 1,
        sensors: vec![p.scale.name.clone()],
    };
    simulate_procedure(&m, truth, &spec, 2)
        .iter()
        .map(|run| {
            let rec = read_run(&m, &p.truth, run, std::slice::from_ref(&p.scale), 2).unwrap();
            let RunData::TimeSeries { t, columns } = rec.data else { panic!("crawl runs are time series") };
            assert_eq!(t.len(), 2000, "1 s at 2 kHz");
            let x = &columns.iter().find(|(n, _)| n == &p.scale.name).unwrap().1;
            ssi(x)
        })
        .collect()
}

#[test]
fn preset_reproduces_the_seed002_stick_slip_trend() {
    let p = crawl_seed002();
    let s = crawl_ssi(&p, &p.truth, &[5.0, 20.0, 80.0]);
    println!("SSI at 5/20/80 mm/min: {:.3} / {:.3} / {:.3}", s[0], s[1], s[2]);
    // Quantisation floor 2q/(Δt·v) of the seed's 4.88 nm scale: 0.23 at 5 mm/min, so the values below
    // come from the motion, not from counting (also checked by the Coulomb test).
    let floor5 = 2.0 * SEED002_SCALE_RESOLUTION * RATE / (5.0 * MM_PER_MIN);
    assert!((floor5 - 0.234).abs() < 1e-3);
    // Seed 002 reports one measurement per feed of one machine (2.51, 1.07, 0.15), no repeatability;
    // the issue fixes the band as about ±25 % of the reported value (±0.6 of 2.51): a preset for a
    // different machine can match the trend, not the exact digits.
    assert!((s[0] - 2.5).abs() <= 0.6, "SSI at 5 mm/min = {:.3}, seed 002: 2.51 (band 2.5 ± 0.6)", s[0]);
    // ±0.3 of 1.07 (about ±25 %, as above); the band also keeps it on the seed's side of the patent's
    // "crawl" criterion SSI ≥ 1 only loosely (0.8…1.4), since 1.07 is at that criterion.
    assert!((s[1] - 1.1).abs() <= 0.3, "SSI at 20 mm/min = {:.3}, seed 002: 1.07 (band 1.1 ± 0.3)", s[1]);
    // 80 mm/min: the seed's 0.15 is "no crawl" (SSI < 1); the bound 0.3 is twice the reported value and
    // well below the criterion.
    assert!(s[2] < 0.3, "SSI at 80 mm/min = {:.3}, seed 002: 0.15 (bound 0.3)", s[2]);
    // The trend itself: crawl weakens monotonically with feed.
    assert!(s[0] > s[1] && s[1] > s[2]);
}

#[test]
fn coulomb_plus_viscous_friction_does_not_crawl() {
    let p = crawl_seed002();
    let GuideFriction::Stribeck(mut f) = p.truth.friction.clone() else { panic!("preset uses Stribeck") };
    f.fs = f.fc; // Coulomb + viscous: same Fc and Fv, no Stribeck drop, so no negative slope.
    let truth = AxisTruth { friction: GuideFriction::Stribeck(f), ..p.truth.clone() };
    let s = crawl_ssi(&p, &truth, &[5.0]);
    println!("SSI at 5 mm/min, Coulomb + viscous: {:.3}", s[0]);
    // The patent's criterion: SSI < 1 means no crawl. Without the Stribeck drop the only ripple left is
    // the scale's counting (floor 0.23), so the value must fall below 1.
    assert!(s[0] < 1.0, "SSI at 5 mm/min with Coulomb + viscous friction = {:.3}, expected < 1", s[0]);
}
