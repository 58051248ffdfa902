//! Shared helpers for the end-to-end tests (see the `[[test]]` targets in Cargo.toml).
