//! Cooperative cancellation of long computations (a binding): a cheap,
//! cloneable flag that the caller raises and the computation checks between
//! its stages and every few thousand iterations of its long loops, returning
//! [`Error::Cancelled`].
//!
//! What cannot be interrupted — the sparse Cholesky factorisation runs as one
//! call into faer — is checked for just before and just after; a caller that
//! needs a bound on it estimates its cost up front (it is fixed by the mesh).

use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};

use crate::error::{Error, Result};

/// Iterations between two checks inside a long loop: cheap (one relaxed
/// load) yet frequent enough that a binding stops within milliseconds.
pub const CHECK_EVERY: usize = 1024;

/// A cancellation flag shared by the caller and the computation. Clones
/// share the flag; the default one is never raised unless `cancel` is called.
#[derive(Debug, Clone, Default)]
pub struct Cancel(Arc<AtomicBool>);

impl Cancel {
    /// A fresh, unraised flag.
    pub fn new() -> Self {
        Self::default()
    }

    /// Raises the flag: the computation stops at its next check.
    pub fn cancel(&self) {
        self.0.store(true, Ordering::Relaxed);
    }

    /// Whether the flag is raised.
    pub fn is_cancelled(&self) -> bool {
        self.0.load(Ordering::Relaxed)
    }

    /// `Err(Error::Cancelled { stage })` when the flag is raised.
    pub fn check(&self, stage: &'static str) -> Result<()> {
        if self.is_cancelled() { Err(Error::Cancelled { stage }) } else { Ok(()) }
    }

    /// [`Self::check`] on every [`CHECK_EVERY`]-th iteration `i` of a loop.
    #[inline]
    pub fn check_every(&self, i: usize, stage: &'static str) -> Result<()> {
        if i.is_multiple_of(CHECK_EVERY) { self.check(stage) } else { Ok(()) }
    }
}
