//! Long work the service can stop: every binding being computed is a
//! [`Job`] holding a [`Cancel`] flag the core checks between its stages and
//! inside its long loops. A job is cancelled, with a reason, when
//!
//! - its request goes away (the client disconnected: the handler's future is
//!   dropped, and with it the job's [`Job`] guard),
//! - it runs past the binding time limit (`--max-binding-seconds`),
//! - the drain deadline passes at shutdown ([`Jobs::cancel_all`]).

use std::collections::HashMap;
use std::sync::atomic::{AtomicU8, AtomicU64, Ordering};
use std::sync::{Arc, Mutex};

use curvenet_core::Cancel;

/// Why a job was cancelled.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[repr(u8)]
pub enum Reason {
    /// Not cancelled.
    None = 0,
    /// Nobody waits for the result any more (the client disconnected).
    Abandoned = 1,
    /// It ran past the binding time limit.
    TimeLimit = 2,
    /// The drain deadline passed at shutdown.
    Shutdown = 3,
}

impl Reason {
    fn from_u8(x: u8) -> Self {
        match x {
            1 => Reason::Abandoned,
            2 => Reason::TimeLimit,
            3 => Reason::Shutdown,
            _ => Reason::None,
        }
    }
}

struct Shared {
    cancel: Cancel,
    reason: AtomicU8,
    /// Jobs cancelled so far (the registry's count).
    cancelled: Arc<AtomicU64>,
}

impl Shared {
    /// Raises the flag; the first reason given wins (and is counted).
    fn cancel(&self, reason: Reason) {
        if self.reason.compare_exchange(0, reason as u8, Ordering::SeqCst, Ordering::SeqCst).is_ok() {
            self.cancelled.fetch_add(1, Ordering::Relaxed);
        }
        self.cancel.cancel();
    }
}

/// The jobs running now.
#[derive(Default)]
pub struct Jobs {
    next: AtomicU64,
    running: Mutex<HashMap<u64, Arc<Shared>>>,
    cancelled: Arc<AtomicU64>,
}

impl Jobs {
    /// Registers a new job. Dropping the returned guard before
    /// [`Job::finish`] cancels it as [`Reason::Abandoned`]; either way it
    /// leaves the registry.
    pub fn start(self: &Arc<Self>) -> Job {
        let id = self.next.fetch_add(1, Ordering::Relaxed);
        let shared =
            Arc::new(Shared { cancel: Cancel::new(), reason: AtomicU8::new(0), cancelled: self.cancelled.clone() });
        self.running.lock().unwrap_or_else(|e| e.into_inner()).insert(id, shared.clone());
        Job { id, shared, jobs: self.clone(), finished: false }
    }

    /// Cancels every running job; returns how many there were.
    pub fn cancel_all(&self, reason: Reason) -> usize {
        let running = self.running.lock().unwrap_or_else(|e| e.into_inner());
        for job in running.values() {
            job.cancel(reason);
        }
        running.len()
    }

    /// Jobs cancelled since the start, whatever the reason.
    pub fn cancelled(&self) -> u64 {
        self.cancelled.load(Ordering::Relaxed)
    }

    /// Jobs running now.
    pub fn len(&self) -> usize {
        self.running.lock().unwrap_or_else(|e| e.into_inner()).len()
    }
}

/// A running job's guard (see [`Jobs::start`]).
pub struct Job {
    id: u64,
    shared: Arc<Shared>,
    jobs: Arc<Jobs>,
    finished: bool,
}

impl Job {
    /// The flag to hand to the core.
    pub fn cancel_flag(&self) -> Cancel {
        self.shared.cancel.clone()
    }

    /// A handle that can cancel this job from elsewhere (a timer).
    pub fn handle(&self) -> JobHandle {
        JobHandle(self.shared.clone())
    }

    /// Why the job was cancelled ([`Reason::None`] if it was not).
    pub fn reason(&self) -> Reason {
        Reason::from_u8(self.shared.reason.load(Ordering::SeqCst))
    }

    /// The job is done (whatever its result): dropping it no longer cancels.
    pub fn finish(mut self) -> Reason {
        self.finished = true;
        self.reason()
    }
}

impl Drop for Job {
    fn drop(&mut self) {
        if !self.finished {
            self.shared.cancel(Reason::Abandoned);
        }
        self.jobs.running.lock().unwrap_or_else(|e| e.into_inner()).remove(&self.id);
    }
}

/// Cancels a job from elsewhere.
#[derive(Clone)]
pub struct JobHandle(Arc<Shared>);

impl JobHandle {
    pub fn cancel(&self, reason: Reason) {
        self.0.cancel(reason);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_dropped_job_is_abandoned_and_a_finished_one_is_not() {
        let jobs = Arc::new(Jobs::default());
        let a = jobs.start();
        let flag = a.cancel_flag();
        assert_eq!(jobs.len(), 1);
        drop(a);
        assert!(flag.is_cancelled());
        assert_eq!(jobs.len(), 0);
        assert_eq!(jobs.cancelled(), 1);
        let b = jobs.start();
        let flag = b.cancel_flag();
        assert_eq!(b.finish(), Reason::None);
        assert!(!flag.is_cancelled());
        assert_eq!(jobs.len(), 0);
    }

    #[test]
    fn the_first_reason_wins_and_cancel_all_reaches_every_job() {
        let jobs = Arc::new(Jobs::default());
        let a = jobs.start();
        let b = jobs.start();
        a.handle().cancel(Reason::TimeLimit);
        assert_eq!(jobs.cancel_all(Reason::Shutdown), 2);
        assert_eq!(a.reason(), Reason::TimeLimit);
        assert_eq!(b.reason(), Reason::Shutdown);
        assert!(b.cancel_flag().is_cancelled());
        assert_eq!(jobs.cancelled(), 2);
    }
}
