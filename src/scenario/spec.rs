//! The estimators a scenario asks for (`[[estimators]]`, FORMAT.md §3) with the tolerance each estimate
//! must meet. Plain data read with the scenario; the estimate workflow (`crate::estimate`) acts on it, so
//! the dependency runs one way: scenario → estimate.

use serde::{Deserialize, Serialize};

/// Estimators a scenario can ask for (`[[estimators]]`), each with the tolerance its estimate must meet.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case", deny_unknown_fields)]
pub enum EstimatorSpec {
    /// ISO 230-2 evaluation of a positioning run read by a linear laser: E, M and B̄ compared with the
    /// values of the injected deviations at the laser's measuring point.
    Iso230_2 {
        /// Name of the positioning run (a procedure's name).
        run: String,
        /// The laser sensor whose column is evaluated.
        sensor: String,
        /// Largest allowed |recovered − injected| of each of E, M and B̄, m.
        tolerance: f64,
    },
    /// Laser line-set identification (seeds 001, 003) of the six error motions from a point-table run
    /// read by several lasers (the 9-line / three-point design): general least squares with one zero
    /// offset per laser line. Translations are compared with `tolerance_translation` (m RMS), angles
    /// with `tolerance_angle` (rad RMS), in the identifier's conventions (EXX and angles relative to the
    /// first target, straightness about its least-squares line).
    LaserLines {
        /// Name of the point-table run (a procedure's name).
        run: String,
        /// The laser sensors (one line each) read in that run.
        sensors: Vec<String>,
        /// Largest allowed RMS difference of a translational error motion, m.
        tolerance_translation: f64,
        /// Largest allowed RMS difference of an angular error motion, rad.
        tolerance_angle: f64,
    },
    /// Compensation table (seed 004): a variable-step table from the mean bidirectional deviations of a
    /// positioning run, applied in the simulated CNC; the test is repeated at other irregular targets and
    /// E and A must fall to at most `max_ratio` of their values before compensation.
    Compensation {
        /// Name of the positioning run the table is made from.
        run: String,
        /// The laser sensor whose column gives the deviations.
        sensor: String,
        /// Largest allowed ratio of E (and of A) after compensation to before (dimensionless).
        #[serde(default = "default_max_ratio")]
        max_ratio: f64,
        /// Smallest allowed Pearson correlation between the table's corrections and the injected
        /// deviation (dimensionless).
        #[serde(default = "default_pearson")]
        pearson: f64,
        /// Largest allowed RMS of (table correction + injected deviation) at the table's points, m.
        #[serde(default = "default_residual")]
        residual: f64,
    },
    /// Stick-slip index (seed 002) of each crawl run of a procedure, compared with expected values.
    Ssi {
        /// Name of the crawl procedure (its runs are `{procedure}_{k}`).
        procedure: String,
        /// The position sensor whose readings are differentiated.
        sensor: String,
        /// Expected SSI of each run, in run order (dimensionless).
        expected: Vec<f64>,
        /// Largest allowed |SSI − expected| of each run (dimensionless).
        tolerance: Vec<f64>,
    },
    /// The model-check loop (DESIGN.md §8) run automatically: compare the starting model (`model`, a
    /// vmt-model/1 file relative to the scenario) with the recording, diagnose, add the best significant
    /// effect, repeat (at most `max_steps`). Checks that the `expected` effects are found and that the final
    /// normalised RMS is at most `tolerance`.
    ModelCheck {
        /// The starting model, a vmt-model/1 file relative to the scenario.
        model: String,
        /// Effects (named as the model file writes them) the loop must find.
        expected: Vec<vmt_sim::effects::EffectName>,
        /// Most effects the loop adds before it stops.
        #[serde(default = "default_steps")]
        max_steps: usize,
        /// Largest allowed final normalised RMS (residual RMS over the noise σ, dimensionless).
        tolerance: f64,
    },
    /// Straightness from an accelerometer's constant-velocity runs (seed 000, and the SNR-weighted
    /// fusion), compared with the lateral motion of its mount point band-limited to the recoverable
    /// wavelengths; `tolerance` bounds the RMS difference.
    AccelStraightness {
        /// Name of the constant-velocity procedure whose runs are the passes.
        procedure: String,
        /// The accelerometer.
        sensor: String,
        /// Fusion method: `snr_weighted` (default) or `spatial_continuity` (seed 000).
        #[serde(default)]
        method: Option<String>,
        /// Largest allowed RMS difference from the band-limited injected straightness, m.
        tolerance: f64,
    },
    /// Laser line-set identification of a multi-axis chain (seed 001; issue 3): every line of the chain
    /// procedure `procedure` (`[[chain_procedures]]`, kind `laser_lines`) fed to
    /// `vmt_estimators::laser_ls::identify` with the chain's axes (six error motions each, as values at
    /// the joint positions the lines stop at) and `squareness: true`. One check per squareness angle of
    /// the chain: injected as laser lines see it (`ChainModel::effective_squareness`, the angles between
    /// the least-squares lines of the tool point's paths) against recovered, with the tolerance
    /// `k_sigma`·σ + `bias` (σ the identifier's standard error, rad; `bias` the quasi-static bound of the
    /// simulated composition, rad). Also one check per angular error motion the lines determine: RMS of
    /// (identified − injected, relative to the reference position) within `k_sigma`·RMS(σ) +
    /// `bias_angle` (rad, default `bias`).
    #[serde(rename = "laser_lines_3d")]
    LaserLines3d {
        /// Name of the chain procedure (`[[chain_procedures]]`).
        procedure: String,
        /// Multiple of the standard error in the tolerance (dimensionless).
        #[serde(default = "default_k_sigma")]
        k_sigma: f64,
        /// Allowance for the simulated composition added to a squareness tolerance, rad.
        #[serde(default)]
        bias: f64,
        /// Allowance added to an angular error motion's tolerance, rad (default `bias`).
        #[serde(default)]
        bias_angle: Option<f64>,
    },
}

impl EstimatorSpec {
    /// Checks the estimator's tolerances and thresholds: each finite and ≥ 0 (a negative or NaN
    /// tolerance is bad input, not a missed estimate). Returns the key and message of the first problem.
    pub fn check(&self) -> Result<(), (String, String)> {
        let values: Vec<(&str, f64)> = match self {
            EstimatorSpec::Iso230_2 { tolerance, .. }
            | EstimatorSpec::ModelCheck { tolerance, .. }
            | EstimatorSpec::AccelStraightness { tolerance, .. } => vec![("tolerance", *tolerance)],
            EstimatorSpec::LaserLines { tolerance_translation, tolerance_angle, .. } => {
                vec![("tolerance_translation", *tolerance_translation), ("tolerance_angle", *tolerance_angle)]
            }
            EstimatorSpec::Compensation { max_ratio, pearson, residual, .. } => {
                vec![("max_ratio", *max_ratio), ("pearson", *pearson), ("residual", *residual)]
            }
            EstimatorSpec::Ssi { expected, tolerance, .. } => {
                expected.iter().map(|v| ("expected", *v)).chain(tolerance.iter().map(|v| ("tolerance", *v))).collect()
            }
            EstimatorSpec::LaserLines3d { k_sigma, bias, bias_angle, .. } => {
                let mut v = vec![("k_sigma", *k_sigma), ("bias", *bias)];
                v.extend(bias_angle.map(|b| ("bias_angle", b)));
                v
            }
        };
        match values.iter().find(|(_, v)| !(v.is_finite() && *v >= 0.0)) {
            Some((k, v)) => Err((k.to_string(), format!("expected a finite value ≥ 0, got {v}"))),
            None => Ok(()),
        }
    }
}

fn default_k_sigma() -> f64 {
    4.0
}

fn default_steps() -> usize {
    3
}

fn default_max_ratio() -> f64 {
    0.3
}
fn default_pearson() -> f64 {
    0.98
}
fn default_residual() -> f64 {
    0.5e-6
}
