//! The database, through sqlx: an embedded SQLite file by default, or a PostgreSQL server
//! when many stations and a dashboard share one ([`DbLocation`], [`Db`]). Migrations from the
//! repository's `migrations/sqlite/` or `migrations/postgres/` (embedded at build time,
//! applied at open). SQLite runs with a WAL journal, a busy timeout and foreign keys, so
//! several simulator stations (processes) can write to one file at once. Multi-statement
//! writes run in transactions that write ([`BeginWrite`](db::BeginWrite)).
//!
//! Times are integer nanoseconds since the Unix epoch (UTC), see [`now_ns`] and
//! [`iso8601`].

mod attempts;
mod builtins;
mod cohorts;
mod curricula;
mod db;
mod evidence;
mod exercises;
mod hub;
mod names;
mod progression;
mod recorded;
pub mod text;
mod users;

use std::path::PathBuf;
use std::time::Duration;

use sqlx::postgres::{PgConnectOptions, PgPoolOptions};
use sqlx::sqlite::{SqliteConnectOptions, SqliteJournalMode, SqlitePoolOptions, SqliteSynchronous};
use sqlx::{ConnectOptions, Connection};
use sqlx::{PgPool, SqlitePool};

pub use attempts::{Attempt, AttemptStatus, Outcome, ProficiencyRecord, StoredMetric};
pub use builtins::{
    BODY_WALL_EXERCISE, BUILTIN_EXERCISE, BUILTIN_SCENE, Builtin, EXCISION_EXERCISE,
    FIELD_EXERCISE, PATTERN_EXERCISE, builtins,
};
pub use cohorts::Cohort;
pub use curricula::{Curriculum, Module};
pub(crate) use db::BeginWrite;
pub use db::{Db, DbLocation, TEST_POSTGRES_ENV, scratch_postgres, test_postgres};
pub use evidence::PassMark;
pub use exercises::{Exercise, ExerciseEdit, NewExercise, ThresholdSource};
pub use hub::{AttemptUpload, Imported, StationToken, is_uuid, new_uuid};
pub use names::{MAX_NAME_CHARS, check_name, printable, skeleton};
pub use progression::{Access, CUTTING_BASICS, Opening, reached_proficiency};
pub use users::{Role, User};

use crate::error::{AssessError, Result};

/// The SQLite migrations, `migrations/sqlite/`.
pub static SQLITE_MIGRATOR: sqlx::migrate::Migrator = sqlx::migrate!("../migrations/sqlite");
/// The PostgreSQL migrations, `migrations/postgres/`.
pub static POSTGRES_MIGRATOR: sqlx::migrate::Migrator = sqlx::migrate!("../migrations/postgres");

/// The environment variable naming the database when `--db` is not given.
pub const DB_ENV: &str = "CUTLAB_DB";

/// The database: `cli` (`--db`) if given, else `$CUTLAB_DB` if set and not empty, else the
/// SQLite file `./cutlab.db`.
pub fn default_db(cli: Option<&DbLocation>) -> DbLocation {
    if let Some(l) = cli {
        return l.clone();
    }
    match std::env::var(DB_ENV) {
        Ok(v) if !v.trim().is_empty() => v
            .parse()
            .unwrap_or_else(|_| DbLocation::Sqlite(PathBuf::from(v))),
        _ => DbLocation::Sqlite(PathBuf::from("cutlab.db")),
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
    db: Db,
}

/// Maps a unique-constraint violation to [`AssessError::Conflict`] with `what`.
pub(crate) fn conflict(what: impl FnOnce() -> String) -> impl FnOnce(sqlx::Error) -> AssessError {
    move |e| match &e {
        sqlx::Error::Database(d) if d.is_unique_violation() => AssessError::Conflict(what()),
        _ => AssessError::Database(e),
    }
}

impl Store {
    /// Opens the database at `location` and applies the migrations. An SQLite file is created
    /// if missing, with its folder; so is a PostgreSQL database on a server that has none of
    /// that name (given the right to create one).
    pub async fn open(location: impl Into<DbLocation>) -> Result<Self> {
        match location.into() {
            DbLocation::Sqlite(path) => {
                if let Some(dir) = path.parent().filter(|d| !d.as_os_str().is_empty()) {
                    std::fs::create_dir_all(dir).map_err(|source| AssessError::Io {
                        path: dir.display().to_string(),
                        error: source,
                    })?;
                }
                Self::open_with(SqliteConnectOptions::new().filename(path)).await
            }
            DbLocation::Postgres(url) => {
                let connect: PgConnectOptions = url.parse()?;
                // one connection first: its error is the cause (refused, password, ...),
                // where a pool's is a timeout
                match connect.connect().await {
                    Ok(c) => c.close().await?,
                    // a server without the database: create it, like SQLite's file
                    Err(sqlx::Error::Database(e)) if e.code().as_deref() == Some("3D000") => {
                        use sqlx::migrate::MigrateDatabase;
                        if let Err(e) = sqlx::Postgres::create_database(&url).await {
                            // another process may have created it meanwhile
                            tracing::debug!("creating the database: {e}");
                        }
                    }
                    Err(e) => return Err(e.into()),
                }
                let pool = PgPoolOptions::new()
                    .max_connections(16)
                    .acquire_timeout(Duration::from_secs(10))
                    .connect_with(connect)
                    .await?;
                Self::from_postgres(pool).await
            }
        }
    }

    /// Opens an SQLite database with the given connection options plus the store's settings
    /// (create if missing, WAL, synchronous NORMAL, 30 s busy timeout, foreign keys) and
    /// migrates.
    pub async fn open_with(options: SqliteConnectOptions) -> Result<Self> {
        let options = options
            .create_if_missing(true)
            .journal_mode(SqliteJournalMode::Wal)
            .synchronous(SqliteSynchronous::Normal)
            .busy_timeout(Duration::from_secs(30))
            .foreign_keys(true);
        let started = std::time::Instant::now();
        let pool = loop {
            match SqlitePoolOptions::new()
                .max_connections(4)
                .connect_with(options.clone())
                .await
            {
                // a fresh file another process is creating: switching it to WAL needs the
                // whole database, and SQLite answers "locked" at once rather than waiting
                Err(sqlx::Error::Database(d))
                    if is_busy(d.code().as_deref()) && started.elapsed() < MIGRATION_PATIENCE =>
                {
                    tracing::debug!("opening the database: {d}; retrying");
                    tokio::time::sleep(Duration::from_millis(200)).await;
                }
                other => break other?,
            }
        };
        Self::from_pool(pool).await
    }

    /// Uses an existing SQLite pool (tests), applying the migrations.
    pub async fn from_pool(pool: SqlitePool) -> Result<Self> {
        migrate(&SQLITE_MIGRATOR, &pool).await?;
        Ok(Self {
            db: Db::Sqlite(pool),
        })
    }

    /// Uses an existing PostgreSQL pool, applying the migrations.
    pub async fn from_postgres(pool: PgPool) -> Result<Self> {
        migrate(&POSTGRES_MIGRATOR, &pool).await?;
        Ok(Self {
            db: Db::Postgres(pool),
        })
    }

    /// The connection pool, for queries the store does not offer (run them with
    /// [`on_db!`](crate::on_db)).
    pub fn db(&self) -> &Db {
        &self.db
    }

    /// Closes the pool (waits for connections to finish; SQLite checkpoints the WAL).
    pub async fn close(&self) {
        crate::on_db!(&self.db, pool => pool.close().await);
    }
}

/// Applies `migrator`'s migrations. Another process migrating the same database at the same
/// moment is tolerated: any failure is retried 5 times, a busy database for up to about 30 s
/// (SQLite answers "database is locked" at once, without its busy timeout, when a migration's
/// transaction must wait for another process's; a fresh database's migrations take seconds
/// on a busy machine).
async fn migrate<'a, A>(migrator: &sqlx::migrate::Migrator, pool: A) -> Result<()>
where
    A: sqlx::Acquire<'a> + Copy,
    <A::Connection as std::ops::Deref>::Target: sqlx::migrate::Migrate,
{
    let started = std::time::Instant::now();
    let mut tries = 0u64;
    loop {
        match migrator.run(pool).await {
            Ok(()) => return Ok(()),
            Err(e) if (tries < 5 || busy(&e)) && started.elapsed() < MIGRATION_PATIENCE => {
                tracing::debug!("migration attempt {tries} failed ({e}); retrying");
                tries += 1;
                tokio::time::sleep(Duration::from_millis((100 * tries).min(1000))).await;
            }
            Err(e) => return Err(e.into()),
        }
    }
}

/// Whether a migration failed because another connection held the database (SQLite's
/// `SQLITE_BUSY` and `SQLITE_LOCKED`, extended codes included).
fn busy(e: &sqlx::migrate::MigrateError) -> bool {
    use sqlx::migrate::MigrateError;
    let (MigrateError::Execute(sqlx::Error::Database(d))
    | MigrateError::ExecuteMigration(sqlx::Error::Database(d), _)) = e
    else {
        return false;
    };
    is_busy(d.code().as_deref())
}

/// How long opening and migrating a database waits for another process that holds it.
const MIGRATION_PATIENCE: Duration = Duration::from_secs(30);

/// Whether an SQLite error code is `SQLITE_BUSY` or `SQLITE_LOCKED` (extended codes included).
fn is_busy(code: Option<&str>) -> bool {
    code.and_then(|c| c.parse::<u32>().ok())
        .is_some_and(|c| matches!(c & 0xff, 5 | 6))
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
    fn db_resolution() {
        let given = DbLocation::Sqlite(PathBuf::from("x.db"));
        assert_eq!(default_db(Some(&given)), given);
        // the environment is shared by the test threads: only read it here
        let expected = std::env::var(DB_ENV)
            .ok()
            .filter(|p| !p.trim().is_empty())
            .map_or(DbLocation::Sqlite(PathBuf::from("cutlab.db")), |v| {
                v.parse().expect("location")
            });
        assert_eq!(default_db(None), expected);
    }
}
