//! The one error type of the core. Every variant names the offending element
//! (face, vertex, spline, control point) so a user can fix the input from the
//! message alone. The skinning and cage errors live here too, below the
//! modules that raise them, so no module this file names imports it back.

use crate::cage::limits::{MAX_CAGE_VERTICES, MAX_PHI_BYTES};

/// Errors raised by curvenet-core. User mistakes (bad input) and internal
/// failures are separate variants; the latter should never happen.
///
/// Not `#[non_exhaustive]`: the service maps every variant to an error
/// code explicitly, so a new variant does not compile until it has one.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum Error {
    /// A polygon mesh or curvenet has no elements where some are required.
    #[error("{what} is empty")]
    Empty { what: &'static str },
    /// `face_vertex_counts` does not add up to the length of `face_vertex_indices`.
    #[error("face vertex counts sum to {counts_sum} but there are {indices_len} face vertex indices")]
    FaceCountMismatch { counts_sum: usize, indices_len: usize },
    /// A face has fewer than three corners.
    #[error("face {face} has {count} vertices; a face needs at least 3")]
    DegenerateFaceCount { face: usize, count: u32 },
    /// An index refers past the end of the array it indexes.
    #[error("{what} {index} refers to {target} {value}, but there are only {len}")]
    IndexOutOfRange { what: &'static str, index: usize, target: &'static str, value: u32, len: usize },
    /// A coordinate is NaN or infinite.
    #[error("{what} {index} has a non-finite coordinate {value:?}")]
    NonFinite { what: &'static str, index: usize, value: [f64; 3] },
    /// A scalar input (a weight) is NaN or infinite.
    #[error("{what} {index} is {value}, not a finite number")]
    NonFiniteScalar { what: &'static str, index: usize, value: f64 },
    /// An error about one curvenet's own shape (its splines, sampling or
    /// intersections), naming the curvenet by its index in the binding.
    #[error("curvenet {curvenet}: {source}")]
    Curvenet { curvenet: u32, source: Box<Error> },
    /// An error of a curvenet tracked onto a frame's own rest pose
    /// (Elemental's knot tracking): what degenerated is the rest pose the
    /// frame brought, not the curvenet as drawn or posed. Wrapped in
    /// [`Error::Curvenet`] naming the curvenet.
    #[error("tracked onto the frame's rest pose: {source}")]
    RestPose { source: Box<Error> },
    /// Two arrays that must have the same length do not.
    #[error("{what}: expected {expected} entries, got {got}")]
    CountMismatch { what: &'static str, expected: usize, got: usize },
    /// More than two faces share an edge.
    #[error("non-manifold edge ({a}, {b}): {count} faces share it ({faces:?})")]
    NonManifoldEdge { a: u32, b: u32, faces: Vec<u32>, count: usize },
    /// Two faces traverse their shared edge in the same direction.
    #[error("faces {} and {} have opposite orientations across edge ({a}, {b})", faces[0], faces[1])]
    InconsistentOrientation { a: u32, b: u32, faces: [u32; 2] },
    /// The faces around a vertex form more than one fan (e.g. a bowtie).
    #[error(
        "non-manifold vertex {vertex}: its faces form several fans (one fan covers {fans_cover} of its {faces} faces)"
    )]
    NonManifoldVertex { vertex: u32, fans_cover: u32, faces: u32 },
    /// Two consecutive corners of a face coincide (a zero-length edge).
    #[error(
        "face {face} has coincident corners: vertices {a} and {b} are at the same position (merge them or remove the edge)"
    )]
    CoincidentFaceVertices { face: usize, a: u32, b: u32 },
    /// A face of (numerically) zero area.
    #[error("face {face} (vertices {vertices:?}) has zero area ({area:e}): its corners are collinear")]
    ZeroAreaFace { face: usize, vertices: Vec<u32>, area: f64 },
    /// A face whose corners, projected onto its own plane, fold over each other.
    #[error(
        "face {face} folds over itself (its projection onto its own plane is not a simple counter-clockwise polygon)"
    )]
    FoldedFace { face: usize },
    /// A curvenet sample too far from the surface to bind.
    #[error("{at} at {position:?} is {distance:e} from the surface, farther than the limit {limit:e}")]
    SampleFarFromSurface { at: SampleRef, position: [f64; 3], distance: f64, limit: f64 },
    /// A segment's path could not be traced over the surface (a bug: a
    /// path between two points of one component always exists).
    #[error("{segment} could not be traced over the surface between its samples")]
    SegmentNotTraced { segment: SegmentRef },
    /// In strict mode: a segment whose surface path is much longer than the
    /// segment (its samples project across a concavity or onto the far side
    /// of a thin part), or whose samples project onto different components
    /// (`path_length` infinite).
    #[error("{segment} at {position:?} (spline parameter {t:.3}) {}", detour_text(*path_length, *segment_length))]
    SegmentDetour { segment: SegmentRef, t: f64, position: [f64; 3], path_length: f64, segment_length: f64 },
    /// Segments of two different curves run over one stretch of the surface
    /// (overlapping curves or curvenets).
    #[error(
        "{segment} and {other} run over one stretch of the surface without a shared knot (overlapping curves or curvenets)"
    )]
    CurvesOverlap { segment: SegmentRef, other: SegmentRef },
    /// In strict mode: two segments' surface paths meet at a point that is
    /// not a shared knot (bound with a `CurvesTouch` warning otherwise).
    #[error("{segment} and {other} meet at a point of face {face} that is not a shared knot")]
    CurvesCross { segment: SegmentRef, other: SegmentRef, face: u32 },
    /// A segment's chord crosses the boundary of the face it was traced in.
    #[error("{segment} crosses the boundary of face {face} (the face is too curved for its chord)")]
    SegmentCrossesFaceBoundary { segment: SegmentRef, face: u32 },
    /// A curve whose samples all land on one point of the surface (a curve
    /// shorter than the cutting's snapping tolerance, drawn over a mesh
    /// vertex or edge): it has no length on the surface to cut along.
    #[error(
        "{segment} collapses onto one point of the surface at {position:?}: the curve is shorter there than \
         the binding can cut along (draw it longer, or remove it)"
    )]
    CurveCollapsedOnSurface { segment: SegmentRef, position: [f64; 3] },
    /// A connected component no curvenet touches, refused in strict mode.
    #[error("mesh component {component} ({vertices} vertices) is touched by no curvenet")]
    UntouchedComponent { component: usize, vertices: usize },
    /// The binding's Laplacian is not numerically positive definite: a face
    /// of the mesh is too thin for its cotangent weights. Names the first
    /// failing pivot's mesh vertex and the face of that vertex's mesh
    /// component with the smallest corner angle (the likely culprit).
    #[error(
        "the surface's Laplacian is not numerically positive definite (its factorisation failed at mesh vertex {vertex}): face {face} (vertices {vertices:?}) is the most nearly degenerate face of that part of the mesh, its smallest corner angle {angle_deg:.1e}°; remove or remesh the sliver"
    )]
    IllConditionedFace { vertex: u32, face: usize, vertices: Vec<u32>, angle_deg: f64 },
    /// A matrix that must be symmetric positive definite is not (numerically).
    #[error("the system matrix is not positive definite{}", pivot.map(|p| format!(" (first failing pivot: row {p})")).unwrap_or_default())]
    NotPositiveDefinite { pivot: Option<usize> },
    /// A feature not available yet.
    #[error("not supported yet: {what}")]
    Unsupported { what: &'static str },
    /// A failure that is a bug in curvenet, not a problem with the input.
    #[error("internal error: {what}")]
    Internal { what: String },
    /// A face repeats a vertex.
    #[error("face {face} repeats vertex {vertex}")]
    RepeatedFaceVertex { face: usize, vertex: u32 },
    /// A spline's four control points coincide (within a tolerance relative
    /// to the curvenet's size), or its arc length is zero.
    #[error("spline {spline} has zero length: its control points coincide")]
    ZeroLengthSpline { spline: usize },
    /// Two curves leave an intersection in the same direction (seen along the
    /// surface normal), so their counter-clockwise order and the corner
    /// between them are undefined.
    #[error(
        "splines {splines:?} leave the intersection at control point {point} in the same direction; \
         their counter-clockwise order is undefined"
    )]
    CoincidentTangents { point: u32, splines: [usize; 2] },
    /// A curve leaves an intersection along the surface normal, so it has no
    /// direction in the tangent plane to be ordered by.
    #[error("spline {spline} leaves the intersection at control point {point} along the surface normal")]
    TangentAlongNormal { point: u32, spline: usize },
    /// The surface face closest to an intersection has zero area, hence no normal.
    #[error("the surface face {face} closest to the intersection at control point {point} has zero area (no normal)")]
    DegenerateSurfaceFace { point: u32, face: usize },
    /// A segment of the sampled curvenet has (numerically) zero length in
    /// some pose. `segment` counts from the spline's control point 0.
    #[error("segment {segment} of spline {spline} has collapsed to length {length:e}")]
    SegmentCollapsed { spline: usize, segment: usize, length: f64 },
    /// In some pose all curves at an intersection are collinear, so no
    /// corner normal can be formed.
    #[error("the curves at the intersection at control point {point} are collinear; its corner normals are undefined")]
    DegenerateIntersection { point: u32 },
    /// The sampling would give a spline more segments than allowed.
    #[error("spline {spline} would get {segments} segments, more than the maximum {max}")]
    TooManySegments { spline: usize, segments: f64, max: u32 },
    /// The tangents at an intersection are all parallel in some pose, so
    /// the rotation fitting them (its knot orientation) is undetermined.
    #[error(
        "the tangents at the intersection at control point {point} are all parallel in this pose; \
         its knot orientation is undetermined"
    )]
    UndeterminedKnotOrientation { point: u32 },
    /// An adjustment names a control point that is not a knot (spline endpoint).
    #[error(
        "adjustment {adjustment}: control point {point} of curvenet {curvenet} is not a knot (a spline \
         endpoint); only knots can be adjusted"
    )]
    NotAKnot { adjustment: usize, curvenet: usize, point: u32 },
    /// An adjustment carries a value it cannot apply.
    #[error("adjustment {adjustment} (knot {point} of curvenet {curvenet}): {problem}")]
    InvalidAdjustment { adjustment: usize, curvenet: usize, point: u32, problem: &'static str },
    /// An adjustment's tangent translates do not match its knot's tangents.
    #[error(
        "adjustment {adjustment} (knot {point} of curvenet {curvenet}) has {got} tangent translates; \
         the knot has {expected} tangents (give one per tangent, or none)"
    )]
    TangentTranslateCount { adjustment: usize, curvenet: usize, point: u32, expected: usize, got: usize },
    /// Two adjustments of the same knot.
    #[error("adjustments {} and {} both adjust knot {point} of curvenet {curvenet}", adjustments[0], adjustments[1])]
    DuplicateAdjustment { curvenet: usize, point: u32, adjustments: [usize; 2] },
    /// A numeric parameter or option is out of its valid range.
    #[error("{what} must be finite and positive, got {value}")]
    InvalidParameter { what: &'static str, value: f64 },
    /// Skinning input (influences, transforms, spline weights) refused; names the element.
    #[error(transparent)]
    Skinning(SkinningError),
    /// Cage input (the cage's triangles and points, a frame's cage arrays)
    /// refused, or a coupled cage-and-skeleton rig that cannot be built;
    /// names the face, edge, vertex or field.
    #[error(transparent)]
    Cage(CageError),
    /// The caller cancelled the computation ([`crate::Cancel`]) during `stage`.
    #[error("cancelled during {stage}")]
    Cancelled { stage: &'static str },
}

/// Why skinning input was refused. Every variant names the element.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum SkinningError {
    /// `element_size` is zero.
    #[error("the influences' element size must be at least 1")]
    ZeroElementSize,
    /// The influence arrays do not hold `element_size` entries per point.
    #[error("{what} has {got} entries, expected {expected} ({points} points x element size {element_size})")]
    InfluenceCount { what: &'static str, got: usize, expected: usize, points: usize, element_size: usize },
    /// A joint index is negative or past the last joint.
    #[error("point {point}, influence {influence}: joint index {joint} is outside 0..{n_joints}")]
    JointOutOfRange { point: usize, influence: usize, joint: i64, n_joints: usize },
    /// A weight is NaN or infinite.
    #[error("point {point}, influence {influence}: weight {weight} is not finite")]
    NonFiniteWeight { point: usize, influence: usize, weight: f64 },
    /// A transform has a non-finite entry.
    #[error("{what} {index} has a non-finite entry")]
    NonFiniteTransform { what: &'static str, index: usize },
    /// A transform that must be affine has a last column other than (0, 0, 0, 1).
    #[error("{what} {index} is not affine (its last column is {column:?}, expected [0, 0, 0, 1])")]
    NotAffine { what: &'static str, index: usize, column: [f64; 4] },
    /// A bind transform cannot be inverted.
    #[error("the bind transform of joint {joint} is singular")]
    SingularBindTransform { joint: usize },
    /// A joint's parent is not an earlier joint (UsdSkel orders parents first).
    #[error("joint {joint} has parent {parent}, which does not come before it")]
    BadParent { joint: usize, parent: usize },
    /// The number of transforms does not match the skeleton.
    #[error("{what}: expected {expected} joints, got {got}")]
    JointCount { what: &'static str, expected: usize, got: usize },
    /// A curvenet control point that no weight reaches (all its weights are zero).
    #[error("{what} {index} has no joint weight (all its weights are zero)")]
    Unweighted { what: &'static str, index: usize },
    /// The skinned tangents of an angle-constrained knot are parallel, so the
    /// rotation axis of the constraint is undefined.
    #[error("the skinned tangents at knot {knot} (control point) are parallel: its angle constraint has no axis")]
    DegenerateAngleAxis { knot: u32 },
}

impl From<SkinningError> for Error {
    fn from(e: SkinningError) -> Self {
        Error::Skinning(e)
    }
}

/// Why cage input was refused. Every variant names the element.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum CageError {
    /// Fewer than 4 points or no triangles: no closed cage.
    #[error("a cage needs at least 4 vertices and some triangles, got {vertices} vertices and {triangles} triangles")]
    TooSmall { vertices: usize, triangles: usize },
    /// A triangle corner refers past the last cage point.
    #[error("cage triangle {face}, corner {corner}: vertex {vertex} is outside 0..{n_vertices}")]
    IndexOutOfRange { face: usize, corner: usize, vertex: u32, n_vertices: usize },
    /// A triangle repeats a vertex or has zero area.
    #[error("cage triangle {face} (vertices {vertices:?}) is degenerate: a repeated vertex or zero area")]
    DegenerateFace { face: usize, vertices: [u32; 3] },
    /// A NaN or infinite coordinate.
    #[error("{what} {index} has a non-finite coordinate {value:?}")]
    NonFinite { what: &'static str, index: usize, value: [f64; 3] },
    /// A cage vertex no triangle uses (its coordinates would all be zero).
    #[error("cage vertex {vertex} is used by no triangle")]
    UnusedVertex { vertex: usize },
    /// An edge with a single triangle: the cage is open there.
    #[error("cage edge ({a}, {b}) has only triangle {face}: the cage is not closed")]
    OpenEdge { a: u32, b: u32, face: usize },
    /// An edge shared by more than two triangles.
    #[error("cage edge ({a}, {b}) is shared by triangles {faces:?}; a cage edge must have exactly two")]
    NonManifoldEdge { a: u32, b: u32, faces: Vec<u32> },
    /// Two triangles run their shared edge the same way: one is flipped.
    #[error("cage triangle {face} is flipped: it runs edge ({a}, {b}) the same way as triangle {neighbour}")]
    FlippedFace { face: usize, neighbour: usize, a: u32, b: u32 },
    /// Consistently oriented but with inward normals (negative volume).
    #[error(
        "the cage is inside out: its signed volume is {volume:e} (triangles must wind counter-clockwise seen from outside)"
    )]
    InsideOut { volume: f64 },
    /// The cage is too fine for dense coordinates ([`MAX_CAGE_VERTICES`], [`MAX_PHI_BYTES`]).
    #[error(
        "a cage of {cage_vertices} vertices over {points} points needs {bytes} bytes of mean value coordinates; a cage \
         is a coarse control mesh (at most {max_vertices} vertices and {max_bytes} bytes of coordinates)",
        max_vertices = MAX_CAGE_VERTICES,
        max_bytes = MAX_PHI_BYTES
    )]
    TooLarge { points: usize, cage_vertices: usize, bytes: usize },
    /// A point lies outside the cage (winding number below ½).
    #[error(
        "point {point} ({position:?}) is outside the cage ({outside} points are): a cage must enclose every point it deforms"
    )]
    NotEnclosing { point: usize, position: [f64; 3], outside: usize },
    /// An array has the wrong length.
    #[error("{what}: expected {expected} entries, got {got}")]
    Count { what: &'static str, expected: usize, got: usize },
    /// The MaxVol square system is singular (the cage's coordinates of the
    /// points do not span every cage vertex: some cage vertex influences no point).
    #[error(
        "the MaxVol system of the cage is singular (condition number {condition:e}): cage vertex {vertex} influences the points too little"
    )]
    SingularMaxVol { vertex: usize, condition: f64 },
    /// The CageRev system (Eq. 19) is singular at this pose.
    #[error("the reverse cage system (CageRev) is singular at this pose (pivot {pivot})")]
    SingularCageRev { pivot: usize },
    /// A joint no skin weight reaches, so SkelUp cannot place it.
    #[error("joint {joint} has no localised skin weight: SkelUp cannot relocate it")]
    UnlocalizedJoint { joint: usize },
    /// The maximum-entropy projection of a joint's coordinates (Eq. 11) did not converge.
    #[error("the barycentric coordinates of joint {joint} (Eq. 11) did not converge (residual {residual:e})")]
    JointCoordinates { joint: usize, residual: f64 },
    /// The rig is missing something the coupling needs.
    #[error("{what}")]
    Missing { what: &'static str },
}

impl From<CageError> for Error {
    fn from(e: CageError) -> Self {
        Error::Cage(e)
    }
}

pub type Result<T, E = Error> = std::result::Result<T, E>;

/// A curvenet segment as users number it: the curvenet (in binding
/// order), the spline within that curvenet, and the segment within the
/// spline counted from the spline's control point 0. Every error and
/// warning about a segment uses this numbering.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, serde::Serialize, serde::Deserialize)]
pub struct SegmentRef {
    pub curvenet: u32,
    pub spline: u32,
    pub segment: u32,
}

impl std::fmt::Display for SegmentRef {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "curvenet {} spline {} segment {}", self.curvenet, self.spline, self.segment)
    }
}

/// A curvenet sample as users number it: the curvenet (in binding order),
/// a spline it belongs to, and the sample's index among the curvenet's samples.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct SampleRef {
    pub curvenet: u32,
    pub spline: u32,
    pub sample: u32,
}

impl std::fmt::Display for SampleRef {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "curvenet {} sample {} (spline {})", self.curvenet, self.sample, self.spline)
    }
}

fn detour_text(path_length: f64, segment_length: f64) -> String {
    if path_length.is_finite() {
        format!(
            "takes a surface path {path_length:.4e} long for a segment {segment_length:.4e} long: the curve bridges a concavity or a thin part there (draw it closer to the surface)"
        )
    } else {
        "projects onto two different mesh components (draw the curve on one of them)".to_string()
    }
}
