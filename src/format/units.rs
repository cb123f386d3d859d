//! Units of CSV header cells (FORMAT.md §1): `name[unit]`, unit optional (then SI).
//!
//! Units: m, mm, um, nm; s, ms; m/s, mm/s, mm/min; m/s^2, g; rad, mrad, urad, arcsec, deg; N;
//! K, degC; Pa; percent. A value v in unit u is v_SI = v·scale + offset (offset only for degC:
//! K = °C + 273.15). Decimal prefixes divide by an exact power of ten (v/1e6 rather than v·1e-6),
//! so the conversion is a single correctly rounded operation.

use serde::{Deserialize, Serialize};

/// The physical dimension of a column.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Dimension {
    /// m.
    Length,
    /// s.
    Time,
    /// m/s.
    Velocity,
    /// m/s².
    Acceleration,
    /// rad.
    Angle,
    /// N.
    Force,
    /// K.
    Temperature,
    /// Pa.
    Pressure,
    /// Dimensionless ratio (1; `percent` = 0.01).
    Ratio,
}

impl Dimension {
    /// The dimension with its accepted units, for messages: "a length (m, mm, um, nm)".
    pub fn describe(self) -> String {
        let units: Vec<&str> = UNITS.iter().filter(|u| u.dimension == self).map(|u| u.symbol).collect();
        let name = match self {
            Dimension::Length => "a length",
            Dimension::Time => "a time",
            Dimension::Velocity => "a velocity",
            Dimension::Acceleration => "an acceleration",
            Dimension::Angle => "an angle",
            Dimension::Force => "a force",
            Dimension::Temperature => "a temperature",
            Dimension::Pressure => "a pressure",
            Dimension::Ratio => "a ratio",
        };
        format!("{name} ({})", units.join(", "))
    }

    /// The SI unit of the dimension.
    pub fn si(self) -> Unit {
        let sym = match self {
            Dimension::Length => "m",
            Dimension::Time => "s",
            Dimension::Velocity => "m/s",
            Dimension::Acceleration => "m/s^2",
            Dimension::Angle => "rad",
            Dimension::Force => "N",
            Dimension::Temperature => "K",
            Dimension::Pressure => "Pa",
            Dimension::Ratio => "1",
        };
        unit(sym).unwrap_or(Unit { symbol: "1", dimension: self, factor: 1.0, divide: false, offset: 0.0 })
    }
}

/// A unit: v_SI = v·factor + offset (or v/factor + offset when `divide`, for exact powers of
/// ten).
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct Unit {
    /// Symbol as written in headers, e.g. `um`.
    pub symbol: &'static str,
    /// Its dimension.
    pub dimension: Dimension,
    /// Conversion factor (see `divide`).
    pub factor: f64,
    /// True: v_SI = v / factor + offset; false: v_SI = v·factor + offset.
    pub divide: bool,
    /// Additive offset in SI (273.15 K for degC).
    pub offset: f64,
}

const fn u(symbol: &'static str, dimension: Dimension, factor: f64, divide: bool) -> Unit {
    Unit { symbol, dimension, factor, divide, offset: 0.0 }
}

/// Standard gravity, m/s² (CGPM 1901): 1 g = 9.80665 m/s².
pub const STANDARD_GRAVITY: f64 = 9.80665;

/// The unit table of FORMAT.md §1 (plus `1`, the SI unit of a ratio).
pub static UNITS: [Unit; 23] = [
    u("m", Dimension::Length, 1.0, false),
    u("mm", Dimension::Length, 1e3, true),
    u("um", Dimension::Length, 1e6, true),
    u("nm", Dimension::Length, 1e9, true),
    u("s", Dimension::Time, 1.0, false),
    u("ms", Dimension::Time, 1e3, true),
    u("m/s", Dimension::Velocity, 1.0, false),
    u("mm/s", Dimension::Velocity, 1e3, true),
    u("mm/min", Dimension::Velocity, 6e4, true),
    u("m/s^2", Dimension::Acceleration, 1.0, false),
    u("g", Dimension::Acceleration, STANDARD_GRAVITY, false),
    u("rad", Dimension::Angle, 1.0, false),
    u("mrad", Dimension::Angle, 1e3, true),
    u("urad", Dimension::Angle, 1e6, true),
    u("arcsec", Dimension::Angle, 648000.0 / std::f64::consts::PI, true),
    u("deg", Dimension::Angle, 180.0 / std::f64::consts::PI, true),
    u("N", Dimension::Force, 1.0, false),
    u("K", Dimension::Temperature, 1.0, false),
    Unit { symbol: "degC", dimension: Dimension::Temperature, factor: 1.0, divide: false, offset: 273.15 },
    u("Pa", Dimension::Pressure, 1.0, false),
    u("percent", Dimension::Ratio, 100.0, true),
    u("1", Dimension::Ratio, 1.0, false),
    // Alias with the micro sign, common in laser software exports.
    u("µm", Dimension::Length, 1e6, true),
];

/// Looks a unit symbol up (exact, case-sensitive; `µm` accepted for `um`).
pub fn unit(symbol: &str) -> Option<Unit> {
    UNITS.iter().copied().find(|u| u.symbol == symbol)
}

impl Unit {
    /// Converts a value in this unit to SI: v·factor + offset (or v/factor + offset).
    pub fn to_si(&self, v: f64) -> f64 {
        let scaled = if self.divide { v / self.factor } else { v * self.factor };
        // Adding a zero offset would turn −0 into +0: skip it, so SI reads are bit-exact.
        if self.offset == 0.0 {
            scaled
        } else {
            scaled + self.offset
        }
    }

    /// Converts an SI value to this unit, the inverse of [`Unit::to_si`].
    pub fn from_si(&self, si: f64) -> f64 {
        let s = if self.offset == 0.0 { si } else { si - self.offset };
        if self.divide {
            s * self.factor
        } else {
            s / self.factor
        }
    }

    /// True if this is the SI unit (identity conversion).
    pub fn is_si(&self) -> bool {
        self.factor == 1.0 && self.offset == 0.0
    }
}

/// Why a CSV header cell or its unit is refused; the message names the cell or unit and what was
/// expected, the caller adds the file and the place.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum UnitError {
    /// `name[unit` without its `]`.
    #[error("header cell `{cell}`: expected `name[unit]`, the `]` is missing")]
    MissingBracket {
        /// The cell, trimmed.
        cell: String,
    },
    /// `name[unit]text`.
    #[error("header cell `{cell}`: expected `name[unit]`, found text after `]`")]
    TextAfterBracket {
        /// The cell, trimmed.
        cell: String,
    },
    /// `[unit]` with no name.
    #[error("header cell `{cell}`: the column name is empty")]
    EmptyName {
        /// The cell, trimmed.
        cell: String,
    },
    /// `name[]`.
    #[error("header cell `{cell}`: empty unit `[]` (leave the brackets out for SI)")]
    EmptyUnit {
        /// The cell, trimmed.
        cell: String,
    },
    /// A symbol vmt does not know.
    #[error("unknown unit `{symbol}`: expected {}", expected.describe())]
    Unknown {
        /// The symbol as written.
        symbol: String,
        /// The dimension the column must have.
        expected: Dimension,
    },
    /// A known unit of another dimension (`mm` for an angle).
    #[error("unit `{symbol}` is {}, expected {}", found.describe(), expected.describe())]
    WrongDimension {
        /// The symbol as written.
        symbol: String,
        /// Its dimension.
        found: Dimension,
        /// The dimension the column must have.
        expected: Dimension,
    },
}

/// Splits a header cell `name[unit]` into its name and optional unit symbol (both trimmed).
/// Errors on an empty name, a missing `]`, text after it or an empty unit.
pub fn parse_header_cell(cell: &str) -> Result<(String, Option<String>), UnitError> {
    let cell = cell.trim();
    let owned = || cell.to_string();
    let (name, unit) = match cell.find('[') {
        None => (cell, None),
        Some(i) => {
            let rest = &cell[i + 1..];
            let Some(j) = rest.find(']') else {
                return Err(UnitError::MissingBracket { cell: owned() });
            };
            if !rest[j + 1..].trim().is_empty() {
                return Err(UnitError::TextAfterBracket { cell: owned() });
            }
            (cell[..i].trim(), Some(rest[..j].trim().to_string()))
        }
    };
    if name.is_empty() {
        return Err(UnitError::EmptyName { cell: owned() });
    }
    if unit.as_deref() == Some("") {
        return Err(UnitError::EmptyUnit { cell: owned() });
    }
    Ok((name.to_string(), unit))
}

/// Resolves the unit of a column whose values must have dimension `expected`: no unit → SI;
/// an unknown unit or one of another dimension → an error naming the unit and what was
/// expected (the caller adds the file and column).
pub fn resolve_unit(symbol: Option<&str>, expected: Dimension) -> Result<Unit, UnitError> {
    let Some(sym) = symbol else {
        return Ok(expected.si());
    };
    match unit(sym) {
        None => Err(UnitError::Unknown { symbol: sym.to_string(), expected }),
        Some(u) if u.dimension != expected => {
            Err(UnitError::WrongDimension { symbol: sym.to_string(), found: u.dimension, expected })
        }
        Some(u) => Ok(u),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn header_cells_split_into_name_and_unit() {
        assert_eq!(parse_header_cell(" laser_p1[um] ").unwrap(), ("laser_p1".to_string(), Some("um".to_string())));
        assert_eq!(parse_header_cell("t").unwrap(), ("t".to_string(), None));
        assert_eq!(parse_header_cell("x[mm"), Err(UnitError::MissingBracket { cell: "x[mm".into() }));
        assert_eq!(parse_header_cell("[mm]"), Err(UnitError::EmptyName { cell: "[mm]".into() }));
        assert_eq!(parse_header_cell("x[]"), Err(UnitError::EmptyUnit { cell: "x[]".into() }));
        assert_eq!(parse_header_cell("x[mm]y"), Err(UnitError::TextAfterBracket { cell: "x[mm]y".into() }));
    }

    #[test]
    fn conversions_match_hand_worked_numbers() {
        // Exact cases: divisions by powers of ten of values that are exact in binary after the
        // division (0.5 mm = 5e-4 m is not; compare with the correctly rounded literal).
        assert_eq!(unit("mm").unwrap().to_si(0.5), 5e-4);
        assert_eq!(unit("um").unwrap().to_si(3.0), 3e-6);
        assert_eq!(unit("mm/min").unwrap().to_si(60.0), 1e-3);
        assert_eq!(unit("g").unwrap().to_si(1.0), 9.80665);
        assert_eq!(unit("degC").unwrap().to_si(20.0), 293.15);
        assert_eq!(unit("percent").unwrap().to_si(50.0), 0.5);
        // 1 arcsec = π/648000 rad ≈ 4.8481e-6; one rounding in the factor and one in the
        // division: relative error below 4 ulp = 9e-16.
        let a = unit("arcsec").unwrap().to_si(1.0);
        assert!((a / (std::f64::consts::PI / 648000.0) - 1.0).abs() < 9e-16);
        let d = unit("deg").unwrap().to_si(180.0);
        assert!((d - std::f64::consts::PI).abs() < 1e-15);
        // from_si inverts to_si: two roundings of a scaling, relative error ≤ 2 ulp ≈ 4.4e-16.
        for sym in ["mm", "um", "nm", "ms", "mm/min", "g", "urad"] {
            let un = unit(sym).unwrap();
            let v = 12.345;
            assert!((un.from_si(un.to_si(v)) / v - 1.0).abs() < 1e-15, "{sym}");
        }
        // degC goes through 285.495 K: the offset costs absolute precision at the ulp of
        // 285 K (5.7e-14), so the bound is absolute, 2 ulp of 285 K.
        let c = unit("degC").unwrap();
        assert!((c.from_si(c.to_si(12.345)) - 12.345).abs() <= 2.0 * 5.7e-14);
    }

    #[test]
    fn wrong_or_unknown_units_are_rejected_with_the_expected_dimension() {
        let e = resolve_unit(Some("mm"), Dimension::Angle).unwrap_err().to_string();
        assert!(e.contains("`mm` is a length") && e.contains("expected an angle"), "{e}");
        let e = resolve_unit(Some("furlong"), Dimension::Length).unwrap_err().to_string();
        assert!(e.contains("unknown unit `furlong`") && e.contains("um"), "{e}");
        assert_eq!(resolve_unit(None, Dimension::Length).unwrap().symbol, "m");
        assert_eq!(Dimension::Ratio.si().symbol, "1");
    }
}
