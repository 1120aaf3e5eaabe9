//! Attempts in progress (status `running`), for supervision: who, what, since when, and how
//! far the recording has grown.

use cutlab_assessor::store::{Role, now_ns};
use serde::Serialize;

use super::{ExerciseRef, UserRef};
use crate::AppState;
use crate::auth::CurrentUser;
use crate::error::AppError;

#[derive(Debug, Clone, Serialize)]
pub struct RunningAttempt {
    pub id: i64,
    pub trainee: UserRef,
    pub exercise: ExerciseRef,
    pub started_ns: i64,
    pub elapsed_s: f64,
    /// The recording's size so far (it is flushed every second).
    pub recording_bytes: Option<u64>,
    /// A station session of this server: its live view is `/station/{id}`.
    pub live: bool,
}

type Row = (i64, i64, String, i64, String, i64, Option<String>);

/// The running attempts `viewer` may see, oldest first.
pub async fn running(
    state: &AppState,
    viewer: &CurrentUser,
) -> Result<Vec<RunningAttempt>, AppError> {
    let base = "SELECT a.id, u.id, u.name, e.id, e.name, a.started_ns, a.recording_path FROM attempts a JOIN users u ON u.id = a.trainee_id JOIN exercises e ON e.id = a.exercise_id WHERE a.status = 'running'";
    let rows: Vec<Row> = cutlab_assessor::on_db!(state.store().db(), pool => {
        match viewer.role() {
            Role::Admin => sqlx::query_as(sqlx::AssertSqlSafe(format!("{base} ORDER BY a.started_ns"))).fetch_all(pool).await?,
            Role::Trainee => sqlx::query_as(sqlx::AssertSqlSafe(format!("{base} AND a.trainee_id = $1 ORDER BY a.started_ns"))).bind(viewer.id()).fetch_all(pool).await?,
            Role::Instructor => {
                sqlx::query_as(sqlx::AssertSqlSafe(format!(
                    "{base} AND (a.trainee_id = $1 OR a.trainee_id IN (SELECT m.user_id FROM cohort_members m JOIN cohorts c ON c.id = m.cohort_id WHERE c.instructor_id = $2)) ORDER BY a.started_ns"
                )))
                .bind(viewer.id())
                .bind(viewer.id())
                .fetch_all(pool)
                .await?
            }
        }
    });
    let now = now_ns();
    Ok(rows
        .into_iter()
        .map(
            |(id, uid, uname, eid, ename, started_ns, path)| RunningAttempt {
                id,
                trainee: UserRef {
                    id: uid,
                    name: uname,
                },
                exercise: ExerciseRef {
                    id: eid,
                    name: ename,
                },
                started_ns,
                elapsed_s: (now - started_ns).max(0) as f64 * 1e-9,
                recording_bytes: path
                    .and_then(|p| std::fs::metadata(p).ok())
                    .map(|m| m.len()),
                live: state.station().get(id).is_some(),
            },
        )
        .collect())
}
