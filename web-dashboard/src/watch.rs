//! Watches the database for commits, so that the caches ([`crate::cache`]) hold until the
//! data changes rather than for a fixed time.
//!
//! A connection of its own, which never writes, polls every [`POLL`] a value that changes
//! when any other connection (the dashboard's pool, a `cutlab session` in another process or
//! on another station) has committed since the last poll: SQLite's `PRAGMA data_version`, or
//! PostgreSQL's write-ahead log position (`pg_current_wal_lsn()`: any write to the server,
//! so at worst a cache is dropped that was still good). Each change bumps the generation of
//! [`Changes`]. The task ends with the dashboard (it holds only a weak reference); on an
//! error it stops vouching for the caches (short times to live again) and retries. An
//! in-memory SQLite database has no file that another connection could share, so it is not
//! watched.

use std::sync::{Arc, Weak};
use std::time::Duration;

use cutlab_assessor::store::Db;
use sqlx::Connection;

use crate::cache::Changes;

/// How often the watcher asks.
pub const POLL: Duration = Duration::from_millis(100);
/// Wait after an error before connecting again.
const RETRY: Duration = Duration::from_secs(1);

/// Starts the watcher on the current Tokio runtime (none: nothing is watched).
pub(crate) fn spawn(db: &Db, changes: &Arc<Changes>) {
    let Ok(runtime) = tokio::runtime::Handle::try_current() else {
        tracing::debug!("no runtime: the database is not watched; caches use short times to live");
        return;
    };
    let db = db.clone();
    let changes = Arc::downgrade(changes);
    runtime.spawn(async move {
        while changes.strong_count() > 0 {
            let watched = match &db {
                Db::Sqlite(pool) => watch_sqlite(&pool.connect_options(), &changes).await,
                Db::Postgres(pool) => watch_postgres(&pool.connect_options(), &changes).await,
            };
            match watched {
                Ok(()) => return,
                Err(e) => tracing::warn!("watching the database for changes: {e}"),
            }
            if let Some(c) = changes.upgrade() {
                c.set_watching(false);
                c.bump();
            }
            tokio::time::sleep(RETRY).await;
        }
    });
}

/// Polls until the dashboard is gone (`Ok`), or the database is in memory (`Ok` at once), or
/// the connection fails.
async fn watch_sqlite(
    options: &sqlx::sqlite::SqliteConnectOptions,
    changes: &Weak<Changes>,
) -> Result<(), sqlx::Error> {
    let mut conn = sqlx::sqlite::SqliteConnection::connect_with(options).await?;
    // `file` is empty for an in-memory or temporary database
    let files: Vec<(i64, String, String)> = sqlx::query_as("PRAGMA database_list")
        .fetch_all(&mut conn)
        .await?;
    if !files
        .iter()
        .any(|(_, name, file)| name == "main" && !file.is_empty())
    {
        tracing::debug!("an in-memory database: not watched; caches use short times to live");
        return Ok(());
    }
    let mut versions = Versions::default();
    loop {
        let version: i64 = sqlx::query_scalar("PRAGMA data_version")
            .fetch_one(&mut conn)
            .await?;
        if !versions.seen(changes, version) {
            return Ok(());
        }
        tokio::time::sleep(POLL).await;
    }
}

/// Polls until the dashboard is gone (`Ok`) or the connection fails.
async fn watch_postgres(
    options: &sqlx::postgres::PgConnectOptions,
    changes: &Weak<Changes>,
) -> Result<(), sqlx::Error> {
    let mut conn = sqlx::postgres::PgConnection::connect_with(options).await?;
    let mut versions = Versions::default();
    loop {
        let version: String = sqlx::query_scalar("SELECT pg_current_wal_lsn()::text")
            .fetch_one(&mut conn)
            .await?;
        if !versions.seen(changes, version) {
            return Ok(());
        }
        tokio::time::sleep(POLL).await;
    }
}

/// The last version a watcher saw.
struct Versions<V>(Option<V>);

impl<V> Default for Versions<V> {
    fn default() -> Self {
        Self(None)
    }
}

impl<V: PartialEq> Versions<V> {
    /// Bumps `changes` if `version` differs from the last one; `false` when the dashboard is
    /// gone.
    fn seen(&mut self, changes: &Weak<Changes>, version: V) -> bool {
        let Some(c) = changes.upgrade() else {
            return false;
        };
        if self.0.as_ref().is_some_and(|l| *l != version) {
            c.bump();
        }
        if self.0.is_none() {
            // what was cached before the first poll may predate changes it cannot see
            c.bump();
            c.set_watching(true);
        }
        self.0 = Some(version);
        true
    }
}
