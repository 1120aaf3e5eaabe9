//! The `excision` kind: elliptical (fusiform) excision of a skin lesion, an outline incised
//! round it with a margin, along the skin's tension lines, down into the fat. Measured by
//! [`crate::metrics::excision`]; the targets and their sources are in
//! `docs/guide/assessment.md`.
//!
//! The planned outline is the classic fusiform one: two circular arcs meeting at the apexes,
//! `2 L` long along the long axis and `2 w` wide, `w = r + margin` (the lesion's radius `r`)
//! and `L = k w` (the planned length to width `k`). Each arc has radius
//! `R = (L² + w²) / (2 w)` about a centre `R - w` beyond the axis; the apex angle is
//! `2 atan(L / (R - w))`.

use nalgebra::{Point3, Vector3};
use serde::{Deserialize, Serialize};

use super::{Drawing, ExerciseKind, ExercisePlan, FormField, HandLine, PlanKey};
use crate::error::{Result, ScoreError};
use crate::geom;
use crate::input::AttemptData;
use crate::metrics::excision::{self, Excision};
use crate::metrics::{Better, Metric, MetricSet, Values};
use crate::proficiency::Threshold;

/// How far past its start the hand goes round the outline, so the cut closes (m).
const OVERLAP_M: f64 = 0.006;

/// An elliptical excision plan (SI units: metres, seconds, newtons).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ExcisionPlan {
    /// A name for reports.
    #[serde(default)]
    pub name: String,
    /// The scene the plan is for (e.g. `skin-block`), informative.
    #[serde(default)]
    pub scene: Option<String>,
    /// The lesion's centre, on the surface (m).
    pub lesion_centre_m: [f64; 3],
    /// The lesion's radius (m).
    pub lesion_radius_m: f64,
    /// The surface's outward normal (unit after normalisation; default +z).
    #[serde(default = "default_normal")]
    pub normal: [f64; 3],
    /// The outline's long axis: along the skin's tension lines (default +x).
    #[serde(default = "default_axis")]
    pub long_axis: [f64; 3],
    /// The planned margin from the lesion's edge to the incision (m), default 2 mm.
    #[serde(default = "default_margin")]
    pub margin_m: f64,
    /// The smallest margin accepted (m), default 1 mm.
    #[serde(default = "default_min_margin")]
    pub min_margin_m: f64,
    /// The planned outline's length to width, default 3.5.
    #[serde(default = "default_ratio")]
    pub length_to_width: f64,
    /// The length to width accepted, default 3 to 4.
    #[serde(default = "default_ratio_range")]
    pub ratio_range: [f64; 2],
    /// How deep the blade's tip goes below the surface (m): into the fat.
    pub depth_m: f64,
    /// The depth below the surface at which the fat begins (m): the skin's thickness.
    pub fat_depth_m: f64,
    /// The depth at which the fascia begins (m): the cut stays short of it.
    pub fascia_depth_m: f64,
    /// Where the field is seen from (m).
    pub viewpoint_m: [f64; 3],
    /// How far from the planned outline the review's band is drawn (m), default 1 mm.
    #[serde(default = "default_tolerance")]
    pub tolerance_m: f64,
    /// The force the tissue should not be loaded beyond (N), default 2.5 N.
    #[serde(default = "default_force_limit")]
    pub force_limit_n: f64,
}

fn default_normal() -> [f64; 3] {
    [0.0, 0.0, 1.0]
}
fn default_axis() -> [f64; 3] {
    [1.0, 0.0, 0.0]
}
fn default_margin() -> f64 {
    0.002
}
fn default_min_margin() -> f64 {
    0.001
}
fn default_ratio() -> f64 {
    3.5
}
fn default_ratio_range() -> [f64; 2] {
    [3.0, 4.0]
}
fn default_tolerance() -> f64 {
    0.001
}
fn default_force_limit() -> f64 {
    2.5
}

/// The built-in `elliptical-excision` plan (TOML, embedded).
pub const EXCISION_PLAN_TOML: &str = include_str!("../../examples/excision.toml");

impl ExcisionPlan {
    /// The built-in plan of `elliptical-excision`.
    pub fn builtin() -> Result<Self> {
        match ExercisePlan::from_toml(EXCISION_PLAN_TOML)? {
            ExercisePlan::Excision(p) => Ok(p),
            other => Err(ScoreError::InvalidPlan(format!(
                "the built-in excision plan is of kind {}",
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
            self.lesion_centre_m,
            self.normal,
            self.long_axis,
            self.viewpoint_m,
        ]
        .concat();
        numbers.extend(self.ratio_range);
        numbers.extend([
            self.lesion_radius_m,
            self.margin_m,
            self.min_margin_m,
            self.length_to_width,
            self.depth_m,
            self.fat_depth_m,
            self.fascia_depth_m,
            self.tolerance_m,
            self.force_limit_n,
        ]);
        if !geom::finite(&numbers) {
            return bad("a number is not finite (NaN or infinite)");
        }
        if !(self.lesion_radius_m >= 0.0005) {
            return bad("lesion_radius_m: an excision needs a lesion at least 1 mm across");
        }
        let Some(n) = geom::unit(self.normal.into()) else {
            return bad("normal: zero");
        };
        let a = Vector3::from(self.long_axis);
        if geom::unit(a - n * a.dot(&n)).is_none() {
            return bad("long_axis: zero or along the normal");
        }
        for (name, v) in [
            ("margin_m", self.margin_m),
            ("min_margin_m", self.min_margin_m),
            ("depth_m", self.depth_m),
            ("fat_depth_m", self.fat_depth_m),
            ("tolerance_m", self.tolerance_m),
            ("force_limit_n", self.force_limit_n),
        ] {
            if !(v > 0.0) {
                return bad(&format!("{name} must be > 0"));
            }
        }
        if self.min_margin_m > self.margin_m {
            return bad("min_margin_m: larger than the planned margin_m");
        }
        let [lo, hi] = self.ratio_range;
        if !(1.0 < lo && lo <= self.length_to_width && self.length_to_width <= hi) {
            return bad("length_to_width: must lie in ratio_range, whose low end is above 1");
        }
        if !(self.fat_depth_m < self.depth_m && self.depth_m < self.fascia_depth_m) {
            return bad("depth_m: must lie in the fat, between fat_depth_m and fascia_depth_m");
        }
        Ok(())
    }

    /// What the metrics measure against.
    pub fn excision(&self) -> Excision {
        Excision {
            centre_m: self.lesion_centre_m,
            normal: self.normal,
            long_axis: self.long_axis,
            lesion_radius_m: self.lesion_radius_m,
            margin_m: self.margin_m,
            ratio_range: self.ratio_range,
            fat_depth_m: self.fat_depth_m,
            fascia_depth_m: self.fascia_depth_m,
            outline_m: self.outline(180, 0.0),
        }
    }

    /// The outline's half-length and half-width `(L, w)` (m).
    pub fn half_extents(&self) -> (f64, f64) {
        let w = self.lesion_radius_m + self.margin_m;
        (self.length_to_width * w, w)
    }

    /// The planned outline's apex angle (degrees).
    pub fn apex_angle_deg(&self) -> f64 {
        let (l, w) = self.half_extents();
        let r = (l * l + w * w) / (2.0 * w);
        2.0 * (l / (r - w)).atan().to_degrees()
    }

    /// Points along the planned outline, from the apex at `-L` along the side at `-w` to the
    /// apex at `+L` and back along the other side (counter-clockwise seen from outside), then
    /// on past the start by `overlap_m`; `per_side` points a side.
    pub fn outline(&self, per_side: usize, overlap_m: f64) -> Vec<[f64; 3]> {
        let (u, v) = self.axes();
        let c = Point3::from(self.lesion_centre_m);
        let (l, w) = self.half_extents();
        let r = (l * l + w * w) / (2.0 * w);
        let phi0 = (l / r).asin();
        let at = |phi: f64, side: f64| {
            let (x, y) = (r * phi.sin(), side * (r - w - r * phi.cos()));
            (c + u * x + v * y).into()
        };
        let n = per_side.max(2);
        let step = 2.0 * phi0 / n as f64;
        let mut points: Vec<[f64; 3]> = (0..n).map(|i| at(-phi0 + step * i as f64, 1.0)).collect();
        points.extend((0..=n).map(|i| at(phi0 - step * i as f64, -1.0)));
        let extra = (overlap_m / (r * step)).ceil() as usize;
        points.extend((1..=extra.min(n)).map(|i| at(-phi0 + step * i as f64, 1.0)));
        points
    }

    /// The plane's axes: the long axis made perpendicular to the normal, and the normal
    /// across it.
    fn axes(&self) -> (Vector3<f64>, Vector3<f64>) {
        excision::plane_axes(self.normal, self.long_axis)
    }

    /// The lesion's edge, a point every degree.
    pub fn lesion_edge(&self) -> Vec<[f64; 3]> {
        let (u, v) = self.axes();
        let c = Point3::from(self.lesion_centre_m);
        (0..=360)
            .map(|k| {
                let a = f64::from(k).to_radians();
                (c + (u * a.cos() + v * a.sin()) * self.lesion_radius_m).into()
            })
            .collect()
    }
}

const DEFAULT_THRESHOLDS: [(&str, Better, f64, f64); 6] = {
    use Better::*;
    [
        // at least 1 mm from the lesion's edge everywhere
        ("excision_min_margin_m", HigherIsBetter, 0.002, 0.001),
        ("excision_margin_error_m", LowerIsBetter, 0.0003, 0.0015),
        // 3:1 to 4:1: 0 inside the range
        ("excision_ratio_error", LowerIsBetter, 0.0, 0.25),
        ("excision_axis_error_deg", LowerIsBetter, 2.0, 10.0),
        ("excision_depth_in_fat", HigherIsBetter, 1.0, 0.85),
        ("outline_closed", HigherIsBetter, 1.0, 0.5),
    ]
};

const CENTRE: Option<&str> = Some("Centre of the lesion, on the surface");
const VIEWPOINT: Option<&str> = Some("Viewpoint: the eye the field is seen from");

/// The form's fields, in the order of [`ExcisionPlan::slot`].
const FIELDS: [FormField; 14] = [
    FormField::mm("lesion_x_mm", "x", CENTRE),
    FormField::mm("lesion_y_mm", "y", CENTRE),
    FormField::mm("lesion_z_mm", "z", CENTRE),
    FormField::mm("viewpoint_x_mm", "x", VIEWPOINT),
    FormField::mm("viewpoint_y_mm", "y", VIEWPOINT),
    FormField::mm("viewpoint_z_mm", "z", VIEWPOINT),
    FormField::mm("lesion_radius_mm", "Radius of the lesion", None),
    FormField::mm("margin_mm", "Planned margin from the lesion's edge", None),
    FormField::mm("min_margin_mm", "Smallest margin accepted", None),
    FormField {
        name: "length_to_width",
        label: "Planned length to width",
        unit: "",
        factor: 1.0,
        group: None,
    },
    FormField::mm("depth_mm", "Depth of the blade below the surface", None),
    FormField::mm(
        "fat_depth_mm",
        "Depth of the fat's top (the skin's thickness)",
        None,
    ),
    FormField::mm("fascia_depth_mm", "Depth of the fascia", None),
    FormField {
        name: "force_limit_n",
        label: "Force limit: forces above it count as excessive",
        unit: "N",
        factor: 1.0,
        group: None,
    },
];

const KEYS: [PlanKey; 16] = [
    PlanKey::new("name", "text", "a name for reports (optional)"),
    PlanKey::new(
        "scene",
        "text",
        "the scene the plan is for, e.g. skin-block (optional)",
    ),
    PlanKey::new(
        "lesion_centre_m",
        "[x, y, z] m",
        "the lesion's centre, on the surface (required)",
    ),
    PlanKey::new(
        "lesion_radius_m",
        "m",
        "the lesion's radius, at least 0.0005 (required)",
    ),
    PlanKey::new(
        "normal",
        "[x, y, z]",
        "the surface's outward normal (default [0, 0, 1])",
    ),
    PlanKey::new(
        "long_axis",
        "[x, y, z]",
        "the outline's long axis, along the skin's tension lines (default [1, 0, 0])",
    ),
    PlanKey::new(
        "margin_m",
        "m",
        "the planned margin from the lesion's edge (default 0.002)",
    ),
    PlanKey::new(
        "min_margin_m",
        "m",
        "the smallest margin accepted (default 0.001)",
    ),
    PlanKey::new(
        "length_to_width",
        "1",
        "the planned outline's length to width (default 3.5)",
    ),
    PlanKey::new(
        "ratio_range",
        "[low, high]",
        "the length to width accepted (default [3, 4])",
    ),
    PlanKey::new(
        "depth_m",
        "m",
        "how deep the blade's tip goes, in the fat (required)",
    ),
    PlanKey::new(
        "fat_depth_m",
        "m",
        "the depth at which the fat begins (required)",
    ),
    PlanKey::new(
        "fascia_depth_m",
        "m",
        "the depth at which the fascia begins (required)",
    ),
    PlanKey::new(
        "viewpoint_m",
        "[x, y, z] m",
        "where the field is seen from (required)",
    ),
    PlanKey::new(
        "tolerance_m",
        "m",
        "the band drawn round the outline in reviews (default 0.001)",
    ),
    PlanKey::new(
        "force_limit_n",
        "N",
        "forces above it count as excessive (default 2.5)",
    ),
];

impl ExcisionPlan {
    /// The number form field `i` edits.
    fn slot(&mut self, i: usize) -> Option<&mut f64> {
        Some(match i {
            0..=2 => &mut self.lesion_centre_m[i],
            3..=5 => &mut self.viewpoint_m[i - 3],
            6 => &mut self.lesion_radius_m,
            7 => &mut self.margin_m,
            8 => &mut self.min_margin_m,
            9 => &mut self.length_to_width,
            10 => &mut self.depth_m,
            11 => &mut self.fat_depth_m,
            12 => &mut self.fascia_depth_m,
            13 => &mut self.force_limit_n,
            _ => return None,
        })
    }
}

impl ExerciseKind for ExcisionPlan {
    fn check(&self) -> Result<()> {
        ExcisionPlan::check(self)
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

    /// Round the outline once and a little further, so the cut closes.
    fn hand_line(&self) -> HandLine {
        HandLine {
            line_m: self.outline(90, OVERLAP_M),
            normal: self.normal,
            depth_m: self.depth_m,
            viewpoint_m: self.viewpoint_m,
        }
    }

    fn metrics(&self) -> &'static [Metric] {
        excision::METRICS
    }

    fn assess(&self, data: &AttemptData) -> Result<MetricSet> {
        self.check()?;
        let mut values = Values::default();
        excision::assess(&self.excision(), data, &mut values);
        Ok(values.collect(excision::METRICS))
    }

    fn default_thresholds(&self) -> Vec<Threshold> {
        let mut rows = DEFAULT_THRESHOLDS;
        rows[0].2 = self.margin_m;
        rows[0].3 = self.min_margin_m;
        super::fixed_thresholds(&rows)
    }

    fn form_fields(&self) -> &'static [FormField] {
        &FIELDS
    }

    fn field(&self, i: usize) -> f64 {
        super::slot_value(self, i, Self::slot)
    }

    fn with_fields(&self, changed: &[(usize, f64)]) -> Result<ExercisePlan> {
        let plan = super::with_slots(self, changed, Self::slot);
        Ok(ExercisePlan::Excision(plan.normalised()?))
    }

    fn form_note(&self) -> &'static str {
        "The outline is fusiform (two arcs); its long axis, normal and accepted length to width are set in the plan text."
    }

    fn keys(&self) -> &'static [PlanKey] {
        &KEYS
    }

    fn drawing(&self) -> Drawing {
        Drawing {
            lines_m: vec![self.outline(90, 0.0)],
            marks_m: vec![self.lesion_edge()],
            normal: self.normal,
            tolerance_m: self.tolerance_m,
            force_limit_n: self.force_limit_n,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The built-in outline: 2 mm beside the lesion, 3.5 times as long as wide, closed past
    /// its start, its apex angle worked by hand (`w = 6`, `L = 21`, `R = 39.75` mm:
    /// `2 atan(21 / 33.75) = 63.78°`); bad plans name the field.
    #[test]
    fn the_builtin_outline_and_bad_plans() {
        let plan = ExcisionPlan::builtin().unwrap();
        let (l, w) = plan.half_extents();
        assert!((w - 0.006).abs() < 1e-12 && (l - 0.021).abs() < 1e-12);
        assert!(
            (plan.apex_angle_deg() - 63.78).abs() < 0.01,
            "{}",
            plan.apex_angle_deg()
        );
        let outline = plan.outline(90, 0.0);
        let c = Point3::from(plan.lesion_centre_m);
        let nearest = outline
            .iter()
            .map(|p| nalgebra::distance(&Point3::from(*p), &c))
            .fold(f64::INFINITY, f64::min);
        assert!((nearest - w).abs() < 1e-6, "{nearest}");
        let (first, last) = (outline[0], outline[outline.len() - 1]);
        assert!(
            nalgebra::distance(&first.into(), &last.into()) < 1e-12,
            "closed"
        );
        let line = plan.hand_line().line_m;
        assert!(line.len() > outline.len(), "past the start");
        for (field, bad) in [
            (
                "lesion_radius_m",
                plan.clone().with(|p| p.lesion_radius_m = 0.0),
            ),
            ("depth_m", plan.clone().with(|p| p.depth_m = 0.015)),
            (
                "length_to_width",
                plan.clone().with(|p| p.length_to_width = 5.0),
            ),
            (
                "long_axis",
                plan.clone().with(|p| p.long_axis = [0.0, 0.0, 2.0]),
            ),
            (
                "min_margin_m",
                plan.clone().with(|p| p.min_margin_m = 0.003),
            ),
            (
                "not finite",
                plan.clone().with(|p| p.lesion_centre_m[1] = f64::NAN),
            ),
        ] {
            let e = bad.check().unwrap_err().to_string();
            assert!(e.contains(field), "{field}: {e}");
        }
        for (i, f) in FIELDS.iter().enumerate() {
            let v = plan.field(i) * 1.01 + 1e-4;
            let changed = ExercisePlan::Excision(plan.clone())
                .kind_plan()
                .with_fields(&[(i, v)]);
            let ExercisePlan::Excision(changed) = changed.unwrap() else {
                panic!("kind changed")
            };
            assert_eq!(changed.field(i), v, "{}", f.name);
        }
    }

    /// The planned outline itself, cut 5 mm deep, meets every threshold.
    #[test]
    fn the_planned_outline_passes_its_own_thresholds() {
        let plan = ExcisionPlan::builtin().unwrap();
        let cuts = plan
            .outline(400, 0.0)
            .iter()
            .enumerate()
            .map(|(i, p)| crate::input::CutSample {
                t_s: i as f64 * 0.05,
                tip_m: [p[0], p[1], p[2] - plan.depth_m],
                edge_dir: [0.0, 0.0, 1.0],
                depth_m: plan.depth_m,
                stroke: Some(0),
            })
            .collect();
        let data = AttemptData {
            cuts,
            ..Default::default()
        };
        let out = plan.assess(&data).unwrap();
        for t in plan.default_thresholds() {
            let v = crate::metrics::value_of(&out, &t.key).unwrap();
            assert!(t.passes(v), "{}: {v}", t.key);
        }
        let apex = crate::metrics::value_of(&out, "excision_apex_angle_deg").unwrap();
        assert!(
            apex < plan.apex_angle_deg(),
            "chords inside the tangents: {apex}"
        );
    }

    impl ExcisionPlan {
        fn with(mut self, f: impl FnOnce(&mut Self)) -> Self {
            f(&mut self);
            self
        }
    }
}
