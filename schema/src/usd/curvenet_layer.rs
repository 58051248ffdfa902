//! Writing a drafted curvenet (`curvenet draft`): a layer that sublayers the
//! stage it was drafted on, defines the curvenet (a `BasisCurves` following
//! the contract in schema/README.md) and binds it to the mesh with an `over`
//! authoring `rel curvenet:curvenets`. Opened on its own it composes the
//! input with the curvenet bound; sublayered into an asset above the input
//! it adds the same opinions.
//!
//! The relationship is authored as an explicit list, so it replaces any
//! curvenets the input binds to that mesh (a re-draft replaces the last one).

use std::path::Path;

use openusd::gf;
use openusd::sdf::{self, AbstractData as _, Value};

use super::write::{LayerFormat, WriteError, encode_layer, write_atomically};

/// What [`write_curvenet_layer`] writes.
#[derive(Debug, Clone, PartialEq)]
pub struct CurvenetLayer {
    /// Asset path of the stage drafted on, as the layer should name it
    /// (usually relative to the layer's directory).
    pub sublayer: String,
    /// The mesh prim the curvenet deforms.
    pub mesh: String,
    /// The prim path of the new curvenet.
    pub curvenet: String,
    /// Control-point pool (neutral pose).
    pub pool: Vec<[f32; 3]>,
    /// Four pool indices per spline.
    pub splines: Vec<[u32; 4]>,
    /// `curvenet:sampleDensity`.
    pub sample_density: f32,
    /// The layer's `doc` string.
    pub doc: String,
}

fn layer_data(layer: &CurvenetLayer) -> Result<sdf::Data, WriteError> {
    let content = |prim: &str, problem: String| WriteError::Content { prim: prim.to_string(), problem };
    if let Some((s, v)) = layer
        .splines
        .iter()
        .enumerate()
        .find_map(|(s, sp)| sp.iter().find(|&&v| v as usize >= layer.pool.len()).map(|&v| (s, v)))
    {
        return Err(content(
            &layer.curvenet,
            format!("spline {s} refers to control point {v} of {}", layer.pool.len()),
        ));
    }
    if layer.pool.len() > i32::MAX as usize || layer.splines.len() > (i32::MAX / 4) as usize {
        return Err(content(&layer.curvenet, "too many control points or splines for int[] indices".into()));
    }
    let mut data = sdf::Data::new();
    let root = sdf::Path::abs_root();
    data.create_spec(root.clone(), sdf::SpecType::PseudoRoot);
    data.set_field(&root, sdf::FieldKey::Documentation.as_str(), Value::String(layer.doc.clone()));
    data.set_field(&root, sdf::FieldKey::SubLayers.as_str(), Value::StringVec(vec![layer.sublayer.clone()]));

    // The binding: an over of the mesh with the relationship.
    let mesh = &layer.mesh;
    sdf::PrimSpec::over(&mut data, mesh.as_str()).map_err(|e| content(mesh, format!("cannot author an over: {e}")))?;
    let rel_path = format!("{mesh}.curvenet:curvenets");
    let mut rel = sdf::RelationshipSpecMut::new(&mut data, rel_path.as_str(), sdf::Variability::Uniform, false)
        .map_err(|e| content(mesh, format!("cannot author curvenet:curvenets: {e}")))?;
    rel.set_target_paths([layer.curvenet.as_str()])
        .map_err(|e| content(&layer.curvenet, format!("not a prim path: {e}")))?;

    // The curvenet.
    let net = &layer.curvenet;
    sdf::PrimSpec::new(&mut data, net.as_str(), sdf::Specifier::Def, "BasisCurves")
        .map_err(|e| content(net, format!("cannot define the prim: {e}")))?;
    let indices: Vec<i32> = layer.splines.iter().flatten().map(|&i| i as i32).collect();
    let expanded: Vec<gf::Vec3f> =
        layer.splines.iter().flatten().map(|&i| gf::Vec3f::from(layer.pool[i as usize])).collect();
    let (lo, hi) = layer.pool.iter().fold(([f32::INFINITY; 3], [f32::NEG_INFINITY; 3]), |(lo, hi), p| {
        ([0, 1, 2].map(|k| lo[k].min(p[k])), [0, 1, 2].map(|k| hi[k].max(p[k])))
    });
    let uniform = sdf::Variability::Uniform;
    let varying = sdf::Variability::Varying;
    let attributes: Vec<(&str, &str, sdf::Variability, Value, Option<&str>)> = vec![
        ("basis", "token", uniform, Value::token("bezier"), None),
        ("curveVertexCounts", "int[]", varying, Value::IntVec(vec![4; layer.splines.len()]), None),
        ("curvenet:sampleDensity", "float", uniform, Value::Float(layer.sample_density), None),
        ("extent", "float3[]", varying, Value::Vec3fVec(vec![gf::Vec3f::from(lo), gf::Vec3f::from(hi)]), None),
        ("points", "point3f[]", varying, Value::Vec3fVec(expanded), None),
        (
            "primvars:curvenet:cv",
            "point3f[]",
            varying,
            Value::Vec3fVec(layer.pool.iter().map(|&p| gf::Vec3f::from(p)).collect()),
            Some("vertex"),
        ),
        ("primvars:curvenet:cv:indices", "int[]", varying, Value::IntVec(indices), None),
        ("type", "token", uniform, Value::token("cubic"), None),
        ("wrap", "token", uniform, Value::token("nonperiodic"), None),
    ];
    for (name, type_name, variability, value, interpolation) in attributes {
        let path = format!("{net}.{name}");
        let mut attr = sdf::AttributeSpecMut::new(&mut data, path.as_str(), type_name, variability, false)
            .map_err(|e| content(net, format!("cannot author {name}: {e}")))?;
        attr.set_default(value).map_err(|e| content(net, format!("cannot set {name}: {e}")))?;
        if let Some(i) = interpolation {
            attr.set("interpolation", Value::token(i));
        }
    }
    Ok(data)
}

/// The layer of [`write_curvenet_layer`], serialised in memory.
pub fn encode_curvenet_layer(layer: &CurvenetLayer, format: LayerFormat) -> Result<Vec<u8>, WriteError> {
    let data = layer_data(layer)?;
    let mut buf = std::io::Cursor::new(Vec::new());
    encode_layer(&data, format, &mut buf)?;
    Ok(buf.into_inner())
}

/// Writes `layer` to `path` (`.usda` or `.usdc` by its extension), atomically
/// (a temporary file beside it, synced and renamed over it).
pub fn write_curvenet_layer(path: &Path, layer: &CurvenetLayer) -> Result<(), WriteError> {
    let format = LayerFormat::from_path(path)?;
    let data = layer_data(layer)?;
    write_atomically(path, |file| encode_layer(&data, format, file))
}
