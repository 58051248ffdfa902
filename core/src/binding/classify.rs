//! Binding stage 3: what every corner (cut halfedge) takes its value from —
//! a constraint row (a slot of its segment end, or the crossing row of the
//! segment its cut-vertex lies on), an unknown (a mesh vertex off the
//! curvenet in a component the curvenet touches), or nothing (a vertex of
//! an untouched component, which passes through) — and the numbering of the
//! unknowns.

use rustc_hash::FxHashMap as HashMap;

use crate::curvenet::Side;
use crate::error::{Error, Result};
use crate::halfedge::INVALID;
use crate::ids::{ConstraintRow, MeshVertex, Unknown};

use super::cut::{CROSSING, CurvePoint, CutMesh, MESH_VERTEX, SAMPLE};
use super::join::{HEAD, Joined, TAIL};
use super::parts::{BindWarning, Corner, CrossingRow};
use super::surface::Surface;

/// The corners' classification.
#[derive(Debug)]
pub(crate) struct Classified {
    /// Per cut halfedge.
    pub corner: Vec<Corner>,
    /// Constraint rows after the slots: one per (crossing cut-vertex, segment, side).
    pub crossings: Vec<CrossingRow>,
    /// Per mesh vertex: whether the curvenet passes through it.
    pub vertex_is_curve: Vec<bool>,
    /// Per mesh vertex: its connected component, or INVALID in no face.
    pub vertex_component: Vec<u32>,
    /// The mesh vertex of each unknown.
    pub unknown_vertex: Vec<MeshVertex>,
    /// Per mesh vertex: its unknown, if it has one.
    pub vertex_unknown: Vec<Option<Unknown>>,
}

impl Classified {
    /// Number of constraint rows (slots, then crossing rows).
    pub fn n_rows(&self, joined: &Joined) -> usize {
        joined.n_slots as usize + self.crossings.len()
    }

    /// Renumbers the unknowns: new unknown `k` is old unknown `perm[k]`
    /// (the factor's order, [`crate::cholesky::Cholesky::into_factor_order`]).
    pub fn renumber_unknowns(&mut self, perm: &[u32]) {
        let mut new_of = vec![0u32; perm.len()];
        for (k, &old) in perm.iter().enumerate() {
            new_of[old as usize] = k as u32;
        }
        for c in &mut self.corner {
            if let Corner::Unknown(u) = c {
                *u = Unknown(new_of[u.index()]);
            }
        }
        for u in self.vertex_unknown.iter_mut().flatten() {
            *u = Unknown(new_of[u.index()]);
        }
        self.unknown_vertex = perm.iter().map(|&old| self.unknown_vertex[old as usize]).collect();
    }
}

/// The error for cut-vertex `v`, on the curvenet but reached by no curve
/// halfedge: every sample of its curve landed on this one point (a curve
/// shorter than the snapping tolerance over a mesh vertex or edge). Names
/// a segment of that curve; an internal error if `v` holds none.
fn collapsed(cut: &CutMesh, joined: &Joined, v: u32) -> Error {
    let cv = cut.vertex(v);
    let segment = match cv.curve {
        CurvePoint::Sample(s) => joined.segments.iter().position(|pair| pair.contains(&s)),
        CurvePoint::Crossing { segment, .. } => Some(segment as usize),
        CurvePoint::None => None,
    };
    match segment.and_then(|s| joined.segment_ref.get(s)) {
        Some(&segment) => Error::CurveCollapsedOnSurface { segment, position: cv.pos.to_array() },
        None => Error::Internal { what: format!("cut-vertex {v} is on the curvenet but no curve halfedge reaches it") },
    }
}

/// Classifies the corners of `cut`. Components no curvenet touches are
/// refused with `strict`, otherwise reported in `warnings`.
pub(crate) fn classify(
    surface: &Surface,
    cut: &CutMesh,
    joined: &Joined,
    strict: bool,
    cancel: &crate::cancel::Cancel,
    warnings: &mut Vec<BindWarning>,
) -> Result<Classified> {
    let n_vertices = surface.mesh.n_vertices();
    let mut corner = vec![Corner::Fixed; cut.n_halfedges()];
    let mut crossings: Vec<CrossingRow> = Vec::new();
    let mut crossing_row: HashMap<(u32, u32, Side), u32> = HashMap::default();
    let mut vertex_is_curve = vec![false; n_vertices];
    for h in 0..cut.n_halfedges() as u32 {
        cancel.check_every(h as usize, "assembly")?;
        let v = cut.tail(h);
        let cv = cut.vertex(v);
        if cv.mask & (SAMPLE | CROSSING) == 0 {
            continue; // a plain mesh vertex: decided below
        }
        if cv.mask & MESH_VERTEX != 0 {
            vertex_is_curve[v as usize] = true;
        }
        let (seg, side, end) = curve_side(cut, h).ok_or_else(|| collapsed(cut, joined, v))?;
        // A vertex the segment's path passes through takes a crossing row
        // of that segment; one of its samples, the sample's slot.
        let row = match cut.crossing_t(v, seg) {
            Some(t) => {
                let key = (v, seg, side);
                match crossing_row.get(&key) {
                    Some(&r) => r,
                    None => {
                        let lo = joined.slot(seg, TAIL, side)?;
                        let hi = joined.slot(seg, HEAD, side)?;
                        let r = joined.n_slots + crossings.len() as u32;
                        crossings.push(CrossingRow { lo, hi, t, vertex: v });
                        crossing_row.insert(key, r);
                        r
                    }
                }
            }
            None => joined.slot(seg, end, side)?,
        };
        corner[h as usize] = Corner::Constraint(ConstraintRow(row));
    }

    // Components touched by the curvenet.
    let components = &surface.components;
    let mut touched = vec![false; components.len()];
    for h in 0..cut.n_halfedges() as u32 {
        if matches!(corner[h as usize], Corner::Constraint(_)) {
            touched[components.of_face(cut.parent(cut.face(h))) as usize] = true;
        }
    }
    let mut component_vertices = vec![0usize; components.len()];
    let mut vertex_component = vec![INVALID; n_vertices];
    for f in 0..surface.mesh.n_faces() {
        for &v in surface.mesh.face(f) {
            vertex_component[v as usize] = components.of_face(f as u32);
        }
    }
    for &c in &vertex_component {
        if c != INVALID {
            component_vertices[c as usize] += 1;
        }
    }
    let (mut count, mut vertices, mut examples) = (0, 0, Vec::new());
    for (c, &t) in touched.iter().enumerate() {
        if !t {
            if strict {
                return Err(Error::UntouchedComponent { component: c, vertices: component_vertices[c] });
            }
            count += 1;
            vertices += component_vertices[c];
            if examples.len() < BindWarning::EXAMPLES {
                examples.push((c, component_vertices[c]));
            }
        }
    }
    if count > 0 {
        warnings.push(BindWarning::UntouchedComponents { count, vertices, examples });
    }
    // Unknowns are numbered along a space-filling curve over the vertices'
    // positions, not in the mesh's vertex order: meshes from scans,
    // remeshers and DCC exports often list their vertices in no spatial
    // order (hand_94k: 55% of a face's unknowns more than 512 rows apart).
    // AMD, run on the system in this numbering, then gives an order that
    // keeps neighbours near each other, into which the binding renumbers
    // the unknowns after factoring (`Binding::new`).
    let mut unknown_vertex: Vec<MeshVertex> = (0..n_vertices)
        .filter(|&v| {
            let c = vertex_component[v];
            c != INVALID && touched[c as usize] && !vertex_is_curve[v]
        })
        .map(|v| MeshVertex(v as u32))
        .collect();
    sort_spatially(&mut unknown_vertex, &surface.points);
    let mut vertex_unknown = vec![None; n_vertices];
    for (u, v) in unknown_vertex.iter().enumerate() {
        vertex_unknown[v.index()] = Some(Unknown(u as u32));
    }
    for h in 0..cut.n_halfedges() as u32 {
        if corner[h as usize] == Corner::Fixed {
            // Corners of plain mesh vertices: cut-vertex ids below the mesh's
            // vertex count are the mesh's vertices (`CutMesh`).
            if let Some(u) = vertex_unknown.get(cut.tail(h) as usize).copied().flatten() {
                corner[h as usize] = Corner::Unknown(u);
            }
        }
    }
    Ok(Classified { corner, crossings, vertex_is_curve, vertex_component, unknown_vertex, vertex_unknown })
}

/// For the corner at `tail(h)`: the curve halfedge bounding its sector (the
/// nearest clockwise, else the nearest counter-clockwise when the mesh
/// boundary intervenes), as (segment, side of the corner, which end of the
/// segment the cut-vertex is: TAIL or HEAD).
fn curve_side(cut: &CutMesh, h: u32) -> Option<(u32, Side, u8)> {
    // Clockwise: g = outgoing, the corner lies to the left of g.
    let mut g = h;
    for _ in 0..cut.n_halfedges() {
        if let Some((s, fwd)) = cut.segment(g) {
            // g leaves the vertex: forward means the vertex is the segment's tail side.
            return Some((s, if fwd { Side::Plus } else { Side::Minus }, if fwd { TAIL } else { HEAD }));
        }
        let t = cut.twin(g);
        if t == INVALID {
            break;
        }
        g = cut.next(t);
        if g == h {
            return None;
        }
    }
    // Counter-clockwise: p = incoming, the corner lies to the left of p.
    let mut g = h;
    for _ in 0..cut.n_halfedges() {
        let p = cut.prev(g);
        if let Some((s, fwd)) = cut.segment(p) {
            // p arrives at the vertex: forward means the vertex is the segment's head side.
            return Some((s, if fwd { Side::Plus } else { Side::Minus }, if fwd { HEAD } else { TAIL }));
        }
        let t = cut.twin(p);
        if t == INVALID || t == h {
            return None;
        }
        g = t;
    }
    None
}

/// Sorts `vertices` along a Morton (Z-order) curve over their positions'
/// bounding box, 10 bits per axis; ties (and non-finite positions, which the
/// surface refuses before this) keep the vertex order.
fn sort_spatially(vertices: &mut [MeshVertex], points: &[glam::DVec3]) {
    let (mut lo, mut hi) = (glam::DVec3::splat(f64::INFINITY), glam::DVec3::splat(f64::NEG_INFINITY));
    for v in vertices.iter() {
        lo = lo.min(points[v.index()]);
        hi = hi.max(points[v.index()]);
    }
    let scale = 1023.0 / (hi - lo).max_element().max(f64::MIN_POSITIVE);
    // Spreads the low 10 bits of x to every third bit.
    let spread = |x: u32| -> u64 {
        let mut x = x as u64 & 0x3ff;
        x = (x | (x << 16)) & 0x0300_00ff;
        x = (x | (x << 8)) & 0x0300_f00f;
        x = (x | (x << 4)) & 0x030c_30c3;
        (x | (x << 2)) & 0x0924_9249
    };
    let code = |v: &MeshVertex| -> u64 {
        let q = ((points[v.index()] - lo) * scale).clamp(glam::DVec3::ZERO, glam::DVec3::splat(1023.0));
        spread(q.x as u32) | (spread(q.y as u32) << 1) | (spread(q.z as u32) << 2)
    };
    vertices.sort_by_cached_key(|v| (code(v), v.0));
}
