//! Subcommands of the `curvenet` command line.

pub mod bake;
pub mod bench;
mod bench_batch;
pub mod bind;
pub mod draft;
pub mod inspect;
pub mod rig;
pub mod serve;
pub mod stitch;
pub mod store;
pub mod units;

/// A command-line failure. Bad input (exit 2) is kept apart from failures
/// that may succeed on retry (exit 75, EX_TEMPFAIL), so a farm retries only
/// what can succeed.
#[derive(Debug, thiserror::Error)]
pub enum CliError {
    #[error(transparent)]
    Usd(#[from] curvenet_schema::usd::UsdError),
    #[error("{0}")]
    Input(String),
    /// The core refused the input (names the element); `context` names the prim and frame.
    #[error("{context}: {source}")]
    Core { context: String, source: curvenet_core::Error },
    /// An I/O failure (writing output): worth retrying.
    #[error("{context}: {source}")]
    Io { context: String, source: std::io::Error },
    /// `serve` stopped at its drain deadline with work cut short (exit 1).
    #[error("{0}")]
    CutShort(String),
    /// Over a limit the caller set (a service bake's points): bad input for
    /// this caller, not worth retrying as is.
    #[error("{0}")]
    Limit(String),
    /// A service the command needs is unavailable now (a binding store that
    /// cannot be reached or written): worth retrying (exit 75).
    #[error("{0}")]
    Unavailable(String),
    /// The caller withdrew the work (a service bake whose client left, or
    /// the server's drain deadline).
    #[error("the bake was cancelled")]
    Cancelled,
}

impl CliError {
    pub fn exit_code(&self) -> u8 {
        match self {
            CliError::Usd(curvenet_schema::usd::UsdError::Open { message, .. }) if is_transient(message) => 75,
            CliError::Io { source, .. } if never_writable(source.kind()) => 2,
            CliError::Io { .. } => 75,
            CliError::CutShort(_) => 1,
            CliError::Cancelled | CliError::Unavailable(_) => 75,
            _ => 2,
        }
    }
}

/// I/O failures a retry cannot mend: the path itself can never be written
/// (a file where a directory must be, a directory named as the output, a
/// name too long or holding a NUL byte).
fn never_writable(kind: std::io::ErrorKind) -> bool {
    use std::io::ErrorKind as K;
    matches!(kind, K::NotADirectory | K::IsADirectory | K::InvalidFilename | K::InvalidInput)
}

fn is_transient(message: &str) -> bool {
    // A missing or unparsable file is bad input; an interrupted read is not.
    let m = message.to_ascii_lowercase();
    m.contains("interrupted") || m.contains("timed out") || m.contains("resource temporarily unavailable")
}

pub type CliResult<T = ()> = Result<T, CliError>;

/// Worker threads a command may start per CPU: more only add memory (a
/// stack and a solve workspace each) and switching, and a typo such as
/// `--threads 100000` would otherwise start them all.
pub const MAX_THREADS_PER_CPU: usize = 4;

/// Checks a thread-count flag against [`MAX_THREADS_PER_CPU`] × this
/// machine's CPUs; `0` (where the flag allows it) is one per CPU.
pub fn check_threads(flag: &str, threads: usize) -> CliResult<usize> {
    let cpus = std::thread::available_parallelism().map_or(1, |n| n.get());
    let most = MAX_THREADS_PER_CPU * cpus;
    match threads {
        0 => Ok(cpus),
        t if t <= most => Ok(t),
        t => Err(CliError::Input(format!(
            "{flag} {t}: at most {most} on this machine ({MAX_THREADS_PER_CPU} per CPU, {cpus} CPUs); more threads \
             only add memory and switching"
        ))),
    }
}

/// `1/share` of this machine's memory (`MemTotal` in `/proc/meminfo`),
/// `None` where it cannot be read: a default bound on what one command holds.
pub fn memory_fraction(share: u64) -> Option<u64> {
    let info = std::fs::read_to_string("/proc/meminfo").ok()?;
    let line = info.lines().find(|l| l.starts_with("MemTotal:"))?;
    let kib: u64 = line.split_whitespace().nth(1)?.parse().ok()?;
    Some(kib * 1024 / share.max(1))
}

/// `/A/Net, /B/Net`: the curvenets' paths for messages.
pub fn net_list(nets: &[curvenet_schema::CurvenetData]) -> String {
    nets.iter().map(|n| n.path.as_str()).collect::<Vec<_>>().join(", ")
}

/// A deformed mesh of a stage with its curvenets, and whether its rest pose
/// must be read per frame (`points` animated or not the projection pose).
pub type DeformedMesh = (curvenet_schema::MeshData, Vec<curvenet_schema::CurvenetData>, bool);

/// Every mesh of `stage` with `rel curvenet:curvenets`, with its curvenets;
/// no such mesh is bad input ("nothing to {purpose}").
pub fn deformed_meshes(stage: &curvenet_schema::usd::Stage, purpose: &str) -> CliResult<Vec<DeformedMesh>> {
    let meshes = stage.deformed_meshes()?;
    if meshes.is_empty() {
        return Err(CliError::Input(format!(
            "{}: no Mesh has rel curvenet:curvenets, so there is nothing to {purpose}",
            stage.path()
        )));
    }
    let mut inputs = Vec::with_capacity(meshes.len());
    for mesh in meshes {
        let nets = mesh.curvenets.iter().map(|p| stage.curvenet(p)).collect::<Result<Vec<_>, _>>()?;
        let reads_rest =
            !mesh.rest_sample_times.is_empty() || stage.rest_points(&mesh, None)? != mesh.projection_points;
        inputs.push((mesh, nets, reads_rest));
    }
    Ok(inputs)
}

/// Fails (exit 75, like every failure to write an output) when `out`'s
/// directory does not exist, before any work is done.
pub fn check_output_dir(out: &std::path::Path) -> CliResult {
    // A path naming a directory can never be written as a layer: bad input,
    // said before any work (not after the bake, at the rename).
    if curvenet_server::names_a_directory(&out.as_os_str().to_string_lossy()) || out.is_dir() {
        return Err(CliError::Input(format!("{}: the output names a directory, not a layer file", out.display())));
    }
    let dir = match out.parent() {
        Some(p) if !p.as_os_str().is_empty() => p,
        _ => std::path::Path::new("."),
    };
    match std::fs::metadata(dir) {
        Ok(m) if m.is_dir() => Ok(()),
        Ok(_) => Err(CliError::Io {
            context: format!("cannot write {}", out.display()),
            source: std::io::Error::new(
                std::io::ErrorKind::NotADirectory,
                format!("{} is not a directory", dir.display()),
            ),
        }),
        Err(source) => Err(CliError::Io {
            context: format!("cannot write {}: directory {}", out.display(), dir.display()),
            source,
        }),
    }
}
