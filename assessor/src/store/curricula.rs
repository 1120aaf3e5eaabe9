//! Curricula: ordered modules, each an ordered list of exercises.

use serde::{Deserialize, Serialize};

use super::{BeginWrite, Store, conflict, now_ns, text};
use crate::error::{AssessError, Result};

/// A curriculum.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Curriculum {
    pub id: i64,
    pub name: String,
    pub description: String,
    /// Proficiency-based progression: each exercise opens when the one before it is proficient
    /// (see [`Store::exercise_access`]).
    pub progression: bool,
}

type CurriculumRow = (i64, String, String, bool);

fn curriculum((id, name, description, progression): CurriculumRow) -> Curriculum {
    Curriculum {
        id,
        name,
        description,
        progression,
    }
}

/// A module of a curriculum, with its exercises in order.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Module {
    pub id: i64,
    pub curriculum_id: i64,
    /// 1-based order within the curriculum.
    pub position: i64,
    pub name: String,
    pub exercise_ids: Vec<i64>,
}

impl Store {
    pub async fn create_curriculum(&self, name: &str, description: &str) -> Result<Curriculum> {
        let name = text::label("a curriculum's name", name, text::MAX_LABEL_CHARS)?;
        let description = text::text(
            "a curriculum's description",
            description,
            text::MAX_DESCRIPTION_CHARS,
        )?;
        let id: i64 = crate::on_db!(&self.db, pool => sqlx::query_scalar(
            "INSERT INTO curricula (name, description, created_ns) VALUES ($1, $2, $3) RETURNING id",
        )
        .bind(name)
        .bind(description)
        .bind(now_ns())
        .fetch_one(pool).await)
        .map_err(conflict(|| format!("a curriculum named {name:?} exists")))?;
        Ok(Curriculum {
            id,
            name: name.into(),
            description: description.into(),
            progression: false,
        })
    }

    pub async fn get_curriculum(&self, id: i64) -> Result<Curriculum> {
        let row: Option<CurriculumRow> = crate::on_db!(&self.db, pool => sqlx::query_as("SELECT id, name, description, progression FROM curricula WHERE id = $1")
                .bind(id)
                .fetch_optional(pool).await)?;
        row.map(curriculum)
            .ok_or_else(|| AssessError::NotFound(format!("curriculum {id}")))
    }

    pub async fn curriculum_by_name(&self, name: &str) -> Result<Curriculum> {
        let row: Option<CurriculumRow> = crate::on_db!(&self.db, pool => sqlx::query_as("SELECT id, name, description, progression FROM curricula WHERE name = $1")
                .bind(name)
                .fetch_optional(pool).await)?;
        row.map(curriculum)
            .ok_or_else(|| AssessError::NotFound(format!("curriculum {name:?}")))
    }

    pub async fn list_curricula(&self) -> Result<Vec<Curriculum>> {
        let rows: Vec<CurriculumRow> = crate::on_db!(&self.db, pool => sqlx::query_as("SELECT id, name, description, progression FROM curricula ORDER BY name")
                .fetch_all(pool).await)?;
        Ok(rows.into_iter().map(curriculum).collect())
    }

    /// Turns proficiency-based progression on or off for a curriculum.
    pub async fn set_progression(&self, curriculum_id: i64, progression: bool) -> Result<()> {
        let done = crate::on_db!(&self.db, pool => sqlx::query(
            "UPDATE curricula SET progression = $1 WHERE id = $2",
        )
        .bind(progression)
        .bind(curriculum_id)
        .execute(pool).await.map(|r| r.rows_affected()))?;
        if done == 0 {
            return Err(AssessError::NotFound(format!("curriculum {curriculum_id}")));
        }
        Ok(())
    }

    /// Appends a module with `exercise_ids` (in that order) to a curriculum.
    pub async fn add_module(
        &self,
        curriculum_id: i64,
        name: &str,
        exercise_ids: &[i64],
    ) -> Result<Module> {
        let name = text::label("a module's name", name, text::MAX_LABEL_CHARS)?;
        for &e in exercise_ids {
            self.get_exercise(e).await?;
        }
        let (id, position) = crate::on_db!(&self.db, pool => {
            let mut tx = pool.begin_write().await?;
            let exists: Option<i64> = sqlx::query_scalar("SELECT id FROM curricula WHERE id = $1")
                .bind(curriculum_id)
                .fetch_optional(&mut *tx)
                .await?;
            if exists.is_none() {
                return Err(AssessError::NotFound(format!("curriculum {curriculum_id}")));
            }
            let position: i64 = sqlx::query_scalar(
                "SELECT COALESCE(MAX(position), 0) + 1 FROM modules WHERE curriculum_id = $1",
            )
            .bind(curriculum_id)
            .fetch_one(&mut *tx)
            .await?;
            let id: i64 = sqlx::query_scalar(
                "INSERT INTO modules (curriculum_id, position, name) VALUES ($1, $2, $3) RETURNING id",
            )
            .bind(curriculum_id)
            .bind(position)
            .bind(name)
            .fetch_one(&mut *tx)
            .await?;
            for (i, &e) in exercise_ids.iter().enumerate() {
                sqlx::query(
                    "INSERT INTO module_exercises (module_id, position, exercise_id) VALUES ($1, $2, $3)",
                )
                .bind(id)
                .bind(i as i64 + 1)
                .bind(e)
                .execute(&mut *tx)
                .await?;
            }
            tx.commit().await?;
            (id, position)
        });
        Ok(Module {
            id,
            curriculum_id,
            position,
            name: name.into(),
            exercise_ids: exercise_ids.to_vec(),
        })
    }

    /// The exercises of a curriculum's modules, in the modules' order and each module's.
    pub async fn curriculum_exercise_ids(&self, curriculum_id: i64) -> Result<Vec<i64>> {
        let modules = self.curriculum_modules(curriculum_id).await?;
        Ok(modules.into_iter().flat_map(|m| m.exercise_ids).collect())
    }

    /// A curriculum's modules in order, each with its exercises in order.
    pub async fn curriculum_modules(&self, curriculum_id: i64) -> Result<Vec<Module>> {
        let rows: Vec<(i64, i64, String)> = crate::on_db!(&self.db, pool => sqlx::query_as(
            "SELECT id, position, name FROM modules WHERE curriculum_id = $1 ORDER BY position",
        )
        .bind(curriculum_id)
        .fetch_all(pool).await)?;
        let mut out = Vec::with_capacity(rows.len());
        for (id, position, name) in rows {
            let exercise_ids: Vec<i64> = crate::on_db!(&self.db, pool => sqlx::query_scalar(
                "SELECT exercise_id FROM module_exercises WHERE module_id = $1 ORDER BY position",
            )
            .bind(id)
            .fetch_all(pool).await)?;
            out.push(Module {
                id,
                curriculum_id,
                position,
                name,
                exercise_ids,
            });
        }
        Ok(out)
    }
}
