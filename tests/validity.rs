//! The assessor's validity test (issue 6): ten seeded scripted `expert` attempts and ten
//! `novice` attempts on the default exercise, simulated, recorded and scored by the real
//! `cutlab` binary. The experts' attempts set the thresholds; then every novice must score
//! below every expert, and every novice must fail the expert-derived thresholds.
//!
//! At the station's pointer (issue 41): four people's steady hands (`pointer:steady`, the
//! hand model through the pointer device) set the pointer's thresholds; other steady hands
//! pass them and sloppy ones fail.
//!
//! The sessions run on the built-in `chest-wall` scene at 3,000 tets on the virtual clock,
//! two at a time.

use std::path::{Path, PathBuf};
use std::process::Command;

const SEEDS: std::ops::RangeInclusive<u64> = 1..=10;
const MIN_TETS: &str = "3000";

fn cutlab(db: &Path, args: &[&str]) -> String {
    let out = Command::new(env!("CARGO_BIN_EXE_cutlab"))
        .arg("--db")
        .arg(db)
        .args(args)
        .env_remove("CUTLAB_DB")
        .env("RUST_LOG", "error")
        .output()
        .expect("cutlab runs");
    assert!(
        out.status.success(),
        "cutlab {args:?} failed: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    String::from_utf8_lossy(&out.stdout).into_owned()
}

/// Records a scripted session of `skill` with `seed` into `dir/skill-seed/session.mcap`.
fn record(db: &Path, dir: &Path, skill: &str, seed: u64) -> PathBuf {
    let out = dir.join(format!("{skill}-{seed}"));
    // the expert finishes the 60 mm incision in about 4 s, the novice (slower, hesitating)
    // in about 12 s
    // (a person's hand at the pointer is done in 7-12 s, when the session ends)
    let duration = if skill == "expert" { "6" } else { "15" };
    let seed = seed.to_string();
    let out_arg = out.to_str().expect("utf-8 path");
    cutlab(
        db,
        &[
            "session",
            "--device",
            skill,
            "--seed",
            &seed,
            "--min-tets",
            MIN_TETS,
            "--duration",
            duration,
            "--surface-hz",
            "0",
            "--out",
            out_arg,
        ],
    );
    out.join("session.mcap")
}

/// Records the sessions of `skill` for every seed, two at a time.
fn record_all(db: &Path, dir: &Path, skill: &str) -> Vec<PathBuf> {
    record_seeds(db, dir, skill, SEEDS)
}

/// Records the sessions of `skill` for `seeds`, two at a time.
fn record_seeds(
    db: &Path,
    dir: &Path,
    skill: &str,
    seeds: impl IntoIterator<Item = u64>,
) -> Vec<PathBuf> {
    let seeds: Vec<u64> = seeds.into_iter().collect();
    let mut files = Vec::new();
    for pair in seeds.chunks(2) {
        let handles: Vec<_> = pair
            .iter()
            .map(|&seed| {
                let (db, dir, skill) = (db.to_owned(), dir.to_owned(), skill.to_owned());
                std::thread::spawn(move || record(&db, &dir, &skill, seed))
            })
            .collect();
        files.extend(
            handles
                .into_iter()
                .map(|h| h.join().expect("session thread")),
        );
    }
    files
}

/// Scores `file` for `trainee`; returns (score, passed).
fn assess(db: &Path, file: &Path, trainee: &str, expert: bool) -> (f64, bool) {
    let mut args = vec![
        "assess",
        file.to_str().expect("utf-8 path"),
        "--trainee",
        trainee,
        "--json",
    ];
    if expert {
        args.push("--expert");
    }
    let v: serde_json::Value = serde_json::from_str(&cutlab(db, &args)).expect("assess --json");
    (
        v["score"].as_f64().expect("score"),
        v["pass"].as_bool().expect("pass"),
    )
}

#[test]
fn every_novice_scores_below_every_expert_and_fails_the_expert_thresholds() {
    let dir = std::env::temp_dir().join(format!("cutlab-validity-{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("temp dir");
    let db = dir.join("validity.db");

    // the experts' reference attempts, then the thresholds they set
    let experts = record_all(&db, &dir, "expert");
    for (k, file) in experts.iter().enumerate() {
        assess(&db, file, &format!("expert-{k}"), true);
    }
    let thresholds = cutlab(&db, &["exercise", "thresholds", "--json"]);
    let t: serde_json::Value = serde_json::from_str(&thresholds).expect("thresholds json");
    let metrics = t["metrics"].as_array().expect("metrics");
    assert!(
        metrics.len() >= 5,
        "thresholds for the metrics: {thresholds}"
    );
    assert!(
        metrics
            .iter()
            .all(|m| m["n_experts"].as_u64().is_some_and(|n| n >= 8)),
        "from the experts: {thresholds}"
    );

    // the experts' attempts scored against their own thresholds, as a trainee's would be
    let expert_scores: Vec<f64> = experts
        .iter()
        .enumerate()
        .map(|(k, f)| assess(&db, f, &format!("expert-check-{k}"), false).0)
        .collect();
    let novices = record_all(&db, &dir, "novice");
    let novice: Vec<(f64, bool)> = novices
        .iter()
        .enumerate()
        .map(|(k, f)| assess(&db, f, &format!("novice-{k}"), false))
        .collect();
    eprintln!("expert scores {expert_scores:.3?}");
    eprintln!(
        "novice scores {:.3?}",
        novice.iter().map(|n| n.0).collect::<Vec<_>>()
    );

    let lowest_expert = expert_scores.iter().copied().fold(f64::INFINITY, f64::min);
    let highest_novice = novice.iter().map(|n| n.0).fold(f64::NEG_INFINITY, f64::max);
    assert!(
        highest_novice < lowest_expert,
        "the best novice ({highest_novice:.3}) scores below the worst expert ({lowest_expert:.3})"
    );
    assert!(
        novice.iter().all(|n| !n.1),
        "every novice fails the expert-derived thresholds"
    );
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn steady_hands_at_the_pointer_pass_the_thresholds_people_set_and_sloppy_ones_fail() {
    let dir = std::env::temp_dir().join(format!("cutlab-validity-pointer-{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("temp dir");
    let db = dir.join("validity.db");
    let experts = record_seeds(&db, &dir, "pointer:steady", 1..=4);
    for (k, file) in experts.iter().enumerate() {
        assess(&db, file, &format!("expert-{k}"), true);
    }
    cutlab(&db, &["exercise", "thresholds"]);
    let steady: Vec<(f64, bool)> = record_seeds(&db, &dir, "pointer:steady", 11..=13)
        .iter()
        .enumerate()
        .map(|(k, f)| assess(&db, f, &format!("steady-{k}"), false))
        .collect();
    let sloppy: Vec<(f64, bool)> = record_seeds(&db, &dir, "pointer:sloppy", 11..=13)
        .iter()
        .enumerate()
        .map(|(k, f)| assess(&db, f, &format!("sloppy-{k}"), false))
        .collect();
    eprintln!("steady {steady:.3?}, sloppy {sloppy:.3?}");
    assert!(
        steady.iter().all(|s| s.1),
        "every steady hand passes: {steady:?}"
    );
    assert!(
        sloppy.iter().all(|s| !s.1),
        "every sloppy hand fails: {sloppy:?}"
    );
    let _ = std::fs::remove_dir_all(&dir);
}
