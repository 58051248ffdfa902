//! A curvenet's Curvenet Adjustments (`CurvenetAdjustment` children): their
//! knot, tangents, animated attributes and values at `--time`, and their lines
//! of the text report.

use std::collections::BTreeMap;
use std::fmt::Write as _;

use curvenet_schema::CurvenetData;
use curvenet_schema::usd::Stage;
use serde::Serialize;

use super::wording::{list, plural};
use crate::cli::CliResult;

/// A `CurvenetAdjustment` prim (schema/README.md).
#[derive(Serialize)]
pub(super) struct AdjustmentReport {
    path: String,
    /// The knot's pool index.
    knot: u32,
    /// `intersection`, `anchor` or `pass-through` (a valence-2 knot).
    knot_kind: &'static str,
    valence: usize,
    attach_tangents: bool,
    /// The knot's tangent control points (the order of `curvenet:tangentTranslates`).
    tangents: Vec<u32>,
    /// The authored attributes and how many time samples each has (0: static).
    attributes: BTreeMap<String, usize>,
    /// The values at `--time` (the default values without it): translate,
    /// rotate (`euler_xyz_degrees` or `quaternion_wxyz`), scale, tangent translates.
    values: AdjustmentValues,
}

#[derive(Serialize)]
pub(super) struct AdjustmentValues {
    time: Option<f64>,
    translate: [f64; 3],
    euler_xyz_degrees: Option<[f64; 3]>,
    quaternion_wxyz: Option<[f64; 4]>,
    scale: [f64; 3],
    tangent_translates: Vec<[f64; 3]>,
}

/// The curvenet's adjustments with their values at `time`.
pub(super) fn adjustment_reports(
    stage: &Stage,
    c: &CurvenetData,
    time: Option<f64>,
) -> CliResult<Vec<AdjustmentReport>> {
    let list = stage.curvenet_adjustments(c)?;
    let values = stage.adjustments_at(std::slice::from_ref(&list), time)?;
    Ok(list
        .into_iter()
        .zip(values)
        .map(|(a, v)| {
            let valence = c.splines.iter().map(|s| (s[0] == a.knot) as usize + (s[3] == a.knot) as usize).sum();
            let (euler_xyz_degrees, quaternion_wxyz) = match v.rotate {
                curvenet_core::Rotate::EulerXyz(e) => (Some(e), None),
                curvenet_core::Rotate::Quaternion(q) => (None, Some(q)),
            };
            AdjustmentReport {
                knot_kind: match valence {
                    1 => "anchor",
                    2 => "pass-through",
                    _ => "intersection",
                },
                path: a.path,
                knot: a.knot,
                valence,
                attach_tangents: a.attach_tangents,
                tangents: a.tangents,
                attributes: a.attributes.into_iter().map(|(name, times)| (name, times.len())).collect(),
                values: AdjustmentValues {
                    time,
                    translate: v.translate,
                    euler_xyz_degrees,
                    quaternion_wxyz,
                    scale: v.scale,
                    tangent_translates: v.tangent_translates,
                },
            }
        })
        .collect())
}

pub(super) fn adjustment_text(s: &mut String, a: &AdjustmentReport) {
    let attributes: Vec<String> = a
        .attributes
        .iter()
        .map(|(name, n)| match n {
            0 => format!("{name} (static)"),
            n => format!("{name} ({n} time sample{})", plural(*n)),
        })
        .collect();
    let _ = writeln!(
        s,
        "  adjustment {}: knot {} ({}, valence {}), tangents {} ({}): {}",
        a.path,
        a.knot,
        a.knot_kind,
        a.valence,
        if a.attach_tangents { "attached" } else { "free" },
        list(&a.tangents),
        if attributes.is_empty() { "nothing authored".to_string() } else { attributes.join(", ") }
    );
    let v = &a.values;
    let rotate = match (v.euler_xyz_degrees, v.quaternion_wxyz) {
        (_, Some(q)) => format!("orient (w, x, y, z) {q:?}"),
        (Some(e), None) => format!("rotateXYZ {e:?} degrees"),
        (None, None) => "no rotate".to_string(),
    };
    let _ = writeln!(
        s,
        "    {}: translate {:?}, {rotate}, scale {:?}, tangent translates {:?}",
        match v.time {
            Some(t) => format!("at time {t}"),
            None => "default values".to_string(),
        },
        v.translate,
        v.scale,
        v.tangent_translates
    );
}
