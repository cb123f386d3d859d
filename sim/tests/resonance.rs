//! A structural mode of the column shows in the accelerometer spectrum at its own frequency, whatever
//! the speed (issue 3): it is a temporal frequency, unlike guideway errors, whose temporal frequency
//! scales with the speed.

use crate::util;
use vmt_sim::axis_sim::{AxisTruth, StructuralMode};
use vmt_sim::geometry::ErrorMotions;
use vmt_sim::procedures::{read_run, simulate_procedure, ProcedureSpec, RunData};
use vmt_sim::profile::{Profile, RandomProfile, Term};
use vmt_sim::sensors::{SensorKind, SensorSpec};

/// Frequency (Hz) of the largest peak of |DFT| of x (mean removed) between f_lo and f_hi (capped at Nyquist).
fn peak_frequency(x: &[f64], fs: f64, f_lo: f64, f_hi: f64) -> f64 {
    let n = x.len();
    let mean = x.iter().sum::<f64>() / n as f64;
    let df = fs / n as f64;
    let mut best = (0.0, 0.0);
    let mut k = (f_lo / df).ceil() as usize;
    while (k as f64) * df < (fs / 2.0).min(f_hi) {
        let w = std::f64::consts::TAU * k as f64 / n as f64;
        let (mut re, mut im) = (0.0, 0.0);
        for (i, xi) in x.iter().enumerate() {
            let (s, c) = (w * i as f64).sin_cos();
            re += (xi - mean) * c;
            im -= (xi - mean) * s;
        }
        let p = re * re + im * im;
        if p > best.1 {
            best = (k as f64 * df, p);
        }
        k += 1;
    }
    best.0
}

#[test]
fn column_mode_appears_at_its_frequency_for_every_speed() {
    let model = util::slide_column();
    let f_mode = 45.0;
    let truth = AxisTruth {
        // A fine random straightness (roughness, 0.5 mm correlation) excites the column broadly.
        motions: ErrorMotions {
            straightness_y: Profile {
                terms: vec![Term::random(RandomProfile { rms: 0.3e-6, correlation_length: 0.0005, seed: 5 })],
            },
            ..Default::default()
        },
        mode: Some(StructuralMode { frequency: f_mode, damping: 0.02, height: 1.4 }),
        ..Default::default()
    };
    let acc = SensorSpec {
        link: Some("mp3".into()),
        direction: [0.0, 1.0, 0.0],
        ..SensorSpec::new("acc", SensorKind::Accelerometer)
    };
    let spec = ProcedureSpec::ConstantVelocity {
        name: "cv".into(),
        speeds: vec![0.1, 0.2, 0.4],
        start: 0.1,
        end: 0.9,
        high_rate: 1200.0,
        direction: 1,
        settle: 0.3,
        sensors: vec!["acc".into()],
    };
    for run in simulate_procedure(&model, &truth, &spec, 2) {
        let rec = read_run(&model, &truth, &run, std::slice::from_ref(&acc), 2).unwrap();
        let RunData::TimeSeries { t, columns } = rec.data else { panic!() };
        let fs = 1.0 / (t[1] - t[0]);
        let f = peak_frequency(&columns[1].1, fs, 0.5 * f_mode, 2.0 * f_mode);
        println!("speed {} m/s: spectrum peak at {f:.2} Hz (fs {fs:.0} Hz)", run.feed.unwrap());
        // The largest peak within an octave either side of the mode lies within the half-power bandwidth
        // 2ζ·f = 1.8 Hz plus one frequency bin (fs/N ≤ 0.5 Hz): a randomly excited resonance's periodogram
        // peak scatters across that bandwidth.
        let tol = 2.0 * 0.02 * f_mode + fs / columns[1].1.len() as f64;
        assert!((f - f_mode).abs() < tol, "peak at {f} Hz for speed {:?}", run.feed);
    }
}
