//! Exercise kinds: what an exercise's plan is and how an attempt at it is measured.
//!
//! An [`ExercisePlan`] is tagged by its [`Kind`] (`kind = "incision"`; a plan without a tag
//! is an incision plan, as every plan stored before kinds existed). Each kind is one module
//! that implements [`ExerciseKind`] for its plan type, answering the same questions: is the
//! plan valid, what does the hand follow, which metrics, how an attempt is scored, the default
//! thresholds, the plan form's fields and what a review draws. [`ExercisePlan::kind_plan`] is
//! the one `match` over kinds that reaches them; parsing is the other place a kind is named.
//!
//! A new kind: a module beside [`incision`] with its plan type and an [`ExerciseKind`] impl,
//! a variant in [`Kind`] and [`ExercisePlan`], and its arm in the matches of this file.

pub mod excision;
pub mod field;
pub mod incision;
pub mod pattern;

use std::path::Path;

use serde::{Deserialize, Serialize};

use crate::error::{Result, ScoreError};
use crate::input::AttemptData;
use crate::metrics::{Metric, MetricSet};
use crate::proficiency::Threshold;

pub use excision::{EXCISION_PLAN_TOML, ExcisionPlan};
pub use field::{FIELD_PLAN_TOML, FieldPlan};
pub use incision::{BODY_WALL_PLAN_TOML, CHEST_WALL_PLAN_TOML, IncisionPlan};
pub use pattern::{PATTERN_PLAN_TOML, PatternPlan};

/// The kinds of exercise.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Kind {
    /// A line cut to a depth, measured against the planned line (`chest-wall-incision`).
    Incision,
    /// A marked circle cut out of a held sheet, scored by the MISTELS rule (`pattern-cutting`).
    Pattern,
    /// An outline incised round a skin lesion into the fat (`elliptical-excision`).
    Excision,
    /// An incision the trainee places to expose a structure behind a wall, scored by what
    /// the opened wound shows (`mini-thoracotomy`).
    Field,
}

impl Kind {
    /// Every kind, in the order forms offer them.
    pub const ALL: [Kind; 4] = [Kind::Incision, Kind::Pattern, Kind::Excision, Kind::Field];

    /// The tag in plans and forms.
    pub fn as_str(self) -> &'static str {
        match self {
            Kind::Incision => "incision",
            Kind::Pattern => "pattern",
            Kind::Excision => "excision",
            Kind::Field => "field",
        }
    }

    /// The inverse of [`Kind::as_str`].
    pub fn parse(tag: &str) -> Option<Self> {
        Self::ALL.into_iter().find(|k| k.as_str() == tag)
    }
}

/// What the hand follows, before it is laid on the tissue: points on the planned surface,
/// the surface's outward normal, the depth to cut at and the eye the field is seen from.
#[derive(Debug, Clone, PartialEq)]
pub struct HandLine {
    /// Points along the line to cut (m), in cutting order.
    pub line_m: Vec<[f64; 3]>,
    /// The outward normal the line is laid on the tissue along (unit).
    pub normal: [f64; 3],
    /// Depth of the blade's tip below the surface (m).
    pub depth_m: f64,
    /// Where the exercise views the field from (m).
    pub viewpoint_m: [f64; 3],
}

/// What a review draws of the plan, seen along its normal.
#[derive(Debug, Clone, PartialEq)]
pub struct Drawing {
    /// The planned lines (m), each open.
    pub lines_m: Vec<Vec<[f64; 3]>>,
    /// Lines marked on the tissue itself (m), seen in every mode (a pattern's circle), along
    /// the plan's normal.
    pub marks_m: Vec<Vec<[f64; 3]>>,
    /// The plan's outward normal (unit).
    pub normal: [f64; 3],
    /// How far from a line still counts as on it (m): the band drawn around it.
    pub tolerance_m: f64,
    /// The force the plan counts as excessive (N).
    pub force_limit_n: f64,
}

/// One number of a plan that the plan form edits: its form name, label, the unit shown and
/// the factor from the plan's SI value, and the group it is shown in.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FormField {
    pub name: &'static str,
    pub label: &'static str,
    pub unit: &'static str,
    pub factor: f64,
    /// The fieldset (a point's x, y, z share one); `None` for a value on its own.
    pub group: Option<&'static str>,
}

impl FormField {
    /// A length shown in mm.
    pub(crate) const fn mm(
        name: &'static str,
        label: &'static str,
        group: Option<&'static str>,
    ) -> Self {
        Self {
            name,
            label,
            unit: "mm",
            factor: 1e3,
            group,
        }
    }
}

/// The unit vector of a plan's `normal`, or an error naming it.
pub(crate) fn unit_normal(normal: [f64; 3]) -> Result<[f64; 3]> {
    crate::geom::unit(normal.into())
        .map(Into::into)
        .ok_or_else(|| ScoreError::InvalidPlan("normal: zero".into()))
}

/// A plan's number that form field `i` edits, reached through the plan's `slot`.
pub(crate) type Slot<P> = fn(&mut P, usize) -> Option<&mut f64>;

/// The value of form field `i` of `plan` (NaN for no such field).
pub(crate) fn slot_value<P: Clone>(plan: &P, i: usize, slot: Slot<P>) -> f64 {
    slot(&mut plan.clone(), i).map_or(f64::NAN, |v| *v)
}

/// `plan` with the form's `changed` fields `(i, SI value)` written through `slot`.
pub(crate) fn with_slots<P: Clone>(plan: &P, changed: &[(usize, f64)], slot: Slot<P>) -> P {
    let mut plan = plan.clone();
    for &(i, v) in changed {
        if let Some(s) = slot(&mut plan, i) {
            *s = v;
        }
    }
    plan
}

/// Hand-set thresholds from `(key, better, reference, limit)` rows ([`Threshold::fixed`]).
pub(crate) fn fixed_thresholds(
    rows: &[(&str, crate::metrics::Better, f64, f64)],
) -> Vec<Threshold> {
    rows.iter()
        .map(|&(key, better, reference, limit)| Threshold::fixed(key, better, reference, limit))
        .collect()
}

/// One key of a plan's text form (TOML / JSON): its unit and meaning, for the form's help.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct PlanKey {
    pub key: &'static str,
    pub unit: &'static str,
    pub meaning: &'static str,
}

impl PlanKey {
    pub(crate) const fn new(key: &'static str, unit: &'static str, meaning: &'static str) -> Self {
        Self { key, unit, meaning }
    }
}

/// The questions every kind of exercise answers about its plan.
pub trait ExerciseKind {
    /// Rejects a plan that cannot be assessed against, naming the field.
    fn check(&self) -> Result<()>;
    /// A name for reports.
    fn name(&self) -> &str;
    /// The scene the plan is for, informative.
    fn scene(&self) -> Option<&str>;
    /// The planned depth (m).
    fn depth_m(&self) -> f64;
    /// How far from the plan still counts as on it (m).
    fn tolerance_m(&self) -> f64;
    /// The force the plan counts as excessive (N): the station's force bar without thresholds.
    fn force_limit_n(&self) -> f64;
    /// What the hand follows.
    fn hand_line(&self) -> HandLine;
    /// The metrics an attempt is measured on, in report order.
    fn metrics(&self) -> &'static [Metric];
    /// Every metric of [`ExerciseKind::metrics`] for one attempt.
    fn assess(&self, data: &AttemptData) -> Result<MetricSet>;
    /// Hand-set thresholds until expert attempts replace them.
    fn default_thresholds(&self) -> Vec<Threshold>;
    /// The numbers the plan form edits.
    fn form_fields(&self) -> &'static [FormField];
    /// The value of form field `i` (SI).
    fn field(&self, i: usize) -> f64;
    /// The plan with the form's changed fields `(i, SI value)` applied, normalised and checked.
    fn with_fields(&self, changed: &[(usize, f64)]) -> Result<ExercisePlan>;
    /// What the form says under the fields about what they cannot express.
    fn form_note(&self) -> &'static str;
    /// The keys of the plan's text form.
    fn keys(&self) -> &'static [PlanKey];
    /// What a review draws of the plan.
    fn drawing(&self) -> Drawing;
    /// Whether the trainee chooses where to cut (the plan's line is one good choice, not the
    /// task), as in the `field` kind; a synthetic trainee then places its own.
    fn trainee_places_incision(&self) -> bool {
        false
    }
}

/// An exercise's plan, tagged by kind.
#[derive(Debug, Clone, PartialEq)]
pub enum ExercisePlan {
    Incision(IncisionPlan),
    Pattern(PatternPlan),
    Excision(ExcisionPlan),
    Field(FieldPlan),
}

impl From<IncisionPlan> for ExercisePlan {
    fn from(p: IncisionPlan) -> Self {
        ExercisePlan::Incision(p)
    }
}

impl ExercisePlan {
    /// The kind's answers for this plan: the one `match` over kinds.
    pub fn kind_plan(&self) -> &dyn ExerciseKind {
        match self {
            ExercisePlan::Incision(p) => p,
            ExercisePlan::Pattern(p) => p,
            ExercisePlan::Excision(p) => p,
            ExercisePlan::Field(p) => p,
        }
    }

    /// The plan's kind.
    pub fn kind(&self) -> Kind {
        match self {
            ExercisePlan::Incision(_) => Kind::Incision,
            ExercisePlan::Pattern(_) => Kind::Pattern,
            ExercisePlan::Excision(_) => Kind::Excision,
            ExercisePlan::Field(_) => Kind::Field,
        }
    }

    /// The incision plan, if it is one.
    pub fn as_incision(&self) -> Option<&IncisionPlan> {
        match self {
            ExercisePlan::Incision(p) => Some(p),
            _ => None,
        }
    }

    /// The incision plan, or an error naming the kind it is.
    pub fn into_incision(self) -> Result<IncisionPlan> {
        match self {
            ExercisePlan::Incision(p) => Ok(p),
            other => Err(ScoreError::InvalidPlan(format!(
                "kind: {}, not an incision",
                other.kind().as_str()
            ))),
        }
    }

    /// The built-in plan of `chest-wall-incision`.
    pub fn chest_wall() -> Result<Self> {
        IncisionPlan::chest_wall().map(Self::from)
    }

    /// The built-in plan of `body-wall-incision`.
    pub fn body_wall() -> Result<Self> {
        IncisionPlan::body_wall().map(Self::from)
    }

    /// Parses a plan from a JSON value: its `kind` (default `incision`) picks the type, which
    /// then reads the other keys (unknown keys are errors).
    fn from_value(mut value: serde_json::Value, what: &str) -> Result<Self> {
        let parse = |message: String| ScoreError::Parse {
            what: what.into(),
            message,
        };
        let map = value
            .as_object_mut()
            .ok_or_else(|| parse("a plan is a table of keys".into()))?;
        let kind = match map.remove("kind") {
            None => Kind::Incision,
            Some(serde_json::Value::String(tag)) => Kind::parse(&tag).ok_or_else(|| {
                parse(format!(
                    "kind: unknown kind `{tag}` (known: {})",
                    Kind::ALL.map(Kind::as_str).join(", ")
                ))
            })?,
            Some(_) => return Err(parse("kind: must be text".into())),
        };
        let read = |e: serde_json::Error| parse(format!("{} plan: {e}", kind.as_str()));
        match kind {
            Kind::Incision => {
                let plan: IncisionPlan = serde_json::from_value(value).map_err(read)?;
                Ok(plan.normalised()?.into())
            }
            Kind::Pattern => {
                let plan: PatternPlan = serde_json::from_value(value).map_err(read)?;
                Ok(ExercisePlan::Pattern(plan.normalised()?))
            }
            Kind::Excision => {
                let plan: ExcisionPlan = serde_json::from_value(value).map_err(read)?;
                Ok(ExercisePlan::Excision(plan.normalised()?))
            }
            Kind::Field => {
                let plan: FieldPlan = serde_json::from_value(value).map_err(read)?;
                Ok(ExercisePlan::Field(plan.normalised()?))
            }
        }
    }

    /// Parses JSON.
    pub fn from_json(text: &str) -> Result<Self> {
        let value = serde_json::from_str(text).map_err(|e| ScoreError::Parse {
            what: "expert plan (JSON)".into(),
            message: e.to_string(),
        })?;
        Self::from_value(value, "expert plan (JSON)")
    }

    /// Parses TOML.
    pub fn from_toml(text: &str) -> Result<Self> {
        let value = toml::from_str(text).map_err(|e| ScoreError::Parse {
            what: "expert plan (TOML)".into(),
            message: e.to_string(),
        })?;
        Self::from_value(value, "expert plan (TOML)")
    }

    /// Parses TOML or JSON (JSON when the text starts with `{`).
    pub fn parse(text: &str) -> Result<Self> {
        if text.trim_start().starts_with('{') {
            Self::from_json(text)
        } else {
            Self::from_toml(text)
        }
    }

    /// Reads a `.toml` or `.json` file (by extension; anything else is tried as TOML, then JSON).
    pub fn load(path: &Path) -> Result<Self> {
        let text = std::fs::read_to_string(path).map_err(|source| ScoreError::Io {
            path: path.display().to_string(),
            error: source,
        })?;
        let ext = path
            .extension()
            .and_then(|e| e.to_str())
            .unwrap_or("")
            .to_ascii_lowercase();
        let at = |e: ScoreError| match e {
            ScoreError::Parse { what, message } => ScoreError::Parse {
                what: format!("{} ({what})", path.display()),
                message,
            },
            ScoreError::InvalidPlan(m) => {
                ScoreError::InvalidPlan(format!("{}: {m}", path.display()))
            }
            e => e,
        };
        match ext.as_str() {
            "json" => Self::from_json(&text).map_err(at),
            "toml" => Self::from_toml(&text).map_err(at),
            _ => Self::from_toml(&text)
                .or_else(|_| Self::from_json(&text))
                .map_err(at),
        }
    }

    /// The plan as JSON with its `kind` tag (what the store keeps).
    pub fn to_json(&self) -> Result<String> {
        Ok(serde_json::to_string(self)?)
    }

    /// Checks the plan.
    pub fn check(&self) -> Result<()> {
        self.kind_plan().check()
    }

    /// Every metric of the kind for one attempt, and for an attempt made with a grasper the
    /// tissue handling ([`crate::metrics::handling`]) after them. Errors only on an invalid
    /// plan; unusable inputs give missing metrics.
    pub fn assess(&self, data: &AttemptData) -> Result<MetricSet> {
        let kind = self.kind_plan();
        let mut out = kind.assess(data)?;
        if !data.grasper.is_empty() {
            let mut values = crate::metrics::Values::default();
            crate::metrics::handling::assess(data, kind.force_limit_n(), &mut values);
            out.extend(values.collect(&crate::metrics::handling::metrics()));
        }
        Ok(out)
    }
}

impl Serialize for ExercisePlan {
    fn serialize<S: serde::Serializer>(&self, s: S) -> std::result::Result<S::Ok, S::Error> {
        let inner = match self {
            ExercisePlan::Incision(p) => serde_json::to_value(p),
            ExercisePlan::Pattern(p) => serde_json::to_value(p),
            ExercisePlan::Excision(p) => serde_json::to_value(p),
            ExercisePlan::Field(p) => serde_json::to_value(p),
        };
        let mut value = inner.map_err(serde::ser::Error::custom)?;
        if let Some(map) = value.as_object_mut() {
            map.insert("kind".into(), self.kind().as_str().into());
        }
        value.serialize(s)
    }
}

impl<'de> Deserialize<'de> for ExercisePlan {
    fn deserialize<D: serde::Deserializer<'de>>(d: D) -> std::result::Result<Self, D::Error> {
        let value = serde_json::Value::deserialize(d)?;
        Self::from_value(value, "expert plan").map_err(serde::de::Error::custom)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const OLD: &str =
        r#"{"entry_m":[0,0,0],"exit_m":[0.05,0,0],"depth_m":0.005,"viewpoint_m":[0,0,0.1]}"#;

    /// Plans stored before kinds existed read as incisions; a plan written now carries its
    /// tag and reads back equal; an unknown kind is an error naming the field.
    #[test]
    fn untagged_plans_are_incisions_and_tags_round_trip() {
        let old = ExercisePlan::from_json(OLD).unwrap();
        assert_eq!(old.kind(), Kind::Incision);
        let json = old.to_json().unwrap();
        assert!(json.contains(r#""kind":"incision""#), "{json}");
        assert_eq!(ExercisePlan::from_json(&json).unwrap(), old);
        let toml = ExercisePlan::from_toml(CHEST_WALL_PLAN_TOML).unwrap();
        assert_eq!(toml.kind_plan().name(), "chest-wall incision");
        let tagged = format!("kind = \"incision\"\n{CHEST_WALL_PLAN_TOML}");
        assert_eq!(ExercisePlan::parse(&tagged).unwrap(), toml);
        let unknown = OLD.replace('{', r#"{"kind":"knot","#);
        let e = ExercisePlan::from_json(&unknown).unwrap_err().to_string();
        assert!(e.contains("kind") && e.contains("knot"), "{e}");
        let not_table = ExercisePlan::from_json("[1, 2]").unwrap_err().to_string();
        assert!(not_table.contains("table"), "{not_table}");
    }
}
