//! The demo's training history, simulated: a curriculum of two exercises on the chest wall,
//! expert attempts that set their thresholds (a steady person's hand model on a stylus and at
//! the station's pointer, one device class's each), and two
//! trainees whose scripted attempts improve from novice towards expert. Every attempt is a
//! real session (synthetic trainee or hand model, 1 kHz servo loop on the virtual clock, cutting simulation, recording), scored from its recording and
//! stored, so instructors can replay each one in the dashboard.

use std::path::{Path, PathBuf};

use anyhow::Context;
use cutlab_assessor::AssessError;
use cutlab_assessor::store::{BUILTIN_EXERCISE, BUILTIN_SCENE, DbLocation, NewExercise, Store};
use cutlab_dashboard::seed_demo_accounts;
use cutlab_haptics::device::HandKind;
use cutlab_haptics::servo::Clock;
use cutlab_recorder::RerunTarget;
use cutlab_scoring::proficiency::DEFAULT_K;
use cutlab_scoring::{ExercisePlan, IncisionPlan, ScoreError};

use crate::localise_choice::Localise;
use crate::session::{self, AttemptArgs, DeviceArg};
use cutlab_station::attempt_run::RunSettings;

/// The demo's curriculum (created last: its presence means the history is complete).
pub const DEMO_CURRICULUM: &str = "demo-curriculum";
/// The second exercise: a shorter, shallower incision along the wall's axis.
pub const AXIAL_EXERCISE: &str = "chest-wall-axial-incision";
/// Resolution of the attempts' chest wall (the sessions of a novice take 20 s of wall time).
const MIN_TETS: usize = 3000;
/// Expert attempts per exercise with a stylus (a steady person's hand model), which set the
/// stylus class's thresholds.
const EXPERTS: u64 = 6;
/// Expert attempts per exercise with the station's pointer (a steady person's hand model),
/// which set the pointer's thresholds.
const POINTER_EXPERTS: u64 = 4;

/// One scripted attempt.
#[derive(Debug, Clone)]
struct Attempt {
    exercise: &'static str,
    trainee: &'static str,
    /// Skill from 0 (novice) to 1 (expert).
    level: f64,
    seed: u64,
    expert: bool,
    /// A person's hand model (on the station's pointer or a stylus) instead of a synthetic
    /// trainee at `level`.
    hand: Option<DeviceArg>,
}

impl Attempt {
    /// Simulated seconds: the novice needs about 12 s for the 60 mm incision, the expert 4 s;
    /// a person at the pointer about 10 s, and the session ends when the hand is done.
    fn duration_s(&self) -> f64 {
        match self.hand {
            Some(_) => 20.0,
            None => 15.0 - 9.0 * self.level,
        }
    }
}

/// The axial exercise's plan: 40 mm along the top of the wall (y, 5 mm off the middle), 5 mm
/// deep, with the built-in plan's viewpoint and tolerances, and as target what it lays open
/// (as many points as the built-in plan's, half its depth below its middle third).
pub fn axial_plan() -> Result<IncisionPlan, ScoreError> {
    let base = IncisionPlan::chest_wall()?;
    let targets = base.target_m.len();
    // on the curved surface z = sqrt(R^2 - x^2) - R, R = 150 mm
    let (x, r) = (0.005f64, 0.15f64);
    let z = (r * r - x * x).sqrt() - r;
    let (entry_m, exit_m) = ([x, -0.02, z], [x, 0.02, z]);
    let mut plan = IncisionPlan {
        name: "chest-wall axial incision".into(),
        entry_m,
        exit_m,
        incision_m: vec![entry_m, exit_m],
        depth_m: 0.005,
        ..base
    };
    plan.target_m = plan.mid_depth_targets(targets);
    plan.normalised()
}

/// Seeds the demo's history into the database `db` (recordings under `dir`) unless
/// [`DEMO_CURRICULUM`] exists already; returns whether it seeded. The accounts and cohort are
/// made sure of either way.
pub fn run(db: &DbLocation, dir: &Path) -> anyhow::Result<bool> {
    let rt = tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
        .context("starting the async runtime")?;
    let open = || async {
        Store::open(db)
            .await
            .with_context(|| format!("opening the database {db}"))
    };
    let done = rt.block_on(async {
        let store = open().await?;
        seed_demo_accounts(&store).await?;
        let done = store.curriculum_by_name(DEMO_CURRICULUM).await.is_ok();
        if !done {
            ensure_axial_exercise(&store).await?;
        }
        store.close().await;
        anyhow::Ok(done)
    })?;
    if done {
        return Ok(false);
    }
    let exercises = [BUILTIN_EXERCISE, AXIAL_EXERCISE];
    println!(
        "simulating the demo's attempts ({MIN_TETS} tets, virtual clock; recordings in {}):",
        dir.display()
    );
    let experts: Vec<Attempt> = exercises
        .iter()
        .flat_map(|&exercise| {
            let expert = move |seed: u64, hand: DeviceArg| Attempt {
                exercise,
                trainee: "dr-kim",
                level: 1.0,
                seed,
                expert: true,
                hand: Some(hand),
            };
            let stylus = (1..=EXPERTS)
                .map(move |k| expert(100 + k, DeviceArg::StylusHand(HandKind::Steady)));
            let pointer = (1..=POINTER_EXPERTS)
                .map(move |k| expert(150 + k, DeviceArg::PointerHand(HandKind::Steady)));
            stylus.chain(pointer)
        })
        .collect();
    run_lanes(
        db,
        dir,
        "expert reference attempts",
        &[
            experts.iter().step_by(2).cloned().collect(),
            experts.iter().skip(1).step_by(2).cloned().collect(),
        ],
    )?;
    rt.block_on(async {
        let store = open().await?;
        for name in exercises {
            let e = store.exercise_by_name(name).await?;
            let t = store
                .thresholds_from_experts(e.id)
                .await
                .with_context(|| format!("thresholds of {name} from its expert attempts"))?;
            println!(
                "  {name}: thresholds of {} metrics from {EXPERTS} expert attempts with a \
                 stylus and {POINTER_EXPERTS} at the pointer, and for each device class",
                t.metrics.len()
            );
        }
        store.close().await;
        anyhow::Ok(())
    })?;
    // ana improves from novice to expert level (proficient at her last attempts) and becomes
    // proficient at the second exercise; ben is still learning
    let ana = [0.1, 0.35, 0.6, 0.8, 0.95, 1.0, 1.0]
        .iter()
        .map(|&level| (BUILTIN_EXERCISE, level))
        .chain([0.8, 1.0, 1.0].map(|l| (AXIAL_EXERCISE, l)));
    let ana: Vec<Attempt> = ana
        .enumerate()
        .map(|(k, (exercise, level))| Attempt {
            exercise,
            trainee: "ana",
            level,
            seed: 200 + k as u64,
            expert: false,
            hand: None,
        })
        .collect();
    let ben: Vec<Attempt> = [0.0, 0.15, 0.3, 0.45]
        .iter()
        .enumerate()
        .map(|(k, &level)| Attempt {
            exercise: BUILTIN_EXERCISE,
            trainee: "ben",
            level,
            seed: 300 + k as u64,
            expert: false,
            hand: None,
        })
        .collect();
    run_lanes(db, dir, "trainee attempts", &[ana, ben])?;
    rt.block_on(async {
        let store = open().await?;
        let c = store
            .create_curriculum(
                DEMO_CURRICULUM,
                "Open incisions on the chest wall: a transverse incision, then a shorter axial one",
            )
            .await?;
        for (name, exercise) in [
            ("Transverse incision", BUILTIN_EXERCISE),
            ("Axial incision", AXIAL_EXERCISE),
        ] {
            let e = store.exercise_by_name(exercise).await?;
            store.add_module(c.id, name, &[e.id]).await?;
        }
        for trainee in ["ana", "ben"] {
            let u = store.user_by_name(trainee).await?;
            for name in exercises {
                let e = store.exercise_by_name(name).await?;
                let scores: Vec<String> = store
                    .list_attempts(Some(u.id), Some(e.id))
                    .await?
                    .iter()
                    .filter_map(|a| a.score)
                    .map(|s| format!("{s:+.2}"))
                    .collect();
                if !scores.is_empty() {
                    let p = store.proficiency(u.id, e.id).await?;
                    println!(
                        "  {trainee} at {name}: scores {}; {}",
                        scores.join(" "),
                        if p.state.proficient {
                            "proficient"
                        } else if p.lapsed() {
                            "proficiency lapsed"
                        } else {
                            "not yet proficient"
                        }
                    );
                }
            }
        }
        store.close().await;
        anyhow::Ok(())
    })?;
    Ok(true)
}

/// The axial exercise, created when missing.
async fn ensure_axial_exercise(store: &Store) -> anyhow::Result<()> {
    match store.exercise_by_name(AXIAL_EXERCISE).await {
        Ok(_) => Ok(()),
        Err(AssessError::NotFound(_)) => {
            let plan = ExercisePlan::from(axial_plan()?);
            let new = NewExercise {
                name: AXIAL_EXERCISE,
                scene: BUILTIN_SCENE,
                description: "A 40 mm incision 5 mm deep along y, 5 mm off the middle of the chest wall",
                plan: &plan,
                thresholds: &plan.kind_plan().default_thresholds(),
                threshold_k: DEFAULT_K,
                exam_only: false,
            };
            match store.create_exercise(&new).await {
                Ok(_) | Err(AssessError::Conflict(_)) => Ok(()),
                Err(e) => Err(e.into()),
            }
        }
        Err(e) => Err(e.into()),
    }
}

/// Runs each lane's attempts in order, the lanes side by side (one per core).
fn run_lanes(
    db: &DbLocation,
    dir: &Path,
    what: &str,
    lanes: &[Vec<Attempt>],
) -> anyhow::Result<()> {
    let total: usize = lanes.iter().map(Vec::len).sum();
    let bar = cutlab_bench::progress::bar(total as u64, false);
    bar.set_message(what.to_owned());
    std::thread::scope(|scope| {
        let handles: Vec<_> = lanes
            .iter()
            .map(|lane| {
                let bar = bar.clone();
                scope.spawn(move || {
                    for a in lane {
                        simulate(db, dir, a).with_context(|| {
                            format!(
                                "{}'s attempt at {} (seed {})",
                                a.trainee, a.exercise, a.seed
                            )
                        })?;
                        bar.inc(1);
                    }
                    anyhow::Ok(())
                })
            })
            .collect();
        handles.into_iter().try_for_each(|h| {
            h.join()
                .map_err(|_| anyhow::anyhow!("a session thread panicked"))?
        })
    })?;
    bar.finish_and_clear();
    println!("  {total} {what} simulated, scored and stored");
    Ok(())
}

/// One attempt: a recorded session of a synthetic trainee at the attempt's level (or a
/// person's hand model), scored.
fn simulate(db: &DbLocation, dir: &Path, a: &Attempt) -> anyhow::Result<()> {
    let out: PathBuf = dir
        .join(a.exercise)
        .join(format!("{}-{}", a.trainee, a.seed));
    let device = match &a.hand {
        Some(hand) => hand.clone(),
        None => DeviceArg::Trainee {
            name: format!("level:{}", a.level),
            skill: cutlab_haptics::device::Skill::at_level(a.level).context("skill level")?,
        },
    };
    let o = session::Options {
        scene: Some(BUILTIN_SCENE.into()),
        device,
        run: RunSettings {
            min_tets: Some(MIN_TETS),
            clock: Clock::Virtual,
            duration_s: a.duration_s(),
            realtime_priority: false,
            keyframe_every_s: 1.0,
            surface_hz: 10.0,
            seed: a.seed,
            ..RunSettings::default()
        },
        out,
        // the dashboard's replay review opens the .rrd in the rerun viewer
        rerun: Some(RerunTarget::File(PathBuf::from("session.rrd"))),
        attempt: Some(AttemptArgs {
            db: db.clone(),
            recordings: None,
            hub: None,
            exercise: a.exercise.into(),
            trainee: a.trainee.into(),
            expert: a.expert,
        }),
        localise: Localise::Off,
    };
    let run = session::run_session(&o, None)?;
    if let Some((id, Err(e))) = &run.result.attempt {
        anyhow::bail!("finishing attempt {id}: {e}");
    }
    run.result.observer.map_err(anyhow::Error::msg)?;
    match run.result.recorded {
        Ok(r) => r.report.map(|_| ()).context("running the session"),
        Err(e) => Err(anyhow::Error::new(e).context("recording the session")),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_axial_plan_is_valid_and_shorter_than_the_transverse_one() {
        let (axial, transverse) = (
            axial_plan().expect("axial plan"),
            IncisionPlan::chest_wall().expect("built-in plan"),
        );
        assert!(
            (axial.length_m() - 0.04).abs() < 1e-12 && axial.length_m() < transverse.length_m()
        );
        assert_eq!(axial.viewpoint_m, transverse.viewpoint_m);
        // its own target: along its line, within its depth
        assert_eq!(axial.target_m.len(), transverse.target_m.len());
        for t in &axial.target_m {
            let below = cutlab_scoring::metrics::incision::depth_below_plan(&axial, *t);
            assert!(
                (t[0] - 0.005).abs() < 1e-12 && below > 0.0 && below <= axial.depth_m,
                "{t:?}: {below}"
            );
        }
    }
}
