//! Cohorts of trainees and their instructor.

use serde::{Deserialize, Serialize};

use super::{Store, User, conflict, now_ns};
use crate::error::{AssessError, Result};

/// A group of users.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Cohort {
    pub id: i64,
    pub name: String,
    pub instructor_id: Option<i64>,
    pub created_ns: i64,
}

type CohortRow = (i64, String, Option<i64>, i64);

fn cohort((id, name, instructor_id, created_ns): CohortRow) -> Cohort {
    Cohort {
        id,
        name,
        instructor_id,
        created_ns,
    }
}

impl Store {
    /// Adds a cohort (unique name), optionally led by an instructor.
    pub async fn create_cohort(&self, name: &str, instructor_id: Option<i64>) -> Result<Cohort> {
        let name = super::text::label("a cohort's name", name, super::text::MAX_LABEL_CHARS)?;
        if let Some(i) = instructor_id {
            self.get_user(i).await?;
        }
        let id: i64 = crate::on_db!(&self.db, pool => sqlx::query_scalar(
            "INSERT INTO cohorts (name, instructor_id, created_ns) VALUES ($1, $2, $3) RETURNING id",
        )
        .bind(name)
        .bind(instructor_id)
        .bind(now_ns())
        .fetch_one(pool).await)
        .map_err(conflict(|| format!("a cohort named {name:?} exists")))?;
        self.get_cohort(id).await
    }

    pub async fn get_cohort(&self, id: i64) -> Result<Cohort> {
        let row: Option<CohortRow> = crate::on_db!(&self.db, pool => sqlx::query_as("SELECT id, name, instructor_id, created_ns FROM cohorts WHERE id = $1")
                .bind(id)
                .fetch_optional(pool).await)?;
        row.map(cohort)
            .ok_or_else(|| AssessError::NotFound(format!("cohort {id}")))
    }

    pub async fn cohort_by_name(&self, name: &str) -> Result<Cohort> {
        let row: Option<CohortRow> = crate::on_db!(&self.db, pool => sqlx::query_as(
            "SELECT id, name, instructor_id, created_ns FROM cohorts WHERE name = $1",
        )
        .bind(name)
        .fetch_optional(pool).await)?;
        row.map(cohort)
            .ok_or_else(|| AssessError::NotFound(format!("cohort {name:?}")))
    }

    pub async fn list_cohorts(&self) -> Result<Vec<Cohort>> {
        let rows: Vec<CohortRow> = crate::on_db!(&self.db, pool => sqlx::query_as("SELECT id, name, instructor_id, created_ns FROM cohorts ORDER BY name")
                .fetch_all(pool).await)?;
        Ok(rows.into_iter().map(cohort).collect())
    }

    /// Puts a user in a cohort (joining twice is a no-op).
    pub async fn join_cohort(&self, cohort_id: i64, user_id: i64) -> Result<()> {
        self.get_cohort(cohort_id).await?;
        self.get_user(user_id).await?;
        crate::on_db!(&self.db, pool => sqlx::query("INSERT INTO cohort_members (cohort_id, user_id, joined_ns) VALUES ($1, $2, $3) ON CONFLICT (cohort_id, user_id) DO NOTHING")
            .bind(cohort_id)
            .bind(user_id)
            .bind(now_ns())
            .execute(pool).await.map(|r| r.rows_affected()))?;
        Ok(())
    }

    /// The members of a cohort, by name.
    pub async fn cohort_members(&self, cohort_id: i64) -> Result<Vec<User>> {
        let ids: Vec<i64> = crate::on_db!(&self.db, pool => sqlx::query_scalar("SELECT u.id FROM users u JOIN cohort_members m ON m.user_id = u.id WHERE m.cohort_id = $1 ORDER BY u.name").bind(cohort_id).fetch_all(pool).await)?;
        let mut out = Vec::with_capacity(ids.len());
        for id in ids {
            out.push(self.get_user(id).await?);
        }
        Ok(out)
    }
}
