//! Whole workflows (issue 7): the `run` of the default scenario (simulation, estimators, report), one
//! trial of the accelerometer tolerance study (sensor noise redrawn and the estimator run on traces
//! simulated once), and one trial of a study of the default scenario, whose compensation check re-tests
//! each trial's table: simulated (as `vmt run` does; what a study trial cost before issue 12) and derived
//! from the re-test simulated once without compensation (what a study trial does now).
use criterion::{criterion_group, criterion_main, Criterion};
use vmt::scenario::Scenario;
use vmt::simulate::Retest;

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
            vmt::workflow::run::estimate_session(&study, &ph, &truths, &set, Retest::Simulated).unwrap()
        })
    });
    let ph = vmt::simulate::physics(&sc).unwrap();
    let truths = vmt::simulate::simulate_truth(&sc, &ph);
    let retests = vmt::simulate::uncompensated_retests(&sc, &ph, truths.end).unwrap();
    let clean = vmt::simulate::clean_all(&sc, &ph, &truths).unwrap();
    for (name, retest) in [("simulated", Retest::Simulated), ("derived", Retest::Derived(&retests))] {
        let mut seed = 0u64;
        g.bench_function(format!("one default-scenario study trial, compensation re-test {name}"), |b| {
            b.iter(|| {
                seed += 1;
                // As `vmt::study::run_study` does per trial: noise redrawn on the readings computed once.
                let runs = vmt::simulate::read_all_clean(&sc, &ph, &truths, seed, &clean).unwrap();
                let set = vmt::simulate::to_measurement_set(&sc, &runs).unwrap();
                vmt::workflow::run::estimate_session(&sc, &ph, &truths, &set, retest).unwrap()
            })
        });
    }
    g.finish();
}

criterion_group!(benches, workflows);
criterion_main!(benches);
