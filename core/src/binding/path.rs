//! A segment's path over the surface, how it was found, and why tracing one
//! can fail: shared by the straightest-path tracer (`trace`) and the
//! fallback in a strip of faces (`strip`).

use super::locate::Location;

/// A traced path: `points[k]` to `points[k + 1]` lies in face `faces[k]`.
#[derive(Debug, Clone, Default)]
pub struct Path {
    pub points: Vec<Location>,
    pub faces: Vec<u32>,
}

/// Why a path could not be traced.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum TraceFailure {
    /// The path reached a boundary edge of an open mesh.
    LeftTheSurface,
    /// The path did not arrive within the step or length budget.
    Lost,
    /// The two points lie on different connected components: no path exists.
    Disconnected,
}

/// How a segment's surface path was found.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum PathMethod {
    /// Both points share a face: the straight chord in its plane.
    Chord,
    /// The straightest path (the paper's choice), traced from either end.
    Straightest,
    /// The shortest path inside a strip of faces ([`super::strip::trace_in_strip`]),
    /// when the straightest path missed its target.
    Fallback,
}
