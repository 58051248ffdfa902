//! How large a cage may be: a leaf the error type names in its message
//! without importing the cage module back.

/// The most cage vertices a cage may have: a cage is a coarse control
/// mesh (the paper's have tens to a few hundred vertices); a cage of
/// thousands is a mesh given where a cage was meant (e.g. the character
/// itself), whose dense `Φ` would not fit in memory.
pub const MAX_CAGE_VERTICES: usize = 4096;

/// The most memory `Φ` (points × cage vertices × 8 bytes) may take: 2 GiB,
/// a 376k-vertex character with a 700-vertex cage.
pub const MAX_PHI_BYTES: usize = 2 << 30;
