//! The six error motions of a linear axis (ISO 230-1) and the first-order deviation they cause.
//!
//! For the X axis: EXX (positioning), EYX, EZX (straightness), EAX, EBX, ECX (roll, pitch, yaw), each a
//! function of the axis position, defined at the axis reference point. Small-angle, first-order model
//! (DESIGN.md §2): the deviation of a point r on the moving body (r from the reference point, axis frame) is
//! δ(r) = [EXX, EYX, EZX] + [EAX, EBX, ECX] × r.

use crate::profile::Profile;
use rapier3d_f64::glamx::DVec3;

/// The six error motions of one axis, as functions of the axis position (m → m or rad).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct ErrorMotions {
    /// EXX, m
    pub positioning: Profile,
    /// EYX, m
    pub straightness_y: Profile,
    /// EZX, m
    pub straightness_z: Profile,
    /// EAX, rad
    pub roll: Profile,
    /// EBX, rad
    pub pitch: Profile,
    /// ECX, rad
    pub yaw: Profile,
}

impl ErrorMotions {
    /// Translation error (EXX, EYX, EZX)(x), m, axis frame.
    pub fn translation(&self, x: f64) -> DVec3 {
        DVec3::new(self.positioning.value(x), self.straightness_y.value(x), self.straightness_z.value(x))
    }

    /// Angular error (EAX, EBX, ECX)(x), rad, axis frame.
    pub fn rotation(&self, x: f64) -> DVec3 {
        DVec3::new(self.roll.value(x), self.pitch.value(x), self.yaw.value(x))
    }

    /// δ(r) = E(x) + ε(x) × r: first-order deviation of body point r (m, axis frame, from the reference
    /// point) at axis position x.
    pub fn deviation(&self, x: f64, r: DVec3) -> DVec3 {
        self.translation(x) + self.rotation(x).cross(r)
    }

    /// δ''(r) = E''(x) + ε''(x) × r: second derivative with respect to position of the deviation of body
    /// point r (1/m times m): what an accelerometer at r reads, times v², at constant velocity v.
    pub fn curvature(&self, x: f64, r: DVec3) -> DVec3 {
        let d = |p: &Profile| p.eval3(x)[2];
        let e = DVec3::new(d(&self.positioning), d(&self.straightness_y), d(&self.straightness_z));
        e + DVec3::new(d(&self.roll), d(&self.pitch), d(&self.yaw)).cross(r)
    }

    /// [`ErrorMotions::deviation`] on plain arrays (for callers without the physics engine's vector type):
    /// δ = E(x) + ε(x) × r, m, for body point `r` (m, axis frame) at axis position `x` (m).
    pub fn deviation_at(&self, x: f64, r: [f64; 3]) -> [f64; 3] {
        self.deviation(x, DVec3::from_array(r)).to_array()
    }

    /// [`ErrorMotions::curvature`] on plain arrays: δ'' = E''(x) + ε''(x) × r, 1/m·m, for body point `r`
    /// (m, axis frame) at axis position `x` (m).
    pub fn curvature_at(&self, x: f64, r: [f64; 3]) -> [f64; 3] {
        self.curvature(x, DVec3::from_array(r)).to_array()
    }

    /// Derivatives with respect to position of (translation, rotation): (E'(x), ε'(x)).
    pub fn slope(&self, x: f64) -> (DVec3, DVec3) {
        let d = |p: &Profile| p.eval3(x)[1];
        (
            DVec3::new(d(&self.positioning), d(&self.straightness_y), d(&self.straightness_z)),
            DVec3::new(d(&self.roll), d(&self.pitch), d(&self.yaw)),
        )
    }

    /// Value and slope of all six error motions at x, each profile evaluated once: what one physics
    /// step needs (the guideway rest pose and its velocity, DESIGN.md §4).
    pub fn at(&self, x: f64) -> MotionsAt {
        self.at_with(|_, p| {
            let e = p.eval3(x);
            [e[0], e[1]]
        })
    }

    /// The six error motions and their slopes as `value_slope(i, profile)` gives them for the motion of
    /// ISO index i (0..6: EXX, EYX, EZX, EAX, EBX, ECX) — exactly, or from a table of the profile.
    #[inline(always)]
    pub fn at_with(&self, value_slope: impl Fn(usize, &Profile) -> [f64; 2]) -> MotionsAt {
        let [px, py, pz, rx, ry, rz] = [
            value_slope(0, &self.positioning),
            value_slope(1, &self.straightness_y),
            value_slope(2, &self.straightness_z),
            value_slope(3, &self.roll),
            value_slope(4, &self.pitch),
            value_slope(5, &self.yaw),
        ];
        MotionsAt {
            translation: DVec3::new(px[0], py[0], pz[0]),
            rotation: DVec3::new(rx[0], ry[0], rz[0]),
            translation_slope: DVec3::new(px[1], py[1], pz[1]),
            rotation_slope: DVec3::new(rx[1], ry[1], rz[1]),
        }
    }

    /// The profile of an error motion by its ISO 230-1 index: 0..6 = EXX, EYX, EZX, EAX, EBX, ECX.
    pub fn by_index(&self, i: usize) -> &Profile {
        [&self.positioning, &self.straightness_y, &self.straightness_z, &self.roll, &self.pitch, &self.yaw][i]
    }
}

/// The six error motions and their slopes at one axis position (axis frame).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct MotionsAt {
    /// [EXX, EYX, EZX], m.
    pub translation: DVec3,
    /// [EAX, EBX, ECX], rad.
    pub rotation: DVec3,
    /// d/dx of the translation, m/m.
    pub translation_slope: DVec3,
    /// d/dx of the rotation, rad/m.
    pub rotation_slope: DVec3,
}

/// Effect names of the six error motions, in ISO index order (FORMAT.md §2).
pub const ERROR_MOTION_NAMES: [&str; 6] = ["positioning", "straightness_y", "straightness_z", "roll", "pitch", "yaw"];

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn pitch_moves_a_high_point_along_x_and_a_far_point_down() {
        // ε = (0, EBX, 0), r = (rx, 0, rz): ε × r = (EBX·rz, 0, −EBX·rx).
        let e = ErrorMotions { pitch: Profile::poly(vec![10e-6]), ..Default::default() };
        let d = e.deviation(0.3, DVec3::new(0.5, 0.0, 1.0));
        assert!((d - DVec3::new(10e-6, 0.0, -5e-6)).length() < 1e-18);
    }
}
