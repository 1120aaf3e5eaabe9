//! The built-in exercises, always present so `cutlab assess` works on a fresh database:
//! `chest-wall-incision`, `pattern-cutting`, `elliptical-excision`, `body-wall-incision` and
//! `mini-thoracotomy`,
//! and the curriculum that orders them, `cutting-basics` (with progression).

use std::collections::BTreeSet;

use super::{CUTTING_BASICS, Exercise, NewExercise, Store};
use crate::error::{AssessError, Result};
use cutlab_scoring::exercise::{ExcisionPlan, ExercisePlan, FieldPlan, PatternPlan};
use cutlab_scoring::proficiency::DEFAULT_K;

/// The built-in exercise's name.
pub const BUILTIN_EXERCISE: &str = "chest-wall-incision";
/// Its scene.
pub const BUILTIN_SCENE: &str = "chest-wall";

/// The built-in pattern cutting exercise's name.
pub const PATTERN_EXERCISE: &str = "pattern-cutting";

/// The built-in elliptical excision of a skin lesion: its name.
pub const EXCISION_EXERCISE: &str = "elliptical-excision";

/// The built-in curved incision on the CT's body wall: its name.
pub const BODY_WALL_EXERCISE: &str = "body-wall-incision";

/// The built-in mini-thoracotomy: expose the heart through an intercostal space.
pub const FIELD_EXERCISE: &str = "mini-thoracotomy";

/// A built-in exercise: its name, scene, description, plan and its module's title in
/// `cutting-basics`.
#[derive(Debug, Clone)]
pub struct Builtin {
    pub name: &'static str,
    pub scene: &'static str,
    pub description: &'static str,
    pub plan: ExercisePlan,
    pub module: &'static str,
}

/// The built-in exercises, in the order of `cutting-basics`.
pub fn builtins() -> Result<Vec<Builtin>> {
    Ok(vec![
        Builtin {
            name: BUILTIN_EXERCISE,
            scene: BUILTIN_SCENE,
            description: "A 60 mm incision 8 mm deep along x across the top of the chest wall",
            plan: ExercisePlan::chest_wall()?,
            module: "Incision",
        },
        Builtin {
            name: PATTERN_EXERCISE,
            scene: "sheet",
            description: "FLS pattern cutting: cut the marked 40 mm circle out of the held sheet, along the mark",
            plan: ExercisePlan::Pattern(PatternPlan::builtin()?),
            module: "Pattern cutting",
        },
        Builtin {
            name: EXCISION_EXERCISE,
            scene: "skin-block",
            description: "Elliptical excision: incise a fusiform outline round the 8 mm pigmented lesion, 2 mm from its edge, 3.5 times as long as wide along the tension lines, into the fat",
            plan: ExercisePlan::Excision(ExcisionPlan::builtin()?),
            module: "Elliptical excision",
        },
        Builtin {
            name: BODY_WALL_EXERCISE,
            scene: "body-wall",
            description: "A curved transverse incision of 100 mm on a patient's abdominal wall (from a CT), 8 mm deep into the fat",
            plan: ExercisePlan::body_wall()?,
            module: "Curved incision on a patient",
        },
        Builtin {
            name: FIELD_EXERCISE,
            scene: "thorax",
            description: "Mini-thoracotomy: expose the front of the heart through an intercostal space with the shortest incision that gives a working view; scored on what the opened wound shows, wherever it is",
            plan: ExercisePlan::Field(FieldPlan::builtin()?),
            module: "Surgical field: mini-thoracotomy",
        },
    ])
}

impl Store {
    /// Inserts the built-in exercises if missing (safe when several processes do it at once);
    /// returns `chest-wall-incision`.
    pub async fn ensure_builtins(&self) -> Result<Exercise> {
        let mut made = Vec::new();
        for b in builtins()? {
            let (e, created) = self
                .ensure_exercise(b.name, b.scene, b.description, &b.plan)
                .await?;
            made.push(BuiltinModule {
                title: b.module,
                exercise: e,
                created,
            });
        }
        self.ensure_cutting_basics(&made).await?;
        Ok(made.swap_remove(0).exercise)
    }

    /// Makes the `cutting-basics` curriculum, one module per exercise in order, with
    /// progression, unless it exists. One that exists keeps an instructor's edits; a built-in
    /// exercise this call created (one a newer cutlab brings to an older database) joins its
    /// end as a module of its own, unless a module holds it already.
    async fn ensure_cutting_basics(&self, modules: &[BuiltinModule]) -> Result<()> {
        let made = self
            .create_curriculum(
                CUTTING_BASICS,
                "The cutting exercises in order, each opening when the one before is proficient",
            )
            .await;
        let c = match made {
            Ok(c) => c,
            Err(AssessError::Conflict(_)) => return self.append_new_builtins(modules).await,
            Err(e) => return Err(e),
        };
        for m in modules {
            self.add_module(c.id, m.title, &[m.exercise.id]).await?;
        }
        self.set_progression(c.id, true).await
    }

    /// Appends to an existing `cutting-basics` a module for each of `modules` created by this
    /// call that no module holds.
    async fn append_new_builtins(&self, modules: &[BuiltinModule]) -> Result<()> {
        if !modules.iter().any(|m| m.created) {
            return Ok(());
        }
        let c = self.curriculum_by_name(CUTTING_BASICS).await?;
        let held: BTreeSet<i64> = self
            .curriculum_exercise_ids(c.id)
            .await?
            .into_iter()
            .collect();
        for m in modules.iter().filter(|m| m.created) {
            if !held.contains(&m.exercise.id) {
                self.add_module(c.id, m.title, &[m.exercise.id]).await?;
            }
        }
        Ok(())
    }

    /// Inserts exercise `name` with `plan` and its kind's default thresholds if missing;
    /// returns it and whether this call created it.
    async fn ensure_exercise(
        &self,
        name: &str,
        scene: &str,
        description: &str,
        plan: &ExercisePlan,
    ) -> Result<(Exercise, bool)> {
        match self.exercise_by_name(name).await {
            Ok(e) => return Ok((e, false)),
            Err(AssessError::NotFound(_)) => {}
            Err(e) => return Err(e),
        }
        let thresholds = plan.kind_plan().default_thresholds();
        let new = NewExercise {
            name,
            scene,
            description,
            plan,
            thresholds: &thresholds,
            threshold_k: DEFAULT_K,
            exam_only: false,
        };
        match self.create_exercise(&new).await {
            Ok(e) => Ok((e, true)),
            Err(AssessError::Conflict(_)) => Ok((self.exercise_by_name(name).await?, false)),
            Err(e) => Err(e),
        }
    }
}

/// A built-in exercise as [`Store::ensure_builtins`] found or made it, with its module's
/// title in `cutting-basics`.
struct BuiltinModule {
    title: &'static str,
    exercise: Exercise,
    created: bool,
}
