//! Workflow `simulate`: scenario → machine → recording. The physics of each procedure is simulated
//! once (in parallel: procedures are independent, and each is deterministic, so the result does not
//! depend on the number of threads); the sensors then read the truth with noise seeded per run and
//! sensor.

use crate::error::VmtError;
use crate::scenario::Scenario;
use rayon::prelude::*;
use vmt_sim::effects::EffectParams;
use vmt_sim::geometry::ErrorMotions;
use vmt_sim::procedures::{read_run, simulate_procedure, RunRecord, RunTruth};

/// The axis letter of a joint, for matching effects (`axis = "x"`): the joint name's last letter.
pub fn axis_letter(joint: &str) -> char {
    joint.chars().last().unwrap_or('x').to_ascii_lowercase()
}

/// The six error motions of `axis` from a truth model (effects of other axes and other kinds are not
/// geometric error motions of this axis and are ignored here).
pub fn error_motions(truth: &crate::model::Model, axis: char) -> ErrorMotions {
    let mut e = ErrorMotions::default();
    for me in &truth.effects {
        if me.effect.axis != axis {
            continue;
        }
        if let EffectParams::ErrorMotion(p) = &me.effect.params {
            use vmt_sim::effects::EffectName as N;
            let slot = match me.effect.name {
                N::Positioning => &mut e.positioning,
                N::StraightnessY => &mut e.straightness_y,
                N::StraightnessZ => &mut e.straightness_z,
                N::Roll => &mut e.roll,
                N::Pitch => &mut e.pitch,
                N::Yaw => &mut e.yaw,
                _ => continue,
            };
            *slot = p.clone();
        }
    }
    e
}

/// Noise-free truth traces of every procedure of a scenario, in scenario order.
pub fn simulate_truth(sc: &Scenario) -> Vec<RunTruth> {
    let errors = error_motions(&sc.truth, axis_letter(&sc.axis.joint));
    sc.procedures
        .par_iter()
        .map(|p| simulate_procedure(&sc.axis, &errors, p, sc.seed))
        .collect::<Vec<_>>()
        .into_iter()
        .flatten()
        .collect()
}

/// Sensor readings of every run, noise seeded by `seed`.
pub fn read_all(sc: &Scenario, truths: &[RunTruth], seed: u64) -> Result<Vec<RunRecord>, VmtError> {
    truths
        .iter()
        .map(|t| read_run(&sc.axis, t, &sc.sensors, seed).map_err(|m| VmtError::input(&sc.source, "sensors", m)))
        .collect()
}
