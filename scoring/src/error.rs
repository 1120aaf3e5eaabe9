//! The crate's one error type.

/// What can go wrong in scoring: bad plans and inputs, files that do not parse.
#[derive(Debug, thiserror::Error)]
pub enum ScoreError {
    /// An expert plan that cannot be used (NaN, degenerate line, non-positive depth...).
    #[error("invalid expert plan: {0}")]
    InvalidPlan(String),
    /// A plan or other file that does not parse.
    #[error("cannot parse {what}: {message}")]
    Parse { what: String, message: String },
    /// Input data that cannot be assessed (too few samples, non-finite values...).
    #[error("invalid input: {0}")]
    InvalidInput(String),
    /// Reading a file.
    #[error("{path}: {error}")]
    Io { path: String, error: std::io::Error },
    /// JSON (de)serialisation.
    #[error("json: {0}")]
    Json(#[from] serde_json::Error),
}

/// Results of this crate.
pub type Result<T, E = ScoreError> = std::result::Result<T, E>;
