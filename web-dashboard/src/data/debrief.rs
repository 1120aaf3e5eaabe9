//! Debriefing: instructors' comments on an attempt and their sign-off (tables
//! `attempt_comments`, `attempt_signoffs`).

use cutlab_assessor::store::now_ns;
use serde::Serialize;

use super::UserRef;
use crate::AppState;
use crate::error::AppError;

/// The longest comment kept.
pub const MAX_COMMENT_CHARS: usize = 4000;

#[derive(Debug, Clone, Serialize)]
pub struct Comment {
    pub id: i64,
    pub author: UserRef,
    pub body: String,
    pub created_ns: i64,
}

#[derive(Debug, Clone, Serialize)]
pub struct SignOff {
    pub instructor: UserRef,
    pub signed_ns: i64,
}

pub async fn comments(state: &AppState, attempt_id: i64) -> Result<Vec<Comment>, AppError> {
    let rows: Vec<(i64, i64, String, String, i64)> = sqlx::query_as(
        "SELECT c.id, u.id, u.name, c.body, c.created_ns FROM attempt_comments c JOIN users u ON u.id = c.author_id WHERE c.attempt_id = ? ORDER BY c.created_ns, c.id",
    )
    .bind(attempt_id)
    .fetch_all(state.store().pool())
    .await?;
    Ok(rows
        .into_iter()
        .map(|(id, uid, name, body, created_ns)| Comment {
            id,
            author: UserRef { id: uid, name },
            body,
            created_ns,
        })
        .collect())
}

/// Adds a comment (trimmed, not empty, at most [`MAX_COMMENT_CHARS`]).
pub async fn add_comment(
    state: &AppState,
    attempt_id: i64,
    author_id: i64,
    body: &str,
) -> Result<(), AppError> {
    let body = body.trim();
    if body.is_empty() {
        return Err(AppError::BadRequest("an empty comment".into()));
    }
    if body.chars().count() > MAX_COMMENT_CHARS {
        return Err(AppError::BadRequest(format!(
            "a comment has at most {MAX_COMMENT_CHARS} characters"
        )));
    }
    sqlx::query("INSERT INTO attempt_comments (attempt_id, author_id, body, created_ns) VALUES (?, ?, ?, ?)")
        .bind(attempt_id)
        .bind(author_id)
        .bind(body)
        .bind(now_ns())
        .execute(state.store().pool())
        .await?;
    Ok(())
}

pub async fn sign_off(
    state: &AppState,
    attempt_id: i64,
    instructor_id: i64,
) -> Result<(), AppError> {
    let done = sqlx::query("INSERT INTO attempt_signoffs (attempt_id, instructor_id, signed_ns) VALUES (?, ?, ?) ON CONFLICT (attempt_id) DO NOTHING")
        .bind(attempt_id)
        .bind(instructor_id)
        .bind(now_ns())
        .execute(state.store().pool())
        .await?;
    if done.rows_affected() == 0 {
        return Err(AppError::Conflict(format!(
            "attempt {attempt_id} is already signed off"
        )));
    }
    Ok(())
}

pub async fn signoff(state: &AppState, attempt_id: i64) -> Result<Option<SignOff>, AppError> {
    let row: Option<(i64, String, i64)> = sqlx::query_as("SELECT u.id, u.name, s.signed_ns FROM attempt_signoffs s JOIN users u ON u.id = s.instructor_id WHERE s.attempt_id = ?")
        .bind(attempt_id)
        .fetch_optional(state.store().pool())
        .await?;
    Ok(row.map(|(id, name, signed_ns)| SignOff {
        instructor: UserRef { id, name },
        signed_ns,
    }))
}
