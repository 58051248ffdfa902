//! Binding stages 4 and 5: the cut-aware Laplacian assembled face by face
//! (each cut-face's polygon Laplacian, paper §4.2), split by corner into
//! `VᵀL_hV` (the system matrix) and `VᵀL_hC` (`b`, the map from constraint
//! rows to the right-hand side), and the factorisation of `VᵀL_hV`.

use crate::cancel::Cancel;
use crate::cholesky::{Cholesky, SymmetricTriplets};
use crate::error::{Error, Result};
use crate::polygon_laplacian::{PolygonScratch, polygon_laplacian};
use crate::sparse::Csr;

use super::cut::CutMesh;
use super::parts::{BindWarning, Corner};
use super::surface::Surface;
use crate::ids::MeshVertex;

/// The assembled Laplacian.
#[derive(Debug)]
pub(crate) struct Assembled {
    /// Per-cut-face Laplacians, row-major, concatenated.
    pub face_laplacian: Vec<f64>,
    /// Where each cut-face's square starts in `face_laplacian` (one more than faces).
    pub face_laplacian_start: Vec<u32>,
    /// Lower triangle of `VᵀL_hV` as (row, column, value) triplets.
    pub system: Vec<(u32, u32, f64)>,
    /// `VᵀL_hC`: unknowns × constraint rows.
    pub b: Csr,
}

/// Assembles the Laplacian of `cut` with corners classified as `corner`.
/// Zero-area cut-faces contribute nothing (reported in `warnings`).
pub(crate) fn assemble(
    cut: &CutMesh,
    corner: &[Corner],
    (n_unknowns, n_rows): (usize, usize),
    lambda: f64,
    cancel: &Cancel,
    warnings: &mut Vec<BindWarning>,
) -> Result<Assembled> {
    let mut system = Vec::new();
    let mut b_entries: Vec<(u32, u32, f64)> = Vec::new();
    let mut face_laplacian = Vec::new();
    let mut face_laplacian_start = vec![0u32];
    let mut scratch = PolygonScratch::default();
    let mut lf = Vec::new();
    let mut corners = Vec::new();
    let mut degenerate = 0usize;
    for f in 0..cut.n_faces() as u32 {
        cancel.check("assembly")?; // per face: a cut-face's Laplacian costs up to its corners cubed
        let hs = cut.face_halfedges(f);
        corners.clear();
        corners.extend(hs.clone().map(|h| cut.vertex(cut.tail(h)).pos));
        let n = corners.len();
        if polygon_laplacian(&corners, lambda, &mut scratch, &mut lf).is_none() {
            degenerate += 1;
            lf.clear();
            lf.resize(n * n, 0.0);
        }
        face_laplacian.extend_from_slice(&lf);
        face_laplacian_start.push(face_laplacian.len() as u32);
        split_face(&lf, &corner[hs.start as usize..hs.end as usize], &mut system, Some(&mut b_entries));
    }
    if degenerate > 0 {
        warnings.push(BindWarning::DegenerateCutFaces { count: degenerate });
    }
    let b = Csr::from_triplets(n_unknowns, n_rows, b_entries);
    Ok(Assembled { face_laplacian, face_laplacian_start, system, b })
}

/// Splits one cut-face's Laplacian `lf` (n×n, row-major, n = `corner.len()`,
/// its corners in order) by corner: unknown–unknown entries of the lower
/// triangle to `system` (`VᵀL_hV`), unknown–constraint entries to `b`
/// (`VᵀL_hC`) when given. [`assemble`] and [`super::Binding::system_matrix`]
/// both split through here, so the exported matrix is the factored one.
pub(crate) fn split_face(
    lf: &[f64],
    corner: &[Corner],
    system: &mut Vec<(u32, u32, f64)>,
    mut b: Option<&mut Vec<(u32, u32, f64)>>,
) {
    let n = corner.len();
    for j in 0..n {
        let Corner::Unknown(uj) = corner[j] else { continue };
        for k in 0..n {
            let l = lf[j * n + k];
            if l == 0.0 {
                continue;
            }
            match corner[k] {
                Corner::Unknown(uk) if uk <= uj => system.push((uj.0, uk.0, l)),
                Corner::Constraint(r) => {
                    if let Some(b) = b.as_deref_mut() {
                        b.push((uj.0, r.0, l));
                    }
                }
                _ => {}
            }
        }
    }
}

/// Factors `VᵀL_hV`. Every unknown's component is constrained, so the
/// matrix is positive definite in exact arithmetic; a pivot that fails
/// means a face too thin for the cotangent weights (a sliver that passed
/// the zero-area check): [`Error::IllConditionedFace`] names the failing
/// pivot's mesh vertex and the face of its component with the smallest
/// corner angle.
pub(crate) fn factor(
    system: Vec<(u32, u32, f64)>,
    surface: &Surface,
    unknown_vertex: &[MeshVertex],
    vertex_component: &[u32],
) -> Result<Cholesky> {
    let n = unknown_vertex.len();
    if n == 0 {
        return Cholesky::new(&SymmetricTriplets { n: 0, entries: Vec::new() });
    }
    Cholesky::new(&SymmetricTriplets { n, entries: system }).map_err(|e| match e {
        Error::NotPositiveDefinite { pivot } => {
            let Some(v) = pivot.and_then(|u| unknown_vertex.get(u)) else {
                return Error::Internal { what: "VᵀLV is not positive definite (no failing pivot named)".into() };
            };
            let component = vertex_component[v.index()];
            match thinnest_face(surface, |v| vertex_component[v as usize] == component) {
                Some((f, angle_deg)) => Error::IllConditionedFace {
                    vertex: v.index() as u32,
                    face: surface.input_face[f] as usize,
                    vertices: surface.mesh.face(f).to_vec(),
                    angle_deg,
                },
                None => Error::Internal { what: format!("VᵀLV is not positive definite at mesh vertex {v}") },
            }
        }
        other => other,
    })
}

/// The face (of `surface`'s mesh) with the smallest corner angle, in
/// degrees, among the faces whose first vertex `keep` accepts.
fn thinnest_face(surface: &Surface, keep: impl Fn(u32) -> bool) -> Option<(usize, f64)> {
    let p = &surface.points;
    let mut best: Option<(usize, f64)> = None;
    for f in 0..surface.mesh.n_faces() {
        let c = surface.mesh.face(f);
        if !keep(c[0]) {
            continue;
        }
        for k in 0..c.len() {
            let o = p[c[k] as usize];
            let (a, b) = (p[c[(k + 1) % c.len()] as usize] - o, p[c[(k + c.len() - 1) % c.len()] as usize] - o);
            let angle = a.cross(b).length().atan2(a.dot(b)).to_degrees();
            if best.is_none_or(|(_, m)| angle < m) {
                best = Some((f, angle));
            }
        }
    }
    best
}
