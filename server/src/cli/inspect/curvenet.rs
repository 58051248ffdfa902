//! One curvenet's report: its data, its analysis against the first mesh that
//! targets it (or why there is none), its warnings and adjustments, and its
//! lines of the text report.

use std::fmt::Write as _;

use curvenet_core::{PolyMesh, Surface};
use curvenet_schema::usd::Stage;
use curvenet_schema::{CurvenetData, MeshData};
use serde::Serialize;

use super::adjustments::{AdjustmentReport, adjustment_reports, adjustment_text};
use super::analysis::{Analysis, analyse, analysis_text};
use super::wording::{list, plural};
use crate::cli::CliResult;

#[derive(Serialize)]
pub(super) struct CurvenetReport {
    path: String,
    control_points: usize,
    splines: usize,
    sample_density: f64,
    posed_frames: usize,
    control_points_at_time: Option<Vec<[f64; 3]>>,
    spline_indices: Vec<[u32; 4]>,
    /// The neutral-pose analysis; `None` when no mesh targets the curvenet
    /// or the analysis failed (then `error` says why).
    analysis: Option<Analysis>,
    /// Why the analysis failed (a `curvenet_core::Error`).
    pub(super) error: Option<AnalysisError>,
    /// The warnings about this curvenet (also in the report's `warnings`).
    pub(super) warnings: Vec<String>,
    /// Its `CurvenetAdjustment` prims, in the stage's child order.
    adjustments: Vec<AdjustmentReport>,
}

#[derive(Serialize)]
pub(super) struct AnalysisError {
    /// The `curvenet_core::Error` variant, e.g. `CoincidentTangents`.
    kind: String,
    /// The message, starting with the curvenet's prim path.
    pub(super) message: String,
}

/// A mesh's surface in its projection pose (core's, as the bake samples
/// against it), built once for all the curvenets that target it.
pub(super) fn surface(m: &MeshData) -> Result<Surface, curvenet_core::Error> {
    let mesh = PolyMesh::new(&m.face_vertex_counts, &m.face_vertex_indices, m.projection_points.len())?;
    Surface::new(&mesh, &m.projection_points)
}

pub(super) fn curvenet_report(
    stage: &Stage,
    c: &CurvenetData,
    time: Option<f64>,
    meshes: &[MeshData],
    surfaces: &mut [Option<Result<Surface, curvenet_core::Error>>],
) -> CliResult<CurvenetReport> {
    let mut warnings = Vec::new();
    let control_points_at_time = match time {
        Some(t) => {
            let pool = stage.posed_pool(c, time)?;
            if let Some(pool) = &pool {
                let bad: Vec<u32> =
                    (0..pool.len() as u32).filter(|&i| !pool[i as usize].iter().all(|x| x.is_finite())).collect();
                if !bad.is_empty() {
                    warnings.push(format!(
                        "{}: at time {t} the posed pool (primvars:curvenet:cv) has {} non-finite control point{}: {} \
                         (control point {} is {:?})",
                        c.path,
                        bad.len(),
                        plural(bad.len()),
                        list(&bad),
                        bad[0],
                        pool[bad[0] as usize]
                    ));
                }
            }
            Some(pool.unwrap_or_else(|| c.pool.clone()))
        }
        None => None,
    };
    let unused = unused_control_points(c);
    if !unused.is_empty() {
        warnings.push(format!(
            "{}: {} control point{} of the pool {} used by no spline: {}",
            c.path,
            unused.len(),
            plural(unused.len()),
            if unused.len() == 1 { "is" } else { "are" },
            list(&unused)
        ));
    }
    let targeting: Vec<usize> = (0..meshes.len()).filter(|&m| meshes[m].curvenets.contains(&c.path)).collect();
    let (analysis, error) = match targeting.first() {
        None => {
            warnings.push(format!(
                "{}: no deformed mesh targets this curvenet (rel curvenet:curvenets), so it cannot be analysed \
                 against a surface",
                c.path
            ));
            (None, None)
        }
        Some(&m) => {
            if targeting.len() > 1 {
                let paths: Vec<&str> = targeting.iter().map(|&k| meshes[k].path.as_str()).collect();
                warnings.push(format!(
                    "{}: {} meshes target this curvenet ({}); it is analysed against the first, {}",
                    c.path,
                    targeting.len(),
                    paths.join(", "),
                    meshes[m].path
                ));
            }
            let surface = surfaces[m].get_or_insert_with(|| surface(&meshes[m]));
            let result = match surface {
                Ok(surface) => analyse(c, &meshes[m].path, surface, unused, &mut warnings),
                Err(e) => Err(e.clone()),
            };
            match result {
                Ok(a) => (Some(a), None),
                Err(e) => {
                    let message = match surface {
                        Ok(_) => format!("{}: {e}", c.path),
                        Err(_) => format!("{}: cannot analyse against mesh {}: {e}", c.path, meshes[m].path),
                    };
                    (None, Some(AnalysisError { kind: error_kind(&e), message }))
                }
            }
        }
    };
    Ok(CurvenetReport {
        path: c.path.clone(),
        control_points: c.pool.len(),
        splines: c.splines.len(),
        sample_density: c.sample_density,
        posed_frames: c.sample_times.len(),
        control_points_at_time,
        spline_indices: c.splines.clone(),
        analysis,
        error,
        warnings,
        adjustments: adjustment_reports(stage, c, time)?,
    })
}

fn unused_control_points(c: &CurvenetData) -> Vec<u32> {
    let mut used = vec![false; c.pool.len()];
    for s in &c.splines {
        for &p in s {
            if let Some(u) = used.get_mut(p as usize) {
                *u = true;
            }
        }
    }
    (0..c.pool.len() as u32).filter(|&p| !used[p as usize]).collect()
}

/// The variant name of a core error (`CoincidentTangents`, ...).
fn error_kind(e: &curvenet_core::Error) -> String {
    format!("{e:?}").chars().take_while(|c| c.is_alphanumeric() || *c == '_').collect()
}

/// The curvenet's lines of the text report.
pub(super) fn curvenet_text(s: &mut String, c: &CurvenetReport) {
    let _ = writeln!(
        s,
        "curvenet {}: {} control points, {} splines, sample density {}, {} posed frames",
        c.path, c.control_points, c.splines, c.sample_density, c.posed_frames
    );
    if let Some(e) = &c.error {
        let _ = writeln!(s, "  error ({}): {}", e.kind, e.message);
    }
    if let Some(a) = &c.analysis {
        analysis_text(s, a);
    }
    for a in &c.adjustments {
        adjustment_text(s, a);
    }
}
