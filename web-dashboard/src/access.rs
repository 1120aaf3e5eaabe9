//! Who may see whom: an administrator everyone, an instructor the members of the cohorts
//! they lead, a trainee only themselves. Anything else is answered as if it did not exist
//! ([`AppError::NotFound`]), so ids of other people's data leak nothing.

use cutlab_assessor::store::{Attempt, Role, User};

use crate::AppState;
use crate::auth::CurrentUser;
use crate::error::AppError;

/// Whether `viewer` may see the data of user `target_id`.
pub async fn can_see_user(
    state: &AppState,
    viewer: &CurrentUser,
    target_id: i64,
) -> Result<bool, AppError> {
    Ok(match viewer.role() {
        Role::Admin => true,
        Role::Trainee => viewer.id() == target_id,
        Role::Instructor => {
            if viewer.id() == target_id {
                return Ok(true);
            }
            state
                .caches()
                .access
                .load_once((viewer.id(), target_id), || async {
                    let led: Option<i64> = cutlab_assessor::on_db!(state.store().db(), pool => sqlx::query_scalar("SELECT m.user_id FROM cohort_members m JOIN cohorts c ON c.id = m.cohort_id WHERE c.instructor_id = $1 AND m.user_id = $2 LIMIT 1")
                        .bind(viewer.id())
                        .bind(target_id)
                        .fetch_optional(pool).await)?;
                    Ok::<_, AppError>(led.is_some())
                })
                .await?
        }
    })
}

/// The user `target_id` if `viewer` may see them; else not found.
pub async fn visible_user(
    state: &AppState,
    viewer: &CurrentUser,
    target_id: i64,
) -> Result<User, AppError> {
    if !can_see_user(state, viewer, target_id).await? {
        return Err(AppError::NotFound);
    }
    state
        .caches()
        .users
        .load_once(target_id, || async {
            Ok(state.store().get_user(target_id).await?)
        })
        .await
}

/// The attempt `id` if `viewer` may see its trainee; else not found.
pub async fn visible_attempt(
    state: &AppState,
    viewer: &CurrentUser,
    id: i64,
) -> Result<Attempt, AppError> {
    let a = state.store().get_attempt(id).await?;
    if !can_see_user(state, viewer, a.trainee_id).await? {
        return Err(AppError::NotFound);
    }
    Ok(a)
}

/// The trainees `viewer` may see, by name: all (admin), their cohorts' members (instructor),
/// themselves (trainee).
pub async fn visible_trainees(
    state: &AppState,
    viewer: &CurrentUser,
) -> Result<Vec<User>, AppError> {
    let store = state.store();
    Ok(match viewer.role() {
        Role::Admin => store.list_users(Some(Role::Trainee)).await?,
        Role::Trainee => vec![viewer.user().clone()],
        Role::Instructor => {
            let ids: Vec<i64> = cutlab_assessor::on_db!(store.db(), pool => sqlx::query_scalar("SELECT DISTINCT m.user_id FROM cohort_members m JOIN cohorts c ON c.id = m.cohort_id JOIN users u ON u.id = m.user_id WHERE c.instructor_id = $1 AND u.role = 'trainee'")
                .bind(viewer.id())
                .fetch_all(pool).await)?;
            let mut users = Vec::with_capacity(ids.len());
            for id in ids {
                users.push(store.get_user(id).await?);
            }
            users.sort_by(|a, b| a.name.cmp(&b.name));
            users
        }
    })
}
