//! The `field` kind (issue 62): expose a structure behind a wall through an incision the
//! trainee places (`mini-thoracotomy`: the heart through an intercostal space). The plan
//! holds the expert's incision, which guided mode draws and the synthetic hands follow, but an
//! attempt is scored on what its opened wound shows ([`crate::metrics::wound`]), not on its
//! distance from that line. Landmarks a surgeon palpates (the sternum's edge, the ribs) are
//! marked on the skin in every mode.

use nalgebra::{Point3, Vector3};
use serde::{Deserialize, Serialize};

use super::{Drawing, ExerciseKind, ExercisePlan, FormField, HandLine, PlanKey};
use crate::error::{Result, ScoreError};
use crate::geom;
use crate::input::AttemptData;
use crate::metrics::exposure::Ellipsoid;
use crate::metrics::wound::{self, Field};
use crate::metrics::{Better, Metric, MetricSet, Values};
use crate::proficiency::Threshold;
use cutlab_haptics::landmarks::Spaces;

/// A field plan (SI units: metres, newtons).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct FieldPlan {
    /// A name for reports.
    #[serde(default)]
    pub name: String,
    /// The scene the plan is for (e.g. `thorax`), informative.
    #[serde(default)]
    pub scene: Option<String>,
    /// The expert's incision on the skin (m), at least two points.
    pub incision_m: Vec<[f64; 3]>,
    /// How deep the expert's blade goes below the skin (m).
    pub depth_m: f64,
    /// The skin's outward normal (unit after normalisation; default +z).
    #[serde(default = "default_normal")]
    pub normal: [f64; 3],
    /// The wall's thickness under the incision: a cut this deep opened it (m).
    pub wall_m: f64,
    /// The structure to expose: an ellipsoid's centre (m) ...
    pub target_centre_m: [f64; 3],
    /// ... and its semi-axes along x, y, z (m).
    pub target_radii_m: [f64; 3],
    /// Where the field is seen from (m).
    pub viewpoint_m: [f64; 3],
    /// What the expert's incision shows of the target, opened (m^2): the field's reference.
    pub reference_area_m2: f64,
    /// The width a retractor spreads the trainee's wound to before the field is measured (m);
    /// none: the field is measured on the wound as the tissue's tension opened it.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub retractor_width_m: Option<f64>,
    /// Lines a surgeon finds by touch, marked on the skin in every mode (m).
    #[serde(default)]
    pub landmarks_m: Vec<Vec<[f64; 3]>>,
    /// Structures behind the wall not to touch (the lung): the blade's tip inside one is
    /// critical harm.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub spare: Vec<SpareStructure>,
    /// How far from the expert's line guided mode draws its band (m), default 2 mm.
    #[serde(default = "default_tolerance")]
    pub tolerance_m: f64,
    /// The force counted as excessive (N), default 3 N.
    #[serde(default = "default_force_limit")]
    pub force_limit_n: f64,
}

/// A structure to spare behind the wall: an ellipsoid (m).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SpareStructure {
    /// What it is (`lung`).
    pub name: String,
    /// Its centre (m).
    pub centre_m: [f64; 3],
    /// Its semi-axes along x, y and z (m).
    pub radii_m: [f64; 3],
}

fn default_normal() -> [f64; 3] {
    [0.0, 0.0, 1.0]
}
fn default_tolerance() -> f64 {
    0.002
}
fn default_force_limit() -> f64 {
    3.0
}

/// The built-in `mini-thoracotomy` plan (TOML, embedded).
pub const FIELD_PLAN_TOML: &str = include_str!("../../examples/mini-thoracotomy.toml");

impl FieldPlan {
    /// The built-in plan of `mini-thoracotomy`.
    pub fn builtin() -> Result<Self> {
        match ExercisePlan::from_toml(FIELD_PLAN_TOML)? {
            ExercisePlan::Field(p) => Ok(p),
            other => Err(ScoreError::InvalidPlan(format!(
                "the built-in field plan is of kind {}",
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
        let mut numbers: Vec<f64> = [
            self.normal,
            self.target_centre_m,
            self.target_radii_m,
            self.viewpoint_m,
        ]
        .concat();
        numbers.extend(self.incision_m.iter().flatten());
        numbers.extend(self.landmarks_m.iter().flatten().flatten());
        numbers.extend(
            self.spare
                .iter()
                .flat_map(|s| [s.centre_m, s.radii_m])
                .flatten(),
        );
        numbers.extend([
            self.depth_m,
            self.wall_m,
            self.reference_area_m2,
            self.tolerance_m,
            self.force_limit_n,
        ]);
        if !geom::finite(&numbers) {
            return bad("a number is not finite (NaN or infinite)");
        }
        if self.incision_m.len() < 2 {
            return bad("incision_m: needs at least two points");
        }
        if geom::unit(self.normal.into()).is_none() {
            return bad("normal: zero");
        }
        for (name, v) in [
            ("depth_m", self.depth_m),
            ("wall_m", self.wall_m),
            ("reference_area_m2", self.reference_area_m2),
            ("tolerance_m", self.tolerance_m),
            ("force_limit_n", self.force_limit_n),
        ] {
            if !(v > 0.0) {
                return bad(&format!("{name} must be > 0"));
            }
        }
        if let Some(w) = self.retractor_width_m
            && !(w.is_finite() && w > 0.0 && w <= 0.2)
        {
            return bad("retractor_width_m: above 0 and at most 0.2 m");
        }
        if !self.target_radii_m.iter().all(|&r| r > 0.0) {
            return bad("target_radii_m: every semi-axis must be > 0");
        }
        if let Some(s) = self
            .spare
            .iter()
            .find(|s| !s.radii_m.iter().all(|&r| r > 0.0))
        {
            return bad(&format!("spare {:?}: every semi-axis must be > 0", s.name));
        }
        Ok(())
    }

    /// The expert's incision's length (m).
    pub fn length_m(&self) -> f64 {
        let line: Vec<Point3<f64>> = self.incision_m.iter().map(|&p| p.into()).collect();
        geom::polyline_length(&line)
    }

    /// The spaces between the landmarks parallel to the expert's incision (the ribs either
    /// side of its intercostal space), if they frame it.
    pub fn spaces(&self) -> Option<Spaces> {
        let points = |line: &[[f64; 3]]| line.iter().map(|&p| p.into()).collect::<Vec<_>>();
        let marks: Vec<Vec<Point3<f64>>> = self.landmarks_m.iter().map(|m| points(m)).collect();
        Spaces::new(&points(&self.incision_m), &self.normal.into(), &marks)
    }

    /// What the metrics measure against.
    pub fn reference(&self) -> Field {
        Field {
            target: Ellipsoid {
                centre_m: self.target_centre_m.into(),
                radii_m: self.target_radii_m.into(),
            },
            eye_m: self.viewpoint_m.into(),
            normal: Vector3::from(self.normal),
            wall_m: self.wall_m,
            reference_area_m2: self.reference_area_m2,
            retracted: self.retractor_width_m.is_some(),
            spare: self
                .spare
                .iter()
                .map(|s| Ellipsoid {
                    centre_m: s.centre_m.into(),
                    radii_m: s.radii_m.into(),
                })
                .collect(),
        }
    }

    /// The number form field `i` edits.
    fn slot(&mut self, i: usize) -> Option<&mut f64> {
        Some(match i {
            0..=2 => &mut self.target_centre_m[i],
            3..=5 => &mut self.viewpoint_m[i - 3],
            6 => &mut self.depth_m,
            7 => &mut self.wall_m,
            8 => &mut self.reference_area_m2,
            9 => &mut self.tolerance_m,
            10 => &mut self.force_limit_n,
            _ => return None,
        })
    }
}

const TARGET: Option<&str> = Some("Target: the centre of the structure to expose");
const VIEWPOINT: Option<&str> = Some("Viewpoint: the eye the field is seen from");

/// The form's fields, in the order of [`FieldPlan::slot`].
const FIELDS: [FormField; 11] = [
    FormField::mm("target_x_mm", "x", TARGET),
    FormField::mm("target_y_mm", "y", TARGET),
    FormField::mm("target_z_mm", "z", TARGET),
    FormField::mm("viewpoint_x_mm", "x", VIEWPOINT),
    FormField::mm("viewpoint_y_mm", "y", VIEWPOINT),
    FormField::mm("viewpoint_z_mm", "z", VIEWPOINT),
    FormField::mm(
        "depth_mm",
        "Depth of the expert's blade below the skin",
        None,
    ),
    FormField::mm("wall_mm", "Wall thickness: a cut this deep opened it", None),
    FormField {
        name: "reference_area_mm2",
        label: "The expert's field: the target's area the expert's incision shows",
        unit: "mm²",
        factor: 1e6,
        group: None,
    },
    FormField::mm("tolerance_mm", "Band drawn round the expert's line", None),
    FormField {
        name: "force_limit_n",
        label: "Force limit: forces above it count as excessive",
        unit: "N",
        factor: 1.0,
        group: None,
    },
];

const KEYS: [PlanKey; 14] = [
    PlanKey::new("name", "text", "a name for reports (optional)"),
    PlanKey::new(
        "scene",
        "text",
        "the scene the plan is for, e.g. thorax (optional)",
    ),
    PlanKey::new(
        "incision_m",
        "list of [x, y, z] m",
        "the expert's incision on the skin, at least 2 points (required)",
    ),
    PlanKey::new(
        "depth_m",
        "m",
        "how deep the expert's blade goes below the skin (required)",
    ),
    PlanKey::new(
        "normal",
        "[x, y, z]",
        "the skin's outward normal (default [0, 0, 1])",
    ),
    PlanKey::new(
        "wall_m",
        "m",
        "the wall's thickness: a cut this deep opened it (required)",
    ),
    PlanKey::new(
        "target_centre_m",
        "[x, y, z] m",
        "the centre of the structure to expose, an ellipsoid (required)",
    ),
    PlanKey::new(
        "target_radii_m",
        "[x, y, z] m",
        "its semi-axes along x, y and z (required)",
    ),
    PlanKey::new(
        "viewpoint_m",
        "[x, y, z] m",
        "where the field is seen from (required)",
    ),
    PlanKey::new(
        "reference_area_m2",
        "m^2",
        "what the expert's incision shows of the target (cutlab plan field) (required)",
    ),
    PlanKey::new(
        "retractor_width_m",
        "m",
        "the width a retractor spreads the wound to before the field is measured (optional: else the wound as it opened)",
    ),
    PlanKey::new(
        "landmarks_m",
        "list of lines of [x, y, z] m",
        "lines a surgeon finds by touch, marked on the skin in every mode; those along the incision (ribs) listed head first count its space (optional)",
    ),
    PlanKey::new(
        "tolerance_m",
        "m",
        "the band drawn round the expert's line in guided mode (default 0.002)",
    ),
    PlanKey::new(
        "force_limit_n",
        "N",
        "forces above it count as excessive (default 3)",
    ),
];

impl ExerciseKind for FieldPlan {
    fn check(&self) -> Result<()> {
        FieldPlan::check(self)
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
        wound::METRICS
    }

    fn assess(&self, data: &AttemptData) -> Result<MetricSet> {
        self.check()?;
        let mut values = Values::default();
        let middle = wound::assess(&self.reference(), data, &mut values);
        match (self.spaces(), middle) {
            (Some(spaces), Some(middle)) => values.set("incision_space", spaces.position(&middle)),
            (None, _) => values.missing(
                &["incision_space"],
                "the plan marks no landmarks either side of its incision",
            ),
            (_, None) => values.missing(&["incision_space"], "nothing was cut on the skin"),
        }
        Ok(values.collect(wound::METRICS))
    }

    /// The field at least half the expert's, the incision at most 1.4 times the expert's
    /// length, the wall opened, one brush of a rib at most, nothing critical.
    fn default_thresholds(&self) -> Vec<Threshold> {
        use Better::*;
        let length = self.length_m();
        vec![
            Threshold::fixed("field_of_expert", HigherIsBetter, 1.0, 0.5),
            Threshold::fixed("incision_length_m", LowerIsBetter, length, 1.4 * length),
            Threshold::fixed("wall_opened", HigherIsBetter, 1.0, 0.5),
            Threshold::fixed("bone_contacts", LowerIsBetter, 0.0, 1.5),
            Threshold::fixed("critical_damage", LowerIsBetter, 0.0, 0.5),
        ]
    }

    fn form_fields(&self) -> &'static [FormField] {
        &FIELDS
    }

    fn field(&self, i: usize) -> f64 {
        super::slot_value(self, i, Self::slot)
    }

    fn with_fields(&self, changed: &[(usize, f64)]) -> Result<ExercisePlan> {
        let plan = super::with_slots(self, changed, Self::slot);
        Ok(ExercisePlan::Field(plan.normalised()?))
    }

    fn form_note(&self) -> &'static str {
        "The expert's incision, the target's size and the landmarks are set in the plan text."
    }

    fn keys(&self) -> &'static [PlanKey] {
        &KEYS
    }

    fn trainee_places_incision(&self) -> bool {
        true
    }

    fn drawing(&self) -> Drawing {
        Drawing {
            lines_m: vec![self.incision_m.clone()],
            marks_m: self.landmarks_m.clone(),
            normal: self.normal,
            tolerance_m: self.tolerance_m,
            force_limit_n: self.force_limit_n,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The built-in plan reads; every form field writes its own number; every threshold
    /// names a scored metric of the kind; a bad plan is refused naming the field.
    #[test]
    fn the_builtin_plan_reads_and_its_fields_and_thresholds_fit() {
        let plan = FieldPlan::builtin().unwrap();
        assert!((plan.length_m() - 0.05).abs() < 1e-9);
        for i in 0..FIELDS.len() {
            let v = plan.field(i) * 1.01 + 1e-4;
            let changed = plan.with_fields(&[(i, v)]).unwrap();
            assert_eq!(changed.kind_plan().field(i), v, "{}", FIELDS[i].name);
        }
        for t in plan.default_thresholds() {
            let m = plan.metrics().iter().find(|m| m.key == t.key).unwrap();
            assert!(m.scored && m.better == t.better, "{}", t.key);
        }
        let mut bad = plan.clone();
        bad.target_radii_m[1] = 0.0;
        assert!(
            bad.check()
                .unwrap_err()
                .to_string()
                .contains("target_radii_m")
        );
        let mut bad = plan;
        bad.incision_m.truncate(1);
        assert!(bad.check().unwrap_err().to_string().contains("incision_m"));
    }

    /// The incision's space is counted from the built-in plan's ribs: the expert's line in
    /// space 0, the 5th space (27.5 mm lower) at +1, the rib below at +0.5; without a cut, or
    /// without landmarks, it is missing, not a number.
    #[test]
    fn the_incision_is_placed_among_the_ribs() {
        use crate::input::CutSample;
        let plan = FieldPlan::builtin().unwrap();
        let at = |plan: &FieldPlan, y: f64| {
            let cuts = (0..=50)
                .map(|k| CutSample {
                    t_s: f64::from(k) * 0.1,
                    tip_m: [-0.02 + 0.001 * f64::from(k), y, -0.045],
                    edge_dir: [0.0, 0.0, 1.0],
                    depth_m: 0.045,
                    stroke: Some(0),
                })
                .collect();
            let data = AttemptData {
                cuts,
                ..AttemptData::default()
            };
            let set = plan.assess(&data).unwrap();
            set.iter()
                .find(|v| v.key == "incision_space")
                .unwrap()
                .value
        };
        let space = |y| at(&plan, y).unwrap();
        assert!(space(-0.0025).abs() < 1e-9);
        assert!((space(-0.030) - 1.0).abs() < 1e-9, "{}", space(-0.030));
        assert!((space(-0.015) - 0.5).abs() < 1e-9);
        assert!((space(0.0225) + 1.0).abs() < 1e-9, "{}", space(0.0225));
        let bare = FieldPlan {
            landmarks_m: Vec::new(),
            ..plan.clone()
        };
        assert_eq!(at(&bare, -0.0025), None);
        let none = plan.assess(&AttemptData::default()).unwrap();
        assert_eq!(
            none.iter()
                .find(|v| v.key == "incision_space")
                .unwrap()
                .value,
            None
        );
    }
}
