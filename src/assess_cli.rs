//! The assessment commands: `motion-metrics`, `user`, `cohort`, `exercise`, `evidence`,
//! `import kinematics`, `export xapi`.
//! The database ones open `--db PATH`, else `$CUTLAB_DB`, else `./cutlab.db` (created and
//! migrated on first use, with the built-in exercise).

use std::io::BufRead;
use std::path::PathBuf;

use anyhow::Context;
use clap::Subcommand;
use cutlab_assessor::store::{DbLocation, NewExercise, Role, Store, default_db};
use cutlab_scoring::evidence::Experience;
use cutlab_scoring::{ExercisePlan, proficiency};

/// The assessment commands, flattened into the top-level command enum.
#[derive(Debug, Subcommand)]
pub enum AssessCommand {
    /// Path metrics of a tool trajectory: CSV `t_s, x_m, y_m, z_m, qw, qx, qy, qz` (optional
    /// header, any sampling rate): time, path length, economy, idle time, movements,
    /// angular path, LDLJ and SPARC.
    MotionMetrics {
        /// The trajectory file.
        poses: PathBuf,
        /// Machine-readable output.
        #[arg(long)]
        json: bool,
    },
    /// Score a recorded session (`DIR/session.mcap`) against an exercise's expert plan: the
    /// attempt, its metrics and verdict are stored; prints a report (`--json` for machines).
    Assess {
        /// The recording.
        file: PathBuf,
        /// The exercise (default: the built-in chest-wall incision).
        #[arg(long, default_value = cutlab_assessor::store::BUILTIN_EXERCISE)]
        exercise: String,
        /// The trainee's user name (a new name is created as a trainee).
        #[arg(long)]
        trainee: String,
        /// An expert's reference attempt (used to derive thresholds).
        #[arg(long)]
        expert: bool,
        /// Machine-readable output.
        #[arg(long)]
        json: bool,
    },
    /// Users of the assessment database.
    User {
        #[command(subcommand)]
        command: UserCommand,
    },
    /// Cohorts of trainees.
    Cohort {
        #[command(subcommand)]
        command: CohortCommand,
    },
    /// Exercises: a scene and an expert plan.
    Exercise {
        #[command(subcommand)]
        command: ExerciseCommand,
    },
    /// The validity evidence of an exercise's scores: experience groups, Mann-Whitney U and
    /// AUC per metric, test-retest ICC, learning curves, the contrasting-groups pass mark.
    Evidence(crate::evidence_cli::EvidenceArgs),
    /// Imports from other systems.
    Import {
        #[command(subcommand)]
        command: ImportCommand,
    },
    /// Exports for other systems.
    Export {
        #[command(subcommand)]
        command: ExportCommand,
    },
}

#[derive(Debug, Subcommand)]
pub enum ImportCommand {
    /// The evidence report on kinematic data with raters' ratings: DIR/ratings.csv
    /// (trial,subject,experience,rating) and DIR/trials/TRIAL/TOOL.csv (the motion-metrics
    /// layout). Nothing is written to the database.
    Kinematics {
        /// The folder.
        dir: PathBuf,
        /// Machine-readable output.
        #[arg(long)]
        json: bool,
        /// Instead of the report: how well composites of the metrics predict the ratings of
        /// subjects they were not fitted on (leave one subject out).
        #[arg(long)]
        predict: bool,
    },
}

#[derive(Debug, Subcommand)]
pub enum UserCommand {
    /// Adds a user (the password is stored as an argon2id hash, never in plain text).
    Add {
        #[arg(long)]
        name: String,
        /// instructor | trainee | admin
        #[arg(long)]
        role: String,
        /// Read the password from the first line of standard input.
        #[arg(long, conflicts_with = "password")]
        password_stdin: bool,
        /// The password (visible in the process list: prefer --password-stdin).
        #[arg(long)]
        password: Option<String>,
        /// novice | intermediate | expert: the group the evidence report puts them in.
        #[arg(long)]
        experience: Option<String>,
    },
    /// Records a user's surgical experience (novice, intermediate, expert, or none).
    Experience {
        #[arg(long)]
        name: String,
        /// novice | intermediate | expert | none
        #[arg(long)]
        level: String,
    },
    /// Opens an exercise to a trainee before they are proficient in the one before it in a
    /// curriculum with progression (as an instructor does on the trainee's progress page);
    /// a new name becomes a trainee.
    Open {
        /// The trainee.
        #[arg(long)]
        name: String,
        /// The exercise opened.
        #[arg(long)]
        exercise: String,
        /// The instructor or administrator who opens it.
        #[arg(long)]
        by: String,
        /// Why, kept with the opening.
        #[arg(long)]
        reason: String,
    },
    /// Lists the users.
    List,
}

#[derive(Debug, Subcommand)]
pub enum CohortCommand {
    /// Adds a cohort.
    Add {
        #[arg(long)]
        name: String,
        /// The instructor's user name.
        #[arg(long)]
        instructor: Option<String>,
    },
    /// Puts a user in a cohort.
    Join {
        #[arg(long)]
        cohort: String,
        #[arg(long)]
        user: String,
    },
    /// Lists the cohorts and their members.
    List,
}

#[derive(Debug, Subcommand)]
pub enum ExerciseCommand {
    /// Adds an exercise: a scene and an expert plan file (TOML or JSON, see
    /// scoring/examples/plan.toml). Thresholds come from expert attempts.
    Add {
        #[arg(long)]
        name: String,
        #[arg(long)]
        scene: String,
        #[arg(long)]
        plan: PathBuf,
        #[arg(long, default_value = "")]
        description: String,
        /// k of the thresholds mean +/- k SD.
        #[arg(long, default_value_t = proficiency::DEFAULT_K)]
        k: f64,
        /// The station runs it in exam mode only (the planned incision never shown).
        #[arg(long)]
        exam_only: bool,
    },
    /// Lists the exercises.
    List,
    /// Shows an exercise: its scene, mode and plan (`--json`: the plan's fields as a plan file
    /// holds them, `incision_m`, `depth_m`, `target_m`, `viewpoint_m`...).
    Show {
        /// The exercise.
        name: String,
        #[arg(long)]
        json: bool,
    },
    /// Sets an exercise's thresholds from its complete expert attempts (mean +/- k SD after
    /// removing outliers with |z| > 1.96) and prints them (`--json` for machines).
    Thresholds {
        /// The exercise.
        #[arg(default_value = cutlab_assessor::store::BUILTIN_EXERCISE)]
        name: String,
        #[arg(long)]
        json: bool,
    },
}

#[derive(Debug, Subcommand)]
pub enum ExportCommand {
    /// xAPI statements (attempted / passed / failed / mastered) of a trainee's attempts, JSON.
    Xapi {
        #[arg(long)]
        trainee: String,
    },
}

/// Runs an assessment command; `db` is the global `--db`.
pub fn run(db: Option<&DbLocation>, command: AssessCommand) -> anyhow::Result<()> {
    match command {
        AssessCommand::MotionMetrics { poses, json } => crate::motion_metrics::run(&poses, json),
        AssessCommand::Import {
            command: ImportCommand::Kinematics { dir, json, predict },
        } => crate::kinematics::run(&dir, json, predict),
        command => on_store(db, async |store| with_store(store, command).await),
    }
}

/// Runs `f` on the database `db` (else the default one): opened, its built-in exercises made
/// sure of, closed after.
pub fn on_store<T>(
    db: Option<&DbLocation>,
    f: impl AsyncFnOnce(&Store) -> anyhow::Result<T>,
) -> anyhow::Result<T> {
    let location = default_db(db);
    let rt = tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
        .context("starting the async runtime")?;
    rt.block_on(async {
        let store = Store::open(&location)
            .await
            .with_context(|| format!("opening the database {location}"))?;
        store.ensure_builtins().await?;
        let result = f(&store).await;
        store.close().await;
        result
    })
}

async fn with_store(store: &Store, command: AssessCommand) -> anyhow::Result<()> {
    match command {
        AssessCommand::Assess {
            file,
            exercise,
            trainee,
            expert,
            json,
        } => {
            let rec = cutlab_recorder::Recording::open(&file)
                .with_context(|| format!("reading {}", file.display()))?;
            let attempt = store
                .start_recorded_attempt(&exercise, &trainee, &file, expert)
                .await?;
            let (outcome, values) = store
                .score_recording(attempt.id, &rec)
                .await
                .context("scoring the recording")?;
            print_outcome(&outcome, &values, json)?;
        }
        AssessCommand::MotionMetrics { poses, json } => crate::motion_metrics::run(&poses, json)?,
        AssessCommand::Import {
            command: ImportCommand::Kinematics { dir, json, predict },
        } => crate::kinematics::run(&dir, json, predict)?,
        AssessCommand::User { command } => user(store, command).await?,
        AssessCommand::Cohort { command } => cohort(store, command).await?,
        AssessCommand::Evidence(args) => crate::evidence_cli::run(store, args).await?,
        AssessCommand::Exercise { command } => exercise(store, command).await?,
        AssessCommand::Export {
            command: ExportCommand::Xapi { trainee },
        } => {
            let statements = store.xapi_statements(&trainee).await?;
            println!("{}", serde_json::to_string_pretty(&statements)?);
        }
    }
    Ok(())
}

async fn user(store: &Store, command: UserCommand) -> anyhow::Result<()> {
    match command {
        UserCommand::Add {
            name,
            role,
            password_stdin,
            password,
            experience,
        } => {
            let role: Role = role.parse()?;
            let experience: Option<Experience> = experience.map(|e| e.parse()).transpose()?;
            let password = if password_stdin {
                let mut line = String::new();
                std::io::stdin()
                    .lock()
                    .read_line(&mut line)
                    .context("reading the password from standard input")?;
                let line = line.trim_end_matches(['\r', '\n']).to_owned();
                anyhow::ensure!(!line.is_empty(), "empty password on standard input");
                Some(line)
            } else {
                password
            };
            let u = store.create_user(&name, role, password.as_deref()).await?;
            if experience.is_some() {
                store.set_experience(u.id, experience).await?;
            }
            println!(
                "added {} {} (id {}){}",
                u.role,
                u.name,
                u.id,
                if u.has_password { "" } else { ", no password" }
            );
        }
        UserCommand::Experience { name, level } => {
            let level: Option<Experience> = match level.as_str() {
                "none" => None,
                l => Some(l.parse()?),
            };
            let u = store.user_by_name(&name).await?;
            store.set_experience(u.id, level).await?;
            println!(
                "{} is {}",
                u.name,
                level.map_or("of no recorded experience", Experience::as_str)
            );
        }
        UserCommand::Open {
            name,
            exercise,
            by,
            reason,
        } => {
            let trainee = store.trainee_named(&name).await?;
            let e = store.exercise_by_name(&exercise).await?;
            let by = store.user_by_name(&by).await?;
            store.open_early(trainee.id, e.id, by.id, &reason).await?;
            println!("{} is open to {} ({reason})", e.name, trainee.name);
        }
        UserCommand::List => {
            for u in store.list_users(None).await? {
                // names from before names were checked may hold control characters
                let name = cutlab_assessor::store::printable(&u.name);
                let level = store.experience(u.id).await?;
                println!(
                    "{:>4}  {:<11} {:<13} {name}",
                    u.id,
                    u.role.as_str(),
                    level.map_or("-", Experience::as_str)
                );
            }
        }
    }
    Ok(())
}

async fn cohort(store: &Store, command: CohortCommand) -> anyhow::Result<()> {
    match command {
        CohortCommand::Add { name, instructor } => {
            let instructor = match instructor {
                Some(n) => Some(store.user_by_name(&n).await?.id),
                None => None,
            };
            let c = store.create_cohort(&name, instructor).await?;
            println!("added cohort {} (id {})", c.name, c.id);
        }
        CohortCommand::Join { cohort, user } => {
            let c = store.cohort_by_name(&cohort).await?;
            let u = store.user_by_name(&user).await?;
            store.join_cohort(c.id, u.id).await?;
            println!("{} is in cohort {}", u.name, c.name);
        }
        CohortCommand::List => {
            for c in store.list_cohorts().await? {
                let members: Vec<String> = store
                    .cohort_members(c.id)
                    .await?
                    .into_iter()
                    .map(|u| u.name)
                    .collect();
                println!("{}: {}", c.name, members.join(", "));
            }
        }
    }
    Ok(())
}

async fn exercise(store: &Store, command: ExerciseCommand) -> anyhow::Result<()> {
    match command {
        ExerciseCommand::Add {
            name,
            scene,
            plan,
            description,
            k,
            exam_only,
        } => {
            let plan = ExercisePlan::load(&plan)?;
            let e = store
                .create_exercise(&NewExercise {
                    name: &name,
                    scene: &scene,
                    description: &description,
                    plan: &plan,
                    thresholds: &[],
                    threshold_k: k,
                    exam_only,
                })
                .await?;
            println!(
                "added exercise {} (id {}, scene {}, {} plan {:.1} mm deep); thresholds come from expert attempts",
                e.name,
                e.id,
                e.scene,
                plan.kind().as_str(),
                plan.kind_plan().depth_m() * 1e3
            );
        }
        ExerciseCommand::List => {
            for e in store.list_exercises().await? {
                let t = store.thresholds(e.id).await?;
                println!(
                    "{:>4}  {:<24} scene {:<12} {} thresholds",
                    e.id,
                    e.name,
                    e.scene,
                    t.metrics.len()
                );
            }
        }
        ExerciseCommand::Show { name, json } => {
            let e = store.exercise_by_name(&name).await?;
            let plan = store.get_plan(e.plan_id).await?;
            print_exercise(&e, &plan, json)?;
        }
        ExerciseCommand::Thresholds { name, json } => {
            let e = store.exercise_by_name(&name).await?;
            let t = store.thresholds_from_experts(e.id).await?;
            if json {
                println!("{}", serde_json::to_string_pretty(&t)?);
            } else {
                print_thresholds(&e, &t);
            }
        }
    }
    Ok(())
}

/// Exercise `e` and its `plan`: a few lines, or (`json`) one object with the plan as a plan
/// file holds it.
fn print_exercise(
    e: &cutlab_assessor::store::Exercise,
    plan: &ExercisePlan,
    json: bool,
) -> anyhow::Result<()> {
    let plan_value: serde_json::Value = serde_json::from_str(&plan.to_json()?)?;
    if json {
        let v = serde_json::json!({
            "id": e.id,
            "name": e.name,
            "scene": e.scene,
            "description": e.description,
            "exam_only": e.exam_only,
            "threshold_k": e.threshold_k,
            "kind": plan.kind().as_str(),
            "plan": plan_value,
        });
        println!("{}", serde_json::to_string_pretty(&v)?);
        return Ok(());
    }
    println!("{} (id {}): {}", e.name, e.id, e.description);
    println!(
        "scene {}, {} plan, {}, thresholds mean +/- {} SD",
        e.scene,
        plan.kind().as_str(),
        if e.exam_only {
            "exam only"
        } else {
            "guided or exam"
        },
        e.threshold_k
    );
    println!("{}", serde_json::to_string_pretty(&plan_value)?);
    Ok(())
}

/// The thresholds `t` of exercise `e` as a table.
fn print_thresholds(e: &cutlab_assessor::store::Exercise, t: &cutlab_scoring::Thresholds) {
    println!(
        "{}: thresholds from expert attempts, mean +/- {} SD",
        e.name, e.threshold_k
    );
    println!(
        "{:<28} {:>12} {:>12} {:>4} {:>12} {:>12}",
        "metric", "mean", "sd", "n", "lower", "upper"
    );
    let limit = |v: Option<f64>| v.map_or_else(|| "-".to_owned(), |v| format!("{v:.4}"));
    for m in &t.metrics {
        println!(
            "{:<28} {:>12.4} {:>12.4} {:>4} {:>12} {:>12}",
            m.key,
            m.mean,
            m.sd,
            m.n_experts,
            limit(m.lower),
            limit(m.upper)
        );
    }
}

/// The report of a scored attempt: every metric with its verdict, the score, pass/fail and
/// proficiency (JSON: the same, with the overall normalised `score`).
pub fn print_outcome(
    o: &cutlab_assessor::store::Outcome,
    values: &[cutlab_scoring::MetricValue],
    json: bool,
) -> anyhow::Result<()> {
    let verdict = |key: &str| o.verdict.metrics.iter().find(|m| m.key == key);
    if json {
        let metrics: Vec<_> = values
            .iter()
            .map(|v| {
                let m = verdict(&v.key);
                serde_json::json!({ "key": v.key, "value": v.value, "unit": v.unit, "missing": v.missing,
                    "thresholded": m.is_some(), "pass": m.map(|m| m.pass), "score": m.map(|m| m.score) })
            })
            .collect();
        let p = &o.proficiency.state;
        let v = serde_json::json!({
            "attempt": o.attempt.id, "score": o.verdict.score, "pass": o.verdict.pass, "note": o.attempt.note, "metrics": metrics,
            "proficiency": { "attempts": p.attempts, "passes": p.passes, "consecutive_passes": p.consecutive_passes, "proficient": p.proficient, "lapsed": o.proficiency.lapsed(), "cusum": o.proficiency.cusum },
        });
        println!("{}", serde_json::to_string_pretty(&v)?);
        return Ok(());
    }
    println!(
        "attempt {}: score {:+.2}, {}",
        o.attempt.id,
        o.verdict.score,
        if o.verdict.pass { "PASS" } else { "FAIL" }
    );
    if let Some(note) = &o.attempt.note {
        println!("  note: {note}");
    }
    println!("  {:<28} {:>12} {:<8} verdict", "metric", "value", "unit");
    for v in values {
        let value = v
            .value
            .map_or_else(|| "-".to_owned(), |x| format!("{x:.4}"));
        let judged = match verdict(&v.key) {
            Some(m) => format!(
                "{} (score {:+.2})",
                if m.pass { "pass" } else { "FAIL" },
                m.score
            ),
            None => v
                .missing
                .clone()
                .map_or_else(String::new, |r| format!("missing: {r}")),
        };
        println!("  {:<28} {:>12} {:<8} {}", v.key, value, v.unit, judged);
    }
    let p = &o.proficiency.state;
    println!(
        "  proficiency: {} attempts, {} passed, {} consecutive; {}; CUSUM {:.2}",
        p.attempts,
        p.passes,
        p.consecutive_passes,
        if p.proficient {
            "proficient"
        } else if o.proficiency.lapsed() {
            "proficiency lapsed (an unacceptable failure rate after it): retrain"
        } else {
            "not yet proficient"
        },
        o.proficiency.cusum
    );
    Ok(())
}
