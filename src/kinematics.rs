//! `cutlab import kinematics DIR`: the evidence report on kinematic data recorded anywhere,
//! with raters' ratings (JIGSAWS, converted by `scripts/jigsaws_to_cutlab.py`).
//!
//! The layout (docs/guide/evidence.md):
//!
//! - `DIR/ratings.csv`: a header, then `trial,subject,experience,rating` per trial
//!   (experience `novice`, `intermediate` or `expert`; the rating a number, e.g. a GRS);
//! - `DIR/trials/TRIAL/TOOL.csv`: each tool's poses in the `motion-metrics` layout
//!   (`t_s, x_m, y_m, z_m, qw, qx, qy, qz`, the time increasing).
//!
//! Every tool's path metrics, depth path and speed entropy (`KEY@TOOL`) are computed, and
//! with two tools the bimanual measures; the trials become attempts of their
//! subject (in the order of their names), the rating their score. Nothing is written to the
//! database: the trials have no plan or recording to be attempts of an exercise.

use std::collections::BTreeMap;
use std::path::Path;

use anyhow::{Context, bail};
use cutlab_scoring::evidence::predict::{Composite, Prediction, leave_one_subject_out};
use cutlab_scoring::evidence::{EvidenceAttempt, EvidenceOptions, Experience, Report};
use cutlab_scoring::metrics::motion;
use cutlab_scoring::metrics::path::{PathParams, path};

use crate::motion_metrics::parse_poses;

/// One row of `ratings.csv`.
#[derive(Debug, Clone, PartialEq)]
pub struct Rating {
    pub trial: String,
    pub subject: String,
    pub experience: Experience,
    pub rating: f64,
}

/// Parses `ratings.csv` (`name` for messages): a header, then one row per trial.
pub fn parse_ratings(text: &str, name: &str) -> anyhow::Result<Vec<Rating>> {
    let mut rows: Vec<Rating> = Vec::new();
    let mut lines = text
        .lines()
        .enumerate()
        .filter(|(_, l)| !l.trim().is_empty() && !l.trim_start().starts_with('#'));
    match lines.next() {
        Some((_, h)) if h.trim().to_lowercase().starts_with("trial") => {}
        _ => bail!("{name}: the first line must be the header trial,subject,experience,rating"),
    }
    for (i, line) in lines {
        let f: Vec<&str> = line.split(',').map(str::trim).collect();
        let at = i + 1;
        let [trial, subject, experience, rating] = f[..] else {
            bail!(
                "{name}:{at}: expected 4 fields (trial, subject, experience, rating), found {}",
                f.len()
            );
        };
        if trial.is_empty()
            || subject.is_empty()
            || trial.contains(['/', '\\'])
            || trial.starts_with('.')
        {
            bail!("{name}:{at}: the trial and the subject must be plain names");
        }
        let experience: Experience = experience.parse().with_context(|| format!("{name}:{at}"))?;
        let rating: f64 = rating
            .parse()
            .ok()
            .filter(|r: &f64| r.is_finite())
            .with_context(|| format!("{name}:{at}: the rating {rating:?} is not a number"))?;
        if rows.iter().any(|r| r.trial == trial) {
            bail!("{name}:{at}: the trial {trial:?} is rated twice");
        }
        rows.push(Rating {
            trial: trial.into(),
            subject: subject.into(),
            experience,
            rating,
        });
    }
    if rows.is_empty() {
        bail!("{name}: no trials rated");
    }
    Ok(rows)
}

/// The trials of `dir` as attempts: each rated trial's tools' path metrics.
pub fn load(dir: &Path) -> anyhow::Result<Vec<EvidenceAttempt>> {
    let ratings_path = dir.join("ratings.csv");
    let text = std::fs::read_to_string(&ratings_path)
        .with_context(|| format!("reading {}", ratings_path.display()))?;
    let mut ratings = parse_ratings(&text, &ratings_path.display().to_string())?;
    ratings.sort_by(|a, b| a.trial.cmp(&b.trial));
    let trials = dir.join("trials");
    check_every_trial_rated(&trials, &ratings)?;
    let mut subjects: BTreeMap<&str, i64> = BTreeMap::new();
    for r in &ratings {
        let next = subjects.len() as i64 + 1;
        subjects.entry(r.subject.as_str()).or_insert(next);
    }
    ratings
        .iter()
        .enumerate()
        .map(|(k, r)| {
            Ok(EvidenceAttempt {
                attempt_id: k as i64 + 1,
                trainee_id: subjects[r.subject.as_str()],
                trainee: r.subject.clone(),
                experience: Some(r.experience),
                started_ns: k as i64,
                reference: false,
                score: Some(r.rating),
                metrics: trial_metrics(&trials.join(&r.trial), &r.trial)?,
                rating: Some(r.rating),
            })
        })
        .collect()
}

/// Every trial folder has a rating (a folder nobody rated is a mistake, not data to drop).
fn check_every_trial_rated(trials: &Path, ratings: &[Rating]) -> anyhow::Result<()> {
    let entries = std::fs::read_dir(trials)
        .with_context(|| format!("reading the trials folder {}", trials.display()))?;
    for e in entries {
        let e = e.with_context(|| format!("reading {}", trials.display()))?;
        let name = e.file_name().to_string_lossy().into_owned();
        if e.path().is_dir() && !ratings.iter().any(|r| r.trial == name) {
            bail!(
                "{}: the trial {name:?} has no row in ratings.csv",
                trials.display()
            );
        }
    }
    Ok(())
}

/// The path metrics of each `TOOL.csv` in a trial's folder, keyed `KEY@TOOL`.
fn trial_metrics(folder: &Path, trial: &str) -> anyhow::Result<Vec<(String, f64)>> {
    let entries = std::fs::read_dir(folder).with_context(|| {
        format!(
            "ratings.csv names the trial {trial:?}, but {} cannot be read",
            folder.display()
        )
    })?;
    let mut files: Vec<std::path::PathBuf> = entries
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.extension().is_some_and(|x| x == "csv"))
        .collect();
    files.sort();
    if files.is_empty() {
        bail!("{}: no tool's poses (TOOL.csv)", folder.display());
    }
    let mut out = Vec::new();
    let mut tools = Vec::new();
    for file in files {
        let tool = file
            .file_stem()
            .map(|s| s.to_string_lossy().into_owned())
            .unwrap_or_default();
        let text = std::fs::read_to_string(&file)
            .with_context(|| format!("reading {}", file.display()))?;
        let poses = parse_poses(&text, &file.display().to_string())?;
        let m =
            path(&poses, &PathParams::default()).with_context(|| format!("{}", file.display()))?;
        let extra = [
            ("depth_path_m", Some(motion::depth_path_m(&poses))),
            ("speed_apen", motion::speed_apen(&poses)),
        ];
        out.extend(
            m.keyed()
                .into_iter()
                .chain(extra)
                .filter_map(|(k, v)| Some((format!("{k}@{tool}"), v?))),
        );
        tools.push(poses);
    }
    if let [a, b] = &tools[..] {
        let (ratio, corr) = motion::bimanual(a, b);
        let both = [
            ("bimanual_path_ratio", ratio),
            ("bimanual_speed_correlation", corr),
        ];
        out.extend(
            both.into_iter()
                .filter_map(|(k, v)| Some((k.to_owned(), v?))),
        );
    }
    Ok(out)
}

/// The metric families whose composites `--predict` tries: each a name and which `KEY@TOOL`
/// keys it takes.
/// Which `KEY@TOOL` keys a family takes.
type Takes = fn(&str) -> bool;

const FAMILIES: [(&str, Takes); 4] = [
    ("task time", |k| k.starts_with("time_s@")),
    ("path metrics of each tool", |k| {
        k.contains('@')
            && !motion::METRICS
                .iter()
                .any(|m| k.starts_with(&format!("{}@", m.key)))
    }),
    ("+ depth path, speed entropy", |k| k.contains('@')),
    ("+ bimanual", |_| true),
];

/// Leave-one-subject-out predictions of the ratings, per family and composite.
pub fn predictions(attempts: &[EvidenceAttempt]) -> Vec<Prediction> {
    let mut keys: Vec<String> = attempts
        .iter()
        .flat_map(|a| a.metrics.iter().map(|(k, _)| k.clone()))
        .collect();
    keys.sort();
    keys.dedup();
    FAMILIES
        .iter()
        .flat_map(|(name, take)| {
            let keys: Vec<String> = keys.iter().filter(|k| take(k)).cloned().collect();
            [Composite::MeanZ, Composite::Ridge]
                .map(|c| leave_one_subject_out(attempts, name, &keys, c))
        })
        .collect()
}

/// `cutlab import kinematics DIR`.
pub fn run(dir: &Path, json: bool, predict: bool) -> anyhow::Result<()> {
    let attempts = load(dir)?;
    if predict {
        let p = predictions(&attempts);
        if json {
            println!("{}", serde_json::to_string_pretty(&p)?);
        } else {
            println!(
                "Leave one subject out: Spearman's rho of the out-of-fold predictions with the rating"
            );
            for p in &p {
                let rho = p.rho.map_or("-".into(), |r| format!("{r:+.2}"));
                println!(
                    "  {:<28} {:<7} {:>3} metrics  {rho:>6}  ({} trials, {} subjects)",
                    p.family,
                    match p.composite {
                        Composite::MeanZ => "mean-z",
                        Composite::Ridge => "ridge",
                    },
                    p.metrics,
                    p.n,
                    p.subjects
                );
            }
        }
        return Ok(());
    }
    let ratings: Vec<f64> = attempts.iter().filter_map(|a| a.rating).collect();
    let span = ratings.iter().fold(f64::NEG_INFINITY, |a, b| a.max(*b))
        - ratings.iter().fold(f64::INFINITY, |a, b| a.min(*b));
    let options = EvidenceOptions {
        score_label: "Rating".into(),
        // a tenth of the ratings' span, as 0.1 is of the overall score's [-1, 1] in part
        plateau_band: 0.1 * span.max(f64::EPSILON),
        ..EvidenceOptions::default()
    };
    let name = dir.file_name().map_or_else(
        || dir.display().to_string(),
        |n| n.to_string_lossy().into_owned(),
    );
    let report = Report::build(&name, &attempts, &options);
    if json {
        println!("{}", serde_json::to_string_pretty(&report)?);
    } else {
        print!("{}", crate::evidence_cli::text(&report));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ratings_with_their_errors() {
        let ok =
            "trial,subject,experience,rating\nKT_B001,B,novice,13\n\nKT_C001, C, expert, 20.5\n";
        let r = parse_ratings(ok, "r.csv").unwrap();
        assert_eq!(r.len(), 2);
        assert_eq!(
            (r[1].subject.as_str(), r[1].experience, r[1].rating),
            ("C", Experience::Expert, 20.5)
        );
        let cases = [
            ("KT_B001,B,novice,13\n", "the header"),
            (
                "trial,subject,experience,rating\nKT_B001,B,novice\n",
                "r.csv:2: expected 4 fields",
            ),
            (
                "trial,subject,experience,rating\nKT_B001,B,surgeon,13\n",
                "unknown experience level",
            ),
            (
                "trial,subject,experience,rating\nKT_B001,B,novice,NaN\n",
                "r.csv:2: the rating \"NaN\" is not a number",
            ),
            (
                "trial,subject,experience,rating\nKT_B001,B,novice,1\nKT_B001,B,novice,2\n",
                "rated twice",
            ),
            (
                "trial,subject,experience,rating\n../x,B,novice,1\n",
                "plain names",
            ),
            ("trial,subject,experience,rating\n", "no trials"),
        ];
        for (text, want) in cases {
            let e = format!("{:#}", parse_ratings(text, "r.csv").unwrap_err());
            assert!(e.contains(want), "{text:?}: {e}");
        }
    }
}
