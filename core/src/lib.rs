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
pub mod frame;
pub mod halfedge;
pub mod heap;
pub mod ids;
pub mod mesh;
pub mod persist;
pub mod polygon_laplacian;
pub mod rig;
pub mod simd;
pub mod skinning;
pub mod solve;
pub mod sparse;

// The curated API: everything code outside core (schema, server, the
// workspace tests) may name is re-exported here, grouped by concept;
// `scripts/check-imports` fails when code outside core reaches past it.
// The modules stay `pub` for core's own integration tests (core/tests).

// Binding (precompute) and the frame solve (runtime).
pub use binding::cut::{
    CROSSING as CUT_CROSSING, CutOptions, DEFAULT_MAX_PROJECTION_DISTANCE, MESH_VERTEX as CUT_MESH_VERTEX,
    SAMPLE as CUT_SAMPLE,
};
pub use binding::{BindOptions, BindStats, BindTimings, BindWarning, Binding, Surface};
pub use deformer::{
    BatchError, BlendShapeMode, CageInput, CagePose, CurvenetInput, DEFAULT_BATCH_FRAMES, Deformer, DeformerInput,
    DeformerOptions, FlexibleStats, Frame, FrameOut, FramePose, MAX_BATCH_FRAMES, MeshInput,
};
pub use solve::Workspace;

// Inputs: meshes, curvenets, blend shapes, animation controls.
pub use adjust::{Adjustment, Rotate, fit_rotation, knot_tangents};
pub use blend_shapes::{BlendShape, BlendShapes};
pub use curvenet::{CurveEnd, Curvenet, CurvenetLayout, Mat3, SamplingOptions, ScaledFrame, Side};
pub use halfedge::INVALID as INVALID_INDEX;
pub use mesh::{PolyMesh, bounding_box_diagonal};

// Rig layers underneath: UsdSkel and spline skinning, coupled cages.
pub use cage::{CageError, CageFrame, CageRevApproximation, CoupledRig, CoupledWorkspace, fan_triangles};
pub use rig::{
    InfluenceArrays, NetSkinning, Rig, RigCurvenet, RigError, RigInput, RigPart, RigReport, WEIGHT_SUM_TOLERANCE,
};
pub use skinning::{
    ControlPointWeights, DERIVED_WEIGHT_SAMPLES, IDENTITY as MAT4_IDENTITY, Influences, JunctionKind, Mat4, Skeleton,
    Skin, SkinningMethod, SplineSkinning, SplineSkinningOptions, SurfaceWeights, check_affine, inverse as mat4_inverse,
    mul as mat4_mul, skin_points, transform_point,
};

// Errors, cancellation, geometry queries.
pub use cancel::Cancel;
pub use closest_point::{ClosestPointBvh, Hit};
pub use error::{Error, Result, SampleRef, SegmentRef};

// Drafting curvenets on a bare mesh (`curvenet draft`, the stress tests).
pub use draft::{Draft, DraftError, DraftOptions, Jitter, SplitMix64, draft};

// Diagnostics for `curvenet bench` and `curvenet inspect`: the solver's
// stages one by one, the vector unit, counters of rebuilds.
pub use cholesky::{Cholesky, Ordering as FillOrdering, SymmetricTriplets};
#[cfg(feature = "counters")]
pub use counters::{cut_mesh_builds, lane_row_groups, numeric_factorizations};
pub use curvenet::{constraint_gradients_into, deformation_gradients_into, scaled_frames_into};
pub use ids::Unknown;
// The stored form of a deformer (`Deformer::to_bytes` / `from_bytes`).
pub use persist::{
    FORMAT_VERSION as STORED_FORMAT_VERSION, FormatError as StoredFormatError, HEADER_BYTES as STORED_HEADER_BYTES,
};
pub use simd::Simd;
