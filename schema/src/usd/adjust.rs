//! Reading `CurvenetAdjustment` prims (schema/README.md, "Curvenet
//! adjustment") and turning them into the core's plain
//! [`curvenet_core::Adjustment`]s for a frame.

use curvenet_core::{Adjustment, Rotate, knot_tangents};

use super::error::UsdError;
use super::read::{Stage, at};
use super::value;
use crate::data::{AdjustmentData, CurvenetData};

type Result<T> = std::result::Result<T, UsdError>;

/// The prim type of an adjustment (typed by convention, like the curvenet).
pub const ADJUSTMENT_TYPE: &str = "CurvenetAdjustment";
pub const KNOT: &str = "curvenet:knot";
pub const ATTACH: &str = "curvenet:attachTangents";
pub const TANGENT_TRANSLATES: &str = "curvenet:tangentTranslates";
pub const TRANSLATE: &str = "xformOp:translate";
pub const ROTATE_XYZ: &str = "xformOp:rotateXYZ";
pub const ORIENT: &str = "xformOp:orient";
pub const SCALE: &str = "xformOp:scale";
pub const OP_ORDER: &str = "xformOpOrder";

impl Stage {
    /// The `CurvenetAdjustment` children of `curvenet`'s prim, in the
    /// stage's child order. Refuses (naming the prim and attribute) a
    /// missing, animated or out-of-range `curvenet:knot`, a knot that is a
    /// handle (not a spline endpoint), an animated `curvenet:attachTangents`,
    /// both `xformOp:rotateXYZ` and `xformOp:orient`, an `xformOpOrder`
    /// other than translate, rotate, scale (any may be left out), and two
    /// adjustments of one knot.
    pub fn curvenet_adjustments(&self, curvenet: &CurvenetData) -> Result<Vec<AdjustmentData>> {
        let parent = self.prim(&curvenet.path)?;
        let children = parent.children().map_err(|e| UsdError::contract(&curvenet.path, "", e.to_string()))?;
        let mut out: Vec<AdjustmentData> = Vec::new();
        for child in children {
            if self.type_name(&child)? != ADJUSTMENT_TYPE {
                continue;
            }
            let a = self.adjustment(&child, curvenet)?;
            if let Some(other) = out.iter().find(|o| o.knot == a.knot) {
                return Err(UsdError::contract(
                    &a.path,
                    KNOT,
                    format!("is {}, the knot {} already adjusts", a.knot, other.path),
                ));
            }
            out.push(a);
        }
        Ok(out)
    }

    fn adjustment(&self, prim: &openusd::usd::Prim, curvenet: &CurvenetData) -> Result<AdjustmentData> {
        let path = prim.path().as_str().to_string();
        let knot_v = self.static_value(prim, KNOT)?.ok_or_else(|| UsdError::contract(&path, KNOT, "is missing"))?;
        let knot = value::int(&knot_v).ok_or_else(|| {
            UsdError::contract(&path, KNOT, format!("has type {}, expected int", value::kind(&knot_v)))
        })?;
        let n = curvenet.pool.len();
        if knot < 0 || knot as u64 >= n as u64 {
            return Err(UsdError::contract(
                &path,
                KNOT,
                format!("is {knot}, outside the pool of {} (0..{n})", curvenet.path),
            ));
        }
        let knot = knot as u32;
        if !curvenet.splines.iter().any(|s| s[0] == knot || s[3] == knot) {
            return Err(UsdError::contract(
                &path,
                KNOT,
                format!("is {knot}, a control point of {} that is not a knot (no spline ends there)", curvenet.path),
            ));
        }
        let attach_tangents = match self.static_value(prim, ATTACH)? {
            None => true,
            Some(v) => value::bool(&v).ok_or_else(|| {
                UsdError::contract(&path, ATTACH, format!("has type {}, expected bool", value::kind(&v)))
            })?,
        };
        let has = |name: &str| {
            prim.attribute(name).has_authored_value().map_err(|e| UsdError::contract(&path, name, e.to_string()))
        };
        let rotate = match (has(ROTATE_XYZ)?, has(ORIENT)?) {
            (true, true) => {
                return Err(UsdError::contract(
                    &path,
                    ORIENT,
                    format!("is authored together with {ROTATE_XYZ}; an adjustment has one rotate"),
                ));
            }
            (true, false) => Some(ROTATE_XYZ.to_string()),
            (false, true) => Some(ORIENT.to_string()),
            (false, false) => None,
        };
        if let Some(v) = self.value(prim, OP_ORDER, None)? {
            let ops = value::tokens(&v).unwrap_or_default();
            let rank = |op: &str| match op {
                TRANSLATE => Some(0),
                ROTATE_XYZ | ORIENT => Some(1),
                SCALE => Some(2),
                _ => None,
            };
            let ranks: Vec<Option<i32>> = ops.iter().map(|o| rank(o)).collect();
            if ranks.iter().any(Option::is_none) || ranks.windows(2).any(|w| w[0] >= w[1]) {
                return Err(UsdError::contract(
                    &path,
                    OP_ORDER,
                    format!("is {ops:?}; an adjustment composes {TRANSLATE}, then one rotate, then {SCALE}"),
                ));
            }
        }
        let mut attributes = Vec::new();
        for name in [TRANSLATE, ROTATE_XYZ, ORIENT, SCALE, TANGENT_TRANSLATES] {
            if has(name)? {
                attributes.push((name.to_string(), self.sample_times(prim, name)?));
            }
        }
        let tangents = knot_tangents(&curvenet.splines, knot);
        Ok(AdjustmentData {
            path,
            curvenet: curvenet.path.clone(),
            knot,
            attach_tangents,
            tangents,
            rotate,
            attributes,
        })
    }

    /// The core adjustments of a frame: `per_curvenet[k]` are the
    /// adjustments of the binding's curvenet `k` (from
    /// [`Self::curvenet_adjustments`]); each is evaluated at `time` (`None`:
    /// the default values; time samples interpolate as USD's do: linearly,
    /// quaternions by slerp). Unauthored values are no change. Refuses
    /// (naming the prim, attribute and time) wrong types, non-finite values,
    /// a zero quaternion and a `curvenet:tangentTranslates` that is neither
    /// empty nor one per tangent.
    pub fn adjustments_at(&self, per_curvenet: &[Vec<AdjustmentData>], time: Option<f64>) -> Result<Vec<Adjustment>> {
        let mut out = Vec::with_capacity(per_curvenet.iter().map(Vec::len).sum());
        for (k, list) in per_curvenet.iter().enumerate() {
            for a in list {
                out.push(self.adjustment_at(k, a, time)?);
            }
        }
        Ok(out)
    }

    fn adjustment_at(&self, curvenet: usize, a: &AdjustmentData, time: Option<f64>) -> Result<Adjustment> {
        let prim = self.prim(&a.path)?;
        let vec3 = |name: &str| -> Result<Option<[f64; 3]>> {
            let Some(v) = self.value(&prim, name, time)? else { return Ok(None) };
            let x = value::vec3(&v).ok_or_else(|| {
                UsdError::contract(&a.path, name, format!("has type {}, expected a 3-vector", value::kind(&v)))
            })?;
            finite(&x, &a.path, name, time)?;
            Ok(Some(x))
        };
        let mut adjustment = Adjustment::new(curvenet, a.knot).with_attach_tangents(a.attach_tangents);
        if let Some(t) = vec3(TRANSLATE)? {
            adjustment.translate = t;
        }
        if let Some(s) = vec3(SCALE)? {
            adjustment.scale = s;
        }
        match a.rotate.as_deref() {
            Some(ROTATE_XYZ) => {
                if let Some(r) = vec3(ROTATE_XYZ)? {
                    adjustment.rotate = Rotate::EulerXyz(r);
                }
            }
            Some(ORIENT) => {
                if let Some(v) = self.value(&prim, ORIENT, time)? {
                    let q = value::quat(&v).ok_or_else(|| {
                        UsdError::contract(&a.path, ORIENT, format!("has type {}, expected a quatf", value::kind(&v)))
                    })?;
                    finite(&q, &a.path, ORIENT, time)?;
                    if q.iter().map(|x| x * x).sum::<f64>() < 1e-24 {
                        return Err(UsdError::contract(&a.path, ORIENT, format!("is a zero quaternion{}", at(time))));
                    }
                    adjustment.rotate = Rotate::Quaternion(q);
                }
            }
            _ => {}
        }
        if let Some(v) = self.value(&prim, TANGENT_TRANSLATES, time)? {
            let t = self.points_value(&prim, TANGENT_TRANSLATES, &v)?;
            if !t.is_empty() && t.len() != a.tangents.len() {
                return Err(UsdError::contract(
                    &a.path,
                    TANGENT_TRANSLATES,
                    format!(
                        "has {} entries{}, the knot {} has {} tangents (control points {:?})",
                        t.len(),
                        at(time),
                        a.knot,
                        a.tangents.len(),
                        a.tangents
                    ),
                ));
            }
            for p in &t {
                finite(p, &a.path, TANGENT_TRANSLATES, time)?;
            }
            adjustment.tangent_translates = t;
        }
        Ok(adjustment)
    }
}

fn finite(x: &[f64], prim: &str, name: &str, time: Option<f64>) -> Result<()> {
    if x.iter().all(|v| v.is_finite()) {
        Ok(())
    } else {
        Err(UsdError::contract(prim, name, format!("is {x:?}{}, not finite", at(time))))
    }
}
