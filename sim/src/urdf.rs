//! Machine structure from URDF: links joined by fixed joints merged into rigid bodies, prismatic joints
//! kept as axes (guideways). Unknown tags are ignored and meshes are never loaded (no collision
//! geometry is needed); a malformed structure is rejected with an error that names the link or joint.

use rapier3d_f64::glamx::{DMat3, DQuat, DVec3};
use std::collections::{BTreeMap, HashMap};

/// Why a URDF could not be turned into a machine.
#[derive(Debug, thiserror::Error, PartialEq)]
pub enum UrdfError {
    /// The text is not well-formed URDF XML (the parser's message).
    #[error("not a readable URDF: {0}")]
    Parse(String),
    /// A joint that breaks a rule.
    #[error("joint `{joint}`: {what}")]
    Joint {
        /// Joint name.
        joint: String,
        /// What is wrong and what was expected.
        what: String,
    },
    /// A link that breaks a rule.
    #[error("link `{link}`: {what}")]
    Link {
        /// Link name.
        link: String,
        /// What is wrong and what was expected.
        what: String,
    },
    /// The tree as a whole is unusable (no root, a cycle, a link with two parents, …).
    #[error("structure: {0}")]
    Structure(String),
}

/// A rigid placement: x_parent = rotation·x_child + translation.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Frame {
    /// Origin of the child frame in the parent frame, m.
    pub translation: DVec3,
    /// Rotation of the child frame's axes into the parent's.
    pub rotation: DQuat,
}

impl Frame {
    /// The identity placement (child frame = parent frame).
    pub const IDENTITY: Frame = Frame { translation: DVec3::ZERO, rotation: DQuat::IDENTITY };

    /// URDF origin: translation xyz (m) and fixed-axis roll, pitch, yaw (rad): R = Rz(y)·Ry(p)·Rx(r).
    pub fn from_xyz_rpy(xyz: [f64; 3], rpy: [f64; 3]) -> Frame {
        let rotation = DQuat::from_rotation_z(rpy[2]) * DQuat::from_rotation_y(rpy[1]) * DQuat::from_rotation_x(rpy[0]);
        Frame { translation: DVec3::from_array(xyz), rotation }
    }

    /// Composition: (self ∘ child) maps child coordinates to self's parent coordinates.
    pub fn compose(&self, child: &Frame) -> Frame {
        Frame {
            translation: self.translation + self.rotation * child.translation,
            rotation: self.rotation * child.rotation,
        }
    }

    /// A point given in child coordinates, in parent coordinates: rotation·p + translation (m).
    pub fn transform_point(&self, p: DVec3) -> DVec3 {
        self.translation + self.rotation * p
    }
}

/// Mass properties of a body, in the body frame.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct MassProps {
    /// kg
    pub mass: f64,
    /// Centre of mass, m, body frame.
    pub com: DVec3,
    /// Inertia tensor about the centre of mass, kg·m², body-frame axes.
    pub inertia: DMat3,
}

impl MassProps {
    /// No mass (the neutral element of [`MassProps::combine`]).
    pub const ZERO: MassProps = MassProps { mass: 0.0, com: DVec3::ZERO, inertia: DMat3::ZERO };

    /// Combines two sets of mass properties expressed in the same frame (parallel-axis theorem:
    /// I = Σ [I_i + m_i·(|d_i|²·1 − d_i·d_iᵀ)], d_i = com_i − com).
    pub fn combine(&self, other: &MassProps) -> MassProps {
        let mass = self.mass + other.mass;
        if mass <= 0.0 {
            return MassProps::ZERO;
        }
        let com = (self.com * self.mass + other.com * other.mass) / mass;
        let shift = |m: f64, d: DVec3| {
            m * (DMat3::from_diagonal(DVec3::splat(d.length_squared())) - DMat3::from_cols(d * d.x, d * d.y, d * d.z))
        };
        let inertia =
            self.inertia + shift(self.mass, self.com - com) + other.inertia + shift(other.mass, other.com - com);
        MassProps { mass, com, inertia }
    }

    /// The same properties seen in a parent frame.
    pub fn transformed(&self, f: &Frame) -> MassProps {
        let r = DMat3::from_quat(f.rotation);
        MassProps { mass: self.mass, com: f.transform_point(self.com), inertia: r * self.inertia * r.transpose() }
    }
}

/// A rigid body: links welded by fixed joints. Its frame is the frame of its first (root) link.
#[derive(Clone, Debug)]
pub struct Body {
    /// Name of the body's root link.
    pub name: String,
    /// Each link of the body with its placement in the body frame.
    pub links: Vec<(String, Frame)>,
    /// Mass properties of all its links combined, body frame.
    pub mass: MassProps,
}

impl Body {
    /// Placement of `link` in the body frame; `None` if the link is not part of this body.
    pub fn link_frame(&self, link: &str) -> Option<Frame> {
        self.links.iter().find(|(n, _)| n == link).map(|(_, f)| *f)
    }
}

/// A prismatic joint: the child body slides along `axis` relative to the parent body.
#[derive(Clone, Debug)]
pub struct PrismaticAxis {
    /// Joint name in the URDF.
    pub joint: String,
    /// Index of the parent (fixed-side) body in [`MachineStructure::bodies`].
    pub parent: usize,
    /// Index of the child (moving) body in [`MachineStructure::bodies`].
    pub child: usize,
    /// Placement of the child body frame in the parent body frame at joint position 0.
    pub origin: Frame,
    /// Unit direction of motion, in the parent body frame.
    pub axis: DVec3,
    /// Lower travel limit, m.
    pub lower: f64,
    /// Upper travel limit, m.
    pub upper: f64,
    /// URDF `<dynamics damping>`: viscous damping along the axis, N·s/m, zero where absent.
    pub damping: f64,
    /// URDF `<dynamics friction>`: Coulomb friction along the axis, N, zero where absent.
    pub friction: f64,
    /// URDF `<limit effort>`: largest drive force, N.
    pub effort: f64,
    /// URDF `<limit velocity>`: largest speed, m/s.
    pub velocity: f64,
}

/// The structure of a machine: bodies and the prismatic axes joining them. Body 0 is the base.
#[derive(Clone, Debug)]
pub struct MachineStructure {
    /// The URDF `<robot name>`.
    pub name: String,
    /// Rigid bodies (links welded by fixed joints); body 0 is the base.
    pub bodies: Vec<Body>,
    /// The prismatic joints between bodies, in URDF order.
    pub axes: Vec<PrismaticAxis>,
}

impl MachineStructure {
    /// The prismatic axis of the joint named `joint`, if any.
    pub fn axis_by_joint(&self, joint: &str) -> Option<&PrismaticAxis> {
        self.axes.iter().find(|a| a.joint == joint)
    }

    /// Index of the body that contains `link`, if any.
    pub fn body_of_link(&self, link: &str) -> Option<usize> {
        self.bodies.iter().position(|b| b.links.iter().any(|(n, _)| n == link))
    }
}

/// Deepest XML element nesting a URDF may have (a URDF is robot → link → visual → geometry → mesh:
/// 5 levels); the XML deserialiser recurses per level, so a deeply nested file would overflow the stack.
pub const MAX_XML_DEPTH: usize = 64;
/// Most XML elements a URDF may have (size budget, DESIGN.md §2).
pub const MAX_XML_ELEMENTS: usize = 200_000;

/// Bounds the XML nesting depth and element count before deserialising: a scan of the tags
/// (`<name` opens, `</` and `/>` close; comments, `<?…?>` and `<!…>` skipped). The error names the
/// line where the limit is crossed.
pub fn check_xml_size(text: &str) -> Result<(), UrdfError> {
    let b = text.as_bytes();
    let (mut depth, mut elements, mut i) = (0usize, 0usize, 0usize);
    let line = |pos: usize| b[..pos].iter().filter(|&&c| c == b'\n').count() + 1;
    while let Some(off) = b[i..].iter().position(|&c| c == b'<') {
        let start = i + off;
        let rest = &b[start..];
        let close_of = |pat: &[u8]| rest.windows(pat.len()).position(|w| w == pat).map(|p| start + p + pat.len());
        let end = if rest.starts_with(b"<!--") {
            close_of(b"-->")
        } else if rest.starts_with(b"<?") {
            close_of(b"?>")
        } else {
            let e = close_of(b">");
            if rest.starts_with(b"</") {
                depth = depth.saturating_sub(1);
            } else if !rest.starts_with(b"<!") {
                let self_closing = e.is_some_and(|e| e >= 2 && b[e - 2] == b'/');
                elements += 1;
                if !self_closing {
                    depth += 1;
                }
                if depth > MAX_XML_DEPTH || elements > MAX_XML_ELEMENTS {
                    return Err(UrdfError::Parse(format!(
                        "line {}: XML nested {depth} elements deep with {elements} elements so far; the limits are {MAX_XML_DEPTH} levels and {MAX_XML_ELEMENTS} elements",
                        line(start)
                    )));
                }
            }
            e
        };
        match end {
            Some(e) => i = e,
            None => break,
        }
    }
    Ok(())
}

/// Attributes that URDF reads as numbers (one, or three/six separated by spaces).
const NUMERIC_ATTRIBUTES: &[&str] = &[
    "value", "xyz", "rpy", "ixx", "ixy", "ixz", "iyy", "iyz", "izz", "lower", "upper", "effort", "velocity", "damping",
    "friction", "radius", "length", "size", "scale",
];

/// Where a URDF that the XML deserialiser refused goes wrong, for its message (issue 14: URDF errors
/// carried no line, e.g. `custom: invalid float literal`): the line of a number attribute that is not
/// a number, of a closing tag that does not match the open element, or of the element the file ends
/// inside. None when the scan finds nothing (the deserialiser's own message is used then).
pub fn locate_xml_error(text: &str) -> Option<String> {
    let b = text.as_bytes();
    let line = |pos: usize| b[..pos].iter().filter(|&&c| c == b'\n').count() + 1;
    let mut open: Vec<(&str, usize)> = Vec::new();
    let mut i = 0;
    while let Some(off) = text[i..].find('<') {
        let start = i + off;
        let rest = &text[start..];
        let skip = |pat: &str| rest.find(pat).map(|p| start + p + pat.len());
        if rest.starts_with("<!--") {
            i = skip("-->")?;
            continue;
        }
        if rest.starts_with("<?") || rest.starts_with("<!") {
            i = skip(">")?;
            continue;
        }
        let Some(end) = skip(">") else {
            return Some(format!("line {}: a tag that is never closed with `>`", line(start)));
        };
        // index: `end` is just past the first `>` after this `<`, so start + 1 ≤ end − 1.
        let tag = &text[start + 1..end - 1];
        if let Some(name) = tag.strip_prefix('/') {
            let name = name.trim();
            match open.pop() {
                Some((n, _)) if n == name => {}
                Some((n, at)) => {
                    return Some(format!("line {}: `</{name}>` closes `<{n}>` opened at line {at}", line(start)))
                }
                None => return Some(format!("line {}: `</{name}>` closes no open element", line(start))),
            }
        } else {
            let self_closing = tag.ends_with('/');
            let tag = tag.trim_end_matches('/');
            let name = tag.split_whitespace().next().unwrap_or("");
            // name="value" pairs; a value in single or double quotes.
            let mut attrs = tag[name.len()..].trim_start();
            while let Some(eq) = attrs.find('=') {
                let key = attrs[..eq].trim();
                let v = attrs[eq + 1..].trim_start();
                let Some(q) = v.chars().next().filter(|c| *c == '"' || *c == '\'') else { break };
                let Some(close) = v[1..].find(q) else { break };
                let value = &v[1..1 + close];
                if NUMERIC_ATTRIBUTES.contains(&key) && value.split_whitespace().any(|t| t.parse::<f64>().is_err()) {
                    return Some(format!("line {}: <{name} {key}=\"{value}\">: expected numbers", line(start)));
                }
                attrs = v[1 + close + 1..].trim_start();
            }
            if !self_closing {
                open.push((name, line(start)));
            }
        }
        i = end;
    }
    open.last().map(|(n, at)| format!("the file ends inside `<{n}>` opened at line {at}"))
}

fn finite3(v: [f64; 3]) -> bool {
    v.iter().all(|x| x.is_finite())
}

/// Reads a machine structure from URDF text. Links without `<inertial>` have no mass (kinematic-only
/// URDFs load; simulating an axis whose moving body has no mass is refused by `AxisModel::build`).
/// Revolute, continuous and other joints are accepted but
/// treated as fixed (vmt simulates linear axes); prismatic joints become axes.
pub fn parse_urdf(text: &str) -> Result<MachineStructure, UrdfError> {
    check_xml_size(text)?;
    let robot = urdf_rs::read_from_string(text)
        .map_err(|e| UrdfError::Parse(locate_xml_error(text).unwrap_or_else(|| e.to_string())))?;
    let mut link_index: HashMap<&str, usize> = HashMap::new();
    for (i, l) in robot.links.iter().enumerate() {
        if link_index.insert(l.name.as_str(), i).is_some() {
            return Err(UrdfError::Link { link: l.name.clone(), what: "defined twice".into() });
        }
    }
    if robot.links.is_empty() {
        return Err(UrdfError::Structure("the URDF has no <link>".into()));
    }
    // Each link's inertial, checked.
    let mut link_mass = Vec::with_capacity(robot.links.len());
    for l in &robot.links {
        let i = &l.inertial;
        let m = i.mass.value;
        let t = &i.inertia;
        let vals = [m, t.ixx, t.ixy, t.ixz, t.iyy, t.iyz, t.izz];
        if !vals.iter().all(|v| v.is_finite()) || !finite3(i.origin.xyz.0) || !finite3(i.origin.rpy.0) {
            return Err(UrdfError::Link { link: l.name.clone(), what: "inertial contains NaN or infinity".into() });
        }
        if m < 0.0 {
            return Err(UrdfError::Link { link: l.name.clone(), what: format!("negative mass {m} kg") });
        }
        let tensor = DMat3::from_cols(
            DVec3::new(t.ixx, t.ixy, t.ixz),
            DVec3::new(t.ixy, t.iyy, t.iyz),
            DVec3::new(t.ixz, t.iyz, t.izz),
        );
        if m > 0.0 && !positive_definite(&tensor) {
            return Err(UrdfError::Link {
                link: l.name.clone(),
                what: format!(
                    "inertia is not positive definite (ixx={} iyy={} izz={} ixy={} ixz={} iyz={})",
                    t.ixx, t.iyy, t.izz, t.ixy, t.ixz, t.iyz
                ),
            });
        }
        let local = MassProps { mass: m, com: DVec3::ZERO, inertia: if m > 0.0 { tensor } else { DMat3::ZERO } };
        link_mass.push(local.transformed(&Frame::from_xyz_rpy(i.origin.xyz.0, i.origin.rpy.0)));
    }
    // Tree: every link has at most one parent joint; exactly one root.
    let mut parent_joint: Vec<Option<usize>> = vec![None; robot.links.len()];
    for (ji, j) in robot.joints.iter().enumerate() {
        let p = *link_index.get(j.parent.link.as_str()).ok_or_else(|| UrdfError::Joint {
            joint: j.name.clone(),
            what: format!("parent link `{}` does not exist", j.parent.link),
        })?;
        let c = *link_index.get(j.child.link.as_str()).ok_or_else(|| UrdfError::Joint {
            joint: j.name.clone(),
            what: format!("child link `{}` does not exist", j.child.link),
        })?;
        if p == c {
            return Err(UrdfError::Joint { joint: j.name.clone(), what: "parent and child are the same link".into() });
        }
        if parent_joint[c].is_some() {
            return Err(UrdfError::Joint {
                joint: j.name.clone(),
                what: format!("link `{}` already has a parent joint", j.child.link),
            });
        }
        if !finite3(j.origin.xyz.0) || !finite3(j.origin.rpy.0) || !finite3(j.axis.xyz.0) {
            return Err(UrdfError::Joint {
                joint: j.name.clone(),
                what: "origin or axis contains NaN or infinity".into(),
            });
        }
        parent_joint[c] = Some(ji);
    }
    let roots: Vec<usize> = (0..robot.links.len()).filter(|&i| parent_joint[i].is_none()).collect();
    if roots.len() != 1 {
        let names: Vec<&str> = roots.iter().map(|&i| robot.links[i].name.as_str()).collect();
        return Err(UrdfError::Structure(if roots.is_empty() {
            "no root link: the joints form a cycle".into()
        } else {
            format!("more than one root link (links without a parent joint): {}", names.join(", "))
        }));
    }
    // Walk from the root; detect cycles (a link unreachable from the root sits on a cycle).
    let mut children: Vec<Vec<usize>> = vec![Vec::new(); robot.links.len()];
    for (ji, j) in robot.joints.iter().enumerate() {
        children[link_index[j.parent.link.as_str()]].push(ji);
    }
    let mut body_of: Vec<Option<usize>> = vec![None; robot.links.len()];
    let mut bodies: Vec<Body> = Vec::new();
    let mut axes: Vec<PrismaticAxis> = Vec::new();
    let root = roots[0];
    bodies.push(Body {
        name: robot.links[root].name.clone(),
        links: vec![(robot.links[root].name.clone(), Frame::IDENTITY)],
        mass: link_mass[root],
    });
    body_of[root] = Some(0);
    let mut stack = vec![root];
    while let Some(l) = stack.pop() {
        let b = body_of[l].expect("visited links have a body");
        let lf = bodies[b].link_frame(&robot.links[l].name).expect("link is in its body");
        for &ji in &children[l] {
            let j = &robot.joints[ji];
            let c = link_index[j.child.link.as_str()];
            if body_of[c].is_some() {
                return Err(UrdfError::Structure(format!("joint `{}` closes a cycle", j.name)));
            }
            let origin = Frame::from_xyz_rpy(j.origin.xyz.0, j.origin.rpy.0);
            if j.joint_type == urdf_rs::JointType::Prismatic {
                let a = DVec3::from_array(j.axis.xyz.0);
                if a.length() < 1e-12 {
                    return Err(UrdfError::Joint { joint: j.name.clone(), what: "axis has zero length".into() });
                }
                let cb = bodies.len();
                bodies.push(Body {
                    name: j.child.link.clone(),
                    links: vec![(j.child.link.clone(), Frame::IDENTITY)],
                    mass: link_mass[c],
                });
                let placed = lf.compose(&origin);
                let (lower, upper) = (j.limit.lower, j.limit.upper);
                if !(lower.is_finite() && upper.is_finite()) || lower > upper {
                    return Err(UrdfError::Joint {
                        joint: j.name.clone(),
                        what: format!("limits lower={lower} upper={upper}: expected finite with lower ≤ upper"),
                    });
                }
                // A machine-tool axis travels metres; profiles and truth tables are sampled over it.
                let max = crate::effects::MAX_LENGTH;
                if lower.abs() > max || upper.abs() > max {
                    return Err(UrdfError::Joint {
                        joint: j.name.clone(),
                        what: format!("limits lower={lower} upper={upper}: expected a travel within ±{max} m"),
                    });
                }
                let dynamics = j.dynamics.clone().unwrap_or(urdf_rs::Dynamics { damping: 0.0, friction: 0.0 });
                axes.push(PrismaticAxis {
                    joint: j.name.clone(),
                    parent: b,
                    child: cb,
                    origin: placed,
                    axis: placed.rotation * a.normalize(),
                    lower,
                    upper,
                    damping: dynamics.damping,
                    friction: dynamics.friction,
                    effort: j.limit.effort,
                    velocity: j.limit.velocity,
                });
                body_of[c] = Some(cb);
            } else {
                let placed = lf.compose(&origin);
                bodies[b].links.push((j.child.link.clone(), placed));
                bodies[b].mass = bodies[b].mass.combine(&link_mass[c].transformed(&placed));
                body_of[c] = Some(b);
            }
            stack.push(c);
        }
    }
    if let Some(l) = (0..robot.links.len()).find(|&i| body_of[i].is_none()) {
        return Err(UrdfError::Structure(format!(
            "link `{}` is not connected to the root (cycle)",
            robot.links[l].name
        )));
    }
    Ok(MachineStructure { name: robot.name.clone(), bodies, axes })
}

/// Sylvester's criterion on a symmetric 3×3 matrix.
pub(crate) fn positive_definite(m: &DMat3) -> bool {
    let a = m.to_cols_array_2d();
    let d1 = a[0][0];
    let d2 = a[0][0] * a[1][1] - a[0][1] * a[1][0];
    d1 > 0.0 && d2 > 0.0 && m.determinant() > 0.0
}

/// Names of the links by body, for messages.
pub fn describe(m: &MachineStructure) -> BTreeMap<String, Vec<String>> {
    m.bodies.iter().map(|b| (b.name.clone(), b.links.iter().map(|(n, _)| n.clone()).collect())).collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    const TWO_LINKS: &str = r#"<robot name="r">
      <link name="base"/>
      <link name="cart"><inertial><mass value="2"/><inertia ixx="1" ixy="0" ixz="0" iyy="1" iyz="0" izz="1"/></inertial></link>
      <link name="top"><inertial><origin xyz="0 0 1"/><mass value="2"/><inertia ixx="1" ixy="0" ixz="0" iyy="1" iyz="0" izz="1"/></inertial></link>
      <joint name="slide" type="prismatic"><parent link="base"/><child link="cart"/><axis xyz="1 0 0"/><limit lower="0" upper="1" effort="10" velocity="1"/><dynamics damping="3" friction="4"/></joint>
      <joint name="weld" type="fixed"><parent link="cart"/><child link="top"/></joint>
      <unknown_tag foo="bar"/>
    </robot>"#;

    #[test]
    fn fixed_links_merge_with_the_parallel_axis_theorem() {
        let m = parse_urdf(TWO_LINKS).unwrap();
        assert_eq!(m.bodies.len(), 2);
        let cart = &m.bodies[m.axes[0].child];
        assert_eq!(cart.mass.mass, 4.0);
        assert!((cart.mass.com - DVec3::new(0.0, 0.0, 0.5)).length() < 1e-15);
        // Hand-worked: Ixx = 1 + 1 + 2·0.5² + 2·0.5² = 3; Izz = 2 (no offset about z).
        assert!((cart.mass.inertia.x_axis.x - 3.0).abs() < 1e-12);
        assert!((cart.mass.inertia.z_axis.z - 2.0).abs() < 1e-12);
        assert_eq!((m.axes[0].damping, m.axes[0].friction), (3.0, 4.0));
    }

    #[test]
    fn missing_parent_link_is_named() {
        let bad = TWO_LINKS.replace(r#"<parent link="cart"/>"#, r#"<parent link="nowhere"/>"#);
        let e = parse_urdf(&bad).unwrap_err().to_string();
        assert!(e.contains("weld") && e.contains("nowhere"), "{e}");
    }

    #[test]
    fn a_cycle_is_rejected() {
        let bad = TWO_LINKS.replace(
            "<unknown_tag foo=\"bar\"/>",
            r#"<joint name="loop" type="fixed"><parent link="top"/><child link="base"/></joint>"#,
        );
        assert!(parse_urdf(&bad).is_err());
    }

    #[test]
    fn a_massless_moving_body_loads_as_structure_but_cannot_be_simulated() {
        // Kinematic-only URDFs (planning models) have no inertials: the structure loads, and
        // simulating such an axis is refused (machine::AxisModel::build).
        let bad = TWO_LINKS.replace(r#"<mass value="2"/>"#, r#"<mass value="0"/>"#);
        let m = parse_urdf(&bad).unwrap();
        let e = crate::machine::AxisModel::build(
            &m,
            &crate::machine::AxisConfig { joint: "slide".into(), ..Default::default() },
        )
        .unwrap_err()
        .to_string();
        assert!(e.contains("cart") && e.contains("positive mass"), "{e}");
    }

    #[test]
    fn non_positive_definite_inertia_and_nan_are_rejected() {
        let bad = TWO_LINKS.replacen(r#"ixx="1""#, r#"ixx="-1""#, 1);
        assert!(parse_urdf(&bad).unwrap_err().to_string().contains("positive definite"));
        let nan = TWO_LINKS.replacen(r#"<mass value="2"/>"#, r#"<mass value="NaN"/>"#, 1);
        assert!(parse_urdf(&nan).is_err());
    }
}
