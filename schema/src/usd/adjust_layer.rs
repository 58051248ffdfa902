//! Writing Curvenet Adjustments (schema/README.md, "Curvenet adjustment")
//! as a layer of opinions on a shot: the viewer's export. The layer
//! sublayers the shot, so opening (or baking) it composes the shot with the
//! adjustments; each adjustment is either an `over` of a `CurvenetAdjustment`
//! prim the shot already has, or a new `def CurvenetAdjustment` under an
//! `over` of its curvenet prim. Values are authored as time samples with
//! the types [`Stage::curvenet_adjustments`](super::Stage::curvenet_adjustments)
//! reads (`double3` translate, `float3` rotateXYZ and scale, `quatf` orient,
//! `float3[]` tangent translates), so what is written is what is read back.
//!
//! ```
//! use curvenet_schema::usd::{AdjustmentLayer, AdjustmentOver, AdjustmentRotate, LayerFormat, encode_adjustment_layer};
//! let layer = AdjustmentLayer {
//!     sublayer: "/shots/hand/shot.usda".into(),
//!     doc: "adjusted in the viewer".into(),
//!     time_range: Some((1.0, 12.0)),
//!     adjustments: vec![AdjustmentOver {
//!         path: "/Hand/Curvenet/Knot_41".into(),
//!         define_knot: Some(41),
//!         attach_tangents: Some(true),
//!         translate: vec![(6.0, [0.0, 0.002, 0.0])],
//!         rotate: Some(AdjustmentRotate::EulerXyz(vec![(6.0, [0.0, 0.0, 15.0])])),
//!         scale: Vec::new(),
//!         tangent_translates: Vec::new(),
//!     }],
//! };
//! let text = String::from_utf8(encode_adjustment_layer(&layer, LayerFormat::Usda)?).unwrap();
//! assert!(text.contains("def CurvenetAdjustment \"Knot_41\""));
//! # Ok::<(), curvenet_schema::usd::WriteError>(())
//! ```

use openusd::gf;
use openusd::sdf::{self, AbstractData as _, Value};

use super::adjust::{ATTACH, KNOT, OP_ORDER, ORIENT, ROTATE_XYZ, SCALE, TANGENT_TRANSLATES, TRANSLATE};
use super::write::{LayerFormat, WriteError, encode_layer};

/// The rotate of an adjustment, as time samples of one of the two rotate
/// attributes (an adjustment has one; schema/README.md).
#[derive(Debug, Clone, PartialEq)]
pub enum AdjustmentRotate {
    /// `float3 xformOp:rotateXYZ`: degrees about X, then Y, then Z.
    EulerXyz(Vec<(f64, [f32; 3])>),
    /// `quatf xformOp:orient`: `(w, x, y, z)`, USD's order.
    Orient(Vec<(f64, [f32; 4])>),
}

/// One adjustment prim of an [`AdjustmentLayer`]. Every time-sampled field
/// is `(time code, value)` pairs; an empty list authors nothing.
#[derive(Debug, Clone, PartialEq)]
pub struct AdjustmentOver {
    /// The adjustment prim's path: a child of its curvenet prim.
    pub path: String,
    /// `Some(knot)`: define the prim (`def CurvenetAdjustment` with
    /// `uniform int curvenet:knot`); `None`: an `over` of a prim the
    /// sublayered stage defines.
    pub define_knot: Option<u32>,
    /// `uniform bool curvenet:attachTangents`, when authored.
    pub attach_tangents: Option<bool>,
    pub translate: Vec<(f64, [f64; 3])>,
    pub rotate: Option<AdjustmentRotate>,
    pub scale: Vec<(f64, [f32; 3])>,
    /// One translate per tangent of the knot, per sample.
    pub tangent_translates: Vec<(f64, Vec<[f32; 3]>)>,
}

/// What [`encode_adjustment_layer`] writes.
#[derive(Debug, Clone, PartialEq)]
pub struct AdjustmentLayer {
    /// Asset path of the shot the adjustments apply to (its `subLayers`).
    pub sublayer: String,
    /// The layer's `doc` string.
    pub doc: String,
    /// `startTimeCode` and `endTimeCode` (the shot's, so baking the layer
    /// takes the shot's frames).
    pub time_range: Option<(f64, f64)>,
    pub adjustments: Vec<AdjustmentOver>,
}

fn samples<T: Copy>(
    list: &[(f64, T)],
    prim: &str,
    name: &str,
    value: impl Fn(T) -> Value,
    finite: impl Fn(&T) -> bool,
) -> Result<sdf::TimeSampleMap, WriteError> {
    let content = |problem: String| WriteError::Content { prim: prim.to_string(), problem };
    let mut sorted: Vec<(f64, T)> = list.to_vec();
    sorted.sort_by(|a, b| a.0.total_cmp(&b.0));
    if let Some((t, _)) = sorted.iter().find(|(t, v)| !t.is_finite() || !finite(v)) {
        return Err(content(format!("{name} at time code {t} is not finite")));
    }
    if let Some(w) = sorted.windows(2).find(|w| w[0].0 == w[1].0) {
        return Err(content(format!("{name} has two samples at time code {}", w[0].0)));
    }
    Ok(sorted.into_iter().map(|(t, v)| (t, value(v))).collect())
}

fn layer_data(layer: &AdjustmentLayer) -> Result<sdf::Data, WriteError> {
    let mut data = sdf::Data::new();
    let root = sdf::Path::abs_root();
    data.create_spec(root.clone(), sdf::SpecType::PseudoRoot);
    data.set_field(&root, sdf::FieldKey::Documentation.as_str(), Value::String(layer.doc.clone()));
    data.set_field(&root, sdf::FieldKey::SubLayers.as_str(), Value::StringVec(vec![layer.sublayer.clone()]));
    if let Some((start, end)) = layer.time_range {
        data.set_field(&root, sdf::FieldKey::StartTimeCode.as_str(), Value::Double(start));
        data.set_field(&root, sdf::FieldKey::EndTimeCode.as_str(), Value::Double(end));
    }
    for a in &layer.adjustments {
        let prim = a.path.as_str();
        let content = |problem: String| WriteError::Content { prim: prim.to_string(), problem };
        match a.define_knot {
            Some(_) => {
                sdf::PrimSpec::new(&mut data, prim, sdf::Specifier::Def, super::ADJUSTMENT_TYPE)
                    .map_err(|e| content(format!("cannot define the prim: {e}")))?;
            }
            None => {
                sdf::PrimSpec::over(&mut data, prim).map_err(|e| content(format!("cannot author an over: {e}")))?;
            }
        }
        let uniform = sdf::Variability::Uniform;
        let varying = sdf::Variability::Varying;
        let set_default = |data: &mut sdf::Data, name: &str, type_name: &str, value: Value| {
            let path = format!("{prim}.{name}");
            let mut attr = sdf::AttributeSpecMut::new(data, path.as_str(), type_name, uniform, false)
                .map_err(|e| content(format!("cannot author {name}: {e}")))?;
            attr.set_default(value).map_err(|e| content(format!("cannot set {name}: {e}")))
        };
        if let Some(knot) = a.define_knot {
            let knot = i32::try_from(knot).map_err(|_| content(format!("{KNOT} {knot} does not fit an int")))?;
            set_default(&mut data, KNOT, "int", Value::Int(knot))?;
        }
        if let Some(attach) = a.attach_tangents {
            set_default(&mut data, ATTACH, "bool", Value::Bool(attach))?;
        }
        let mut ops: Vec<&str> = Vec::new();
        let mut animated: Vec<(&str, &str, sdf::TimeSampleMap)> = Vec::new();
        if !a.translate.is_empty() {
            let map = samples(
                &a.translate,
                prim,
                TRANSLATE,
                |v| Value::Vec3d(gf::Vec3d::from(v)),
                |v| v.iter().all(|x| x.is_finite()),
            )?;
            animated.push((TRANSLATE, "double3", map));
            ops.push(TRANSLATE);
        }
        match &a.rotate {
            Some(AdjustmentRotate::EulerXyz(list)) if !list.is_empty() => {
                let map = samples(
                    list,
                    prim,
                    ROTATE_XYZ,
                    |v| Value::Vec3f(gf::Vec3f::from(v)),
                    |v| v.iter().all(|x| x.is_finite()),
                )?;
                animated.push((ROTATE_XYZ, "float3", map));
                ops.push(ROTATE_XYZ);
            }
            Some(AdjustmentRotate::Orient(list)) if !list.is_empty() => {
                let map = samples(
                    list,
                    prim,
                    ORIENT,
                    |v| Value::Quatf(gf::Quatf::from(v)),
                    |v| v.iter().all(|x| x.is_finite()) && v.iter().map(|x| x * x).sum::<f32>() > 0.0,
                )?;
                animated.push((ORIENT, "quatf", map));
                ops.push(ORIENT);
            }
            _ => {}
        }
        if !a.scale.is_empty() {
            let map = samples(
                &a.scale,
                prim,
                SCALE,
                |v| Value::Vec3f(gf::Vec3f::from(v)),
                |v| v.iter().all(|x| x.is_finite()),
            )?;
            animated.push((SCALE, "float3", map));
            ops.push(SCALE);
        }
        if !a.tangent_translates.is_empty() {
            let indexed: Vec<(f64, usize)> =
                a.tangent_translates.iter().enumerate().map(|(i, (t, _))| (*t, i)).collect();
            let list = &a.tangent_translates;
            let map = samples(
                &indexed,
                prim,
                TANGENT_TRANSLATES,
                |i| Value::Vec3fVec(list[i].1.iter().map(|&p| gf::Vec3f::from(p)).collect()),
                |&i| list[i].1.iter().flatten().all(|x| x.is_finite()),
            )?;
            animated.push((TANGENT_TRANSLATES, "float3[]", map));
        }
        for (name, type_name, map) in animated {
            let path = format!("{prim}.{name}");
            sdf::AttributeSpecMut::new(&mut data, path.as_str(), type_name, varying, false)
                .map_err(|e| content(format!("cannot author {name}: {e}")))?;
            let path = sdf::try_into_path(path.as_str()).map_err(|e| content(e.to_string()))?;
            data.set_field(&path, sdf::FieldKey::TimeSamples.as_str(), Value::TimeSamples(map));
        }
        // A new prim lists its ops (the reader does not need it; USD tools do).
        if a.define_knot.is_some() && !ops.is_empty() {
            set_default(&mut data, OP_ORDER, "token[]", Value::token_vec(ops))?;
        }
    }
    Ok(data)
}

/// The adjustment layer, serialised in memory (`.usda` text or `.usdc`).
/// Refuses (naming the prim) a non-finite value or time, two samples at one
/// time, a zero quaternion, a path that is not a prim path.
pub fn encode_adjustment_layer(layer: &AdjustmentLayer, format: LayerFormat) -> Result<Vec<u8>, WriteError> {
    let data = layer_data(layer)?;
    let mut buf = std::io::Cursor::new(Vec::new());
    encode_layer(&data, format, &mut buf)?;
    Ok(buf.into_inner())
}
