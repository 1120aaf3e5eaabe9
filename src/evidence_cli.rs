//! `cutlab evidence --exercise E`: the validity evidence of an exercise's scores (groups by
//! the trainees' recorded experience, Mann-Whitney U and AUC per metric and for the overall
//! score, test-retest ICC, learning-curve plateaus, the contrasting-groups pass mark), as
//! text or `--json`; `--adopt --by NAME` adopts the pass mark for the exercise.

use std::fmt::Write as _;

use anyhow::Context;
use clap::Args;
use cutlab_assessor::store::{Store, iso8601};
use cutlab_scoring::evidence::{Comparison, Finding, Measure, Report};
use cutlab_scoring::metrics::display_unit;

#[derive(Debug, Args)]
pub struct EvidenceArgs {
    /// The exercise (by name).
    #[arg(long)]
    exercise: String,
    /// Leave out the reference attempts (those that set the thresholds the scores are
    /// measured against).
    #[arg(long)]
    exclude_reference: bool,
    /// Adopt the report's contrasting-groups pass mark for the exercise (needs --by).
    #[arg(long, requires = "by")]
    adopt: bool,
    /// The instructor or administrator adopting it (user name, recorded).
    #[arg(long)]
    by: Option<String>,
    /// Machine-readable output.
    #[arg(long)]
    json: bool,
}

pub async fn run(store: &Store, args: EvidenceArgs) -> anyhow::Result<()> {
    let exercise = store
        .exercise_by_name(&args.exercise)
        .await
        .with_context(|| format!("the exercise {:?}", args.exercise))?;
    let report = store.evidence(exercise.id, !args.exclude_reference).await?;
    if args.json {
        println!("{}", serde_json::to_string_pretty(&report)?);
    } else {
        print!("{}", text(&report));
    }
    if args.adopt {
        let name = args.by.as_deref().unwrap_or_default();
        let by = store.user_by_name(name).await?;
        anyhow::ensure!(
            by.role != cutlab_assessor::store::Role::Trainee,
            "{name} is a trainee: only an instructor or an administrator adopts a pass mark"
        );
        let mark = store
            .adopt_pass_mark(exercise.id, &report.pass_mark, by.id)
            .await?;
        eprintln!(
            "adopted the pass mark {:+.3} for {} (by {}, {})",
            mark.score,
            exercise.name,
            mark.adopted_by,
            iso8601(mark.adopted_ns)
        );
    } else if let Some(mark) = store.pass_mark(exercise.id).await? {
        eprintln!(
            "the exercise's adopted pass mark: {:+.3} ({}, by {}, {})",
            mark.score,
            mark.method,
            mark.adopted_by,
            iso8601(mark.adopted_ns)
        );
    }
    Ok(())
}

/// The report as text.
pub fn text(r: &Report) -> String {
    let mut s = String::new();
    let _ = writeln!(s, "Validity evidence: {}", r.exercise);
    if r.groups.is_empty() {
        let _ = writeln!(
            s,
            "  no complete attempts by people with an experience level"
        );
    }
    for g in &r.groups {
        let _ = writeln!(
            s,
            "  {:<12} {} people, {} attempts{}",
            g.level.as_str(),
            g.trainees,
            g.attempts,
            if g.reference_attempts > 0 {
                format!(" ({} reference attempts)", g.reference_attempts)
            } else {
                String::new()
            }
        );
    }
    if r.attempts_without_level > 0 {
        let _ = writeln!(
            s,
            "  left out: {} attempts by {} people with no experience level recorded",
            r.attempts_without_level, r.trainees_without_level
        );
    }
    if let (Some(h), Some(l)) = (r.higher, r.lower) {
        let _ = writeln!(s, "\nConstruct validity: {h} against {l}");
    }
    let _ = writeln!(
        s,
        "  {:<46} {:>10} {:>10} {:>8} {:>7} {:>17} {:>6}  finding",
        "measure", "med. high", "med. low", "p", "AUC", "95 % interval", "ICC"
    );
    for m in std::iter::once(&r.score).chain(&r.metrics) {
        let _ = writeln!(s, "  {}", measure_row(m));
    }
    if !r.not_discriminating.is_empty() {
        let _ = writeln!(
            s,
            "  do not discriminate: {}",
            r.not_discriminating.join(", ")
        );
    }
    concurrent(&mut s, r);
    reliability_and_pass_mark(&mut s, r);
    learning(&mut s, r);
    s
}

fn concurrent(s: &mut String, r: &Report) {
    if r.concurrent.is_empty() {
        return;
    }
    let _ = writeln!(s, "\nConcurrent validity: Spearman's rho with the rating");
    for c in &r.concurrent {
        let rho = c.rho.map_or("-".into(), |v| format!("{v:+.2}"));
        let _ = writeln!(s, "  {:<46} {rho:>6}  (n = {})", c.label, c.n);
    }
}

fn measure_row(m: &Measure) -> String {
    let (factor, unit) = display_unit(&m.unit);
    let label = if unit.is_empty() {
        m.label.clone()
    } else {
        format!("{} ({unit})", m.label)
    };
    let icc = m.icc.map_or("-".into(), |v| format!("{v:.2}"));
    match (&m.comparison, m.finding) {
        (
            Some(Comparison {
                median_higher,
                median_lower,
                p,
                auc,
                auc_low,
                auc_high,
                ..
            }),
            f,
        ) => {
            format!(
                "{label:<46} {:>10.3} {:>10.3} {p:>8.4} {auc:>7.2} {:>17} {icc:>6}  {}",
                median_higher * factor,
                median_lower * factor,
                format!("{auc_low:.2}-{auc_high:.2}"),
                f.words()
            )
        }
        (None, _) => format!(
            "{label:<46} {:>61} {icc:>6}  {}: {}",
            "",
            Finding::NotComputed.words(),
            m.why_not.as_deref().unwrap_or("")
        ),
    }
}

fn reliability_and_pass_mark(s: &mut String, r: &Report) {
    let rel = &r.reliability;
    let _ = match (rel.icc, rel.band) {
        (Some(icc), Some(band)) => writeln!(
            s,
            "\nTest-retest reliability: ICC(2,1) {icc:.2} ({band}) over the last two attempts \
             of {} trainees",
            rel.trainees
        ),
        _ => writeln!(
            s,
            "\nTest-retest reliability: not computed: {}",
            rel.why_not.as_deref().unwrap_or("")
        ),
    };
    let p = &r.pass_mark;
    let _ = match (p.cut, p.higher, p.lower) {
        (Some(c), Some(h), Some(l)) => writeln!(
            s,
            "\nPass mark (contrasting groups, {h} {} against {l} {}): {} {:+.3}\n  \
             false pass {:.0} % observed, {:.1} % normal; false fail {:.0} % observed, {:.1} % \
             normal",
            p.n_higher,
            p.n_lower,
            r.score.label.to_lowercase(),
            c.cut,
            100.0 * c.false_pass,
            100.0 * c.false_pass_normal,
            100.0 * c.false_fail,
            100.0 * c.false_fail_normal
        ),
        _ => writeln!(
            s,
            "\nPass mark (contrasting groups): not computed: {}",
            p.why_not.as_deref().unwrap_or("")
        ),
    };
}

fn learning(s: &mut String, r: &Report) {
    if r.learning.is_empty() {
        return;
    }
    let _ = writeln!(s, "\nLearning curves ({}):", r.score.label.to_lowercase());
    for c in &r.learning {
        let level = c.experience.map_or("-", |e| e.as_str());
        let scores: Vec<String> = c.scores.iter().map(|v| format!("{v:+.2}")).collect();
        let plateau = match c.plateau {
            Some(p) if p.levelled => {
                format!("plateau {:+.2} from attempt {}", p.plateau, p.reached_at)
            }
            Some(_) => "not levelled off yet".into(),
            None => "plateau: needs 4 attempts".into(),
        };
        let _ = writeln!(
            s,
            "  {:<16} {level:<12} {plateau}; {}",
            cutlab_assessor::store::printable(&c.trainee),
            scores.join(" ")
        );
    }
}
