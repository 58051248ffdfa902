//! `curvenet bake INPUT --out OUTPUT [--frames A-B] [--threads N] [--batch-frames K] [--quiet]`:
//! deforms every mesh of a shot over a frame range and writes the points as
//! an override layer (schema/README.md, "Bake output").
//!
//! 1. Every deformed mesh is bound once (`curvenet_core::Deformer::new`
//!    through [`super::deformer`]: each curvenet sampled at its density, one
//!    binding, the blend shapes); the meshes bind in parallel. A mesh with a
//!    UsdSkel skin gets its rig ([`super::rig::MeshRig`]): the skinning of
//!    the mesh and the spline skinning of the curvenets that ask for it,
//!    precomputed once and handed to the deformer.
//! 2. Frames go in chunks: the reading thread (the USD stage is not `Send`)
//!    reads a chunk's posed pools, rest poses and blend-shape weights and
//!    checks they are finite,
//!    while the previous chunk solves on the thread pool, every group of up
//!    to K (`--batch-frames`) consecutive frames of one mesh an independent
//!    task: one `Deformer::frames` call, which owns the per-frame policy
//!    (workspaces, skinning, blend shapes, adjustments) and solves the
//!    group's frames with one sweep of each triangular solve (bit for bit
//!    what frame-by-frame solves give, so the output does not depend on K
//!    or the thread count). Results keep frame order; the first failing
//!    frame in time order is reported, by its time code.
//!    A frame of a mesh is, in order: skinning of the mesh's points by the
//!    frame's joint transforms (blend shapes added first, UsdSkel's order,
//!    unless `curvenet:blendShapeOrder = "afterSolve"`) → the rest pose;
//!    spline skinning → the posed pools of the skinned curvenets (the
//!    others: their own samples, else knot tracking over the rest pose) →
//!    each curvenet's `CurvenetAdjustment` children (Elemental's Curvenet
//!    Adjustments, read per frame) on top of the posed pool or knot
//!    tracking, in the knots' surface-relative frames → the solve → blend
//!    shapes after the deformation, mapped by each vertex's interpolated
//!    deformation gradient (paper §5), for meshes without a skin or asking
//!    for `afterSolve`.
//! 3. The points (f32) are written as `over` opinions, atomically: a
//!    temporary file beside OUTPUT, synced, renamed over it. A failed bake
//!    leaves neither OUTPUT nor a temporary file.

use std::num::NonZeroUsize;
use std::path::{Path, PathBuf};
use std::sync::Mutex;
use std::sync::atomic::{AtomicU64, AtomicUsize, Ordering};
use std::time::{Duration, Instant};

use curvenet_core::Mat4;
use curvenet_core::{Adjustment, BlendShapeMode, Deformer, Frame, FrameOut};
use curvenet_schema::usd::{BlendShapeOrder, LayerFormat, PrimPoints, Stage, WriteError, write_points_overrides};
use curvenet_schema::{AdjustmentData, CageData, CurvenetData, MeshData};
use rayon::prelude::*;

use super::rig::{JointReader, MeshRig};
use super::{CliError, CliResult, net_list};

/// Most frames' inputs held at once (two chunks: one solving, one read).
const MAX_CHUNK_FRAMES: usize = 256;
/// Budget for one chunk's inputs (posed pools and rest poses, f64).
const CHUNK_BYTES: usize = 256 << 20;
/// Frames of one mesh solved together by default (`--batch-frames`).
const DEFAULT_BATCH_FRAMES: u32 = curvenet_core::DEFAULT_BATCH_FRAMES as u32;
/// Longest frame range accepted (guards against a typo like 1-1000000000).
const MAX_FRAMES: i64 = 1_000_000;

const AFTER_HELP: &str = "\
Output: a layer holding only `over` opinions with the deformed `point3f[] points`
time samples of every deformed mesh at its composed path (and over its
ancestors), plus startTimeCode/endTimeCode of the baked frames. Sublayer it
above (stronger than) INPUT. The file is replaced atomically: a failed bake
leaves OUTPUT as it was and no temporary file. The same bake writes the same bytes.

Curvenet Adjustments: the `CurvenetAdjustment` children of each curvenet
(schema/README.md) are evaluated at every frame and move their knots, in the
knots' surface-relative frames, on top of the posed or tracked curvenet.

Frames: A-B is every integer time code from A to B inclusive (A alone: one
frame). Without --frames: the stage's startTimeCode..endTimeCode, else the
union of the curvenets' and meshes' time samples.

Exit status: 0 success; 2 bad input, not worth retrying (a stage that breaks the
contract, a bad frame - non-finite or miscounted points, points beyond 1e15 or
blend-shape weights beyond 1e6 (the service's bounds), a result past f32, a
core error - named as `frame F, PRIM: ...`, a bad --frames or output
extension); 75 an I/O failure writing OUTPUT, worth retrying: this includes an
output directory that does not exist (checked before any work, so a retry
costs nothing); an OUTPUT that can never be written (a file where a directory
must be, a directory, a name too long) is bad input, 2.

Progress: on a terminal, a line of frames done, frames per second and ETA; else
one summary line on stderr at the end (meshes, frames, bind and mean solve time
per frame, output). --quiet prints neither; warnings and errors always go to stderr.";

#[derive(clap::Args)]
#[command(after_help = AFTER_HELP)]
pub struct Args {
    /// The shot stage to read (.usda, .usdc, .usdz).
    pub input: PathBuf,
    /// The layer to write: .usda (text) or .usdc (binary), by its extension.
    #[arg(long, short)]
    pub out: PathBuf,
    /// Frames to bake: `A-B` (inclusive integer time codes) or `A`.
    #[arg(long, value_name = "A-B", value_parser = parse_frames, allow_hyphen_values = true)]
    pub frames: Option<FrameRange>,
    /// Worker threads for the solves (default: one per CPU).
    #[arg(long)]
    pub threads: Option<NonZeroUsize>,
    /// Frames of one mesh solved together: their right-hand sides share one
    /// sweep of each triangular solve, so the factor is read once per K
    /// frames (the output does not depend on K). At most 32.
    #[arg(long, value_name = "K", default_value_t = DEFAULT_BATCH_FRAMES,
        value_parser = clap::value_parser!(u32).range(1..=curvenet_core::MAX_BATCH_FRAMES as i64))]
    pub batch_frames: u32,
    /// Refuse (exit 2, before any binding) a bake whose points (frames ×
    /// vertices × 12 bytes, all held until the layer is written) exceed
    /// this, e.g. 2GiB (default: 1/8 of this machine's memory; a bake's peak
    /// memory is about 3-4× its points).
    #[arg(long, value_name = "BYTES", value_parser = super::units::parse_bytes)]
    pub max_points_bytes: Option<u64>,
    /// No progress line and no summary.
    #[arg(long, short)]
    pub quiet: bool,
    /// Spline skinning with flexible G1 tangent ratios (Liu et al. 2015,
    /// section 4): after the fixed-ratio fit, up to N alternating iterations
    /// free the tangent length ratios at smooth junctions (0: off). The
    /// summary reports the iterations done.
    #[arg(long, value_name = "N", default_value_t = 0)]
    pub g1_flexible: usize,
    /// Refuse (exit 2) a stage that opens any layer or asset (sublayers,
    /// references, payloads, at any depth) outside these directories, symlinks
    /// followed (repeatable). The service bakes with its --bake-root dirs.
    #[arg(long = "confine", value_name = "DIR")]
    pub confine: Vec<PathBuf>,
    /// A binding store shared by a shot's chunks (and with `serve --store`):
    /// a directory or `s3://bucket/prefix`. Each mesh's binding is read from
    /// it when there, else built and written to it; the output is the same
    /// bytes either way.
    #[arg(long, env = "CURVENET_STORE", value_name = "DIR|URL")]
    pub store: Option<String>,
    /// Largest size of the store (least recently used bindings deleted
    /// beyond it; default: unbounded).
    #[arg(long, env = "CURVENET_STORE_BYTES", value_parser = super::units::parse_bytes, requires = "store")]
    pub store_bytes: Option<u64>,
}

/// An inclusive range of integer time codes.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct FrameRange {
    pub first: i64,
    pub last: i64,
}

/// The largest whole frame `--frames` takes, either sign: 2^53, past which
/// consecutive integers no longer have distinct `f64` time codes.
const MAX_TIME_CODE: u64 = 1 << 53;

/// `text` quoted for a message, cut to its first 40 characters (a request
/// may send megabytes where a frame range belongs; the answer need not echo
/// them).
pub(super) fn quoted(text: &str) -> String {
    const SHOWN: usize = 40;
    match text.char_indices().nth(SHOWN) {
        None => format!("{text:?}"),
        Some((cut, _)) => format!("{:?} (cut; {} bytes in all)", &text[..cut], text.len()),
    }
}

/// `A-B` or `A`; either bound may be negative (`-5--1`).
pub fn parse_frames(s: &str) -> Result<FrameRange, String> {
    let compact: String = s.chars().filter(|c| !c.is_whitespace()).collect();
    let s = compact.as_str();
    // The separating '-' is the first one that follows a digit.
    let split = s.char_indices().find(|&(i, c)| c == '-' && i > 0 && s.as_bytes()[i - 1].is_ascii_digit());
    let (a, b) = match split {
        Some((i, _)) => (&s[..i], &s[i + 1..]),
        None => (s, s),
    };
    let int = |x: &str| {
        x.trim().parse::<i64>().map_err(|_| format!("{} is not an integer frame (expected A-B or A)", quoted(x)))
    };
    let (first, last) = (int(a)?, int(b)?);
    // Time codes are doubles: past 2^53 two frames can share one.
    if let Some(x) = [first, last].into_iter().find(|x| x.unsigned_abs() > MAX_TIME_CODE) {
        return Err(format!(
            "frame {x} is beyond ±{MAX_TIME_CODE}, the largest whole time code a USD double holds exactly"
        ));
    }
    if first > last {
        return Err(format!("{first}-{last} is empty: the first frame must not be after the last"));
    }
    if i128::from(last) - i128::from(first) >= i128::from(MAX_FRAMES) {
        return Err(format!("{first}-{last} is more than {MAX_FRAMES} frames"));
    }
    Ok(FrameRange { first, last })
}

/// One deformed mesh, bound.
struct MeshJob {
    mesh: MeshData,
    nets: Vec<CurvenetData>,
    deformer: Deformer,
    /// Built here or read from the binding store (`--store`).
    source: super::store::Source,
    /// Whether each frame's rest pose is read and passed to the solve (the
    /// mesh's `points` are animated or differ from the projection pose).
    reads_rest: bool,
    /// Whether the mesh has blend shapes (the deformer holds them).
    has_shapes: bool,
    /// Where the blend shapes go: before skinning (the default for a mesh
    /// skinned in process) or after the solve (the default otherwise).
    mode: BlendShapeMode,
    /// What reads the frame's joint transforms, when the mesh is skinned in process.
    joints: Option<JointReader>,
    /// A skinned mesh's bind pose when its `points` have no time samples.
    bind_points: Option<Vec<[f64; 3]>>,
    /// The `CurvenetAdjustment` prims of each curvenet (binding order).
    adjustments: Vec<Vec<AdjustmentData>>,
    /// The mesh's cage (`rel curvenet:cage`), read whole at bind: its
    /// rest-cage edits and posed-cage offsets are evaluated per frame off
    /// the stage's thread ([`CageData::frame`]).
    cage: Option<CageData>,
}

/// One mesh's input at one frame.
struct MeshFrame {
    posed: Vec<Option<Vec<[f64; 3]>>>,
    /// The rest pose read from the stage; for a skinned mesh, its points
    /// before skinning (`None`: the bind pose read once).
    rest: Option<Vec<[f64; 3]>>,
    /// A skinned mesh's skinning transforms this frame.
    transforms: Option<Vec<Mat4>>,
    /// Blend-shape weights (empty when the mesh has no blend shapes).
    weights: Vec<f64>,
    /// The curvenets' adjustments at this frame (empty when there are none).
    adjustments: Vec<Adjustment>,
}

/// One frame's inputs, one entry per mesh job.
struct FrameData {
    time: f64,
    meshes: Vec<MeshFrame>,
}

pub fn run(args: &Args) -> CliResult {
    run_with(args, &mut |w| eprintln!("curvenet: warning: {w}"), &Bounds::default())
}

/// What a caller other than the command line bounds a bake by (`POST
/// /v1/bake`; the command line sets none).
#[derive(Debug, Clone, Default)]
pub struct Bounds {
    /// Largest `frames × vertices × 12` bytes of baked points, all of which
    /// a bake holds until it writes its layer; over it the bake is refused
    /// before any binding, with [`CliError::Limit`].
    pub max_points_bytes: Option<u64>,
    /// Raised: the bake stops at its next chunk of frames (or before its
    /// binding, or its write) with [`CliError::Cancelled`], writing nothing.
    pub cancel: Option<curvenet_core::Cancel>,
}

impl Bounds {
    fn check(&self) -> CliResult {
        match &self.cancel {
            Some(c) if c.is_cancelled() => Err(CliError::Cancelled),
            _ => Ok(()),
        }
    }
}

/// [`run`], every warning handed to `warn` as it arises (the command line
/// prints it on stderr; `POST /v1/bake` returns them in its answer), each
/// naming the stage or the prim it is about, within `bounds`.
pub fn run_with(args: &Args, warn: &mut dyn FnMut(String), bounds: &Bounds) -> CliResult {
    let started = Instant::now();
    // Cheap checks first, so a bad command fails before any work.
    LayerFormat::from_path(&args.out).map_err(write_error)?;
    super::check_output_dir(&args.out)?;
    if same_file(&args.input, &args.out) {
        return Err(CliError::Input(format!("{}: the output would replace the input", args.out.display())));
    }
    let threads = super::check_threads("--threads", args.threads.map_or(0, NonZeroUsize::get))?;
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .build()
        .map_err(|e| CliError::Input(format!("cannot start {threads} worker threads: {e}")))?;

    let stage = if args.confine.is_empty() {
        Stage::open(&args.input)?
    } else {
        let roots = args
            .confine
            .iter()
            .map(|r| std::fs::canonicalize(r).map_err(|e| CliError::Input(format!("--confine {}: {e}", r.display()))))
            .collect::<CliResult<Vec<_>>>()?;
        Stage::open_within(&args.input, &roots)?
    };
    // Not only the stage file: no layer it reads may be replaced by the bake
    // (a shot's animation sublayer, the mesh every shot references).
    if let Some(layer) = stage.layer_files().into_iter().find(|l| same_file(l, &args.out)) {
        return Err(CliError::Input(format!(
            "{}: the output would replace {}, a layer of the stage {}",
            args.out.display(),
            layer.display(),
            args.input.display()
        )));
    }
    let inputs = super::deformed_meshes(&stage, "bake")?;
    let frames = frames(&stage, args.frames, &inputs, warn)?;
    // The command line's bound: --max-points-bytes, else 1/8 of the memory.
    let (max_points, limit_name) = match bounds.max_points_bytes {
        Some(max) => (Some(max), "this server's limit (--max-bake-bytes, CURVENET_MAX_BAKE_BYTES)"),
        None => match args.max_points_bytes {
            Some(max) => (Some(max), "the limit (--max-points-bytes)"),
            None => (
                super::memory_fraction(POINTS_SHARE_OF_MEMORY),
                "the limit (--max-points-bytes; by default 1/8 of this machine's memory)",
            ),
        },
    };
    if let Some(max) = max_points {
        let vertices: usize = inputs.iter().map(|(m, _, _)| m.projection_points.len()).sum();
        let bytes = frames.len() as u128 * vertices as u128 * 12;
        if bytes > max as u128 {
            return Err(CliError::Limit(format!(
                "{}: {} frames of {vertices} vertices are {bytes} bytes of points, all held until the layer is \
                 written, over {limit_name} of {max} bytes: bake fewer frames at once (--frames A-B) and stitch \
                 the layers",
                stage.path(),
                frames.len()
            )));
        }
    }
    bounds.check()?;
    let adjustments = inputs
        .iter()
        .map(|(_, nets, _)| nets.iter().map(|n| stage.curvenet_adjustments(n)).collect::<Result<Vec<_>, _>>())
        .collect::<Result<Vec<_>, _>>()?;

    let t_bind = Instant::now();
    // The rigs (and what else only the stage's thread can read), then the bindings in parallel.
    let inputs = inputs
        .into_iter()
        .map(|(m, n, r)| {
            let rig = MeshRig::new(&stage, &m, &n, args.g1_flexible)?;
            let reading = FrameReading::new(&stage, &m, r, rig.is_some())?;
            let cage = stage.cage(&m)?;
            Ok(Read { mesh: m, nets: n, rig, reading, cage })
        })
        .collect::<CliResult<Vec<_>>>()?;
    for Read { mesh: m, rig, .. } in &inputs {
        if let Some(rig) = rig
            && let Some(&p) = rig.unnormalized.first()
        {
            warn(format!(
                "{}: the skin weights of {} point{} (the first: point {p}, sum {}) do not sum to 1; they are \
                 skinned as authored, as usd-core does",
                m.path,
                rig.unnormalized.len(),
                if rig.unnormalized.len() == 1 { "" } else { "s" },
                rig.skinning.skin.influences().weight_sum(p)
            ));
        }
    }
    let store = match args.store.as_deref() {
        Some(s) => super::store::BakeStore::open(s, args.store_bytes, warn)?,
        None => None,
    };
    let store = store.as_ref();
    let jobs: Vec<MeshJob> = pool.install(|| {
        inputs.into_par_iter().zip(adjustments).map(|(read, a)| bind(read, a, store)).collect::<CliResult<_>>()
    })?;
    let bind_ms = ms(t_bind.elapsed());
    let loaded = jobs.iter().filter(|j| j.source == super::store::Source::Loaded).count();
    let unstored = jobs.iter().filter(|j| j.source == super::store::Source::BuiltNotStored).count();
    for job in &jobs {
        for w in job.deformer.binding().warnings() {
            warn(format!("{}: {w}", job.mesh.path));
        }
    }

    // Read chunk k + 1 on this thread while chunk k solves on the pool.
    let per_frame_bytes: usize = jobs
        .iter()
        .map(|j| {
            24 * (j.nets.iter().map(|n| n.pool.len()).sum::<usize>()
                + if j.reads_rest { j.deformer.n_vertices() } else { 0 })
                + j.joints.as_ref().map_or(0, |r| 128 * r.rig.joints.len())
        })
        .sum();
    let threads = pool.current_num_threads();
    // Each thread gets about two groups of --batch-frames per chunk.
    let batch = args.batch_frames as usize;
    let chunk =
        (4 * threads).max(2 * threads * batch).min(MAX_CHUNK_FRAMES).min((CHUNK_BYTES / per_frame_bytes.max(1)).max(1));
    let progress = Progress::new(frames.len(), jobs.len(), args.quiet);
    let solve_ns = AtomicU64::new(0);
    let mut baked: Vec<Vec<(f64, Vec<[f32; 3]>)>> = jobs.iter().map(|_| Vec::with_capacity(frames.len())).collect();
    let mut read_time = Duration::ZERO;
    let mut chunks = frames.chunks(chunk);
    let t_read = Instant::now();
    let mut next = chunks.next().map(|c| read_chunk(&stage, &jobs, c)).transpose()?;
    read_time += t_read.elapsed();
    while let Some(current) = next.take() {
        bounds.check()?;
        let (solved, read) = std::thread::scope(|s| {
            let solving = s.spawn(|| pool.install(|| solve_chunk(&jobs, &current, batch, &solve_ns, &progress)));
            let t_read = Instant::now();
            let read = chunks.next().map(|c| read_chunk(&stage, &jobs, c)).transpose();
            read_time += t_read.elapsed();
            (solving.join().expect("a solve thread panicked"), read)
        });
        // An error of this chunk comes before any of the next one's.
        for (frame, results) in current.iter().zip(solved?) {
            for (k, points) in results.into_iter().enumerate() {
                baked[k].push((frame.time, points));
            }
        }
        next = read?;
    }
    progress.finish();
    bounds.check()?;

    let t_write = Instant::now();
    let range = (frames[0], frames[frames.len() - 1]);
    // The doc names no frames (startTimeCode/endTimeCode do): chunks of one
    // shot then carry the same doc, and `curvenet stitch` keeps it, so the
    // stitched layer is byte for byte the whole-range bake.
    let doc = format!(
        "Baked by curvenet {} (`curvenet bake`) from {}: the deformed points of {} from startTimeCode to \
         endTimeCode, as over opinions only. Sublayer above (stronger than) the input.",
        env!("CARGO_PKG_VERSION"),
        args.input.display(),
        jobs.iter().map(|j| j.mesh.path.as_str()).collect::<Vec<_>>().join(", "),
    );
    let prims = jobs.iter().zip(baked).map(|(j, samples)| PrimPoints { prim: j.mesh.path.clone(), samples }).collect();
    write_points_overrides(&args.out, prims, range, &doc).map_err(write_error)?;
    let write_ms = ms(t_write.elapsed());
    let (iterations, poses) =
        jobs.iter().map(|j| j.deformer.flexible_stats()).fold((0, 0), |(i, p), f| (i + f.iterations, p + f.poses));

    if !args.quiet {
        let vertices: usize = jobs.iter().map(|j| j.deformer.n_vertices()).sum();
        eprintln!(
            "curvenet: baked {} mesh{} ({vertices} vertices) x {} frame{} ({}) to {} in {:.2} s: bind {:.0} ms{}, \
             mean solve {:.2} ms per frame ({threads} thread{}), read {:.0} ms, write {:.0} ms{}",
            jobs.len(),
            if jobs.len() == 1 { "" } else { "es" },
            frames.len(),
            if frames.len() == 1 { "" } else { "s" },
            frame_list(&frames),
            args.out.display(),
            started.elapsed().as_secs_f64(),
            bind_ms,
            match (store, loaded, unstored) {
                (None, _, _) => String::new(),
                (Some(_), 0, 0) => " (built, written to the store)".to_string(),
                (Some(_), 0, u) if u == jobs.len() =>
                    " (built, not written to the store: see the warnings)".to_string(),
                (Some(_), k, 0) if k == jobs.len() => " (loaded from the store)".to_string(),
                (Some(_), k, 0) => format!(" ({k} of {} loaded from the store)", jobs.len()),
                (Some(_), k, u) => format!(
                    " ({k} of {} loaded from the store, {u} built and not written to it: see the warnings)",
                    jobs.len()
                ),
            },
            solve_ns.load(Ordering::Relaxed) as f64 / 1e6 / frames.len() as f64,
            if threads == 1 { "" } else { "s" },
            ms(read_time),
            write_ms,
            match poses {
                0 => String::new(),
                p => format!(
                    ", G1-flexible spline skinning: {iterations} iterations over {p} curvenet poses ({:.1} each)",
                    iterations as f64 / p as f64
                ),
            },
        );
    }
    Ok(())
}

/// The frames to bake: `--frames`, else the stage's time-code range, else
/// the union of the time samples of the meshes' points and curvenets' pools.
/// A requested range reaching outside the stage's is baked, with a warning
/// to `warn`.
pub(super) fn frames(
    stage: &Stage,
    requested: Option<FrameRange>,
    inputs: &[super::DeformedMesh],
    warn: &mut dyn FnMut(String),
) -> CliResult<Vec<f64>> {
    if let Some(r) = requested {
        // Frames outside the stage's range are valid USD times (a pre-roll,
        // a chunk cut past the end): every attribute holds its nearest
        // authored sample, so the bake repeats the first or last pose. Baked
        // as asked, but said, since it is more often a wrong range.
        if let Some((start, end)) = stage.time_code_range()
            && ((r.first as f64) < start || (r.last as f64) > end)
        {
            warn(format!(
                "{}: the frames {}-{} reach outside the stage's startTimeCode {start} .. endTimeCode {end}; \
                 frames there hold the nearest authored samples",
                stage.path(),
                r.first,
                r.last
            ));
        }
        return Ok((r.first..=r.last).map(|t| t as f64).collect());
    }
    if let Some((start, end)) = stage.time_code_range() {
        let (first, last) = (start.ceil(), end.floor());
        if !(first <= last) || last - first >= MAX_FRAMES as f64 {
            return Err(CliError::Input(format!(
                "{}: startTimeCode {start} .. endTimeCode {end} holds no bakeable frame range; pass --frames A-B",
                stage.path()
            )));
        }
        return Ok((first as i64..=last as i64).map(|t| t as f64).collect());
    }
    let mut times: Vec<f64> = inputs
        .iter()
        .flat_map(|(m, nets, _)| m.rest_sample_times.iter().chain(nets.iter().flat_map(|n| &n.sample_times)))
        .copied()
        .collect();
    // A skinned mesh: the animation's joint-transform samples.
    for (m, _, _) in inputs {
        if let Some(rig) = stage.skin_rig(m)? {
            times.extend(&rig.time_samples);
        }
        // A caged mesh: the cage's rest-cage edits and posed-cage offsets.
        if let Some(cage) = stage.cage(m)? {
            times.extend(cage.sample_times());
        }
    }
    times.sort_by(f64::total_cmp);
    times.dedup();
    if times.is_empty() {
        return Err(CliError::Input(format!(
            "{}: the stage authors no startTimeCode/endTimeCode and no time samples on its meshes or curvenets; \
             pass --frames A-B",
            stage.path()
        )));
    }
    Ok(times)
}

/// What the stage's thread reads for one mesh before it is bound.
struct Read {
    mesh: MeshData,
    nets: Vec<CurvenetData>,
    rig: Option<MeshRig>,
    reading: FrameReading,
    cage: Option<CageData>,
}

/// How a mesh's frames are read from the stage besides its curvenets, joints
/// and cage: the bake's, and the viewer's for the stages it opens
/// (`serve --open-stage`), so that the two draw the same frames.
pub struct FrameReading {
    /// Whether each frame reads the mesh's `points` at its time as the rest pose.
    pub reads_rest: bool,
    /// The rest pose of every frame otherwise, for a mesh skinned in process
    /// whose `points` have no time samples: its bind pose.
    pub bind_points: Option<Vec<[f64; 3]>>,
    /// Where the blend shapes go (`curvenet:blendShapeOrder`; by default
    /// before skinning for a mesh skinned in process, after the solve otherwise).
    pub order: BlendShapeOrder,
}

impl FrameReading {
    /// `reads_rest` as [`super::deformed_meshes`] found it (the `points` are
    /// animated or differ from the projection pose); `skinned`: whether the
    /// mesh is skinned in process (its UsdSkel rig is read).
    pub fn new(stage: &Stage, mesh: &MeshData, reads_rest: bool, skinned: bool) -> CliResult<Self> {
        let order = stage.blend_shape_order(mesh)?.unwrap_or(match skinned {
            true => BlendShapeOrder::BeforeSkinning,
            false => BlendShapeOrder::AfterSolve,
        });
        // A skinned mesh reads its points per frame only when they are animated.
        let animated = !mesh.rest_sample_times.is_empty();
        let (reads_rest, bind_points) = match (skinned, animated) {
            (true, true) => (true, None),
            (true, false) => (false, Some(stage.rest_points(mesh, None)?)),
            (false, _) => (reads_rest, None),
        };
        Ok(Self { reads_rest, bind_points, order })
    }
}

fn bind(
    read: Read,
    adjustments: Vec<Vec<AdjustmentData>>,
    store: Option<&super::store::BakeStore>,
) -> CliResult<MeshJob> {
    let Read { mesh, nets, rig, reading, cage } = read;
    let FrameReading { reads_rest, bind_points, order } = reading;
    let (joints, skinning) = match rig {
        Some(r) => (Some(r.joints), Some(r.skinning)),
        None => (None, None),
    };
    let (deformer, source) = super::bind::deformer_in(store, &mesh, &nets, skinning, cage.as_ref())?;
    let mode = match order {
        BlendShapeOrder::BeforeSkinning => BlendShapeMode::Before,
        BlendShapeOrder::AfterSolve => BlendShapeMode::After,
    };
    let has_shapes = !mesh.blend_shapes.is_empty();
    Ok(MeshJob { mesh, nets, deformer, source, reads_rest, has_shapes, mode, joints, bind_points, adjustments, cage })
}

/// Reads one chunk's inputs and checks they are finite; errors name the frame
/// and the prim.
fn read_chunk(stage: &Stage, jobs: &[MeshJob], times: &[f64]) -> CliResult<Vec<FrameData>> {
    times
        .iter()
        .map(|&t| {
            let at = |e: curvenet_schema::usd::UsdError| CliError::Input(format!("frame {t}, {e}"));
            let meshes = jobs
                .iter()
                .map(|job| {
                    let mut posed = Vec::with_capacity(job.nets.len());
                    for net in &job.nets {
                        let pool = stage.posed_pool(net, Some(t)).map_err(at)?;
                        if let Some(pool) = &pool {
                            check_frame_points(pool, t, &net.path, "primvars:curvenet:cv", "control point")?;
                        }
                        posed.push(pool);
                    }
                    let rest = match job.reads_rest {
                        true => {
                            let rest = stage.rest_points(&job.mesh, Some(t)).map_err(at)?;
                            check_frame_points(&rest, t, &job.mesh.path, "points", "point")?;
                            Some(rest)
                        }
                        false => None,
                    };
                    let weights = match !job.has_shapes {
                        true => Vec::new(),
                        false => stage.blend_shape_weights(&job.mesh, Some(t)).map_err(at)?,
                    };
                    check_weights(&weights, t, &job.mesh.path)?;
                    let transforms = match &job.joints {
                        Some(rig) => Some(rig.read_transforms(stage, Some(t)).map_err(|e| match e {
                            CliError::Usd(u) => at(u),
                            other => other,
                        })?),
                        None => None,
                    };
                    let adjustments = stage.adjustments_at(&job.adjustments, Some(t)).map_err(at)?;
                    Ok(MeshFrame { posed, rest, transforms, weights, adjustments })
                })
                .collect::<CliResult<Vec<_>>>()?;
            Ok(FrameData { time: t, meshes })
        })
        .collect()
}

/// The default `--max-points-bytes`: this share of the machine's memory.
/// A bake's peak memory was measured at 2.8-3.6× its points' bytes (the
/// points held, then the layer made from them and written; hand_wave, 5,000
/// and 20,000 frames), so 1/8 keeps a bake under half the memory.
const POINTS_SHARE_OF_MEMORY: u64 = 8;

/// Checks a frame's points as the service does (`MAX_COORDINATE`): finite,
/// and at most 1e15 in magnitude (an f32 output spaces its values 1e8 apart
/// there, so larger values are no longer geometry).
fn check_frame_points(points: &[[f64; 3]], t: f64, prim: &str, attribute: &str, what: &str) -> CliResult {
    let limit = curvenet_server::MAX_COORDINATE;
    let non_finite: Vec<usize> = (0..points.len()).filter(|&i| !points[i].iter().all(|x| x.is_finite())).collect();
    let in_all = |bad: &[usize], kind: &str| match bad.len() {
        1 => String::new(),
        n => format!(" ({n} {kind} {what}s in all)"),
    };
    if let Some(&i) = non_finite.first() {
        return Err(CliError::Input(format!(
            "frame {t}, {prim}: {attribute} {what} {i} is {:?}, not finite{}",
            points[i],
            in_all(&non_finite, "non-finite")
        )));
    }
    let huge: Vec<usize> = (0..points.len()).filter(|&i| points[i].iter().any(|x| x.abs() > limit)).collect();
    match huge.first() {
        None => Ok(()),
        Some(&i) => Err(CliError::Input(format!(
            "frame {t}, {prim}: {attribute} {what} {i} is {:?}, beyond {limit:e} in magnitude{}",
            points[i],
            in_all(&huge, "such")
        ))),
    }
}

/// Checks a frame's blend-shape weights as the service does (`MAX_WEIGHT`):
/// finite and at most 1e6 in magnitude.
fn check_weights(weights: &[f64], t: f64, prim: &str) -> CliResult {
    let limit = curvenet_server::MAX_WEIGHT;
    match weights.iter().position(|w| !(w.is_finite() && w.abs() <= limit)) {
        None => Ok(()),
        Some(i) => Err(CliError::Input(format!(
            "frame {t}, {prim}: skel:blendShapeWeights weight {i} is {}, not finite or beyond {limit:e} in magnitude",
            weights[i]
        ))),
    }
}

/// Solves every (frame, mesh) pair of a chunk, in groups of up to `batch`
/// frames of one mesh (one multi-frame solve each, `Deformer::frames`),
/// the groups in parallel; answers per frame, per mesh, in order.
fn solve_chunk(
    jobs: &[MeshJob],
    chunk: &[FrameData],
    batch: usize,
    solve_ns: &AtomicU64,
    progress: &Progress,
) -> CliResult<Vec<Vec<Vec<[f32; 3]>>>> {
    let n = jobs.len();
    let groups = chunk.len().div_ceil(batch);
    let solved: Vec<CliResult<Vec<Vec<[f32; 3]>>>> = (0..groups * n)
        .into_par_iter()
        .map(|item| {
            let (g, k) = (item / n, item % n);
            let frames = &chunk[g * batch..((g + 1) * batch).min(chunk.len())];
            let r = solve_group(&jobs[k], k, frames, solve_ns);
            progress.tick(frames.len());
            r
        })
        .collect();
    // Per group (mesh fastest), per frame of the group → per frame, per mesh.
    let mut out: Vec<Vec<Vec<[f32; 3]>>> = (0..chunk.len()).map(|_| Vec::with_capacity(n)).collect();
    for (item, r) in solved.into_iter().enumerate() {
        let g = item / n;
        for (j, points) in r?.into_iter().enumerate() {
            out[g * batch + j].push(points);
        }
    }
    Ok(out)
}

/// Solves mesh `k` of `frames` in one multi-frame solve; an error names the frame.
fn solve_group(job: &MeshJob, k: usize, frames: &[FrameData], solve_ns: &AtomicU64) -> CliResult<Vec<Vec<[f32; 3]>>> {
    let t0 = Instant::now();
    let posed: Vec<Vec<Option<&[[f64; 3]]>>> =
        frames.iter().map(|f| f.meshes[k].posed.iter().map(|p| p.as_deref()).collect()).collect();
    // The cage's edits of each frame, evaluated off the stage's thread.
    let cages: Vec<Option<curvenet_schema::CageFrame<'_>>> =
        frames.iter().map(|f| job.cage.as_ref().map(|c| c.frame(Some(f.time)))).collect();
    let inputs: Vec<Frame<'_>> = frames
        .iter()
        .zip(&posed)
        .zip(&cages)
        .map(|((f, posed), cage)| {
            let input = &f.meshes[k];
            Frame {
                posed,
                // A skinned mesh's points before skinning: the frame's, else its bind pose.
                rest: input.rest.as_deref().or(job.bind_points.as_deref()),
                blend_shape_weights: (!input.weights.is_empty()).then_some(&input.weights[..]),
                blend_shape_mode: job.mode,
                adjustments: &input.adjustments,
                joint_transforms: input.transforms.as_deref(),
                rest_cage: cage.as_ref().and_then(|c| c.rest_cage()),
                posed_cage_offsets: cage.as_ref().and_then(|c| c.posed_cage_offsets()),
            }
        })
        .collect();
    let mut points = vec![vec![[0.0; 3]; job.deformer.n_vertices()]; frames.len()];
    let mut outs: Vec<FrameOut<'_>> = points.iter_mut().map(|p| FrameOut { points: p, gradients: None }).collect();
    job.deformer.frames(&inputs, &mut outs).map_err(|e| match e.error {
        // A degenerate pose of one curvenet names it.
        curvenet_core::Error::Curvenet { curvenet, source } => CliError::Core {
            context: format!(
                "frame {}, {} (deforming {})",
                frames[e.frame].time, job.nets[curvenet as usize].path, job.mesh.path
            ),
            source: *source,
        },
        error => CliError::Core {
            context: format!("frame {}, {} (deformed by {})", frames[e.frame].time, job.mesh.path, net_list(&job.nets)),
            source: error,
        },
    })?;
    solve_ns.fetch_add(t0.elapsed().as_nanos() as u64, Ordering::Relaxed);
    let written: Vec<Vec<[f32; 3]>> =
        points.iter().map(|out| out.iter().map(|p| [p[0] as f32, p[1] as f32, p[2] as f32]).collect()).collect();
    // Inputs within bounds can still deform far away (a rig's transforms, a
    // blend shape's large offsets, a cage's edits, an adjustment): a frame
    // whose points are past f32 or beyond the 1e15 every input is held to
    // (so that the bake could not read its own output back) is refused,
    // never written.
    let limit = curvenet_server::MAX_COORDINATE;
    for ((frame, out), solved) in frames.iter().zip(&written).zip(&points) {
        if let Some(i) = out.iter().position(|p| !p.iter().all(|x| x.is_finite() && (x.abs() as f64) <= limit)) {
            return Err(CliError::Input(format!(
                "frame {}, {}: deformed point {i} is {:?}, not finite in f32 (the output's type) or beyond {limit:e}",
                frame.time, job.mesh.path, solved[i]
            )));
        }
    }
    Ok(written)
}

/// The progress line on a terminal (stderr), redrawn at most every 100 ms.
struct Progress {
    frames: usize,
    meshes: usize,
    done: AtomicUsize,
    start: Instant,
    /// `None` when not drawing (not a terminal, or `--quiet`).
    last_draw: Option<Mutex<Instant>>,
}

impl Progress {
    fn new(frames: usize, meshes: usize, quiet: bool) -> Self {
        use std::io::IsTerminal;
        let draw = !quiet && std::io::stderr().is_terminal();
        let start = Instant::now();
        Self { frames, meshes, done: AtomicUsize::new(0), start, last_draw: draw.then(|| Mutex::new(start)) }
    }

    /// `frames` more (frame, mesh) pairs solved.
    fn tick(&self, frames: usize) {
        let done = self.done.fetch_add(frames, Ordering::Relaxed) + frames;
        let Some(last) = &self.last_draw else { return };
        let Ok(mut last) = last.try_lock() else { return };
        if last.elapsed() < Duration::from_millis(100) && done < self.frames * self.meshes {
            return;
        }
        *last = Instant::now();
        let frames_done = done / self.meshes.max(1);
        let secs = self.start.elapsed().as_secs_f64();
        let fps = frames_done as f64 / secs.max(1e-9);
        let eta = if fps > 0.0 { format!("{:.1} s", (self.frames - frames_done) as f64 / fps) } else { "?".into() };
        eprint!("\r\x1b[Kbaking: {frames_done}/{} frames, {fps:.1} frames/s, ETA {eta}", self.frames);
    }

    fn finish(&self) {
        if self.last_draw.is_some() {
            eprint!("\r\x1b[K");
        }
    }
}

fn same_file(a: &Path, b: &Path) -> bool {
    matches!((std::fs::canonicalize(a), std::fs::canonicalize(b)), (Ok(a), Ok(b)) if a == b)
}

fn write_error(e: WriteError) -> CliError {
    match e {
        WriteError::Io { what, path, source } => CliError::Io { context: format!("{what} {path}"), source },
        e => CliError::Input(e.to_string()),
    }
}

/// `1-24` for a contiguous integer range, else the count of times and the ends.
fn frame_list(frames: &[f64]) -> String {
    let (a, b) = (frames[0], frames[frames.len() - 1]);
    let contiguous = frames.windows(2).all(|w| w[1] - w[0] == 1.0) && a.fract() == 0.0;
    if contiguous { format!("{a}-{b}") } else { format!("time codes {a}..{b}") }
}

fn ms(d: Duration) -> f64 {
    d.as_secs_f64() * 1e3
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn frame_ranges_parse() {
        assert_eq!(parse_frames("1-24"), Ok(FrameRange { first: 1, last: 24 }));
        assert_eq!(parse_frames("7"), Ok(FrameRange { first: 7, last: 7 }));
        assert_eq!(parse_frames("-5--1"), Ok(FrameRange { first: -5, last: -1 }));
        assert_eq!(parse_frames("-3-2"), Ok(FrameRange { first: -3, last: 2 }));
        assert_eq!(parse_frames(" 5 - 7 "), Ok(FrameRange { first: 5, last: 7 }));
        assert!(parse_frames("7-5").unwrap_err().contains("empty"));
        assert!(parse_frames("1.5-3").is_err());
        assert!(parse_frames("a-b").is_err());
        assert!(parse_frames("").is_err());
        // Spans and bounds at the edges of i64 and of exact doubles: refused, never overflowing.
        for bad in ["-1-9223372036854775807", "-9223372036854775808-9223372036854775807", "9007199254740993"] {
            assert!(parse_frames(bad).is_err(), "{bad}");
        }
        assert!(parse_frames("-5000000000000000000-5000000000000000000").unwrap_err().contains("beyond"));
        assert_eq!(
            parse_frames("9007199254740991-9007199254740992"),
            Ok(FrameRange { first: 9007199254740991, last: 9007199254740992 })
        );
        assert!(parse_frames("-9007199254740992-0").unwrap_err().contains("more than"));
        assert!(parse_frames("1-100000000").is_err());
        // A megabyte where a frame belongs is not echoed back whole.
        let huge = "1".repeat(1 << 20);
        let e = parse_frames(&huge).unwrap_err();
        assert!(e.len() < 200 && e.contains("1048576 bytes in all"), "{e}");
        assert!(parse_frames("x").unwrap_err().starts_with("\"x\" is not"));
    }
}
