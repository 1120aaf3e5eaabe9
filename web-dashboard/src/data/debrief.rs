//! Debriefing: instructors' comments on an attempt and their sign-off (tables
//! `attempt_comments`, `attempt_signoffs`).

use cutlab_assessor::store::now_ns;
use serde::Serialize;

use super::UserRef;
use crate::AppState;
use crate::error::AppError;

/// The longest comment kept.
pub const MAX_COMMENT_CHARS: usize = cutlab_assessor::store::text::MAX_NOTE_CHARS;

#[derive(Debug, Clone, Serialize)]
pub struct Comment {
    pub id: i64,
    pub author: UserRef,
    pub body: String,
    pub created_ns: i64,
    /// The moment of the attempt the comment is pinned to (a review note), simulated time
    /// from the recording's start, nanoseconds; none for a comment on the whole attempt.
    pub at_ns: Option<i64>,
}

/// The latest moment a note may be pinned to: a day of simulated time, far beyond any
/// attempt.
pub const MAX_MOMENT_NS: i64 = 86_400 * 1_000_000_000;

/// A moment of an attempt as an instructor types it, or as rerun's viewer shows it:
/// seconds (`"12.5"`, `"+1.700s"`) or minutes and seconds (`"1:02.5"`). Empty: none.
pub fn parse_moment(text: &str) -> Result<Option<i64>, AppError> {
    let t = text.trim();
    if t.is_empty() {
        return Ok(None);
    }
    let bad = || {
        AppError::BadRequest(format!(
            "{t:?} is not a moment of the attempt: seconds (12.5) or minutes:seconds (1:02.5)"
        ))
    };
    let plain = t.strip_prefix('+').unwrap_or(t);
    let plain = plain.strip_suffix('s').unwrap_or(plain).trim();
    let number = |s: &str| -> Result<f64, AppError> {
        // digits and one point only: no signs, exponents, "inf" or "NaN"
        if s.is_empty() || !s.bytes().all(|c| c.is_ascii_digit() || c == b'.') {
            return Err(bad());
        }
        s.parse::<f64>().map_err(|_| bad())
    };
    let seconds = match plain.split_once(':') {
        Some((m, s)) => {
            let s = number(s)?;
            if s >= 60.0 {
                return Err(bad());
            }
            number(m)? * 60.0 + s
        }
        None => number(plain)?,
    };
    let ns = (seconds * 1e9).round();
    if !(0.0..=MAX_MOMENT_NS as f64).contains(&ns) {
        return Err(bad());
    }
    Ok(Some(ns as i64))
}

/// `ns` as the attempt page shows a moment: `m:ss.sss`.
pub fn moment_label(ns: i64) -> String {
    let ms = ns / 1_000_000;
    format!("{}:{:02}.{:03}", ms / 60_000, (ms / 1000) % 60, ms % 1000)
}

#[derive(Debug, Clone, Serialize)]
pub struct SignOff {
    pub instructor: UserRef,
    pub signed_ns: i64,
}

pub async fn comments(state: &AppState, attempt_id: i64) -> Result<Vec<Comment>, AppError> {
    let rows: Vec<(i64, i64, String, String, i64, Option<i64>)> = cutlab_assessor::on_db!(state.store().db(), pool => sqlx::query_as(
        "SELECT c.id, u.id, u.name, c.body, c.created_ns, c.at_ns FROM attempt_comments c JOIN users u ON u.id = c.author_id WHERE c.attempt_id = $1 ORDER BY c.created_ns, c.id",
    )
    .bind(attempt_id)
    .fetch_all(pool).await)?;
    Ok(rows
        .into_iter()
        .map(|(id, uid, name, body, created_ns, at_ns)| Comment {
            id,
            author: UserRef { id: uid, name },
            body,
            created_ns,
            at_ns,
        })
        .collect())
}

/// Adds a comment (trimmed, not empty, at most [`MAX_COMMENT_CHARS`], by the store's one text
/// policy), pinned to the moment `at_ns` of the attempt if given (see [`parse_moment`]).
pub async fn add_comment(
    state: &AppState,
    attempt_id: i64,
    author_id: i64,
    body: &str,
    at_ns: Option<i64>,
) -> Result<(), AppError> {
    let body = cutlab_assessor::store::text::text("a comment", body, MAX_COMMENT_CHARS)?;
    if body.is_empty() {
        return Err(AppError::BadRequest("an empty comment".into()));
    }
    if at_ns.is_some_and(|t| !(0..=MAX_MOMENT_NS).contains(&t)) {
        return Err(AppError::BadRequest(
            "a note's moment is outside the attempt".into(),
        ));
    }
    cutlab_assessor::on_db!(state.store().db(), pool => sqlx::query("INSERT INTO attempt_comments (attempt_id, author_id, body, created_ns, at_ns) VALUES ($1, $2, $3, $4, $5)")
        .bind(attempt_id)
        .bind(author_id)
        .bind(body)
        .bind(now_ns())
        .bind(at_ns)
        .execute(pool).await.map(|_| ()))?;
    Ok(())
}

pub async fn sign_off(
    state: &AppState,
    attempt_id: i64,
    instructor_id: i64,
) -> Result<(), AppError> {
    let done = cutlab_assessor::on_db!(state.store().db(), pool => sqlx::query("INSERT INTO attempt_signoffs (attempt_id, instructor_id, signed_ns) VALUES ($1, $2, $3) ON CONFLICT (attempt_id) DO NOTHING")
        .bind(attempt_id)
        .bind(instructor_id)
        .bind(now_ns())
        .execute(pool).await.map(|r| r.rows_affected()))?;
    if done == 0 {
        return Err(AppError::Conflict(format!(
            "attempt {attempt_id} is already signed off"
        )));
    }
    Ok(())
}

pub async fn signoff(state: &AppState, attempt_id: i64) -> Result<Option<SignOff>, AppError> {
    let row: Option<(i64, String, i64)> = cutlab_assessor::on_db!(state.store().db(), pool => sqlx::query_as("SELECT u.id, u.name, s.signed_ns FROM attempt_signoffs s JOIN users u ON u.id = s.instructor_id WHERE s.attempt_id = $1")
        .bind(attempt_id)
        .fetch_optional(pool).await)?;
    Ok(row.map(|(id, name, signed_ns)| SignOff {
        instructor: UserRef { id, name },
        signed_ns,
    }))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn moments_read_as_typed_or_as_the_viewer_shows_them() {
        let s = 1_000_000_000;
        assert_eq!(parse_moment("").ok(), Some(None));
        assert_eq!(parse_moment(" 12.5 ").ok(), Some(Some(12 * s + s / 2)));
        assert_eq!(parse_moment("+1.700s").ok(), Some(Some(1_700_000_000)));
        assert_eq!(parse_moment("1:02.5").ok(), Some(Some(62 * s + s / 2)));
        for bad in [
            "-1", "NaN", "inf", "1e3", "1:60", "1:2:3", ":", "abc", "99999999",
        ] {
            assert!(parse_moment(bad).is_err(), "{bad}");
        }
        assert_eq!(moment_label(62 * s + s / 2), "1:02.500");
        assert_eq!(moment_label(1_700_000_000), "0:01.700");
    }
}
