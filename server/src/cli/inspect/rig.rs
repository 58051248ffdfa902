//! A mesh's UsdSkel rig (skeleton, animation, skinning) and the spline
//! skinning of its curvenets, with their distance to the skinned curves at
//! `--time`, and their lines of the text report.

use std::fmt::Write as _;

use curvenet_schema::usd::Stage;
use curvenet_schema::{CurvenetData, MeshData};
use serde::Serialize;

use crate::cli::rig::MeshRig;
use crate::cli::{CliError, CliResult};

/// The rig found for a mesh (`crate::cli::rig::MeshRig`).
#[derive(Serialize)]
pub(super) struct RigReport {
    skel_root: String,
    skeleton: String,
    joints: Vec<String>,
    animation: Option<String>,
    /// Time codes of the animation's joint-transform samples.
    animation_frames: usize,
    method: &'static str,
    influences_per_point: usize,
    /// The influences were authored `constant` (one set for the whole mesh).
    rigid: bool,
    geom_bind_transform: [f64; 16],
    /// Points whose skin weights do not sum to 1 (skinned as authored).
    unnormalized_points: usize,
    /// Blend shapes before skinning (UsdSkel's order) or after the solve.
    blend_shape_order: &'static str,
    curvenets: Vec<NetRigReport>,
    /// Wall time of the spline skinning precomputation.
    spline_precompute_ms: f64,
}

#[derive(Serialize)]
struct NetRigReport {
    path: String,
    /// `weights` (per control point), `mesh` (from the mesh's skin weights)
    /// or `none` (its own samples, else knot tracking).
    skinning: &'static str,
    /// The joints that weigh on the curvenet.
    joints: Vec<String>,
    /// `mesh`: the largest difference between the per-control-point weights
    /// derived from the mesh's and the mesh's own, at samples of the curves.
    #[serde(skip_serializing_if = "Option::is_none")]
    derived_weight_deviation: Option<f64>,
    c1_junctions: usize,
    g1_junctions: usize,
    angle_junctions: usize,
    /// With `--time`: the integrated distance (mean over arc length, and the
    /// largest) of the spline-skinned and of the naively skinned control
    /// points' curves to the densely skinned curves, over the mesh's diagonal.
    #[serde(skip_serializing_if = "Option::is_none")]
    distance_at_time: Option<SkinDistanceReport>,
}

#[derive(Serialize)]
struct SkinDistanceReport {
    spline_mean: f64,
    spline_max: f64,
    naive_mean: f64,
    naive_max: f64,
}

pub(super) fn rig_report(
    stage: &Stage,
    m: &MeshData,
    nets: &[CurvenetData],
    rig: MeshRig,
    time: Option<f64>,
) -> CliResult<RigReport> {
    use curvenet_core::JunctionKind;
    let transforms = match time {
        Some(_) => Some(rig.joints.read_transforms(stage, time)?),
        None => None,
    };
    let diagonal = curvenet_core::bounding_box_diagonal(&m.projection_points);
    let mut curvenets = Vec::new();
    for ((net, nr), spline) in nets.iter().zip(&rig.nets).zip(&rig.skinning.curvenets) {
        let (Some(nr), Some(spline)) = (nr, spline) else {
            curvenets.push(NetRigReport {
                path: net.path.clone(),
                skinning: "none",
                joints: Vec::new(),
                derived_weight_deviation: None,
                c1_junctions: 0,
                g1_junctions: 0,
                angle_junctions: 0,
                distance_at_time: None,
            });
            continue;
        };
        let count = |f: fn(&JunctionKind) -> bool| spline.junctions().iter().filter(|j| f(&j.kind)).count();
        let distance_at_time = match &transforms {
            None => None,
            Some(xf) => {
                let core = |source| CliError::Core { context: net.path.clone(), source };
                let mut fit = vec![[0.0; 3]; spline.n_points()];
                let mut naive = fit.clone();
                spline.pose(xf, &mut fit).map_err(core)?;
                spline.pose_naive(xf, &mut naive).map_err(core)?;
                let (a, b) = (
                    spline.distance_to_skinned(&fit, xf).map_err(core)?,
                    spline.distance_to_skinned(&naive, xf).map_err(core)?,
                );
                Some(SkinDistanceReport {
                    spline_mean: a.mean / diagonal,
                    spline_max: a.max / diagonal,
                    naive_mean: b.mean / diagonal,
                    naive_max: b.max / diagonal,
                })
            }
        };
        curvenets.push(NetRigReport {
            path: net.path.clone(),
            skinning: nr.mode,
            joints: spline.joints().iter().map(|&j| rig.joints.rig.joints[j as usize].clone()).collect(),
            derived_weight_deviation: nr.weight_deviation,
            c1_junctions: count(|k| *k == JunctionKind::C1),
            g1_junctions: count(|k| *k == JunctionKind::G1),
            angle_junctions: count(|k| matches!(k, JunctionKind::Angle(_))),
            distance_at_time,
        });
    }
    let order = stage.blend_shape_order(m)?.unwrap_or(curvenet_schema::usd::BlendShapeOrder::BeforeSkinning);
    Ok(RigReport {
        skel_root: rig.joints.rig.skel_root.clone(),
        skeleton: rig.joints.rig.skeleton.clone(),
        joints: rig.joints.rig.joints.clone(),
        animation: rig.joints.rig.animation.clone(),
        animation_frames: rig.joints.rig.time_samples.len(),
        method: rig.skinning.skin.method().token(),
        influences_per_point: rig.joints.rig.element_size,
        rigid: rig.joints.rig.constant_influences,
        geom_bind_transform: rig.joints.rig.geom_bind_transform,
        unnormalized_points: rig.unnormalized.len(),
        blend_shape_order: match order {
            curvenet_schema::usd::BlendShapeOrder::BeforeSkinning => "beforeSkinning",
            curvenet_schema::usd::BlendShapeOrder::AfterSolve => "afterSolve",
        },
        curvenets,
        spline_precompute_ms: rig.spline_ms,
    })
}

pub(super) fn rig_text(s: &mut String, r: &RigReport) {
    let short: Vec<&str> = r.joints.iter().map(|j| j.rsplit('/').next().unwrap_or(j)).collect();
    let _ = writeln!(
        s,
        "  rig: skeleton {} ({} joints: {}) under {}, animation {} ({} frames), {}, {} influences per point{}, \
         geomBindTransform {}, blend shapes {}",
        r.skeleton,
        r.joints.len(),
        short.join(", "),
        r.skel_root,
        r.animation.as_deref().unwrap_or("none (rest pose)"),
        r.animation_frames,
        r.method,
        r.influences_per_point,
        if r.rigid { " (rigid: constant)" } else { "" },
        if r.geom_bind_transform == curvenet_core::MAT4_IDENTITY {
            "identity".to_string()
        } else {
            format!("{:?}", r.geom_bind_transform)
        },
        r.blend_shape_order
    );
    if r.unnormalized_points > 0 {
        let _ = writeln!(s, "    {} points' weights do not sum to 1 (skinned as authored)", r.unnormalized_points);
    }
    for c in &r.curvenets {
        if c.skinning == "none" {
            let _ = writeln!(s, "  curvenet {}: not spline-skinned (own samples, else knot tracking)", c.path);
            continue;
        }
        let how = match c.derived_weight_deviation {
            None => "weights per control point".to_string(),
            Some(d) => format!("weights from the mesh, per control point, within {d:.3} of the mesh's"),
        };
        let _ = writeln!(
            s,
            "  curvenet {}: spline-skinned ({how}) by {}; constraints: {} C1, {} G1, {} angle",
            c.path,
            c.joints.iter().map(|j| j.rsplit('/').next().unwrap_or(j)).collect::<Vec<_>>().join(", "),
            c.c1_junctions,
            c.g1_junctions,
            c.angle_junctions
        );
        if let Some(d) = &c.distance_at_time {
            let _ = writeln!(
                s,
                "    distance to the skinned curves (x diagonal): spline skinning mean {:.3e}, max {:.3e}; naive control points mean {:.3e}, max {:.3e}",
                d.spline_mean, d.spline_max, d.naive_mean, d.naive_max
            );
        }
    }
}
