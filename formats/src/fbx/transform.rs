//! FBX transforms: Euler rotations in the file's rotation orders, a model's local transform with pivots, offsets
//! and pre/post-rotations (the FBX SDK's formula, stated in the module above), and the axis system.

use super::binary::Prop;
use super::scene::Scene;
use crate::error::Result;
use crate::skeletal::{IDENTITY, Mat, axis_rotation, inverse, mul};

/// Euler rotation of `deg` in FBX rotation order `order` (0 `XYZ` … 5 `ZYX`; the first letter turns first).
pub(super) fn euler(deg: [f64; 3], order: i64) -> Mat {
    let seq = match order {
        1 => [0, 2, 1],
        2 => [1, 2, 0],
        3 => [1, 0, 2],
        4 => [2, 0, 1],
        5 => [2, 1, 0],
        _ => [0, 1, 2],
    };
    seq.iter().fold(IDENTITY, |m, &a| mul(&axis_rotation(a, deg[a]), &m))
}

pub(super) fn translation(t: [f64; 3]) -> Mat {
    let mut m = IDENTITY;
    (0..3).for_each(|k| m[k][3] = t[k]);
    m
}

pub(super) fn scaling(s: [f64; 3]) -> Mat {
    let mut m = IDENTITY;
    (0..3).for_each(|k| m[k][k] = s[k]);
    m
}

/// What a model's local transform is made of besides its animated translation, rotation and scale.
pub(super) struct Pivots {
    pub(super) t: [f64; 3],
    pub(super) r: [f64; 3],
    pub(super) s: [f64; 3],
    pub(super) order: i64,
    /// `T(Roff) · T(Rp) · Rpre`.
    pub(super) before_r: Mat,
    /// `Rpost⁻¹ · T(Rp)⁻¹ · T(Soff) · T(Sp)`.
    pub(super) after_r: Mat,
    /// `T(Sp)⁻¹`.
    pub(super) after_s: Mat,
}

impl Pivots {
    pub(super) fn read(scene: &Scene, id: i64) -> Result<Self> {
        let v = |name: &str, d: [f64; 3]| scene.vec3(id, name, d);
        let neg = |p: [f64; 3]| p.map(|x| -x);
        let rp = v("RotationPivot", [0.0; 3])?;
        let sp = v("ScalingPivot", [0.0; 3])?;
        let post = euler(v("PostRotation", [0.0; 3])?, 0);
        let post_inv = inverse(&post).unwrap_or(IDENTITY);
        Ok(Pivots {
            t: v("Lcl Translation", [0.0; 3])?,
            r: v("Lcl Rotation", [0.0; 3])?,
            s: v("Lcl Scaling", [1.0; 3])?,
            order: scene
                .prop(id, "RotationOrder")
                .and_then(|p| p.first())
                .and_then(Prop::int)
                .unwrap_or(0),
            before_r: mul(
                &mul(&translation(v("RotationOffset", [0.0; 3])?), &translation(rp)),
                &euler(v("PreRotation", [0.0; 3])?, 0),
            ),
            after_r: mul(
                &mul(&post_inv, &translation(neg(rp))),
                &mul(&translation(v("ScalingOffset", [0.0; 3])?), &translation(sp)),
            ),
            after_s: translation(neg(sp)),
        })
    }

    pub(super) fn local(&self, t: [f64; 3], r: [f64; 3], s: [f64; 3]) -> Mat {
        let m = mul(&translation(t), &self.before_r);
        let m = mul(&mul(&m, &euler(r, self.order)), &self.after_r);
        mul(&mul(&m, &scaling(s)), &self.after_s)
    }
}

/// The coordinate change from the file's axis system to Y-up, and whether it mirrors.
pub(super) fn axes(scene: &Scene) -> Result<([[f64; 3]; 3], bool)> {
    let int = |name: &str, d: i64| scene.setting(name).and_then(Prop::int).unwrap_or(d);
    let picks = [("CoordAxis", 0), ("UpAxis", 1), ("FrontAxis", 2)];
    let mut m = [[0.0; 3]; 3];
    let mut seen = [false; 3];
    for (row, (name, d)) in picks.iter().enumerate() {
        let axis = int(name, *d);
        let sign = int(&format!("{name}Sign"), 1);
        let Some(a) = usize::try_from(axis).ok().filter(|a| *a < 3 && !seen[*a]) else {
            return Err(scene.err(
                format!("GlobalSettings {name}"),
                format!("axis {axis}: the coordinate, up and front axes must be 0, 1 and 2 in some order"),
            ));
        };
        seen[a] = true;
        m[row][a] = if sign < 0 { -1.0 } else { 1.0 };
    }
    let det = m[0][0] * (m[1][1] * m[2][2] - m[1][2] * m[2][1]) - m[0][1] * (m[1][0] * m[2][2] - m[1][2] * m[2][0])
        + m[0][2] * (m[1][0] * m[2][1] - m[1][1] * m[2][0]);
    Ok((m, det < 0.0))
}
