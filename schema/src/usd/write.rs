//! Writing the bake output (schema/README.md, "Bake output"): a layer of
//! `over` opinions carrying the deformed `points` time samples of each mesh at
//! its composed path, meant to be sublayered above the input.
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
//! The same input writes the same bytes.

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

    fn id(self) -> &'static str {
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
fn encode_layer(data: &sdf::Data, format: LayerFormat, sink: &mut dyn sdf::WriteSeek) -> Result<(), WriteError> {
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
pub fn write_points_overrides(path: &Path, prims: Vec<PrimPoints>, time_range: (f64, f64), doc: &str) -> Result<(), WriteError> {
    let format = LayerFormat::from_path(path)?;
    let data = points_overrides_data(prims, time_range, doc)?;
    write_atomically(path, |file| encode_layer(&data, format, file))
}

/// Runs `write` on a fresh temporary file beside `path`, syncs it and renames
/// it over `path`; on any failure removes the temporary file.
fn write_atomically(
    path: &Path,
    write: impl FnOnce(&mut BufWriter<File>) -> Result<(), WriteError>,
) -> Result<(), WriteError> {
    let io = |what: &'static str, p: &Path| {
        let p = p.display().to_string();
        move |source| WriteError::Io { what, path: p, source }
    };
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

/// `DIR/.NAME.tmp-PID-N-NANOS`: unique per process (counter) and across
/// processes (pid, clock), hidden, and in the output's directory so the
/// rename stays on one file system.
fn temp_path(path: &Path) -> PathBuf {
    static COUNTER: AtomicU64 = AtomicU64::new(0);
    let n = COUNTER.fetch_add(1, Ordering::Relaxed);
    let nanos = std::time::SystemTime::now().duration_since(std::time::UNIX_EPOCH).map_or(0, |d| d.subsec_nanos());
    let name = path.file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_else(|| "layer".into());
    parent_dir(path).join(format!(".{name}.tmp-{}-{n}-{nanos}", std::process::id()))
}

struct RemoveOnDrop(Option<PathBuf>);

impl Drop for RemoveOnDrop {
    fn drop(&mut self) {
        if let Some(p) = self.0.take() {
            let _ = std::fs::remove_file(p);
        }
    }
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
        let e = write_atomically(&dir.join("out.usda"), |_| Err(WriteError::Encode { format: "usda", message: "boom".into() }))
            .unwrap_err();
        assert!(!e.is_io());
        assert_eq!(std::fs::read_dir(&dir).unwrap().count(), 0);
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
