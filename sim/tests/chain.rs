//! The multi-axis chain (issue 3, squareness): a 3-axis machine (vmc_3axis) simulated as three rapier
//! axes composed exactly through the chain. At rest at several points of the working volume, the
//! composed deviation of a point (relative to the same moves with every error set to zero, which
//! removes the bearings' gravity sag) equals the first-order volumetric model of
//! vmt_estimators::laser_ls (written out below) within second-order terms and the servo's quantisation.

use rapier3d_f64::glamx::DVec3;
use vmt_sim::axis_sim::Sample;
use vmt_sim::chain::{simulate_chain, ChainModel, ChainPlan};
use vmt_sim::effects::{Effect, EffectName, EffectParams, EffectSet, Squareness};
use vmt_sim::machine::AxisConfig;
use vmt_sim::profile::{Harmonic, Profile};
use vmt_sim::urdf::{parse_urdf, MachineStructure};
use vmt_sim::Axis;

fn machine() -> MachineStructure {
    let text = std::fs::read_to_string(concat!(env!("CARGO_MANIFEST_DIR"), "/../urdf/vmc_3axis.urdf")).unwrap();
    parse_urdf(&text).unwrap()
}

fn configs() -> Vec<AxisConfig> {
    ["x", "y", "z"].iter().map(|j| AxisConfig { joint: j.to_string(), ..Default::default() }).collect()
}

const SQ: [f64; 3] = [20e-6, -15e-6, 10e-6]; // EC0Y, EB0Z, EA0Z

/// Error motions of the test, by (axis, FORMAT.md name): (EffectName, axis, profile).
fn motions() -> Vec<(EffectName, Axis, Profile)> {
    let h = |a: f64, w: f64, p: f64| Profile::harmonics(vec![Harmonic { amplitude: a, wavelength: w, phase: p }]);
    vec![
        (EffectName::Positioning, Axis::X, Profile::poly(vec![0.0, 12e-6])),
        (EffectName::StraightnessY, Axis::X, h(2e-6, 0.9, 0.3)),
        (EffectName::StraightnessZ, Axis::X, h(3e-6, 1.2, 1.0)),
        (EffectName::Roll, Axis::X, h(10e-6, 0.8, 0.2)),
        (EffectName::Pitch, Axis::X, Profile::poly(vec![4e-6, -15e-6])),
        (EffectName::Yaw, Axis::X, h(12e-6, 0.7, 1.5)),
        (EffectName::Positioning, Axis::Y, Profile::poly(vec![0.0, -8e-6])),
        (EffectName::StraightnessY, Axis::Y, h(1.5e-6, 0.6, 0.4)), // EXY
        (EffectName::StraightnessZ, Axis::Y, h(2.5e-6, 0.5, 2.0)), // EZY
        (EffectName::Roll, Axis::Y, h(8e-6, 0.7, 0.1)),            // EBY
        (EffectName::Pitch, Axis::Y, Profile::poly(vec![-3e-6, 10e-6])), // EAY
        (EffectName::Yaw, Axis::Y, h(9e-6, 0.9, 2.5)),             // ECY
        (EffectName::Positioning, Axis::Z, Profile::poly(vec![0.0, 6e-6])),
        (EffectName::StraightnessY, Axis::Z, h(1.8e-6, 0.45, 0.7)), // EXZ
        (EffectName::StraightnessZ, Axis::Z, h(2.2e-6, 0.55, 1.1)), // EYZ
        (EffectName::Roll, Axis::Z, h(7e-6, 0.6, 0.9)),             // ECZ
        (EffectName::Pitch, Axis::Z, Profile::poly(vec![5e-6, -12e-6])), // EAZ
        (EffectName::Yaw, Axis::Z, h(11e-6, 0.8, 0.3)),             // EBZ
    ]
}

fn effect_set(with_squareness: bool) -> EffectSet {
    let mut set = EffectSet::default();
    for (n, a, p) in motions() {
        set.insert(Effect::error_motion(n, a, p));
    }
    if with_squareness {
        for (n, v) in [EffectName::SquarenessXy, EffectName::SquarenessXz, EffectName::SquarenessYz].iter().zip(SQ) {
            set.insert(Effect { name: *n, axis: Axis::X, params: EffectParams::Squareness(Squareness { value: v }) });
        }
    }
    set
}

/// Value of the injected error motion (name, axis) at q.
fn value(name: EffectName, axis: Axis, q: f64) -> f64 {
    motions().iter().find(|(n, a, _)| *n == name && *a == axis).map_or(0.0, |(_, _, p)| p.value(q))
}

/// The first-order volumetric error of laser_ls's module doc, written out for X → Y → Z:
/// δ = Σ_j [E_j + ε_j × ρ_j] + (−EC0Y·q_y + EB0Z·q_z, −EA0Z·q_z, 0), with E_X = (EXX, EYX, EZX),
/// ε_X = (EAX, EBX, ECX), E_Y = (EXY, EYY, EZY), ε_Y = (EAY, EBY, ECY), E_Z = (EXZ, EYZ, EZZ),
/// ε_Z = (EAZ, EBZ, ECZ), and ρ_j the lever arm from axis j's reference point (its carriage frame
/// origin in vmc_3axis.urdf: X at (q_x, 0, 0), Y at (q_x, q_y, 0.16), Z at (q_x, q_y, 0.36 + q_z);
/// tool 0.15 m below the Z origin) to the measuring point.
fn first_order(q: [f64; 3], r: DVec3, sq: [f64; 3]) -> DVec3 {
    use EffectName::*;
    let [x, y, z] = q;
    let p = DVec3::new(x, y, 0.36 + z - 0.15) + r;
    let ox = DVec3::new(x, 0.0, 0.0);
    let oy = DVec3::new(x, y, 0.16);
    let oz = DVec3::new(x, y, 0.36 + z);
    let ex =
        DVec3::new(value(Positioning, Axis::X, x), value(StraightnessY, Axis::X, x), value(StraightnessZ, Axis::X, x));
    let epx = DVec3::new(value(Roll, Axis::X, x), value(Pitch, Axis::X, x), value(Yaw, Axis::X, x));
    let ey =
        DVec3::new(value(StraightnessY, Axis::Y, y), value(Positioning, Axis::Y, y), value(StraightnessZ, Axis::Y, y));
    let epy = DVec3::new(value(Pitch, Axis::Y, y), value(Roll, Axis::Y, y), value(Yaw, Axis::Y, y));
    let ez =
        DVec3::new(value(StraightnessY, Axis::Z, z), value(StraightnessZ, Axis::Z, z), value(Positioning, Axis::Z, z));
    let epz = DVec3::new(value(Pitch, Axis::Z, z), value(Yaw, Axis::Z, z), value(Roll, Axis::Z, z));
    let [c0y, b0z, a0z] = sq;
    ex + epx.cross(p - ox)
        + ey
        + epy.cross(p - oy)
        + ez
        + epz.cross(p - oz)
        + DVec3::new(-c0y * y + b0z * z, -a0z * z, 0.0)
}

#[test]
fn composed_deviation_matches_the_first_order_model_at_rest() {
    let m = machine();
    let with = ChainModel::build(&m, &configs(), &effect_set(true), "tool").unwrap();
    let zero = ChainModel::build(&m, &configs(), &EffectSet::default(), "tool").unwrap();
    // Points of the working volume (800 × 600 × 500 mm travel), visited by synchronised moves.
    let points = [[0.05, 0.05, 0.05], [0.75, 0.05, 0.1], [0.7, 0.55, 0.1], [0.7, 0.5, 0.45], [0.2, 0.3, 0.4]];
    let mut plan = ChainPlan::starting_at(&points[0]);
    let mut times = Vec::new();
    plan.dwell(1.0);
    times.push(plan.end);
    for p in &points[1..] {
        plan.move_to(p, 0.3, 2.0);
        let (_, t1) = plan.dwell(0.4);
        times.push(t1);
    }
    let a = simulate_chain(&with, &plan, &times);
    let b = simulate_chain(&zero, &plan, &times);
    let offsets = [DVec3::ZERO, DVec3::new(0.1, 0.15, -0.1), DVec3::new(-0.12, 0.05, 0.0)];
    let mut worst = 0.0f64;
    let mut worst_sq = 0.0f64;
    for (k, q) in points.iter().enumerate() {
        let sa: Vec<&Sample> = a.iter().map(|t| &t.samples[k]).collect();
        let sb: Vec<&Sample> = b.iter().map(|t| &t.samples[k]).collect();
        for r in offsets {
            let d = with.actual_point(&sa, r) - zero.actual_point(&sb, r);
            let fo = first_order(*q, r, SQ);
            // The same from the library's first-order formula (chain.first_order_deviation).
            let lib = with.first_order_deviation(q, r);
            assert!((lib - fo).length() < 1e-15, "library first-order {lib:?} vs test {fo:?}");
            let e = (d - fo).length();
            println!(
                "q = {q:?} r = {:?}: composed {:+.4} {:+.4} {:+.4} µm, error vs first order {:.3} nm",
                r.to_array(),
                d.x * 1e6,
                d.y * 1e6,
                d.z * 1e6,
                e * 1e9
            );
            worst = worst.max(e);
            // Size of the squareness part itself, to show the test can fail: up to ~10 µm.
            worst_sq = worst_sq.max(DVec3::new(-SQ[0] * q[1] + SQ[1] * q[2], -SQ[2] * q[2], 0.0).length());
        }
    }
    println!("worst composition error {:.3} nm; largest squareness term {:.3} µm", worst * 1e9, worst_sq * 1e6);
    // Bound 3 nm: second-order terms ε·θ·L and ε²·L ≤ (20 µrad)²·1 m ≈ 0.4 nm; the feedback
    // quantisation (1 nm per axis, the servo holds within ±q/2 in each run: ≤ 1.5 nm per run
    // summed over three axes, uncorrelated between the two runs); the difference of the bearings'
    // sag acting through the error rotations ≈ 2.5 µm·20 µrad ≈ 5e-14 m.
    assert!(worst < 3e-9, "composed deviation differs from the first-order model by {worst:e} m");
    assert!(worst_sq > 5e-6);
}

#[test]
fn squareness_sign_by_hand() {
    // EC0Y = 20 µrad alone: Y travels along (−sin θ, cos θ, 0), so at q_y = 0.5 m the tool is
    // 10 µm towards −x (hand: −20e-6 · 0.5 = −10e-6 m); EB0Z = −15 µrad alone at q_z = 0.4: −6 µm in x;
    // EA0Z = 10 µrad alone at q_z = 0.4: −4 µm in y. Checked through the exact composition of
    // error-free rapier samples at rest.
    let m = machine();
    for (k, (name, want)) in [
        (EffectName::SquarenessXy, DVec3::new(-10e-6, 0.0, 0.0)),
        (EffectName::SquarenessXz, DVec3::new(-6e-6, 0.0, 0.0)),
        (EffectName::SquarenessYz, DVec3::new(0.0, -4e-6, 0.0)),
    ]
    .into_iter()
    .enumerate()
    {
        let mut set = EffectSet::default();
        set.insert(Effect { name, axis: Axis::X, params: EffectParams::Squareness(Squareness { value: SQ[k] }) });
        let chain = ChainModel::build(&m, &configs(), &set, "tool").unwrap();
        let zero = ChainModel::build(&m, &configs(), &EffectSet::default(), "tool").unwrap();
        let q = [0.2, 0.5, 0.4];
        let mut plan = ChainPlan::starting_at(&q);
        let (_, t1) = plan.dwell(0.6);
        let a = simulate_chain(&chain, &plan, &[t1]);
        let b = simulate_chain(&zero, &plan, &[t1]);
        let sa: Vec<&Sample> = a.iter().map(|t| &t.samples[0]).collect();
        let sb: Vec<&Sample> = b.iter().map(|t| &t.samples[0]).collect();
        let d = chain.actual_point(&sa, DVec3::ZERO) - zero.actual_point(&sb, DVec3::ZERO);
        println!("{name}: {:?} µm", (d * 1e6).to_array());
        // 1 nm: the runs are identical but for the rotation, the second-order term θ²·L/2 ≈ 1e-10 m.
        assert!((d - want).length() < 1e-9, "{name}: got {d:?}, want {want:?}");
    }
}

#[test]
fn bad_chains_are_refused_with_a_reason() {
    let m = machine();
    let mut c = configs();
    c.swap(0, 1);
    let e = ChainModel::build(&m, &c, &EffectSet::default(), "tool").unwrap_err().to_string();
    assert!(e.contains("needs it on `bed`"), "{e}");
    let e = ChainModel::build(&m, &configs()[..2], &EffectSet::default(), "tool").unwrap_err().to_string();
    assert!(e.contains("tool link"), "{e}");
    let mut set = EffectSet::default();
    set.insert(Effect {
        name: EffectName::SquarenessYz,
        axis: Axis::X,
        params: EffectParams::Squareness(Squareness { value: 1e-5 }),
    });
    let c2 = vec![configs()[0].clone()];
    let e = ChainModel::build(&m, &c2, &set, "x_carriage").unwrap_err().to_string();
    assert!(e.contains("squareness_yz"), "{e}");
    let mut c3 = configs();
    c3[2].joint = "w".into();
    let e = ChainModel::build(&m, &c3, &EffectSet::default(), "tool").unwrap_err().to_string();
    assert!(e.contains("no prismatic joint"), "{e}");
}
