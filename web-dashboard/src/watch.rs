//! Watches the database for commits, so that the caches ([`crate::cache`]) hold until the
//! data changes rather than for a fixed time.
//!
//! A connection of its own, which never writes, polls SQLite's `PRAGMA data_version` every
//! [`POLL`]: the value changes when any other connection (the dashboard's pool, a
//! `cutlab session` in another process) has committed since the last poll. Each change bumps
//! the generation of [`Changes`]. The task ends with the dashboard (it holds only a weak
//! reference); on an error it stops vouching for the caches (short times to live again) and
//! retries. An in-memory database has no file that another connection could share, so it is
//! not watched.

use std::sync::{Arc, Weak};
use std::time::Duration;

use sqlx::{Connection, SqlitePool};

use crate::cache::Changes;

/// How often the watcher asks.
pub const POLL: Duration = Duration::from_millis(100);
/// Wait after an error before connecting again.
const RETRY: Duration = Duration::from_secs(1);

/// Starts the watcher on the current Tokio runtime (none: nothing is watched).
pub(crate) fn spawn(pool: &SqlitePool, changes: &Arc<Changes>) {
    let Ok(runtime) = tokio::runtime::Handle::try_current() else {
        tracing::debug!("no runtime: the database is not watched; caches use short times to live");
        return;
    };
    let options = pool.connect_options();
    let changes = Arc::downgrade(changes);
    runtime.spawn(async move {
        while changes.strong_count() > 0 {
            match watch(&options, &changes).await {
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
async fn watch(
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
    let mut last: Option<i64> = None;
    loop {
        let version: i64 = sqlx::query_scalar("PRAGMA data_version")
            .fetch_one(&mut conn)
            .await?;
        let Some(c) = changes.upgrade() else {
            return Ok(());
        };
        if last.is_some_and(|l| l != version) {
            c.bump();
        }
        if last.is_none() {
            // what was cached before the first poll may predate changes it cannot see
            c.bump();
            c.set_watching(true);
        }
        last = Some(version);
        drop(c);
        tokio::time::sleep(POLL).await;
    }
}
