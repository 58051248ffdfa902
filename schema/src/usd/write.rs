//! Writing the bake output (schema/README.md, "Bake output"): a layer of
//! `over` opinions carrying the deformed `points` time samples of each mesh at
//! its composed path, meant to be sublayered above the input. The same layer
//! is read back by [`read_points_overrides`] (for `curvenet stitch`), which
//! refuses anything the writer would not have written.
//!
//! ```no_run
//! use curvenet_schema::usd::{PrimPoints, write_points_overrides};
//! let mesh = PrimPoints {
//!     prim: "/Hand/Mesh".into(),
//!     samples: vec![(1.0, vec![[0.0, 0.0, 0.0]; 3]), (2.0, vec![[0.0, 0.1, 0.0]; 3])],
//! };
//! write_points_overrides("bake.usdc".as_ref(), vec![mesh], (1.0, 2.0), "curvenet bake of shot.usda")?;
//! # Ok::<(), curvenet_schema::usd::WriteError>(())
//! ```
//!
//! The file is written whole or not at all: the layer is serialised into a
//! temporary file beside the output, synced to disk and renamed over it; on
//! any failure the temporary file is removed and the output is untouched.
//! The same input writes the same bytes. A writer killed mid-write leaves
//! its temporary file; the next write of the same output removes it (see
//! [`remove_stale_temporaries`]).

use std::fs::File;
use std::io::{BufWriter, Write as _};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};

use openusd::gf;
use openusd::sdf::{self, AbstractData as _, Value};

const POINTS: &str = "points";

/// One prim's `point3f[] points` time samples: `(time code, one point per vertex)`.
#[derive(Debug, Clone, PartialEq)]
pub struct PrimPoints {
    /// The prim's absolute path, e.g. `/Hand/Mesh`.
    pub prim: String,
    pub samples: Vec<(f64, Vec<[f32; 3]>)>,
}

/// The file format of a layer, chosen by the file's extension.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum LayerFormat {
    /// `.usda`: text.
    Usda,
    /// `.usdc`: the binary crate format.
    Usdc,
}

impl LayerFormat {
    /// `.usda` or `.usdc` (case-insensitive); any other extension is
    /// [`WriteError::Extension`].
    pub fn from_path(path: &Path) -> Result<Self, WriteError> {
        match path.extension().and_then(|e| e.to_str()).map(str::to_ascii_lowercase).as_deref() {
            Some("usda") => Ok(Self::Usda),
            Some("usdc") => Ok(Self::Usdc),
            _ => Err(WriteError::Extension { path: path.display().to_string() }),
        }
    }

    pub(super) fn id(self) -> &'static str {
        match self {
            Self::Usda => "usda",
            Self::Usdc => "usdc",
        }
    }
}

/// Why a layer could not be written.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum WriteError {
    /// The output's extension is neither `.usda` nor `.usdc`.
    #[error("{path}: the output must end in .usda or .usdc")]
    Extension { path: String },
    /// A prim path or sample the layer cannot hold (a bad path, a
    /// non-finite time, a time given twice).
    #[error("{prim}: {problem}")]
    Content { prim: String, problem: String },
    /// The USD writer failed (a bug, not bad input).
    #[error("cannot encode the layer as {format}: {message}")]
    Encode { format: &'static str, message: String },
    /// Creating, writing, syncing or renaming a file failed: worth retrying.
    #[error("{what} {path}: {source}")]
    Io { what: &'static str, path: String, source: std::io::Error },
}

impl WriteError {
    /// Whether the failure is the file system's (the same call may succeed
    /// later), not the content's.
    pub fn is_io(&self) -> bool {
        matches!(self, Self::Io { .. })
    }
}

/// Builds the layer: `over` specs for every prim and its ancestors, one
/// `point3f[] points` attribute with the given time samples per prim, and the
/// layer metadata `doc`, `startTimeCode` and `endTimeCode`. Prims are
/// authored in the order given; samples are sorted by time.
fn points_overrides_data(prims: Vec<PrimPoints>, time_range: (f64, f64), doc: &str) -> Result<sdf::Data, WriteError> {
    let mut data = sdf::Data::new();
    let root = sdf::Path::abs_root();
    data.create_spec(root.clone(), sdf::SpecType::PseudoRoot);
    data.set_field(&root, sdf::FieldKey::Documentation.as_str(), Value::String(doc.to_string()));
    data.set_field(&root, sdf::FieldKey::StartTimeCode.as_str(), Value::Double(time_range.0));
    data.set_field(&root, sdf::FieldKey::EndTimeCode.as_str(), Value::Double(time_range.1));
    for PrimPoints { prim, mut samples } in prims {
        let content = |problem: String| WriteError::Content { prim: prim.clone(), problem };
        if let Some((t, _)) = samples.iter().find(|(t, _)| !t.is_finite()) {
            return Err(content(format!("time code {t} is not finite")));
        }
        samples.sort_by(|a, b| a.0.total_cmp(&b.0));
        if let Some(w) = samples.windows(2).find(|w| w[0].0 == w[1].0) {
            return Err(content(format!("two samples at time code {}", w[0].0)));
        }
        // `over` specs for the prim and every ancestor (never `def`: the
        // layer only overrides what the input defines).
        sdf::PrimSpec::over(&mut data, prim.as_str()).map_err(|e| content(format!("cannot author an over: {e}")))?;
        let attr_path = format!("{prim}.{POINTS}");
        sdf::AttributeSpecMut::new(&mut data, attr_path.as_str(), "point3f[]", sdf::Variability::Varying, false)
            .map_err(|e| content(format!("cannot author {POINTS}: {e}")))?;
        // The whole sample map in one field write (the spec API's per-sample
        // upsert copies the map every time). Each frame's points are
        // converted and released in turn, so the peak is one extra frame.
        let map: sdf::TimeSampleMap = samples
            .into_iter()
            .map(|(t, points)| (t, Value::Vec3fVec(points.into_iter().map(gf::Vec3f::from).collect())))
            .collect();
        let attr_path = sdf::try_into_path(attr_path.as_str()).map_err(|e| content(e.to_string()))?;
        data.set_field(&attr_path, sdf::FieldKey::TimeSamples.as_str(), Value::TimeSamples(map));
    }
    Ok(data)
}

/// The layer of [`write_points_overrides`], serialised in memory.
pub fn encode_points_overrides(
    prims: Vec<PrimPoints>,
    time_range: (f64, f64),
    doc: &str,
    format: LayerFormat,
) -> Result<Vec<u8>, WriteError> {
    let data = points_overrides_data(prims, time_range, doc)?;
    let mut buf = std::io::Cursor::new(Vec::new());
    encode_layer(&data, format, &mut buf)?;
    Ok(buf.into_inner())
}

/// Serialises `data` in `format` into `sink`.
pub(super) fn encode_layer(
    data: &sdf::Data,
    format: LayerFormat,
    sink: &mut dyn sdf::WriteSeek,
) -> Result<(), WriteError> {
    let encoder = sdf::LayerRegistry::find_by_id(format.id())
        .ok_or(WriteError::Encode { format: format.id(), message: "the format is not registered".into() })?;
    encoder.write(data, sink).map_err(|e| match e {
        sdf::FormatError::Io(source) => WriteError::Io { what: "cannot write", path: String::new(), source },
        e => WriteError::Encode { format: format.id(), message: e.to_string() },
    })
}

/// Writes the points overrides of `prims` to `path` (`.usda` or `.usdc` by its
/// extension; see [`points_overrides_data`]), atomically: a temporary file in
/// the same directory, synced, then renamed over `path`. Nothing is left
/// behind on failure.
pub fn write_points_overrides(
    path: &Path,
    prims: Vec<PrimPoints>,
    time_range: (f64, f64),
    doc: &str,
) -> Result<(), WriteError> {
    let format = LayerFormat::from_path(path)?;
    let data = points_overrides_data(prims, time_range, doc)?;
    write_atomically(path, |file| encode_layer(&data, format, file))
}

/// Runs `write` on a fresh temporary file beside `path`, syncs it and renames
/// it over `path`; on any failure removes the temporary file.
pub(super) fn write_atomically(
    path: &Path,
    write: impl FnOnce(&mut BufWriter<File>) -> Result<(), WriteError>,
) -> Result<(), WriteError> {
    let io = |what: &'static str, p: &Path| {
        let p = p.display().to_string();
        move |source| WriteError::Io { what, path: p, source }
    };
    remove_stale_temporaries(path);
    let temp = temp_path(path);
    let file = File::options().write(true).create_new(true).open(&temp).map_err(io("cannot create", &temp))?;
    let guard = RemoveOnDrop(Some(temp.clone()));
    let mut out = BufWriter::new(file);
    write(&mut out).map_err(|e| match e {
        WriteError::Io { what, source, .. } => WriteError::Io { what, path: temp.display().to_string(), source },
        e => e,
    })?;
    out.flush().map_err(io("cannot write", &temp))?;
    let file = out.into_inner().map_err(|e| io("cannot write", &temp)(e.into_error()))?;
    file.sync_all().map_err(io("cannot sync", &temp))?;
    drop(file);
    std::fs::rename(&temp, path).map_err(io("cannot rename the temporary file over", path))?;
    std::mem::forget(guard);
    // Make the rename itself durable. Not every file system can sync a
    // directory; the file is in place either way.
    if let Ok(dir) = File::open(parent_dir(path)) {
        let _ = dir.sync_all();
    }
    Ok(())
}

/// The directory holding `path` (`.` for a bare file name).
fn parent_dir(path: &Path) -> &Path {
    match path.parent() {
        Some(p) if !p.as_os_str().is_empty() => p,
        _ => Path::new("."),
    }
}

/// `DIR/.NAME.tmp-HOST-PID-N-RANDOM`: unique per process (counter) and
/// across processes, also on different hosts writing to shared storage (the
/// host name, the pid and 64 random bits from the OS-seeded `RandomState`),
/// hidden (so a farm's glob of finished chunks skips it), and in the
/// output's directory so the rename stays on one file system. Created with
/// `create_new`, so a clash fails (as I/O, worth retrying) instead of
/// sharing a file.
fn temp_path(path: &Path) -> PathBuf {
    use std::hash::{BuildHasher as _, Hasher as _};
    static COUNTER: AtomicU64 = AtomicU64::new(0);
    let n = COUNTER.fetch_add(1, Ordering::Relaxed);
    let mut random = std::hash::RandomState::new().build_hasher();
    random.write_u64(n);
    parent_dir(path).join(format!(
        "{}{}-{}-{n}-{:016x}",
        temp_prefix(path),
        host_name(),
        std::process::id(),
        random.finish()
    ))
}

/// `.NAME.tmp-`: what every temporary file of output `path` starts with.
/// NAME is cut to its first [`TEMP_NAME_BYTES`] bytes (at a character
/// boundary), so that a legal output name of up to 255 bytes still has a
/// temporary name within the file system's 255 (the host, pid, counter and
/// random parts add at most 119). Outputs sharing those bytes share the
/// prefix; that only lets one's stale-temporary sweep see the other's dead
/// writers' files, which it may remove as well.
fn temp_prefix(path: &Path) -> String {
    let name = path.file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_else(|| "layer".into());
    let mut end = name.len().min(TEMP_NAME_BYTES);
    while !name.is_char_boundary(end) {
        end -= 1;
    }
    format!(".{}.tmp-", &name[..end])
}

/// How much of the output's name its temporary file's name keeps.
const TEMP_NAME_BYTES: usize = 128;

/// This host's name, made safe for a file name (letters, digits, `.`, `_`; at most 64 bytes).
fn host_name() -> String {
    let raw = std::fs::read_to_string("/proc/sys/kernel/hostname")
        .or_else(|_| std::fs::read_to_string("/etc/hostname"))
        .unwrap_or_default();
    let name: String = raw
        .trim()
        .chars()
        .map(|c| if c.is_ascii_alphanumeric() || c == '.' || c == '_' { c } else { '_' })
        .take(64)
        .collect();
    if name.is_empty() { "host".into() } else { name }
}

/// A temporary file untouched this long is stale whoever wrote it (a write
/// takes seconds; this also covers writers on other hosts of shared storage).
pub const STALE_TEMPORARY_AGE: std::time::Duration = std::time::Duration::from_secs(3600);

/// Removes the temporary files a killed writer of `path` left beside it:
/// those written on this host by a process that no longer exists (checked
/// in `/proc`), and any not modified for [`STALE_TEMPORARY_AGE`]. A live
/// writer's file — this host's, or another host's recent one — is kept.
/// Best effort: failures are ignored (the write itself reports what matters).
pub fn remove_stale_temporaries(path: &Path) {
    let prefix = temp_prefix(path);
    let Ok(entries) = std::fs::read_dir(parent_dir(path)) else { return };
    let host = host_name();
    let proc_fs = Path::new("/proc/self").exists();
    for entry in entries.flatten() {
        let file_name = entry.file_name();
        let Some(rest) = file_name.to_str().and_then(|n| n.strip_prefix(&prefix)) else { continue };
        // HOST-PID-N-RANDOM, the host possibly holding '-' in files of old versions: parse from the right.
        let parts: Vec<&str> = rest.rsplitn(4, '-').collect();
        let dead_here = match parts.as_slice() {
            [_, _, pid, writer] => {
                proc_fs
                    && *writer == host
                    && pid
                        .parse::<u32>()
                        .is_ok_and(|p| p != std::process::id() && !Path::new(&format!("/proc/{p}")).exists())
            }
            _ => false,
        };
        let old = entry
            .metadata()
            .and_then(|m| m.modified())
            .is_ok_and(|t| t.elapsed().is_ok_and(|age| age > STALE_TEMPORARY_AGE));
        if dead_here || old {
            let _ = std::fs::remove_file(entry.path());
        }
    }
}

struct RemoveOnDrop(Option<PathBuf>);

impl Drop for RemoveOnDrop {
    fn drop(&mut self) {
        if let Some(p) = self.0.take() {
            let _ = std::fs::remove_file(p);
        }
    }
}

/// A bake layer read back: the arguments [`write_points_overrides`] was
/// given, so writing them again writes the same bytes.
#[derive(Debug, Clone, PartialEq)]
pub struct PointsOverrides {
    /// Prims with `points` samples in the layer's namespace order (depth
    /// first, children in authored order), samples sorted by time, every
    /// sample of a prim holding the same number of points.
    pub prims: Vec<PrimPoints>,
    /// The layer's `startTimeCode` and `endTimeCode`.
    pub time_range: (f64, f64),
    /// The layer's `doc` string.
    pub doc: String,
}

/// Why a bake layer could not be read back.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum ReadOverridesError {
    /// Opening or reading the file failed.
    #[error("cannot read {path}: {source}")]
    Io { path: String, source: std::io::Error },
    /// The file is not a USD layer openusd can decode.
    #[error("{path}: cannot decode the layer: {message}")]
    Decode { path: String, message: String },
    /// The layer holds something the bake writer never writes; `spec` is the
    /// offending spec path (`/` for the layer metadata).
    #[error("{path}: not a curvenet bake layer: {spec}: {problem}")]
    NotABake { path: String, spec: String, problem: String },
}

/// Reads a layer written by [`write_points_overrides`] (either format, by
/// its content). Anything else - a `def`, another attribute or field, a
/// sample that is not `point3f[]`, a prim whose samples disagree on the
/// number of points, a sample outside startTimeCode..endTimeCode - is
/// [`ReadOverridesError::NotABake`], naming the spec.
pub fn read_points_overrides(path: &Path) -> Result<PointsOverrides, ReadOverridesError> {
    let name = path.display().to_string();
    let bytes = std::fs::read(path).map_err(|source| ReadOverridesError::Io { path: name.clone(), source })?;
    decode_points_overrides(&name, bytes)
}

/// [`read_points_overrides`] on bytes in hand; `name` names them in errors.
pub fn decode_points_overrides(name: &str, bytes: Vec<u8>) -> Result<PointsOverrides, ReadOverridesError> {
    let layer = sdf::Layer::from_bytes(name, bytes)
        .map_err(|e| ReadOverridesError::Decode { path: name.to_string(), message: e.to_string() })?;
    points_overrides_from_data(name, layer.data())
}

/// The inverse of [`points_overrides_data`], checking every spec and field.
fn points_overrides_from_data(name: &str, data: &dyn sdf::AbstractData) -> Result<PointsOverrides, ReadOverridesError> {
    let not_a_bake = |spec: &sdf::Path, problem: String| ReadOverridesError::NotABake {
        path: name.to_string(),
        spec: spec.as_str().to_string(),
        problem,
    };
    let field = |spec: &sdf::Path, key: &str| {
        data.try_field(spec, key)
            .map_err(|e| not_a_bake(spec, format!("cannot read {key}: {e}")))
            .map(|v| v.map(std::borrow::Cow::into_owned))
    };
    let only_fields = |spec: &sdf::Path, allowed: &[&str]| {
        let fields = data.list_fields(spec).unwrap_or_default();
        match fields.iter().find(|f| !allowed.contains(&f.as_str())) {
            Some(f) => Err(not_a_bake(spec, format!("authors {f}, which a bake never writes"))),
            None => Ok(()),
        }
    };
    let children_key = sdf::ChildrenKey::PrimChildren.as_str();
    let properties_key = sdf::ChildrenKey::PropertyChildren.as_str();
    let names = |spec: &sdf::Path, key: &str| -> Result<Vec<String>, ReadOverridesError> {
        match field(spec, key)? {
            None => Ok(Vec::new()),
            Some(Value::TokenVec(v)) => Ok(v.iter().map(|t| t.as_str().to_string()).collect()),
            Some(v) => Err(not_a_bake(spec, format!("{key} is {v:?}, not a token list"))),
        }
    };

    // The layer metadata.
    let root = sdf::Path::abs_root();
    let doc_key = sdf::FieldKey::Documentation.as_str();
    let start_key = sdf::FieldKey::StartTimeCode.as_str();
    let end_key = sdf::FieldKey::EndTimeCode.as_str();
    if data.spec_type(&root) != Some(sdf::SpecType::PseudoRoot) {
        return Err(not_a_bake(&root, "the layer has no pseudo-root".into()));
    }
    only_fields(&root, &[doc_key, start_key, end_key, children_key])?;
    let doc = match field(&root, doc_key)? {
        Some(Value::String(s)) => s,
        Some(v) => return Err(not_a_bake(&root, format!("doc is {v:?}, not a string"))),
        None => return Err(not_a_bake(&root, "no doc string (a bake always writes one)".into())),
    };
    let time = |key: &str| match field(&root, key)? {
        Some(Value::Double(t)) if t.is_finite() => Ok(t),
        Some(v) => Err(not_a_bake(&root, format!("{key} is {v:?}, not a finite time code"))),
        None => Err(not_a_bake(&root, format!("no {key} (a bake always writes one)"))),
    };
    let time_range = (time(start_key)?, time(end_key)?);
    if !(time_range.0 <= time_range.1) {
        return Err(not_a_bake(&root, format!("startTimeCode {} is after endTimeCode {}", time_range.0, time_range.1)));
    }

    // Every spec: prims (over) and their `points` attributes, nothing else.
    let mut points_attrs = 0usize;
    for spec in data.spec_paths() {
        match data.spec_type(&spec) {
            Some(sdf::SpecType::PseudoRoot) => {}
            Some(sdf::SpecType::Prim) => {
                only_fields(&spec, &[sdf::FieldKey::Specifier.as_str(), children_key, properties_key])?;
                match field(&spec, sdf::FieldKey::Specifier.as_str())? {
                    // Absent is Sdf's fallback, `over`: usd-core's crate writer omits it.
                    Some(Value::Specifier(sdf::Specifier::Over)) | None => {}
                    Some(v) => {
                        return Err(not_a_bake(&spec, format!("specifier {v:?}: a bake holds over opinions only")));
                    }
                }
            }
            Some(sdf::SpecType::Attribute) if spec.split_property().is_some_and(|(_, name)| name == POINTS) => {
                points_attrs += 1
            }
            Some(sdf::SpecType::Attribute) => {
                let attr = spec.split_property().map_or("", |(_, name)| name);
                return Err(not_a_bake(&spec, format!("attribute {attr}: a bake writes {POINTS} only")));
            }
            other => {
                return Err(not_a_bake(&spec, format!("a {other:?} spec: a bake holds prims and their points only")));
            }
        }
    }

    // The prims in namespace order, and each one's points samples.
    let mut prims = Vec::new();
    let mut reached = 0usize;
    let mut stack = vec![root.clone()];
    while let Some(parent) = stack.pop() {
        let children = names(&parent, children_key)?;
        for child in children.iter().rev() {
            let path = parent
                .append_path(child.as_str())
                .map_err(|e| not_a_bake(&parent, format!("child {child:?} is not a prim name: {e}")))?;
            if data.spec_type(&path) != Some(sdf::SpecType::Prim) {
                return Err(not_a_bake(&path, "listed as a child but has no prim spec".into()));
            }
            stack.push(path);
        }
        if parent.is_abs_root() {
            continue;
        }
        reached += 1;
        let properties = names(&parent, properties_key)?;
        match properties.as_slice() {
            [] if children.is_empty() => {
                return Err(not_a_bake(&parent, "an over with neither points nor children".into()));
            }
            [] => {}
            [p] if p == POINTS => prims.push(read_points(name, data, &parent, time_range)?),
            _ => return Err(not_a_bake(&parent, format!("properties {properties:?}: a bake writes {POINTS} only"))),
        }
    }
    let prim_specs = data.spec_paths().iter().filter(|p| data.spec_type(p) == Some(sdf::SpecType::Prim)).count();
    if reached != prim_specs || points_attrs != prims.len() {
        return Err(not_a_bake(&root, "prim or property specs that no parent lists as children".into()));
    }
    if prims.is_empty() {
        return Err(not_a_bake(&root, format!("no prim with {POINTS} samples")));
    }
    Ok(PointsOverrides { prims, time_range, doc })
}

/// One prim's `points` attribute as the writer authors it.
fn read_points(
    name: &str,
    data: &dyn sdf::AbstractData,
    prim: &sdf::Path,
    range: (f64, f64),
) -> Result<PrimPoints, ReadOverridesError> {
    let attr = prim.append_property(POINTS).map_err(|e| ReadOverridesError::NotABake {
        path: name.to_string(),
        spec: prim.as_str().to_string(),
        problem: e.to_string(),
    })?;
    let not_a_bake = |problem: String| ReadOverridesError::NotABake {
        path: name.to_string(),
        spec: attr.as_str().to_string(),
        problem,
    };
    if data.spec_type(&attr) != Some(sdf::SpecType::Attribute) {
        return Err(not_a_bake("listed as a property but has no attribute spec".into()));
    }
    let keys = [
        sdf::FieldKey::TypeName.as_str(),
        sdf::FieldKey::Variability.as_str(),
        sdf::FieldKey::Custom.as_str(),
        sdf::FieldKey::TimeSamples.as_str(),
    ];
    if let Some(f) = data.list_fields(&attr).unwrap_or_default().iter().find(|f| !keys.contains(&f.as_str())) {
        return Err(not_a_bake(format!("authors {f}, which a bake never writes")));
    }
    let field = |key: &str| {
        data.try_field(&attr, key)
            .map_err(|e| not_a_bake(format!("cannot read {key}: {e}")))
            .map(|v| v.map(std::borrow::Cow::into_owned))
    };
    match field(keys[0])? {
        Some(Value::Token(t)) if t.as_str() == "point3f[]" => {}
        other => return Err(not_a_bake(format!("type {other:?}, not point3f[]"))),
    }
    if let Some(v) = field(keys[1])?
        && v != Value::Variability(sdf::Variability::Varying)
    {
        return Err(not_a_bake(format!("variability {v:?}, not varying")));
    }
    if let Some(v) = field(keys[2])?
        && v != Value::Bool(false)
    {
        return Err(not_a_bake(format!("custom is {v:?}")));
    }
    let map = match field(keys[3])? {
        Some(Value::TimeSamples(map)) => map,
        Some(v) => return Err(not_a_bake(format!("timeSamples is {v:?}"))),
        None => return Err(not_a_bake("no time samples".into())),
    };
    let mut samples: Vec<(f64, Vec<[f32; 3]>)> = Vec::with_capacity(map.len());
    for (t, value) in map {
        if !(t >= range.0 && t <= range.1) {
            return Err(not_a_bake(format!(
                "a sample at time code {t}, outside startTimeCode..endTimeCode {}..{}",
                range.0, range.1
            )));
        }
        let Value::Vec3fVec(points) = value else {
            return Err(not_a_bake(format!("the sample at time code {t} is not point3f[]")));
        };
        samples.push((t, points.into_iter().map(<[f32; 3]>::from).collect()));
    }
    if samples.is_empty() {
        return Err(not_a_bake("no time samples".into()));
    }
    samples.sort_by(|a, b| a.0.total_cmp(&b.0));
    if let Some(w) = samples.windows(2).find(|w| w[0].0 == w[1].0) {
        return Err(not_a_bake(format!("two samples at time code {}", w[0].0)));
    }
    if let Some((t, p)) = samples.iter().find(|(_, p)| p.len() != samples[0].1.len()) {
        return Err(not_a_bake(format!(
            "{} points at time code {t} but {} at time code {}",
            p.len(),
            samples[0].1.len(),
            samples[0].0
        )));
    }
    Ok(PrimPoints { prim: prim.as_str().to_string(), samples })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn temp_dir(tag: &str) -> PathBuf {
        let d = std::env::temp_dir().join(format!("curvenet-write-{tag}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&d);
        std::fs::create_dir_all(&d).unwrap();
        d
    }

    fn prims() -> Vec<PrimPoints> {
        vec![PrimPoints {
            prim: "/A/B/Mesh".into(),
            samples: vec![(2.0, vec![[1.0, 2.0, 3.0], [0.1, 0.2, 0.3]]), (1.0, vec![[0.0; 3], [1e-7, -5.5, 3.25]])],
        }]
    }

    #[test]
    fn usda_holds_only_overs_with_sorted_samples_and_metadata() {
        let bytes = encode_points_overrides(prims(), (1.0, 2.0), "a test", LayerFormat::Usda).unwrap();
        let text = String::from_utf8(bytes).unwrap();
        assert!(text.contains("over \"A\"") && text.contains("over \"B\"") && text.contains("over \"Mesh\""), "{text}");
        assert!(!text.contains("def "), "{text}");
        assert!(text.contains("point3f[] points.timeSamples"), "{text}");
        assert!(text.contains("startTimeCode = 1") && text.contains("endTimeCode = 2"), "{text}");
        assert!(text.contains("a test"), "{text}");
        let at = |key: &str| text.find(key).unwrap_or_else(|| panic!("no {key:?} in {text}"));
        assert!(at("1.0: [") < at("2.0: ["), "{text}");
    }

    #[test]
    fn both_formats_read_back_exactly_and_write_the_same_bytes_twice() {
        let dir = temp_dir("roundtrip");
        for ext in ["usda", "usdc"] {
            let path = dir.join(format!("out.{ext}"));
            write_points_overrides(&path, prims(), (1.0, 2.0), "doc").unwrap();
            let first = std::fs::read(&path).unwrap();
            write_points_overrides(&path, prims(), (1.0, 2.0), "doc").unwrap();
            assert_eq!(first, std::fs::read(&path).unwrap(), "{ext}: not idempotent");
            let layer = sdf::Layer::open(path.to_str().unwrap()).unwrap();
            let attr = layer.attribute("/A/B/Mesh.points").unwrap().expect("points spec");
            let samples = attr.time_samples().unwrap();
            assert_eq!(samples.len(), 2);
            let Value::Vec3fVec(p) = &samples[0].1 else { panic!("{ext}: {:?}", samples[0].1) };
            assert_eq!(samples[0].0, 1.0);
            assert_eq!(<[f32; 3]>::from(p[1]), [1e-7, -5.5, 3.25], "{ext}");
            assert_eq!(layer.prim("/A").unwrap().unwrap().specifier(), Some(sdf::Specifier::Over));
        }
        let names: Vec<_> = std::fs::read_dir(&dir).unwrap().map(|e| e.unwrap().file_name()).collect();
        assert_eq!(names.len(), 2, "temporary files left: {names:?}");
        std::fs::remove_dir_all(&dir).unwrap();
    }

    /// A legal output name of 255 bytes (found by a hostile review: its
    /// temporary file's name had overflowed the file system's 255 bytes).
    #[test]
    fn the_longest_legal_output_name_is_written() {
        let dir = temp_dir("long-name");
        for stem in ["b".repeat(250), "é".repeat(125)] {
            let path = dir.join(format!("{stem}.usda"));
            assert!(path.file_name().unwrap().len() >= 254, "{}", path.display());
            write_points_overrides(&path, prims(), (1.0, 2.0), "").unwrap();
            assert!(path.exists());
            assert!(temp_path(&path).file_name().unwrap().len() <= 255);
        }
        let names: Vec<_> = std::fs::read_dir(&dir).unwrap().map(|e| e.unwrap().file_name()).collect();
        assert_eq!(names.len(), 2, "temporary files left: {names:?}");
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn failures_leave_nothing_behind() {
        let dir = temp_dir("fail");
        assert!(matches!(
            write_points_overrides(&dir.join("out.obj"), prims(), (1.0, 2.0), ""),
            Err(WriteError::Extension { .. })
        ));
        let missing = dir.join("no/such/dir/out.usda");
        let e = write_points_overrides(&missing, prims(), (1.0, 2.0), "").unwrap_err();
        assert!(e.is_io(), "{e}");
        let bad = vec![PrimPoints { prim: "not a path".into(), samples: vec![(1.0, vec![])] }];
        let e = write_points_overrides(&dir.join("out.usda"), bad, (1.0, 1.0), "").unwrap_err();
        assert!(matches!(e, WriteError::Content { .. }), "{e}");
        let e = write_atomically(&dir.join("out.usda"), |_| {
            Err(WriteError::Encode { format: "usda", message: "boom".into() })
        })
        .unwrap_err();
        assert!(!e.is_io());
        assert_eq!(std::fs::read_dir(&dir).unwrap().count(), 0);
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn a_write_removes_the_stale_temporaries_of_its_output_only() {
        let dir = temp_dir("stale");
        let host = host_name();
        // A pid that no longer exists: a child that has exited and been reaped.
        let mut child = std::process::Command::new("true").spawn().unwrap();
        let dead = child.id();
        child.wait().unwrap();
        let touch = |name: &str, age_s: u64| {
            let f = File::create(dir.join(name)).unwrap();
            f.set_modified(std::time::SystemTime::now() - std::time::Duration::from_secs(age_s)).unwrap();
        };
        let dead_here = format!(".out.usda.tmp-{host}-{dead}-0-00000000000000aa");
        let live_here = format!(".out.usda.tmp-{host}-{}-7-00000000000000bb", std::process::id());
        let other_host_recent = format!(".out.usda.tmp-{host}x-{dead}-0-00000000000000cc");
        let other_host_old = format!(".out.usda.tmp-{host}x-{dead}-1-00000000000000dd");
        let other_output = format!(".other.usda.tmp-{host}-{dead}-0-00000000000000ee");
        touch(&dead_here, 0);
        touch(&live_here, 0);
        touch(&other_host_recent, 60);
        touch(&other_host_old, 2 * 3600);
        touch(&other_output, 0);
        write_points_overrides(&dir.join("out.usda"), prims(), (1.0, 2.0), "").unwrap();
        let mut left: Vec<String> =
            std::fs::read_dir(&dir).unwrap().map(|e| e.unwrap().file_name().into_string().unwrap()).collect();
        left.sort();
        let mut want = vec![live_here, other_host_recent, other_output, "out.usda".to_string()];
        want.sort();
        assert_eq!(left, want);
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn layers_read_back_as_written_and_rewrite_to_the_same_bytes() {
        let prims = vec![
            PrimPoints {
                prim: "/B/Mesh".into(),
                samples: vec![(3.0, vec![[1.5, -2.0, 0.25]; 4]), (4.0, vec![[0.0; 3]; 4])],
            },
            PrimPoints {
                prim: "/A/X/Mesh".into(),
                samples: vec![(3.0, vec![[1e-7, 2.0, 3.0]]), (4.0, vec![[f32::MAX, -0.0, 1.0]])],
            },
        ];
        for format in [LayerFormat::Usda, LayerFormat::Usdc] {
            let bytes = encode_points_overrides(prims.clone(), (3.0, 4.0), "a doc \"quoted\"", format).unwrap();
            let read = decode_points_overrides("mem", bytes.clone()).unwrap();
            assert_eq!(read.prims, prims, "{format:?}");
            assert_eq!(read.time_range, (3.0, 4.0));
            assert_eq!(read.doc, "a doc \"quoted\"");
            let again = encode_points_overrides(read.prims, read.time_range, &read.doc, format).unwrap();
            assert!(again == bytes, "{format:?}: the layer read back writes different bytes");
        }
    }

    #[test]
    fn layers_a_bake_never_writes_are_refused_naming_the_spec() {
        let good =
            String::from_utf8(encode_points_overrides(prims(), (1.0, 2.0), "d", LayerFormat::Usda).unwrap()).unwrap();
        let refused = |text: &str, spec: &str, problem: &str| {
            let e = decode_points_overrides("x.usda", text.as_bytes().to_vec()).unwrap_err();
            let ReadOverridesError::NotABake { path, spec: s, problem: p } = &e else { panic!("{e}") };
            assert_eq!((path.as_str(), s.as_str()), ("x.usda", spec), "{e}\n{text}");
            assert!(p.contains(problem), "{e}");
        };
        refused(&good.replacen("over \"Mesh\"", "def Mesh \"Mesh\"", 1), "/A/B/Mesh", "type");
        refused(&good.replacen("over \"B\"", "def \"B\"", 1), "/A/B", "specifier");
        refused(
            &good.replacen("startTimeCode = 1.0", "startTimeCode = 1.0\n    defaultPrim = \"A\"", 1),
            "/",
            "defaultPrim",
        );
        refused(
            &good.replacen("point3f[] points", "float3[] extent = [(0, 0, 0)]\n        point3f[] points", 1),
            "/A/B/Mesh.extent",
            "extent",
        );
        refused(&good.replacen("endTimeCode = 2.0", "endTimeCode = 1.5", 1), "/A/B/Mesh.points", "outside");
        // The sample at 2 loses its first point.
        let at = good.find("2.0: [").expect("a sample at 2") + "2.0: [".len();
        let end = at + good[at..].find("), ").unwrap() + "), ".len();
        refused(&format!("{}{}", &good[..at], &good[end..]), "/A/B/Mesh.points", "1 points at time code 2");
        refused(&good.replacen("point3f[] points", "normal3f[] points", 2), "/A/B/Mesh.points", "not point3f[]");
        let e = decode_points_overrides("y.usda", b"not usd".to_vec()).unwrap_err();
        assert!(matches!(e, ReadOverridesError::Decode { .. }) && e.to_string().starts_with("y.usda: "), "{e}");
        let e = read_points_overrides(Path::new("/no/such/bake.usdc")).unwrap_err();
        assert!(
            matches!(&e, ReadOverridesError::Io { source, .. } if source.kind() == std::io::ErrorKind::NotFound),
            "{e}"
        );
    }
}
