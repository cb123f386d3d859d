//! Whole workflows (issue 7): the `run` of the default scenario (simulation, estimators, report) and one
//! trial of the accelerometer tolerance study (sensor noise redrawn and the estimator run on traces
//! simulated once).
use criterion::{criterion_group, criterion_main, Criterion};
use vmt::scenario::Scenario;

fn workflows(c: &mut Criterion) {
    let mut g = c.benchmark_group("workflows");
    g.sample_size(10);
    let sc = Scenario::bundled_default().unwrap();
    g.bench_function("simulate + estimate the default scenario", |b| {
        b.iter(|| {
            let ph = vmt::simulate::physics(&sc).unwrap();
            let truths = vmt::simulate::simulate_truth(&sc, &ph);
            let runs = vmt::simulate::read_all(&sc, &ph, &truths, sc.seed).unwrap();
            vmt::workflow::run::run_estimators(&sc, &ph, &truths, &runs).unwrap()
        })
    });
    let study =
        Scenario::load(std::path::Path::new(concat!(env!("CARGO_MANIFEST_DIR"), "/scenarios/study_accel.toml")))
            .unwrap();
    let ph = vmt::simulate::physics(&study).unwrap();
    let truths = vmt::simulate::simulate_truth(&study, &ph);
    let mut seed = 0u64;
    g.bench_function("one accelerometer study trial (noise draw + estimate)", |b| {
        b.iter(|| {
            seed += 1;
            // As `vmt::study::run_study` does per trial: noise redrawn, the set written once, the estimators
            // run on it with the compensation check re-measuring after the session simulated once.
            let runs = vmt::simulate::read_all(&study, &ph, &truths, seed).unwrap();
            let set = vmt::simulate::to_measurement_set(&study, &runs).unwrap();
            vmt::workflow::run::estimate_session(&study, &ph, &truths, &set).unwrap()
        })
    });
    g.finish();
}

criterion_group!(benches, workflows);
criterion_main!(benches);
