//! `vmt diagnose` on time series (issue 19), on sets of about 15 000 and 100 000 samples written by
//! the tests' independent generator (`tests/gen_timeseries`):
//! - accelerometer passes (three speeds, smooth straightness with waviness, noise from piezo to
//!   MEMS; the sample rate set for the size), a starting model with fitted straightness in y and z
//!   (flexible shapes whose terms BIC chooses) — complete, and with a hidden structural mode;
//! - encoder logs of a ball-screw axis (two passes, two crawls, a slow reversal; scale and motor
//!   encoder), a starting model with fitted positioning and servo lag; the size sets the passes'
//!   rows (a fifth of it each) and the crawls and the reversal add their own, so `enc15000` has
//!   24 498 samples and `enc100000` 74 914 (two per row); at 15 000 samples also a closed loop
//!   whose fit is repeated until its loop gains hold (`enc15000_refits`, 14 526 samples), a closed
//!   loop with a cyclic lead the model lacks (`enc_cyclic`, 11 974) and one with a backlash it
//!   lacks (`enc_backlash`, 19 910): draws of the rate studies at their own rates.
//!
//! The 15 000-sample hidden-mode set also with its clock as loggers keep it: its times rounded to
//! 1 µs (intervals of 665 and 666 µs in turn), and sampled at instants with Gaussian jitter of
//! 0.5 µs (no two intervals alike; the generator's logger clock, the same draw otherwise): the
//! mode's interval maps are then kept and reused, or had from a built one's Taylor tables.
//!
//! Also `vmt compare` of the complete models on the same accelerometer sets (its channel
//! reports hold each residual's least-squares periodogram), and the periodogram itself on an
//! evenly spaced grid (Fourier sums) against the explicit fit at each frequency, in one run.
//!
//! And `sin_cos` right after a faer product with the vector state as the product leaves it and
//! cleared (`vmt_estimators::cpu::clear_upper_state`).
//!
//! Run with `cargo bench --bench modelcheck` (quick: `-- --warm-up-time 1 --measurement-time 5
//! --sample-size 10`; one group: `-- periodogram`). With `VMT_BENCH_SETS=DIR` the `diagnose` group
//! writes its sets under DIR (kept, for timing another build's `vmt diagnose` on the same data)
//! instead of a temporary directory.
use criterion::{criterion_group, criterion_main, Criterion};
use std::path::Path;

#[path = "../tests/gen_timeseries/mod.rs"]
mod gen_timeseries;
use gen_timeseries::{
    accel_set_clocked, accel_set_sized, encoder_set, encoder_set_sized, AccelHidden, Clock, EncoderHidden,
};

fn diagnose(c: &mut Criterion) {
    // The allocator as `vmt` sets it (its `main`), so the times are the command's.
    vmt::cli::keep_freed_memory();
    let mut g = c.benchmark_group("diagnose");
    g.sample_size(10);
    let tmp = tempfile::tempdir().unwrap();
    let root = std::env::var_os("VMT_BENCH_SETS").map_or_else(|| tmp.path().to_path_buf(), std::path::PathBuf::from);
    let bench = |g: &mut criterion::BenchmarkGroup<_>, label: String, dir: &Path| {
        let model = vmt::model::read_model(&dir.join("model.toml")).unwrap();
        let set = vmt::measurement::read(dir).unwrap();
        g.bench_function(label, |b| b.iter(|| vmt::modelcheck::diagnose(&model, &set, dir).unwrap()));
    };
    for samples in [15_000usize, 100_000] {
        let dir = root.join(format!("acc{samples}"));
        let t = accel_set_sized(&dir, 11, AccelHidden::None, 0.0, Some(samples));
        bench(&mut g, format!("accelerometer passes, complete, {} samples", t.samples), &dir);
        let dir = root.join(format!("res{samples}"));
        let t = accel_set_sized(&dir, 12, AccelHidden::Resonance, 200.0, Some(samples));
        bench(&mut g, format!("accelerometer passes, hidden mode, {} samples", t.samples), &dir);
        if samples == 15_000 {
            let to = root.join("res15000_us");
            retimed(&dir, &to, &mut |t: f64| (t * 1e6).round() / 1e6);
            bench(
                &mut g,
                format!("accelerometer passes, hidden mode, {} samples, times rounded to 1 µs", t.samples),
                &to,
            );
            // Sampled at jittered instants (each sample, its command and its stamp at the same
            // instant): a copy of the set with only its stamps jittered is read at its regular clock
            // (`vmt::modelcheck::ticked_clock`), which times the even clock again.
            let to = root.join("res15000_jitter");
            let logger = Clock::Logger { jitter: 0.5e-6, resolution: 1e-9, lost: 0.0 };
            let t = accel_set_clocked(&to, 12, AccelHidden::Resonance, 200.0, Some(samples), logger);
            bench(
                &mut g,
                format!("accelerometer passes, hidden mode, {} samples, sampled with 0.5 µs jitter", t.samples),
                &to,
            );
        }
        let dir = root.join(format!("enc{samples}"));
        let t = encoder_set_sized(&dir, 13, EncoderHidden::None, Some(samples));
        bench(&mut g, format!("encoder logs, complete, {:?} loop, {} samples", t.feedback, t.samples), &dir);
        if samples == 15_000 {
            // A closed loop whose fit was repeated four times before its loop gains held (the rate
            // studies' draw 46: 1 fit + 4 refits of about 2 s each, 8.5 s; now 1.6 s), where the
            // set above needs few.
            let dir = root.join("enc15000_refits");
            let t = encoder_set(&dir, 2046, EncoderHidden::None);
            bench(
                &mut g,
                format!("encoder logs, complete, {:?} loop, {} samples, refitted", t.feedback, t.samples),
                &dir,
            );
            // A cyclic lead the model lacks (the rate studies' draw 7): the shape takes it up with
            // about 190 orders, and the lead is scanned against them.
            let dir = root.join("enc_cyclic");
            let t = encoder_set(&dir, 2007, EncoderHidden::CyclicLead);
            bench(
                &mut g,
                format!("encoder logs, cyclic lead hidden, {:?} loop, {} samples", t.feedback, t.samples),
                &dir,
            );
            // A backlash the model lacks (the rate studies' draw 22, 15.4 µm): the closed loop's kv
            // does not settle, the shape takes about 200 orders, and the orders are chosen again
            // with each of six candidates in the model.
            let dir = root.join("enc_backlash");
            let t = encoder_set(&dir, 2022, EncoderHidden::Backlash);
            bench(&mut g, format!("encoder logs, backlash hidden, {:?} loop, {} samples", t.feedback, t.samples), &dir);
        }
    }
    g.finish();
}

/// The set in `from` copied to `to` with each CSV's first column (the time, s) rewritten by `clock`.
fn retimed(from: &Path, to: &Path, clock: &mut dyn FnMut(f64) -> f64) {
    std::fs::create_dir_all(to).unwrap();
    for entry in std::fs::read_dir(from).unwrap() {
        let path = entry.unwrap().path();
        let name = path.file_name().unwrap();
        let text = std::fs::read_to_string(&path).unwrap();
        let out = if path.extension().is_some_and(|e| e == "csv") {
            let mut lines = text.lines();
            let mut out = format!("{}\n", lines.next().unwrap_or(""));
            for line in lines {
                let (t, rest) = line.split_once(',').unwrap();
                out.push_str(&format!("{:?},{rest}\n", clock(t.parse::<f64>().unwrap())));
            }
            out
        } else {
            text
        };
        std::fs::write(to.join(name), out).unwrap();
    }
}

fn compare(c: &mut Criterion) {
    let mut g = c.benchmark_group("compare");
    g.sample_size(10);
    let tmp = tempfile::tempdir().unwrap();
    for samples in [15_000usize, 100_000] {
        let dir = tmp.path().join(format!("acc{samples}"));
        let t = accel_set_sized(&dir, 11, AccelHidden::None, 0.0, Some(samples));
        let model = vmt::model::read_model(&dir.join("model.toml")).unwrap();
        let set = vmt::measurement::read(&dir).unwrap();
        g.bench_function(format!("accelerometer passes, complete, {} samples", t.samples), |b| {
            b.iter(|| vmt::modelcheck::compare(&model, &set, &dir).unwrap())
        });
    }
    g.finish();
}

/// `ls_periodogram` of 4 000 irregular samples (a sinusoid in noise) on `frequency_grid`'s 5×
/// oversampled grid (about 10 000 frequencies): the evenly spaced grid (Fourier sums), and the
/// same grid with its last frequency moved by a hundredth of a step, which is not evenly spaced
/// and takes the explicit fit at every frequency (the reference).
fn periodogram(c: &mut Criterion) {
    use vmt_estimators::modelcheck::{frequency_grid, ls_periodogram, Sigma};
    let mut g = c.benchmark_group("periodogram");
    g.sample_size(10);
    let n = 4_000;
    let x: Vec<f64> = (0..n).map(|i| 1e-3 * (i as f64 + 0.6 * ((i as f64 * 0.618).fract() - 0.5))).collect();
    let r: Vec<f64> =
        x.iter().enumerate().map(|(i, x)| (x * 300.0).sin() + 0.3 * ((i as f64 * 0.377).fract() - 0.5)).collect();
    let even = frequency_grid(&x, 5.0, None).unwrap();
    let mut uneven = even.clone();
    let last = uneven.len() - 1;
    uneven[last] += 0.01 * (even[1] - even[0]);
    g.bench_function(format!("{n} samples, {} frequencies, evenly spaced (Fourier sums)", even.len()), |b| {
        b.iter(|| ls_periodogram(&x, &r, &Sigma::Unknown, &even).unwrap())
    });
    g.bench_function(format!("{n} samples, {} frequencies, explicit fit at each (reference)", uneven.len()), |b| {
        b.iter(|| ls_periodogram(&x, &r, &Sigma::Unknown, &uneven).unwrap())
    });
    g.finish();
}

/// libm after faer (`vmt_estimators::cpu`): 20 000 `sin_cos` right after a faer product, with the
/// vector registers' upper halves as the product left them and cleared (`clear_upper_state`), and
/// alone (the reference), in one run.
fn vector_state(c: &mut Criterion) {
    use faer::linalg::matmul::matmul;
    use faer::{Accum, Mat, Par};
    let mut g = c.benchmark_group("vector_state");
    let x: Vec<f64> = (0..20_000).map(|i| 0.0876 + 2.2e-5 * i as f64).collect();
    let waves =
        |x: &[f64]| x.iter().map(|x| (std::f64::consts::TAU * x / 0.0123).sin_cos()).fold(0.0, |a, (s, c)| a + s * c);
    let a = Mat::<f64>::from_fn(200, 50, |i, j| (i + 2 * j) as f64);
    let b = Mat::<f64>::from_fn(50, 30, |i, j| (i * j) as f64);
    let mut m = Mat::<f64>::zeros(200, 30);
    let mut product = || matmul(m.as_mut(), Accum::Replace, a.as_ref(), b.as_ref(), 1.0, Par::Seq);
    g.bench_function("20 000 sin_cos after a faer product, state as left", |bch| {
        bch.iter(|| {
            product();
            waves(&x)
        })
    });
    g.bench_function("20 000 sin_cos after a faer product, upper halves cleared", |bch| {
        bch.iter(|| {
            product();
            vmt_estimators::cpu::clear_upper_state();
            waves(&x)
        })
    });
    g.bench_function("a faer product alone (reference)", |bch| bch.iter(&mut product));
    g.finish();
}

criterion_group!(benches, diagnose, compare, periodogram, vector_state);
criterion_main!(benches);
