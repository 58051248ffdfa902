//! The stored-binding columns of a bench row (`stored`): the deformer
//! written in the store's format (`curvenet_core::persist`), to a file and
//! read back, against the time `Deformer::new` took in the same run. The
//! goal of the binding store (#36): a load at most 1/5 of a build at 94k and
//! 376k vertices, so that a replica or a farm chunk that finds a binding in
//! the store starts solving in a fraction of the binding time.
//!
//! Measured, medians of `repeats`: `encode_ms` (`Deformer::to_bytes`),
//! `write_ms` (the bytes to a file in the system's temporary directory and
//! `sync_all`), `read_ms` (the file read back into memory: from the page
//! cache, as a replica on the machine that wrote it, or an NFS client with a
//! warm cache, reads it), `decode_ms` (`Deformer::from_bytes`: checks,
//! checksum, copies) and `load_ms` = read + decode. The loaded deformer's
//! first frame is checked to be bit for bit the built one's.

use std::io::Write as _;

use curvenet_core::{Deformer, Frame};
use serde::Serialize;

use super::measure::median;
use crate::cli::{CliError, CliResult};

/// A load at most this share of the build.
pub(super) const LOAD_OVER_BUILD_TARGET: f64 = 0.2;

#[derive(Serialize)]
pub(super) struct StoredBench {
    pub bytes: usize,
    pub encode_ms: f64,
    pub write_ms: f64,
    pub read_ms: f64,
    pub decode_ms: f64,
    pub load_ms: f64,
    /// `Deformer::new`'s wall time in the same run (median).
    pub build_ms: f64,
    pub load_over_build: f64,
    pub target: f64,
    pub met: bool,
}

fn ms(t: std::time::Instant) -> f64 {
    t.elapsed().as_secs_f64() * 1e3
}

/// Writes and reads `deformer` `repeats` times (module docs); `build_ms` is
/// its build time in this run; `posed` a frame to compare the loaded
/// deformer's answer with the built one's.
pub(super) fn measure(
    deformer: &Deformer,
    build_ms: f64,
    repeats: usize,
    posed: &[Option<&[[f64; 3]]>],
) -> CliResult<StoredBench> {
    let io = |context: &str, source| CliError::Io { context: context.to_string(), source };
    let path = std::env::temp_dir().join(format!("curvenet-bench-{}.cnb", std::process::id()));
    let (mut encode, mut write, mut read, mut decode) = (vec![], vec![], vec![], vec![]);
    let mut bytes_len = 0;
    let mut loaded = None;
    for _ in 0..repeats.max(1) {
        let t = std::time::Instant::now();
        let bytes = deformer.to_bytes();
        encode.push(ms(t));
        bytes_len = bytes.len();
        let t = std::time::Instant::now();
        let mut f = std::fs::File::create(&path).map_err(|e| io(&format!("writing {}", path.display()), e))?;
        f.write_all(&bytes).and_then(|()| f.sync_all()).map_err(|e| io(&format!("writing {}", path.display()), e))?;
        write.push(ms(t));
        drop((f, bytes));
        drop(loaded.take());
        let t = std::time::Instant::now();
        let back = std::fs::read(&path).map_err(|e| io(&format!("reading {}", path.display()), e))?;
        read.push(ms(t));
        let t = std::time::Instant::now();
        let d = Deformer::from_bytes(&back)
            .map_err(|e| CliError::Input(format!("the stored binding does not read back: {e}")))?;
        decode.push(ms(t));
        loaded = Some(d);
    }
    let _ = std::fs::remove_file(&path);
    let loaded = loaded.expect("at least one repeat");
    let n = deformer.n_vertices();
    let (mut a, mut b) = (vec![[0.0; 3]; n], vec![[0.0; 3]; n]);
    let frame = Frame { posed, ..Frame::default() };
    let core = |source| CliError::Core { context: "the stored binding's frame".into(), source };
    deformer.frame(&frame, &mut a, None).map_err(core)?;
    loaded.frame(&frame, &mut b, None).map_err(core)?;
    if a.iter().flatten().zip(b.iter().flatten()).any(|(x, y)| x.to_bits() != y.to_bits()) {
        return Err(CliError::Input("the stored binding's frame differs from the built one's".into()));
    }
    let (read_ms, decode_ms) = (median(read.clone()), median(decode.clone()));
    let load_ms = median(read.iter().zip(&decode).map(|(r, d)| r + d).collect());
    let load_over_build = if build_ms > 0.0 { load_ms / build_ms } else { f64::INFINITY };
    Ok(StoredBench {
        bytes: bytes_len,
        encode_ms: median(encode),
        write_ms: median(write),
        read_ms,
        decode_ms,
        load_ms,
        build_ms,
        load_over_build,
        target: LOAD_OVER_BUILD_TARGET,
        met: load_over_build <= LOAD_OVER_BUILD_TARGET,
    })
}
