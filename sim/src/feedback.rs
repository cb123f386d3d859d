//! Errors of the measuring chain the position loop closes on (DESIGN.md §4, FORMAT.md §2): whatever
//! makes the feedback read x_fb = x − e(x, t) for a table at x makes the servo put the table at
//! command + e. The chain is the linear scale in a closed loop, or the screw and rotary encoder in a
//! semi-closed loop (where cyclic lead error and backlash also reach the table).

use crate::effects::{ThermalDrift, ThermalExpansion};
use crate::profile::Profile;

/// The position- and time-dependent error of the feedback chain.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct FeedbackErrors {
    /// Position-dependent part (scale error as a slope, interpolation error and, in a semi-closed loop,
    /// cyclic lead error as harmonics), m.
    pub along: Profile,
    /// Thermal expansion of the scale or screw, δ = α·x·ΔT(t), m; `None`: none.
    pub thermal_expansion: Option<ThermalExpansion>,
    /// Thermal drift of the feedback zero, δ(t) = d∞·(1 − exp(−t/τ)), m; `None`: none.
    pub thermal_drift: Option<ThermalDrift>,
}

impl FeedbackErrors {
    /// True when the chain has no error: [`FeedbackErrors::error`] is +0 at every x and t.
    pub fn is_zero(&self) -> bool {
        self.along.is_zero() && self.thermal_expansion.is_none() && self.thermal_drift.is_none()
    }

    /// e(x, t), m: the table lands at command + e.
    pub fn error(&self, x: f64, t: f64) -> f64 {
        let mut e = if self.along.is_zero() { 0.0 } else { self.along.value(x) };
        if let Some(th) = &self.thermal_expansion {
            e += th.value(x, t);
        }
        if let Some(d) = &self.thermal_drift {
            e += d.value_at(t);
        }
        e
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn thermal_expansion_grows_with_position_and_time() {
        let f = FeedbackErrors {
            thermal_expansion: Some(ThermalExpansion { alpha: 11.5e-6, delta_t: 2.0, tau: 600.0 }),
            ..Default::default()
        };
        // Hand-worked: 11.5e-6 · 0.8 m · 2 K · (1 − e^-1) = 11.63 µm at t = τ.
        assert!((f.error(0.8, 600.0) - 11.5e-6 * 0.8 * 2.0 * (1.0 - (-1.0f64).exp())).abs() < 1e-15);
        assert!(f.error(0.8, 600.0) > f.error(0.4, 600.0) && f.error(0.8, 1200.0) > f.error(0.8, 600.0));
    }
}
