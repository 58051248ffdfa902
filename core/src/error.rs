//! The one error type of the core. Every variant names the offending element
//! (face, vertex, spline, control point) so a user can fix the input from the
//! message alone.

/// Errors raised by curvenet-core. User mistakes (bad input) and internal
/// failures are separate variants; the latter should never happen.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[non_exhaustive]
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
    /// Two arrays that must have the same length do not.
    #[error("{what}: expected {expected} entries, got {got}")]
    CountMismatch { what: &'static str, expected: usize, got: usize },
    /// A face repeats a vertex.
    #[error("face {face} repeats vertex {vertex}")]
    RepeatedFaceVertex { face: usize, vertex: u32 },
}

pub type Result<T, E = Error> = std::result::Result<T, E>;
