//! A stage whose binding is refused, drawn anyway: the stage's input built
//! through core again, stage by stage as `Deformer::new` runs them (the
//! mesh, the surface, each curvenet's analysis, the binding), keeping what
//! succeeded for drawing and reading the typed error for the element it
//! names (`highlight.rs`).

use curvenet_core::{
    BindOptions, Curvenet, CurvenetInput, CurvenetLayout, Deformer, DeformerInput, DeformerOptions, Error, MeshInput,
    PolyMesh, SamplingOptions, Surface,
};

use super::geometry::{fan_mesh_view, flat, surface_mesh_view};
use super::highlight::{NetGeometry, Scene};
use super::stage::ViewerStage;
use super::views::{SketchView, ViewerRefusal, ViewerStageInfo};
use crate::error::{Phase, ServiceError};

/// The refusal of a stage's binding, or `None` when it binds. The stages
/// run in the order `Deformer::new` runs them (mesh, surface, each
/// curvenet's analysis, the binding), keeping what succeeded for drawing.
pub fn refusal(index: usize, stage: &ViewerStage) -> Option<ViewerRefusal> {
    let req = &stage.binding;
    let points = &req.projection_points;
    let mut error: Option<Error> = None;
    let mesh = PolyMesh::new(&req.face_vertex_counts, &req.face_vertex_indices, points.len())
        .map_err(|e| error = Some(e))
        .ok();
    let surface = mesh.as_ref().and_then(|m| Surface::new(m, points).map_err(|e| error = Some(e)).ok());
    let layouts: Vec<Option<CurvenetLayout>> = req
        .curvenets
        .iter()
        .enumerate()
        .map(|(k, c)| {
            let s = surface.as_ref()?;
            let sampling = SamplingOptions::default().with_density(c.sample_density);
            Curvenet::new(&c.splines, &c.pool)
                .and_then(|net| {
                    CurvenetLayout::with_closest_point(&net, s.closest_points(), s.mean_edge_length(), &sampling)
                })
                .map_err(|e| {
                    error.get_or_insert(Error::Curvenet { curvenet: k as u32, source: Box::new(e) });
                })
                .ok()
        })
        .collect();
    if error.is_none() {
        // Everything before the binding went through: the binding itself,
        // through the one constructor, names the rest.
        let nets: Vec<CurvenetInput> = req.curvenets.iter().map(curvenet_schema::wire::CurvenetSpec::input).collect();
        let o = &req.options;
        let mut bind = BindOptions::default().with_strict(o.strict);
        bind.cut.snap_tolerance = o.snap_tolerance.unwrap_or(bind.cut.snap_tolerance);
        bind.cut.max_projection_distance = o.max_projection_distance.unwrap_or(bind.cut.max_projection_distance);
        let input = DeformerInput {
            mesh: MeshInput {
                face_vertex_counts: &req.face_vertex_counts,
                face_vertex_indices: &req.face_vertex_indices,
                projection_points: points,
            },
            curvenets: &nets,
            blend_shapes: Vec::new(),
            skinning: None,
            cage: None,
            options: DeformerOptions::default().with_bind(bind),
        };
        error = Some(Deformer::new(&input).err()?);
    }
    let error = error?;
    let answered = ServiceError::core(error.clone(), Phase::Bind).context(&stage.mesh);

    let raw = Scene::raw_faces(&req.face_vertex_counts, &req.face_vertex_indices, points.len());
    let scene = Scene {
        points,
        faces: raw.clone(),
        surface: surface.as_ref(),
        nets: req
            .curvenets
            .iter()
            .zip(&layouts)
            .map(|(c, l)| NetGeometry { pool: &c.pool, splines: &c.splines, layout: l.as_ref() })
            .collect(),
    };
    let highlight = scene.error(&error, answered.code.as_str(), &answered.message);
    let mesh_view = match &surface {
        Some(s) => surface_mesh_view(s, points),
        None => fan_mesh_view(&raw, points),
    };
    let curvenets = layouts
        .iter()
        .enumerate()
        .map(|(k, layout)| {
            let mut view =
                SketchView { points: Vec::new(), spline_start: vec![0], samples: Vec::new(), segments: Vec::new() };
            for s in 0..req.curvenets[k].splines.len() {
                let line = scene.spline_polyline(k, s);
                view.points.extend(flat(&line));
                view.spline_start.push((view.points.len() / 3) as u32);
            }
            if let Some(l) = layout {
                view.samples = flat(l.neutral_samples());
                view.segments = l.sampling().segments().iter().flat_map(|s| s.samples).collect();
            }
            view
        })
        .collect();
    Some(ViewerRefusal {
        stage: ViewerStageInfo::of(index, stage),
        code: answered.code.as_str().to_string(),
        message: answered.message,
        diagonal: curvenet_core::bounding_box_diagonal(points),
        mesh: mesh_view,
        curvenets,
        highlight,
    })
}
