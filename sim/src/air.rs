//! Refractive index of air for laser interferometry: the updated Edlén equation (Birch & Downs 1993,
//! corrected 1994), with the saturation vapour pressure of water from the IAPWS formulation as used by
//! the NIST "Engineering Metrology Toolbox" (Stone & Zimmerman). A laser that counts fringes in air of
//! index n_actual but converts them with n_assumed reads L·n_actual/n_assumed.

use serde::{Deserialize, Serialize};

/// Air conditions.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Air {
    /// Temperature, °C.
    pub temperature: f64,
    /// Pressure, Pa.
    pub pressure: f64,
    /// Relative humidity, %.
    pub humidity: f64,
}

impl Air {
    /// 20 °C, 101 325 Pa, 50 % RH: the reference conditions of dimensional metrology.
    pub const REFERENCE: Air = Air { temperature: 20.0, pressure: 101_325.0, humidity: 50.0 };
}

/// Vacuum wavelength of the stabilised He-Ne laser, µm.
pub const HENE_WAVELENGTH_UM: f64 = 0.632_991;

/// Saturation vapour pressure of water over liquid water, Pa, at temperature t (°C) (IAPWS-IF97
/// equation as in the NIST toolbox).
pub fn saturation_vapour_pressure(t: f64) -> f64 {
    const K: [f64; 10] = [
        1.16705214528E+03,
        -7.24213167032E+05,
        -1.70738469401E+01,
        1.20208247025E+04,
        -3.23255503223E+06,
        1.49151086135E+01,
        -4.82326573616E+03,
        4.05113405421E+05,
        -2.38555575678E-01,
        6.50175348448E+02,
    ];
    let tk = t + 273.15;
    let o = tk + K[8] / (tk - K[9]);
    let a = o * o + K[0] * o + K[1];
    let b = K[2] * o * o + K[3] * o + K[4];
    let c = K[5] * o * o + K[6] * o + K[7];
    let x = -b + (b * b - 4.0 * a * c).sqrt();
    1e6 * (2.0 * c / x).powi(4)
}

/// Refractive index n of moist air for vacuum wavelength λ (µm), updated Edlén equation:
/// (n−1)_s = [8342.54 + 2406147/(130 − σ²) + 15998/(38.9 − σ²)]·1e-8, σ = 1/λ (µm⁻¹);
/// (n−1)_tp = p·(n−1)_s/96095.43 · [1 + 1e-8·(0.601 − 0.00972·t)·p]/(1 + 0.0036610·t);
/// n − 1 = (n−1)_tp − f·(3.7345 − 0.0401·σ²)·1e-10, f = RH/100 · p_sv(t) (Pa).
pub fn edlen_index(air: &Air, wavelength_um: f64) -> f64 {
    let s2 = (1.0 / wavelength_um).powi(2);
    let ns = (8342.54 + 2_406_147.0 / (130.0 - s2) + 15998.0 / (38.9 - s2)) * 1e-8;
    let (t, p) = (air.temperature, air.pressure);
    let ntp = p * ns / 96095.43 * (1.0 + 1e-8 * (0.601 - 0.00972 * t) * p) / (1.0 + 0.003_661_0 * t);
    let f = air.humidity / 100.0 * saturation_vapour_pressure(t);
    1.0 + ntp - f * (3.7345 - 0.0401 * s2) * 1e-10
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn edlen_at_reference_conditions_matches_the_hand_worked_value() {
        // Worked by hand (σ² = 1/0.632991² = 2.495772 µm⁻²):
        // (n−1)_s = 2.765311e-4; (n−1)_tp = 101325·2.765311e-4/96095.43·(1 + 1e-8·0.4066·101325)/1.07322
        //         = 2.717991e-4; p_sv(20 °C) = 2339.21 Pa, f = 1169.61 Pa;
        // n − 1 = 2.717991e-4 − 1169.61·(3.7345 − 0.1001)·1e-10 = 2.713740e-4
        // (NIST's Edlén calculator prints 1.00027137 for these conditions).
        let n = edlen_index(&Air::REFERENCE, HENE_WAVELENGTH_UM);
        assert!((n - 1.0 - 2.713740e-4).abs() < 5e-10, "n − 1 = {:e}", n - 1.0);
        assert!((saturation_vapour_pressure(20.0) - 2339.21).abs() < 0.05);
    }

    #[test]
    fn warmer_air_has_a_lower_index() {
        // About −0.93 ppm per kelvin near 20 °C (the usual rule of thumb).
        let warm = Air { temperature: 21.0, ..Air::REFERENCE };
        let d = edlen_index(&warm, HENE_WAVELENGTH_UM) - edlen_index(&Air::REFERENCE, HENE_WAVELENGTH_UM);
        assert!((d / 1e-6 + 0.93).abs() < 0.05, "dn/dT = {d:e}");
    }
}
