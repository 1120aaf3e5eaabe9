//! The built-in exercise, always present so `cutlab assess` works on a fresh database.

use super::{Exercise, NewExercise, Store};
use crate::error::{AssessError, Result};
use crate::metrics::Better;
use crate::plan::ExpertPlan;
use crate::proficiency::{DEFAULT_K, Threshold};

/// The built-in exercise's name.
pub const BUILTIN_EXERCISE: &str = "chest-wall-incision";
/// Its scene.
pub const BUILTIN_SCENE: &str = "chest-wall";

/// Provisional hand-set thresholds of the built-in exercise, `(reference, limit)` per scored
/// metric, until expert attempts replace them ([`Store::thresholds_from_experts`]). Metrics
/// whose scale depends on the session script (smoothness) have none until then.
pub fn default_thresholds() -> Vec<Threshold> {
    use Better::*;
    [
        ("entry_error_m", LowerIsBetter, 0.001, 0.004),
        ("exit_error_m", LowerIsBetter, 0.001, 0.004),
        ("length_error_m", TwoSided, 0.0, 0.008),
        ("lateral_mean_m", LowerIsBetter, 0.0005, 0.002),
        ("lateral_max_m", LowerIsBetter, 0.0015, 0.004),
        ("fraction_cut_in_tolerance", HigherIsBetter, 0.95, 0.80),
        ("direction_error_deg", LowerIsBetter, 1.0, 5.0),
        ("depth_error_m", TwoSided, 0.0, 0.003),
        ("time_s", LowerIsBetter, 8.0, 20.0),
        ("path_length_m", LowerIsBetter, 0.15, 0.35),
        // the plan's force limit (the station's force bar shows it)
        ("peak_force_n", LowerIsBetter, 1.5, 2.5),
        ("cut_outside_corridor_m", LowerIsBetter, 0.0, 0.005),
    ]
    .into_iter()
    .map(|(key, better, reference, limit)| Threshold::fixed(key, better, reference, limit))
    .collect()
}

impl Store {
    /// Inserts the built-in exercise `chest-wall-incision` if missing (safe when several
    /// processes do it at once); returns it.
    pub async fn ensure_builtins(&self) -> Result<Exercise> {
        match self.exercise_by_name(BUILTIN_EXERCISE).await {
            Ok(e) => return Ok(e),
            Err(AssessError::NotFound(_)) => {}
            Err(e) => return Err(e),
        }
        let plan = ExpertPlan::chest_wall()?;
        let thresholds = default_thresholds();
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
