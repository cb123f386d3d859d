//! `vmt diagnose` on accelerometer passes (issue 19): a starting model with fitted straightness in
//! y and z (flexible Legendre shapes whose order BIC chooses) and every candidate the model lacks,
//! on sets of about 15 000 and 100 000 samples written by the tests' independent generator
//! (`tests/gen_timeseries`, three passes at different speeds, smooth straightness with waviness,
//! noise from piezo to MEMS; the sample rate set for the size). Run with
//! `cargo bench --bench modelcheck`.
use criterion::{criterion_group, criterion_main, Criterion};

#[path = "../tests/gen_timeseries/mod.rs"]
mod gen_timeseries;

fn diagnose(c: &mut Criterion) {
    let mut g = c.benchmark_group("diagnose");
    g.sample_size(10);
    let tmp = tempfile::tempdir().unwrap();
    for samples in [15_000usize, 100_000] {
        let dir = tmp.path().join(format!("acc{samples}"));
        gen_timeseries::accel_set_sized(&dir, 11, gen_timeseries::AccelHidden::None, 0.0, Some(samples));
        let model = vmt::model::read_model(&dir.join("model.toml")).unwrap();
        let set = vmt::measurement::read(&dir).unwrap();
        g.bench_function(format!("accelerometer passes, {samples} samples"), |b| {
            b.iter(|| vmt::modelcheck::diagnose(&model, &set, &dir).unwrap())
        });
    }
    g.finish();
}

criterion_group!(benches, diagnose);
criterion_main!(benches);
