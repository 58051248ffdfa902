//! Measuring: wall and thread-CPU laps, series of them, medians, ratios,
//! and the deterministic random numbers the bench's right-hand sides use.

use std::time::{Duration, Instant};

/// One measurement: wall time and, where available, the calling thread's
/// CPU time (which leaves out the time the thread was preempted: the
/// machine this runs on is often shared).
#[derive(Clone, Copy)]
pub(super) struct Lap {
    pub(super) wall_ms: f64,
    pub(super) cpu_ms: Option<f64>,
}

#[derive(Clone, Copy)]
pub(super) struct Stopwatch {
    pub(super) wall: Instant,
    pub(super) cpu: Option<Duration>,
}

impl Stopwatch {
    pub(super) fn start() -> Self {
        let cpu = thread_cpu_time();
        Self { wall: Instant::now(), cpu }
    }

    pub(super) fn stop(self) -> Lap {
        let wall_ms = ms_since(self.wall);
        let cpu_ms = self.cpu.zip(thread_cpu_time()).map(|(a, b)| b.saturating_sub(a).as_secs_f64() * 1e3);
        Lap { wall_ms, cpu_ms }
    }
}

/// Repeated measurements of one thing.
#[derive(Default)]
pub(super) struct Series {
    pub(super) wall: Vec<f64>,
    pub(super) cpu: Vec<Option<f64>>,
}

impl Series {
    pub(super) fn push(&mut self, lap: Lap) {
        self.wall.push(lap.wall_ms);
        self.cpu.push(lap.cpu_ms);
    }
    pub(super) fn wall(&self) -> f64 {
        median(self.wall.clone())
    }
    pub(super) fn wall_min(&self) -> f64 {
        self.wall.iter().copied().fold(f64::INFINITY, f64::min)
    }
    pub(super) fn wall_max(&self) -> f64 {
        self.wall.iter().copied().fold(0.0, f64::max)
    }
    /// Median CPU time, if every measurement has one.
    pub(super) fn cpu(&self) -> Option<f64> {
        let v: Option<Vec<f64>> = self.cpu.iter().copied().collect();
        v.filter(|v| !v.is_empty()).map(median)
    }
}

/// CPU time consumed by the calling thread (`CLOCK_THREAD_CPUTIME_ID`).
/// std has no thread CPU clock; libc's `clock_gettime` is linked into
/// every Linux Rust program, so it is declared here rather than adding a
/// dependency.
#[cfg(all(target_os = "linux", target_pointer_width = "64"))]
pub(super) fn thread_cpu_time() -> Option<Duration> {
    #[repr(C)]
    struct Timespec {
        tv_sec: i64,
        tv_nsec: i64,
    }
    unsafe extern "C" {
        fn clock_gettime(clock: i32, tp: *mut Timespec) -> i32;
    }
    const CLOCK_THREAD_CPUTIME_ID: i32 = 3;
    let mut ts = Timespec { tv_sec: 0, tv_nsec: 0 };
    // SAFETY: clock_gettime writes one `struct timespec` (two 64-bit fields
    // on 64-bit Linux) through the pointer, which points to one.
    let rc = unsafe { clock_gettime(CLOCK_THREAD_CPUTIME_ID, &mut ts) };
    (rc == 0 && ts.tv_sec >= 0 && (0..1_000_000_000).contains(&ts.tv_nsec))
        .then(|| Duration::new(ts.tv_sec as u64, ts.tv_nsec as u32))
}

#[cfg(not(all(target_os = "linux", target_pointer_width = "64")))]
pub(super) fn thread_cpu_time() -> Option<Duration> {
    None
}

pub(super) fn uniform(state: &mut u64) -> f64 {
    // xorshift64*: deterministic right-hand sides in [-1, 1).
    *state ^= *state >> 12;
    *state ^= *state << 25;
    *state ^= *state >> 27;
    let x = state.wrapping_mul(0x2545_F491_4F6C_DD1D);
    (x >> 11) as f64 / (1u64 << 52) as f64 - 1.0
}

pub(super) fn max_distance(a: &[[f64; 3]], b: &[[f64; 3]]) -> f64 {
    a.iter()
        .zip(b)
        .map(|(p, q)| ((p[0] - q[0]).powi(2) + (p[1] - q[1]).powi(2) + (p[2] - q[2]).powi(2)).sqrt())
        .fold(0.0, f64::max)
}

pub(super) fn ms_since(t: Instant) -> f64 {
    t.elapsed().as_secs_f64() * 1e3
}

pub(super) fn ratio(a: f64, b: f64) -> f64 {
    if b > 0.0 { a / b } else { 0.0 }
}

pub(super) fn median(mut v: Vec<f64>) -> f64 {
    if v.is_empty() {
        return 0.0;
    }
    v.sort_by(f64::total_cmp);
    let n = v.len();
    if n % 2 == 1 { v[n / 2] } else { 0.5 * (v[n / 2 - 1] + v[n / 2]) }
}
