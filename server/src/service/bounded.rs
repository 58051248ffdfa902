//! `{"frames": [...]}` deserialised with a cap on the number of frames,
//! refused as soon as the cap is passed: the answer of a batch is bounded
//! (`--max-batch-bytes`), and so is what its request may make the server
//! hold while parsing (an empty frame `{}` is 3 bytes of body but a hundred
//! bytes parsed).

use std::fmt;
use std::marker::PhantomData;

use serde::de::{self, DeserializeOwned, DeserializeSeed, MapAccess, SeqAccess, Visitor};

/// Why a batch did not parse.
#[derive(Debug)]
pub enum BatchError {
    /// Not JSON for `{"frames": [...]}`.
    Malformed(serde_json::Error),
    /// The object's first key is not `frames` (a single frame's header, perhaps).
    NotBatch,
    /// More than the cap.
    TooMany(usize),
}

/// The `limit_exceeded` answer to a batch of more than `max` frames.
pub fn too_many(max: usize, vertices: usize) -> crate::error::ServiceError {
    crate::error::ServiceError::new(
        crate::error::Code::LimitExceeded,
        format!(
            "the batch has more than {max} frames: the answer of that many frames of {vertices} vertices would be \
             larger than this server's limit (--max-batch-bytes, CURVENET_MAX_BATCH_BYTES); split it"
        ),
    )
}

/// The most frames of `vertices` vertices whose answer (12 bytes a vertex) fits in `max_bytes`.
pub fn max_frames(max_bytes: u64, vertices: usize) -> usize {
    usize::try_from(max_bytes / (12 * vertices.max(1) as u64)).unwrap_or(usize::MAX)
}

/// Parses `{"frames": [T, ...]}` (no other key), with at most `max` frames.
pub fn frames<T: DeserializeOwned>(json: &[u8], max: usize) -> Result<Vec<T>, BatchError> {
    let mut de = serde_json::Deserializer::from_slice(json);
    let outcome = std::cell::Cell::new(None);
    let r = de::Deserializer::deserialize_map(&mut de, Outer::<T> { max, outcome: &outcome, _t: PhantomData })
        .and_then(|v| de.end().map(|()| v));
    match (r, outcome.take()) {
        (Ok(v), _) => Ok(v),
        (Err(_), Some(e)) => Err(e),
        (Err(e), None) => Err(BatchError::Malformed(e)),
    }
}

struct Outer<'a, T> {
    max: usize,
    outcome: &'a std::cell::Cell<Option<BatchError>>,
    _t: PhantomData<T>,
}

impl<'de, T: DeserializeOwned> Visitor<'de> for Outer<'_, T> {
    type Value = Vec<T>;

    fn expecting(&self, f: &mut fmt::Formatter) -> fmt::Result {
        f.write_str("an object {\"frames\": [...]}")
    }

    fn visit_map<A: MapAccess<'de>>(self, mut map: A) -> Result<Vec<T>, A::Error> {
        let mut frames = None;
        while let Some(key) = map.next_key::<String>()? {
            if key != "frames" {
                if frames.is_none() {
                    self.outcome.set(Some(BatchError::NotBatch));
                }
                return Err(de::Error::custom(format!("unknown field `{key}`, expected `frames`")));
            }
            if frames.is_some() {
                return Err(de::Error::duplicate_field("frames"));
            }
            frames = Some(map.next_value_seed(Seq::<T> { max: self.max, outcome: self.outcome, _t: PhantomData })?);
        }
        frames.ok_or_else(|| de::Error::missing_field("frames"))
    }
}

struct Seq<'a, T> {
    max: usize,
    outcome: &'a std::cell::Cell<Option<BatchError>>,
    _t: PhantomData<T>,
}

impl<'de, T: DeserializeOwned> DeserializeSeed<'de> for Seq<'_, T> {
    type Value = Vec<T>;

    fn deserialize<D: de::Deserializer<'de>>(self, d: D) -> Result<Vec<T>, D::Error> {
        d.deserialize_seq(self)
    }
}

impl<'de, T: DeserializeOwned> Visitor<'de> for Seq<'_, T> {
    type Value = Vec<T>;

    fn expecting(&self, f: &mut fmt::Formatter) -> fmt::Result {
        f.write_str("an array of frames")
    }

    fn visit_seq<A: SeqAccess<'de>>(self, mut seq: A) -> Result<Vec<T>, A::Error> {
        let mut out = Vec::new();
        while let Some(x) = seq.next_element::<T>()? {
            if out.len() == self.max {
                self.outcome.set(Some(BatchError::TooMany(self.max)));
                return Err(de::Error::custom("too many frames"));
            }
            out.push(x);
        }
        Ok(out)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_cap_is_enforced_and_other_shapes_are_told_apart() {
        let ok: Vec<u32> = frames(br#"{"frames": [1, 2, 3]}"#, 3).unwrap();
        assert_eq!(ok, [1, 2, 3]);
        assert!(matches!(frames::<u32>(br#"{"frames": [1, 2, 3]}"#, 2), Err(BatchError::TooMany(2))));
        assert!(matches!(frames::<u32>(br#"{"arrays": []}"#, 2), Err(BatchError::NotBatch)));
        assert!(matches!(frames::<u32>(br#"{"frames": [1], "x": 2}"#, 2), Err(BatchError::Malformed(_))));
        assert!(matches!(frames::<u32>(br#"{"frames": [1]} 7"#, 2), Err(BatchError::Malformed(_))));
        assert!(matches!(frames::<u32>(b"[", 2), Err(BatchError::Malformed(_))));
    }
}
