//! The stored form of a binding: a versioned, checksummed, little-endian
//! byte format, so a binding built once can be written to a shared store
//! and read back by another process in a fraction of its build time.
//!
//! # Format
//!
//! ```text
//! offset  size  field
//!      0     8  magic, b"CURVENET"
//!      8     4  format version, u32 LE (FORMAT_VERSION)
//!     12     4  kind, u32 LE (what the payload holds: KIND_DEFORMER)
//!     16     8  payload length in bytes, u64 LE
//!     24     4  CRC-32 (IEEE, as zlib) of the payload, u32 LE
//!     28     4  zero
//!     32     -  payload
//! ```
//!
//! The payload is the value in [postcard](https://postcard.jamesmunns.com/wire-format)
//! (a documented, stable binary serde format: varint integers, f64 as 8 LE
//! bytes, sequences prefixed by their length), through serde derives on the
//! binding's types. The large numeric arrays (the factor, the face
//! Laplacians, the operators, the halfedges) are written as one byte string
//! each ([`pod`]: the array's little-endian bytes), so reading one is a
//! length check and a copy, not a loop over its elements.
//!
//! Why not a crate with zero-copy reading (rkyv, memory maps): the binding's
//! arrays are owned `Vec`s its solves index directly; borrowing them from a
//! mapped file would change every type the solve reads. One copy at load
//! time costs a few milliseconds per hundred megabytes.
//!
//! A file is refused, with an [`FormatError`] naming why, when it is
//! shorter than its header or its length says, has another magic, version
//! or kind, fails its checksum, or does not decode to a whole value with no
//! bytes left over. Whatever the bytes, decoding never panics: postcard
//! checks every length against the bytes left, and every index the binding
//! reads was checked when it was built (the checksum is what vouches that
//! these are the bytes that binding wrote).
//!
//! Little-endian hosts only (x86-64, aarch64): the numeric arrays are
//! written as the host's bytes.

#[cfg(target_endian = "big")]
compile_error!("curvenet's stored bindings are written as little-endian bytes; big-endian hosts are not supported");

use serde::Serialize;
use serde::de::DeserializeOwned;

/// The first 8 bytes of a stored binding.
pub const MAGIC: [u8; 8] = *b"CURVENET";
/// The version this build writes and the only one it reads. Raised with
/// every change of any stored type (a field added, removed or reordered).
pub const FORMAT_VERSION: u32 = 1;
/// The payload is a whole [`crate::Deformer`].
pub const KIND_DEFORMER: u32 = 1;
/// Bytes of the header before the payload.
pub const HEADER_BYTES: usize = 32;

/// Why stored bytes were refused.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum FormatError {
    #[error("the stored binding is truncated: {got} bytes, {expected} expected (header and payload)")]
    Truncated { expected: u64, got: u64 },
    #[error("the stored binding has {extra} bytes after its payload")]
    Trailing { extra: u64 },
    #[error("not a stored curvenet binding (its first bytes are {found:02x?}, not \"CURVENET\")")]
    Magic { found: Vec<u8> },
    #[error("the stored binding is format version {found}; this build reads version {supported} only")]
    Version { found: u32, supported: u32 },
    #[error("the stored value is of kind {found}, not {expected}")]
    Kind { found: u32, expected: u32 },
    #[error("the stored binding fails its checksum (CRC-32 {found:08x}, header says {expected:08x}): corrupted")]
    Checksum { found: u32, expected: u32 },
    #[error("the stored binding does not decode: {reason}")]
    Decode { reason: String },
}

/// `value` as a stored blob of `kind`: the header, then its payload.
pub fn encode<T: Serialize>(value: &T, kind: u32, size_hint: usize) -> Vec<u8> {
    let mut out = Vec::with_capacity(HEADER_BYTES + size_hint);
    encode_into(value, kind, &mut out);
    out
}

/// [`encode`], appended to `out` (so that an envelope around the blob is
/// written in place, not copied): reserve room first to avoid regrowth.
pub fn encode_into<T: Serialize>(value: &T, kind: u32, out: &mut Vec<u8>) {
    let start = out.len();
    out.resize(start + HEADER_BYTES, 0);
    // Serialising into a Vec cannot fail for these types (no maps with
    // non-string keys, no unsized sequences): postcard's only errors are
    // about writers that run out of room and unsupported serde features.
    *out = postcard::to_extend(value, std::mem::take(out)).expect("postcard serialises every stored type into a Vec");
    let blob = &mut out[start..];
    let payload_len = (blob.len() - HEADER_BYTES) as u64;
    let crc = crc32fast::hash(&blob[HEADER_BYTES..]);
    blob[0..8].copy_from_slice(&MAGIC);
    blob[8..12].copy_from_slice(&FORMAT_VERSION.to_le_bytes());
    blob[12..16].copy_from_slice(&kind.to_le_bytes());
    blob[16..24].copy_from_slice(&payload_len.to_le_bytes());
    blob[24..28].copy_from_slice(&crc.to_le_bytes());
}

/// The value of `kind` stored in `bytes` (as [`encode`] wrote it), after
/// checking its header, length and checksum.
pub fn decode<T: DeserializeOwned>(bytes: &[u8], kind: u32) -> Result<T, FormatError> {
    let payload = check(bytes, kind)?;
    let (value, rest) =
        postcard::take_from_bytes::<T>(payload).map_err(|e| FormatError::Decode { reason: e.to_string() })?;
    if !rest.is_empty() {
        return Err(FormatError::Trailing { extra: rest.len() as u64 });
    }
    Ok(value)
}

/// The payload of `bytes`, checked: header, length and checksum.
fn check(bytes: &[u8], kind: u32) -> Result<&[u8], FormatError> {
    let got = bytes.len() as u64;
    if bytes.len() < 8 || bytes[..8] != MAGIC {
        return Err(FormatError::Magic { found: bytes[..bytes.len().min(8)].to_vec() });
    }
    if bytes.len() < HEADER_BYTES {
        return Err(FormatError::Truncated { expected: HEADER_BYTES as u64, got });
    }
    let u32_at = |at: usize| u32::from_le_bytes(bytes[at..at + 4].try_into().expect("4 bytes"));
    let version = u32_at(8);
    if version != FORMAT_VERSION {
        return Err(FormatError::Version { found: version, supported: FORMAT_VERSION });
    }
    let found_kind = u32_at(12);
    if found_kind != kind {
        return Err(FormatError::Kind { found: found_kind, expected: kind });
    }
    let len = u64::from_le_bytes(bytes[16..24].try_into().expect("8 bytes"));
    let expected = (HEADER_BYTES as u64).saturating_add(len);
    if got < expected {
        return Err(FormatError::Truncated { expected, got });
    }
    if got > expected {
        return Err(FormatError::Trailing { extra: got - expected });
    }
    let payload = &bytes[HEADER_BYTES..];
    let crc = crc32fast::hash(payload);
    let stored = u32_at(24);
    if crc != stored {
        return Err(FormatError::Checksum { found: crc, expected: stored });
    }
    Ok(payload)
}

/// Serde for a `Vec` of plain numbers or arrays of them (`#[serde(with =
/// "crate::persist::pod")]`): one byte string of the elements'
/// little-endian bytes instead of one serde call per element.
pub mod pod {
    use bytemuck::Pod;
    use serde::de::{Error, Visitor};
    use serde::{Deserializer, Serializer};

    pub fn serialize<T: Pod, S: Serializer>(v: &[T], s: S) -> Result<S::Ok, S::Error> {
        s.serialize_bytes(bytemuck::cast_slice(v))
    }

    pub fn deserialize<'de, T: Pod, D: Deserializer<'de>>(d: D) -> Result<Vec<T>, D::Error> {
        d.deserialize_bytes(PodVisitor::<T>(std::marker::PhantomData))
    }

    struct PodVisitor<T>(std::marker::PhantomData<T>);

    impl<T: Pod> Visitor<'_> for PodVisitor<T> {
        type Value = Vec<T>;

        fn expecting(&self, f: &mut std::fmt::Formatter) -> std::fmt::Result {
            write!(f, "a byte string of {}-byte elements", std::mem::size_of::<T>())
        }

        fn visit_bytes<E: Error>(self, bytes: &[u8]) -> Result<Vec<T>, E> {
            let size = std::mem::size_of::<T>();
            if size == 0 || !bytes.len().is_multiple_of(size) {
                return Err(E::custom(format_args!(
                    "{} bytes are not a whole number of {size}-byte elements",
                    bytes.len()
                )));
            }
            let mut v = vec![T::zeroed(); bytes.len() / size];
            bytemuck::cast_slice_mut::<T, u8>(&mut v).copy_from_slice(bytes);
            Ok(v)
        }
    }

    /// The same for an `Option<Vec<_>>`.
    pub mod option {
        use bytemuck::Pod;
        use serde::{Deserialize, Deserializer, Serialize, Serializer};

        #[derive(Serialize)]
        struct Ref<'a, T: Pod>(#[serde(with = "super")] &'a [T]);
        #[derive(Deserialize)]
        struct Own<T: Pod>(#[serde(with = "super")] Vec<T>);

        pub fn serialize<T: Pod, S: Serializer>(v: &Option<Vec<T>>, s: S) -> Result<S::Ok, S::Error> {
            v.as_deref().map(Ref).serialize(s)
        }

        pub fn deserialize<'de, T: Pod, D: Deserializer<'de>>(d: D) -> Result<Option<Vec<T>>, D::Error> {
            Ok(Option::<Own<T>>::deserialize(d)?.map(|o| o.0))
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use serde::Deserialize;

    #[derive(Debug, PartialEq, Serialize, Deserialize)]
    struct Sample {
        #[serde(with = "pod")]
        values: Vec<f64>,
        #[serde(with = "pod")]
        points: Vec<[f64; 3]>,
        #[serde(with = "pod::option")]
        maybe: Option<Vec<u32>>,
        count: usize,
        name: String,
    }

    fn sample() -> Sample {
        Sample {
            values: vec![1.5, -0.0, f64::MIN_POSITIVE, 3e300],
            points: vec![[1.0, 2.0, 3.0], [4.0, 5.0, 6.0]],
            maybe: Some(vec![7, 8, u32::MAX]),
            count: 12345,
            name: "a".into(),
        }
    }

    #[test]
    fn a_value_round_trips_bit_for_bit() {
        let s = sample();
        let bytes = encode(&s, 7, 0);
        let back: Sample = decode(&bytes, 7).unwrap();
        assert_eq!(back, s);
        assert_eq!(back.values[1].to_bits(), (-0.0f64).to_bits());
        let none = Sample { maybe: None, ..sample() };
        assert_eq!(decode::<Sample>(&encode(&none, 7, 0), 7).unwrap(), none);
    }

    #[test]
    fn every_damaged_file_is_refused_with_its_reason() {
        let bytes = encode(&sample(), 7, 0);
        assert!(matches!(decode::<Sample>(&bytes, 8), Err(FormatError::Kind { found: 7, expected: 8 })));
        for cut in [0, 5, 8, 20, HEADER_BYTES, bytes.len() - 1] {
            let e = decode::<Sample>(&bytes[..cut], 7).unwrap_err();
            let ok = match cut {
                0 | 5 => matches!(e, FormatError::Magic { .. }),
                _ => matches!(e, FormatError::Truncated { .. }),
            };
            assert!(ok, "cut at {cut}: {e:?}");
        }
        let mut longer = bytes.clone();
        longer.push(0);
        assert!(matches!(decode::<Sample>(&longer, 7), Err(FormatError::Trailing { extra: 1 })));
        let mut version = bytes.clone();
        version[8] = 99;
        assert!(matches!(decode::<Sample>(&version, 7), Err(FormatError::Version { found: 99, .. })));
        // Every single flipped bit of the payload fails the checksum.
        for at in HEADER_BYTES..bytes.len() {
            for bit in 0..8 {
                let mut flipped = bytes.clone();
                flipped[at] ^= 1 << bit;
                let e = decode::<Sample>(&flipped, 7).unwrap_err();
                assert!(matches!(e, FormatError::Checksum { .. }), "byte {at} bit {bit}: {e:?}");
            }
        }
    }

    #[test]
    fn a_payload_that_lies_about_its_lengths_is_refused_not_a_panic() {
        // A valid header over payloads that are not a `Sample`: the checksum
        // passes (it is recomputed), the decoder must refuse them.
        let good = encode(&sample(), 7, 0);
        let mut seed = 0x2545_f491_4f6c_dd1du64;
        for trial in 0..2000 {
            seed ^= seed << 13;
            seed ^= seed >> 7;
            seed ^= seed << 17;
            let mut payload = good[HEADER_BYTES..].to_vec();
            let at = (seed as usize) % payload.len();
            payload[at] = (seed >> 32) as u8;
            payload.truncate(payload.len() - (trial % 3));
            let mut bytes = good[..HEADER_BYTES].to_vec();
            bytes[16..24].copy_from_slice(&(payload.len() as u64).to_le_bytes());
            bytes[24..28].copy_from_slice(&crc32fast::hash(&payload).to_le_bytes());
            bytes.extend_from_slice(&payload);
            // Either a value or a typed error; never a panic or a huge allocation.
            let _ = decode::<Sample>(&bytes, 7);
        }
        let bad_len = postcard::to_allocvec(&(u64::MAX, 1u8)).unwrap();
        let mut bytes = good[..HEADER_BYTES].to_vec();
        bytes[16..24].copy_from_slice(&(bad_len.len() as u64).to_le_bytes());
        bytes[24..28].copy_from_slice(&crc32fast::hash(&bad_len).to_le_bytes());
        bytes.extend_from_slice(&bad_len);
        assert!(matches!(decode::<Sample>(&bytes, 7), Err(FormatError::Decode { .. })));
    }
}
