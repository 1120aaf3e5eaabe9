//! The database: SQLite through sqlx, migrations from the repository's `migrations/`
//! (embedded at build time, applied at open), WAL journal, a busy timeout and foreign keys,
//! so several simulator stations (processes) can write to one file at once. Multi-statement
//! writes run in `BEGIN IMMEDIATE` transactions (they take the write lock up front and wait
//! for it instead of failing on an upgrade).
//!
//! Times are integer nanoseconds since the Unix epoch (UTC), see [`now_ns`] and
//! [`iso8601`].

mod attempts;
mod builtins;
mod cohorts;
mod curricula;
mod exercises;
mod users;

use std::path::{Path, PathBuf};
use std::time::Duration;

use sqlx::SqlitePool;
use sqlx::sqlite::{SqliteConnectOptions, SqliteJournalMode, SqlitePoolOptions, SqliteSynchronous};

pub use attempts::{Attempt, AttemptStatus, Outcome, ProficiencyRecord, StoredMetric};
pub use builtins::{BUILTIN_EXERCISE, BUILTIN_SCENE, default_thresholds};
pub use cohorts::Cohort;
pub use curricula::{Curriculum, Module};
pub use exercises::{Exercise, ExerciseEdit, NewExercise, ThresholdSource};
pub use users::{Role, User};

use crate::error::{AssessError, Result};

/// The migrations in the repository's `migrations/` directory.
pub static MIGRATOR: sqlx::migrate::Migrator = sqlx::migrate!("../migrations");

/// The environment variable naming the database when `--db` is not given.
pub const DB_ENV: &str = "CUTLAB_DB";

/// The database path: `cli` (`--db`) if given, else `$CUTLAB_DB` if set and not empty, else
/// `./cutlab.db`.
pub fn default_db_path(cli: Option<&Path>) -> PathBuf {
    if let Some(p) = cli {
        return p.to_path_buf();
    }
    match std::env::var_os(DB_ENV) {
        Some(p) if !p.is_empty() => PathBuf::from(p),
        _ => PathBuf::from("cutlab.db"),
    }
}

/// Now, in nanoseconds since the Unix epoch.
pub fn now_ns() -> i64 {
    std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0, |d| i64::try_from(d.as_nanos()).unwrap_or(i64::MAX))
}

/// `ns` since the epoch as ISO 8601 UTC with milliseconds, e.g. `2026-05-01T08:00:00.000Z`.
pub fn iso8601(ns: i64) -> String {
    let ms = ns.div_euclid(1_000_000);
    let (secs, milli) = (ms.div_euclid(1000), ms.rem_euclid(1000));
    let (days, sod) = (secs.div_euclid(86_400), secs.rem_euclid(86_400));
    // civil from days (Howard Hinnant's algorithm)
    let z = days + 719_468;
    let era = z.div_euclid(146_097);
    let doe = z.rem_euclid(146_097);
    let yoe = (doe - doe / 1460 + doe / 36_524 - doe / 146_096) / 365;
    let doy = doe - (365 * yoe + yoe / 4 - yoe / 100);
    let mp = (5 * doy + 2) / 153;
    let d = doy - (153 * mp + 2) / 5 + 1;
    let m = if mp < 10 { mp + 3 } else { mp - 9 };
    let y = yoe + era * 400 + i64::from(m <= 2);
    format!(
        "{y:04}-{m:02}-{d:02}T{:02}:{:02}:{:02}.{milli:03}Z",
        sod / 3600,
        sod % 3600 / 60,
        sod % 60
    )
}

/// The assessor's database.
#[derive(Debug, Clone)]
pub struct Store {
    pool: SqlitePool,
}

/// Maps a unique-constraint violation to [`AssessError::Conflict`] with `what`.
pub(crate) fn conflict(what: impl FnOnce() -> String) -> impl FnOnce(sqlx::Error) -> AssessError {
    move |e| match &e {
        sqlx::Error::Database(d) if d.is_unique_violation() => AssessError::Conflict(what()),
        _ => AssessError::Database(e),
    }
}

impl Store {
    /// Opens (creating if needed) the database at `path` and applies the migrations.
    pub async fn open(path: &Path) -> Result<Self> {
        if let Some(dir) = path.parent().filter(|d| !d.as_os_str().is_empty()) {
            std::fs::create_dir_all(dir).map_err(|source| AssessError::Io {
                path: dir.display().to_string(),
                error: source,
            })?;
        }
        Self::open_with(SqliteConnectOptions::new().filename(path)).await
    }

    /// Opens with the given connection options plus the store's settings (create if missing,
    /// WAL, synchronous NORMAL, 30 s busy timeout, foreign keys) and migrates.
    pub async fn open_with(options: SqliteConnectOptions) -> Result<Self> {
        let options = options
            .create_if_missing(true)
            .journal_mode(SqliteJournalMode::Wal)
            .synchronous(SqliteSynchronous::Normal)
            .busy_timeout(Duration::from_secs(30))
            .foreign_keys(true);
        let pool = SqlitePoolOptions::new()
            .max_connections(4)
            .connect_with(options)
            .await?;
        Self::from_pool(pool).await
    }

    /// Uses an existing pool (tests), applying the migrations. Another process migrating the
    /// same file at the same moment is tolerated (retried).
    pub async fn from_pool(pool: SqlitePool) -> Result<Self> {
        let mut tries = 0;
        loop {
            match MIGRATOR.run(&pool).await {
                Ok(()) => break,
                Err(e) if tries < 5 => {
                    tracing::debug!("migration attempt {tries} failed ({e}); retrying");
                    tries += 1;
                    tokio::time::sleep(Duration::from_millis(100 * tries)).await;
                }
                Err(e) => return Err(e.into()),
            }
        }
        Ok(Self { pool })
    }

    /// The connection pool, for queries the store does not offer.
    pub fn pool(&self) -> &SqlitePool {
        &self.pool
    }

    /// Closes the pool (waits for connections to finish; checkpoints the WAL).
    pub async fn close(&self) {
        self.pool.close().await;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn iso8601_by_hand() {
        assert_eq!(iso8601(0), "1970-01-01T00:00:00.000Z");
        // 2000-02-29T12:34:56.789Z = 951827696789 ms
        assert_eq!(iso8601(951_827_696_789_000_000), "2000-02-29T12:34:56.789Z");
        assert_eq!(iso8601(-1_000_000), "1969-12-31T23:59:59.999Z");
    }

    #[test]
    fn db_path_resolution() {
        assert_eq!(
            default_db_path(Some(Path::new("x.db"))),
            PathBuf::from("x.db")
        );
        // the environment is shared by the test threads: only read it here
        let expected = std::env::var_os(DB_ENV)
            .filter(|p| !p.is_empty())
            .map_or(PathBuf::from("cutlab.db"), PathBuf::from);
        assert_eq!(default_db_path(None), expected);
    }
}
