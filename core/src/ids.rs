//! Typed ids of the binding's elements, so a mesh vertex cannot be passed
//! where an unknown is expected.
//!
//! Conventions (one place for all of them):
//! - [`MeshVertex`] and [`MeshFace`] index the input mesh (`PolyMesh`), in
//!   its own order.
//! - [`CutVertex`]: the cut-mesh's vertices. **Ids below the mesh's vertex
//!   count are the mesh's own vertices, with the same number**; the vertices
//!   the cut adds (samples, segment–edge crossings) follow.
//! - [`CutHalfedge`]: the cut-mesh's halfedges, face by face, so a cut-face's
//!   corners are a contiguous range; a halfedge stands for the corner at its
//!   tail. [`CutFace`]: the cut-mesh's faces (each lies in one input face).
//! - [`Unknown`]: a column of `V` (a mesh vertex off the curvenet in a
//!   component the curvenet touches), numbered in the order of the
//!   binding's Cholesky factor (the system is first numbered along a Morton
//!   curve over the vertices' positions, then renumbered into AMD's order;
//!   not the mesh's vertex order): map with `Binding::unknown_vertex` /
//!   `Binding::vertex_unknown`.
//! - [`ConstraintRow`]: a column of `C`: the curvenets' slots first (curvenet
//!   after curvenet), then one row per (crossing cut-vertex, segment, side).
//!
//! Inside the cut-mesh's own algorithms ids stay plain `u32` with
//! `halfedge::INVALID` as "none"; the types mark the binding's interfaces.

macro_rules! id {
    ($(#[$doc:meta])* $name:ident) => {
        $(#[$doc])*
        #[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash)]
        #[derive(serde::Serialize, serde::Deserialize)]
        pub struct $name(pub u32);

        impl $name {
            /// The id as an index into per-element arrays.
            #[inline]
            pub fn index(self) -> usize {
                self.0 as usize
            }
        }

        impl std::fmt::Display for $name {
            fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
                self.0.fmt(f)
            }
        }
    };
}

id!(
    /// A vertex of the input mesh.
    MeshVertex
);
id!(
    /// A face of the input mesh.
    MeshFace
);
id!(
    /// A vertex of the cut-mesh (below the mesh's vertex count: that mesh vertex).
    CutVertex
);
id!(
    /// A halfedge of the cut-mesh, standing for the corner at its tail.
    CutHalfedge
);
id!(
    /// A face of the cut-mesh.
    CutFace
);
id!(
    /// An unknown of the solve (a column of `V`).
    Unknown
);
id!(
    /// A constraint row (a column of `C`).
    ConstraintRow
);
