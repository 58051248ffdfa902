//! Subcommands of the `curvenet` command line.

pub mod inspect;

/// A command-line failure. Bad input (exit 2) is kept apart from failures
/// that may succeed on retry (exit 75, EX_TEMPFAIL), so a farm retries only
/// what can succeed.
#[derive(Debug, thiserror::Error)]
pub enum CliError {
    #[error(transparent)]
    Usd(#[from] curvenet_schema::usd::UsdError),
    #[error("{0}")]
    Input(String),
}

impl CliError {
    pub fn exit_code(&self) -> u8 {
        match self {
            CliError::Usd(curvenet_schema::usd::UsdError::Open { message, .. }) if is_transient(message) => 75,
            _ => 2,
        }
    }
}

fn is_transient(message: &str) -> bool {
    // A missing or unparsable file is bad input; an interrupted read is not.
    let m = message.to_ascii_lowercase();
    m.contains("interrupted") || m.contains("timed out") || m.contains("resource temporarily unavailable")
}

pub type CliResult<T = ()> = Result<T, CliError>;
