//! The binary frame form (`application/octet-stream`), documented in
//! `curvenet_schema::wire`: `u32` LE header length, a JSON header listing
//! the arrays, then the arrays as raw little-endian f32.

use curvenet_schema::wire::{BinaryArray, BinaryFrameHeader, BinaryResponseHeader};

use crate::error::{Code, ServiceError};
use crate::frames::{Frame, Solved};

pub const CONTENT_TYPE: &str = "application/octet-stream";

fn malformed(message: impl Into<String>) -> ServiceError {
    ServiceError::new(Code::MalformedBinary, message)
}

/// Splits a binary body into its JSON header and the data after it.
fn split(body: &[u8]) -> Result<(serde_json::Value, &[u8]), ServiceError> {
    if body.len() < 4 {
        return Err(malformed(format!(
            "the body has {} bytes; it must start with a u32 little-endian header length",
            body.len()
        )));
    }
    let h = u32::from_le_bytes([body[0], body[1], body[2], body[3]]) as usize;
    if body.len() - 4 < h {
        return Err(malformed(format!("the header length is {h} bytes but only {} bytes follow it", body.len() - 4)));
    }
    let header =
        serde_json::from_slice(&body[4..4 + h]).map_err(|e| malformed(format!("the header is not JSON: {e}")))?;
    Ok((header, &body[4 + h..]))
}

/// Parses a binary frame request: one frame, or `{"frames": [...]}` (then
/// `batch` is true). Only the framing and the header's own consistency are
/// checked here; counts against the binding are checked by `frames::validate`.
pub fn parse(body: &[u8]) -> Result<(Vec<Frame>, bool), ServiceError> {
    let (header, mut data) = split(body)?;
    let batch = header.get("frames").is_some();
    let headers: Vec<BinaryFrameHeader> = if batch {
        #[derive(serde::Deserialize)]
        #[serde(deny_unknown_fields)]
        struct Batch {
            frames: Vec<BinaryFrameHeader>,
        }
        serde_json::from_value::<Batch>(header).map_err(|e| malformed(format!("the batch header: {e}")))?.frames
    } else {
        vec![serde_json::from_value(header).map_err(|e| malformed(format!("the header: {e}")))?]
    };
    let mut frames = Vec::with_capacity(headers.len());
    for (f, h) in headers.into_iter().enumerate() {
        let ctx = |m: String| if batch { format!("frames[{f}]: {m}") } else { m };
        let mut frame = Frame {
            mode: h.blend_shape_mode,
            gradients: h.gradients,
            topology_hash: h.topology_hash,
            ..Frame::default()
        };
        let mut posed: Vec<(usize, Vec<[f64; 3]>)> = Vec::new();
        for (a, array) in h.arrays.iter().enumerate() {
            if !matches!(array.dtype.as_str(), "f32" | "float32" | "<f4") {
                return Err(malformed(ctx(format!(
                    "arrays[{a}] ({}) has dtype {:?}; only little-endian f32 is accepted",
                    array.name, array.dtype
                ))));
            }
            let (width, what) = match array.name.as_str() {
                "posed" | "rest" => (3, "[n, 3]"),
                "blend_shape_weights" => (1, "[k]"),
                other => {
                    return Err(malformed(ctx(format!(
                        "arrays[{a}] is named {other:?}; expected posed (with index), rest or blend_shape_weights"
                    ))));
                }
            };
            let rows = match (width, array.shape.as_slice()) {
                (3, &[n, 3]) | (1, &[n]) => n,
                _ => {
                    return Err(malformed(ctx(format!(
                        "arrays[{a}] ({}) has shape {:?}; expected {what}",
                        array.name, array.shape
                    ))));
                }
            };
            let bytes = usize::try_from(rows)
                .ok()
                .and_then(|r| r.checked_mul(width * 4))
                .filter(|&b| b <= data.len())
                .ok_or_else(|| {
                    malformed(ctx(format!(
                        "arrays[{a}] ({}) of shape {:?} needs {} bytes but only {} remain",
                        array.name,
                        array.shape,
                        rows.saturating_mul(width as u64 * 4),
                        data.len()
                    )))
                })?;
            let (raw, rest) = data.split_at(bytes);
            data = rest;
            match array.name.as_str() {
                "posed" => {
                    let k = array
                        .index
                        .ok_or_else(|| malformed(ctx(format!("arrays[{a}] (posed) has no index (the curvenet)"))))?
                        as usize;
                    if posed.iter().any(|(j, _)| *j == k) {
                        return Err(malformed(ctx(format!("arrays[{a}]: posed index {k} appears twice"))));
                    }
                    posed.push((k, points(raw)));
                }
                "rest" if frame.rest.is_some() => {
                    return Err(malformed(ctx(format!("arrays[{a}]: rest appears twice"))));
                }
                "rest" => frame.rest = Some(points(raw)),
                _ if frame.weights.is_some() => {
                    return Err(malformed(ctx(format!("arrays[{a}]: blend_shape_weights appears twice"))));
                }
                _ => {
                    frame.weights =
                        Some(raw.chunks_exact(4).map(|c| f32::from_le_bytes([c[0], c[1], c[2], c[3]]) as f64).collect())
                }
            }
        }
        if let Some(max) = posed.iter().map(|(k, _)| *k).max() {
            frame.posed = vec![None; max + 1];
            for (k, p) in posed {
                frame.posed[k] = Some(p);
            }
        }
        frames.push(frame);
    }
    if !data.is_empty() {
        return Err(malformed(format!("{} bytes follow the last array the header lists", data.len())));
    }
    Ok((frames, batch))
}

/// Fits a binary frame's posed pools to the binding's `n_curvenets`: a
/// curvenet without a `posed` array is not articulated; an index past the
/// last curvenet is refused.
pub fn fit_posed(frame: &mut Frame, n_curvenets: usize) -> Result<(), ServiceError> {
    if frame.posed.len() > n_curvenets {
        return Err(ServiceError::new(
            Code::IndexOutOfRange,
            format!("posed index {} refers to a curvenet, but the binding has {n_curvenets}", frame.posed.len() - 1),
        ));
    }
    if !frame.posed.is_empty() {
        frame.posed.resize(n_curvenets, None);
    }
    Ok(())
}

fn points(raw: &[u8]) -> Vec<[f64; 3]> {
    raw.chunks_exact(12)
        .map(|c| {
            let f = |i: usize| f32::from_le_bytes([c[i], c[i + 1], c[i + 2], c[i + 3]]) as f64;
            [f(0), f(4), f(8)]
        })
        .collect()
}

fn response_header(s: &Solved) -> BinaryResponseHeader {
    let mut arrays = vec![BinaryArray {
        name: "points".into(),
        index: None,
        dtype: "f32".into(),
        shape: vec![s.points.len() as u64, 3],
    }];
    if let Some(g) = &s.gradients {
        arrays.push(BinaryArray {
            name: "gradients".into(),
            index: None,
            dtype: "f32".into(),
            shape: vec![g.len() as u64, 9],
        });
    }
    BinaryResponseHeader { arrays, solve_ms: s.solve_ms }
}

/// Encodes solved frames: one frame's header, or `{"frames": [...]}` for a batch.
pub fn encode(solved: &[Solved], batch: bool) -> Vec<u8> {
    let headers: Vec<BinaryResponseHeader> = solved.iter().map(response_header).collect();
    let mut header = if batch {
        serde_json::to_vec(&serde_json::json!({ "frames": headers }))
    } else {
        serde_json::to_vec(&headers[0])
    }
    .expect("the header serialises");
    // Pad with spaces (valid JSON whitespace) so the arrays start 4-byte aligned.
    while header.len() % 4 != 0 {
        header.push(b' ');
    }
    let data: usize =
        solved.iter().map(|s| s.points.len() * 12 + s.gradients.as_ref().map_or(0, |g| g.len() * 36)).sum();
    let mut out = Vec::with_capacity(4 + header.len() + data);
    out.extend_from_slice(&(header.len() as u32).to_le_bytes());
    out.extend_from_slice(&header);
    for s in solved {
        for p in &s.points {
            for x in p {
                out.extend_from_slice(&(*x as f32).to_le_bytes());
            }
        }
        if let Some(g) = &s.gradients {
            for m in g {
                for x in m {
                    out.extend_from_slice(&(*x as f32).to_le_bytes());
                }
            }
        }
    }
    out
}
