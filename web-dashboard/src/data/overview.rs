//! The cohort overview: trainees x exercises with attempts, standing and trials to
//! proficiency.

use std::collections::BTreeMap;

use cutlab_assessor::store::{Cohort, Role};
use serde::Serialize;

use super::{ExerciseRef, ProficiencySummary, UserRef};
use crate::AppState;
use crate::auth::CurrentUser;
use crate::error::AppError;

#[derive(Debug, Serialize)]
pub struct CohortOverview {
    pub cohort: Cohort,
    pub instructor: Option<UserRef>,
    pub exercises: Vec<ExerciseRef>,
    pub trainees: Vec<TraineeRow>,
}

#[derive(Debug, Serialize)]
pub struct TraineeRow {
    pub trainee: UserRef,
    /// One per exercise, in the order of `exercises`.
    pub cells: Vec<Cell>,
}

#[derive(Debug, Serialize)]
pub struct Cell {
    pub exercise_id: i64,
    /// Every attempt (running and unscored ones too).
    pub attempts: u32,
    pub proficiency: ProficiencySummary,
    pub last_score: Option<f64>,
}

/// The cohorts `viewer` leads (all for an administrator; a trainee has none to oversee).
pub async fn cohorts_of(state: &AppState, viewer: &CurrentUser) -> Result<Vec<Cohort>, AppError> {
    let all = state.store().list_cohorts().await?;
    Ok(match viewer.role() {
        Role::Admin => all,
        Role::Instructor => all
            .into_iter()
            .filter(|c| c.instructor_id == Some(viewer.id()))
            .collect(),
        Role::Trainee => Vec::new(),
    })
}

type Row = (i64, i64, String, Option<bool>, bool, Option<f64>);
/// Per (trainee, exercise): attempts, the scored attempts' passes, the last score.
type CellAcc = (u32, Vec<bool>, Option<f64>);

/// The grid of one cohort.
pub async fn cohort_overview(state: &AppState, cohort: Cohort) -> Result<CohortOverview, AppError> {
    let store = state.store();
    let instructor = match cohort.instructor_id {
        Some(id) => Some(UserRef::from(&store.get_user(id).await?)),
        None => None,
    };
    let exercises: Vec<ExerciseRef> = store
        .list_exercises()
        .await?
        .into_iter()
        .map(|e| ExerciseRef {
            id: e.id,
            name: e.name,
        })
        .collect();
    let members: Vec<UserRef> = store
        .cohort_members(cohort.id)
        .await?
        .iter()
        .filter(|u| u.role == Role::Trainee)
        .map(UserRef::from)
        .collect();
    let rows: Vec<Row> = cutlab_assessor::on_db!(store.db(), pool => sqlx::query_as(
        "SELECT a.trainee_id, a.exercise_id, a.status, a.passed, a.scored, a.score FROM attempts a JOIN cohort_members m ON m.user_id = a.trainee_id \
         WHERE m.cohort_id = $1 AND a.expert = FALSE ORDER BY a.started_ns, a.id",
    )
    .bind(cohort.id)
    .fetch_all(pool).await)?;
    // (trainee, exercise) -> (attempts, scored passes, last score)
    let mut cells: BTreeMap<(i64, i64), CellAcc> = BTreeMap::new();
    for (trainee, exercise, status, passed, scored, score) in rows {
        let c = cells.entry((trainee, exercise)).or_default();
        c.0 += 1;
        if scored && status == "complete" {
            c.1.push(passed.unwrap_or(false));
            c.2 = score;
        }
    }
    let trainees = members
        .into_iter()
        .map(|t| {
            let cells = exercises
                .iter()
                .map(|e| {
                    let (attempts, passes, last_score) =
                        cells.remove(&(t.id, e.id)).unwrap_or_default();
                    Cell {
                        exercise_id: e.id,
                        attempts,
                        proficiency: ProficiencySummary::of(passes, attempts > 0),
                        last_score,
                    }
                })
                .collect();
            TraineeRow { trainee: t, cells }
        })
        .collect();
    Ok(CohortOverview {
        cohort,
        instructor,
        exercises,
        trainees,
    })
}

/// The grids of every cohort `viewer` oversees.
pub async fn overview(
    state: &AppState,
    viewer: &CurrentUser,
) -> Result<Vec<CohortOverview>, AppError> {
    let mut out = Vec::new();
    for c in cohorts_of(state, viewer).await? {
        out.push(cohort_overview(state, c).await?);
    }
    Ok(out)
}
