//! Dynamics are real (issue 2): the accelerometer feels the carriage pushed along its error path, and
//! the bearing resonance sits where k/m puts it.

use crate::util;
use rapier3d_f64::glamx::DVec3;
use vmt_sim::axis_sim::AxisTruth;
use vmt_sim::axis_sim::{AxisSim, GRAVITY};
use vmt_sim::geometry::ErrorMotions;
use vmt_sim::motion::Command;
use vmt_sim::procedures::{read_run, simulate_procedure, ProcedureSpec, RunData};
use vmt_sim::profile::{Harmonic, Profile};
use vmt_sim::sensors::{SensorKind, SensorSpec};

#[test]
fn noise_free_accelerometer_reads_v2_times_curvature_at_constant_speed() {
    let model = util::slide_column();
    let (amp, wl, v) = (2e-6, 0.1, 0.5);
    let errors = AxisTruth::geometric(ErrorMotions {
        straightness_z: Profile::harmonics(vec![Harmonic { amplitude: amp, wavelength: wl, phase: 0.4 }]),
        ..Default::default()
    });
    let acc = SensorSpec {
        link: Some("accel_mount".into()),
        direction: [0.0, 0.0, 1.0],
        ..SensorSpec::new("acc_z", SensorKind::Accelerometer)
    };
    // Settle 1 s after reaching speed: the start-up ringing of the pitch mode (ζ = 0.05, ~110 Hz) has
    // decayed by e^-35 by then, so only the response to the guideway remains.
    let spec = ProcedureSpec::ConstantVelocity {
        name: "cv".into(),
        speeds: vec![v],
        start: 0.3,
        end: 0.7,
        high_rate: 1200.0,
        direction: 1,
        settle: 1.0,
        sensors: vec!["acc_z".into()],
    };
    let truth = simulate_procedure(&model, &errors, &spec, 1);
    let rec = read_run(&model, &errors, &truth[0], &[acc], 1).unwrap();
    let RunData::TimeSeries { columns, .. } = rec.data else { panic!("time series expected") };
    let x = &columns[0].1;
    let a = &columns[1].1;
    let k = std::f64::consts::TAU / wl;
    let (mut se, mut ss) = (0.0, 0.0);
    for (xi, ai) in x.iter().zip(a) {
        // The reading is the boxcar average over the sample interval T = 1/1200 s ending at the sample
        // (the sensor's anti-alias filter): group delay T/2, i.e. position x − v·T/2; its attenuation of a
        // 5 Hz sine is 1e-5 only.
        let xm = xi - v / 1200.0 / 2.0;
        let expect = -v * v * k * k * amp * (k * xm + 0.4).sin();
        se += (ai - GRAVITY - expect).powi(2);
        ss += expect * expect;
    }
    let rel = (se / ss).sqrt();
    println!("accelerometer vs v²E'': relative RMS difference {rel:.4}");
    // The remainder (2.4 % measured) is mostly the servo hunting on the 1 nm feedback quantisation,
    // which shakes the carriage by ~3e-5 m/s² RMS: physical, and below a piezo accelerometer's noise.
    // Issue 2: within 3 % RMS below the bearing resonance (5 Hz excitation vs ~300 Hz bounce mode).
    assert!(rel < 0.03, "relative RMS difference {rel}");
}

#[test]
fn vertical_bearing_resonance_sits_at_sqrt_of_n_k_over_m() {
    let model = util::slide_column();
    let errors = AxisTruth::default();
    let mut sim = AxisSim::new(&model, &errors, 0.5);
    let hold = Command { pos: 0.5, vel: 0.0, acc: 0.0 };
    for _ in 0..3000 {
        sim.step(hold);
    }
    sim.kick(DVec3::new(0.0, 0.0, 1e-4));
    let mut z = Vec::new();
    for _ in 0..2000 {
        sim.step(hold);
        z.push(sim.sample(hold).pos.z);
    }
    let mean = z.iter().sum::<f64>() / z.len() as f64;
    // Upward zero crossings, linearly interpolated.
    let mut crossings = Vec::new();
    for i in 1..z.len() {
        let (a, b) = (z[i - 1] - mean, z[i] - mean);
        if a < 0.0 && b >= 0.0 {
            crossings.push((i - 1) as f64 + a / (a - b));
        }
    }
    let periods = (crossings.len() - 1) as f64;
    let f = periods / ((crossings[crossings.len() - 1] - crossings[0]) * model.dt);
    let n = model.blocks.len() as f64;
    let zeta: f64 = 0.05;
    let f_pred = (n * model.k_z / model.mass).sqrt() / std::f64::consts::TAU * (1.0 - zeta * zeta).sqrt();
    println!("bounce mode: simulated {f:.2} Hz, predicted {f_pred:.2} Hz");
    // 1 %: the symplectic Euler step shifts the frequency by (ω·dt)²/24 ≈ 0.15 %.
    assert!((f / f_pred - 1.0).abs() < 0.01, "simulated {f} Hz vs predicted {f_pred} Hz");
}
