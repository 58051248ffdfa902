//! Curvenet Adjustments in the viewer: the stage's own `CurvenetAdjustment`
//! prims (read as `curvenet bake` reads them, `Stage::curvenet_adjustments`
//! and `Stage::adjustments_at`), the user's interactive ones composed on
//! top, and the export of the user's as a USD layer that bakes to what the
//! viewer showed.
//!
//! **Composition.** The user's adjustment of a knot *replaces* the stage's
//! adjustment of that knot at the frame shown (core refuses two adjustments
//! of one knot, and translate · rotate · scale of two adjustments is not one
//! adjustment). The panel starts from the stage's values at that frame, so
//! an edit changes what the stage had. Adjustments of different knots move
//! different control points, so their order does not matter.
//!
//! **Exactness.** The user's values are rounded to the types the layer
//! stores before they are solved (`float3` rotateXYZ, scale and tangent
//! translates; `double3` translate), and a knot whose stage prim rotates by
//! `xformOp:orient` gets its rotate as that `quatf` (the Euler angles turned
//! into a quaternion as core turns them into a rotation). So the adjustment
//! the viewer solves is, bit for bit, the one `curvenet bake` reads back
//! from the exported layer at that time code.
//!
//! **Export.** Each user adjustment becomes time samples at the frame's time
//! code: an `over` of the stage's prim for a knot the stage adjusts (its own
//! samples at other times are kept, so the edit is a key among the stage's
//! keys; an attribute the stage authors without samples is held at the new
//! value on every frame), else a new `def CurvenetAdjustment "Knot_N"` under
//! the curvenet prim (one sample: the value on every frame). The layer
//! sublayers the stage by the path it was opened with, and carries the
//! stage's frame range, so `curvenet bake LAYER -o OUT` bakes the shot with
//! the adjustments.

use curvenet_core::{Adjustment, Rotate};
use curvenet_schema::AdjustmentData;
use curvenet_schema::usd::adjustment_attributes::{ORIENT, ROTATE_XYZ, SCALE, TANGENT_TRANSLATES, TRANSLATE};
use curvenet_schema::usd::{AdjustmentLayer, AdjustmentOver, AdjustmentRotate};
use curvenet_schema::wire::AdjustmentSpec;
use glam::{DQuat, EulerRot};

/// A `CurvenetAdjustment` prim of a stage opened in the viewer.
#[derive(Debug, Clone)]
pub struct StageAdjustment {
    /// The curvenet it adjusts, by its index in the stage's binding.
    pub curvenet: usize,
    /// The prim, as the schema crate reads it.
    pub data: AdjustmentData,
    /// Its values at each time code any of its attributes has a sample at,
    /// in time order (empty when nothing is animated).
    pub keys: Vec<(f64, Adjustment)>,
}

impl StageAdjustment {
    fn orient(&self) -> bool {
        self.data.rotate.as_deref() == Some(ORIENT)
    }

    /// The times of attribute `name` when the prim authors it (empty: a
    /// value without samples), `None` when it does not.
    fn times(&self, name: &str) -> Option<&[f64]> {
        self.data.attributes.iter().find(|(n, _)| n == name).map(|(_, t)| t.as_slice())
    }

    fn key(&self, time: f64) -> Option<&Adjustment> {
        self.keys.iter().find(|(t, _)| *t == time).map(|(_, a)| a)
    }
}

/// The stage adjustment of `(curvenet, knot)`, if any.
pub fn find(stage: &[StageAdjustment], curvenet: u32, knot: u32) -> Option<&StageAdjustment> {
    stage.iter().find(|s| s.curvenet == curvenet as usize && s.data.knot == knot)
}

fn f32s<const N: usize>(v: [f64; N]) -> [f64; N] {
    v.map(|x| x as f32 as f64)
}

/// Euler angles (degrees, about X then Y then Z) as `(w, x, y, z)`: the
/// quaternion core builds for `Rotate::EulerXyz`.
pub fn euler_to_quat([x, y, z]: [f64; 3]) -> [f64; 4] {
    let q = DQuat::from_rotation_z(z.to_radians())
        * DQuat::from_rotation_y(y.to_radians())
        * DQuat::from_rotation_x(x.to_radians());
    [q.w, q.x, q.y, q.z]
}

/// `(w, x, y, z)` as Euler angles in degrees (about X, then Y, then Z).
pub fn quat_to_euler([w, x, y, z]: [f64; 4]) -> [f64; 3] {
    let (c, b, a) = DQuat::from_xyzw(x, y, z, w).normalize().to_euler(EulerRot::ZYX);
    [a.to_degrees(), b.to_degrees(), c.to_degrees()]
}

fn euler_of(r: &Rotate) -> [f64; 3] {
    match *r {
        Rotate::EulerXyz(e) => e,
        Rotate::Quaternion(q) => quat_to_euler(q),
    }
}

fn quat_of(r: &Rotate) -> [f64; 4] {
    match *r {
        Rotate::EulerXyz(e) => euler_to_quat(e),
        Rotate::Quaternion(q) => q,
    }
}

/// The user's adjustment as the exported layer stores it (see the module
/// docs): what the viewer solves. `stage` is the stage's adjustment of the
/// same knot; an absent `attach_tangents` keeps the stage's. The rotation
/// is the spec's `orient` (a quaternion) or else its `rotate` (Euler
/// angles), stored in the form the layer keeps for that knot (`quatf` for
/// a prim that rotates by `xformOp:orient`, else `float3` rotateXYZ). The
/// spec was checked first (`user_adjustments`: not both, no zero
/// quaternion).
pub fn layer_adjustment(spec: &AdjustmentSpec, stage: Option<&StageAdjustment>) -> Adjustment {
    let attach = spec.attach_tangents.or(stage.map(|s| s.data.attach_tangents)).unwrap_or(true);
    let given = match spec.orient {
        Some(q) => Rotate::Quaternion(q),
        None => Rotate::EulerXyz(spec.rotate.unwrap_or([0.0; 3])),
    };
    let rotate = if stage.is_some_and(StageAdjustment::orient) {
        Rotate::Quaternion(f32s(quat_of(&given)))
    } else {
        Rotate::EulerXyz(f32s(euler_of(&given)))
    };
    Adjustment::new(spec.curvenet as usize, spec.knot)
        .with_translate(spec.translate.unwrap_or([0.0; 3]))
        .with_rotate(rotate)
        .with_scale(f32s(spec.scale.unwrap_or([1.0; 3])))
        .with_tangent_translates(spec.tangent_translates.iter().map(|&t| f32s(t)).collect())
        .with_attach_tangents(attach)
}

/// A core adjustment on the wire (a quaternion rotate as Euler angles).
pub fn spec_of(a: &Adjustment) -> AdjustmentSpec {
    AdjustmentSpec {
        curvenet: a.curvenet as u32,
        knot: a.knot,
        translate: Some(a.translate),
        rotate: Some(euler_of(&a.rotate)),
        orient: None,
        scale: Some(a.scale),
        attach_tangents: Some(a.attach_tangents),
        tangent_translates: a.tangent_translates.clone(),
    }
}

/// The frame's adjustments: the stage's, but for the knots the user
/// adjusts, then the user's.
pub fn compose(stage: Vec<AdjustmentSpec>, user: &[AdjustmentSpec]) -> Vec<AdjustmentSpec> {
    let mut out: Vec<AdjustmentSpec> =
        stage.into_iter().filter(|s| !user.iter().any(|u| u.curvenet == s.curvenet && u.knot == s.knot)).collect();
    out.extend(user.iter().cloned());
    out
}

/// The export layer of the user's adjustments `user` (already checked
/// against the binding) at time code `time`. `curvenets` are the stage's
/// curvenet prims in binding order; `tangent_counts(curvenet, knot)` the
/// number of the knot's tangents.
pub fn export_layer(
    stage_path: &str,
    curvenets: &[String],
    time_range: Option<(f64, f64)>,
    stage: &[StageAdjustment],
    time: f64,
    user: &[AdjustmentSpec],
    tangent_count: impl Fn(usize, u32) -> usize,
) -> AdjustmentLayer {
    let adjustments = user
        .iter()
        .map(|spec| {
            let s = find(stage, spec.curvenet, spec.knot);
            let a = layer_adjustment(spec, s);
            // The samples of one attribute: the stage's own at its other
            // times, and the user's value at `time`; nothing when neither
            // the stage authors it nor the user changes it.
            fn merged<V>(
                s: Option<&StageAdjustment>,
                name: &str,
                time: f64,
                user: V,
                changed: bool,
                stage_value: impl Fn(&Adjustment) -> V,
            ) -> Vec<(f64, V)> {
                let Some(times) = s.and_then(|s| s.times(name)) else {
                    return if changed { vec![(time, user)] } else { Vec::new() };
                };
                let s = s.expect("times come from the stage adjustment");
                let mut out: Vec<(f64, V)> = times
                    .iter()
                    .filter(|&&t| t != time)
                    .filter_map(|&t| s.key(t).map(|k| (t, stage_value(k))))
                    .collect();
                out.push((time, user));
                out
            }
            let f32v = |v: [f64; 3]| v.map(|x| x as f32);
            let translate = merged(s, TRANSLATE, time, a.translate, a.translate != [0.0; 3], |k| k.translate);
            let rotate = if s.is_some_and(StageAdjustment::orient) {
                let q = |r: &Rotate| quat_of(r).map(|x| x as f32);
                AdjustmentRotate::Orient(merged(s, ORIENT, time, q(&a.rotate), !a.rotate.is_identity(), |k| {
                    q(&k.rotate)
                }))
            } else {
                let e = |r: &Rotate| f32v(euler_of(r));
                AdjustmentRotate::EulerXyz(merged(s, ROTATE_XYZ, time, e(&a.rotate), !a.rotate.is_identity(), |k| {
                    e(&k.rotate)
                }))
            };
            let scale = merged(s, SCALE, time, f32v(a.scale), a.scale != [1.0; 3], |k| f32v(k.scale));
            let n = tangent_count(a.curvenet, a.knot);
            let tangents = |t: &[[f64; 3]]| -> Vec<[f32; 3]> {
                if t.is_empty() { vec![[0.0; 3]; n] } else { t.iter().map(|&v| f32v(v)).collect() }
            };
            let tangent_translates = merged(
                s,
                TANGENT_TRANSLATES,
                time,
                tangents(&a.tangent_translates),
                !a.tangent_translates.is_empty(),
                |k| tangents(&k.tangent_translates),
            );
            let attach_tangents = match s {
                Some(s) if s.data.attach_tangents == a.attach_tangents => None,
                _ => Some(a.attach_tangents),
            };
            AdjustmentOver {
                path: match s {
                    Some(s) => s.data.path.clone(),
                    None => format!("{}/Knot_{}", curvenets[a.curvenet], a.knot),
                },
                define_knot: if s.is_some() { None } else { Some(a.knot) },
                attach_tangents,
                translate,
                rotate: Some(rotate),
                scale,
                tangent_translates,
            }
        })
        .collect();
    AdjustmentLayer {
        sublayer: stage_path.to_string(),
        doc: format!("Curvenet Adjustments made in the curvenet viewer at time code {time}, over {stage_path}"),
        time_range,
        adjustments,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The quaternion of Euler angles is core's rotation of those angles, and
    /// the panel's Euler angles of a quaternion turn back into it.
    #[test]
    fn euler_angles_and_quaternions_agree_with_core() {
        for e in [[0.0, 0.0, 25.0], [10.0, -35.0, 70.0], [-120.0, 15.0, 5.0], [0.0, 0.0, 0.0]] {
            let q = euler_to_quat(e);
            let (a, b) = (Rotate::EulerXyz(e).matrix(), Rotate::Quaternion(q).matrix());
            let d = a.iter().flatten().zip(b.iter().flatten()).map(|(x, y)| (x - y).abs()).fold(0.0, f64::max);
            assert!(d < 1e-12, "{e:?}: {d}");
            let back = quat_to_euler(q);
            let c = Rotate::EulerXyz(back).matrix();
            let d = a.iter().flatten().zip(c.iter().flatten()).map(|(x, y)| (x - y).abs()).fold(0.0, f64::max);
            assert!(d < 1e-12, "{e:?} -> {back:?}: {d}");
        }
        assert_eq!(euler_to_quat([0.0; 3]), [1.0, 0.0, 0.0, 0.0]);
    }

    /// The user's adjustment replaces the stage's of the same knot only.
    #[test]
    fn the_users_adjustment_replaces_the_stages_of_its_knot() {
        let spec = |a: Adjustment| AdjustmentSpec::from(&a);
        let stage = vec![spec(Adjustment::new(0, 3).with_translate([1.0, 0.0, 0.0])), spec(Adjustment::new(0, 7))];
        let user = [spec(Adjustment::new(0, 3).with_translate([0.0, 2.0, 0.0]))];
        let out = compose(stage, &user);
        assert_eq!(out.len(), 2);
        assert_eq!((out[0].knot, out[1].knot), (7, 3));
        assert_eq!(out[1].translate, Some([0.0, 2.0, 0.0]));
    }
}
