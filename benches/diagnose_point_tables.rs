//! `vmt diagnose` on the data sets issue 11 names (it asks < 1 s each): a 21-target, 5-cycle ISO
//! 230-2 point table (one laser, 210 readings) whose model lacks a backlash, and a 30-run friction
//! sweep (15 feeds × 2 directions) whose model lacks the Stribeck term. The data are made here by
//! the tests' independent generator (`tests/gen/mod.rs`: not vmt's simulator, defaults or basis):
//! the first draw index of each family with that shape, written to a temporary directory once;
//! the timed part is `modelcheck::diagnose` on the loaded model and measurement set (all
//! candidates, their hyper-parameter searches and the null calibration), not the file reading.
//!
//! `cargo bench --bench diagnose_point_tables`
use criterion::{criterion_group, criterion_main, Criterion};

#[path = "../tests/gen/mod.rs"]
mod gen;

use gen::{draw, Draw, Effect, Family};

/// The first draw of `family` (index 0, 1, …) that `fits`, searched over 10 000 indices.
fn first_draw(family: &Family, fits: impl Fn(&Draw) -> bool) -> Draw {
    (0..10_000)
        .map(|i| draw(family, i))
        .find(|d| fits(d))
        .unwrap_or_else(|| panic!("no draw of {} of the wanted shape", family.label()))
}

/// Time `diagnose` of draw `d`'s starting model (`start.toml`: the hidden effect missing).
fn bench_diagnose(g: &mut criterion::BenchmarkGroup<'_, criterion::measurement::WallTime>, name: &str, d: &Draw) {
    let tmp = tempfile::tempdir().unwrap();
    d.write(tmp.path()).unwrap();
    let data = tmp.path().join("data");
    let model = vmt::model::read_model(&tmp.path().join("start.toml")).unwrap();
    let set = vmt::measurement::read_data(&data).unwrap();
    eprintln!("{name}: {}", d.describe());
    g.bench_function(name, |b| b.iter(|| vmt::modelcheck::diagnose(&model, &set, &data).unwrap()));
}

/// Distinct targets of a point-table file of the generator (first CSV column).
fn targets(d: &Draw, file: &str) -> usize {
    let text = &d.data_files.iter().find(|f| f.0 == file).map_or("", |f| f.1.as_str());
    let mut t: Vec<&str> = text.lines().skip(1).filter_map(|l| l.split(',').next()).collect();
    t.sort_unstable();
    t.dedup();
    t.len()
}

fn diagnose_point_tables(c: &mut Criterion) {
    let mut g = c.benchmark_group("diagnose");
    g.sample_size(10);
    // 21 targets × 5 bidirectional cycles, one laser, one block (ISO 230-2's standard test).
    let table = first_draw(&Family::Hidden(vec![Effect::Backlash]), |d| {
        d.channel_counts.len() == 1 && d.channel_counts[0].1 == 210 && targets(d, "iso.csv") == 21
    });
    bench_diagnose(&mut g, "point table, 21 targets x 5 cycles, backlash missing", &table);
    // 15 feeds × 2 directions.
    let sweep = first_draw(&Family::Hidden(vec![Effect::Stribeck]), |d| d.channel_counts.len() == 30);
    bench_diagnose(&mut g, "friction sweep, 30 runs, stribeck missing", &sweep);
    g.finish();
}

criterion_group!(benches, diagnose_point_tables);
criterion_main!(benches);
