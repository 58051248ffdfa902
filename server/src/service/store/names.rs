//! What the two backends share below them: the names of entries, markers
//! and temporary files, and the choice of what to evict. Pure functions, so
//! the rule that decides which files are the store's is written once.

/// The first 8 bytes of every blob the store holds (the service's and the
/// bake's entries, `stored.rs`). A backend reads a blob's first bytes
/// before the rest and answers a blob that does not start so with those
/// bytes alone, for its reader to refuse: garbage under an entry's name is
/// never read whole, whatever its size.
pub const BLOB_MAGIC: [u8; 8] = *b"CNENTRY\0";

use std::time::{Duration, SystemTime};

/// The suffix of a blob's file or object name (`<64 hex>.cnb`).
pub const BLOB_SUFFIX: &str = ".cnb";

/// The suffix of an S3 recency marker (`<64 hex>.used`, see the module docs of `store`).
pub const MARKER_SUFFIX: &str = ".used";

/// A temporary file or orphan marker untouched this long belongs to a writer
/// that died (a write takes seconds; an hour also covers slow clocks of
/// other hosts sharing the directory), so eviction deletes it.
pub const STALE_AGE: Duration = Duration::from_secs(3600);

/// Lowercase hex of a key: the entry's name without its suffix, and how
/// errors and logs name the key.
pub fn hex(key: &[u8; 32]) -> String {
    const DIGITS: &[u8; 16] = b"0123456789abcdef";
    let mut s = String::with_capacity(64);
    for b in key {
        s.push(DIGITS[usize::from(b >> 4)] as char);
        s.push(DIGITS[usize::from(b & 15)] as char);
    }
    s
}

/// The key of exactly 64 lowercase hex digits, else None. Uppercase is
/// refused on purpose: the store writes lowercase only, so `ABC….cnb` is a
/// foreign file, never a second name for one entry.
pub fn parse_hex(s: &str) -> Option<[u8; 32]> {
    let digits = s.as_bytes();
    if digits.len() != 64 {
        return None;
    }
    let value = |c: u8| match c {
        b'0'..=b'9' => Some(c - b'0'),
        b'a'..=b'f' => Some(c - b'a' + 10),
        _ => None,
    };
    let mut key = [0u8; 32];
    for (i, pair) in digits.chunks_exact(2).enumerate() {
        key[i] = value(pair[0])? << 4 | value(pair[1])?;
    }
    Some(key)
}

/// `<hex>.cnb`: the blob's file or object name.
pub fn blob_name(key: &[u8; 32]) -> String {
    format!("{}{BLOB_SUFFIX}", hex(key))
}

/// `<hex>.used`: the key's S3 recency marker.
pub fn marker_name(key: &[u8; 32]) -> String {
    format!("{}{MARKER_SUFFIX}", hex(key))
}

/// The key named by `name` if it is `<64 lowercase hex><suffix>`.
pub fn parse_name(name: &str, suffix: &str) -> Option<[u8; 32]> {
    parse_hex(name.strip_suffix(suffix)?)
}

/// `.<tag>.<pid>.<unique>.tmp`: the name of a temporary file being written.
/// Hidden (a dot), so the listing and a person's `ls` skip it; `tag` is the
/// key's hex (or `probe` for the check that the directory is writable), the
/// pid and `unique` keep two writers apart, also on different hosts of one
/// NFS directory (`unique` holds 64 random bits).
pub fn temp_name(tag: &str, pid: u32, unique: &str) -> String {
    format!(".{tag}.{pid}.{unique}.tmp")
}

/// Whether `name` is one of the store's temporary files: `.<tag>.<pid
/// digits>.<unique>.tmp`, with no dot inside `tag` or `unique`. Strict on
/// purpose, so that another program's hidden files (`.nfs…` silly renames,
/// `.DS_Store`) are never taken for stale temporaries and deleted.
pub fn is_temp(name: &str) -> bool {
    let Some(inner) = name.strip_prefix('.').and_then(|n| n.strip_suffix(".tmp")) else { return false };
    let parts: Vec<&str> = inner.split('.').collect();
    match parts.as_slice() {
        [tag, pid, unique] => {
            !tag.is_empty() && !unique.is_empty() && !pid.is_empty() && pid.bytes().all(|b| b.is_ascii_digit())
        }
        _ => false,
    }
}

/// 64 bits that differ between processes and between calls: the std
/// hasher's keys come from the OS's random source, mixed with a counter and
/// the clock. Not cryptographic; it only keeps temporary names apart.
pub fn unique_bits() -> u64 {
    use std::hash::{BuildHasher as _, Hasher as _};
    use std::sync::atomic::{AtomicU64, Ordering};
    static COUNTER: AtomicU64 = AtomicU64::new(0);
    let mut h = std::hash::RandomState::new().build_hasher();
    h.write_u64(COUNTER.fetch_add(1, Ordering::Relaxed));
    let now = SystemTime::now().duration_since(SystemTime::UNIX_EPOCH).unwrap_or_default();
    h.write_u128(now.as_nanos());
    h.finish()
}

/// One entry as listed: its key, its size and when it was last used (written or hit).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Listed {
    pub key: [u8; 32],
    pub bytes: u64,
    pub used: SystemTime,
}

/// What eviction deletes, and the total it leaves.
#[derive(Debug)]
pub struct Plan {
    /// Entries to delete, least recently used first.
    pub evict: Vec<Listed>,
    /// Bytes of the entries kept.
    pub kept_bytes: u64,
    /// Entries kept.
    pub kept_entries: usize,
}

/// What an eviction sweep left and did.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Swept {
    /// Bytes of the entries left.
    pub bytes: u64,
    /// Entries left.
    pub entries: usize,
    /// Entries this sweep deleted (not those another process deleted first).
    pub evicted: usize,
}

/// The least recently used entries to delete so that the rest hold at most
/// `max_bytes` (all of them kept when `max_bytes` is None), never `keep`
/// (the key just written: it may alone be over the limit, and then stays,
/// with everything else gone). Ties of recency are broken by key, so two
/// processes sweeping the same listing choose the same victims.
pub fn plan(mut entries: Vec<Listed>, max_bytes: Option<u64>, keep: &[u8; 32]) -> Plan {
    let total: u64 = entries.iter().map(|e| e.bytes).sum();
    let Some(max) = max_bytes.filter(|max| total > *max) else {
        return Plan { evict: Vec::new(), kept_bytes: total, kept_entries: entries.len() };
    };
    entries.sort_by(|a, b| a.used.cmp(&b.used).then(a.key.cmp(&b.key)));
    let mut kept_bytes = total;
    let mut evict = Vec::new();
    let mut kept = Vec::new();
    for e in entries {
        if kept_bytes > max && e.key != *keep {
            kept_bytes -= e.bytes;
            evict.push(e);
        } else {
            kept.push(e);
        }
    }
    Plan { evict, kept_bytes, kept_entries: kept.len() }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn hex_round_trips_and_refuses_what_the_store_never_writes() {
        let key: [u8; 32] = std::array::from_fn(|i| (i * 37 + 11) as u8);
        let h = hex(&key);
        assert_eq!(h.len(), 64);
        assert_eq!(parse_hex(&h), Some(key));
        assert_eq!(parse_hex(&h.to_uppercase()), None, "uppercase is a foreign name");
        assert_eq!(parse_hex(&h[..63]), None);
        assert_eq!(parse_hex(&format!("{h}0")), None);
        assert_eq!(parse_hex(&"g".repeat(64)), None);
        assert_eq!(parse_name(&blob_name(&key), BLOB_SUFFIX), Some(key));
        assert_eq!(parse_name(&marker_name(&key), MARKER_SUFFIX), Some(key));
        assert_eq!(parse_name(&marker_name(&key), BLOB_SUFFIX), None);
        // Multi-byte characters must not make the length check lie.
        assert_eq!(parse_hex(&"é".repeat(32)), None);
    }

    #[test]
    fn temporary_names_are_recognised_strictly() {
        let key = [7u8; 32];
        let t = temp_name(&hex(&key), 1234, "00ff-3");
        assert!(is_temp(&t), "{t}");
        assert!(is_temp(&temp_name("probe", 1, "x")));
        for foreign in
            [".nfs000000000123", ".DS_Store", ".a.b.tmp", ".a.1x.b.tmp", "a.1.b.tmp", "..1.b.tmp", ".a.1..tmp"]
        {
            assert!(!is_temp(foreign), "{foreign}");
        }
        assert_ne!(unique_bits(), unique_bits());
    }

    #[test]
    fn the_plan_evicts_the_least_recently_used_and_never_the_kept_key() {
        let t = |s| SystemTime::UNIX_EPOCH + Duration::from_secs(s);
        let e = |k: u8, bytes, s| Listed { key: [k; 32], bytes, used: t(s) };
        let entries = vec![e(1, 10, 5), e(2, 10, 1), e(3, 10, 3), e(4, 10, 9)];
        let p = plan(entries.clone(), None, &[4; 32]);
        assert!(p.evict.is_empty());
        assert_eq!((p.kept_bytes, p.kept_entries), (40, 4));
        let p = plan(entries.clone(), Some(25), &[4; 32]);
        assert_eq!(p.evict.iter().map(|e| e.key[0]).collect::<Vec<_>>(), vec![2, 3]);
        assert_eq!((p.kept_bytes, p.kept_entries), (20, 2));
        // The kept key is the oldest: the next ones go in its place.
        let p = plan(entries.clone(), Some(25), &[2; 32]);
        assert_eq!(p.evict.iter().map(|e| e.key[0]).collect::<Vec<_>>(), vec![3, 1]);
        // A limit below the kept entry alone: everything else goes, it stays.
        let p = plan(entries, Some(5), &[3; 32]);
        assert_eq!(p.evict.len(), 3);
        assert_eq!((p.kept_bytes, p.kept_entries), (10, 1));
    }
}
