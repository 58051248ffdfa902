//! Binding stage 6: the maps a frame uses to build its right-hand sides and
//! its output — which sample each slot reads, every sample's projection and
//! rest offset, every crossing row's rest offset from its chord, every
//! corner's Poisson right-hand side of a unit gradient, and the constraint
//! rows of the mesh vertices on the curvenet (whose output is their mean) —
//! and, per curvenet, where its knots sit over the surface (knot tracking).

use glam::DVec3;

use crate::cancel::Cancel;
use crate::curvenet::CurvenetLayout;
use crate::error::Result;
use crate::ids::MeshVertex;

use super::classify::Classified;
use super::cut::CutMesh;
use super::join::Joined;
use super::{Corner, KnotBinding, Surface, triangle_frame};

/// The right-hand-side maps.
#[derive(Debug)]
pub(crate) struct RhsMaps {
    pub slot_sample: Vec<u32>,
    pub sample_projection: Vec<DVec3>,
    pub sample_offset: Vec<DVec3>,
    pub crossing_offset: Vec<DVec3>,
    pub corner_r: Vec<DVec3>,
    pub curve_vertices: Vec<MeshVertex>,
    pub curve_vertex_start: Vec<u32>,
    pub curve_vertex_rows: Vec<u32>,
}

pub(crate) fn rhs_maps(
    cut: &CutMesh,
    joined: &Joined,
    curvenets: &[&CurvenetLayout],
    classified: &Classified,
    face_laplacian: (&[f64], &[u32]),
    cancel: &Cancel,
) -> Result<RhsMaps> {
    let samples = &joined.samples;
    let mut slot_sample = Vec::with_capacity(joined.n_slots as usize);
    for (layout, range) in curvenets.iter().zip(&joined.nets) {
        slot_sample.extend(layout.constraints().slots().iter().map(|s| s.sample + range.sample));
    }
    let sample_projection: Vec<DVec3> = (0..samples.len() as u32)
        .map(|i| match cut.sample_vertex(i) {
            Some(v) => cut.vertex(v).pos,
            None => DVec3::from_array(samples[i as usize]),
        })
        .collect();
    let sample_offset: Vec<DVec3> =
        samples.iter().zip(&sample_projection).map(|(q, p)| DVec3::from_array(*q) - *p).collect();
    let crossing_offset = classified
        .crossings
        .iter()
        .map(|c| {
            let (pl, ph) = (
                sample_projection[slot_sample[c.lo as usize] as usize],
                sample_projection[slot_sample[c.hi as usize] as usize],
            );
            cut.vertex(c.vertex).pos - pl.lerp(ph, c.t)
        })
        .collect();
    let (laplacian, start) = face_laplacian;
    let mut corner_r = vec![DVec3::ZERO; cut.n_halfedges()];
    for f in 0..cut.n_faces() as u32 {
        cancel.check("assembly")?; // per face: a cut-face's Laplacian costs up to its corners cubed
        let hs = cut.face_halfedges(f);
        let n = hs.len();
        let lf = &laplacian[start[f as usize] as usize..start[f as usize + 1] as usize];
        for j in 0..n {
            corner_r[hs.start as usize + j] =
                (0..n).map(|k| lf[j * n + k] * cut.vertex(cut.tail(hs.start + k as u32)).pos).sum();
        }
    }
    let n_vertices = classified.vertex_is_curve.len();
    let mut rows_of: Vec<Vec<u32>> = vec![Vec::new(); n_vertices];
    for h in 0..cut.n_halfedges() as u32 {
        let v = cut.tail(h) as usize;
        if v < n_vertices
            && classified.vertex_is_curve[v]
            && let Corner::Constraint(r) = classified.corner[h as usize]
        {
            rows_of[v].push(r.0);
        }
    }
    let mut curve_vertices = Vec::new();
    let mut curve_vertex_start = vec![0u32];
    let mut curve_vertex_rows = Vec::new();
    for (v, rows) in rows_of.iter().enumerate() {
        if !rows.is_empty() {
            curve_vertices.push(MeshVertex(v as u32));
            curve_vertex_rows.extend_from_slice(rows);
            curve_vertex_start.push(curve_vertex_rows.len() as u32);
        }
    }
    Ok(RhsMaps {
        slot_sample,
        sample_projection,
        sample_offset,
        crossing_offset,
        corner_r,
        curve_vertices,
        curve_vertex_start,
        curve_vertex_rows,
    })
}

/// Per curvenet, per pool point: its closest surface point (triangle and
/// barycentric coordinates) and its offset from it in the triangle's frame
/// (Elemental's knot tracking carries the knots to a frame's rest pose).
pub(crate) fn bind_knots(surface: &Surface, curvenets: &[&CurvenetLayout]) -> Result<Vec<Vec<KnotBinding>>> {
    let mut knots = Vec::with_capacity(curvenets.len());
    for layout in curvenets {
        let pool = layout.neutral_pool();
        let mut bound = Vec::with_capacity(pool.len());
        for p in pool {
            let hit = surface.bvh.closest_point(*p)?;
            let tri = hit.triangle;
            let [a, b, c] = surface.triangle_points(tri, &surface.points);
            let offset = DVec3::from_array(*p) - DVec3::from_array(hit.point);
            let local = match triangle_frame(a, b, c) {
                Some(fr) => [offset.dot(fr[0]), offset.dot(fr[1]), offset.dot(fr[2])],
                None => offset.to_array(),
            };
            bound.push(KnotBinding { tri, bary: hit.barycentric, local });
        }
        knots.push(bound);
    }
    Ok(knots)
}
