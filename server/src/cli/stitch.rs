//! `curvenet stitch CHUNK... --out OUTPUT [--frames A-B] [--quiet]`: merges
//! the layers of a chunked bake (`curvenet bake --frames A-B` per farm task)
//! into the one layer a single whole-range bake would have written, byte for
//! byte (schema/README.md, "Bake output").
//!
//! 1. Every chunk is read back with `read_points_overrides`, which refuses a
//!    layer the bake writer would not have written.
//! 2. The chunks must come from one bake: the same doc string (it names the
//!    input and the meshes, never the frames), the same prims in the same
//!    order, the same vertex count per prim.
//! 3. Samples are merged per prim; a frame in two chunks must carry the same
//!    bits (a rerun chunk does), else the two files and the frame are named.
//! 4. The time range is the union of the chunks' (or `--frames`); every
//!    integer frame in it must lie in some chunk's range, so a missing chunk
//!    is an error, not a hole.
//! 5. The result goes through the bake's own writer, atomically.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::time::Instant;

use curvenet_schema::usd::{
    LayerFormat, PointsOverrides, PrimPoints, ReadOverridesError, WriteError, read_points_overrides,
    write_points_overrides,
};

use super::bake::{FrameRange, parse_frames};
use super::{CliError, CliResult};

/// Longest stitched range, as for the bake (guards against a stray chunk range).
const MAX_FRAMES: f64 = 1_000_000.0;

const AFTER_HELP: &str = "\
Input: the layers written by `curvenet bake --frames A-B` for chunks of one shot
(.usda or .usdc, in any order; chunks may overlap if they agree bit for bit).
Output: the layer `curvenet bake` would write for the whole range, byte for byte
(same format by OUTPUT's extension), replaced atomically like the bake's. OUTPUT
may be one of the chunks.

Frames: the stitched range is the union of the chunks' startTimeCode..endTimeCode.
With --frames A-B, only the samples in A..B are kept and the range is A-B, so
stale chunks outside it (from an earlier, longer submission) do no harm.
Every integer frame of the range must lie in some chunk.

Exit status: 0 success; 2 bad input, not worth retrying (a chunk that is missing,
unreadable or not a bake layer; chunks from different bakes - doc string, prims
or vertex counts; chunks that disagree on a frame; a frame no chunk covers; a
bad --frames or output extension), naming the file, prim and frame; 75 an I/O
failure worth retrying (reading a chunk other than not-found/permission, writing
OUTPUT, an output directory that does not exist).";

#[derive(clap::Args)]
#[command(after_help = AFTER_HELP)]
pub struct Args {
    /// The chunk layers (bake outputs) to merge.
    #[arg(required = true, value_name = "CHUNK")]
    pub chunks: Vec<PathBuf>,
    /// The layer to write: .usda (text) or .usdc (binary), by its extension.
    #[arg(long, short)]
    pub out: PathBuf,
    /// Keep only frames A-B (inclusive integer time codes) or A; all must be covered.
    #[arg(long, value_name = "A-B", value_parser = parse_frames, allow_hyphen_values = true)]
    pub frames: Option<FrameRange>,
    /// No summary line.
    #[arg(long, short)]
    pub quiet: bool,
}

/// One prim's merged samples: time code (by its bits, ordered) → points and
/// the chunk they came from.
type Merged<'a> = BTreeMap<TimeKey, (&'a [[f32; 3]], usize)>;

/// A finite time code ordered by value (`f64::total_cmp`), for map keys.
#[derive(Debug, Clone, Copy, PartialEq)]
struct TimeKey(f64);

impl Eq for TimeKey {}

impl PartialOrd for TimeKey {
    fn partial_cmp(&self, other: &Self) -> Option<std::cmp::Ordering> {
        Some(self.cmp(other))
    }
}

impl Ord for TimeKey {
    fn cmp(&self, other: &Self) -> std::cmp::Ordering {
        self.0.total_cmp(&other.0)
    }
}

pub fn run(args: &Args) -> CliResult {
    let started = Instant::now();
    LayerFormat::from_path(&args.out).map_err(write_error)?;
    super::check_output_dir(&args.out)?;

    let chunks: Vec<PointsOverrides> = args.chunks.iter().map(|p| read_chunk(p)).collect::<CliResult<_>>()?;
    let stitched = stitch(&args.chunks, &chunks, args.frames)?;
    let frames = stitched.prims[0].samples.len();
    let range = stitched.time_range;
    let meshes = stitched.prims.len();
    write_points_overrides(&args.out, stitched.prims, stitched.time_range, &stitched.doc).map_err(write_error)?;

    if !args.quiet {
        eprintln!(
            "curvenet: stitched {} chunk{} ({meshes} mesh{}, {frames} frame{}, time codes {}..{}) to {} in {:.2} s",
            chunks.len(),
            if chunks.len() == 1 { "" } else { "s" },
            if meshes == 1 { "" } else { "es" },
            if frames == 1 { "" } else { "s" },
            range.0,
            range.1,
            args.out.display(),
            started.elapsed().as_secs_f64()
        );
    }
    Ok(())
}

/// Merges chunks already read (`names[i]` names `chunks[i]` in errors) into
/// the layer a whole-range bake writes.
pub fn stitch(names: &[PathBuf], chunks: &[PointsOverrides], frames: Option<FrameRange>) -> CliResult<PointsOverrides> {
    let name = |i: usize| names[i].display().to_string();
    let Some(first) = chunks.first() else {
        return Err(CliError::Input("no chunks to stitch".into()));
    };

    // A bake writes every frame of every prim.
    for (i, chunk) in chunks.iter().enumerate() {
        let times = |p: &PrimPoints| p.samples.iter().map(|s| s.0).collect::<Vec<_>>();
        let first_times = times(&chunk.prims[0]);
        if let Some(p) = chunk.prims.iter().find(|p| times(p) != first_times) {
            let other = times(p);
            let (has, lacks, t) = match first_times.iter().find(|t| !other.contains(t)) {
                Some(t) => (&chunk.prims[0].prim, &p.prim, *t),
                None => (&p.prim, &chunk.prims[0].prim, *other.iter().find(|t| !first_times.contains(t)).unwrap()),
            };
            return Err(CliError::Input(format!(
                "{}: not a bake layer: {has} has a sample at frame {t} that {lacks} lacks (a bake writes every frame of every mesh)",
                name(i)
            )));
        }
    }
    // One bake: the same doc, prims and vertex counts in every chunk.
    for (i, chunk) in chunks.iter().enumerate().skip(1) {
        if chunk.doc != first.doc {
            return Err(CliError::Input(format!(
                "{} and {} come from different bakes (input, meshes or curvenet version): their doc strings are\n  {:?}\n  {:?}",
                name(0),
                name(i),
                first.doc,
                chunk.doc
            )));
        }
        let paths = |c: &PointsOverrides| c.prims.iter().map(|p| p.prim.clone()).collect::<Vec<_>>();
        if paths(chunk) != paths(first) {
            let (a, b) = (paths(first), paths(chunk));
            let differs = a.iter().find(|p| !b.contains(p)).map(|p| format!("{p} is in {} only", name(0)));
            let differs = differs
                .or_else(|| b.iter().find(|p| !a.contains(p)).map(|p| format!("{p} is in {} only", name(i))))
                .unwrap_or_else(|| {
                    format!("the prims are in a different order ({} vs {})", a.join(", "), b.join(", "))
                });
            return Err(CliError::Input(format!("{} and {} bake different prims: {differs}", name(0), name(i))));
        }
        for (p, q) in first.prims.iter().zip(&chunk.prims) {
            let (n, m) = (p.samples[0].1.len(), q.samples[0].1.len());
            if n != m {
                return Err(CliError::Input(format!(
                    "{}: {} has {m} points at time code {}, but {n} in {} (time code {}): not the same mesh",
                    name(i),
                    q.prim,
                    q.samples[0].0,
                    name(0),
                    p.samples[0].0
                )));
            }
        }
    }

    // The time range, and every integer frame in it covered by some chunk.
    let range = match frames {
        Some(r) => (r.first as f64, r.last as f64),
        None => chunks
            .iter()
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), c| (a.min(c.time_range.0), b.max(c.time_range.1))),
    };
    let keep = |t: f64| t >= range.0 && t <= range.1;
    if range.1 - range.0 >= MAX_FRAMES {
        return Err(CliError::Input(format!("time codes {}..{} span more than {MAX_FRAMES} frames", range.0, range.1)));
    }
    let uncovered: Vec<i64> = (range.0.ceil() as i64..=range.1.floor() as i64)
        .filter(|&f| !chunks.iter().any(|c| (f as f64) >= c.time_range.0 && (f as f64) <= c.time_range.1))
        .collect();
    if let Some(&f) = uncovered.first() {
        // The first run of consecutive uncovered frames.
        let l = uncovered.iter().zip(f..).take_while(|(g, h)| **g == *h).count() as i64 + f - 1;
        let span = if l > f { format!("frames {f}-{l} are") } else { format!("frame {f} is") };
        let mut have: Vec<String> = (0..chunks.len())
            .map(|i| format!("{} ({}..{})", name(i), chunks[i].time_range.0, chunks[i].time_range.1))
            .collect();
        have.sort();
        return Err(CliError::Input(format!(
            "{span} in no chunk (a chunk is missing) of time codes {}..{}; the chunks: {}",
            range.0,
            range.1,
            have.join(", ")
        )));
    }

    // Merge per prim; a frame twice must hold the same bits.
    let mut prims = Vec::with_capacity(first.prims.len());
    for k in 0..first.prims.len() {
        let prim = &first.prims[k].prim;
        let mut merged: Merged = BTreeMap::new();
        for (i, chunk) in chunks.iter().enumerate() {
            for (t, points) in &chunk.prims[k].samples {
                if !keep(*t) {
                    continue;
                }
                match merged.get(&TimeKey(*t)) {
                    None => {
                        merged.insert(TimeKey(*t), (points, i));
                    }
                    Some((earlier, j)) => {
                        if let Some(v) = earlier.iter().zip(points).position(|(a, b)| bits(a) != bits(b)) {
                            return Err(CliError::Input(format!(
                                "{} and {} disagree on {prim} at frame {t}: point {v} is {:?} in one and {:?} in the other \
                                 (chunks of different bakes of a changed shot? rebake or remove the stale chunk)",
                                name(*j),
                                name(i),
                                earlier[v],
                                points[v]
                            )));
                        }
                    }
                }
            }
        }
        if merged.is_empty() {
            return Err(CliError::Input(format!(
                "no chunk holds a sample of {prim} in time codes {}..{}",
                range.0, range.1
            )));
        }
        let samples = merged.into_iter().map(|(t, (p, _))| (t.0, p.to_vec())).collect();
        prims.push(PrimPoints { prim: prim.clone(), samples });
    }
    Ok(PointsOverrides { prims, time_range: range, doc: first.doc.clone() })
}

fn bits(p: &[f32; 3]) -> [u32; 3] {
    p.map(f32::to_bits)
}

/// Reads one chunk. A missing or unreadable file, or one that is not a bake
/// layer, is bad input (2); any other read failure may pass on retry (75).
fn read_chunk(path: &Path) -> CliResult<PointsOverrides> {
    use std::io::ErrorKind;
    read_points_overrides(path).map_err(|e| match e {
        ReadOverridesError::Io { path, source }
            if !matches!(
                source.kind(),
                ErrorKind::NotFound | ErrorKind::PermissionDenied | ErrorKind::IsADirectory | ErrorKind::NotADirectory
            ) =>
        {
            CliError::Io { context: format!("cannot read chunk {path}"), source }
        }
        ReadOverridesError::Io { path, source } => CliError::Input(format!("cannot read chunk {path}: {source}")),
        e => CliError::Input(e.to_string()),
    })
}

fn write_error(e: WriteError) -> CliError {
    match e {
        WriteError::Io { what, path, source } => CliError::Io { context: format!("{what} {path}"), source },
        e => CliError::Input(e.to_string()),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn chunk(first: i64, last: i64, value: f32) -> PointsOverrides {
        let samples = (first..=last).map(|t| (t as f64, vec![[value, t as f32, 0.0]; 2])).collect();
        PointsOverrides {
            prims: vec![PrimPoints { prim: "/A/Mesh".into(), samples }],
            time_range: (first as f64, last as f64),
            doc: "d".into(),
        }
    }

    fn names(n: usize) -> Vec<PathBuf> {
        (0..n).map(|i| PathBuf::from(format!("c{i}.usdc"))).collect()
    }

    #[test]
    fn chunks_merge_in_time_order_whatever_their_order() {
        let whole = chunk(1, 9, 1.0);
        let parts = [chunk(7, 9, 1.0), chunk(1, 3, 1.0), chunk(3, 6, 1.0)];
        assert_eq!(stitch(&names(3), &parts, None).unwrap(), whole);
        let some = stitch(&names(3), &parts, Some(FrameRange { first: 2, last: 4 })).unwrap();
        assert_eq!(some.time_range, (2.0, 4.0));
        assert_eq!(some.prims[0].samples.iter().map(|s| s.0).collect::<Vec<_>>(), [2.0, 3.0, 4.0]);
    }

    #[test]
    fn gaps_and_disagreements_are_named() {
        let e = stitch(&names(2), &[chunk(1, 3, 1.0), chunk(7, 9, 1.0)], None).unwrap_err().to_string();
        assert!(e.contains("frames 4-6 are in no chunk"), "{e}");
        let e = stitch(&names(2), &[chunk(1, 3, 1.0), chunk(5, 9, 1.0)], None).unwrap_err().to_string();
        assert!(e.contains("frame 4 is in no chunk"), "{e}");
        let e = stitch(&names(1), &[chunk(1, 3, 1.0)], Some(FrameRange { first: 1, last: 5 })).unwrap_err().to_string();
        assert!(e.contains("frames 4-5 are in no chunk"), "{e}");
        let e = stitch(&names(2), &[chunk(1, 5, 1.0), chunk(4, 9, 2.0)], None).unwrap_err().to_string();
        assert!(e.contains("c0.usdc and c1.usdc disagree on /A/Mesh at frame 4: point 0"), "{e}");
        let mut two = chunk(1, 3, 1.0);
        let mut second = two.prims[0].clone();
        second.prim = "/B/Mesh".into();
        second.samples.remove(1);
        two.prims.push(second);
        let e = stitch(&names(1), &[two], None).unwrap_err().to_string();
        assert!(e.contains("c0.usdc: not a bake layer: /A/Mesh has a sample at frame 2 that /B/Mesh lacks"), "{e}");
        let mut other = chunk(4, 9, 1.0);
        other.doc = "e".into();
        let e = stitch(&names(2), &[chunk(1, 3, 1.0), other], None).unwrap_err().to_string();
        assert!(e.contains("different bakes"), "{e}");
    }
}
