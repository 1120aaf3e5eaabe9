//! The metrics: pure functions of an [`crate::AttemptData`] and an exercise's plan; each
//! kind of exercise ([`crate::exercise`]) picks its metrics from [`METRICS`].
//!
//! Each group ([`incision`], [`path`], [`safety`], [`field`]) checks its own input; a group
//! whose input is unusable (too few samples, NaN or infinite values, no surface) reports its
//! metrics as missing (`value: None`, with the reason) instead of failing the whole
//! assessment or panicking. Only an invalid plan is an error. A metric the attempt's device
//! cannot measure (the approach angle with the station's pointer, whose blade enters the
//! tissue along an orientation the station fixes) is missing with a reason beginning
//! [`NOT_MEASURED_WITH_DEVICE`]: it measures neither for nor against the trainee
//! ([`crate::proficiency`] leaves it out of the verdict and the score).

pub mod excision;
pub mod exposure;
pub mod field;
pub mod handling;
pub mod incision;
pub mod motion;
pub mod path;
pub mod pattern;
pub mod safety;
pub mod smoothness;
pub mod wound;

use serde::{Deserialize, Serialize};

/// Which way a metric improves.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Better {
    /// Smaller is better (errors, times, forces): an upper threshold.
    LowerIsBetter,
    /// Larger is better (fractions cut or visible, economy): a lower threshold.
    HigherIsBetter,
    /// Closest to the expert mean is best (signed errors): thresholds on both sides.
    TwoSided,
}

impl Better {
    /// The name stored in the database.
    pub fn as_str(self) -> &'static str {
        match self {
            Better::LowerIsBetter => "lower-is-better",
            Better::HigherIsBetter => "higher-is-better",
            Better::TwoSided => "two-sided",
        }
    }

    /// The inverse of [`Better::as_str`].
    pub fn parse(s: &str) -> Option<Self> {
        match s {
            "lower-is-better" => Some(Better::LowerIsBetter),
            "higher-is-better" => Some(Better::HigherIsBetter),
            "two-sided" => Some(Better::TwoSided),
            _ => None,
        }
    }
}

/// A metric's definition: its key and SI unit (what is stored), which way it improves,
/// whether it is scored, and how people see it (its label, the unit it is shown in).
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Metric {
    /// Stable key (`snake_case`, SI unit suffix).
    pub key: &'static str,
    /// What people call it ("Entry error").
    pub label: &'static str,
    /// SI unit (`m`, `s`, `N`, `rad`, `deg`, `m^2`, `1` for ratios and counts).
    pub unit: &'static str,
    /// Which way it improves.
    pub better: Better,
    /// Whether pass/fail and the overall score use it (the others are reported only).
    pub scored: bool,
    /// One line for reports.
    pub description: &'static str,
    /// The unit it is shown in and the factor from the SI value, where it is not the SI
    /// unit's own ([`display_unit`]): a fraction shown in %.
    #[serde(skip)]
    shown: Option<(&'static str, f64)>,
    /// A distance from the plan (m), which the plan's tolerance allows whatever the experts'
    /// spread ([`crate::proficiency::Thresholds::within_plan_tolerance`]).
    #[serde(skip)]
    pub from_plan: bool,
}

impl Metric {
    const fn labelled(self, label: &'static str) -> Self {
        Self { label, ..self }
    }

    /// Marks a distance from the plan (see [`Metric::from_plan`]).
    pub(crate) const fn distance_from_plan(self) -> Self {
        Self {
            from_plan: true,
            ..self
        }
    }

    const fn shown_in(self, unit: &'static str, factor: f64) -> Self {
        Self {
            shown: Some((unit, factor)),
            ..self
        }
    }

    /// The factor from the stored SI value to the shown one, and the unit shown (empty for
    /// counts and scores): 1000 and "mm" for metres.
    pub fn display(&self) -> (f64, &'static str) {
        match self.shown {
            Some((unit, factor)) => (factor, unit),
            None => display_unit(self.unit),
        }
    }
}

/// How a stored SI unit is shown: the factor and the display unit (metres as millimetres).
pub fn display_unit(unit: &str) -> (f64, &str) {
    match unit {
        "m" => (1e3, "mm"),
        "m^2" => (1e6, "mm²"),
        "m^3" => (1e9, "mm³"),
        "deg" => (1.0, "°"),
        "1" => (1.0, ""),
        other => (1.0, other),
    }
}

/// One metric's value for one attempt. `value` is `None` when the metric could not be
/// computed (`missing` says why).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct MetricValue {
    pub key: String,
    pub value: Option<f64>,
    pub unit: String,
    pub better: Better,
    pub scored: bool,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub missing: Option<String>,
}

impl MetricValue {
    fn of(metric: &Metric, value: Option<f64>, missing: Option<String>) -> Self {
        let value = value.filter(|v| v.is_finite());
        let missing = if value.is_none() {
            Some(missing.unwrap_or_else(|| "not finite".into()))
        } else {
            None
        };
        Self {
            key: metric.key.into(),
            value,
            unit: metric.unit.into(),
            better: metric.better,
            scored: metric.scored,
            missing,
        }
    }
}

impl MetricValue {
    /// Whether the value is missing because the attempt's device cannot measure the metric
    /// (its reason begins [`NOT_MEASURED_WITH_DEVICE`]) or the station lagged behind the hand
    /// ([`STATION_LAGGED`]), not because of what the trainee did.
    pub fn not_measured(&self) -> bool {
        self.value.is_none()
            && self.missing.as_deref().is_some_and(|m| {
                m.starts_with(NOT_MEASURED_WITH_DEVICE) || m.starts_with(STATION_LAGGED)
            })
    }
}

/// How a paced metric's reason begins when the station lagged (stored with the attempt's
/// results: it measures neither for nor against the trainee).
pub const STATION_LAGGED: &str = "not measured: the station lagged";

/// How the reason of a metric the attempt's device cannot measure begins (stored with the
/// attempt's results, so it holds for attempts scored before as after).
pub const NOT_MEASURED_WITH_DEVICE: &str = "not measured with this device";

/// One attempt's metrics, in catalogue order (what [`assess`] returns).
pub type MetricSet = Vec<MetricValue>;

/// The metric catalogue, in report order.
pub const METRICS: &[Metric] = &[
    // incision
    m(
        "entry_error_m",
        "m",
        Better::LowerIsBetter,
        true,
        "distance of the cut's start from the planned entry (seen along the normal)",
    )
    .labelled("Entry error")
    .distance_from_plan(),
    m(
        "exit_error_m",
        "m",
        Better::LowerIsBetter,
        true,
        "distance of the cut's end from the planned exit",
    )
    .labelled("Exit error")
    .distance_from_plan(),
    m(
        "length_error_m",
        "m",
        Better::TwoSided,
        true,
        "cut length minus planned length (signed)",
    )
    .labelled("Length error")
    .distance_from_plan(),
    m(
        "lateral_mean_m",
        "m",
        Better::LowerIsBetter,
        true,
        "mean distance of the cut from the planned line",
    )
    .labelled("Lateral deviation (mean)")
    .distance_from_plan(),
    m(
        "lateral_rms_m",
        "m",
        Better::LowerIsBetter,
        false,
        "RMS distance of the cut from the planned line",
    )
    .labelled("Lateral deviation (RMS)"),
    m(
        "lateral_max_m",
        "m",
        Better::LowerIsBetter,
        true,
        "largest distance of the cut from the planned line",
    )
    .labelled("Lateral deviation (max)")
    .distance_from_plan(),
    m(
        "fraction_cut_in_tolerance",
        "1",
        Better::HigherIsBetter,
        true,
        "fraction of the planned line cut within the tolerance",
    )
    .labelled("Cut within tolerance")
    .shown_in("%", 100.0),
    m(
        "direction_error_deg",
        "deg",
        Better::LowerIsBetter,
        true,
        "angle between the cut's overall direction and the plan's",
    )
    .labelled("Direction error"),
    m(
        "depth_error_m",
        "m",
        Better::TwoSided,
        true,
        "mean cut depth minus planned depth (signed)",
    )
    .labelled("Depth error (mean)")
    .distance_from_plan(),
    m(
        "depth_rms_error_m",
        "m",
        Better::LowerIsBetter,
        false,
        "RMS of cut depth minus planned depth",
    )
    .labelled("Depth error (RMS)"),
    m(
        "approach_error_deg",
        "deg",
        Better::LowerIsBetter,
        false,
        "angle between the tip's motion entering the tissue and the planned approach",
    )
    .labelled("Approach angle error"),
    // path
    m(
        "time_s",
        "s",
        Better::LowerIsBetter,
        true,
        "task time: from the tip's first movement to its last",
    )
    .labelled("Task time"),
    m(
        "path_length_m",
        "m",
        Better::LowerIsBetter,
        true,
        "distance travelled by the tip (filtered)",
    )
    .labelled("Path length"),
    m(
        "economy_of_motion",
        "1",
        Better::HigherIsBetter,
        false,
        "straight distance start to end over path length",
    )
    .labelled("Economy of motion"),
    m(
        "idle_time_s",
        "s",
        Better::LowerIsBetter,
        false,
        "time with the tip (nearly) still",
    )
    .labelled("Idle time"),
    m(
        "movements",
        "1",
        Better::LowerIsBetter,
        true,
        "number of movements (speed threshold crossings)",
    )
    .labelled("Movements"),
    m(
        "angular_path_rad",
        "rad",
        Better::LowerIsBetter,
        false,
        "total rotation of the tool",
    )
    .labelled("Tool rotation"),
    m(
        "ldlj",
        "1",
        Better::HigherIsBetter,
        true,
        "log dimensionless jerk of the whole speed profile",
    )
    .labelled("Smoothness (LDLJ)"),
    m(
        "sparc",
        "1",
        Better::HigherIsBetter,
        false,
        "spectral arc length of the whole speed profile",
    )
    .labelled("Smoothness (SPARC)"),
    m(
        "ldlj_per_movement",
        "1",
        Better::HigherIsBetter,
        false,
        "mean log dimensionless jerk per movement",
    )
    .labelled("Smoothness per movement (LDLJ)"),
    m(
        "sparc_per_movement",
        "1",
        Better::HigherIsBetter,
        false,
        "mean spectral arc length per movement",
    )
    .labelled("Smoothness per movement (SPARC)"),
    // safety
    m(
        "peak_force_n",
        "N",
        Better::LowerIsBetter,
        true,
        "largest force",
    )
    .labelled("Peak force"),
    m(
        "mean_force_n",
        "N",
        Better::LowerIsBetter,
        false,
        "mean force while touching",
    )
    .labelled("Mean force"),
    m(
        "time_above_force_limit_s",
        "s",
        Better::LowerIsBetter,
        false,
        "time above the plan's force limit",
    )
    .labelled("Time above force limit"),
    m(
        "excessive_force_events",
        "1",
        Better::LowerIsBetter,
        false,
        "times the force rose above the limit",
    )
    .labelled("Excessive force events"),
    m(
        "cut_outside_corridor_m",
        "m",
        Better::LowerIsBetter,
        true,
        "length of cut beyond the corridor",
    )
    .labelled("Cut outside corridor"),
    m(
        "cut_area_outside_corridor_m2",
        "m^2",
        Better::LowerIsBetter,
        false,
        "cut area (length x depth) beyond the corridor",
    )
    .labelled("Cut area outside corridor"),
    // field
    m(
        "target_visible_fraction",
        "1",
        Better::HigherIsBetter,
        false,
        "fraction of the target seen from the viewpoint",
    )
    .labelled("Target visible")
    .shown_in("%", 100.0),
    m(
        "opening_width_m",
        "m",
        Better::HigherIsBetter,
        false,
        "widest gap between the wound's lips",
    )
    .labelled("Opening width"),
    m(
        "opening_area_m2",
        "m^2",
        Better::HigherIsBetter,
        false,
        "area of the wound's opening seen along the normal",
    )
    .labelled("Opening area"),
];

const fn m(
    key: &'static str,
    unit: &'static str,
    better: Better,
    scored: bool,
    description: &'static str,
) -> Metric {
    Metric {
        key,
        label: key,
        unit,
        better,
        scored,
        description,
        shown: None,
        from_plan: false,
    }
}

/// Every metric of every kind of exercise, in report order: [`METRICS`] (the incision's and
/// those every motion has), then [`pattern::METRICS`], [`excision::METRICS`],
/// [`wound::METRICS`], the tissue handling of an attempt with a grasper
/// ([`handling::METRICS`]), then the motion measures of imported kinematics
/// ([`motion::METRICS`]).
pub fn all() -> impl Iterator<Item = &'static Metric> {
    METRICS
        .iter()
        .chain(pattern::METRICS)
        .chain(excision::METRICS)
        .chain(wound::METRICS)
        .chain(handling::METRICS)
        .chain(motion::METRICS)
}

/// The definition of a metric key.
pub fn metric(key: &str) -> Option<&'static Metric> {
    all().find(|m| m.key == key)
}

/// Where a metric key stands in [`all`] (unknown keys last): the order reports list them.
pub fn catalogue_rank(key: &str) -> usize {
    all().position(|m| m.key == key).unwrap_or(usize::MAX)
}

/// Values keyed as in [`METRICS`], built by the groups.
#[derive(Debug, Default)]
pub(crate) struct Values(Vec<(&'static str, Option<f64>, Option<String>)>);

impl Values {
    pub(crate) fn set(&mut self, key: &'static str, value: f64) {
        self.0.push((key, Some(value), None));
    }
    pub(crate) fn missing(&mut self, keys: &[&'static str], why: &str) {
        for k in keys {
            self.0.push((k, None, Some(why.to_owned())));
        }
    }
    /// `keys` are not measured with the attempt's device, for the reason `why`.
    pub(crate) fn not_measured(&mut self, keys: &[&'static str], why: &str) {
        self.missing(keys, &format!("{NOT_MEASURED_WITH_DEVICE}: {why}"));
    }
}

impl Values {
    /// The values of `metrics`, in their order; a metric no group set is missing.
    pub(crate) fn collect(self, metrics: &[Metric]) -> MetricSet {
        metrics
            .iter()
            .map(|metric| {
                let found = self.0.iter().find(|(k, _, _)| *k == metric.key);
                match found {
                    Some((_, v, why)) => MetricValue::of(metric, *v, why.clone()),
                    None => MetricValue::of(metric, None, Some("not computed".into())),
                }
            })
            .collect()
    }
}

/// The value of `key` in a list of metric values, if present and finite.
pub fn value_of(values: &[MetricValue], key: &str) -> Option<f64> {
    values.iter().find(|v| v.key == key).and_then(|v| v.value)
}

/// Whether `key` is among `values` and not measured with the attempt's device
/// ([`MetricValue::not_measured`]).
pub fn not_measured(values: &[MetricValue], key: &str) -> bool {
    values
        .iter()
        .find(|v| v.key == key)
        .is_some_and(MetricValue::not_measured)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::exercise::{ExerciseKind, IncisionPlan};
    use crate::input::AttemptData;

    #[test]
    fn keys_are_unique_and_empty_data_gives_missing_metrics_not_errors() {
        let mut keys: Vec<_> = all().map(|m| m.key).collect();
        keys.sort_unstable();
        keys.dedup();
        assert_eq!(keys.len(), all().count());
        let plan = IncisionPlan::chest_wall().unwrap();
        let out = plan.assess(&AttemptData::default()).unwrap();
        assert_eq!(out.len(), METRICS.len());
        // no cuts: nothing cut outside the corridor (a true zero); everything else is missing
        for v in &out {
            if v.key.starts_with("cut_") {
                assert_eq!(v.value, Some(0.0));
            } else {
                assert!(v.value.is_none() && v.missing.is_some(), "{v:?}");
            }
        }
    }

    #[test]
    fn the_approach_is_not_measured_with_a_device_that_fixes_it() {
        let plan = IncisionPlan::chest_wall().unwrap();
        let entry = plan.entry_m;
        let mut data = AttemptData::default();
        // the tip comes down 10 mm straight onto the entry, then cuts along the line
        for i in 0..=20 {
            data.poses.push(crate::input::PoseSample {
                t_s: f64::from(i) * 0.05,
                tip_m: [entry[0], entry[1], entry[2] + 0.01 - f64::from(i) * 5e-4],
                quat_wxyz: [1.0, 0.0, 0.0, 0.0],
                blade_engaged: true,
            });
        }
        for i in 0..=60 {
            let x = entry[0] + f64::from(i) * 1e-3;
            data.cuts.push(crate::input::CutSample {
                t_s: 1.0 + f64::from(i) * 0.05,
                tip_m: [x, 0.0, -0.008],
                edge_dir: [0.0, 0.0, 1.0],
                depth_m: 0.008,
                stroke: Some(0),
            });
        }
        let approach = |device: Option<&str>| {
            let data = AttemptData {
                device: device.map(str::to_owned),
                ..data.clone()
            };
            let out = plan.assess(&data).unwrap();
            out.into_iter()
                .find(|v| v.key == "approach_error_deg")
                .unwrap()
        };
        for device in [None, Some("expert"), Some("csv:hand.csv")] {
            let a = approach(device);
            assert!(
                a.value.unwrap() < 1.0 && !a.not_measured(),
                "{device:?}: {a:?}"
            );
        }
        for device in ["pointer", "recording of pointer"] {
            let a = approach(Some(device));
            assert!(a.value.is_none() && a.not_measured(), "{device}: {a:?}");
            assert!(
                a.missing.as_deref().unwrap().contains("the station fixes"),
                "{a:?}"
            );
        }
        // a value missing for another reason is not "not measured"
        let none = plan.assess(&AttemptData::default()).unwrap();
        assert!(!not_measured(&none, "approach_error_deg"));
    }

    #[test]
    fn nan_samples_are_quarantined() {
        let plan = IncisionPlan::chest_wall().unwrap();
        let mut data = AttemptData::default();
        for i in 0..200 {
            let t = i as f64 * 0.01;
            data.poses.push(crate::input::PoseSample {
                t_s: t,
                tip_m: [t * 0.01, 0.0, 0.01],
                quat_wxyz: [1.0, 0.0, 0.0, 0.0],
                blade_engaged: false,
            });
        }
        data.poses[50].tip_m[0] = f64::NAN;
        let out = plan.assess(&data).unwrap();
        let time = out.iter().find(|v| v.key == "time_s").unwrap();
        assert!(time.value.is_none());
        assert!(
            time.missing.as_deref().unwrap().contains("not finite"),
            "{time:?}"
        );
    }
}
