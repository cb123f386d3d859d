//! vmt-core: the plain types and laws that both the simulator (`vmt-sim`) and the estimators
//! (`vmt-estimators`) need, so that each is written once while the two crates stay independent of each
//! other (the estimators have no physics engine; the simulator runs no estimator). No I/O, no physics
//! engine: equations and small value types only.
//!
//! - [`friction`]: the Stribeck friction law F(v) and its derivatives (the simulator integrates it, the
//!   estimators fit it);
//! - [`axis`]: the machine axes X, Y, Z as an enum (the simulator's chain, the laser-line identifier);
//! - [`named_enum!`]: an enum whose variants have fixed file names, with its list of variants and
//!   their names generated from one row per variant.
#![deny(missing_docs)]

pub mod axis;
pub mod friction;

/// Defines a fieldless enum from rows `Variant = "name",` (each with its doc comment), serialised
/// by those names, and from the same rows `ALL` (every variant in the order of the rows, its length
/// counted, not written) and `as_str` (the name): a new variant is one row. The enum's attributes
/// are written before `enum` and must derive serde's `Serialize`/`Deserialize` (the rows write
/// `#[serde(rename = "name")]`).
///
/// ```
/// use serde::{Deserialize, Serialize};
/// vmt_core::named_enum! {
///     /// A colour.
///     #[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
///     pub enum Colour {
///         /// Red.
///         Red = "red",
///         /// Dark blue.
///         DarkBlue = "dark_blue",
///     }
/// }
/// assert_eq!(Colour::ALL, [Colour::Red, Colour::DarkBlue]);
/// assert_eq!(Colour::DarkBlue.as_str(), "dark_blue");
/// ```
#[macro_export]
macro_rules! named_enum {
    (
        $(#[$meta:meta])* $vis:vis enum $enum:ident {
            $($(#[$doc:meta])* $variant:ident = $name:literal,)*
        }
    ) => {
        $(#[$meta])*
        $vis enum $enum {
            $($(#[$doc])* #[serde(rename = $name)] $variant,)*
        }

        impl $enum {
            /// Every variant, in the order of its definition's rows.
            pub const ALL: [$enum; [$($name),*].len()] = [$($enum::$variant),*];

            /// The name as written in files and reports.
            pub fn as_str(self) -> &'static str {
                match self {
                    $($enum::$variant => $name,)*
                }
            }
        }
    };
}
