//! Validation of numeric inputs shared by the estimators and the DSP building blocks ([`crate::dsp`]):
//! one error type whose message says what was expected (`time step dt must be > 0, got -1`).

/// Errors of the accelerometer-straightness estimator and the DSP building blocks: the message says what
/// was expected.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum AccelStraightnessError {
    /// A number was NaN or infinite.
    #[error("{what} must be a finite number, got {value}")]
    NotFinite {
        /// Which input.
        what: String,
        /// The offending value.
        value: f64,
    },
    /// A number that must be strictly positive was not.
    #[error("{what} must be > 0, got {value}")]
    NotPositive {
        /// Which input.
        what: String,
        /// The offending value.
        value: f64,
    },
    /// Any other input that does not fit (too short, inconsistent lengths, frequency above Nyquist...).
    #[error("{0}")]
    BadInput(String),
}

/// Result of the estimator and DSP functions.
pub(crate) type Result<T> = std::result::Result<T, AccelStraightnessError>;

pub(crate) fn finite(what: &str, value: f64) -> Result<f64> {
    if value.is_finite() {
        Ok(value)
    } else {
        Err(AccelStraightnessError::NotFinite { what: what.to_string(), value })
    }
}

pub(crate) fn positive(what: &str, value: f64) -> Result<f64> {
    finite(what, value)?;
    if value > 0.0 {
        Ok(value)
    } else {
        Err(AccelStraightnessError::NotPositive { what: what.to_string(), value })
    }
}

/// Every sample finite; the name of the first bad one (`what[i]`) is formatted only on error.
pub(crate) fn finite_slice(what: &str, xs: &[f64]) -> Result<()> {
    match xs.iter().position(|x| !x.is_finite()) {
        Some(i) => finite(&format!("{what}[{i}]"), xs[i]).map(|_| ()),
        None => Ok(()),
    }
}

pub(crate) fn min_len(what: &str, xs: &[f64], n: usize) -> Result<()> {
    if xs.len() < n {
        return Err(AccelStraightnessError::BadInput(format!("{what} needs at least {n} samples, got {}", xs.len())));
    }
    Ok(())
}
