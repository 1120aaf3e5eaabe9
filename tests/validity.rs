//! The assessor's validity test (issue 6): ten seeded scripted `expert` attempts and ten
//! `novice` attempts on the default exercise, simulated, recorded and scored by the real
//! `cutlab` binary. The experts' attempts set the thresholds; then every novice must score
//! below every expert, and every novice must fail the expert-derived thresholds.
//!
//! At the station's pointer (issue 41): four people's steady hands (`pointer:steady`, the
//! hand model through the pointer device) set the pointer's thresholds; other steady hands
//! pass them and sloppy ones fail.
//!
//! Pattern cutting (issue 44): experts pass FLS's rule, novices fail, the MISTELS scores in
//! the order of skill; the curved incision on the CT's body wall: experts pass, novices fail,
//! the scores in the order of skill; elliptical excision of a skin lesion likewise.
//!
//! The sessions run on the built-in `chest-wall` scene at 3,000 tets on the virtual clock,
//! two at a time.

use std::path::{Path, PathBuf};
use std::process::Command;

const SEEDS: std::ops::RangeInclusive<u64> = 1..=10;
const MIN_TETS: &str = "3000";
/// Seeds per level of the pattern cutting run in the suite (each session cuts the sheet at
/// its own size, 25-60 s here: ten seeds a level take 11 minutes, four 4); the environment's
/// `CUTLAB_PATTERN_SEEDS` asks for another count (`docs/guide/assessment.md#validity`).
const PATTERN_SEEDS: u64 = 4;
/// Seeds per level of the body wall's run (53,000 tets: 10-25 s a session here).
const BODY_WALL_SEEDS: u64 = 10;
/// Seeds per level of the elliptical excision's run (18,000 tets at 4 ms: 4-18 s a session).
const EXCISION_SEEDS: u64 = 10;
/// Mini-thoracotomies a level (ten take about 7 minutes on 2 cores, the novices' most of
/// it); the environment's `CUTLAB_FIELD_SEEDS` asks for another count.
const FIELD_SEEDS: u64 = 10;

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

/// The exercise a validity run records.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Exercise {
    /// No exercise: the default scene's own incision, scored as `chest-wall-incision`.
    Incision,
    /// The default scene's own incision as [`Exercise::Incision`], the trainee's other hand
    /// giving countertraction with a grasper (`--second-hand`).
    TwoHanded,
    /// `pattern-cutting` on the sheet at its own size, recorded as an attempt of `trainee`.
    Pattern,
    /// `body-wall-incision` on the CT's body wall at its scene's 10 ms step.
    BodyWall,
    /// `elliptical-excision` on the skin block at its scene's 4 ms step.
    Excision,
    /// `mini-thoracotomy` on the thorax, the incision placed by the trainee.
    Field,
}

impl Exercise {
    /// The session's arguments besides the device, seed and output.
    fn args(self, skill: &str, seed: u64) -> Vec<String> {
        let strings = |a: &[&str]| a.iter().map(|s| (*s).to_owned()).collect::<Vec<_>>();
        match self {
            // the expert finishes the 60 mm incision in about 4 s, the novice (slower,
            // hesitating) in about 12 s (a person's hand at the pointer is done in 7-12 s,
            // when the session ends)
            Exercise::Incision => {
                let duration = if skill == "expert" { "6" } else { "15" };
                strings(&["--min-tets", MIN_TETS, "--duration", duration])
            }
            Exercise::TwoHanded => {
                let mut args = Exercise::Incision.args(skill, seed);
                args.push("--second-hand".into());
                args
            }
            // the expert cuts the circle free in about 8 s; a novice has not in 30 s
            Exercise::Pattern => {
                let duration = if skill == "expert" { "12" } else { "30" };
                attempt_args("pattern-cutting", duration, skill, seed)
            }
            // the expert cuts the 100 mm arc in about 6 s, the intermediate in 9, the novice
            // in 16
            Exercise::BodyWall => {
                let duration = match skill {
                    "expert" => "10",
                    "intermediate" => "16",
                    _ => "25",
                };
                attempt_args("body-wall-incision", duration, skill, seed)
            }
            // the expert incises the 90 mm outline in about 5 s after a 1.3 s approach, the
            // intermediate in 6-8 s, the novice in 13
            Exercise::Excision => {
                let duration = match skill {
                    "expert" => "12",
                    "intermediate" => "16",
                    _ => "25",
                };
                attempt_args("elliptical-excision", duration, skill, seed)
            }
            // the expert goes through the 40 mm wall and along its 50 mm in about 7 s, the
            // intermediate in 10, the novice (pauses, pressing on a rib) in up to 16
            Exercise::Field => {
                let duration = match skill {
                    "expert" => "12",
                    "intermediate" => "16",
                    _ => "25",
                };
                attempt_args("mini-thoracotomy", duration, skill, seed)
            }
        }
    }
}

/// The trainee whose attempt the session of `skill` with `seed` is.
fn trainee_of(skill: &str, seed: u64) -> String {
    format!("rec-{}-{seed}", skill.replace(':', "-"))
}

/// A session of `exercise` for `duration` s, stored as an attempt of its own trainee.
fn attempt_args(exercise: &str, duration: &str, skill: &str, seed: u64) -> Vec<String> {
    let trainee = trainee_of(skill, seed);
    [
        "--exercise",
        exercise,
        "--duration",
        duration,
        "--trainee",
        &trainee,
    ]
    .map(str::to_owned)
    .to_vec()
}

/// Records a scripted session of `skill` with `seed` into `dir/skill-seed/session.mcap`.
fn record(db: &Path, dir: &Path, skill: &str, seed: u64, exercise: Exercise) -> PathBuf {
    let out = dir.join(format!("{skill}-{seed}"));
    let seed_arg = seed.to_string();
    let out_arg = out.to_str().expect("utf-8 path");
    let mut args = vec!["session", "--device", skill, "--seed", &seed_arg];
    let more = exercise.args(skill, seed);
    let named = more.iter().position(|a| a == "--exercise");
    if let Some(name) = named.map(|i| more[i + 1].as_str()) {
        open_for_study(db, &trainee_of(skill, seed), name);
    }
    args.extend(more.iter().map(String::as_str));
    args.extend(["--surface-hz", "0", "--out", out_arg]);
    cutlab(db, &args);
    out.join("session.mcap")
}

/// Opens `exercise` to the synthetic `trainee`, as the study's instructor: a fresh trainee
/// is held back in `cutting-basics` until proficient in the exercise before it, and
/// `cutlab session` refuses them as the station does.
fn open_for_study(db: &Path, trainee: &str, exercise: &str) {
    // the instructor is added by the first session to need them (the others are refused)
    let _ = Command::new(env!("CARGO_BIN_EXE_cutlab"))
        .arg("--db")
        .arg(db)
        .args([
            "user",
            "add",
            "--name",
            "validity-study",
            "--role",
            "instructor",
        ])
        .env_remove("CUTLAB_DB")
        .output();
    cutlab(
        db,
        &[
            "user",
            "open",
            "--name",
            trainee,
            "--exercise",
            exercise,
            "--by",
            "validity-study",
            "--reason",
            "validity study",
        ],
    );
}

/// Records the sessions of `skill` for every seed, two at a time.
fn record_all(db: &Path, dir: &Path, skill: &str) -> Vec<PathBuf> {
    record_seeds(db, dir, skill, SEEDS, Exercise::Incision)
}

/// Records the sessions of `skill` for `seeds`, two at a time.
fn record_seeds(
    db: &Path,
    dir: &Path,
    skill: &str,
    seeds: impl IntoIterator<Item = u64>,
    exercise: Exercise,
) -> Vec<PathBuf> {
    let seeds: Vec<u64> = seeds.into_iter().collect();
    let mut files = Vec::new();
    for pair in seeds.chunks(2) {
        let handles: Vec<_> = pair
            .iter()
            .map(|&seed| {
                let (db, dir, skill) = (db.to_owned(), dir.to_owned(), skill.to_owned());
                std::thread::spawn(move || record(&db, &dir, &skill, seed, exercise))
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

/// Scores `file` for `trainee` at `exercise`; returns the report (`score`, `pass`, `metrics`).
fn assess_at(
    db: &Path,
    file: &Path,
    exercise: &str,
    trainee: &str,
    expert: bool,
) -> serde_json::Value {
    let mut args = vec![
        "assess",
        file.to_str().expect("utf-8 path"),
        "--exercise",
        exercise,
        "--trainee",
        trainee,
        "--json",
    ];
    if expert {
        args.push("--expert");
    }
    serde_json::from_str(&cutlab(db, &args)).expect("assess --json")
}

/// Scores `file` for `trainee` at the built-in incision; returns (score, passed).
fn assess(db: &Path, file: &Path, trainee: &str, expert: bool) -> (f64, bool) {
    let v = assess_at(db, file, "chest-wall-incision", trainee, expert);
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

/// The synthetic trainees with both hands on the incision, 10 seeds per level: the handling
/// metrics of the other hand (issue 66) tell the levels apart. Every expert holds the tissue
/// drawn away from the blade for most of the cut and every novice for less of it than any
/// expert; the mean countertraction goes expert > intermediate > novice; the experts draw
/// away from the blade and the novices towards it.
#[test]
fn two_handed_experts_give_countertraction_and_novices_do_not() {
    let dir = std::env::temp_dir().join(format!("cutlab-validity-hands-{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("temp dir");
    let db = dir.join("validity.db");
    let handling = |skill: &str| -> Vec<[f64; 3]> {
        record_seeds(&db, &dir, skill, SEEDS, Exercise::TwoHanded)
            .iter()
            .enumerate()
            .map(|(k, f)| {
                let v = assess_at(
                    &db,
                    f,
                    "chest-wall-incision",
                    &format!("{skill}-{k}"),
                    false,
                );
                let metric = |key: &str| {
                    v["metrics"]
                        .as_array()
                        .and_then(|m| m.iter().find(|m| m["key"] == key))
                        .and_then(|m| m["value"].as_f64())
                        .unwrap_or_else(|| panic!("{key} of {skill} seed {k}: {v}"))
                };
                [
                    metric("grasps"),
                    metric("countertraction_fraction"),
                    metric("traction_alignment"),
                ]
            })
            .collect()
    };
    let (expert, intermediate, novice) = (
        handling("expert"),
        handling("intermediate"),
        handling("novice"),
    );
    eprintln!(
        "[grasps, countertraction, traction direction]\nexpert {expert:.2?}\n\
         intermediate {intermediate:.2?}\nnovice {novice:.2?}"
    );
    let all = || expert.iter().chain(&intermediate).chain(&novice);
    assert!(all().all(|h| h[0] == 1.0), "one grasp each");
    assert!(
        expert.iter().all(|h| h[1] > 0.5 && h[2] > 0.5),
        "every expert draws away for most of the cut: {expert:?}"
    );
    let least_expert = expert.iter().map(|h| h[1]).fold(f64::INFINITY, f64::min);
    assert!(
        novice.iter().all(|h| h[1] < least_expert),
        "every novice's countertraction below every expert's: {novice:?}"
    );
    let mean = |v: &[[f64; 3]], i: usize| v.iter().map(|h| h[i]).sum::<f64>() / v.len() as f64;
    assert!(
        mean(&expert, 1) > mean(&intermediate, 1) && mean(&intermediate, 1) > mean(&novice, 1),
        "mean countertraction {:.2} > {:.2} > {:.2}",
        mean(&expert, 1),
        mean(&intermediate, 1),
        mean(&novice, 1)
    );
    assert!(
        mean(&novice, 2) < 0.0 && mean(&expert, 2) > mean(&novice, 2),
        "the novices draw towards the blade: {:.2} vs the experts' {:.2}",
        mean(&novice, 2),
        mean(&expert, 2)
    );
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn steady_hands_at_the_pointer_pass_the_thresholds_people_set_and_sloppy_ones_score_lower() {
    let dir = std::env::temp_dir().join(format!("cutlab-validity-pointer-{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("temp dir");
    let db = dir.join("validity.db");
    let experts = record_seeds(&db, &dir, "pointer:steady", 1..=4, Exercise::Incision);
    for (k, file) in experts.iter().enumerate() {
        assess(&db, file, &format!("expert-{k}"), true);
    }
    cutlab(&db, &["exercise", "thresholds"]);
    let steady: Vec<(f64, bool)> =
        record_seeds(&db, &dir, "pointer:steady", 11..=13, Exercise::Incision)
            .iter()
            .enumerate()
            .map(|(k, f)| assess(&db, f, &format!("steady-{k}"), false))
            .collect();
    let sloppy: Vec<(f64, bool)> =
        record_seeds(&db, &dir, "pointer:sloppy", 11..=13, Exercise::Incision)
            .iter()
            .enumerate()
            .map(|(k, f)| assess(&db, f, &format!("sloppy-{k}"), false))
            .collect();
    eprintln!("steady {steady:.3?}, sloppy {sloppy:.3?}");
    steady_and_sloppy_told_apart(&steady, &sloppy);
    // a steady hand on a page a slow machine holds back to 7 samples a second, slowed by what
    // it sees: the lag is not scored as the hand's (issue 63)
    let lagging = record_seeds(&db, &dir, "pointer:lagging", [11], Exercise::Incision);
    let v = assess_at(&db, &lagging[0], "chest-wall-incision", "lagging", false);
    let metric = |key: &str| {
        v["metrics"]
            .as_array()
            .and_then(|m| m.iter().find(|m| m["key"] == key).cloned())
            .unwrap_or_default()
    };
    for key in ["time_s", "idle_time_s", "movements"] {
        let m = metric(key);
        assert!(
            m["value"].is_null()
                && m["missing"]
                    .as_str()
                    .is_some_and(|w| w.starts_with(cutlab_scoring::metrics::STATION_LAGGED)),
            "{key} set aside: {m}"
        );
    }
    assert!(!metric("lateral_mean_m")["value"].is_null(), "{v}");
    assert!(
        v["note"]
            .as_str()
            .is_some_and(|n| n.starts_with(cutlab_scoring::from_recording::LAGGED_NOTE)),
        "the note says the station lagged: {v}"
    );
    assert_eq!(v["pass"], true, "the steady hand still passes: {v}");
    let _ = std::fs::remove_dir_all(&dir);
}

/// Every steady hand passes, every sloppy one scores below every steady one, and most sloppy
/// ones fail: a sloppy hand that happens to stay within the plan's tolerance everywhere (its
/// widest miss 1.7 mm of 2) is on the plan as the plan defines it, and passes lower.
fn steady_and_sloppy_told_apart(steady: &[(f64, bool)], sloppy: &[(f64, bool)]) {
    assert!(
        steady.iter().all(|s| s.1),
        "every steady hand passes: {steady:?}"
    );
    let lowest_steady = steady.iter().map(|s| s.0).fold(f64::INFINITY, f64::min);
    assert!(
        sloppy.iter().all(|s| s.0 < lowest_steady - 0.1),
        "every sloppy hand scores below every steady one: {sloppy:?} {steady:?}"
    );
    let failed = sloppy.iter().filter(|s| !s.1).count();
    assert!(
        2 * failed > sloppy.len(),
        "most sloppy hands fail: {sloppy:?}"
    );
}

/// The stylus class calibrated on a person as the pointer's is (issue 63): a steady hand on a
/// stylus, held at the plan's depth below the rest surface while the tissue gives way, passes
/// the thresholds other steady hands set; sloppy hands are told apart from steady ones, and
/// the synthetic novices fail.
#[test]
fn steady_hands_on_a_stylus_pass_the_thresholds_people_set_and_others_fail() {
    let dir = std::env::temp_dir().join(format!("cutlab-validity-stylus-{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("temp dir");
    let db = dir.join("validity.db");
    let experts = record_seeds(&db, &dir, "stylus:steady", 1..=4, Exercise::Incision);
    for (k, file) in experts.iter().enumerate() {
        assess(&db, file, &format!("expert-{k}"), true);
    }
    cutlab(&db, &["exercise", "thresholds"]);
    let scored = |skill: &str, seeds: std::ops::RangeInclusive<u64>| -> Vec<(f64, bool)> {
        record_seeds(&db, &dir, skill, seeds, Exercise::Incision)
            .iter()
            .enumerate()
            .map(|(k, f)| assess(&db, f, &format!("{}-{k}", skill.replace(':', "-")), false))
            .collect()
    };
    let steady = scored("stylus:steady", 11..=13);
    let sloppy = scored("stylus:sloppy", 11..=13);
    let novice = scored("novice", 1..=3);
    eprintln!("stylus: steady {steady:.3?}, sloppy {sloppy:.3?}, novice {novice:.3?}");
    steady_and_sloppy_told_apart(&steady, &sloppy);
    assert!(
        novice.iter().all(|s| !s.1),
        "every novice fails: {novice:?}"
    );
    let _ = std::fs::remove_dir_all(&dir);
}

/// Pattern cutting (FLS): every synthetic expert cuts the circle free within FLS's 98 s and
/// 2 mm and passes; every novice fails; the MISTELS scores order expert > intermediate >
/// novice on average, and every expert's is above every novice's.
#[test]
fn pattern_cutting_experts_pass_fls_and_novices_fail() {
    let dir = std::env::temp_dir().join(format!("cutlab-validity-pattern-{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("temp dir");
    let db = dir.join("validity.db");
    let seeds = std::env::var("CUTLAB_PATTERN_SEEDS")
        .ok()
        .map(|s| {
            s.parse::<u64>()
                .expect("CUTLAB_PATTERN_SEEDS: a count of seeds")
        })
        .map_or(1..=PATTERN_SEEDS, |n| 1..=n.max(1));
    let score = |skill: &str| -> Vec<(f64, bool, f64)> {
        record_seeds(&db, &dir, skill, seeds.clone(), Exercise::Pattern)
            .iter()
            .enumerate()
            .map(|(k, f)| {
                let v = assess_at(&db, f, "pattern-cutting", &format!("{skill}-{k}"), false);
                let mistels = v["metrics"]
                    .as_array()
                    .expect("metrics")
                    .iter()
                    .find(|m| m["key"] == "mistels_score")
                    .and_then(|m| m["value"].as_f64())
                    .expect("a MISTELS score");
                (
                    v["score"].as_f64().expect("score"),
                    v["pass"].as_bool().expect("pass"),
                    mistels,
                )
            })
            .collect()
    };
    let (expert, intermediate, novice) = (score("expert"), score("intermediate"), score("novice"));
    eprintln!(
        "(score, pass, MISTELS): expert {expert:.2?}\nintermediate {intermediate:.2?}\nnovice {novice:.2?}"
    );
    assert!(
        expert.iter().all(|e| e.1 && e.2 > 200.0),
        "every expert passes: {expert:?}"
    );
    assert!(
        novice.iter().all(|n| !n.1),
        "every novice fails: {novice:?}"
    );
    let mean = |v: &[(f64, bool, f64)]| v.iter().map(|x| x.2).sum::<f64>() / v.len() as f64;
    assert!(
        mean(&expert) > mean(&intermediate) && mean(&intermediate) > mean(&novice),
        "MISTELS means {:.1} > {:.1} > {:.1}",
        mean(&expert),
        mean(&intermediate),
        mean(&novice)
    );
    let worst_expert = expert.iter().map(|e| e.2).fold(f64::INFINITY, f64::min);
    assert!(novice.iter().all(|n| n.2 < worst_expert));
    let _ = std::fs::remove_dir_all(&dir);
}

/// The curved incision on a patient (the CT's body wall): every expert passes, every novice
/// fails, the mean scores go expert > intermediate > novice and every novice scores below
/// every expert.
#[test]
fn body_wall_experts_pass_the_curved_incision_and_novices_fail() {
    levels_in_order(Exercise::BodyWall, "body-wall-incision", BODY_WALL_SEEDS);
}

/// Elliptical excision of a skin lesion, ten seeds a level: the same as the body wall's.
#[test]
fn excision_experts_pass_and_novices_fail() {
    levels_in_order(Exercise::Excision, "elliptical-excision", EXCISION_SEEDS);
}

/// The mini-thoracotomy, each trainee choosing where to cut (the expert the plan's space and
/// length; the others sometimes a space off, on a rib, short or shallow), scored on what the
/// retracted wound shows: the same as the body wall's, with `CUTLAB_FIELD_SEEDS` seeds a
/// level (default [`FIELD_SEEDS`]).
#[test]
fn field_experts_expose_the_heart_and_novices_fail() {
    let seeds = std::env::var("CUTLAB_FIELD_SEEDS").map_or(FIELD_SEEDS, |n| {
        n.parse::<u64>()
            .expect("CUTLAB_FIELD_SEEDS: a count of seeds")
            .max(1)
    });
    levels_in_order(Exercise::Field, "mini-thoracotomy", seeds);
}

/// Records `seeds` attempts of `exercise` per level and scores them at `name`: every expert
/// passes, every novice fails, the mean scores go expert > intermediate > novice and every
/// novice scores below every expert.
fn levels_in_order(exercise: Exercise, name: &str, seeds: u64) {
    let dir = std::env::temp_dir().join(format!("cutlab-validity-{name}-{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("temp dir");
    let db = dir.join("validity.db");
    let score = |skill: &str| -> Vec<(f64, bool)> {
        record_seeds(&db, &dir, skill, 1..=seeds, exercise)
            .iter()
            .enumerate()
            .map(|(k, f)| {
                let v = assess_at(&db, f, name, &format!("{skill}-{k}"), false);
                (
                    v["score"].as_f64().expect("score"),
                    v["pass"].as_bool().expect("pass"),
                )
            })
            .collect()
    };
    let (expert, intermediate, novice) = (score("expert"), score("intermediate"), score("novice"));
    eprintln!(
        "{name} (score, pass): expert {expert:.2?}\nintermediate {intermediate:.2?}\nnovice {novice:.2?}"
    );
    assert!(
        expert.iter().all(|e| e.1),
        "every expert passes: {expert:?}"
    );
    assert!(
        novice.iter().all(|n| !n.1),
        "every novice fails: {novice:?}"
    );
    let mean = |v: &[(f64, bool)]| v.iter().map(|x| x.0).sum::<f64>() / v.len() as f64;
    assert!(
        mean(&expert) > mean(&intermediate) && mean(&intermediate) > mean(&novice),
        "mean scores {:.2} > {:.2} > {:.2}",
        mean(&expert),
        mean(&intermediate),
        mean(&novice)
    );
    let worst_expert = expert.iter().map(|e| e.0).fold(f64::INFINITY, f64::min);
    assert!(
        novice.iter().all(|n| n.0 < worst_expert),
        "{novice:?} below {worst_expert}"
    );
    let _ = std::fs::remove_dir_all(&dir);
}
