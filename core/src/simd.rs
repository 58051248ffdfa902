//! Which vector unit the hot loops are compiled for, chosen at run time.
//!
//! The release binary is built for the x86-64 baseline (SSE2), so that it
//! runs on every farm machine; the frame's hot loops (the triangular sweeps
//! of [`crate::cholesky`], the piece lengths of the curvenet sampling, the
//! gradient operator of the Poisson right-hand side and, for groups of
//! frames, `Csr::mul_add_lanes`) are compiled a second and third time with
//! `#[target_feature]` for AVX2 and AVX-512 and picked once per call from
//! what the CPU reports. The variants execute the same IEEE operations in
//! the same order — no fused multiply-add, which Rust never contracts on
//! its own — so a frame's result is bit for bit the same whichever variant
//! ran. (The frame also calls the C library's `sin`, `cos` and `atan2`;
//! glibc picks FMA builds of those at run time, and whether they round
//! alike on every CPU is not verified here.)
//! FMA would change no byte between machines if every variant used it (the
//! baseline through the C library's exact `fma`), but it does not pay here:
//! on the hands' own factors fused multiply-adds were no faster than the
//! separate multiply and subtract (a sweep's entry is bound by the
//! dependency chain of its accumulator and by loads, not by arithmetic,
//! and a fused multiply-add has the longer latency). The wider variants pay
//! for many columns (9 and a group's 72), not for 3 (bound by the factor's
//! memory traffic). The measurements: docs/performance.md, "Vector units,
//! unknown numbering, gathered right-hand side" and "Row-gathered forward
//! sweeps, and what did not pay".

/// The widest vector extension the running CPU has, of those the hot loops
/// are compiled for.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Simd {
    /// No extension beyond the build's target (SSE2 on x86-64; every
    /// non-x86 target).
    Baseline,
    /// AVX2 (4 doubles per register).
    #[cfg(target_arch = "x86_64")]
    Avx2,
    /// AVX-512F (8 doubles per register).
    #[cfg(target_arch = "x86_64")]
    Avx512,
}

impl Simd {
    /// The variant for this CPU (the standard library caches the CPUID
    /// query, so this is a load and a compare per call). The environment
    /// variable `CURVENET_SIMD=baseline|avx2` (any case) caps it, so that
    /// the variants can be compared on one machine and a suspected
    /// vector-unit problem ruled out without a rebuild; `avx512`, any other
    /// value or none takes the best the CPU has (the command line warns
    /// about values it does not know: [`Self::env_problem`]). It is read once per process.
    pub fn detect() -> Self {
        use std::sync::OnceLock;
        static CHOSEN: OnceLock<Simd> = OnceLock::new();
        *CHOSEN.get_or_init(|| {
            let cap = std::env::var("CURVENET_SIMD").unwrap_or_default();
            Self::best(&cap)
        })
    }

    /// What is wrong with `CURVENET_SIMD`, if it is set to a value
    /// [`Self::detect`] does not know (it then takes the best the CPU has):
    /// a message naming the value, for the command line to warn with.
    pub fn env_problem() -> Option<String> {
        let cap = std::env::var("CURVENET_SIMD").ok()?;
        let known = cap.is_empty() || ["baseline", "avx2", "avx512"].iter().any(|k| cap.eq_ignore_ascii_case(k));
        (!known).then(|| {
            format!(
                "CURVENET_SIMD={cap:?} is not \"baseline\", \"avx2\" or \"avx512\"; the sweeps use the best the CPU has ({})",
                Self::detect().name()
            )
        })
    }

    #[cfg(target_arch = "x86_64")]
    fn best(cap: &str) -> Self {
        if cap.eq_ignore_ascii_case("baseline") {
            return Simd::Baseline;
        }
        if !cap.eq_ignore_ascii_case("avx2") && std::arch::is_x86_feature_detected!("avx512f") {
            Simd::Avx512
        } else if std::arch::is_x86_feature_detected!("avx2") {
            Simd::Avx2
        } else {
            Simd::Baseline
        }
    }

    #[cfg(not(target_arch = "x86_64"))]
    fn best(_cap: &str) -> Self {
        Simd::Baseline
    }

    /// Its name, as the bench prints it.
    pub fn name(self) -> &'static str {
        match self {
            Simd::Baseline => "baseline",
            #[cfg(target_arch = "x86_64")]
            Simd::Avx2 => "avx2",
            #[cfg(target_arch = "x86_64")]
            Simd::Avx512 => "avx512",
        }
    }
}
