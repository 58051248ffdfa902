//! What the binding's types hold on the heap, measured rather than
//! estimated: every type's `heap_bytes()` adds the **capacities** of its
//! vectors (spare capacity is held memory too) times their element sizes,
//! recursing into nested vectors. Allocator overhead (size-class rounding,
//! headers) is not included; a caller budgeting memory adds its own margin.
//!
//! Every type implements `heap_bytes` in its own module with the helpers
//! here (this module imports nothing, so it is in no import cycle).

use std::mem::size_of;

/// Heap bytes of a vector's buffer (its capacity).
pub(crate) fn bytes<T>(v: &Vec<T>) -> usize {
    v.capacity() * size_of::<T>()
}

/// Heap bytes of a vector of vectors: the outer buffer and every inner one.
pub(crate) fn nested_bytes<T>(v: &Vec<Vec<T>>) -> usize {
    bytes(v) + v.iter().map(bytes).sum::<usize>()
}
