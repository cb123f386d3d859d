//! Quasi-static truth (issue 2): at a slow traverse the displacement of each laser measuring point,
//! relative to the same traverse with every error set to zero (which removes gravity sag and the
//! drive-force tilt), equals δ(r) = E(x) + ε(x) × r, and the body's rotation equals ε(x).

use crate::util;
use rapier3d_f64::glamx::DVec3;
use vmt_sim::axis_sim::simulate;
use vmt_sim::axis_sim::AxisTruth;
use vmt_sim::geometry::ErrorMotions;
use vmt_sim::motion::MotionPlan;
use vmt_sim::profile::{Harmonic, Profile};

fn errors() -> ErrorMotions {
    let h = |a: f64, w: f64, p: f64| Harmonic { amplitude: a, wavelength: w, phase: p };
    ErrorMotions {
        positioning: Profile::poly(vec![0.0, 20e-6, -8e-6]),
        straightness_y: Profile::harmonics(vec![h(2e-6, 0.8, 0.3), h(0.5e-6, 0.13, 1.0)]),
        straightness_z: Profile::harmonics(vec![h(3e-6, 1.1, 0.0), h(0.6e-6, 0.21, 2.0)]),
        roll: Profile::harmonics(vec![h(12e-6, 0.9, 0.4)]),
        pitch: Profile::poly(vec![5e-6, -20e-6, 10e-6]),
        yaw: Profile::harmonics(vec![h(15e-6, 0.7, 1.2)]),
    }
}

#[test]
fn slow_traverse_reproduces_the_injected_error_motions() {
    let model = util::slide_column();
    let mut plan = MotionPlan::starting_at(0.1);
    plan.dwell(0.3);
    let (t0, t1) = plan.move_to(0.4, 0.01, 0.5);
    let times: Vec<f64> = (0..=60).map(|i| t0 + 0.5 + (t1 - t0 - 1.0) * i as f64 / 60.0).collect();
    let truth = errors();
    let truth_sim = AxisTruth::geometric(truth.clone());
    let zero = AxisTruth::default();
    let a = simulate(&model, &truth_sim, &plan, &times);
    let b = simulate(&model, &zero, &plan, &times);
    let points = ["mp1", "mp2", "mp3", "accel_mount"].map(|n| model.link(n).unwrap().translation);
    let (mut worst_d, mut worst_r) = (0.0f64, 0.0f64);
    for (sa, sb) in a.samples.iter().zip(&b.samples) {
        let x = sa.cmd.pos;
        for p in points {
            let d = sa.point(&model, p, None) - sb.point(&model, p, None);
            let expect = truth.deviation(x, model.body_to_axis(p));
            worst_d = worst_d.max((d - expect).length());
        }
        worst_r = worst_r.max(((sa.rot - sb.rot) - truth.rotation(x)).length());
    }
    println!("worst point deviation error {worst_d:e} m, rotation error {worst_r:e} rad");
    // Issue 2: within 2 nm and 0.02 µrad (second-order terms ε²·r ≈ (30 µrad)²·1.3 m ≈ 1 nm are below).
    assert!(worst_d < 2e-9, "point deviation differs from E + ε × r by {worst_d:e} m");
    assert!(worst_r < 0.02e-6, "rotation differs from ε by {worst_r:e} rad");
    let _ = DVec3::ZERO;
}
