//! The evidence report of one exercise, built from its attempts.

use std::collections::BTreeMap;

use serde::Serialize;

use super::Experience;
use crate::metrics::{self, Better};
use crate::stats::{self, CutScore, Plateau};

/// The key the overall score is reported under, beside the metrics' keys.
pub const SCORE_KEY: &str = "score";

/// One complete attempt as the report sees it.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct EvidenceAttempt {
    pub attempt_id: i64,
    pub trainee_id: i64,
    pub trainee: String,
    /// The trainee's recorded experience (`None`: not recorded; left out of the groups).
    pub experience: Option<Experience>,
    pub started_ns: i64,
    /// A reference attempt (it set the thresholds its score is measured against).
    pub reference: bool,
    /// The overall score in [-1, 1].
    pub score: Option<f64>,
    /// The metric values the attempt has (SI units), by key; `KEY@TOOL` is the catalogue
    /// metric `KEY` of one tool of several.
    pub metrics: Vec<(String, f64)>,
    /// An expert rater's rating of the attempt (e.g. a GRS), where there is one.
    pub rating: Option<f64>,
}

impl EvidenceAttempt {
    fn value(&self, key: &str) -> Option<f64> {
        if key == SCORE_KEY {
            return self.score.filter(|s| s.is_finite());
        }
        self.metrics
            .iter()
            .find(|(k, _)| k == key)
            .map(|(_, v)| *v)
            .filter(|v| v.is_finite())
    }
}

/// How the report is made.
#[derive(Debug, Clone, PartialEq)]
pub struct EvidenceOptions {
    /// Count the reference attempts (those that set the thresholds) in their group.
    pub include_reference: bool,
    /// Bootstrap resamples of each AUC's interval.
    pub resamples: usize,
    /// The bootstrap's seed (the report is reproducible).
    pub seed: u64,
    /// What a two-sided metric is measured from (the experts' mean), by key: its distance
    /// from it is what improves. A two-sided metric without one is measured from the more
    /// experienced group's median.
    pub two_sided_reference: BTreeMap<String, f64>,
    /// What the attempts' `score` is ("Overall score"; "Rating" for imported trials).
    pub score_label: String,
    /// How near its plateau a learning curve's score must stay (0.1 on the overall score's
    /// [-1, 1]).
    pub plateau_band: f64,
}

impl Default for EvidenceOptions {
    fn default() -> Self {
        Self {
            score_label: "Overall score".into(),
            plateau_band: 0.1,
            include_reference: true,
            resamples: 2000,
            seed: 45,
            two_sided_reference: BTreeMap::new(),
        }
    }
}

/// One experience group.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Group {
    pub level: Experience,
    pub trainees: usize,
    pub attempts: usize,
    pub reference_attempts: usize,
}

/// A measure's values in one group (SI units).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct GroupValues {
    pub level: Experience,
    pub values: Vec<f64>,
}

/// The more experienced group against the less experienced one on one measure.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Comparison {
    pub n_higher: usize,
    pub n_lower: usize,
    pub median_higher: f64,
    pub median_lower: f64,
    /// U of the more experienced group (on the measure oriented so that larger is better).
    pub u: f64,
    pub p: f64,
    pub exact_p: bool,
    /// The probability that an attempt of the more experienced group is better than one of
    /// the other (0.5: no better than chance).
    pub auc: f64,
    pub auc_low: f64,
    pub auc_high: f64,
}

/// What a measure's comparison says.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum Finding {
    /// The AUC's 95 % interval lies above 0.5.
    Discriminates,
    /// The interval lies below 0.5: the less experienced do better.
    Reversed,
    /// The interval holds 0.5.
    DoesNotDiscriminate,
    /// Not computed (see `why_not`).
    NotComputed,
}

impl Finding {
    /// Plain words for reports.
    pub fn words(self) -> &'static str {
        match self {
            // the rule is the AUC's interval, not the p value beside it: said with the word
            Finding::Discriminates => "discriminates (AUC interval above 0.5)",
            Finding::Reversed => {
                "reversed: the less experienced do better (AUC interval below 0.5)"
            }
            Finding::DoesNotDiscriminate => "does not discriminate (AUC interval holds 0.5)",
            Finding::NotComputed => "not computed",
        }
    }
}

/// The overall score or one metric.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Measure {
    pub key: String,
    pub label: String,
    /// SI unit of `values` and the medians.
    pub unit: String,
    pub better: Better,
    pub groups: Vec<GroupValues>,
    pub comparison: Option<Comparison>,
    pub finding: Finding,
    /// ICC(2,1) of the measure over each trainee's last two attempts.
    pub icc: Option<f64>,
    pub why_not: Option<String>,
}

/// Test-retest reliability of the overall score.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Reliability {
    /// Trainees with two or more scored attempts (their last two are the pair).
    pub trainees: usize,
    pub icc: Option<f64>,
    /// Koo and Li's (2016) band: poor, moderate, good, excellent.
    pub band: Option<&'static str>,
    pub why_not: Option<String>,
}

/// One trainee's learning curve of the overall score.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct LearningCurve {
    pub trainee_id: i64,
    pub trainee: String,
    pub experience: Option<Experience>,
    pub scores: Vec<f64>,
    /// Where the curve levels off (four or more attempts).
    pub plateau: Option<Plateau>,
}

/// The contrasting-groups pass mark on the overall score.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct PassMarkFinding {
    /// The group that should pass and the one that should not.
    pub higher: Option<Experience>,
    pub lower: Option<Experience>,
    pub n_higher: usize,
    pub n_lower: usize,
    pub cut: Option<CutScore>,
    pub why_not: Option<String>,
}

/// How a metric agrees with the raters' ratings across attempts (concurrent validity).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Concurrent {
    pub key: String,
    pub label: String,
    /// Attempts with both the metric and a rating.
    pub n: usize,
    /// Spearman's rho of the metric with the rating (its sign: as the metric's direction
    /// says, a metric that improves with skill correlates positively when higher is better).
    pub rho: Option<f64>,
}

/// The validity evidence of one exercise.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Report {
    pub exercise: String,
    pub include_reference: bool,
    pub groups: Vec<Group>,
    /// The groups contrasted: the most and the least experienced with attempts.
    pub higher: Option<Experience>,
    pub lower: Option<Experience>,
    pub score: Measure,
    pub metrics: Vec<Measure>,
    /// The labels of the metrics whose comparison was computed and does not discriminate.
    pub not_discriminating: Vec<String>,
    pub reliability: Reliability,
    pub learning: Vec<LearningCurve>,
    pub pass_mark: PassMarkFinding,
    /// Each metric against the ratings (empty without ratings).
    pub concurrent: Vec<Concurrent>,
    /// Attempts and people left out of the groups: no experience level recorded.
    pub attempts_without_level: usize,
    pub trainees_without_level: usize,
}

impl Report {
    /// The report of `exercise` over `attempts` (complete attempts, any order).
    pub fn build(exercise: &str, attempts: &[EvidenceAttempt], options: &EvidenceOptions) -> Self {
        let mut used: Vec<&EvidenceAttempt> = attempts
            .iter()
            .filter(|a| options.include_reference || !a.reference)
            .collect();
        used.sort_by_key(|a| (a.trainee_id, a.started_ns, a.attempt_id));
        let groups = groups(&used);
        let levels: Vec<Experience> = groups.iter().map(|g| g.level).collect();
        let (higher, lower) = match (levels.last(), levels.first()) {
            (Some(h), Some(l)) if h != l => (Some(*h), Some(*l)),
            _ => (None, None),
        };
        let contrast = Contrast {
            higher,
            lower,
            options,
        };
        let score = contrast.measure(
            &used,
            SCORE_KEY,
            &options.score_label,
            "1",
            Better::HigherIsBetter,
        );
        let keys = metric_keys(&used);
        let metrics: Vec<Measure> = keys
            .iter()
            .map(|key| {
                let (label, unit, better) = definition(key);
                contrast.measure(&used, key, &label, unit, better)
            })
            .collect();
        let not_discriminating = metrics
            .iter()
            .filter(|m| m.finding == Finding::DoesNotDiscriminate)
            .map(|m| m.label.clone())
            .collect();
        let no_level: Vec<&&EvidenceAttempt> =
            used.iter().filter(|a| a.experience.is_none()).collect();
        let mut no_level_people: Vec<i64> = no_level.iter().map(|a| a.trainee_id).collect();
        no_level_people.dedup();
        Report {
            exercise: exercise.to_owned(),
            include_reference: options.include_reference,
            pass_mark: pass_mark(&score, higher, lower),
            reliability: reliability(&used),
            learning: learning(&used, options.plateau_band),
            groups,
            higher,
            lower,
            score,
            metrics,
            not_discriminating,
            concurrent: concurrent(&used, &keys),
            attempts_without_level: no_level.len(),
            trainees_without_level: no_level_people.len(),
        }
    }
}

/// The groups with attempts, from the least experienced.
fn groups(used: &[&EvidenceAttempt]) -> Vec<Group> {
    Experience::ALL
        .into_iter()
        .filter_map(|level| {
            let of: Vec<&&EvidenceAttempt> = used
                .iter()
                .filter(|a| a.experience == Some(level))
                .collect();
            let mut people: Vec<i64> = of.iter().map(|a| a.trainee_id).collect();
            people.dedup();
            (!of.is_empty()).then(|| Group {
                level,
                trainees: people.len(),
                attempts: of.len(),
                reference_attempts: of.iter().filter(|a| a.reference).count(),
            })
        })
        .collect()
}

/// The metric keys the attempts have, in the catalogue's order (a tool's after another's).
fn metric_keys(used: &[&EvidenceAttempt]) -> Vec<String> {
    let mut keys: Vec<String> = used
        .iter()
        .flat_map(|a| a.metrics.iter().map(|(k, _)| k.clone()))
        .collect();
    let base = |k: &str| k.split_once('@').map_or(k, |(b, _)| b).to_owned();
    keys.sort_by(|a, b| {
        let (ba, bb) = (base(a), base(b));
        metrics::catalogue_rank(&ba)
            .cmp(&metrics::catalogue_rank(&bb))
            .then(a.cmp(b))
    });
    keys.dedup();
    keys
}

/// A key's label, SI unit and direction from the catalogue; `KEY@TOOL` as `KEY`'s, the
/// tool named; an unknown key as itself, two-sided.
pub(crate) fn definition(key: &str) -> (String, &'static str, Better) {
    let (base, tool) = key
        .split_once('@')
        .map_or((key, None), |(b, t)| (b, Some(t)));
    match (metrics::metric(base), tool) {
        (Some(d), None) => (d.label.to_owned(), d.unit, d.better),
        (Some(d), Some(t)) => (format!("{} · {t}", d.label), d.unit, d.better),
        (None, _) => (key.to_owned(), "1", Better::TwoSided),
    }
}

/// Spearman's rho of each metric with the ratings, where at least three attempts have both.
fn concurrent(used: &[&EvidenceAttempt], keys: &[String]) -> Vec<Concurrent> {
    if used.iter().all(|a| a.rating.is_none()) {
        return Vec::new();
    }
    keys.iter()
        .map(|key| {
            let (x, y): (Vec<f64>, Vec<f64>) = used
                .iter()
                .filter_map(|a| Some((a.value(key)?, a.rating.filter(|r| r.is_finite())?)))
                .unzip();
            Concurrent {
                key: key.clone(),
                label: definition(key).0,
                n: x.len(),
                rho: stats::spearman(&x, &y),
            }
        })
        .collect()
}

struct Contrast<'a> {
    higher: Option<Experience>,
    lower: Option<Experience>,
    options: &'a EvidenceOptions,
}

impl Contrast<'_> {
    fn measure(
        &self,
        used: &[&EvidenceAttempt],
        key: &str,
        label: &str,
        unit: &str,
        better: Better,
    ) -> Measure {
        let groups: Vec<GroupValues> = Experience::ALL
            .into_iter()
            .map(|level| GroupValues {
                level,
                values: used
                    .iter()
                    .filter(|a| a.experience == Some(level))
                    .filter_map(|a| a.value(key))
                    .collect(),
            })
            .filter(|g| !g.values.is_empty())
            .collect();
        let (comparison, why_not) = self.compare(&groups, key, better);
        let finding = match comparison {
            None => Finding::NotComputed,
            Some(c) if c.auc_low > 0.5 => Finding::Discriminates,
            Some(c) if c.auc_high < 0.5 => Finding::Reversed,
            Some(_) => Finding::DoesNotDiscriminate,
        };
        Measure {
            key: key.to_owned(),
            label: label.to_owned(),
            unit: unit.to_owned(),
            better,
            icc: last_two_icc(used, |a| a.value(key)),
            groups,
            comparison,
            finding,
            why_not,
        }
    }

    fn compare(
        &self,
        groups: &[GroupValues],
        key: &str,
        better: Better,
    ) -> (Option<Comparison>, Option<String>) {
        let (Some(h), Some(l)) = (self.higher, self.lower) else {
            return (
                None,
                Some("needs attempts by people of two experience levels".into()),
            );
        };
        let (vh, vl) = (values_of(groups, Some(h)), values_of(groups, Some(l)));
        for (level, v) in [(h, vh), (l, vl)] {
            if v.len() < 2 {
                return (
                    None,
                    Some(format!(
                        "the {level} group has {} value{}: needs at least 2",
                        v.len(),
                        if v.len() == 1 { "" } else { "s" }
                    )),
                );
            }
        }
        let reference = match better {
            Better::TwoSided => self
                .options
                .two_sided_reference
                .get(key)
                .copied()
                .or_else(|| stats::median(vh)),
            _ => None,
        };
        let good = |v: f64| match better {
            Better::HigherIsBetter => v,
            Better::LowerIsBetter => -v,
            Better::TwoSided => -(v - reference.unwrap_or(0.0)).abs(),
        };
        let (gh, gl): (Vec<f64>, Vec<f64>) = (
            vh.iter().map(|v| good(*v)).collect(),
            vl.iter().map(|v| good(*v)).collect(),
        );
        let (Some(mw), Some((auc_low, auc_high))) = (
            stats::mann_whitney(&gh, &gl),
            stats::auc_interval(&gh, &gl, self.options.resamples, self.options.seed),
        ) else {
            return (None, Some("no finite values to compare".into()));
        };
        let comparison = Comparison {
            n_higher: vh.len(),
            n_lower: vl.len(),
            median_higher: stats::median(vh).unwrap_or(f64::NAN),
            median_lower: stats::median(vl).unwrap_or(f64::NAN),
            u: mw.u_a,
            p: mw.p,
            exact_p: mw.exact,
            auc: mw.auc,
            auc_low,
            auc_high,
        };
        (Some(comparison), None)
    }
}

/// The values of the group at `level` (none when it has no values or `level` is `None`).
fn values_of(groups: &[GroupValues], level: Option<Experience>) -> &[f64] {
    groups
        .iter()
        .find(|g| Some(g.level) == level)
        .map_or(&[][..], |g| g.values.as_slice())
}

/// Each trainee's attempts in order (`used` is sorted by trainee, then time).
fn by_trainee<'a>(used: &[&'a EvidenceAttempt]) -> Vec<Vec<&'a EvidenceAttempt>> {
    used.chunk_by(|a, b| a.trainee_id == b.trainee_id)
        .map(|c| c.to_vec())
        .collect()
}

/// ICC(2,1) of `value` over the last two attempts with a value of each trainee who has two.
fn last_two_icc(
    used: &[&EvidenceAttempt],
    value: impl Fn(&EvidenceAttempt) -> Option<f64>,
) -> Option<f64> {
    let rows: Vec<Vec<f64>> = by_trainee(used)
        .iter()
        .filter_map(|attempts| {
            let v: Vec<f64> = attempts.iter().filter_map(|a| value(a)).collect();
            (v.len() >= 2).then(|| v[v.len() - 2..].to_vec())
        })
        .collect();
    stats::icc_2_1(&rows)
}

fn reliability(used: &[&EvidenceAttempt]) -> Reliability {
    let trainees = by_trainee(used)
        .iter()
        .filter(|a| a.iter().filter(|a| a.value(SCORE_KEY).is_some()).count() >= 2)
        .count();
    let icc = last_two_icc(used, |a| a.value(SCORE_KEY));
    let why_not = icc.is_none().then(|| {
        if trainees < 2 {
            format!("{trainees} trainee(s) with two scored attempts: needs at least 2")
        } else {
            "the scores have no spread".into()
        }
    });
    Reliability {
        trainees,
        band: icc.map(|v| match v {
            v if v < 0.5 => "poor",
            v if v < 0.75 => "moderate",
            v if v < 0.9 => "good",
            _ => "excellent",
        }),
        icc,
        why_not,
    }
}

fn learning(used: &[&EvidenceAttempt], band: f64) -> Vec<LearningCurve> {
    let mut curves: Vec<LearningCurve> = by_trainee(used)
        .into_iter()
        .map(|attempts| {
            let scores: Vec<f64> = attempts.iter().filter_map(|a| a.value(SCORE_KEY)).collect();
            LearningCurve {
                trainee_id: attempts[0].trainee_id,
                trainee: attempts[0].trainee.clone(),
                experience: attempts[0].experience,
                plateau: stats::plateau(&scores, band),
                scores,
            }
        })
        .collect();
    curves.sort_by(|a, b| a.trainee.cmp(&b.trainee));
    curves
}

fn pass_mark(
    score: &Measure,
    higher: Option<Experience>,
    lower: Option<Experience>,
) -> PassMarkFinding {
    let (vh, vl) = (
        values_of(&score.groups, higher),
        values_of(&score.groups, lower),
    );
    let cut = stats::contrasting_groups(vh, vl);
    let why_not = match (higher, cut) {
        (_, Some(_)) => None,
        (None, _) => Some("needs scored attempts by people of two experience levels".into()),
        _ if vh.len() < 2 || vl.len() < 2 => {
            Some("each group needs at least 2 scored attempts".into())
        }
        _ => Some(
            "the more experienced group does not score higher on average, or a group's \
             scores have no spread"
                .into(),
        ),
    };
    PassMarkFinding {
        higher,
        lower,
        n_higher: vh.len(),
        n_lower: vl.len(),
        cut,
        why_not,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn attempt(
        id: i64,
        trainee: i64,
        level: Option<Experience>,
        score: f64,
        time_s: f64,
    ) -> EvidenceAttempt {
        EvidenceAttempt {
            attempt_id: id,
            trainee_id: trainee,
            trainee: format!("t{trainee}"),
            experience: level,
            started_ns: id,
            reference: false,
            score: Some(score),
            metrics: vec![
                ("time_s".into(), time_s),
                ("peak_force_n".into(), 1.0 + 0.01 * id as f64),
            ],
            rating: None,
        }
    }

    /// Experts (trainees 1-2) score 0.6-0.8 in 5-7 s, novices (3-4) -0.4-0 in 10-14 s; the
    /// force is the same for both (it rises with the attempt id, interleaved).
    fn cohort() -> Vec<EvidenceAttempt> {
        let mut v = Vec::new();
        let mut id = 0;
        for (trainee, level, s0, t0) in [
            (1, Experience::Expert, 0.6, 5.0),
            (2, Experience::Expert, 0.65, 6.0),
            (3, Experience::Novice, -0.4, 12.0),
            (4, Experience::Novice, -0.3, 14.0),
        ] {
            for k in 0..5 {
                id += 1;
                let level = Some(level);
                v.push(attempt(
                    id,
                    trainee,
                    level,
                    s0 + 0.04 * k as f64,
                    t0 - 0.3 * k as f64,
                ));
            }
        }
        // shuffle the forces so they do not follow the groups
        for (i, a) in v.iter_mut().enumerate() {
            a.metrics[1].1 = 1.0 + 0.1 * ((i * 7) % 20) as f64;
        }
        v
    }

    #[test]
    fn separated_groups_discriminate_and_a_flat_metric_does_not() {
        let r = Report::build("x", &cohort(), &EvidenceOptions::default());
        assert_eq!(
            (r.higher, r.lower),
            (Some(Experience::Expert), Some(Experience::Novice))
        );
        let c = r.score.comparison.unwrap();
        assert_eq!((c.n_higher, c.n_lower, c.auc), (10, 10, 1.0));
        assert!(
            c.p < 1e-3 && r.score.finding == Finding::Discriminates,
            "{c:?}"
        );
        let time = r.metrics.iter().find(|m| m.key == "time_s").unwrap();
        // lower is better: the experts' shorter times give AUC 1
        assert_eq!(time.comparison.unwrap().auc, 1.0);
        let force = r.metrics.iter().find(|m| m.key == "peak_force_n").unwrap();
        assert_eq!(
            force.finding,
            Finding::DoesNotDiscriminate,
            "{:?}",
            force.comparison
        );
        assert_eq!(r.not_discriminating, vec![force.label.clone()]);
        // the pass mark lies between the groups' scores
        let cut = r.pass_mark.cut.unwrap();
        assert!(cut.cut > 0.0 && cut.cut < 0.6 && cut.false_pass == 0.0 && cut.false_fail == 0.0);
        // reliability: each trainee's last two attempts are close, trainees differ widely
        assert_eq!(r.reliability.trainees, 4);
        assert!(r.reliability.icc.unwrap() > 0.9, "{:?}", r.reliability);
        // learning curves of 5 attempts rising 0.04 each: level within 0.1 from the second
        assert_eq!(r.learning.len(), 4);
        assert!(
            r.learning
                .iter()
                .all(|l| l.plateau.is_some() && l.scores.len() == 5)
        );
    }

    #[test]
    fn what_cannot_be_computed_is_said() {
        // one level only
        let one: Vec<EvidenceAttempt> =
            cohort().into_iter().filter(|a| a.trainee_id <= 2).collect();
        let r = Report::build("x", &one, &EvidenceOptions::default());
        assert_eq!(r.score.finding, Finding::NotComputed);
        assert!(
            r.score
                .why_not
                .as_deref()
                .unwrap()
                .contains("two experience levels")
        );
        assert!(r.pass_mark.cut.is_none() && r.pass_mark.why_not.is_some());
        // a group with one attempt
        let mut few = one.clone();
        few.push(attempt(99, 9, Some(Experience::Novice), -0.5, 20.0));
        let r = Report::build("x", &few, &EvidenceOptions::default());
        assert!(
            r.score
                .why_not
                .as_deref()
                .unwrap()
                .contains("novice group has 1 value"),
            "{:?}",
            r.score.why_not
        );
        // no level: left out, counted
        let mut unknown = cohort();
        unknown[0].experience = None;
        unknown[1].experience = None;
        let r = Report::build("x", &unknown, &EvidenceOptions::default());
        assert_eq!((r.attempts_without_level, r.trainees_without_level), (2, 1));
        assert_eq!(r.score.comparison.unwrap().n_higher, 8);
        // nothing at all
        let r = Report::build("x", &[], &EvidenceOptions::default());
        assert!(r.groups.is_empty() && r.reliability.icc.is_none() && r.learning.is_empty());
    }

    #[test]
    fn ratings_give_each_metrics_agreement_and_a_tool_is_named() {
        let mut v = cohort();
        for a in v.iter_mut() {
            a.rating = a.score.map(|s| 10.0 + 10.0 * s);
            a.metrics.push(("time_s@left".into(), a.metrics[0].1));
        }
        let r = Report::build("x", &v, &EvidenceOptions::default());
        let rho = |key: &str| {
            r.concurrent
                .iter()
                .find(|c| c.key == key)
                .and_then(|c| c.rho)
        };
        // the time falls as the score (the rating) rises across the groups (not within the
        // experts: trainee 2 scores higher and takes longer than trainee 1)
        assert!(rho("time_s").unwrap() < -0.7, "{:?}", r.concurrent);
        assert_eq!(rho("time_s@left"), rho("time_s"));
        let left = r.metrics.iter().find(|m| m.key == "time_s@left").unwrap();
        assert_eq!(
            (left.label.as_str(), left.better),
            ("Task time · left", Better::LowerIsBetter)
        );
        // without ratings, no agreement is reported
        assert!(
            Report::build("x", &cohort(), &EvidenceOptions::default())
                .concurrent
                .is_empty()
        );
    }

    #[test]
    fn reference_attempts_can_be_left_out() {
        let mut v = cohort();
        for a in v.iter_mut().filter(|a| a.trainee_id == 1) {
            a.reference = true;
        }
        let with = Report::build("x", &v, &EvidenceOptions::default());
        assert_eq!(with.groups.last().unwrap().reference_attempts, 5);
        let without = Report::build(
            "x",
            &v,
            &EvidenceOptions {
                include_reference: false,
                ..EvidenceOptions::default()
            },
        );
        assert_eq!(without.groups.last().unwrap().attempts, 5);
        assert_eq!(without.groups.last().unwrap().reference_attempts, 0);
    }

    #[test]
    fn a_two_sided_metric_is_measured_from_its_reference() {
        // experts' lateral error near 0 either side, novices' far on both sides
        let mut v = cohort();
        for (i, a) in v.iter_mut().enumerate() {
            let sign = if i % 2 == 0 { 1.0 } else { -1.0 };
            let off = if a.trainee_id <= 2 { 0.0005 } else { 0.004 };
            a.metrics
                .push(("depth_error_m".into(), sign * off * (1.0 + 0.01 * i as f64)));
        }
        let mut o = EvidenceOptions::default();
        o.two_sided_reference.insert("depth_error_m".into(), 0.0);
        let r = Report::build("x", &v, &o);
        let m = r.metrics.iter().find(|m| m.key == "depth_error_m").unwrap();
        assert_eq!(m.comparison.unwrap().auc, 1.0, "{m:?}");
    }
}
