//! The built-in exercise, always present so `cutlab assess` works on a fresh database.

use super::{Exercise, NewExercise, Store};
use crate::error::{AssessError, Result};
use crate::exercise::ExercisePlan;
use crate::proficiency::DEFAULT_K;

/// The built-in exercise's name.
pub const BUILTIN_EXERCISE: &str = "chest-wall-incision";
/// Its scene.
pub const BUILTIN_SCENE: &str = "chest-wall";

impl Store {
    /// Inserts the built-in exercise `chest-wall-incision` if missing (safe when several
    /// processes do it at once); returns it.
    pub async fn ensure_builtins(&self) -> Result<Exercise> {
        match self.exercise_by_name(BUILTIN_EXERCISE).await {
            Ok(e) => return Ok(e),
            Err(AssessError::NotFound(_)) => {}
            Err(e) => return Err(e),
        }
        let plan = ExercisePlan::chest_wall()?;
        let thresholds = plan.kind_plan().default_thresholds();
        let new = NewExercise {
            name: BUILTIN_EXERCISE,
            scene: BUILTIN_SCENE,
            description: "A 60 mm incision 8 mm deep along x across the top of the chest wall",
            plan: &plan,
            thresholds: &thresholds,
            threshold_k: DEFAULT_K,
            exam_only: false,
        };
        match self.create_exercise(&new).await {
            Ok(e) => Ok(e),
            Err(AssessError::Conflict(_)) => self.exercise_by_name(BUILTIN_EXERCISE).await,
            Err(e) => Err(e),
        }
    }
}
