//! The `pattern` kind: pattern cutting after the FLS/MISTELS task, a circle marked on a
//! held sheet cut out along the mark. Scored by the MISTELS rule
//! ([`crate::metrics::pattern`]); proficient after FLS when the piece is cut free within
//! 98 s with the whole cut within 2 mm of the mark (the default thresholds), on two
//! consecutive attempts (the store's rule for every exercise).

use nalgebra::Point3;
use serde::{Deserialize, Serialize};

use super::{Drawing, ExerciseKind, ExercisePlan, FormField, HandLine, PlanKey};
use crate::error::{Result, ScoreError};
use crate::geom;
use crate::input::AttemptData;
use crate::metrics::pattern::{self, Circle};
use crate::metrics::{Better, Metric, MetricSet, Values};
use crate::proficiency::Threshold;

/// How far past a whole turn the hand goes, so the cut closes (turns).
const OVERLAP_TURNS: f64 = 0.06;

/// A pattern cutting plan (SI units: metres, seconds, newtons).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PatternPlan {
    /// A name for reports.
    #[serde(default)]
    pub name: String,
    /// The scene the plan is for (e.g. `sheet`), informative.
    #[serde(default)]
    pub scene: Option<String>,
    /// The centre of the marked circle, on the surface (m).
    pub centre_m: [f64; 3],
    /// The marked circle's radius (m): 20 mm for FLS's 40 mm circle.
    pub radius_m: f64,
    /// The surface's outward normal (unit after normalisation; default +z).
    #[serde(default = "default_normal")]
    pub normal: [f64; 3],
    /// How deep the blade's tip goes below the surface (m): through the sheet.
    pub depth_m: f64,
    /// Where the field is seen from (m).
    pub viewpoint_m: [f64; 3],
    /// Where the hand starts round the circle, degrees from the plan's x axis (default -90:
    /// the side nearest the trainee).
    #[serde(default = "default_start")]
    pub start_deg: f64,
    /// How far from the mark the whole cut must stay (m), default 2 mm (FLS).
    #[serde(default = "default_tolerance")]
    pub tolerance_m: f64,
    /// The width of the marked line (m), default 1 mm.
    #[serde(default = "default_mark_width")]
    pub mark_width_m: f64,
    /// The MISTELS cutoff time (s), default 300.
    #[serde(default = "default_cutoff")]
    pub cutoff_s: f64,
    /// The force the tissue should not be loaded beyond (N), default 2.5 N.
    #[serde(default = "default_force_limit")]
    pub force_limit_n: f64,
}

fn default_normal() -> [f64; 3] {
    [0.0, 0.0, 1.0]
}
fn default_start() -> f64 {
    -90.0
}
fn default_tolerance() -> f64 {
    0.002
}
fn default_mark_width() -> f64 {
    0.001
}
fn default_cutoff() -> f64 {
    300.0
}
fn default_force_limit() -> f64 {
    2.5
}

/// The built-in `pattern-cutting` plan (TOML, embedded).
pub const PATTERN_PLAN_TOML: &str = include_str!("../../examples/pattern.toml");

impl PatternPlan {
    /// The built-in plan of `pattern-cutting`.
    pub fn builtin() -> Result<Self> {
        match ExercisePlan::from_toml(PATTERN_PLAN_TOML)? {
            ExercisePlan::Pattern(p) => Ok(p),
            other => Err(ScoreError::InvalidPlan(format!(
                "the built-in pattern plan is of kind {}",
                other.kind().as_str()
            ))),
        }
    }

    /// Normalises the normal and checks the plan.
    pub fn normalised(mut self) -> Result<Self> {
        self.check()?;
        self.normal = super::unit_normal(self.normal)?;
        Ok(self)
    }

    /// Rejects plans that cannot be assessed against, naming the field.
    pub fn check(&self) -> Result<()> {
        let bad = |m: &str| Err(ScoreError::InvalidPlan(m.into()));
        let mut numbers: Vec<f64> = [self.centre_m, self.normal, self.viewpoint_m].concat();
        numbers.extend([
            self.radius_m,
            self.depth_m,
            self.start_deg,
            self.tolerance_m,
            self.mark_width_m,
            self.cutoff_s,
            self.force_limit_n,
        ]);
        if !geom::finite(&numbers) {
            return bad("a number is not finite (NaN or infinite)");
        }
        if !(self.radius_m >= 0.002) {
            return bad("radius_m: the circle needs a radius of at least 2 mm");
        }
        if geom::unit(self.normal.into()).is_none() {
            return bad("normal: zero");
        }
        for (name, v) in [
            ("depth_m", self.depth_m),
            ("tolerance_m", self.tolerance_m),
            ("mark_width_m", self.mark_width_m),
            ("cutoff_s", self.cutoff_s),
            ("force_limit_n", self.force_limit_n),
        ] {
            if !(v > 0.0) {
                return bad(&format!("{name} must be > 0"));
            }
        }
        if self.mark_width_m >= self.radius_m {
            return bad("mark_width_m: the mark is wider than the circle's radius");
        }
        Ok(())
    }

    /// The circle as the metrics take it.
    pub fn circle(&self) -> Circle {
        Circle {
            centre_m: self.centre_m,
            normal: self.normal,
            radius_m: self.radius_m,
            cutoff_s: self.cutoff_s,
        }
    }

    /// Points every degree round the marked circle, from `start_deg`, `turns` times round,
    /// counter-clockwise seen from outside.
    pub fn circle_points(&self, turns: f64) -> Vec<[f64; 3]> {
        let (u, v) = geom::plane_basis(self.normal);
        let (c, start) = (Point3::from(self.centre_m), self.start_deg.to_radians());
        let steps = (turns * 360.0).ceil().max(1.0) as usize;
        (0..=steps)
            .map(|i| {
                let a = start + std::f64::consts::TAU * turns * i as f64 / steps as f64;
                (c + (u * a.cos() + v * a.sin()) * self.radius_m).into()
            })
            .collect()
    }
}

const DEFAULT_THRESHOLDS: [(&str, Better, f64, f64); 3] = [
    ("piece_freed", Better::HigherIsBetter, 1.0, 0.5),
    // FLS proficiency: at most 98 s, the whole cut within 2 mm of the line
    ("completion_time_s", Better::LowerIsBetter, 60.0, 98.0),
    (
        "pattern_max_deviation_m",
        Better::LowerIsBetter,
        0.0005,
        0.002,
    ),
];

const CENTRE: Option<&str> = Some("Centre of the marked circle, on the surface");
const VIEWPOINT: Option<&str> = Some("Viewpoint: the eye the field is seen from");

/// The form's fields, in the order of [`PatternPlan::slot`].
const FIELDS: [FormField; 11] = [
    FormField::mm("centre_x_mm", "x", CENTRE),
    FormField::mm("centre_y_mm", "y", CENTRE),
    FormField::mm("centre_z_mm", "z", CENTRE),
    FormField::mm("viewpoint_x_mm", "x", VIEWPOINT),
    FormField::mm("viewpoint_y_mm", "y", VIEWPOINT),
    FormField::mm("viewpoint_z_mm", "z", VIEWPOINT),
    FormField::mm("radius_mm", "Radius of the marked circle", None),
    FormField::mm("depth_mm", "Depth of the blade below the surface", None),
    FormField::mm("tolerance_mm", "Tolerance: the whole cut within", None),
    FormField {
        name: "cutoff_s",
        label: "Cutoff time (MISTELS)",
        unit: "s",
        factor: 1.0,
        group: None,
    },
    FormField {
        name: "force_limit_n",
        label: "Force limit: forces above it count as excessive",
        unit: "N",
        factor: 1.0,
        group: None,
    },
];

const KEYS: [PlanKey; 12] = [
    PlanKey::new("name", "text", "a name for reports (optional)"),
    PlanKey::new(
        "scene",
        "text",
        "the scene the plan is for, e.g. sheet (optional)",
    ),
    PlanKey::new(
        "centre_m",
        "[x, y, z] m",
        "the marked circle's centre, on the surface (required)",
    ),
    PlanKey::new(
        "radius_m",
        "m",
        "the marked circle's radius, at least 0.002 (required)",
    ),
    PlanKey::new(
        "normal",
        "[x, y, z]",
        "the surface's outward normal (default [0, 0, 1])",
    ),
    PlanKey::new(
        "depth_m",
        "m",
        "how deep the blade's tip goes below the surface, > 0 (required)",
    ),
    PlanKey::new(
        "viewpoint_m",
        "[x, y, z] m",
        "where the field is seen from (required)",
    ),
    PlanKey::new(
        "start_deg",
        "deg",
        "where the hand starts round the circle (default -90)",
    ),
    PlanKey::new(
        "tolerance_m",
        "m",
        "how far from the mark the whole cut must stay (default 0.002)",
    ),
    PlanKey::new(
        "mark_width_m",
        "m",
        "the width of the marked line (default 0.001)",
    ),
    PlanKey::new("cutoff_s", "s", "the MISTELS cutoff time (default 300)"),
    PlanKey::new(
        "force_limit_n",
        "N",
        "forces above it count as excessive (default 2.5)",
    ),
];

impl PatternPlan {
    /// The number form field `i` edits.
    fn slot(&mut self, i: usize) -> Option<&mut f64> {
        Some(match i {
            0..=2 => &mut self.centre_m[i],
            3..=5 => &mut self.viewpoint_m[i - 3],
            6 => &mut self.radius_m,
            7 => &mut self.depth_m,
            8 => &mut self.tolerance_m,
            9 => &mut self.cutoff_s,
            10 => &mut self.force_limit_n,
            _ => return None,
        })
    }
}

impl ExerciseKind for PatternPlan {
    fn check(&self) -> Result<()> {
        PatternPlan::check(self)
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

    /// Round the mark once and a little further, so the cut closes.
    fn hand_line(&self) -> HandLine {
        HandLine {
            line_m: self.circle_points(1.0 + OVERLAP_TURNS),
            normal: self.normal,
            depth_m: self.depth_m,
            viewpoint_m: self.viewpoint_m,
        }
    }

    fn metrics(&self) -> &'static [Metric] {
        pattern::METRICS
    }

    fn assess(&self, data: &AttemptData) -> Result<MetricSet> {
        self.check()?;
        let mut values = Values::default();
        pattern::assess(&self.circle(), data, &mut values);
        Ok(values.collect(pattern::METRICS))
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

    fn with_fields(&self, changed: &[(usize, f64)]) -> Result<ExercisePlan> {
        let plan = super::with_slots(self, changed, Self::slot);
        Ok(ExercisePlan::Pattern(plan.normalised()?))
    }

    fn form_note(&self) -> &'static str {
        "The mark is a circle; its start, normal and mark width are set in the plan text."
    }

    fn keys(&self) -> &'static [PlanKey] {
        &KEYS
    }

    fn drawing(&self) -> Drawing {
        Drawing {
            lines_m: vec![self.circle_points(1.0)],
            marks_m: vec![self.circle_points(1.0)],
            normal: self.normal,
            tolerance_m: self.tolerance_m,
            force_limit_n: self.force_limit_n,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_builtin_plan_is_fls_s_circle_and_bad_plans_name_the_field() {
        let plan = PatternPlan::builtin().unwrap();
        assert!((plan.radius_m - 0.02).abs() < 1e-12);
        let line = plan.hand_line().line_m;
        let (first, last) = (Point3::from(line[0]), Point3::from(line[line.len() - 1]));
        // past the start by the overlap: the cut closes
        let overlap = 2.0 * plan.radius_m * (std::f64::consts::PI * OVERLAP_TURNS).sin();
        assert!((nalgebra::distance(&first, &last) - overlap).abs() < 1e-9);
        for (field, bad) in [
            ("radius_m", plan.clone().with(|p| p.radius_m = 0.0)),
            ("depth_m", plan.clone().with(|p| p.depth_m = -1.0)),
            ("mark_width_m", plan.clone().with(|p| p.mark_width_m = 0.05)),
            (
                "not finite",
                plan.clone().with(|p| p.centre_m[0] = f64::NAN),
            ),
        ] {
            let e = bad.check().unwrap_err().to_string();
            assert!(e.contains(field), "{field}: {e}");
        }
        for (i, f) in FIELDS.iter().enumerate() {
            let v = plan.field(i) * 1.01 + 1e-3;
            let changed = ExercisePlan::Pattern(plan.clone())
                .kind_plan()
                .with_fields(&[(i, v)]);
            let ExercisePlan::Pattern(changed) = changed.unwrap() else {
                panic!("kind changed")
            };
            assert_eq!(changed.field(i), v, "{}", f.name);
        }
    }

    impl PatternPlan {
        fn with(mut self, f: impl FnOnce(&mut Self)) -> Self {
            f(&mut self);
            self
        }
    }
}
