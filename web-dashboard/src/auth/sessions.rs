//! Login sessions in the database (`login_sessions`): the SHA-256 of the cookie's token, the
//! user, the CSRF token of the session's forms, and an expiry.

use cutlab_assessor::store::{Role, User, now_ns};

use super::AuthSession;
use super::tokens::{random_token, token_hash};
use crate::AppState;
use crate::error::AppError;

/// How long a login lasts.
pub const SESSION_TTL_NS: i64 = 12 * 3600 * 1_000_000_000;

type Row = (i64, String, String, Option<String>, i64, String);

/// A new session for `user`; returns the cookie's token (the database keeps only its hash).
pub async fn create(state: &AppState, user: &User) -> Result<String, AppError> {
    let token = random_token()?;
    let csrf = random_token()?;
    let now = now_ns();
    cutlab_assessor::on_db!(state.store().db(), pool => {
        // expired sessions go when someone logs in
        sqlx::query("DELETE FROM login_sessions WHERE expires_ns < $1")
            .bind(now)
            .execute(pool)
            .await?;
        sqlx::query("INSERT INTO login_sessions (token_sha256, user_id, csrf_token, created_ns, expires_ns) VALUES ($1, $2, $3, $4, $5)")
            .bind(token_hash(&token))
            .bind(user.id)
            .bind(&csrf)
            .bind(now)
            .bind(now + SESSION_TTL_NS)
            .execute(pool)
            .await?;
    });
    Ok(token)
}

/// The live session of a cookie token, if any.
pub async fn lookup(state: &AppState, token: &str) -> Result<Option<AuthSession>, AppError> {
    if token.len() != 64 || !token.bytes().all(|c| c.is_ascii_hexdigit()) {
        return Ok(None);
    }
    let hash = token_hash(token);
    let cache = &state.caches().sessions;
    if let Some(s) = cache.get(&hash) {
        return Ok(Some(s));
    }
    let stamp = cache.stamp();
    let row: Option<Row> = cutlab_assessor::on_db!(state.store().db(), pool => sqlx::query_as(
        "SELECT u.id, u.name, u.role, u.password_hash, u.created_ns, s.csrf_token FROM login_sessions s JOIN users u ON u.id = s.user_id WHERE s.token_sha256 = $1 AND s.expires_ns > $2",
    )
    .bind(&hash)
    .bind(now_ns())
    .fetch_optional(pool).await)?;
    let Some((id, name, role, password_hash, created_ns, csrf)) = row else {
        return Ok(None);
    };
    let role: Role = role
        .parse()
        .map_err(|e: cutlab_assessor::AssessError| AppError::Internal(e.to_string()))?;
    let user = User {
        id,
        name,
        role,
        has_password: password_hash.is_some(),
        created_ns,
    };
    let s = AuthSession {
        user,
        csrf,
        token_hash: hash.clone(),
    };
    cache.put(hash, s.clone(), stamp);
    Ok(Some(s))
}

/// Ends a session.
pub async fn delete(state: &AppState, token_hash: &str) -> Result<(), AppError> {
    state.caches().sessions.remove(&token_hash.to_owned());
    cutlab_assessor::on_db!(state.store().db(), pool => sqlx::query("DELETE FROM login_sessions WHERE token_sha256 = $1")
        .bind(token_hash)
        .execute(pool).await.map(|_| ()))?;
    Ok(())
}

/// Whether the session whose token hashes to `token_hash` is still live (not logged out,
/// not expired).
pub async fn alive(state: &AppState, token_hash: &str) -> Result<bool, AppError> {
    if state
        .caches()
        .sessions
        .get(&token_hash.to_owned())
        .is_some()
    {
        return Ok(true);
    }
    let found: Option<i64> = cutlab_assessor::on_db!(state.store().db(), pool => sqlx::query_scalar(
        "SELECT user_id FROM login_sessions WHERE token_sha256 = $1 AND expires_ns > $2",
    )
    .bind(token_hash)
    .bind(now_ns())
    .fetch_optional(pool).await)?;
    Ok(found.is_some())
}

/// Whether `user_id` has a live session whose token's hash starts with `prefix` (what a
/// replay grant names, [`super::grants`]).
pub async fn alive_by_prefix(
    state: &AppState,
    user_id: i64,
    prefix: &str,
) -> Result<bool, AppError> {
    let hashes: Vec<String> = cutlab_assessor::on_db!(state.store().db(), pool => sqlx::query_scalar(
        "SELECT token_sha256 FROM login_sessions WHERE user_id = $1 AND expires_ns > $2",
    )
    .bind(user_id)
    .bind(now_ns())
    .fetch_all(pool).await)?;
    Ok(!prefix.is_empty() && hashes.iter().any(|h| h.starts_with(prefix)))
}

/// How often a long-lived answer (an event stream, a station's socket) looks whether its
/// session still lives.
pub const ALIVE_EVERY: std::time::Duration = std::time::Duration::from_secs(1);

/// Completes once the session of `token_hash` has ended (logged out or expired): what a
/// stream of that session ends with. A database that cannot answer ends nothing.
pub async fn ended(state: &AppState, token_hash: &str) {
    loop {
        tokio::time::sleep(ALIVE_EVERY).await;
        if let Ok(false) = alive(state, token_hash).await {
            return;
        }
    }
}
