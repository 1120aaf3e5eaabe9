//! The `incision` kind: a line cut to a depth (`chest-wall-incision`). Its plan is
//! [`IncisionPlan`]; an attempt is measured on every metric of [`METRICS`]: the incision
//! against the planned line, the path, safety and the surgical field.

mod plan;

pub use crate::incision_plan::IncisionPlan;
pub use plan::{BODY_WALL_PLAN_TOML, CHEST_WALL_PLAN_TOML};

use super::{Drawing, ExerciseKind, ExercisePlan, FormField, HandLine, PlanKey};
use crate::error::Result;
use crate::input::AttemptData;
use crate::metrics::{Better, METRICS, Metric, MetricSet, Values, field, incision, path, safety};
use crate::proficiency::Threshold;

/// Provisional hand-set thresholds, `(reference, limit)` per scored metric, until expert
/// attempts replace them. Metrics whose scale depends on the session script (smoothness)
/// have none until then.
const DEFAULT_THRESHOLDS: [(&str, Better, f64, f64); 12] = {
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
};

const ENTRY: Option<&str> = Some("Entry: where the incision starts, on the surface");
const EXIT: Option<&str> = Some("Exit: where it ends");
const VIEWPOINT: Option<&str> = Some("Viewpoint: the eye the target is seen from");

/// The form's fields, in the order of [`IncisionPlan::field`]'s slots.
const FIELDS: [FormField; 13] = [
    FormField::mm("entry_x_mm", "x", ENTRY),
    FormField::mm("entry_y_mm", "y", ENTRY),
    FormField::mm("entry_z_mm", "z", ENTRY),
    FormField::mm("exit_x_mm", "x", EXIT),
    FormField::mm("exit_y_mm", "y", EXIT),
    FormField::mm("exit_z_mm", "z", EXIT),
    FormField::mm("viewpoint_x_mm", "x", VIEWPOINT),
    FormField::mm("viewpoint_y_mm", "y", VIEWPOINT),
    FormField::mm("viewpoint_z_mm", "z", VIEWPOINT),
    FormField::mm("depth_mm", "Depth below the surface", None),
    FormField::mm("tolerance_mm", "Tolerance: on the line within", None),
    FormField::mm(
        "corridor_mm",
        "Corridor half-width: cuts beyond it damage tissue",
        None,
    ),
    FormField {
        name: "force_limit_n",
        label: "Force limit: forces above it count as excessive",
        unit: "N",
        factor: 1.0,
        group: None,
    },
];

/// The keys of the plan's text form.
const KEYS: [PlanKey; 13] = [
    PlanKey::new("name", "text", "a name for reports (optional)"),
    PlanKey::new(
        "scene",
        "text",
        "the scene the plan is for, e.g. chest-wall (informative, optional)",
    ),
    PlanKey::new(
        "entry_m",
        "[x, y, z] m",
        "where the incision starts, on the surface (required)",
    ),
    PlanKey::new(
        "exit_m",
        "[x, y, z] m",
        "where it ends, on the surface (required)",
    ),
    PlanKey::new(
        "incision_m",
        "list of [x, y, z] m",
        "the planned line on the surface from entry to exit, at least 2 points (default: the straight segment)",
    ),
    PlanKey::new(
        "depth_m",
        "m",
        "the planned depth below the surface, > 0 (required)",
    ),
    PlanKey::new(
        "normal",
        "[x, y, z]",
        "the surface's outward normal at the incision; depth is measured along −normal (default [0, 0, 1])",
    ),
    PlanKey::new(
        "approach_dir",
        "[x, y, z]",
        "the direction the blade moves entering the tissue (default −normal)",
    ),
    PlanKey::new(
        "target_m",
        "list of [x, y, z] m",
        "points on the target that must become visible through the opening (may be empty: then visibility is not measured)",
    ),
    PlanKey::new(
        "viewpoint_m",
        "[x, y, z] m",
        "where the target is seen from (required)",
    ),
    PlanKey::new(
        "tolerance_m",
        "m",
        "how far from the planned line still counts as on it (default 0.002)",
    ),
    PlanKey::new(
        "corridor_half_width_m",
        "m",
        "half the width of the corridor cuts may stay in without damage (default 0.005)",
    ),
    PlanKey::new(
        "force_limit_n",
        "N",
        "forces above it count as excessive: time above it, events (default 2.5); the pass limit on the peak force is the exercise's threshold",
    ),
];

impl IncisionPlan {
    /// The number form field `i` edits.
    fn slot(&mut self, i: usize) -> Option<&mut f64> {
        Some(match i {
            0..=2 => &mut self.entry_m[i],
            3..=5 => &mut self.exit_m[i - 3],
            6..=8 => &mut self.viewpoint_m[i - 6],
            9 => &mut self.depth_m,
            10 => &mut self.tolerance_m,
            11 => &mut self.corridor_half_width_m,
            12 => &mut self.force_limit_n,
            _ => return None,
        })
    }
}

impl ExerciseKind for IncisionPlan {
    fn check(&self) -> Result<()> {
        IncisionPlan::check(self)
    }

    fn name(&self) -> &str {
        &self.name
    }

    fn scene(&self) -> Option<&str> {
        self.scene.as_deref()
    }

    fn depth_m(&self) -> f64 {
        self.depth_m
    }

    fn tolerance_m(&self) -> f64 {
        self.tolerance_m
    }

    fn force_limit_n(&self) -> f64 {
        self.force_limit_n
    }

    fn hand_line(&self) -> HandLine {
        HandLine {
            line_m: self.incision_m.clone(),
            normal: self.normal,
            depth_m: self.depth_m,
            viewpoint_m: self.viewpoint_m,
        }
    }

    fn metrics(&self) -> &'static [Metric] {
        METRICS
    }

    fn assess(&self, data: &AttemptData) -> Result<MetricSet> {
        self.check()?;
        let mut values = Values::default();
        incision::assess(
            self,
            &data.cuts,
            &data.poses,
            data.device.as_deref(),
            &mut values,
        );
        path::assess(&data.poses, &path::PathParams::default(), &mut values);
        safety::assess(self, &data.forces, &data.cuts, &mut values);
        field::assess(self, data.surface.as_ref(), &mut values);
        Ok(values.collect(METRICS))
    }

    fn default_thresholds(&self) -> Vec<Threshold> {
        super::fixed_thresholds(&DEFAULT_THRESHOLDS)
    }

    fn form_fields(&self) -> &'static [FormField] {
        &FIELDS
    }

    fn field(&self, i: usize) -> f64 {
        super::slot_value(self, i, Self::slot)
    }

    /// Changing the entry or the exit replaces the planned line by the straight one between
    /// them ([`ExerciseKind::form_note`]).
    fn with_fields(&self, changed: &[(usize, f64)]) -> Result<ExercisePlan> {
        let mut plan = super::with_slots(self, changed, Self::slot);
        if plan.entry_m != self.entry_m || plan.exit_m != self.exit_m {
            plan.incision_m.clear();
        }
        Ok(plan.normalised()?.into())
    }

    fn form_note(&self) -> &'static str {
        "Changing the entry or the exit makes the planned line the straight one between them (a curved line needs the plan text)."
    }

    fn keys(&self) -> &'static [PlanKey] {
        &KEYS
    }

    fn drawing(&self) -> Drawing {
        Drawing {
            lines_m: vec![self.incision_m.clone()],
            marks_m: Vec::new(),
            normal: self.normal,
            tolerance_m: self.tolerance_m,
            force_limit_n: self.force_limit_n,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Every form field reads and writes its own number, and every scored threshold names a
    /// metric of the kind.
    #[test]
    fn fields_and_thresholds_name_what_they_set() {
        let plan = IncisionPlan::chest_wall().unwrap();
        for (i, f) in FIELDS.iter().enumerate() {
            let v = plan.field(i) + 1e-3;
            let changed = plan
                .with_fields(&[(i, v)])
                .unwrap()
                .into_incision()
                .unwrap();
            assert_eq!(changed.field(i), v, "{}", f.name);
            for j in (0..FIELDS.len()).filter(|&j| j != i) {
                assert_eq!(
                    changed.field(j),
                    plan.field(j),
                    "{} moved {}",
                    f.name,
                    FIELDS[j].name
                );
            }
        }
        for t in plan.default_thresholds() {
            let m = plan.metrics().iter().find(|m| m.key == t.key).unwrap();
            assert!(m.scored && m.better == t.better, "{}", t.key);
        }
    }
}
