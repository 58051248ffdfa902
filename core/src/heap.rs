//! What the binding's types hold on the heap, measured rather than
//! estimated: every type's `heap_bytes()` adds the **capacities** of its
//! vectors (spare capacity is held memory too) times their element sizes,
//! recursing into nested vectors. Allocator overhead (size-class rounding,
//! headers) is not included; a caller budgeting memory adds its own margin.
//!
//! Types whose fields are private implement `heap_bytes` in their own
//! module with the helpers here; the binding's own types are done below.

use std::mem::size_of;

use crate::binding::{Binding, CutMesh, Surface};

/// Heap bytes of a vector's buffer (its capacity).
pub(crate) fn bytes<T>(v: &Vec<T>) -> usize {
    v.capacity() * size_of::<T>()
}

/// Heap bytes of a vector of vectors: the outer buffer and every inner one.
pub(crate) fn nested_bytes<T>(v: &Vec<Vec<T>>) -> usize {
    bytes(v) + v.iter().map(bytes).sum::<usize>()
}

impl Surface {
    /// Heap bytes held by the surface: the mesh, its halfedges, points,
    /// face planes, triangulation, vertex stars and the closest-point BVH.
    pub fn heap_bytes(&self) -> usize {
        self.mesh.heap_bytes()
            + bytes(&self.input_face)
            + bytes(&self.split_faces)
            + self.halfedges.heap_bytes()
            + bytes(&self.points)
            + bytes(&self.planes)
            + bytes(&self.corners_2d)
            + bytes(&self.triangles)
            + bytes(&self.face_tri_start)
            + bytes(&self.vertex_out)
            + bytes(&self.vertex_out_start)
            + self.bvh.heap_bytes()
    }
}

impl CutMesh {
    /// Heap bytes held by the cut-mesh (its vertices and halfedge arrays).
    pub fn heap_bytes(&self) -> usize {
        bytes(&self.vertices)
            + bytes(&self.tail)
            + bytes(&self.twin)
            + bytes(&self.face)
            + bytes(&self.segment)
            + bytes(&self.forward)
            + bytes(&self.face_start)
            + bytes(&self.parent)
            + bytes(&self.sample_vertex)
            + bytes(&self.detours)
    }
}

impl Binding {
    /// Heap bytes held by the binding: the surface, the cut-mesh, the
    /// factor (with its symbolic analysis), the curvenet layouts and every
    /// per-corner, per-sample and per-vertex array. Add `size_of::<Binding>()`
    /// for the struct itself when it is boxed or shared.
    pub fn heap_bytes(&self) -> usize {
        self.surface.heap_bytes()
            + self.cut.heap_bytes()
            + bytes(&self.nets)
            + bytes(&self.crossings)
            + bytes(&self.corner)
            + bytes(&self.unknown_vertex)
            + bytes(&self.vertex_unknown)
            + bytes(&self.face_laplacian)
            + bytes(&self.face_laplacian_start)
            + self.b.heap_bytes()
            + self.factor.heap_bytes()
            + bytes(&self.layouts)
            + self.layouts.iter().map(|l| l.heap_bytes()).sum::<usize>()
            + bytes(&self.slot_sample)
            + bytes(&self.sample_projection)
            + bytes(&self.sample_offset)
            + bytes(&self.crossing_offset)
            + bytes(&self.corner_r)
            + bytes(&self.curve_vertices)
            + bytes(&self.curve_vertex_start)
            + bytes(&self.curve_vertex_rows)
            + nested_bytes(&self.knots)
            + bytes(&self.warnings)
    }
}
