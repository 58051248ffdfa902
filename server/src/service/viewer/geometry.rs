//! The viewer's geometry: what it draws of a binding (the mesh in core's
//! triangulation, the cut-mesh with its edge kinds, the curvenets with
//! their marked samples and frames, the cage) and of a solved frame (its
//! points and cut-vertices, the posed curvenets, the cage), read from core.
//! Every pose comes from the `Deformer`: a frame's rest pose, posed pools
//! and cage are `Deformer::pose`'s (the code `Deformer::frame` solves
//! from), its points the solve's; nothing here evaluates blend shapes,
//! skinning or cages.

use std::collections::BTreeMap;

use curvenet_core::{Adjustment, Binding, CUT_CROSSING, CUT_MESH_VERTEX, CUT_SAMPLE, CoupledRig, Deformer, FramePose};
use curvenet_core::{INVALID_INDEX, ScaledFrame, Surface};
use curvenet_schema::wire::{BindingResponse, Warning};

use super::adjust;
use super::highlight::{Highlight, NetGeometry, Scene};
use super::views::{
    CageView, CurvenetView, CutView, EDGE_BOUNDARY, EDGE_CRACK, EDGE_CURVE, EDGE_PLAIN, MeshView, PoseView, RestView,
    ViewerAdjustment, ViewerData, ViewerFrame,
};
use crate::error::{Phase, ServiceError};

/// Samples farther than this fraction of the mesh's bounding-box diagonal
/// from the surface are listed as a viewer warning (`far_samples`): half the
/// distance at which the binding refuses them (`CutOptions::max_projection_distance`).
pub const FAR_SAMPLE_WARNING: f64 = 0.5 * curvenet_core::DEFAULT_MAX_PROJECTION_DISTANCE;

/// The cage of a caged binding at bind, with its edges, for the viewer.
fn cage_view(rig: &CoupledRig) -> CageView {
    let cage = rig.mvc().cage();
    let mut edges: Vec<[u32; 2]> = cage
        .triangles()
        .iter()
        .flat_map(|t| {
            [0, 1, 2].map(|i| {
                let (a, b) = (t[i], t[(i + 1) % 3]);
                [a.min(b), a.max(b)]
            })
        })
        .collect();
    edges.sort_unstable();
    edges.dedup();
    CageView {
        points: flat(cage.points()),
        triangles: cage.triangles().iter().flatten().copied().collect(),
        edges: edges.into_iter().flatten().collect(),
    }
}

/// Points as the wire's flat `f32` xyz.
pub fn flat(points: &[[f64; 3]]) -> Vec<f32> {
    points.iter().flat_map(|p| p.map(|x| x as f32)).collect()
}

/// The cut-vertices at their locations on the surface posed at `points`.
fn cut_points(b: &Binding, points: &[[f64; 3]]) -> Vec<f32> {
    let cut = b.cut_mesh();
    (0..cut.n_vertices() as u32)
        .flat_map(|v| b.surface().position_in(cut.vertex(v).loc, points).to_array().map(|x| x as f32))
        .collect()
}

fn flat_frames(frames: &[[ScaledFrame; 2]]) -> Vec<f32> {
    let mut out = Vec::with_capacity(frames.len() * 18);
    for pair in frames {
        for f in pair {
            for (axis, s) in [f.tangent, f.binormal, f.normal].iter().zip(f.scale) {
                out.extend(axis.iter().map(|x| (x * s) as f32));
            }
        }
    }
    out
}

/// The viewer's picture of a binding `b` of the mesh at `projection`, with
/// its coupled `cage` (`Deformer::cage`) and `response`, the answer that
/// described it: the mesh, the cut-mesh with its edge kinds, the curvenets
/// with their marked samples and neutral frames, the cage.
pub fn data(b: &Binding, projection: &[[f64; 3]], cage: Option<&CoupledRig>, response: &BindingResponse) -> ViewerData {
    let mesh_view = surface_mesh_view(b.surface(), projection);

    let cut = b.cut_mesh();
    let mut edges = Vec::new();
    let mut edge_kind = Vec::new();
    for h in 0..cut.n_halfedges() as u32 {
        let t = cut.twin(h);
        if t != INVALID_INDEX && t < h {
            continue; // one edge per halfedge pair
        }
        let kind = if t == INVALID_INDEX {
            EDGE_BOUNDARY
        } else if cut.face(t) == cut.face(h) {
            EDGE_CRACK
        } else if cut.segment(h).is_some() {
            EDGE_CURVE
        } else {
            EDGE_PLAIN
        };
        edges.extend([cut.tail(h), cut.head(h)]);
        edge_kind.push(kind);
    }
    let mut face_start = vec![0u32];
    let mut face_vertices = Vec::with_capacity(cut.n_halfedges());
    for f in 0..cut.n_faces() as u32 {
        face_vertices.extend(cut.face_halfedges(f).map(|h| cut.tail(h)));
        face_start.push(face_vertices.len() as u32);
    }
    let cut_view = CutView {
        points: (0..cut.n_vertices() as u32).flat_map(|v| cut.vertex(v).pos.to_array().map(|x| x as f32)).collect(),
        mask: (0..cut.n_vertices() as u32)
            .map(|v| cut.vertex(v).mask & (CUT_MESH_VERTEX | CUT_SAMPLE | CUT_CROSSING))
            .collect(),
        edges,
        edge_kind,
        face_start,
        face_vertices,
        face_parent: (0..cut.n_faces() as u32).map(|f| cut.parent(f)).collect(),
    };

    let diagonal = b.surface().diagonal();
    let mut warnings = response.warnings.clone();
    // (warning, curvenet) of the far_samples warnings added below.
    let mut far_warnings: Vec<(usize, usize)> = Vec::new();
    let curvenets: Vec<CurvenetView> = b
        .layouts()
        .iter()
        .enumerate()
        .map(|(k, layout)| {
            let base = b.sample_offset(k);
            let samples = layout.neutral_samples();
            let knot = |p: &u32| layout.sampling().knot_sample(*p as usize);
            let projections: Vec<[f64; 3]> = (0..samples.len()).map(|i| b.sample_projection((base + i) as u32)).collect();
            let distance = |i: usize| {
                let (q, p) = (samples[i], projections[i]);
                ((q[0] - p[0]).powi(2) + (q[1] - p[1]).powi(2) + (q[2] - p[2]).powi(2)).sqrt()
            };
            let far_samples: Vec<u32> = (0..samples.len()).filter(|&i| distance(i) > FAR_SAMPLE_WARNING * diagonal).map(|i| i as u32).collect();
            if let Some(worst) = far_samples.iter().copied().max_by(|&i, &j| distance(i as usize).total_cmp(&distance(j as usize))) {
                warnings.push(Warning {
                    code: "far_samples".into(),
                    message: format!(
                        "curvenet {k}: {} samples are farther than {}% of the diagonal from the surface (sample {worst}: {:.3}%; the binding refuses {}%)",
                        far_samples.len(),
                        FAR_SAMPLE_WARNING * 100.0,
                        distance(worst as usize) / diagonal * 100.0,
                        curvenet_core::DEFAULT_MAX_PROJECTION_DISTANCE * 100.0
                    ),
                    segment: None,
                    touches: Vec::new(),
                    faces: Vec::new(),
                    component: None,
                    count: Some(far_samples.len()),
                });
                far_warnings.push((warnings.len() - 1, k));
            }
            CurvenetView {
                samples: flat(samples),
                segments: layout.sampling().segments().iter().flat_map(|s| s.samples).collect(),
                intersections: layout.topology().intersections().iter().filter_map(knot).collect(),
                anchors: layout.topology().anchors().iter().filter_map(knot).collect(),
                removed_samples: (0..samples.len() as u32).filter(|&i| cut.sample_vertex(base as u32 + i).is_none()).collect(),
                far_samples,
                projections: flat(&projections),
                frames: flat_frames(layout.neutral_frames()),
                knots: (0..layout.sampling().n_knots()).map(|i| layout.sampling().knot_point(i)).collect(),
            }
        })
        .collect();
    let highlights = {
        let scene = Scene {
            points: projection,
            faces: Vec::new(),
            surface: Some(b.surface()),
            nets: b
                .layouts()
                .iter()
                .map(|l| NetGeometry { pool: l.neutral_pool(), splines: l.sampling().splines(), layout: Some(l) })
                .collect(),
        };
        let mut highlights: Vec<Highlight> = warnings.iter().map(|w| scene.warning(w)).collect();
        // The viewer's own far_samples warnings: the far samples of their curvenet.
        for &(w, k) in &far_warnings {
            let c: &CurvenetView = &curvenets[k];
            let mut g = Highlight {
                code: warnings[w].code.clone(),
                message: warnings[w].message.clone(),
                ..Highlight::default()
            };
            g.curvenet = Some(k as u32);
            g.sample = c.far_samples.first().copied();
            for &i in &c.far_samples {
                g.points.extend_from_slice(&c.samples[3 * i as usize..3 * i as usize + 3]);
            }
            highlights[w] = scene.finish(g);
        }
        highlights
    };
    ViewerData {
        binding: BindingResponse { cached: true, ..response.clone() },
        diagonal,
        mesh: mesh_view,
        cut: cut_view,
        curvenets,
        warnings,
        highlights,
        cage: cage.map(cage_view),
    }
}

/// The mesh as core's surface triangulates it.
pub fn surface_mesh_view(surface: &Surface, points: &[[f64; 3]]) -> MeshView {
    let (mut triangles, mut triangle_face) = (Vec::new(), Vec::new());
    for (t, f) in surface.triangles() {
        triangles.extend(t);
        triangle_face.push(f);
    }
    MeshView {
        points: flat(points),
        triangles,
        triangle_face,
        edges: surface.mesh().edges().into_iter().flat_map(|(a, c)| [a, c]).collect(),
        triangulation: "surface".into(),
    }
}

/// A mesh core could not make a surface of: a fan per face (faces with a
/// corner out of range left out), edges from the faces' sides.
pub fn fan_mesh_view(faces: &[Option<&[u32]>], points: &[[f64; 3]]) -> MeshView {
    let (mut triangles, mut triangle_face, mut edges) = (Vec::new(), Vec::new(), Vec::new());
    for (f, face) in faces.iter().enumerate() {
        let Some(face) = face else { continue };
        for k in 1..face.len().saturating_sub(1) {
            triangles.extend([face[0], face[k], face[k + 1]]);
            triangle_face.push(f as u32);
        }
        for k in 0..face.len() {
            let (a, b) = (face[k], face[(k + 1) % face.len()]);
            edges.push((a.min(b), a.max(b)));
        }
    }
    edges.sort_unstable();
    edges.dedup();
    MeshView {
        points: flat(points),
        triangles,
        triangle_face,
        edges: edges.into_iter().flat_map(|(a, b)| [a, b]).collect(),
        triangulation: "fan".into(),
    }
}

/// What the viewer draws of a solved frame: its points (the solve's, `f32`
/// as the service answers them) and the cut-vertices on the surface posed
/// at them, the posed curvenets (with the frame's `adjustments`, the
/// adjusted pools the solve used), the rest pose and the cage, all from
/// `pose` (`Deformer::pose` of the frame solved).
pub fn frame_view(
    deformer: &Deformer,
    pose: &FramePose,
    adjustments: &[Adjustment],
    points: &[[f32; 3]],
    solve_ms: f64,
    knot_orientations: Option<Vec<BTreeMap<String, [f64; 9]>>>,
) -> Result<ViewerFrame, ServiceError> {
    let b = deformer.binding();
    let rest = pose.rest.as_deref();
    let poses = |posed: &[Option<&[[f64; 3]]>]| {
        (0..b.n_curvenets())
            .map(|k| {
                let (samples, frames) = b
                    .curvenet_pose(k, posed.get(k).copied().flatten(), rest)
                    .map_err(|e| ServiceError::core(e, Phase::Frame).context(&format!("curvenet {k}")))?;
                Ok(PoseView { samples: flat(&samples), frames: flat_frames(&frames) })
            })
            .collect::<Result<Vec<_>, ServiceError>>()
    };
    // With adjustments, the curvenets drawn are the adjusted pools the solve used.
    let adjusted: Vec<Vec<[f64; 3]>> = if adjustments.is_empty() {
        Vec::new()
    } else {
        (0..b.n_curvenets())
            .map(|k| {
                let posed = pose.posed.get(k).and_then(|p| p.as_deref());
                b.adjusted_pool(k, posed, rest, adjustments)
                    .map_err(|e| ServiceError::core(e, Phase::Frame).context(&format!("curvenet {k}")))
            })
            .collect::<Result<_, _>>()?
    };
    let posed: Vec<Option<&[[f64; 3]]>> = if adjusted.is_empty() {
        pose.posed.iter().map(|p| p.as_deref()).collect()
    } else {
        adjusted.iter().map(|p| Some(&p[..])).collect()
    };
    let curvenets = poses(&posed)?;
    let rest = match rest {
        Some(r) => Some(RestView {
            points: flat(r),
            cut_points: cut_points(b, r),
            curvenets: poses(&[])?,
            cage: pose.cage.as_ref().map(|c| flat(&c.rest)),
        }),
        None => None,
    };
    // The solved points are already the wire's f32; the cut-vertices are
    // placed on the surface posed at those (the viewer draws in f32).
    let wide: Vec<[f64; 3]> = points.iter().map(|p| p.map(f64::from)).collect();
    Ok(ViewerFrame {
        time: None,
        cut_points: cut_points(b, &wide),
        points: points.as_flattened().to_vec(),
        solve_ms,
        curvenets,
        rest,
        adjustments: adjustments
            .iter()
            .map(|a| ViewerAdjustment { adjustment: adjust::spec_of(a), prim: None, source: "stage".into() })
            .collect(),
        knot_orientations,
        cage: pose.cage.as_ref().map(|c| flat(&c.posed)),
    })
}
