//! Machines and scenarios that ship inside the `vmt` binary, so `vmt run` works from any directory.

/// A bundled machine URDF by name.
pub fn machine_urdf(name: &str) -> Option<&'static str> {
    match name {
        "slide_column" => Some(include_str!("../urdf/slide_column.urdf")),
        "vmc_3axis" => Some(include_str!("../urdf/vmc_3axis.urdf")),
        _ => None,
    }
}

/// Names of the bundled machines.
pub const MACHINES: [&str; 2] = ["slide_column", "vmc_3axis"];

/// The default scenario (`scenarios/default.toml`).
pub const DEFAULT_SCENARIO: &str = include_str!("../scenarios/default.toml");
/// Its path in the source tree, for messages.
pub const DEFAULT_SCENARIO_PATH: &str = "scenarios/default.toml";
