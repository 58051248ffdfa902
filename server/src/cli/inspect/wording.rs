//! How the report words counts and lists: plural endings, and lists of
//! pool indices cut at [`MAX_LISTED`].

/// At most this many control points are named in one warning.
const MAX_LISTED: usize = 20;

pub(super) fn plural(n: usize) -> &'static str {
    if n == 1 { "" } else { "s" }
}

/// `a, b, c` (at most [`MAX_LISTED`], then how many more).
pub(super) fn list(items: &[u32]) -> String {
    let mut s: Vec<String> = items.iter().take(MAX_LISTED).map(|i| i.to_string()).collect();
    if items.len() > MAX_LISTED {
        s.push(format!("and {} more", items.len() - MAX_LISTED));
    }
    s.join(", ")
}
