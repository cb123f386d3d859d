//! Real third-party URDFs with prismatic joints (shared/realdata/urdf_prismatic/) must load: unknown
//! extension tags are ignored and missing meshes are never opened.

use vmt_sim::urdf::parse_urdf;

use crate::util::realdata;

#[test]
fn every_real_urdf_with_prismatic_joints_loads() {
    let Some(dir) = realdata::realdata("urdf_prismatic", "every_real_urdf_with_prismatic_joints_loads") else {
        return;
    };
    let mut loaded = 0;
    for entry in std::fs::read_dir(&dir).unwrap_or_else(|e| panic!("{}: {e}", dir.display())) {
        let path = entry.unwrap().path();
        if path.extension().and_then(|e| e.to_str()) != Some("urdf") {
            continue;
        }
        let text = std::fs::read_to_string(&path).unwrap();
        let m = parse_urdf(&text).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
        assert!(!m.axes.is_empty(), "{}: no prismatic joint found", path.display());
        println!(
            "{}: {} bodies, prismatic joints {:?}",
            path.file_name().unwrap().to_string_lossy(),
            m.bodies.len(),
            m.axes.iter().map(|a| &a.joint).collect::<Vec<_>>()
        );
        loaded += 1;
    }
    assert!(loaded >= 5, "expected the five real URDFs, found {loaded}");
}

#[test]
fn bundled_machines_load_with_their_axes() {
    for (file, axes) in [("slide_column.urdf", vec!["x"]), ("vmc_3axis.urdf", vec!["x", "y", "z"])] {
        let text = std::fs::read_to_string(std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../urdf").join(file))
            .unwrap();
        let m = parse_urdf(&text).unwrap();
        assert_eq!(m.axes.iter().map(|a| a.joint.as_str()).collect::<Vec<_>>(), axes, "{file}");
    }
}
