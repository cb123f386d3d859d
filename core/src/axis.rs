//! The three linear axes of vmt's machine frame, as one enum instead of letters.
//!
//! The machine frame is right-handed (ISO 841): X along the bed, Y across it, Z vertical. Files write an
//! axis as its lower-case letter (`axis = "x"`, FORMAT.md); ISO 230-1 names error motions with the
//! upper-case letters and the rotations about X, Y, Z as A, B, C (e.g. EBX, the pitch of X).

use serde::{Deserialize, Serialize};
use std::fmt;

/// A linear machine axis, which is also its nominal direction in the machine frame.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash, Serialize, Deserialize)]
pub enum Axis {
    /// Along the bed, ê = (1, 0, 0).
    X,
    /// ê = (0, 1, 0).
    Y,
    /// Vertical, ê = (0, 0, 1).
    Z,
}

impl Axis {
    /// X, Y, Z in that order (the order of [`Axis::index`]).
    pub const ALL: [Axis; 3] = [Axis::X, Axis::Y, Axis::Z];

    /// Index of the direction: X → 0, Y → 1, Z → 2.
    pub fn index(self) -> usize {
        match self {
            Axis::X => 0,
            Axis::Y => 1,
            Axis::Z => 2,
        }
    }

    /// The letter as files write it: `x`, `y`, `z`.
    pub fn letter(self) -> char {
        match self {
            Axis::X => 'x',
            Axis::Y => 'y',
            Axis::Z => 'z',
        }
    }

    /// The ISO 230-1 letter: `X`, `Y`, `Z`.
    pub fn iso_letter(self) -> char {
        self.letter().to_ascii_uppercase()
    }

    /// The ISO 230-1 letter of a rotation about this axis: A about X, B about Y, C about Z.
    pub fn rotation_letter(self) -> char {
        match self {
            Axis::X => 'A',
            Axis::Y => 'B',
            Axis::Z => 'C',
        }
    }

    /// The axis of a letter (`x`, `y`, `z`, either case); `None` for any other.
    pub fn from_letter(letter: char) -> Option<Axis> {
        match letter.to_ascii_lowercase() {
            'x' => Some(Axis::X),
            'y' => Some(Axis::Y),
            'z' => Some(Axis::Z),
            _ => None,
        }
    }

    /// The axis a prismatic joint moves, by its name's last letter (`x`, `y`, `z`, either case: vmt's
    /// machines name their joints so, e.g. `x` or `column_Z`); `None` for a joint named otherwise.
    pub fn of_joint(joint: &str) -> Option<Axis> {
        joint.chars().last().and_then(Axis::from_letter)
    }

    /// The unit vector of the axis in the machine frame (dimensionless).
    pub fn unit(self) -> [f64; 3] {
        let mut e = [0.0; 3];
        e[self.index()] = 1.0;
        e
    }

    /// The two other axes in x, y, z order: the first and second transverse directions of an error
    /// motion's components (FORMAT.md: X → Y, Z; Y → X, Z; Z → X, Y).
    pub fn transverse(self) -> [Axis; 2] {
        match self {
            Axis::X => [Axis::Y, Axis::Z],
            Axis::Y => [Axis::X, Axis::Z],
            Axis::Z => [Axis::X, Axis::Y],
        }
    }
}

/// Writes the lower-case letter, as files do (`x`).
impl fmt::Display for Axis {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}", self.letter())
    }
}

/// Serde as files write an axis, its lower-case letter (`"x"`), for fields of vmt's file and JSON types:
/// `#[serde(with = "vmt_core::axis::letter")]`. (The derived form of [`Axis`] is its variant name, `"X"`.)
pub mod letter {
    use super::Axis;
    use serde::{de::Error, Deserialize, Deserializer, Serializer};

    /// Writes `Axis::X` as `"x"`.
    pub fn serialize<S: Serializer>(axis: &Axis, s: S) -> Result<S::Ok, S::Error> {
        s.serialize_char(axis.letter())
    }

    /// Reads `"x"`, `"y"` or `"z"` (either case); anything else is an error naming the letters expected.
    pub fn deserialize<'de, D: Deserializer<'de>>(d: D) -> Result<Axis, D::Error> {
        let c = char::deserialize(d)?;
        Axis::from_letter(c)
            .ok_or_else(|| D::Error::custom(format!("expected an axis \"x\", \"y\" or \"z\", got {c:?}")))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn letters_round_trip_and_others_are_refused() {
        for a in Axis::ALL {
            assert_eq!(Axis::from_letter(a.letter()), Some(a));
            assert_eq!(Axis::from_letter(a.iso_letter()), Some(a));
            assert_eq!(a.to_string(), a.letter().to_string());
            assert_eq!(a.unit()[a.index()], 1.0);
            assert!(!a.transverse().contains(&a));
        }
        assert_eq!(Axis::from_letter('w'), None);
        assert_eq!(Axis::Y.rotation_letter(), 'B');
    }
}
