//! Where the store lives: an embedded SQLite file (the default) or a PostgreSQL server, the
//! pools of both, and [`on_db!`](crate::on_db), which runs one piece of query code on
//! whichever it is.
//!
//! The store's SQL is written once for both engines: `$1, $2, ...` parameters (sqlx's SQLite
//! driver reads them too), `TRUE`/`FALSE`, `RETURNING id`, `ON CONFLICT ... DO`, 64-bit
//! integers only. Each engine has its own migrations (`migrations/sqlite/`,
//! `migrations/postgres/`), checked to give the same schema by `assessor/tests/schema.rs`.

use std::fmt;
use std::path::{Path, PathBuf};
use std::str::FromStr;

use sqlx::{PgPool, SqlitePool};

/// A database the store can open: `postgres://...` (or `postgresql://...`) is a server,
/// anything else a SQLite file (an optional `sqlite:` prefix is dropped).
#[derive(Clone, PartialEq, Eq)]
pub enum DbLocation {
    /// An SQLite file, created if missing.
    Sqlite(PathBuf),
    /// A PostgreSQL connection URL.
    Postgres(String),
}

impl DbLocation {
    /// Whether `s` names a PostgreSQL server.
    pub fn is_postgres_url(s: &str) -> bool {
        let lower = s.trim_start().to_ascii_lowercase();
        lower.starts_with("postgres://") || lower.starts_with("postgresql://")
    }

    /// The SQLite file, if it is one.
    pub fn sqlite_path(&self) -> Option<&Path> {
        match self {
            DbLocation::Sqlite(p) => Some(p),
            DbLocation::Postgres(_) => None,
        }
    }
}

impl From<&Path> for DbLocation {
    fn from(p: &Path) -> Self {
        DbLocation::Sqlite(p.to_path_buf())
    }
}

impl From<&PathBuf> for DbLocation {
    fn from(p: &PathBuf) -> Self {
        DbLocation::Sqlite(p.clone())
    }
}

impl From<&DbLocation> for DbLocation {
    fn from(l: &DbLocation) -> Self {
        l.clone()
    }
}

impl From<PathBuf> for DbLocation {
    fn from(p: PathBuf) -> Self {
        DbLocation::Sqlite(p)
    }
}

impl FromStr for DbLocation {
    type Err = String;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        if s.trim().is_empty() {
            return Err("an empty database location".into());
        }
        if Self::is_postgres_url(s) {
            return Ok(DbLocation::Postgres(s.trim().to_owned()));
        }
        let path = s
            .strip_prefix("sqlite://")
            .or_else(|| s.strip_prefix("sqlite:"));
        Ok(DbLocation::Sqlite(PathBuf::from(path.unwrap_or(s))))
    }
}

/// The location as a user may see it: a URL's password is replaced by `***`.
impl fmt::Display for DbLocation {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            DbLocation::Sqlite(p) => write!(f, "{}", p.display()),
            DbLocation::Postgres(url) => f.write_str(&redact_password(url)),
        }
    }
}

impl fmt::Debug for DbLocation {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        fmt::Display::fmt(self, f)
    }
}

/// The environment variable naming a PostgreSQL server for the tests (a URL whose user may
/// create databases); CI sets it. Without it the PostgreSQL halves of the tests say they
/// are skipped.
pub const TEST_POSTGRES_ENV: &str = "CUTLAB_TEST_POSTGRES";

/// A new, empty database with a unique name on the PostgreSQL server of `server_url` (whose
/// user may create databases): for tests and benchmarks that each want their own.
pub async fn scratch_postgres(server_url: &str, prefix: &str) -> sqlx::Result<DbLocation> {
    use sqlx::migrate::MigrateDatabase;
    use std::sync::atomic::{AtomicU64, Ordering};
    static NEXT: AtomicU64 = AtomicU64::new(0);
    let name = format!(
        "{prefix}_{}_{}_{}",
        std::process::id(),
        super::now_ns(),
        NEXT.fetch_add(1, Ordering::Relaxed)
    );
    let url = with_database(server_url, &name);
    sqlx::Postgres::create_database(&url).await?;
    Ok(DbLocation::Postgres(url))
}

/// The byte ranges of `url`'s `scheme://` and of its authority (`user:password@host:port`)
/// after it; `None` without a scheme.
fn scheme_and_authority(url: &str) -> Option<(std::ops::Range<usize>, std::ops::Range<usize>)> {
    let scheme_end = url.find("://")? + 3;
    let authority_len = url[scheme_end..]
        .find(['/', '?'])
        .unwrap_or(url.len() - scheme_end);
    Some((0..scheme_end, scheme_end..scheme_end + authority_len))
}

/// A scratch database ([`scratch_postgres`]) on the server `$CUTLAB_TEST_POSTGRES` names,
/// for a test's PostgreSQL half; `None`, saying the half is skipped, without one.
pub async fn test_postgres(prefix: &str) -> Option<DbLocation> {
    let Ok(server) = std::env::var(TEST_POSTGRES_ENV) else {
        eprintln!("skipped: {TEST_POSTGRES_ENV} names no PostgreSQL server");
        return None;
    };
    match scratch_postgres(&server, prefix).await {
        Ok(at) => Some(at),
        Err(e) => panic!("a scratch database on {TEST_POSTGRES_ENV}'s server: {e}"),
    }
}

/// `url` naming the database `name` instead of its own (its query kept).
fn with_database(url: &str, name: &str) -> String {
    let authority_end = scheme_and_authority(url).map_or(0, |(_, a)| a.end);
    let query = url[authority_end..]
        .find('?')
        .map_or("", |q| &url[authority_end + q..]);
    format!("{}/{name}{query}", &url[..authority_end])
}

/// `scheme://user:password@host/...` with the password replaced by `***`.
fn redact_password(url: &str) -> String {
    let Some((scheme, authority)) = scheme_and_authority(url) else {
        return url.to_owned();
    };
    let userinfo = &url[authority.clone()];
    match (userinfo.rfind('@'), userinfo.find(':')) {
        (Some(at), Some(colon)) if colon < at => format!(
            "{}{}:***{}",
            &url[scheme],
            &userinfo[..colon],
            &url[authority.start + at..]
        ),
        _ => url.to_owned(),
    }
}

/// The connection pool of either engine.
#[derive(Debug, Clone)]
pub enum Db {
    Sqlite(SqlitePool),
    Postgres(PgPool),
}

impl Db {
    /// The engine's name, for messages.
    pub fn engine(&self) -> &'static str {
        match self {
            Db::Sqlite(_) => "SQLite",
            Db::Postgres(_) => "PostgreSQL",
        }
    }
}

/// Runs `$body` with `$pool` bound to the `&SqlitePool` or the `&PgPool` of `$db` (a
/// [`&Db`](crate::store::Db)): the same query code, compiled for each engine.
///
/// ```
/// # async fn f(store: &cutlab_assessor::Store) -> Result<i64, sqlx::Error> {
/// let n: i64 = cutlab_assessor::on_db!(store.db(), pool => {
///     sqlx::query_scalar("SELECT COUNT(*) FROM users").fetch_one(pool).await
/// })?;
/// # Ok(n) }
/// ```
#[macro_export]
macro_rules! on_db {
    ($db:expr, $pool:ident => $body:expr) => {
        match $db {
            $crate::store::Db::Sqlite($pool) => $body,
            $crate::store::Db::Postgres($pool) => $body,
        }
    };
}

/// A transaction that writes: SQLite's takes the write lock up front (`BEGIN IMMEDIATE`, so
/// that two writers wait for each other instead of failing on an upgrade); PostgreSQL's is a
/// plain `BEGIN` (row locks, taken as it goes).
pub(crate) trait BeginWrite {
    type Database: sqlx::Database;

    async fn begin_write(&self) -> sqlx::Result<sqlx::Transaction<'static, Self::Database>>;
}

impl BeginWrite for SqlitePool {
    type Database = sqlx::Sqlite;

    async fn begin_write(&self) -> sqlx::Result<sqlx::Transaction<'static, sqlx::Sqlite>> {
        self.begin_with("BEGIN IMMEDIATE").await
    }
}

impl BeginWrite for PgPool {
    type Database = sqlx::Postgres;

    async fn begin_write(&self) -> sqlx::Result<sqlx::Transaction<'static, sqlx::Postgres>> {
        self.begin().await
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn locations_parse() {
        assert_eq!(
            "cutlab.db".parse::<DbLocation>().unwrap(),
            DbLocation::Sqlite("cutlab.db".into())
        );
        assert_eq!(
            "sqlite:out/x.db".parse::<DbLocation>().unwrap(),
            DbLocation::Sqlite("out/x.db".into())
        );
        assert_eq!(
            "sqlite://out/x.db".parse::<DbLocation>().unwrap(),
            DbLocation::Sqlite("out/x.db".into())
        );
        assert_eq!(
            "PostgreSQL://h/db".parse::<DbLocation>().unwrap(),
            DbLocation::Postgres("PostgreSQL://h/db".into())
        );
        assert!("  ".parse::<DbLocation>().is_err());
    }

    #[test]
    fn another_database_on_the_same_server() {
        assert_eq!(
            with_database("postgres://u:p@h:1/postgres?sslmode=disable", "x"),
            "postgres://u:p@h:1/x?sslmode=disable"
        );
        assert_eq!(with_database("postgres://h", "x"), "postgres://h/x");
        assert_eq!(with_database("postgres://h?a=b", "x"), "postgres://h/x?a=b");
    }

    #[test]
    fn passwords_are_not_shown() {
        let l: DbLocation = "postgres://ann:s3cr3t@db.example:5432/cutlab?sslmode=require"
            .parse()
            .unwrap();
        assert_eq!(
            l.to_string(),
            "postgres://ann:***@db.example:5432/cutlab?sslmode=require"
        );
        assert_eq!(format!("{l:?}"), l.to_string());
        let no_password: DbLocation = "postgres://ann@h/db".parse().unwrap();
        assert_eq!(no_password.to_string(), "postgres://ann@h/db");
        let no_user: DbLocation = "postgres://h:5432/db".parse().unwrap();
        assert_eq!(no_user.to_string(), "postgres://h:5432/db");
    }
}
