//! A rigid pose as a scene file writes it ([`PoseSpec`]: translation plus Euler angles or a
//! quaternion), used by objects, boards and explicit camera poses, and its checked conversion to
//! an isometry.

use nalgebra::{Isometry3, Quaternion, Translation3, UnitQuaternion, Vector3};
use serde::{Deserialize, Serialize};

use super::error::{Located, SceneError};

/// A rigid pose: translation plus rotation (Euler angles or a quaternion, not both).
#[derive(Clone, Copy, Debug, Default, PartialEq, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct PoseSpec {
    /// Translation in metres (default 0).
    #[serde(default)]
    pub translation_m: [f64; 3],
    /// `[rx, ry, rz]` degrees: rotate about x, then y, then z (fixed axes; R = Rz·Ry·Rx).
    #[serde(default)]
    pub rotation_deg: Option<[f64; 3]>,
    /// Unit quaternion `[w, x, y, z]` (normalised on load).
    #[serde(default)]
    pub quaternion_wxyz: Option<[f64; 4]>,
}

impl PoseSpec {
    /// The isometry `parent_from_child`; `key` is the pose table's path.
    pub fn to_isometry(&self, key: &str, loc: &Located<'_>) -> Result<Isometry3<f64>, SceneError> {
        if !self.translation_m.iter().all(|v| v.is_finite()) {
            return Err(loc.invalid(format!("{key}.translation_m"), "must be finite"));
        }
        let rotation = match (self.rotation_deg, self.quaternion_wxyz) {
            (Some(_), Some(_)) => {
                return Err(loc.invalid(
                    format!("{key}.quaternion_wxyz"),
                    "give either rotation_deg or quaternion_wxyz, not both",
                ));
            }
            (Some(r), None) => {
                if !r.iter().all(|v| v.is_finite()) {
                    return Err(loc.invalid(format!("{key}.rotation_deg"), "must be finite"));
                }
                UnitQuaternion::from_euler_angles(
                    r[0].to_radians(),
                    r[1].to_radians(),
                    r[2].to_radians(),
                )
            }
            (None, Some([w, x, y, z])) => {
                let q = Quaternion::new(w, x, y, z);
                let n = q.norm();
                if !(n.is_finite() && n > 1e-9) {
                    return Err(loc.invalid(
                        format!("{key}.quaternion_wxyz"),
                        format!("quaternion norm {n} cannot be normalised"),
                    ));
                }
                UnitQuaternion::from_quaternion(q)
            }
            (None, None) => UnitQuaternion::identity(),
        };
        Ok(Isometry3::from_parts(
            Translation3::from(Vector3::from(self.translation_m)),
            rotation,
        ))
    }
}
