//! The binary frame form (`application/octet-stream`), documented in
//! `curvenet_schema::wire`: `u32` LE header length, a JSON header listing
//! the arrays, then the arrays as raw little-endian f32.

use curvenet_schema::wire::{BinaryArray, BinaryFrameHeader, BinaryResponseHeader, FrameRequest};

use utoipa::ToSchema;

use crate::bounded::BatchError;
use crate::error::{Code, ServiceError};
use crate::frame::Solved;

/// A binary frame body (`application/octet-stream`): u32 LE header length,
/// a JSON header (`BinaryFrameHeader`, or `{"frames": [...]}` for a batch;
/// `BinaryResponseHeader` in answers), then the listed arrays as raw
/// little-endian f32.
#[derive(ToSchema)]
#[schema(value_type = String, format = Binary)]
#[allow(dead_code)]
pub struct BinaryFrames(Vec<u8>);

pub const CONTENT_TYPE: &str = "application/octet-stream";

fn malformed(message: impl Into<String>) -> ServiceError {
    ServiceError::new(Code::MalformedBinary, message)
}

/// Splits a binary body into its JSON header (bytes) and the data after it.
fn split(body: &[u8]) -> Result<(&[u8], &[u8]), ServiceError> {
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
    Ok((&body[4..4 + h], &body[4 + h..]))
}

/// What a binding expects of a frame's arrays. Every array a header lists
/// is checked against it before anything sized by the header is allocated,
/// so a header naming a huge index or shape costs nothing.
#[derive(Debug, Clone, Copy)]
pub struct Expected<'a> {
    /// Control points of each curvenet's pool (its length: the curvenets).
    pub pools: &'a [usize],
    pub vertices: usize,
    pub blend_shapes: usize,
    /// Joints of the binding's skin (`None`: no skin).
    pub joints: Option<usize>,
    /// Vertices of the binding's cage (`None`: no cage).
    pub cage: Option<usize>,
    /// Most frames a batch may hold (see `bounded`).
    pub max_frames: usize,
}

/// Parses a binary frame request: one frame, or `{"frames": [...]}` (then
/// `batch` is true). The framing, the header and every array's name, index
/// and shape (against `expected`) are checked before any array is decoded;
/// values (finiteness) are checked by `frame::validate`. A curvenet without
/// a `posed` array is not articulated.
pub fn parse(body: &[u8], expected: &Expected<'_>) -> Result<(Vec<FrameRequest>, bool), ServiceError> {
    let (header, mut data) = split(body)?;
    // Typed straight from the bytes (a generic JSON value costs tens of bytes
    // per byte of header), a batch's frames counted as they come.
    let (headers, batch): (Vec<BinaryFrameHeader>, bool) = match crate::bounded::frames(header, expected.max_frames) {
        Ok(h) => (h, true),
        Err(BatchError::NotBatch) => {
            (vec![serde_json::from_slice(header).map_err(|e| malformed(format!("the header: {e}")))?], false)
        }
        Err(BatchError::TooMany(max)) => return Err(crate::bounded::too_many(max, expected.vertices)),
        Err(BatchError::Malformed(e)) => {
            // A single frame's header is not an object starting with "frames".
            match serde_json::from_slice::<BinaryFrameHeader>(header) {
                Ok(h) => (vec![h], false),
                Err(_) => return Err(malformed(format!("the header: {e}"))),
            }
        }
    };
    // Plan every array of every frame first: (frame, array, rows, width).
    let mut plans: Vec<Vec<Planned>> = Vec::with_capacity(headers.len());
    let mut total_bytes = 0usize;
    for (f, h) in headers.iter().enumerate() {
        let ctx = |e: ServiceError| if batch { e.in_frame(f) } else { e };
        let plan = plan_frame(h, expected).map_err(ctx)?;
        total_bytes += plan.iter().map(|p| p.rows * p.kind.width() * 4).sum::<usize>();
        plans.push(plan);
    }
    if total_bytes != data.len() {
        let (f, a, p) = first_short(&plans, data.len());
        return Err(match p {
            Some(p) => {
                let m = format!(
                    "arrays[{a}] ({}) of shape [{}{}] needs {} bytes but only {} remain",
                    p.kind.name(),
                    p.rows,
                    match p.kind.width() {
                        1 => String::new(),
                        w => format!(", {w}"),
                    },
                    p.rows * p.kind.width() * 4,
                    p.remaining
                );
                malformed(if batch { format!("frames[{f}]: {m}") } else { m })
            }
            None => malformed(format!("{} bytes follow the last array the header lists", data.len() - total_bytes)),
        });
    }
    let mut frames = Vec::with_capacity(headers.len());
    for (h, plan) in headers.into_iter().zip(plans) {
        // Every field of the header named, so one added to it cannot be
        // left out of the frame: the header is the frame without its arrays.
        let BinaryFrameHeader { arrays: _, blend_shape_mode, gradients, topology_hash, adjustments, orientations } = h;
        let mut frame = FrameRequest {
            blend_shape_mode,
            gradients,
            topology_hash,
            adjustments,
            orientations,
            ..FrameRequest::default()
        };
        for p in plan {
            let (raw, rest) = data.split_at(p.rows * p.kind.width() * 4);
            data = rest;
            match p.kind {
                Kind::Posed(k) => {
                    frame.posed.get_or_insert_with(|| vec![None; expected.pools.len()])[k] = Some(points(raw));
                }
                Kind::Rest => frame.rest = Some(points(raw)),
                Kind::RestCage => frame.rest_cage = Some(points(raw)),
                Kind::PosedCageOffsets => frame.posed_cage_offsets = Some(points(raw)),
                Kind::Weights => {
                    frame.blend_shape_weights =
                        Some(raw.chunks_exact(4).map(|c| f32::from_le_bytes([c[0], c[1], c[2], c[3]]) as f64).collect())
                }
                Kind::Joints => {
                    frame.joint_transforms = Some(
                        raw.chunks_exact(64)
                            .map(|m| {
                                std::array::from_fn(|i| {
                                    f32::from_le_bytes([m[4 * i], m[4 * i + 1], m[4 * i + 2], m[4 * i + 3]]) as f64
                                })
                            })
                            .collect(),
                    )
                }
            }
        }
        frames.push(frame);
    }
    Ok((frames, batch))
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Kind {
    Posed(usize),
    Rest,
    Weights,
    Joints,
    RestCage,
    PosedCageOffsets,
}

impl Kind {
    fn width(self) -> usize {
        match self {
            Kind::Posed(_) | Kind::Rest | Kind::RestCage | Kind::PosedCageOffsets => 3,
            Kind::Weights => 1,
            Kind::Joints => 16,
        }
    }
    fn name(self) -> &'static str {
        match self {
            Kind::Posed(_) => "posed",
            Kind::Rest => "rest",
            Kind::Weights => "blend_shape_weights",
            Kind::Joints => "joint_transforms",
            Kind::RestCage => "rest_cage",
            Kind::PosedCageOffsets => "posed_cage_offsets",
        }
    }
}

/// One array of a frame, checked against the binding: its rows are the
/// binding's own count, so its size is bounded by the binding, not the header.
#[derive(Debug, Clone, Copy)]
struct Planned {
    kind: Kind,
    rows: usize,
}

/// Checks one frame header's arrays against the binding, in order.
fn plan_frame(h: &BinaryFrameHeader, expected: &Expected<'_>) -> Result<Vec<Planned>, ServiceError> {
    let mut plan: Vec<Planned> = Vec::with_capacity(h.arrays.len().min(expected.pools.len() + 2));
    for (a, array) in h.arrays.iter().enumerate() {
        if !matches!(array.dtype.as_str(), "f32" | "float32" | "<f4") {
            return Err(malformed(format!(
                "arrays[{a}] ({}) has dtype {:?}; only little-endian f32 is accepted",
                array.name, array.dtype
            )));
        }
        let kind = match array.name.as_str() {
            "posed" => {
                let k =
                    array.index.ok_or_else(|| malformed(format!("arrays[{a}] (posed) has no index (the curvenet)")))?;
                if k as usize >= expected.pools.len() {
                    return Err(ServiceError::new(
                        Code::IndexOutOfRange,
                        format!(
                            "arrays[{a}]: posed index {k} refers to a curvenet, but the binding has {}",
                            expected.pools.len()
                        ),
                    ));
                }
                Kind::Posed(k as usize)
            }
            "rest" => Kind::Rest,
            "blend_shape_weights" => Kind::Weights,
            "joint_transforms" => Kind::Joints,
            "rest_cage" => Kind::RestCage,
            "posed_cage_offsets" => Kind::PosedCageOffsets,
            other => {
                return Err(malformed(format!(
                    "arrays[{a}] is named {other:?}; expected posed (with index), rest, blend_shape_weights, \
                     joint_transforms, rest_cage or posed_cage_offsets"
                )));
            }
        };
        if plan.iter().any(|p| p.kind == kind) {
            return Err(malformed(match kind {
                Kind::Posed(k) => format!("arrays[{a}]: posed index {k} appears twice"),
                other => format!("arrays[{a}]: {} appears twice", other.name()),
            }));
        }
        let rows = match (kind.width(), array.shape.as_slice()) {
            (3, &[n, 3]) | (1, &[n]) | (16, &[n, 16]) => n,
            _ => {
                let what = match kind.width() {
                    3 => "[n, 3]",
                    16 => "[j, 16]",
                    _ => "[k]",
                };
                return Err(malformed(format!(
                    "arrays[{a}] ({}) has shape {:?}; expected {what}",
                    array.name, array.shape
                )));
            }
        };
        let (want, message) = match kind {
            Kind::Posed(k) => (
                expected.pools[k],
                format!("posed[{k}] has {rows} control points, but curvenet {k}'s pool has {}", expected.pools[k]),
            ),
            Kind::Rest => {
                (expected.vertices, format!("rest has {rows} points, but the mesh has {} vertices", expected.vertices))
            }
            Kind::Joints => {
                let Some(joints) = expected.joints else {
                    return Err(ServiceError::new(
                        Code::Unsupported,
                        format!("arrays[{a}]: joint_transforms, but the binding has no skin"),
                    )
                    .detail(|d| d.what = Some("joint_transforms".into())));
                };
                (joints, format!("joint_transforms has {rows} transforms, but the binding's skin has {joints} joints"))
            }
            Kind::RestCage | Kind::PosedCageOffsets => {
                let name = kind.name();
                let Some(cage) = expected.cage else {
                    return Err(ServiceError::new(
                        Code::Unsupported,
                        format!("arrays[{a}]: {name}, but the binding has no cage"),
                    )
                    .detail(|d| d.what = Some(name.into())));
                };
                (cage, format!("{name} has {rows} points, but the binding's cage has {cage} vertices"))
            }
            Kind::Weights => (
                expected.blend_shapes,
                format!(
                    "blend_shape_weights has {rows} weights, but the binding has {} blend shapes",
                    expected.blend_shapes
                ),
            ),
        };
        if rows != want as u64 {
            let name = kind.name();
            return Err(ServiceError::new(Code::CountMismatch, format!("arrays[{a}]: {message}")).detail(|d| {
                d.what = Some(name.into());
                d.expected = Some(want);
                d.got = usize::try_from(rows).ok();
                // As the JSON form's: a pool's mismatch names its curvenet.
                if let Kind::Posed(k) = kind {
                    d.curvenet = Some(k as u32);
                }
            }));
        }
        plan.push(Planned { kind, rows: want });
    }
    Ok(plan)
}

/// The first planned array that does not fit in `available` data bytes:
/// (frame, array, the array and what remained for it).
fn first_short(plans: &[Vec<Planned>], available: usize) -> (usize, usize, Option<Short>) {
    let mut remaining = available;
    for (f, plan) in plans.iter().enumerate() {
        for (a, p) in plan.iter().enumerate() {
            let need = p.rows * p.kind.width() * 4;
            if need > remaining {
                return (f, a, Some(Short { kind: p.kind, rows: p.rows, remaining }));
            }
            remaining -= need;
        }
    }
    (0, 0, None)
}

struct Short {
    kind: Kind,
    rows: usize,
    remaining: usize,
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
    BinaryResponseHeader { arrays, solve_ms: s.solve_ms, knot_orientations: s.knot_orientations.clone() }
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
                out.extend_from_slice(&x.to_le_bytes());
            }
        }
        if let Some(g) = &s.gradients {
            for m in g {
                for x in m {
                    out.extend_from_slice(&x.to_le_bytes());
                }
            }
        }
    }
    out
}
