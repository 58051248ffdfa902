/// A stage that cannot be opened or breaks the contract. Every contract error
/// names the prim and, where one is at fault, the attribute.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum UsdError {
    /// The file could not be opened or composed (missing file, parse error,
    /// unresolved sublayer or reference).
    #[error("cannot open {path}: {message}")]
    Open { path: String, message: String },
    /// A prim or attribute breaks the contract.
    #[error("{prim}: {attribute}{sep}{problem}", sep = if attribute.is_empty() { "" } else { " " })]
    Contract { prim: String, attribute: String, problem: String },
    /// The stage opens a layer or asset outside the directories it was
    /// confined to ([`super::Stage::open_within`]).
    #[error("cannot open {path}: it opens {asset} ({resolved}), outside the allowed directories ({roots})")]
    Forbidden { path: String, asset: String, resolved: String, roots: String },
}

impl UsdError {
    pub(crate) fn contract(prim: impl ToString, attribute: &str, problem: impl Into<String>) -> Self {
        Self::Contract { prim: prim.to_string(), attribute: attribute.to_string(), problem: problem.into() }
    }
}
