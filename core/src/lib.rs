//! curvenet-core: the math of "Character Articulation through Profile Curves"
//! (de Goes, Sheffler, Fleischer 2022), over plain slices.
//!
//! No async runtime, no JSON, no USD, no HTTP: callers (the `schema` crate's
//! USD reader, the server) hand in `&[[f64; 3]]` points and index slices.
//!
//! Conventions used throughout:
//! - Points are `[f64; 3]`; indices are `u32`.
//! - A polygon mesh is `face_vertex_counts` + `face_vertex_indices`
//!   (the USD / OBJ layout), faces counter-clockwise seen from outside.
//! - A curvenet is a pool of control points plus cubic Bézier splines, each a
//!   `[u32; 4]` of indices into the pool.

pub mod adjust;
pub mod binding;
pub mod blend_shapes;
pub mod cage;
pub mod cancel;
pub mod cholesky;
pub mod closest_point;
#[cfg(feature = "counters")]
pub mod counters;
pub mod curvenet;
pub mod deformer;
pub mod draft;
pub mod error;
pub mod halfedge;
pub mod heap;
pub mod ids;
pub mod mesh;
pub mod polygon_laplacian;
pub mod simd;
pub mod skinning;
pub mod solve;
pub mod sparse;

pub use adjust::{Adjustment, Rotate};
pub use binding::{BindOptions, BindWarning, Binding};
pub use cancel::Cancel;
pub use closest_point::{ClosestPointBvh, Hit};
pub use curvenet::{Curvenet, CurvenetLayout, Mat3, SamplingOptions, Side};
pub use deformer::{
    BatchError, BlendShapeMode, CageInput, CurvenetInput, DEFAULT_BATCH_FRAMES, Deformer, DeformerInput,
    DeformerOptions, FlexibleStats, Frame, FrameOut, MAX_BATCH_FRAMES, MeshInput, Rig,
};
pub use error::{Error, Result};
pub use mesh::PolyMesh;
pub use solve::{FrameInput, Workspace};
