//! Proficiency: thresholds from expert attempts, pass/fail, the normalised score, the
//! consecutive-pass rule and CUSUM.
//!
//! **Thresholds.** For each scored metric (see [`crate::metrics::all`]) the experts'
//! finite values `x_i` are taken; outliers with `|z_i| = |x_i - mean| / sd > 1.96` are removed
//! (one pass, on the mean and sample SD of all values); of the rest the mean `mu` and sample
//! SD `sigma` give the limits: `mu + k sigma` above for lower-is-better metrics, `mu - k sigma`
//! below for higher-is-better ones (`k` default 2). Two-sided metrics are signed errors against
//! the plan (cut length and depth minus planned), whose ideal is 0: their window is the
//! *expert band* `[min(mu, 0), max(mu, 0)]` widened by `k sigma` on both sides, so a cut closer
//! to the plan than the experts' never fails (experts who cut 2.3 mm deeper than planned do not
//! make an exact depth a fail). Metrics with fewer than 2 expert values get no threshold.
//!
//! **Pass.** Only the metrics that decide ([`decides`]: not [`FEEDBACK_ONLY`]) count. An
//! attempt passes a metric when its value is within the limits (inclusive); a missing value
//! fails, except one the attempt's device cannot measure
//! ([`crate::metrics::MetricValue::not_measured`]: the approach angle with the station's
//! pointer, whose blade enters the tissue along an orientation the station fixes), which is
//! left out of the verdict: it neither passes nor fails and does not count in the score. An
//! attempt that did not do the task ([`task_done`]: less than half the planned line cut within
//! the tolerance) fails every metric and scores -1 on each. It passes overall when it passes
//! every deciding thresholded metric (and there is at least one).
//!
//! **Proficiency and CUSUM** ([`Course`]; docs/decisions.md, "Proficiency and CUSUM"). A
//! trainee becomes proficient in an exercise at the attempt that completes
//! [`REQUIRED_CONSECUTIVE_PASSES`] consecutive passes ("proficient since attempt N"). The
//! CUSUM of failures below watches the failure rate, counted afresh from 0 in each phase of
//! the trainee's course: from the first attempt while learning, and from the attempt after each
//! change of standing. So the failures of the learning phase, expected and behind a trainee
//! who has become proficient, do not count against them afterwards; but once proficient, a
//! CUSUM that reaches the unacceptable limit `h1` at attempt M ends the proficiency: "lapsed:
//! unacceptable failure rate since attempt M, retrain". A lapsed trainee is not proficient
//! (nor are the curriculum modules that need the exercise) until they again complete the
//! consecutive passes, when the CUSUM restarts once more. While learning, an unacceptable
//! signal only confirms that the trainee is not proficient yet.
//!
//! **Score.** Per metric, the distance to the limit in units of the expert margin
//! `|limit - mu|`: lower-is-better `s = (upper - x) / (upper - mu)`, higher-is-better
//! `s = (x - lower) / (mu - lower)`, two-sided `s = 1 - d / m` with `d` the distance from `x` to
//! the expert band `[a, b]` and `m` the margin on that side (`upper - b` or `a - lower`); so
//! `s = 1` at the expert mean (and, two-sided, anywhere between it and the plan), `0` at the
//! threshold, negative beyond; clamped to `[-1, 1]` (a missing
//! value is `-1`). The overall score is the mean of `s` over the thresholded metrics: in
//! `[-1, 1]`, higher is better, an attempt at the expert mean scores 1, one on every threshold
//! 0, and `score >= 0` is necessary (not sufficient) for a pass. (A degenerate margin, all
//! experts equal, gives `s = 1` within the limit and `-1` beyond.)
//!
//! **CUSUM** of failures (Bolsin and Colson 2000; Rogers et al. 2004): with acceptable and
//! unacceptable failure rates `p0 < p1` and error rates `alpha`, `beta`:
//! `P = ln(p1 / p0)`, `Q = ln((1 - p0) / (1 - p1))`, `s = Q / (P + Q)`; each failure adds
//! `1 - s`, each pass subtracts `s`. The chart signals an unacceptable rate when it reaches
//! `h1 = ln((1 - beta) / alpha) / (P + Q)` and an acceptable one when it falls to
//! `-h0 = -ln((1 - alpha) / beta) / (P + Q)`. [`cusum`] is the plain chart of a pass/fail
//! sequence; [`Course`] restarts it as the standing changes (above).

use serde::{Deserialize, Serialize};

use crate::error::{Result, ScoreError};
use crate::metrics::{Better, MetricValue};

/// Metrics that are feedback only: they have an expert reference (and limits, shown) but do
/// not decide pass/fail or the score, until thresholds come from people. A person's time,
/// path, movements and smoothness with a mouse or a pen are not a scripted expert's (who
/// makes one movement), and a reach, a lift or a pause is not a skill error; see
/// docs/decisions.md ("What decides a verdict").
pub const FEEDBACK_ONLY: &[&str] = &["time_s", "path_length_m", "movements", "ldlj"];

/// The share of the planned line an attempt must have cut within the tolerance to have done
/// the task at all: below it (no cut, or a cut far from the plan) no metric passes.
pub const TASK_DONE_MIN_FRACTION: f64 = 0.5;

/// Whether metric `key` decides pass/fail (thresholded and not [`FEEDBACK_ONLY`]).
pub fn decides(key: &str) -> bool {
    !FEEDBACK_ONLY.contains(&key)
}

/// Consecutive passes that make a trainee proficient.
pub const REQUIRED_CONSECUTIVE_PASSES: u32 = 2;
/// Expert values with `|z|` above this are outliers.
pub const OUTLIER_Z: f64 = 1.96;
/// The default `k` of `mean +/- k SD`.
pub const DEFAULT_K: f64 = 2.0;

/// The limits of one metric.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Threshold {
    pub key: String,
    pub better: Better,
    /// The experts' mean (the reference value for the score).
    pub mean: f64,
    /// The experts' sample SD after outlier removal, at least [`sd_floor`] (0 for hand-set
    /// thresholds).
    pub sd: f64,
    /// Expert values used (0 for hand-set thresholds).
    pub n_experts: usize,
    pub lower: Option<f64>,
    pub upper: Option<f64>,
}

impl Threshold {
    /// A hand-set threshold: the reference (expert-like) value and the limit on the metric's
    /// bad side (two-sided: the margin on both sides of the expert band).
    pub fn fixed(key: &str, better: Better, reference: f64, limit: f64) -> Self {
        let (lower, upper) = limits(better, reference, (limit - reference).abs());
        Self {
            key: key.into(),
            better,
            mean: reference,
            sd: 0.0,
            n_experts: 0,
            lower,
            upper,
        }
    }

    /// Whether `value` is within the limits.
    pub fn passes(&self, value: f64) -> bool {
        value.is_finite()
            && self.lower.is_none_or(|l| value >= l)
            && self.upper.is_none_or(|u| value <= u)
    }

    /// The per-metric score in `[-1, 1]` (see the module documentation).
    pub fn score(&self, value: f64) -> f64 {
        if !value.is_finite() {
            return -1.0;
        }
        let raw = match (self.better, self.lower, self.upper) {
            (Better::LowerIsBetter, _, Some(u)) => ratio(u - value, u - self.mean),
            (Better::HigherIsBetter, Some(l), _) => ratio(value - l, self.mean - l),
            (Better::TwoSided, l, u) => {
                let (a, b) = expert_band(self.mean);
                // the margin on each side (a side without a limit borrows the other's)
                let above = u.map(|u| u - b).or(l.map(|l| a - l));
                let below = l.map(|l| a - l).or(above);
                match (value > b, value < a) {
                    (true, _) => above.map_or(1.0, |m| 1.0 - ratio(value - b, m)),
                    (_, true) => below.map_or(1.0, |m| 1.0 - ratio(a - value, m)),
                    _ => 1.0,
                }
            }
            _ => 1.0,
        };
        let raw = if raw.is_finite() {
            raw
        } else if self.passes(value) {
            1.0
        } else {
            -1.0
        };
        raw.clamp(-1.0, 1.0)
    }
}

/// The expert band of a two-sided metric (a signed error, ideal 0) with expert mean `mu`:
/// `[min(mu, 0), max(mu, 0)]`.
fn expert_band(mu: f64) -> (f64, f64) {
    (mu.min(0.0), mu.max(0.0))
}

/// The limits `margin` beyond the reference `mu` on the metric's bad side (two-sided: beyond
/// the expert band on both sides).
fn limits(better: Better, mu: f64, margin: f64) -> (Option<f64>, Option<f64>) {
    match better {
        Better::LowerIsBetter => (None, Some(mu + margin)),
        Better::HigherIsBetter => (Some(mu - margin), None),
        Better::TwoSided => {
            let (a, b) = expert_band(mu);
            (Some(a - margin), Some(b + margin))
        }
    }
}

/// `a / b`, with a zero margin mapped to +-infinity (then clamped) or 1 for `a = 0`.
fn ratio(a: f64, b: f64) -> f64 {
    if b.abs() > 1e-300 {
        a / b
    } else if a == 0.0 {
        1.0
    } else {
        f64::INFINITY.copysign(a)
    }
}

/// The thresholds of one exercise.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct Thresholds {
    /// The `k` they were derived with (informative for hand-set ones).
    pub k: f64,
    pub metrics: Vec<Threshold>,
}

/// One metric's verdict.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct MetricVerdict {
    pub key: String,
    pub value: Option<f64>,
    pub pass: bool,
    pub score: f64,
}

/// An attempt's verdict.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Verdict {
    pub metrics: Vec<MetricVerdict>,
    /// Every thresholded metric passes (and there is at least one).
    pub pass: bool,
    /// The normalised overall score in `[-1, 1]`.
    pub score: f64,
}

fn mean_sd(x: &[f64]) -> (f64, f64) {
    let n = x.len() as f64;
    let mean = x.iter().sum::<f64>() / n;
    let sd = if x.len() > 1 {
        (x.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / (n - 1.0)).sqrt()
    } else {
        0.0
    };
    (mean, sd)
}

/// Relative floor of the SD a threshold is derived with: 5 % of the experts' mean.
pub const SD_FLOOR_FRACTION: f64 = 0.05;

/// The smallest SD a threshold is derived with: [`SD_FLOOR_FRACTION`] of `|mean|`, and at
/// least what a person resolves (0.5 mm: a person at the station places the blade to about
/// a millimetre, so that a band is at least 1 mm wide either side at `k = 2`; 0.5 degrees;
/// 0.1 s; 0.05 N; 0.02 of a fraction; 1 mm^2). Experts who repeat an exercise almost identically (a
/// scripted hand, a scene with little to vary) give a near-zero SD, and thresholds that no
/// other attempt, however good, could meet: the demo's six scripted experts all cut 1.41 mm
/// deeper than planned, within 9 um of each other.
pub fn sd_floor(unit: &str, mean: f64) -> f64 {
    let resolution: f64 = match unit {
        "m" => 5e-4,
        "deg" => 0.5,
        "s" => 0.1,
        "N" => 0.05,
        "1" => 0.02,
        "m^2" => 1e-6,
        _ => 0.0,
    };
    resolution.max(SD_FLOOR_FRACTION * mean.abs())
}

/// Expert values of one metric without the outliers (`|z| > 1.96`).
pub fn without_outliers(x: &[f64]) -> Vec<f64> {
    let (mean, sd) = mean_sd(x);
    if !(sd > 0.0) {
        return x.to_vec();
    }
    x.iter()
        .copied()
        .filter(|v| ((v - mean) / sd).abs() <= OUTLIER_Z)
        .collect()
}

impl Thresholds {
    /// Thresholds from expert attempts' metric values (`k` > 0).
    pub fn from_experts(attempts: &[Vec<MetricValue>], k: f64) -> Result<Self> {
        if !(k > 0.0) || !k.is_finite() {
            return Err(ScoreError::InvalidInput(format!("k = {k}: must be > 0")));
        }
        let mut metrics = Vec::new();
        for m in crate::metrics::all().filter(|m| m.scored) {
            let x: Vec<f64> = attempts
                .iter()
                .filter_map(|a| crate::metrics::value_of(a, m.key))
                .collect();
            if x.len() < 2 {
                continue;
            }
            let kept = without_outliers(&x);
            let (mean, sd) = mean_sd(&kept);
            let sd = sd.max(sd_floor(m.unit, mean));
            let (lower, upper) = limits(m.better, mean, k * sd);
            metrics.push(Threshold {
                key: m.key.into(),
                better: m.better,
                mean,
                sd,
                n_experts: kept.len(),
                lower,
                upper,
            });
        }
        Ok(Self { k, metrics })
    }

    /// The thresholds with the plan's tolerance (m) as the floor of every band of a distance
    /// from the plan ([`crate::metrics::Metric::from_plan`]): an error within the tolerance
    /// passes whatever the experts' spread, as the plan says it counts as on the plan. Experts
    /// who all cut within 9 um of each other (a scripted hand) would otherwise fail a person
    /// who follows the plan within its own tolerance. A limit already wider stays.
    pub fn within_plan_tolerance(mut self, tolerance_m: f64) -> Self {
        if !(tolerance_m > 0.0 && tolerance_m.is_finite()) {
            return self;
        }
        for t in &mut self.metrics {
            if !crate::metrics::metric(&t.key).is_some_and(|m| m.from_plan) {
                continue;
            }
            t.upper = t.upper.map(|u| u.max(tolerance_m));
            if t.better == Better::TwoSided {
                t.lower = t.lower.map(|l| l.min(-tolerance_m));
            }
        }
        self
    }

    /// The verdict on one attempt's metric values.
    pub fn verdict(&self, attempt: &[MetricValue]) -> Verdict {
        let done = task_done(attempt);
        let metrics: Vec<MetricVerdict> = self
            .metrics
            .iter()
            .filter(|t| decides(&t.key) && !crate::metrics::not_measured(attempt, &t.key))
            .map(|t| {
                let value = crate::metrics::value_of(attempt, &t.key);
                MetricVerdict {
                    key: t.key.clone(),
                    value,
                    pass: done && value.is_some_and(|v| t.passes(v)),
                    score: match value {
                        Some(v) if done => t.score(v),
                        _ => -1.0,
                    },
                }
            })
            .collect();
        let pass = !metrics.is_empty() && metrics.iter().all(|m| m.pass);
        let score = if metrics.is_empty() {
            0.0
        } else {
            metrics.iter().map(|m| m.score).sum::<f64>() / metrics.len() as f64
        };
        Verdict {
            metrics,
            pass,
            score,
        }
    }
}

/// Whether the attempt did the task: at least [`TASK_DONE_MIN_FRACTION`] of the planned line
/// cut within the tolerance. An attempt without that metric (a kind of exercise that does not
/// measure it) is taken as done.
pub fn task_done(attempt: &[MetricValue]) -> bool {
    match attempt
        .iter()
        .find(|m| m.key == "fraction_cut_in_tolerance")
    {
        None => true,
        Some(m) => m.value.is_some_and(|f| f >= TASK_DONE_MIN_FRACTION),
    }
}

/// A trainee's standing in one exercise.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct ProficiencyState {
    pub attempts: u32,
    pub passes: u32,
    pub consecutive_passes: u32,
    /// Proficient now: reached [`REQUIRED_CONSECUTIVE_PASSES`] consecutive passes, and no
    /// lapse since ([`Course`]).
    pub proficient: bool,
}

impl ProficiencyState {
    /// The state after a sequence of pass/fail outcomes, oldest first ([`Course`] with the
    /// default CUSUM parameters).
    pub fn from_outcomes(passes: &[bool]) -> Self {
        Course::of(passes, &CusumParams::default())
            .map(|c| c.state)
            .unwrap_or_default()
    }
}

/// Where a trainee stands in an exercise after their scored attempts (see the module
/// documentation, "Proficiency and CUSUM"). Attempts are numbered from 1 among the scored
/// ones, oldest first.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case", tag = "state")]
pub enum ProficiencyStatus {
    /// Not proficient yet (no attempt, or never the consecutive passes).
    #[default]
    Learning,
    /// Proficient since attempt `since`, the one that completed the consecutive passes.
    Proficient { since: u32 },
    /// Was proficient; the CUSUM after it reached the unacceptable limit at attempt `since`:
    /// to retrain, proficient again after the consecutive passes.
    Lapsed { since: u32 },
}

/// A trainee's course through an exercise: the counters, the standing and the CUSUM chart
/// restarted with each change of standing (see the module documentation).
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct Course {
    /// The counters; `state.proficient` is whether the trainee is proficient now.
    pub state: ProficiencyState,
    pub status: ProficiencyStatus,
    /// The attempt that first completed the consecutive passes: the trials to proficiency.
    pub first_proficient: Option<u32>,
    /// Per attempt, the CUSUM after it in its phase, with its signal (at an attempt that
    /// changed the standing: the phase it ended).
    pub cusum: Vec<CusumPoint>,
    /// The attempts after which the CUSUM restarted from 0 (the standing changed at them).
    pub restarts: Vec<u32>,
    /// The CUSUM now: after the last attempt, 0 with no signal when the standing changed at it.
    pub current: CusumPoint,
}

impl Course {
    /// The course of a pass/fail sequence, oldest first.
    pub fn of(passes: &[bool], params: &CusumParams) -> Result<Self> {
        params.check()?;
        let s = params.s();
        let fresh = CusumPoint {
            value: 0.0,
            signal: CusumSignal::None,
        };
        let mut c = Course {
            current: fresh,
            ..Course::default()
        };
        for (n, &pass) in (1u32..).zip(passes) {
            let st = &mut c.state;
            st.attempts += 1;
            if pass {
                st.passes += 1;
                st.consecutive_passes += 1;
            } else {
                st.consecutive_passes = 0;
            }
            let value = c.current.value + if pass { -s } else { 1.0 - s };
            let point = CusumPoint {
                value,
                signal: params.signal(value),
            };
            c.cusum.push(point);
            c.current = point;
            let changed = match c.status {
                ProficiencyStatus::Proficient { .. }
                    if point.signal == CusumSignal::Unacceptable =>
                {
                    Some(ProficiencyStatus::Lapsed { since: n })
                }
                ProficiencyStatus::Learning | ProficiencyStatus::Lapsed { .. }
                    if st.consecutive_passes >= REQUIRED_CONSECUTIVE_PASSES =>
                {
                    c.first_proficient.get_or_insert(n);
                    Some(ProficiencyStatus::Proficient { since: n })
                }
                _ => None,
            };
            if let Some(status) = changed {
                c.status = status;
                c.restarts.push(n);
                c.current = fresh;
            }
            c.state.proficient = matches!(c.status, ProficiencyStatus::Proficient { .. });
        }
        Ok(c)
    }
}

/// Parameters of the CUSUM chart.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct CusumParams {
    /// Acceptable failure rate.
    pub p0: f64,
    /// Unacceptable failure rate.
    pub p1: f64,
    /// Type I error (signalling unacceptable when acceptable).
    pub alpha: f64,
    /// Type II error.
    pub beta: f64,
}

impl Default for CusumParams {
    fn default() -> Self {
        Self {
            p0: 0.10,
            p1: 0.20,
            alpha: 0.10,
            beta: 0.10,
        }
    }
}

impl CusumParams {
    /// Checks `0 < p0 < p1 < 1` and `0 < alpha, beta < 1`.
    pub fn check(&self) -> Result<()> {
        let ok = 0.0 < self.p0
            && self.p0 < self.p1
            && self.p1 < 1.0
            && 0.0 < self.alpha
            && self.alpha < 1.0
            && 0.0 < self.beta
            && self.beta < 1.0;
        if ok {
            Ok(())
        } else {
            Err(ScoreError::InvalidInput(format!(
                "CUSUM parameters {self:?}: need 0 < p0 < p1 < 1, 0 < alpha, beta < 1"
            )))
        }
    }
    fn p_plus_q(&self) -> f64 {
        (self.p1 / self.p0).ln() + ((1.0 - self.p0) / (1.0 - self.p1)).ln()
    }
    /// The decrement per pass, `s = Q / (P + Q)`.
    pub fn s(&self) -> f64 {
        ((1.0 - self.p0) / (1.0 - self.p1)).ln() / self.p_plus_q()
    }
    /// The lower decision limit's magnitude `h0` (acceptable at `-h0`).
    pub fn h0(&self) -> f64 {
        ((1.0 - self.alpha) / self.beta).ln() / self.p_plus_q()
    }
    /// The upper decision limit `h1` (unacceptable).
    pub fn h1(&self) -> f64 {
        ((1.0 - self.beta) / self.alpha).ln() / self.p_plus_q()
    }
    /// What a CUSUM value says against the limits.
    pub fn signal(&self, value: f64) -> CusumSignal {
        if value >= self.h1() {
            CusumSignal::Unacceptable
        } else if value <= -self.h0() {
            CusumSignal::Acceptable
        } else {
            CusumSignal::None
        }
    }
}

/// What a CUSUM point says.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum CusumSignal {
    #[default]
    None,
    /// At or below `-h0`: the failure rate is acceptable (`p0`).
    Acceptable,
    /// At or above `h1`: the failure rate is unacceptable (`p1`).
    Unacceptable,
}

/// One point of the chart, after an attempt.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct CusumPoint {
    pub value: f64,
    pub signal: CusumSignal,
}

/// The CUSUM chart of a pass/fail sequence (no reset at the limits; [`Course`] restarts it
/// as the standing changes).
pub fn cusum(passes: &[bool], params: &CusumParams) -> Result<Vec<CusumPoint>> {
    params.check()?;
    let s = params.s();
    let mut value = 0.0;
    Ok(passes
        .iter()
        .map(|&pass| {
            value += if pass { -s } else { 1.0 - s };
            CusumPoint {
                value,
                signal: params.signal(value),
            }
        })
        .collect())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn motion_is_feedback_and_an_attempt_that_did_not_cut_passes_nothing() {
        let t = Thresholds {
            k: 2.0,
            metrics: vec![
                Threshold::fixed("lateral_mean_m", Better::LowerIsBetter, 0.0005, 0.002),
                Threshold::fixed(
                    "fraction_cut_in_tolerance",
                    Better::HigherIsBetter,
                    0.95,
                    0.8,
                ),
                Threshold::fixed("time_s", Better::LowerIsBetter, 4.0, 5.5),
                Threshold::fixed("movements", Better::LowerIsBetter, 1.0, 1.1),
                Threshold::fixed("peak_force_n", Better::LowerIsBetter, 0.5, 2.5),
            ],
        };
        // a careful person: the line right, slower than a script and in three movements
        let careful = attempt(&[
            ("lateral_mean_m", 0.0006),
            ("fraction_cut_in_tolerance", 0.99),
            ("time_s", 11.3),
            ("movements", 3.0),
            ("peak_force_n", 1.2),
        ]);
        let v = t.verdict(&careful);
        assert!(v.pass, "{v:?}");
        assert!(v.metrics.iter().all(|m| decides(&m.key)));
        assert_eq!(v.metrics.len(), 3, "time and movements do not decide");
        // started and stopped without cutting: the geometry is missing or nil, nothing passes
        let idle = attempt(&[
            ("fraction_cut_in_tolerance", 0.0),
            ("time_s", 0.5),
            ("movements", 0.0),
            ("peak_force_n", 0.0),
        ]);
        let v = t.verdict(&idle);
        assert!(!v.pass && v.metrics.iter().all(|m| !m.pass), "{v:?}");
        assert_eq!(v.score, -1.0);
        // a sloppy cut that did the task scores above doing nothing
        let sloppy = attempt(&[
            ("lateral_mean_m", 0.003),
            ("fraction_cut_in_tolerance", 0.6),
            ("peak_force_n", 2.0),
        ]);
        let v = t.verdict(&sloppy);
        assert!(!v.pass && v.score > -1.0, "{v:?}");
    }

    #[test]
    fn a_metric_the_device_cannot_measure_neither_fails_nor_counts() {
        // a threshold on the approach angle (hand-set, or from a hub's experts)
        let t = Thresholds {
            k: 2.0,
            metrics: vec![
                Threshold::fixed("lateral_mean_m", Better::LowerIsBetter, 0.0005, 0.002),
                Threshold::fixed("approach_error_deg", Better::LowerIsBetter, 2.0, 10.0),
            ],
        };
        let with = |missing: &str| {
            let mut a = attempt(&[("lateral_mean_m", 0.0005)]);
            let m = crate::metrics::metric("approach_error_deg").unwrap();
            a.push(MetricValue {
                key: m.key.into(),
                value: None,
                unit: m.unit.into(),
                better: m.better,
                scored: m.scored,
                missing: Some(missing.into()),
            });
            a
        };
        let pointer = t.verdict(&with(&format!(
            "{}: the pointer pushes the blade in",
            crate::metrics::NOT_MEASURED_WITH_DEVICE
        )));
        assert!(pointer.pass, "{pointer:?}");
        assert_eq!(pointer.metrics.len(), 1, "left out of the verdict");
        assert!((pointer.score - 1.0).abs() < 1e-12, "and of the score");
        // missing for what the trainee did (no approach before the cut): a fail, as before
        let other = t.verdict(&with("no approach before a first cut"));
        assert!(!other.pass && other.metrics.len() == 2, "{other:?}");
        assert!(
            (other.score - 0.0).abs() < 1e-12,
            "(1 - 1) / 2: {}",
            other.score
        );
    }

    #[test]
    fn proficiency_lapses_when_the_cusum_after_it_is_unacceptable() {
        let p = CusumParams::default();
        // failing while learning, then proficient: the learning's failures are behind
        let mut passes = vec![false; 5];
        passes.extend([true, true]);
        let learning = cusum(&passes, &p).unwrap();
        assert_eq!(
            learning[6].signal,
            CusumSignal::Unacceptable,
            "{learning:?}"
        );
        let c = Course::of(&passes, &p).unwrap();
        assert_eq!(c.status, ProficiencyStatus::Proficient { since: 7 });
        assert!(c.state.proficient && c.first_proficient == Some(7));
        assert_eq!(
            (c.restarts.clone(), c.current),
            (vec![7], CusumPoint::default())
        );
        assert_eq!(
            c.cusum[6], learning[6],
            "the point at 7 ends the learning phase"
        );
        // failures after it: the CUSUM counts from 0 and lapses where it reaches h1
        let mut after = passes.clone();
        let needed = (p.h1() / (1.0 - p.s())).ceil() as usize;
        after.extend(vec![false; needed]);
        let c = Course::of(&after, &p).unwrap();
        let m = u32::try_from(after.len()).unwrap();
        assert_eq!(c.status, ProficiencyStatus::Lapsed { since: m }, "{c:?}");
        assert!(!c.state.proficient && c.first_proficient == Some(7));
        assert_eq!(c.cusum.last().unwrap().signal, CusumSignal::Unacceptable);
        let short = Course::of(&after[..after.len() - 1], &p).unwrap();
        assert_eq!(short.status, ProficiencyStatus::Proficient { since: 7 });
        assert_ne!(short.current.signal, CusumSignal::Unacceptable);
        assert_eq!(ProficiencyState::from_outcomes(&after), c.state);
        // two passes again: proficient since the second, the CUSUM restarted once more
        after.extend([true, true]);
        let c = Course::of(&after, &p).unwrap();
        assert_eq!(c.status, ProficiencyStatus::Proficient { since: m + 2 });
        assert_eq!(c.restarts, vec![7, m, m + 2]);
        assert!(c.state.proficient);
    }

    fn attempt(pairs: &[(&str, f64)]) -> Vec<MetricValue> {
        pairs
            .iter()
            .map(|(k, v)| {
                let m = crate::metrics::metric(k).unwrap();
                MetricValue {
                    key: (*k).into(),
                    value: Some(*v),
                    unit: m.unit.into(),
                    better: m.better,
                    scored: m.scored,
                    missing: None,
                }
            })
            .collect()
    }

    #[test]
    fn thresholds_by_hand_with_an_outlier_removed() {
        // lateral_mean_m: 1..=9 mm and an outlier at 40 mm
        let mut experts: Vec<Vec<MetricValue>> = (1..=9)
            .map(|i| {
                attempt(&[
                    ("lateral_mean_m", i as f64),
                    ("fraction_cut_in_tolerance", 0.9),
                    ("depth_error_m", if i % 2 == 0 { 1.0 } else { -1.0 }),
                ])
            })
            .collect();
        experts.push(attempt(&[
            ("lateral_mean_m", 40.0),
            ("fraction_cut_in_tolerance", 0.9),
            ("depth_error_m", 0.0),
        ]));
        let t = Thresholds::from_experts(&experts, 2.0).unwrap();
        let lat = t
            .metrics
            .iter()
            .find(|m| m.key == "lateral_mean_m")
            .unwrap();
        // all 10: mean 8.5, sd 11.72; z(40) = 2.69 > 1.96 removed; 1..9: mean 5, sd sqrt(7.5)
        assert_eq!(lat.n_experts, 9);
        assert!((lat.mean - 5.0).abs() < 1e-12);
        assert!((lat.sd - 7.5f64.sqrt()).abs() < 1e-12);
        assert_eq!(lat.lower, None);
        assert!((lat.upper.unwrap() - (5.0 + 2.0 * 7.5f64.sqrt())).abs() < 1e-12);
        let frac = t
            .metrics
            .iter()
            .find(|m| m.key == "fraction_cut_in_tolerance")
            .unwrap();
        // all equal: sd 0, nothing removed; the limit is 2 floors of the SD below (5 % of 0.9)
        assert!(
            (frac.sd - 0.045).abs() < 1e-12
                && (frac.lower.unwrap() - 0.81).abs() < 1e-12
                && frac.upper.is_none(),
            "{frac:?}"
        );
        assert_eq!(frac.n_experts, 10);
        let depth = t.metrics.iter().find(|m| m.key == "depth_error_m").unwrap();
        assert!(depth.lower.is_some() && depth.upper.is_some(), "two-sided");
        assert_eq!(
            t.metrics.len(),
            3,
            "metrics without expert values get no threshold"
        );
        assert!(Thresholds::from_experts(&experts, 0.0).is_err());
    }

    /// Issue 63: experts who all cut 1.4 mm deep within micrometres of each other made a band
    /// of +-1.1 mm that a person following the plan within its 2 mm tolerance failed.
    #[test]
    fn the_plans_tolerance_is_the_floor_of_the_bands_of_errors_from_the_plan() {
        let experts: Vec<Vec<MetricValue>> = (0..6)
            .map(|i| {
                let e = i as f64 * 1e-6;
                attempt(&[
                    ("depth_error_m", 1.4e-3 + e),
                    ("lateral_mean_m", 2e-4 + e),
                    ("time_s", 4.0 + e),
                ])
            })
            .collect();
        let narrow = Thresholds::from_experts(&experts, 2.0).unwrap();
        let wide = narrow.clone().within_plan_tolerance(2e-3);
        let limits = |t: &Thresholds, key: &str| {
            let m = t.metrics.iter().find(|m| m.key == key).unwrap();
            (m.lower, m.upper)
        };
        // a person 1.9 mm shallow, 1.5 mm off the line: out by the experts' spread alone
        let person = attempt(&[
            ("depth_error_m", -1.9e-3),
            ("lateral_mean_m", 1.5e-3),
            ("time_s", 4.5),
        ]);
        assert!(!narrow.verdict(&person).pass);
        assert_eq!(limits(&wide, "depth_error_m").0, Some(-2e-3));
        assert_eq!(
            limits(&wide, "depth_error_m").1,
            limits(&narrow, "depth_error_m").1,
            "a limit already beyond the tolerance stays"
        );
        assert_eq!(limits(&wide, "lateral_mean_m").1, Some(2e-3));
        assert_eq!(
            limits(&wide, "time_s"),
            limits(&narrow, "time_s"),
            "the time is no distance from the plan"
        );
        let v = wide.verdict(&person);
        assert!(v.pass, "{v:?}");
        // beyond the tolerance still fails
        let off = attempt(&[
            ("depth_error_m", -2.1e-3),
            ("lateral_mean_m", 1.5e-3),
            ("time_s", 4.5),
        ]);
        assert!(!wide.verdict(&off).pass);
    }

    #[test]
    fn the_sd_floor_is_relative_and_at_least_the_resolution() {
        assert_eq!(sd_floor("m", 0.0), 5e-4);
        assert!((sd_floor("m", 0.1) - 0.005).abs() < 1e-15);
        assert_eq!(sd_floor("deg", -1.0), 0.5);
        assert!((sd_floor("s", -10.0) - 0.5).abs() < 1e-15);
        assert_eq!(sd_floor("rad", 0.0), 0.0);
    }

    #[test]
    fn pass_and_score_by_hand() {
        let t = Thresholds {
            k: 2.0,
            metrics: vec![
                Threshold::fixed("lateral_mean_m", Better::LowerIsBetter, 1.0, 3.0),
                Threshold::fixed(
                    "fraction_cut_in_tolerance",
                    Better::HigherIsBetter,
                    0.9,
                    0.7,
                ),
                Threshold::fixed("depth_error_m", Better::TwoSided, 0.0, 2.0),
            ],
        };
        let at_mean = t.verdict(&attempt(&[
            ("lateral_mean_m", 1.0),
            ("fraction_cut_in_tolerance", 0.9),
            ("depth_error_m", 0.0),
        ]));
        assert!(at_mean.pass);
        assert!((at_mean.score - 1.0).abs() < 1e-12);
        let on_limits = t.verdict(&attempt(&[
            ("lateral_mean_m", 3.0),
            ("fraction_cut_in_tolerance", 0.7),
            ("depth_error_m", -2.0),
        ]));
        assert!(on_limits.pass);
        assert!(on_limits.score.abs() < 1e-12);
        // lateral 2 -> 0.5; fraction 0.6 -> -0.5 (fails); depth 1 -> 0.5: mean 1/6
        let mixed = t.verdict(&attempt(&[
            ("lateral_mean_m", 2.0),
            ("fraction_cut_in_tolerance", 0.6),
            ("depth_error_m", 1.0),
        ]));
        assert!(!mixed.pass);
        assert!((mixed.score - 1.0 / 6.0).abs() < 1e-12, "{}", mixed.score);
        assert_eq!(
            mixed.metrics.iter().map(|m| m.pass).collect::<Vec<_>>(),
            [true, false, true]
        );
        // far beyond: clamped to -1; missing: -1 and a fail
        let bad = t.verdict(&attempt(&[
            ("lateral_mean_m", 100.0),
            ("fraction_cut_in_tolerance", 0.0),
        ]));
        assert!(!bad.pass);
        assert!((bad.score + 1.0).abs() < 1e-12);
    }

    #[test]
    fn a_cut_closer_to_the_plan_than_the_experts_passes_two_sided() {
        // experts cut 2.2-2.4 mm deeper than planned: mean 2.3 mm, sd 0.1 mm (floor 0.5 mm)
        let experts: Vec<Vec<MetricValue>> = [2.2e-3, 2.3e-3, 2.4e-3]
            .iter()
            .map(|&d| attempt(&[("depth_error_m", d)]))
            .collect();
        let t = Thresholds::from_experts(&experts, 2.0).unwrap();
        let depth = &t.metrics[0];
        assert!((depth.sd - 5e-4).abs() < 1e-15, "{depth:?}");
        // the window reaches from 1 mm too shallow to 1 mm beyond the experts
        assert!(
            (depth.lower.unwrap() + 1e-3).abs() < 1e-15
                && (depth.upper.unwrap() - 3.3e-3).abs() < 1e-15,
            "{depth:?}"
        );
        for (value, score) in [
            (0.0, 1.0),
            (1e-3, 1.0),
            (2.3e-3, 1.0),
            (2.8e-3, 0.5),
            (3.3e-3, 0.0),
            (-5e-4, 0.5),
            (-1e-3, 0.0),
        ] {
            assert!(depth.passes(value), "{value}");
            assert!(
                (depth.score(value) - score).abs() < 1e-9,
                "{value}: {} (expected {score})",
                depth.score(value)
            );
        }
        assert!(!depth.passes(3.4e-3) && !depth.passes(-1.1e-3));
        assert!(depth.score(3.4e-3) < 0.0 && depth.score(-1.1e-3) < 0.0);
        // a band on the other side (experts too shallow) mirrors it
        let shallow = Threshold {
            mean: -2.3e-3,
            lower: Some(-3.3e-3),
            upper: Some(1e-3),
            ..depth.clone()
        };
        assert!(
            (shallow.score(-1e-3) - 1.0).abs() < 1e-12 && (shallow.score(5e-4) - 0.5).abs() < 1e-9
        );
    }

    #[test]
    fn proficient_after_two_consecutive_passes() {
        assert!(!ProficiencyState::from_outcomes(&[true, false, true, false]).proficient);
        let s = ProficiencyState::from_outcomes(&[false, true, true, false]);
        assert!(s.proficient, "stays proficient through a failure");
        assert_eq!((s.attempts, s.passes, s.consecutive_passes), (4, 2, 0));
    }

    #[test]
    fn cusum_by_hand() {
        let p = CusumParams::default();
        // P = ln 2, Q = ln 1.125, s = Q / (P + Q), h0 = h1 = ln 9 / (P + Q)
        let pq = 2f64.ln() + 1.125f64.ln();
        assert!((p.s() - 0.145245).abs() < 1e-6, "{}", p.s());
        assert!((p.h1() - 2.709511).abs() < 1e-6, "{}", p.h1());
        assert!((p.h0() - 9f64.ln() / pq).abs() < 1e-12);
        let c = cusum(&[false, true, true, false], &p).unwrap();
        let expected = [0.8547556, 0.7095113, 0.5642669, 1.4190226];
        for (point, e) in c.iter().zip(expected) {
            assert!((point.value - e).abs() < 1e-6, "{c:?}");
            assert_eq!(point.signal, CusumSignal::None);
        }
        // 2.709511 / 0.145245 = 18.65: acceptable at the 19th pass in a row
        let passes = cusum(&[true; 19], &p).unwrap();
        assert_eq!(passes[17].signal, CusumSignal::None);
        assert_eq!(passes[18].signal, CusumSignal::Acceptable);
        // 4 failures: 3.419 >= 2.7095
        let fails = cusum(&[false; 4], &p).unwrap();
        assert_eq!(fails[2].signal, CusumSignal::None);
        assert_eq!(fails[3].signal, CusumSignal::Unacceptable);
        assert!(
            cusum(
                &[true],
                &CusumParams {
                    p0: 0.3,
                    p1: 0.2,
                    ..p
                }
            )
            .is_err()
        );
    }
}
