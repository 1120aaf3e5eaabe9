//! The crate's one error type: the store's own failures beside the scoring's, which keep
//! their kind ([`From<ScoreError>`](AssessError#impl-From<ScoreError>-for-AssessError)).

use cutlab_scoring::ScoreError;

/// Everything that can go wrong in the assessor: bad plans and inputs, the database, files.
#[derive(Debug, thiserror::Error)]
pub enum AssessError {
    /// An expert plan that cannot be used (NaN, degenerate line, non-positive depth...).
    #[error("invalid expert plan: {0}")]
    InvalidPlan(String),
    /// A plan or other file that does not parse.
    #[error("cannot parse {what}: {message}")]
    Parse { what: String, message: String },
    /// Input data that cannot be assessed (too few samples, non-finite values...).
    #[error("invalid input: {0}")]
    InvalidInput(String),
    /// A name or id that is not in the database.
    #[error("not found: {0}")]
    NotFound(String),
    /// A name that is already taken, or another constraint the database refused.
    #[error("conflict: {0}")]
    Conflict(String),
    /// Password hashing failed (not a wrong password: that is `Ok(None)`).
    #[error("password hashing: {0}")]
    Password(String),
    /// The database.
    #[error("database: {0}")]
    Database(#[from] sqlx::Error),
    /// Applying the migrations.
    #[error("database migration: {0}")]
    Migrate(#[from] sqlx::migrate::MigrateError),
    /// The recording store (object store) refused or failed.
    #[error("recording store: {0}")]
    Recordings(String),
    /// Reading a file.
    #[error("{path}: {error}")]
    Io { path: String, error: std::io::Error },
    /// A background task that failed or panicked.
    #[error("background task: {0}")]
    Task(String),
    /// JSON (de)serialisation of stored values.
    #[error("json: {0}")]
    Json(#[from] serde_json::Error),
}

/// Results of this crate.
pub type Result<T, E = AssessError> = std::result::Result<T, E>;

/// A scoring error keeps its kind: a bad plan stays [`AssessError::InvalidPlan`], a file that
/// does not parse [`AssessError::Parse`], and so on.
impl From<ScoreError> for AssessError {
    fn from(e: ScoreError) -> Self {
        match e {
            ScoreError::InvalidPlan(m) => Self::InvalidPlan(m),
            ScoreError::Parse { what, message } => Self::Parse { what, message },
            ScoreError::InvalidInput(m) => Self::InvalidInput(m),
            ScoreError::Io { path, error } => Self::Io { path, error },
            ScoreError::Json(e) => Self::Json(e),
        }
    }
}
