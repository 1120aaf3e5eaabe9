//! Users: instructors, trainees and administrators, with argon2id password hashes.

use argon2::Argon2;
use argon2::password_hash::rand_core::OsRng;
use argon2::password_hash::{PasswordHash, PasswordHasher, PasswordVerifier, SaltString};
use serde::{Deserialize, Serialize};

use super::{Store, conflict, now_ns};
use crate::error::{AssessError, Result};

/// What a user may do.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Role {
    Instructor,
    Trainee,
    Admin,
}

impl Role {
    pub fn as_str(self) -> &'static str {
        match self {
            Role::Instructor => "instructor",
            Role::Trainee => "trainee",
            Role::Admin => "admin",
        }
    }
}

impl std::str::FromStr for Role {
    type Err = AssessError;
    fn from_str(s: &str) -> Result<Self> {
        match s {
            "instructor" => Ok(Role::Instructor),
            "trainee" => Ok(Role::Trainee),
            "admin" => Ok(Role::Admin),
            _ => Err(AssessError::InvalidInput(format!(
                "unknown role {s:?} (instructor, trainee or admin)"
            ))),
        }
    }
}

impl std::fmt::Display for Role {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.as_str())
    }
}

/// A user (the password hash stays in the database).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct User {
    pub id: i64,
    pub name: String,
    pub role: Role,
    pub has_password: bool,
    pub created_ns: i64,
}

type UserRow = (i64, String, String, Option<String>, i64);

fn user(row: UserRow) -> Result<User> {
    Ok(User {
        id: row.0,
        name: row.1,
        role: row.2.parse()?,
        has_password: row.3.is_some(),
        created_ns: row.4,
    })
}

/// An argon2id PHC string for `password` with a random salt.
pub fn hash_password(password: &str) -> Result<String> {
    let salt = SaltString::generate(&mut OsRng);
    Argon2::default()
        .hash_password(password.as_bytes(), &salt)
        .map(|h| h.to_string())
        .map_err(|e| AssessError::Password(e.to_string()))
}

impl Store {
    /// Adds a user; `password` is hashed (argon2id). Names are unique.
    pub async fn create_user(
        &self,
        name: &str,
        role: Role,
        password: Option<&str>,
    ) -> Result<User> {
        let name = super::names::check_name(name)?;
        self.refuse_look_alike(name).await?;
        let hash = password.map(hash_password).transpose()?;
        let id: i64 = crate::on_db!(&self.db, pool => sqlx::query_scalar("INSERT INTO users (name, role, password_hash, created_ns) VALUES ($1, $2, $3, $4) RETURNING id")
            .bind(name)
            .bind(role.as_str())
            .bind(&hash)
            .bind(now_ns())
            .fetch_one(pool).await)
            .map_err(conflict(|| format!("a user named {name:?} exists")))?;
        self.get_user(id).await
    }

    /// Refuses a new name that looks like another user's ([`super::names::skeleton`]):
    /// `DR-KIM` beside the instructor `dr-kim`. The same name is left to the unique index.
    async fn refuse_look_alike(&self, name: &str) -> Result<()> {
        let names: Vec<String> = crate::on_db!(&self.db, pool => sqlx::query_scalar("SELECT name FROM users")
            .fetch_all(pool).await)?;
        let key = super::names::skeleton(name);
        match names
            .iter()
            .find(|n| n.as_str() != name && super::names::skeleton(n) == key)
        {
            // not a name this server takes (as a control character is not), whoever asks
            Some(other) => Err(AssessError::InvalidInput(format!(
                "the user name {name:?} looks like the existing {other:?}"
            ))),
            None => Ok(()),
        }
    }

    /// The user with `id`.
    pub async fn get_user(&self, id: i64) -> Result<User> {
        let row: Option<UserRow> = crate::on_db!(&self.db, pool => sqlx::query_as(
            "SELECT id, name, role, password_hash, created_ns FROM users WHERE id = $1",
        )
        .bind(id)
        .fetch_optional(pool).await)?;
        user(row.ok_or_else(|| AssessError::NotFound(format!("user {id}")))?)
    }

    /// The user named `name`.
    pub async fn user_by_name(&self, name: &str) -> Result<User> {
        let row: Option<UserRow> = crate::on_db!(&self.db, pool => sqlx::query_as(
            "SELECT id, name, role, password_hash, created_ns FROM users WHERE name = $1",
        )
        .bind(name)
        .fetch_optional(pool).await)?;
        user(row.ok_or_else(|| AssessError::NotFound(format!("user {name:?}")))?)
    }

    /// All users (of one role if given), by name.
    pub async fn list_users(&self, role: Option<Role>) -> Result<Vec<User>> {
        let rows: Vec<UserRow> = crate::on_db!(&self.db, pool => sqlx::query_as("SELECT id, name, role, password_hash, created_ns FROM users WHERE ($1 IS NULL OR role = $2) ORDER BY name")
            .bind(role.map(Role::as_str))
            .bind(role.map(Role::as_str))
            .fetch_all(pool).await)?;
        rows.into_iter().map(user).collect()
    }

    /// Sets (or replaces) a user's password.
    pub async fn set_password(&self, user_id: i64, password: &str) -> Result<()> {
        let hash = hash_password(password)?;
        let done = crate::on_db!(&self.db, pool => sqlx::query("UPDATE users SET password_hash = $1 WHERE id = $2")
            .bind(hash)
            .bind(user_id)
            .execute(pool).await.map(|r| r.rows_affected()))?;
        if done == 0 {
            return Err(AssessError::NotFound(format!("user {user_id}")));
        }
        Ok(())
    }

    /// The user if `name` exists, has a password and `password` matches it; `None` otherwise
    /// (unknown user, no password or a wrong one alike). Every answer costs one argon2
    /// verification, an unknown name's against a hash of nobody's ([`DECOY_HASH`]), so the
    /// time does not tell which names exist; the verifications run on blocking threads, at
    /// most [`VERIFYING_AT_ONCE`] at a time (each takes argon2's 19 MiB).
    pub async fn verify_password(&self, name: &str, password: &str) -> Result<Option<User>> {
        let row: Option<UserRow> = crate::on_db!(&self.db, pool => sqlx::query_as(
            "SELECT id, name, role, password_hash, created_ns FROM users WHERE name = $1",
        )
        .bind(name)
        .fetch_optional(pool).await)?;
        let stored = row.as_ref().and_then(|r| r.3.clone());
        let known = stored.is_some();
        let password = password.to_owned();
        let who = name.to_owned();
        let _turn = VERIFYING
            .acquire()
            .await
            .map_err(|e| AssessError::Password(e.to_string()))?;
        let matches = tokio::task::spawn_blocking(move || {
            let hash = match stored {
                Some(h) => h,
                None => decoy_hash()?.to_owned(),
            };
            let parsed = PasswordHash::new(&hash)
                .map_err(|e| AssessError::Password(format!("stored hash of {who:?}: {e}")))?;
            Ok::<_, AssessError>(
                Argon2::default()
                    .verify_password(password.as_bytes(), &parsed)
                    .is_ok(),
            )
        })
        .await
        .map_err(|e| AssessError::Password(format!("verifying a password: {e}")))??;
        match row {
            Some(row) if known && matches => Ok(Some(user(row)?)),
            _ => Ok(None),
        }
    }
}

/// Password verifications at once (see [`Store::verify_password`]).
pub const VERIFYING_AT_ONCE: usize = 4;
static VERIFYING: tokio::sync::Semaphore = tokio::sync::Semaphore::const_new(VERIFYING_AT_ONCE);

/// A hash of a random password nobody knows, made once: what an unknown name's password is
/// checked against, at the cost of a real one.
static DECOY_HASH: std::sync::OnceLock<std::result::Result<String, String>> =
    std::sync::OnceLock::new();

fn decoy_hash() -> Result<&'static str> {
    let made = DECOY_HASH.get_or_init(|| {
        let mut secret = [0u8; 32];
        getrandom::fill(&mut secret).map_err(|e| e.to_string())?;
        hash_password(&crate::recordings::hex(&secret)).map_err(|e| e.to_string())
    });
    made.as_deref()
        .map_err(|e| AssessError::Password(format!("the decoy hash: {e}")))
}
