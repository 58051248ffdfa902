//! Units on the command line: byte counts with suffixes (`--cache-bytes 2GiB`),
//! shared by `serve` and `bake`, and finite numbers (`--time 3`,
//! `--normal 0,0,1`), shared by `inspect` and `draft`.

/// Parses a byte count with an optional suffix: K/KB (1000), KiB (1024), M/MB, MiB, G/GB, GiB, T/TB, TiB
/// (a shared binding store is sized in terabytes).
pub fn parse_bytes(s: &str) -> Result<u64, String> {
    let s = s.trim();
    let split = s.find(|c: char| !(c.is_ascii_digit() || c == '.')).unwrap_or(s.len());
    let (num, unit) = s.split_at(split);
    let num: f64 = num.parse().map_err(|_| format!("{s:?} is not a byte count (e.g. 512MiB, 2GiB, 1000000)"))?;
    let scale: f64 = match unit.trim().to_ascii_lowercase().as_str() {
        "" | "b" => 1.0,
        "k" | "kb" => 1e3,
        "kib" => 1024.0,
        "m" | "mb" => 1e6,
        "mib" => 1024.0 * 1024.0,
        "g" | "gb" => 1e9,
        "gib" => 1024.0 * 1024.0 * 1024.0,
        "t" | "tb" => 1e12,
        "tib" => 1024.0 * 1024.0 * 1024.0 * 1024.0,
        other => return Err(format!("unknown unit {other:?} (B, KB, KiB, MB, MiB, GB, GiB, TB, TiB)")),
    };
    let bytes = num * scale;
    // Beyond 2^63 bytes (8 EiB) is no memory a machine has: a typo, refused
    // rather than saturated to u64::MAX.
    if !(bytes.is_finite() && bytes < 9.2e18) {
        return Err(format!("{s:?} is too large a byte count (at most 8 EiB)"));
    }
    Ok(bytes as u64)
}

/// Parses `N` comma-separated finite numbers; `what` says what was expected.
pub fn parse_numbers<const N: usize>(s: &str, what: &str) -> Result<[f64; N], String> {
    let parts: Vec<&str> = s.split(',').map(str::trim).collect();
    if parts.len() != N {
        return Err(format!("{s:?}: expected {what}"));
    }
    let mut out = [0.0; N];
    for (o, p) in out.iter_mut().zip(&parts) {
        *o = p.parse::<f64>().map_err(|_| format!("{p:?} is not a number (expected {what})"))?;
        if !o.is_finite() {
            return Err(format!("{p:?} is not finite (expected {what})"));
        }
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::parse_bytes;

    #[test]
    fn byte_counts_parse_and_overflow_is_refused() {
        assert_eq!(parse_bytes("1536MiB"), Ok(1536 << 20));
        assert_eq!(parse_bytes("2GiB"), Ok(2 << 30));
        assert_eq!(parse_bytes("3TiB"), Ok(3 << 40));
        assert_eq!(parse_bytes("2TB"), Ok(2_000_000_000_000));
        assert_eq!(parse_bytes("0"), Ok(0));
        for bad in ["18446744073709551616", "9999999999999999999999KiB", "1e400", "12XB", ""] {
            assert!(parse_bytes(bad).is_err(), "{bad:?} parsed as {:?}", parse_bytes(bad));
        }
    }
}
