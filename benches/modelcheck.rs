//! `vmt diagnose` on time series (issue 19), on sets of about 15 000 and 100 000 samples written by
//! the tests' independent generator (`tests/gen_timeseries`):
//! - accelerometer passes (three speeds, smooth straightness with waviness, noise from piezo to
//!   MEMS; the sample rate set for the size), a starting model with fitted straightness in y and z
//!   (flexible shapes whose terms BIC chooses) — complete, and with a hidden structural mode;
//! - encoder logs of a ball-screw axis (two passes, two crawls, a slow reversal; scale and motor
//!   encoder), a starting model with fitted positioning and servo lag.
//!
//! Run with `cargo bench --bench modelcheck` (quick: `-- --warm-up-time 1 --measurement-time 5
//! --sample-size 10`).
use criterion::{criterion_group, criterion_main, Criterion};
use std::path::Path;

#[path = "../tests/gen_timeseries/mod.rs"]
mod gen_timeseries;
use gen_timeseries::{accel_set_sized, encoder_set_sized, AccelHidden, EncoderHidden};

fn diagnose(c: &mut Criterion) {
    let mut g = c.benchmark_group("diagnose");
    g.sample_size(10);
    let tmp = tempfile::tempdir().unwrap();
    let mut bench = |g: &mut criterion::BenchmarkGroup<_>, label: String, dir: &Path| {
        let model = vmt::model::read_model(&dir.join("model.toml")).unwrap();
        let set = vmt::measurement::read(dir).unwrap();
        g.bench_function(label, |b| b.iter(|| vmt::modelcheck::diagnose(&model, &set, dir).unwrap()));
    };
    for samples in [15_000usize, 100_000] {
        let dir = tmp.path().join(format!("acc{samples}"));
        let t = accel_set_sized(&dir, 11, AccelHidden::None, 0.0, Some(samples));
        bench(&mut g, format!("accelerometer passes, complete, {} samples", t.samples), &dir);
        let dir = tmp.path().join(format!("res{samples}"));
        let t = accel_set_sized(&dir, 12, AccelHidden::Resonance, 200.0, Some(samples));
        bench(&mut g, format!("accelerometer passes, hidden mode, {} samples", t.samples), &dir);
        let dir = tmp.path().join(format!("enc{samples}"));
        let t = encoder_set_sized(&dir, 13, EncoderHidden::None, Some(samples));
        bench(&mut g, format!("encoder logs, complete, {} samples", t.samples), &dir);
    }
    g.finish();
}

criterion_group!(benches, diagnose);
criterion_main!(benches);
