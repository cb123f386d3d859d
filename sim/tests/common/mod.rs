// Shared by the physics tests: the bundled slide_column machine.
use vmt_sim::machine::{AxisConfig, AxisModel};
use vmt_sim::urdf::parse_urdf;

pub fn slide_column() -> AxisModel {
    let text = std::fs::read_to_string(concat!(env!("CARGO_MANIFEST_DIR"), "/../urdf/slide_column.urdf")).unwrap();
    AxisModel::build(&parse_urdf(&text).unwrap(), &AxisConfig::default()).unwrap()
}
