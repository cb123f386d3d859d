//! What the physics tests share: the bundled slide_column machine and the real third-party data.

#[path = "../../../tests/util/realdata.rs"]
pub mod realdata;

use vmt_sim::machine::{AxisConfig, AxisModel};
use vmt_sim::urdf::parse_urdf;

/// The bundled urdf/slide_column.urdf machine with the default axis configuration.
pub fn slide_column() -> AxisModel {
    let text = std::fs::read_to_string(concat!(env!("CARGO_MANIFEST_DIR"), "/../urdf/slide_column.urdf")).unwrap();
    AxisModel::build(&parse_urdf(&text).unwrap(), &AxisConfig::default()).unwrap()
}
