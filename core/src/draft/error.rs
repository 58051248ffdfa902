//! Why drafting stopped: [`DraftError`] (what the caller sees) and
//! `Failure` (why one placement of the planes gave no clean curvenet, and
//! which rings to move).

use super::limits::TINY_LOOP;
use crate::error::Error;

/// Why no curvenet was drafted.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum DraftError {
    /// An option is out of range.
    #[error("draft option {what}: {problem}")]
    Option { what: &'static str, problem: String },
    /// The mesh is not an oriented manifold or has bad points.
    #[error(transparent)]
    Mesh(#[from] Error),
    /// The ring planes cut nothing worth a curve.
    #[error("no ring plane cuts the mesh in a loop longer than {TINY_LOOP} mean edges; try another --axis or --span")]
    Empty,
    /// Every placement of the planes that was tried broke a rule (see the
    /// module docs); `reason` is the last one's.
    #[error(
        "no clean curvenet with these options ({attempts} complete placements of the planes tried); the last \
         failure: {reason} (try other --rings, --lines, --axis or --span, or a --seed)"
    )]
    NoCleanLayout { attempts: usize, reason: String },
}

/// Why a placement did not give a clean curvenet, and which rings to move.
pub(super) struct Failure {
    pub(super) message: String,
    pub(super) rings: Vec<usize>,
}

impl From<String> for Failure {
    fn from(message: String) -> Self {
        Self { message, rings: Vec::new() }
    }
}
