//! Statistics of the model-check loop (DESIGN.md §8): the numerical engine of `vmt compare` and
//! `vmt diagnose`.
//!
//! Pure, generic functions on numbers; nothing here knows about measurement sets or physical
//! effects. The caller turns a model's prediction into a residual `r = y − ŷ` (one value per
//! sample, SI units, e.g. metres) with an optional noise standard deviation per sample, and:
//!
//! - [`stats`]: residual statistics for `compare` — RMS, noise-normalised RMS, NRMSE fit
//!   percentage, sample autocorrelation with white-noise bounds, the Ljung–Box test, residual
//!   binned by any key, a noise-sigma estimate from the data;
//! - [`spectrum`]: the one-sided amplitude spectrum of a uniformly sampled residual and a
//!   least-squares (generalised Lomb–Scargle) periodogram for irregular sampling;
//! - [`lsq`]: weighted linear least squares of a residual on signature columns (faer SVD);
//! - [`ortho`]: orthonormal bases of fixed columns reused across a search (variable projection)
//!   and the residual sums of squares of nested series (order choice) from one QR;
//! - [`refine`]: joint Levenberg–Marquardt refinement of nonlinear parameters over variable
//!   projection, with their standard errors;
//! - [`diagnose`]: ranking of candidate effects by ΔBIC with the verdicts `significant`, `noise`,
//!   `inseparable` (FORMAT.md §4 `ranking`), and greedy forward selection.
//!
//! Every public function validates its input (lengths, NaN, positive σ) and returns
//! [`ModelCheckError`] instead of panicking.

pub mod diagnose;
pub mod lsq;
pub mod ortho;
pub mod refine;
pub mod spectrum;
pub mod stats;

pub use diagnose::{
    brent_min, brent_min_each, fit_candidate, forward_select, golden_max, golden_max_each, rank_candidates, Candidate,
    CandidateFit, DiagnoseConfig, Diagnosis, ForwardSelection, HyperParameter, RankingEntry, ResidualInput, Verdict,
};
pub use lsq::{fit_signature, solve_normal, Columns, LinearFit, NormalFactor};
pub use ortho::{
    greedy_rss, greedy_rss_from_products, greedy_rss_with_gram, lstsq_qr, nested_rss, NestedRss, NestedRssWith,
    NestedSeries, OrthoBase, SparseColumn,
};
/// The complex numbers of the spectra (num-complex, through realfft), for callers' phasors.
pub use realfft::num_complex::Complex64;
pub use refine::{refine_projected, refine_projected_point, AheadFn, ProjectedResidualFn, Refined, DIFFERENCE_STEP};
pub use spectrum::{
    amplitude_spectrum, fourier_sums, frequency_grid, ls_periodogram, sinusoid_reductions, sparse_frequency_scan,
    AmplitudeSpectrum, FrequencyScan, Periodogram,
};
pub use stats::{
    autocorrelation, bin_by_edges, bin_by_label, chi_square_isf, chi_square_sf, estimate_noise_sigma, fit_percent,
    ljung_box, normalized_rms, pooled_group_scatter, rms, uniform_edges, Autocorrelation, BinnedResidual, LabelBin,
    LjungBox, RangeBin, MIN_SAMPLES_NOISE_SIGMA,
};

use serde::{Deserialize, Serialize};
use thiserror::Error;

/// Errors of the model-check statistics. Each message says what was expected.
#[derive(Debug, Clone, PartialEq, Error)]
pub enum ModelCheckError {
    /// Fewer samples than the statistic needs.
    #[error("{what}: need at least {need} samples, got {got}")]
    TooFewSamples {
        /// The statistic or input that is short.
        what: String,
        /// Samples it needs.
        need: usize,
        /// Samples it got.
        got: usize,
    },
    /// Fewer samples than [`estimate_noise_sigma`] needs.
    #[error("too little data to estimate the noise sigma: need ≥ {need} samples, got {got}")]
    TooLittleDataForSigma {
        /// Samples it needs ([`MIN_SAMPLES_NOISE_SIGMA`]).
        need: usize,
        /// Samples it got.
        got: usize,
    },
    /// Two inputs that must have one value per sample differ in length.
    #[error("{what} must have {expected} values (one per sample), got {got}")]
    LengthMismatch {
        /// The input whose length is wrong.
        what: String,
        /// Its expected length.
        expected: usize,
        /// Its length.
        got: usize,
    },
    /// A NaN or infinite input value.
    #[error("{what}[{index}] must be a finite number, got {value}")]
    NotFinite {
        /// The input holding the value.
        what: String,
        /// The value's index in it.
        index: usize,
        /// The value.
        value: f64,
    },
    /// A noise standard deviation that is not strictly positive.
    #[error("sigma[{index}] must be positive and finite, got {value}")]
    BadSigma {
        /// The sample's index.
        index: usize,
        /// The σ given for it.
        value: f64,
    },
    /// Any other argument out of its allowed range.
    #[error("invalid argument: {0}")]
    Invalid(String),
    /// A candidate's signature could not be evaluated or fitted.
    #[error("candidate `{effect}`: {message}")]
    Candidate {
        /// The candidate's effect name.
        effect: String,
        /// What went wrong.
        message: String,
    },
    /// A signature that is zero at every sample (e.g. a period aliased to a constant by the
    /// sampling): the hyper-parameter value that produced it is skipped.
    #[error("the signature vanishes on these samples (an alias of a constant)")]
    VanishingSignature,
    /// The residual is zero (below 1e-12 of its norm) after fitting the base columns.
    #[error("the residual is zero after fitting the base columns: nothing to explain")]
    NothingToExplain,
    /// The linear algebra failed (e.g. SVD did not converge).
    #[error("numerical failure: {0}")]
    Numerical(String),
}

/// Noise standard deviation of the residual samples, in the residual's unit (e.g. metres).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Sigma {
    /// No noise level is known: fits are unweighted and ΔBIC uses n·ln(RSS/n).
    Unknown,
    /// One σ for all samples.
    Constant(f64),
    /// One σ per sample.
    PerSample(Vec<f64>),
}

impl Sigma {
    /// Whether a noise level is known (χ² statistics are available).
    pub fn is_known(&self) -> bool {
        match self {
            Sigma::Unknown => false,
            Sigma::Constant(_) | Sigma::PerSample(_) => true,
        }
    }

    /// Weights w_i = 1/σ_i for n samples (all 1 when σ is unknown), validated.
    pub fn weights(&self, n: usize) -> Result<Vec<f64>, ModelCheckError> {
        match self {
            Sigma::Unknown => Ok(vec![1.0; n]),
            Sigma::Constant(s) => {
                check_sigma_value(0, *s)?;
                Ok(vec![1.0 / s; n])
            }
            Sigma::PerSample(v) => {
                check_len("sigma", n, v.len())?;
                v.iter().enumerate().map(|(i, s)| check_sigma_value(i, *s).map(|_| 1.0 / s)).collect()
            }
        }
    }
}

fn check_sigma_value(index: usize, value: f64) -> Result<(), ModelCheckError> {
    if value.is_finite() && value > 0.0 {
        Ok(())
    } else {
        Err(ModelCheckError::BadSigma { index, value })
    }
}

/// Rejects NaN and infinite values, naming the input and the index.
pub(crate) fn check_finite(what: &str, xs: &[f64]) -> Result<(), ModelCheckError> {
    match xs.iter().position(|x| !x.is_finite()) {
        Some(index) => Err(ModelCheckError::NotFinite { what: what.to_string(), index, value: xs[index] }),
        None => Ok(()),
    }
}

pub(crate) fn check_len(what: &str, expected: usize, got: usize) -> Result<(), ModelCheckError> {
    if expected == got {
        Ok(())
    } else {
        Err(ModelCheckError::LengthMismatch { what: what.to_string(), expected, got })
    }
}

pub(crate) fn check_min(what: &str, need: usize, got: usize) -> Result<(), ModelCheckError> {
    if got >= need {
        Ok(())
    } else {
        Err(ModelCheckError::TooFewSamples { what: what.to_string(), need, got })
    }
}
