//! What a trainee should fix next, in plain words: the debrief's first lines, before the
//! table of metrics. From an attempt's metric results and its exercise's limits: the task
//! not done first, then the deciding metrics that failed, the worst first (how far past its
//! limit, in units of the expert margin), at most three; then the feedback-only metrics
//! against the experts' reference ([`crate::proficiency::FEEDBACK_ONLY`]), and how the
//! second hand handled the tissue in an attempt made with a grasper.

use crate::proficiency::{TASK_DONE_MIN_FRACTION, decides};

/// One metric of an attempt as the debrief reads it (SI units).
#[derive(Debug, Clone, PartialEq)]
pub struct MetricResult<'a> {
    pub key: &'a str,
    pub value: Option<f64>,
    /// The verdict on it, for a metric that decides (`None`: no threshold, or feedback).
    pub passed: Option<bool>,
    /// The experts' reference.
    pub mean: Option<f64>,
    pub lower: Option<f64>,
    pub upper: Option<f64>,
}

/// The debrief's summary.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Advice {
    /// At most three things to fix next, the most important first; empty when every
    /// deciding metric passed.
    pub fix: Vec<String>,
    /// What went well, when nothing is to fix (one line).
    pub praise: Option<String>,
    /// The feedback-only metrics against the experts (do not decide the verdict).
    pub feedback: Vec<String>,
}

/// The most things to fix the debrief names.
pub const MAX_FIXES: usize = 3;

/// The debrief of an attempt with `results`.
pub fn advice(results: &[MetricResult<'_>]) -> Advice {
    let mut fix = Vec::new();
    let fraction = results
        .iter()
        .find(|m| m.key == "fraction_cut_in_tolerance");
    match fraction.map(|m| m.value) {
        Some(None) => fix.push(
            "No incision was made: press the blade into the tissue at the planned entry and \
             draw it along the line."
                .to_owned(),
        ),
        Some(Some(f)) if f < TASK_DONE_MIN_FRACTION => fix.push(format!(
            "Cut along the planned line: only {:.0} % of it was cut within the tolerance \
             (at least {:.0} % counts as an attempt at the task).",
            f * 100.0,
            TASK_DONE_MIN_FRACTION * 100.0
        )),
        _ => {}
    }
    // an attempt at something else than the task is told the task, not its details, and its
    // motion says nothing of how the task was done
    let done = fix.is_empty();
    if done {
        let mut failed: Vec<(f64, String)> = results
            .iter()
            .filter(|m| decides(m.key) && m.passed == Some(false))
            .filter_map(|m| Some((severity(m), words(m, results)?)))
            .collect();
        failed.sort_by(|a, b| b.0.total_cmp(&a.0));
        fix.extend(failed.into_iter().map(|f| f.1));
    }
    fix.truncate(MAX_FIXES);
    let praise = fix.is_empty().then(|| {
        // what the exercise's limits were on, in its own words
        let has = |key: &str| results.iter().any(|m| m.key == key);
        let what = if has("piece_freed") {
            "the piece is free, in time and on the mark"
        } else if has("field_of_expert") {
            "the opening shows the target, through a short incision and without harm"
        } else {
            "the line, its depth and the force were right"
        };
        format!("Within every limit: {what}.")
    });
    // (only feedback-only metrics and the second hand's handling have words here)
    let feedback = results
        .iter()
        .filter(|_| done)
        .filter_map(feedback_words)
        .collect();
    Advice {
        fix,
        praise,
        feedback,
    }
}

/// How far past its limit a failed metric is, in units of the expert margin (a missing value:
/// the most).
fn severity(m: &MetricResult<'_>) -> f64 {
    let Some(v) = m.value else {
        return f64::INFINITY;
    };
    let (limit, beyond) = match (m.lower, m.upper) {
        (_, Some(u)) if v > u => (u, v - u),
        (Some(l), _) if v < l => (l, l - v),
        _ => return 0.0,
    };
    let margin = m.mean.map_or(limit.abs(), |mean| (limit - mean).abs());
    if margin > 0.0 {
        beyond / margin
    } else {
        beyond
    }
}

/// A failed deciding metric in plain words (`results`: the attempt's others, which some
/// words draw on).
fn words(m: &MetricResult<'_>, results: &[MetricResult<'_>]) -> Option<String> {
    let Some(v) = m.value else {
        // a piece not cut free has no completion time: `piece_freed` says what to do
        if m.key == "completion_time_s" {
            return None;
        }
        // the catalogue's name, never the stored key, reaches the trainee
        let name = crate::metrics::metric(m.key).map_or(m.key, |d| d.label);
        return Some(format!(
            "{name}: could not be measured from this attempt's cut, so it cannot pass."
        ));
    };
    if let Some(said) = field_words(m.key, v, m.upper, results) {
        return Some(said);
    }
    let mm = v * 1e3;
    Some(match m.key {
        "depth_error_m" if v > 0.0 => {
            format!("Cut shallower: the blade went {mm:.1} mm deeper than planned.")
        }
        "depth_error_m" => format!(
            "Cut deeper: the blade stayed {:.1} mm shallower than planned.",
            -mm
        ),
        "lateral_mean_m" => format!("Stay on the line: the cut was {mm:.1} mm from it on average."),
        "lateral_max_m" => {
            format!("Stay on the line throughout: the cut strayed up to {mm:.1} mm from it.")
        }
        "entry_error_m" => format!("Start on the planned entry: the cut began {mm:.1} mm from it."),
        "exit_error_m" => format!("End at the planned exit: the cut ended {mm:.1} mm from it."),
        "length_error_m" if v < 0.0 => {
            format!("Cut the whole length: the cut was {:.1} mm too short.", -mm)
        }
        "length_error_m" => format!("Stop at the planned length: the cut was {mm:.1} mm too long."),
        "fraction_cut_in_tolerance" => format!(
            "Keep within the tolerance: {:.0} % of the line was cut within it.",
            v * 100.0
        ),
        "direction_error_deg" => {
            format!("Cut along the line's direction: the cut ran {v:.1} degrees off it.")
        }
        "peak_force_n" => format!(
            "Press more gently: the force peaked at {v:.2} N, over the {} N limit.",
            m.upper
                .map_or("exercise's".to_owned(), |u| format!("{u:.1}"))
        ),
        "cut_outside_corridor_m" => {
            format!("Keep inside the safe corridor: {mm:.1} mm of the cut ran outside it.")
        }
        "piece_freed" => {
            "Cut the piece free: go all the way round the mark, back past where you started."
                .to_owned()
        }
        "completion_time_s" => format!(
            "Work faster: the piece was free after {v:.0} s, the limit is {} s.",
            m.upper
                .map_or("the exercise's".to_owned(), |u| format!("{u:.0}"))
        ),
        "pattern_max_deviation_m" => {
            format!("Stay on the mark all the way round: the cut strayed up to {mm:.1} mm from it.")
        }
        key => match crate::metrics::metric(key) {
            Some(d) => {
                let (factor, unit) = d.display();
                let shown = format!("{:.2} {unit}", v * factor);
                format!("{}: {} is beyond its limit.", d.label, shown.trim_end())
            }
            None => format!("{key}: {v:.4} is beyond its limit."),
        },
    })
}

/// A failed metric of the `field` kind with value `v` and upper limit `upper`, in plain words:
/// the field says what was wrong with the incision's place or length, from `results`.
fn field_words(
    key: &str,
    v: f64,
    upper: Option<f64>,
    results: &[MetricResult<'_>],
) -> Option<String> {
    let value = |key: &str| results.iter().find(|m| m.key == key).and_then(|m| m.value);
    Some(match key {
        "field_of_expert" => {
            let why = field_failure(results);
            format!(
                "{why}: the opening shows {:.0} % of the expert's view of the target.",
                v * 100.0
            )
        }
        "incision_length_m" => format!(
            "Make the incision shorter: {:.0} mm, over the {} mm limit; the view it bought was not worth the wound.",
            v * 1e3,
            upper.map_or("exercise's".to_owned(), |u| format!("{:.0}", u * 1e3))
        ),
        "wall_opened" => format!(
            "Cut through the whole wall: the deepest cut was {:.0} mm, and the wall's innermost layer was not opened, so nothing behind it shows.",
            value("deepest_cut_m").unwrap_or(0.0) * 1e3
        ),
        "bone_contacts" => format!(
            "Keep the blade off the ribs: it came down on bone {v:.0} times; cut in the middle of the space."
        ),
        "critical_damage" => format!(
            "Spare what must not be cut: {v:.0} critical harm(s), the artery beside the sternum cut, the lung or the target itself touched."
        ),
        _ => return None,
    })
}

/// Why an incision shows too little of the target: its place among the ribs, else its
/// length against the experts', else that it shows too little.
fn field_failure(results: &[MetricResult<'_>]) -> String {
    use cutlab_haptics::landmarks::Placement;
    let find = |key: &str| results.iter().find(|m| m.key == key);
    let count = |k: i32| match k.abs() {
        1 => "One space".to_owned(),
        2 => "Two spaces".to_owned(),
        n => format!("{n} spaces"),
    };
    match find("incision_space")
        .and_then(|m| m.value)
        .map(Placement::of)
    {
        Some(Placement::Space(k)) if k > 0 => return format!("{} too low", count(k)),
        Some(Placement::Space(k)) if k < 0 => return format!("{} too high", count(k)),
        Some(Placement::OnMark(k)) => {
            let which = match k {
                0 => "the rib below the expert's space".to_owned(),
                -1 => "the rib above the expert's space".to_owned(),
                k => format!("a rib {} spaces from the expert's", k.abs()),
            };
            return format!("On {which}, not in a space");
        }
        _ => {}
    }
    if let Some(length) = find("incision_length_m")
        && let (Some(v), Some(mean)) = (length.value, length.mean)
        && v < 0.8 * mean
    {
        return format!(
            "Too short at {:.0} mm (the experts' {:.0} mm)",
            v * 1e3,
            mean * 1e3
        );
    }
    "Expose more of the target".to_owned()
}

/// A feedback-only metric against the experts' reference, in plain words.
fn feedback_words(m: &MetricResult<'_>) -> Option<String> {
    if let Some(said) = handling_words(m.key, m.value?) {
        return Some(said);
    }
    let (v, mean) = (m.value?, m.mean?);
    let relative = |what_more: &str, what_less: &str| {
        if !(mean.abs() > 0.0) {
            return None;
        }
        let p = (v / mean - 1.0) * 100.0;
        Some(if p >= 0.0 {
            format!("{p:.0} % {what_more}")
        } else {
            format!("{:.0} % {what_less}", -p)
        })
    };
    Some(match m.key {
        "time_s" => format!(
            "Time {v:.1} s: {} than the experts ({mean:.1} s).",
            relative("slower", "faster")?
        ),
        "path_length_m" => format!(
            "Path {:.0} mm: {} than the experts' ({:.0} mm).",
            v * 1e3,
            relative("longer", "shorter")?,
            mean * 1e3
        ),
        "movements" => format!("{v:.0} movements (the experts: {mean:.1})."),
        "ldlj" => format!("Smoothness (LDLJ) {v:.1} (the experts: {mean:.1}; higher is smoother)."),
        _ => return None,
    })
}

/// The second hand's handling of the tissue ([`crate::metrics::handling`]) in plain words,
/// where it says something to do or to keep: it needs no experts' reference.
fn handling_words(key: &str, v: f64) -> Option<String> {
    Some(match key {
        "countertraction_fraction" if v < 0.5 => format!(
            "Countertraction: the other hand held the tissue drawn away from the blade during \
             {:.0} % of the cut; keep it taut, pulling away from where you cut.",
            v * 100.0
        ),
        "countertraction_fraction" => format!(
            "Countertraction: the tissue was held drawn away from the blade during {:.0} % of \
             the cut.",
            v * 100.0
        ),
        "grasp_slips" if v > 0.0 => format!(
            "The tissue slipped out of the grasper {v:.0} time(s): take a fuller bite and pull \
             less hard."
        ),
        "time_traction_over_limit_s" if v > 0.0 => format!(
            "The grasper pulled on the tissue past the force limit for {v:.1} s: such traction \
             tears tissue; draw it more gently."
        ),
        _ => return None,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn r(
        key: &str,
        value: Option<f64>,
        passed: Option<bool>,
        mean: f64,
        lower: Option<f64>,
        upper: Option<f64>,
    ) -> MetricResult<'_> {
        MetricResult {
            key,
            value,
            passed,
            mean: Some(mean),
            lower,
            upper,
        }
    }

    #[test]
    fn the_second_hands_handling_is_said_without_an_experts_reference() {
        let m = |key, value| MetricResult {
            key,
            value: Some(value),
            passed: None,
            mean: None,
            lower: None,
            upper: None,
        };
        let a = advice(&[
            m("countertraction_fraction", 0.3),
            m("grasp_slips", 2.0),
            m("time_traction_over_limit_s", 0.0),
        ]);
        assert_eq!(a.feedback.len(), 2, "{a:?}");
        assert!(
            a.feedback[0].contains("during 30 % of the cut; keep it taut"),
            "{a:?}"
        );
        assert!(
            a.feedback[1].contains("slipped out of the grasper 2 time(s)"),
            "{a:?}"
        );
        let good = advice(&[m("countertraction_fraction", 0.9)]);
        assert!(!good.feedback[0].contains("keep it taut"), "{good:?}");
    }

    #[test]
    fn a_metric_that_could_not_be_measured_is_named_as_people_read_it() {
        let a = advice(&[
            r(
                "fraction_cut_in_tolerance",
                Some(0.9),
                Some(true),
                0.95,
                Some(0.8),
                None,
            ),
            r(
                "pattern_max_deviation_m",
                None,
                Some(false),
                0.001,
                None,
                Some(0.002),
            ),
        ]);
        assert_eq!(a.fix.len(), 1);
        assert!(!a.fix[0].contains('_'), "{}", a.fix[0]);
        let label = crate::metrics::metric("pattern_max_deviation_m")
            .unwrap()
            .label;
        assert!(a.fix[0].starts_with(label), "{}", a.fix[0]);
    }

    #[test]
    fn the_worst_failures_come_first_in_plain_words() {
        let results = [
            r(
                "fraction_cut_in_tolerance",
                Some(0.9),
                Some(true),
                0.95,
                Some(0.8),
                None,
            ),
            r(
                "lateral_mean_m",
                Some(0.0021),
                Some(false),
                0.0005,
                None,
                Some(0.002),
            ),
            r(
                "depth_error_m",
                Some(0.0021),
                Some(false),
                0.0,
                Some(-0.003),
                Some(0.0015),
            ),
            r(
                "entry_error_m",
                Some(0.009),
                Some(false),
                0.001,
                None,
                Some(0.004),
            ),
            r(
                "exit_error_m",
                Some(0.0041),
                Some(false),
                0.001,
                None,
                Some(0.004),
            ),
            r("time_s", Some(8.4), None, 6.0, None, Some(9.0)),
        ];
        let a = advice(&results);
        assert_eq!(a.fix.len(), MAX_FIXES);
        // past the limit by 1.7, 0.4 and 0.07 expert margins; the exit's 0.03 left out
        assert!(a.fix[0].contains("began 9.0 mm"), "{a:?}");
        assert!(a.fix[1].contains("2.1 mm deeper"), "{a:?}");
        assert!(a.fix[2].contains("2.1 mm from it on average"), "{a:?}");
        assert!(a.praise.is_none());
        assert_eq!(
            a.feedback,
            ["Time 8.4 s: 40 % slower than the experts (6.0 s)."]
        );
    }

    #[test]
    fn what_the_device_cannot_measure_is_not_something_to_fix() {
        // the approach with the station's pointer: no value, no verdict (left out of it)
        let plan = crate::IncisionPlan::chest_wall().unwrap();
        let data = crate::AttemptData {
            device: Some("pointer".into()),
            ..Default::default()
        };
        let values = crate::ExerciseKind::assess(&plan, &data).unwrap();
        let approach = values
            .iter()
            .find(|v| v.key == "approach_error_deg")
            .unwrap();
        assert!(approach.not_measured(), "{approach:?}");
        let thresholds = crate::proficiency::Thresholds {
            k: 2.0,
            metrics: vec![crate::proficiency::Threshold::fixed(
                "approach_error_deg",
                crate::Better::LowerIsBetter,
                2.0,
                10.0,
            )],
        };
        let verdict = thresholds.verdict(&values);
        let passed = verdict
            .metrics
            .iter()
            .find(|m| m.key == approach.key)
            .map(|m| m.pass);
        assert_eq!(passed, None);
        let a = advice(&[
            r(
                "lateral_mean_m",
                Some(0.0004),
                Some(true),
                0.0005,
                None,
                Some(0.002),
            ),
            MetricResult {
                key: &approach.key,
                value: approach.value,
                passed,
                mean: Some(2.0),
                lower: None,
                upper: Some(10.0),
            },
        ]);
        assert!(a.fix.is_empty() && a.praise.is_some(), "{a:?}");
    }

    #[test]
    fn an_attempt_without_a_cut_is_told_to_cut_and_a_good_one_is_praised() {
        let none = advice(&[
            r(
                "fraction_cut_in_tolerance",
                None,
                Some(false),
                0.95,
                Some(0.8),
                None,
            ),
            r("time_s", Some(4.0), None, 5.0, None, Some(8.0)),
        ]);
        assert_eq!(none.fix.len(), 1);
        assert!(none.fix[0].starts_with("No incision"), "{none:?}");
        assert!(
            none.feedback.is_empty(),
            "no praise of the speed of no cut: {none:?}"
        );
        let little = advice(&[
            r(
                "fraction_cut_in_tolerance",
                Some(0.2),
                Some(false),
                0.95,
                Some(0.8),
                None,
            ),
            r(
                "lateral_mean_m",
                Some(0.01),
                Some(false),
                0.0005,
                None,
                Some(0.002),
            ),
        ]);
        assert_eq!(little.fix.len(), 1, "the task first: {little:?}");
        assert!(little.fix[0].contains("only 20 %"));
        let good = advice(&[r(
            "lateral_mean_m",
            Some(0.0004),
            Some(true),
            0.0005,
            None,
            Some(0.002),
        )]);
        assert!(good.fix.is_empty() && good.praise.is_some());
    }

    /// A pattern not cut free is told to close the circle (not that its time could not be
    /// measured); a slow, wandering one is told both, in words.
    #[test]
    fn a_pattern_attempt_is_told_what_to_fix_in_words() {
        let open = advice(&[
            r("piece_freed", Some(0.0), Some(false), 1.0, Some(0.5), None),
            r(
                "completion_time_s",
                None,
                Some(false),
                60.0,
                None,
                Some(98.0),
            ),
        ]);
        assert_eq!(open.fix.len(), 1, "{open:?}");
        assert!(open.fix[0].contains("Cut the piece free"), "{open:?}");
        let slow = advice(&[
            r("piece_freed", Some(1.0), Some(true), 1.0, Some(0.5), None),
            r(
                "completion_time_s",
                Some(120.0),
                Some(false),
                60.0,
                None,
                Some(98.0),
            ),
            r(
                "pattern_max_deviation_m",
                Some(0.0031),
                Some(false),
                0.0005,
                None,
                Some(0.002),
            ),
        ]);
        assert!(
            slow.fix
                .iter()
                .any(|f| f.contains("120 s, the limit is 98 s")),
            "{slow:?}"
        );
        assert!(
            slow.fix.iter().any(|f| f.contains("up to 3.1 mm")),
            "{slow:?}"
        );
    }

    /// A field attempt is told where its incision went wrong: a space too low, on a rib, too
    /// short, with the share of the expert's view it shows; a good one is praised for the
    /// field, not for a line.
    #[test]
    fn a_field_attempt_is_told_where_its_incision_went_wrong() {
        let field = |v: f64, space: Option<f64>, length: f64| {
            vec![
                r(
                    "field_of_expert",
                    Some(v),
                    Some(v >= 0.5),
                    1.0,
                    Some(0.5),
                    None,
                ),
                r("incision_space", space, None, 0.0, None, None),
                r(
                    "incision_length_m",
                    Some(length),
                    Some(true),
                    0.05,
                    None,
                    Some(0.07),
                ),
            ]
        };
        let low = advice(&field(0.3, Some(1.05), 0.05));
        assert_eq!(
            low.fix,
            ["One space too low: the opening shows 30 % of the expert's view of the target."]
        );
        let high = advice(&field(0.1, Some(-2.0), 0.05));
        assert!(high.fix[0].starts_with("Two spaces too high"), "{high:?}");
        let rib = advice(&field(0.2, Some(0.5), 0.05));
        assert!(
            rib.fix[0].starts_with("On the rib below the expert's space"),
            "{rib:?}"
        );
        let short = advice(&field(0.4, Some(0.1), 0.025));
        assert!(
            short.fix[0].starts_with("Too short at 25 mm (the experts' 50 mm)"),
            "{short:?}"
        );
        let unplaced = advice(&field(0.4, None, 0.05));
        assert!(unplaced.fix[0].starts_with("Expose more"), "{unplaced:?}");
        let good = advice(&field(0.9, Some(0.0), 0.05));
        assert!(good.fix.is_empty());
        assert!(good.praise.unwrap().contains("opening shows the target"));
        let walled = advice(&[
            r("wall_opened", Some(0.0), Some(false), 1.0, Some(0.5), None),
            r("deepest_cut_m", Some(0.027), None, 0.045, None, None),
        ]);
        assert!(
            walled.fix[0].contains("deepest cut was 27 mm"),
            "{walled:?}"
        );
    }
}
