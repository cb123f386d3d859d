//! The one Stribeck friction law of vmt (DESIGN.md §4), used by the simulator (`vmt-sim`, which
//! integrates it with sticking) and the estimators (`vmt-estimators`, which fit it to a sweep), so the
//! equation and its derivatives are written once.
//!
//! Steady sliding friction at velocity v (m/s), N, in the Armstrong-Hélouvry (1991) form with shape
//! exponent δ (Canudas de Wit et al. 1995 use δ = 2):
//!
//!   F(v) = sgn(v)·g(v) + Fv·v,   g(v) = Fc + (Fs − Fc)·w(v),   w(v) = exp(−|v/vs|^δ).
//!
//! F is odd in v and has the sign of v (it opposes the motion when applied with a minus sign). At v = 0
//! the static force is undetermined in [−Fs, Fs]; [`StribeckLaw::force`] returns 0 there (sticking is the
//! integrator's business). Coulomb friction is the special case Fs = Fc, Fv = 0; viscous friction alone
//! is Fc = Fs = 0.
//!
//! Sources: B. Armstrong-Hélouvry, *Control of Machines with Friction*, Kluwer 1991; C. Canudas de Wit,
//! H. Olsson, K. J. Åström, P. Lischinsky, "A new model for control of systems with friction", IEEE TAC
//! 40(3):419–425, 1995.

use serde::{Deserialize, Serialize};

/// A friction parameter (or a step input of a friction element) that is NaN, infinite or out of its
/// physical range.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum FrictionError {
    /// A parameter is NaN, infinite or out of its physical range.
    #[error("friction parameter `{name}` must be {expected}, got {value}")]
    BadParameter {
        /// Parameter name as in the TOML (fc, fs, vs, delta, fv, sigma0, ...).
        name: &'static str,
        /// What is expected, in words.
        expected: &'static str,
        /// The offending value.
        value: f64,
    },
}

/// `Ok` when `value` is finite and `ok` holds, else [`FrictionError::BadParameter`] naming `name` and
/// what was `expected`.
pub fn check(name: &'static str, value: f64, ok: bool, expected: &'static str) -> Result<(), FrictionError> {
    if value.is_finite() && ok {
        Ok(())
    } else {
        Err(FrictionError::BadParameter { name, expected, value })
    }
}

fn default_delta() -> f64 {
    2.0
}

/// Stribeck weight w(v) = exp(−|v/vs|^δ) (dimensionless, 1 at rest, → 0 for |v| ≫ vs), for velocity v
/// and Stribeck velocity vs in m/s and shape exponent δ: the share of the static excess Fs − Fc left at
/// speed v, i.e. ∂F/∂Fs = sgn(v)·w(v).
pub fn stribeck_weight(v: f64, vs: f64, delta: f64) -> f64 {
    (-(v / vs).abs().powf(delta)).exp()
}

/// sgn(v) with sgn(0) = 0 (and sgn(NaN) = 0): the sign of the dry friction at velocity v, unlike
/// `f64::signum`, which gives +1 at +0.
pub fn sign(v: f64) -> f64 {
    if v > 0.0 {
        1.0
    } else if v < 0.0 {
        -1.0
    } else {
        0.0
    }
}

/// The parameters of the Stribeck law F(v) = sgn(v)·[Fc + (Fs − Fc)·exp(−|v/vs|^δ)] + Fv·v (module doc).
/// Serialized with these field names; `delta` defaults to 2 and `fv` to 0.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct StribeckLaw {
    /// Coulomb (dry, kinetic) level Fc, N (≥ 0).
    pub fc: f64,
    /// Static (break-away) level Fs, N (≥ Fc).
    pub fs: f64,
    /// Stribeck velocity vs, m/s (> 0).
    pub vs: f64,
    /// Shape exponent δ (> 0, typically 0.5…2; the LuGre paper uses 2). Default 2.
    #[serde(default = "default_delta")]
    pub delta: f64,
    /// Viscous coefficient Fv, N·s/m (≥ 0).
    #[serde(default)]
    pub fv: f64,
}

/// Index of each parameter in [`StribeckLaw::to_array`] and in the gradient of
/// [`StribeckLaw::force_and_gradient`]: Fc, Fs, vs, δ, Fv.
pub const PARAMETER_NAMES: [&str; 5] = ["fc", "fs", "vs", "delta", "fv"];

impl StribeckLaw {
    /// Checks 0 ≤ Fc ≤ Fs, vs > 0, δ > 0, Fv ≥ 0, all finite.
    pub fn validate(&self) -> Result<(), FrictionError> {
        // The conditions below, tested at once for the common case (a simulator validates its law every
        // step); any failure goes through the named checks for the message.
        let finite = [self.fc, self.fs, self.vs, self.delta, self.fv].iter().all(|v| v.is_finite());
        if finite && self.fc >= 0.0 && self.fs >= self.fc && self.vs > 0.0 && self.delta > 0.0 && self.fv >= 0.0 {
            return Ok(());
        }
        check("fc", self.fc, self.fc >= 0.0, "finite and >= 0 N")?;
        check("fs", self.fs, self.fs >= self.fc, "finite and >= fc")?;
        check("vs", self.vs, self.vs > 0.0, "finite and > 0 m/s")?;
        check("delta", self.delta, self.delta > 0.0, "finite and > 0")?;
        check("fv", self.fv, self.fv >= 0.0, "finite and >= 0 N*s/m")
    }

    /// Coulomb friction F = Fc·sgn(v) as a Stribeck law (Fs = Fc, Fv = 0; vs and δ then do not matter).
    pub fn coulomb(fc: f64) -> StribeckLaw {
        StribeckLaw { fc, fs: fc, vs: 1.0, delta: 2.0, fv: 0.0 }
    }

    /// The parameters as [Fc, Fs, vs, δ, Fv] (order of [`PARAMETER_NAMES`]).
    pub fn to_array(self) -> [f64; 5] {
        [self.fc, self.fs, self.vs, self.delta, self.fv]
    }

    /// The law from [Fc, Fs, vs, δ, Fv] (order of [`PARAMETER_NAMES`]).
    pub fn from_array(a: [f64; 5]) -> StribeckLaw {
        StribeckLaw { fc: a[0], fs: a[1], vs: a[2], delta: a[3], fv: a[4] }
    }

    /// Stribeck level g(v) = Fc + (Fs − Fc)·exp(−|v/vs|^δ), N: the magnitude of the dry part at velocity
    /// v (m/s). Equals Fs at v = 0 and tends to Fc for |v| ≫ vs. The LuGre model's g(v).
    pub fn level(&self, v: f64) -> f64 {
        if self.fs == self.fc && self.fc.is_finite() && !(v / self.vs).is_nan() && !self.delta.is_nan() {
            // Coulomb (Fs = Fc finite): Fs − Fc = +0, and w = exp(−|v/vs|^δ) is in [0, 1] (never NaN
            // when v/vs and δ are not), so the excess is +0 and the level is Fc + 0 — the same bits
            // as the full expression, without its powf and exp.
            return self.fc + 0.0;
        }
        self.fc + (self.fs - self.fc) * stribeck_weight(v, self.vs, self.delta)
    }

    /// Steady sliding friction F(v) = sgn(v)·g(v) + Fv·v, N, at velocity v (m/s); 0 at v = 0 exactly.
    /// No parameter checks ([`StribeckLaw::validate`] does them).
    pub fn force(&self, v: f64) -> f64 {
        if v == 0.0 {
            return 0.0;
        }
        v.signum() * self.level(v) + self.fv * v
    }

    /// F(v) as [`StribeckLaw::force`] and its gradient with respect to [Fc, Fs, vs, δ, Fv], with
    /// s = sgn(v) (0 at v = 0), u = |v|/vs, w = exp(−u^δ):
    /// ∂F/∂Fc = s·(1 − w), ∂F/∂Fs = s·w, ∂F/∂vs = s·(Fs − Fc)·w·δ·u^δ/vs (N·s/m),
    /// ∂F/∂δ = −s·(Fs − Fc)·w·u^δ·ln u (0 at u = 0), ∂F/∂Fv = v.
    pub fn force_and_gradient(&self, v: f64) -> (f64, [f64; 5]) {
        let StribeckLaw { fc, fs, vs, delta, fv } = *self;
        let s = sign(v);
        let u = v.abs() / vs;
        let ud = u.powf(delta);
        let w = (-ud).exp();
        let grad = [
            s * (1.0 - w),
            s * w,
            s * (fs - fc) * w * delta * ud / vs,
            if u > 0.0 { -s * (fs - fc) * w * ud * u.ln() } else { 0.0 },
            v,
        ];
        (s * (fc + (fs - fc) * w) + fv * v, grad)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const LAW: StribeckLaw = StribeckLaw { fc: 10.0, fs: 15.0, vs: 0.01, delta: 2.0, fv: 50.0 };

    #[test]
    fn hand_worked_values_and_oddness() {
        // v = vs: g = 10 + 5·e^{-1} = 11.839397; + 50·0.01 = 0.5 → 12.339397 (hand-worked).
        assert!((LAW.force(0.01) - (10.0 + 5.0 * (-1.0f64).exp() + 0.5)).abs() < 1e-12);
        assert_eq!(LAW.force(-0.01), -LAW.force(0.01));
        assert_eq!(LAW.force(0.0), 0.0);
        assert_eq!(LAW.level(0.0), 15.0);
        // Far above vs the Stribeck term vanishes: 10 + 50·1 = 60 (e^{-10000} underflows to 0).
        assert_eq!(LAW.force(1.0), 60.0);
    }

    #[test]
    fn value_and_gradient_agree_with_force_and_with_central_differences() {
        for &v in &[-0.03, -0.004, 0.0007, 0.01, 0.2] {
            let (f, g) = LAW.force_and_gradient(v);
            assert!((f - LAW.force(v)).abs() <= 1e-12 * f.abs().max(1.0), "v = {v}");
            let th = LAW.to_array();
            for k in 0..5 {
                // Central difference with a step 1e-6 of the parameter's scale: truncation error
                // O(h²) ≈ 1e-12 relative, rounding ≈ 1e-16/1e-6 = 1e-10 relative.
                let h = 1e-6 * th[k].abs().max(1e-3);
                let (mut lo, mut hi) = (th, th);
                lo[k] -= h;
                hi[k] += h;
                let d = (StribeckLaw::from_array(hi).force(v) - StribeckLaw::from_array(lo).force(v)) / (2.0 * h);
                assert!(
                    (d - g[k]).abs() <= 1e-6 * d.abs().max(1e-3),
                    "v = {v}, ∂F/∂{}: {d} vs {}",
                    PARAMETER_NAMES[k],
                    g[k]
                );
            }
        }
    }

    #[test]
    fn bad_parameters_name_the_key() {
        let e = StribeckLaw { fs: 5.0, ..LAW }.validate().unwrap_err().to_string();
        assert!(e.contains("fs") && e.contains(">= fc"), "{e}");
        assert!(StribeckLaw { vs: f64::NAN, ..LAW }.validate().is_err());
        assert!(LAW.validate().is_ok() && StribeckLaw::coulomb(3.0).validate().is_ok());
    }
}
