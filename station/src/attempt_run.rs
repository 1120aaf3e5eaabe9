//! One attempt run, the path `cutlab session`, the station, the demo's seeding and the benches
//! share: the scene built and what the hand follows planned on its tissue ([`Prepared::new`]),
//! the device made for that plan ([`Prepared::device`]), the attempt let in ([`attempt::admit`]:
//! its exercise and plan loaded once, the curriculum's lock checked) and opened in the store
//! ([`OpenAttempt::start`]), the session recorded ([`Prepared::record`]), the attempt scored or
//! marked incomplete ([`OpenAttempt::finish`]) and sent to a hub ([`crate::sync::sync_new`]).
//! [`run_blocking`] strings them together on the caller's thread; the station runs the same
//! stages, the recording on a thread of its own. Printing is the caller's.

use std::net::SocketAddr;
use std::path::{Path, PathBuf};

use cutlab_assessor::recordings::RecordingStore;
use cutlab_assessor::store::Store;
use cutlab_haptics::device::{
    CsvDevice, DeviceSpec, GraspPlan, GrasperHand, HapticDevice, IgtlDevice, IgtlOptions,
    PointerHand, Skill, StylusHand, SyntheticTrainee,
};
use cutlab_haptics::plan::Plan;
use cutlab_haptics::servo::Clock;
use cutlab_haptics::tap::TapSettings;
use cutlab_haptics::{Hands, Session, SessionConfig, StepChoice, TimeStep};
use cutlab_recorder::record::{self, Provenance, RecordSettings, RecordedSession};
use cutlab_recorder::writer::RecordObserver;
use cutlab_recorder::{RecordedHand, Recording, RerunSink, RerunTarget, WriterOptions};
use cutlab_scoring::ExercisePlan;
use cutlab_sim::scene::{BuildOptions, Scene};

use crate::StationError;
use crate::attempt::{self, Admitted, AttemptLock, Finished};
use crate::sync::{Hub, SyncReport};

/// How an attempt's session runs, whoever starts it.
#[derive(Debug, Clone)]
pub struct RunSettings {
    /// The scene's resolution when it is generated: at least this many tetrahedra (`None`:
    /// the scene's own).
    pub min_tets: Option<usize>,
    /// The simulation step (the scene's, a fixed one, or the smallest that keeps real time
    /// here, measured when the run is prepared).
    pub time_step: TimeStep,
    /// The live clock for a person; the virtual clock for tests, benchmarks and the demo.
    pub clock: Clock,
    /// The longest session, s.
    pub duration_s: f64,
    /// Whether the servo thread asks for real-time priority (live clock only).
    pub realtime_priority: bool,
    /// A keyframe every this many seconds (a replay resumes at each).
    pub keyframe_every_s: f64,
    /// The recorded surface at least this often, Hz (0: never).
    pub surface_hz: f64,
    /// The seed of a synthetic trainee's or a scripted hand's variation.
    pub seed: u64,
    /// How an OpenIGTLink device sends the force back.
    pub igtl: IgtlOptions,
    /// The second hand: a synthetic grasper holding the tissue as this plans (`None`: one
    /// hand).
    pub grasp: Option<GraspPlan>,
    /// A synthetic trainee uses both hands: its other hand's grasper gives countertraction
    /// beside the incision as its skill does ([`cutlab_haptics::device::Traction`]).
    pub second_hand: bool,
}

impl Default for RunSettings {
    fn default() -> Self {
        Self {
            min_tets: None,
            time_step: TimeStep::Scene,
            clock: Clock::Live,
            duration_s: 60.0,
            realtime_priority: true,
            keyframe_every_s: 1.0,
            surface_hz: 0.0,
            seed: 0,
            igtl: IgtlOptions::default(),
            grasp: None,
            second_hand: false,
        }
    }
}

impl RunSettings {
    /// Whether the settings make a session: a duration of at most a day, a positive keyframe
    /// interval, a surface rate that is not negative.
    pub fn check(&self) -> Result<(), StationError> {
        let bad = |what: String| Err(StationError::Settings(what));
        if !(self.duration_s > 0.0 && self.duration_s <= 86_400.0) {
            return bad(format!(
                "the duration must be between 0 and 86400 seconds, got {}",
                self.duration_s
            ));
        }
        if !(self.keyframe_every_s > 0.0 && self.keyframe_every_s.is_finite()) {
            return bad(format!(
                "the keyframe interval must be positive, got {} s",
                self.keyframe_every_s
            ));
        }
        if !(self.surface_hz >= 0.0 && self.surface_hz.is_finite()) {
            return bad(format!(
                "the surface rate must not be negative, got {} Hz",
                self.surface_hz
            ));
        }
        Ok(())
    }

    /// The recording's settings at the simulation step `time_step_s`: a keyframe every
    /// `keyframe_every_s` (to the nearest step), the surface at least `surface_hz` often.
    pub fn record_settings(&self, time_step_s: f64) -> RecordSettings {
        RecordSettings {
            tap: TapSettings {
                keyframe_every_steps: self.keyframe_every_steps(time_step_s),
                surface_every_steps: surface_every_steps(self.surface_hz, time_step_s),
                ..TapSettings::default()
            },
            writer: WriterOptions::default(),
        }
    }

    fn keyframe_every_steps(&self, time_step_s: f64) -> u64 {
        ((self.keyframe_every_s / time_step_s).round() as u64).max(1)
    }
}

/// The surface recorded every this many steps of `time_step_s`, so at least `hz` often
/// (0: never). A ratio within 1e-9 of a whole number is that number (10 Hz at 1 ms: every
/// 100th step).
fn surface_every_steps(hz: f64, time_step_s: f64) -> u64 {
    if hz > 0.0 {
        ((1.0 / (hz * time_step_s) * (1.0 + 1e-9)).floor() as u64).max(1)
    } else {
        0
    }
}

/// What the hand follows, planned on the tissue once the scene is built.
#[derive(Debug, Clone, Copy)]
pub enum PlanSource<'a> {
    /// An exercise's expert plan, projected onto the tissue.
    Exercise(&'a ExercisePlan),
    /// 60 mm across the tissue's top in the scene's `incision` directions, at most 8 mm deep.
    AcrossScene,
}

/// A session ready to run: its scene built and settled, its step chosen, what the hand
/// follows planned on its tissue, and how it runs and is recorded.
pub struct Prepared {
    pub scene: Scene,
    /// The scene as given (a built-in name or a file), as a replay loads it again.
    pub scene_arg: String,
    pub session: Session,
    /// What choosing the step measured (`TimeStep::Auto`).
    pub step_choice: Option<StepChoice>,
    /// What the hand follows, or why nothing can be planned on this tissue (a device that
    /// follows no plan runs all the same).
    plan: Result<Plan, String>,
    /// The lines marked on the tissue (the exercise's), laid on it.
    pub marks: Vec<Vec<cutlab_sim::Point3>>,
    /// The exercise's plan, where a synthetic trainee chooses its own incision from it.
    chooses_from: Option<ExercisePlan>,
    pub config: SessionConfig,
    pub settings: RunSettings,
}

impl std::fmt::Debug for Prepared {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Prepared")
            .field("scene", &self.scene.spec.name)
            .field("plan", &self.plan)
            .finish_non_exhaustive()
    }
}

impl Prepared {
    /// Builds `scene` (a built-in name or a file) and settles it; plans what the hand follows
    /// from `plan`. An exercise's plan that does not fit the tissue is an error; the scene's own
    /// incision that does not is kept as the reason (see [`Self::plan`]). Takes a while: call
    /// it off async threads.
    pub fn new(
        scene: &str,
        settings: &RunSettings,
        plan: PlanSource<'_>,
    ) -> Result<Self, StationError> {
        settings.check()?;
        let min_tets = settings.min_tets;
        let built = Scene::load(scene, BuildOptions { min_tets })?;
        let (built, session, step_choice) = Session::at_time_step(built, settings.time_step)?;
        let chooses_from = match plan {
            PlanSource::Exercise(p) if p.kind_plan().trainee_places_incision() => Some(p.clone()),
            _ => None,
        };
        let (plan, marks) = match plan {
            PlanSource::Exercise(p) => (
                Ok(attempt::plan_on_tissue(&session, p)?),
                attempt::marks_on_tissue(&session, p)?,
            ),
            PlanSource::AcrossScene => (across(&built, &session), Vec::new()),
        };
        let time_step_s = session.sim.settings.time_step_s;
        let mut config = SessionConfig {
            clock: settings.clock,
            duration_s: settings.duration_s,
            realtime_priority: settings.realtime_priority,
            // the surface BVH is built again at every keyframe, so a replay can resume at each
            collider_rebuild_every_steps: settings.keyframe_every_steps(time_step_s),
            ..SessionConfig::default()
        };
        config.render = config.render.with_scene_cut(&built.spec);
        config.blade_length_m = built.spec.blade_length_mm * 1e-3;
        Ok(Self {
            scene: built,
            scene_arg: scene.to_owned(),
            session,
            step_choice,
            plan,
            marks,
            chooses_from,
            config,
            settings: settings.clone(),
        })
    }

    /// What the hand follows.
    pub fn plan(&self) -> Result<&Plan, StationError> {
        self.plan
            .as_ref()
            .map_err(|why| StationError::Plan(why.clone()))
    }

    /// The simulation step, s.
    pub fn time_step_s(&self) -> f64 {
        self.session.sim.settings.time_step_s
    }

    /// The device `spec` names: one that follows the plan is made for it (with the run's
    /// seed; a synthetic trainee places its own incision where the exercise leaves that to
    /// the trainee); a file, a recording or a port is opened ([`open_device`]: an
    /// OpenIGTLink port brings the second tool it names).
    pub fn device(&self, spec: &DeviceSpec) -> Result<Hands, StationError> {
        let seed = self.settings.seed;
        if self.settings.second_hand && !matches!(spec, DeviceSpec::Trainee { .. }) {
            return Err(StationError::Settings(format!(
                "a second hand of its own is a synthetic trainee's (expert, intermediate, \
                 novice, level:L), not {spec}'s"
            )));
        }
        let device: Box<dyn HapticDevice> = match spec {
            DeviceSpec::Trainee { name, skill } => {
                let chosen = match &self.chooses_from {
                    Some(p) => {
                        attempt::chosen_plan_on_tissue(&self.session, p, &skill.planning, seed)?
                    }
                    None => None,
                };
                let plan = match chosen {
                    Some(plan) => plan,
                    None => self.plan()?.clone(),
                };
                let grasper = self.trainees_other_hand(&plan, skill)?;
                let scalpel = SyntheticTrainee::new(name, plan, *skill, seed)?
                    .expecting_cut_of(&self.config.render);
                return Ok(Hands {
                    scalpel: Box::new(scalpel),
                    grasper,
                });
            }
            DeviceSpec::PointerHand(kind) => Box::new(PointerHand::new(*kind, self.plan()?, seed)?),
            DeviceSpec::StylusHand(kind) => Box::new(StylusHand::new(*kind, self.plan()?, seed)?),
            DeviceSpec::Csv(_) | DeviceSpec::Recording(_) | DeviceSpec::Igtl(_) => {
                return open_device(spec, &self.settings.igtl)?
                    .ok_or_else(|| StationError::NoSuchDevice(format!("{spec} follows no plan")));
            }
        };
        Ok(device.into())
    }

    /// A synthetic trainee's other hand, when the settings ask for both: a grasper giving
    /// its `skill`'s countertraction beside `plan`'s incision.
    fn trainees_other_hand(
        &self,
        plan: &Plan,
        skill: &Skill,
    ) -> Result<Option<Box<dyn HapticDevice>>, StationError> {
        if !self.settings.second_hand {
            return Ok(None);
        }
        let length_m: f64 = plan.line_m.windows(2).map(|w| (w[1] - w[0]).norm()).sum();
        let stroke_s = length_m / skill.cut_speed_m_per_s.max(1e-6);
        let seed = self.settings.seed;
        let hand = GraspPlan::countertraction(plan, &skill.traction, stroke_s, seed)
            .and_then(|grasp| GrasperHand::new(grasp, seed))
            .map_err(|e| StationError::Settings(format!("the trainee's other hand: {e}")))?;
        Ok(Some(Box::new(hand)))
    }

    /// Who did what, as the recording says it (a replay builds the same scene from it).
    pub fn provenance(&self, trainee: &str, exercise: &str, device: &str) -> Provenance {
        Provenance {
            scene: self.scene_arg.clone(),
            min_tets: self.settings.min_tets,
            seed: self.settings.seed,
            trainee: trainee.to_owned(),
            exercise: exercise.to_owned(),
            device: device.to_owned(),
        }
    }

    /// A rerun log of the session at `target`, with the plan logged and the view framed on it.
    pub fn rerun_sink(&self, target: &RerunTarget) -> Result<RerunSink, StationError> {
        RerunSink::of_session(
            target,
            self.config.period_nanos,
            self.config.blade_length_m,
            self.plan.as_ref().ok(),
        )
        .map_err(|e| StationError::Settings(format!("starting the rerun log: {e}")))
    }

    /// Runs the session with `hands` (a grasper the settings plan when they bring none),
    /// recorded to `mcap` (and to `observer`).
    pub fn record(
        self,
        hands: impl Into<Hands>,
        provenance: &Provenance,
        mcap: &Path,
        observer: Option<Box<dyn RecordObserver>>,
    ) -> Result<RecordedSession, StationError> {
        let settings = self.settings.record_settings(self.time_step_s());
        let Hands { scalpel, grasper } = hands.into();
        let grasper = match (grasper, self.settings.grasp) {
            (Some(hand), _) => Some(hand),
            (None, Some(plan)) => {
                let hand = GrasperHand::new(plan, self.settings.seed)
                    .map_err(|e| StationError::Settings(format!("the grasper: {e}")))?;
                Some(Box::new(hand) as Box<dyn HapticDevice>)
            }
            (None, None) => None,
        };
        Ok(record::run_recorded(
            self.session,
            Hands { scalpel, grasper },
            &self.config,
            provenance,
            self.plan.as_ref().ok(),
            &self.scene.spec,
            mcap,
            settings,
            observer,
        )?)
    }
}

/// 60 mm across the tissue's top in the scene's `incision` directions, at most 8 mm deep.
fn across(scene: &Scene, session: &Session) -> Result<Plan, String> {
    // the scene's incision directions were checked when it was built
    let (up, along) = scene.spec.incision.unit().map_err(|e| e.to_string())?;
    let (lo, hi) = scene.model.mesh.bounding_box();
    let depth_m = (0.4 * (hi - lo).dot(&up.abs())).min(0.008);
    session
        .plan_across(&up, &along, 0.06, depth_m)
        .map_err(|e| format!("planning the incision across the tissue: {e}"))
}

/// The device `spec` names when it needs no plan (a trajectory file, a recorded hand, an
/// OpenIGTLink port), opened now so that a bad file or a busy port is said before the scene
/// is built; `None` for a device that follows the plan.
pub fn open_device(spec: &DeviceSpec, igtl: &IgtlOptions) -> Result<Option<Hands>, StationError> {
    let device: Box<dyn HapticDevice> = match spec {
        DeviceSpec::Trainee { .. } | DeviceSpec::PointerHand(_) | DeviceSpec::StylusHand(_) => {
            return Ok(None);
        }
        DeviceSpec::Csv(path) => Box::new(CsvDevice::open(path)?),
        DeviceSpec::Recording(path) => {
            let recording = Recording::open(path).map_err(|e| {
                StationError::Settings(format!("reading the recording {}: {e}", path.display()))
            })?;
            Box::new(RecordedHand::new(&recording)?)
        }
        DeviceSpec::Igtl(port) => {
            let mut d =
                IgtlDevice::listen_with(SocketAddr::from(([0, 0, 0, 0], *port)), igtl.clone())?;
            tracing::info!(
                "OpenIGTLink device listening on {} (TRANSFORM in, mm; force out as {:?} {:?}, N)",
                d.address(),
                igtl.force_output,
                igtl.force_device_name
            );
            let grasper = d
                .take_grasper()
                .map(|g| Box::new(g) as Box<dyn HapticDevice>);
            return Ok(Some(Hands {
                scalpel: Box::new(d),
                grasper,
            }));
        }
    };
    Ok(Some(device.into()))
}

/// Whose attempt a run is, at which exercise.
#[derive(Debug, Clone)]
pub struct AttemptSpec {
    pub exercise: String,
    pub trainee: String,
    /// An expert's reference attempt (its metrics set the exercise's thresholds).
    pub expert: bool,
    /// Guided or exam, when the run says (the station's).
    pub mode: Option<String>,
    /// The device as its user named it.
    pub device: String,
}

impl AttemptSpec {
    /// Lets the attempt in ([`attempt::admit`]): its exercise and plan, or why not.
    pub async fn admit(&self, store: &Store) -> Result<Admitted, StationError> {
        attempt::admit(store, &self.exercise, &self.trainee, self.expert).await
    }
}

/// An attempt in the store while its session runs, its lock held (no sweep takes it for a
/// dead station's).
#[derive(Debug)]
pub struct OpenAttempt {
    pub id: i64,
    lock: AttemptLock,
    plan: ExercisePlan,
}

impl OpenAttempt {
    /// Starts `who`'s attempt, let in as `admitted`, recorded at `mcap`.
    pub async fn start(
        store: &Store,
        who: &AttemptSpec,
        admitted: &Admitted,
        mcap: &Path,
    ) -> Result<Self, StationError> {
        // held until the attempt has ended
        let lock = AttemptLock::hold(mcap)?;
        let recording = mcap.display().to_string();
        let id = store
            .start_attempt(
                admitted.trainee_id(),
                admitted.exercise().id,
                Some(&recording),
                who.expert,
            )
            .await?
            .id;
        store
            .set_attempt_setup(id, who.mode.as_deref(), &who.device)
            .await?;
        Ok(Self {
            id,
            lock,
            plan: admitted.plan().clone(),
        })
    }

    /// Scores the attempt from the recording at `outcome`'s path, or marks it incomplete with
    /// `outcome`'s reason; keeps its recordings in `recordings`; lets go of the lock.
    pub async fn finish(
        self,
        store: &Store,
        outcome: Result<&Path, String>,
        recordings: Option<&RecordingStore>,
    ) -> Result<Finished, StationError> {
        let finished =
            attempt::finish_attempt(store, self.id, outcome, recordings, Some(&self.plan)).await;
        drop(self.lock);
        finished
    }
}

/// How a recorded session ended, for its attempt: the recording to score, or why not.
pub fn outcome_of(recorded: &Result<RecordedSession, StationError>) -> Result<&Path, String> {
    match recorded {
        Ok(r) => match &r.report {
            Ok(_) => Ok(r.path.as_path()),
            Err(e) => Err(format!("the session failed: {e}")),
        },
        Err(e) => Err(format!("recording failed: {e}")),
    }
}

/// The store an attempt run keeps its attempt in, and where its recordings and the attempt go
/// once it ends.
#[derive(Debug)]
pub struct AttemptStore<'a> {
    pub store: &'a Store,
    pub recordings: Option<&'a RecordingStore>,
    pub hub: Option<&'a Hub>,
}

/// What [`run_blocking`] did.
#[derive(Debug)]
pub struct RunResult {
    /// The recorded session, or why it could not be recorded.
    pub recorded: Result<RecordedSession, StationError>,
    /// The attempt's id and how it ended (an attempt run).
    pub attempt: Option<(i64, Result<Finished, StationError>)>,
    /// What was sent to the hub, or why nothing was.
    pub sync: Option<Result<SyncReport, String>>,
    /// Whether the observer (a rerun log) was finished, before the attempt was scored.
    pub observer: Result<(), String>,
}

/// One attempt run on this thread (`rt` runs the store's steps): `prepared` recorded to
/// `mcap` with `device` and `observer`; as `who`'s attempt in `store` when given (let in as
/// the [`Admitted`]), scored when it ends and sent to the hub. An attempt that cannot be
/// opened is the error; everything after it is in the result (the attempt is ended whatever
/// happens to its session).
pub fn run_blocking(
    rt: &tokio::runtime::Runtime,
    prepared: Prepared,
    hands: impl Into<Hands>,
    who: Option<(&AttemptStore<'_>, &AttemptSpec, &Admitted)>,
    mcap: &Path,
    observer: Option<Box<dyn RecordObserver>>,
) -> Result<RunResult, StationError> {
    let (trainee, exercise) = who.map_or(("", ""), |(_, w, _)| (&*w.trainee, &*w.exercise));
    let hands = hands.into();
    let provenance = prepared.provenance(trainee, exercise, hands.scalpel.name());
    let open = match who {
        Some((at, w, admitted)) => {
            Some(rt.block_on(OpenAttempt::start(at.store, w, admitted, mcap))?)
        }
        None => None,
    };
    let mut recorded = prepared.record(hands, &provenance, mcap, observer);
    let observer = finish_observer(&mut recorded);
    let (Some(open), Some((at, _, _))) = (open, who) else {
        return Ok(RunResult {
            recorded,
            attempt: None,
            sync: None,
            observer,
        });
    };
    let id = open.id;
    let outcome = outcome_of(&recorded);
    let (finished, sync) = rt.block_on(async {
        let finished = open.finish(at.store, outcome, at.recordings).await;
        let sync = match at.hub {
            // a hub that is down leaves the attempt queued, not the run failed
            Some(hub) => Some(
                crate::sync::sync_new(at.store, hub, at.recordings)
                    .await
                    .map_err(|e| e.to_string()),
            ),
            None => None,
        };
        (finished, sync)
    });
    Ok(RunResult {
        recorded,
        attempt: Some((id, finished)),
        sync,
        observer,
    })
}

/// Finishes the recorded session's observer (flushes a rerun log, ends a view).
pub fn finish_observer(recorded: &mut Result<RecordedSession, StationError>) -> Result<(), String> {
    match recorded.as_mut().ok().and_then(|r| r.observer.take()) {
        Some(o) => o
            .finish()
            .map_err(|e| format!("finishing the view and rerun log: {e}")),
        None => Ok(()),
    }
}

/// The recording's path in `dir` (`session.mcap`), the folder made if need be.
pub fn session_mcap(dir: &Path) -> Result<PathBuf, StationError> {
    std::fs::create_dir_all(dir).map_err(|source| StationError::Io {
        what: format!("creating {}", dir.display()),
        source,
    })?;
    Ok(dir.join("session.mcap"))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_surface_is_recorded_at_least_as_often_as_asked() {
        // 60 Hz at 1 ms: every 16th step (62.5 Hz), not the nearest (17th, 58.8 Hz)
        assert_eq!(surface_every_steps(60.0, 0.001), 16);
        // a whole ratio stays whole despite rounding: 10 Hz at 1 ms, 30 Hz at 1/300 s
        assert_eq!(surface_every_steps(10.0, 0.001), 100);
        assert_eq!(surface_every_steps(30.0, 1.0 / 300.0), 10);
        assert_eq!(surface_every_steps(0.0, 0.001), 0);
        // faster than the step: every step
        assert_eq!(surface_every_steps(5000.0, 0.001), 1);
    }

    #[test]
    fn settings_that_make_no_session_are_refused() {
        let ok = RunSettings::default();
        assert!(ok.check().is_ok());
        for bad in [
            RunSettings {
                duration_s: 0.0,
                ..ok.clone()
            },
            RunSettings {
                duration_s: f64::NAN,
                ..ok.clone()
            },
            RunSettings {
                keyframe_every_s: 0.0,
                ..ok.clone()
            },
            RunSettings {
                surface_hz: -1.0,
                ..ok.clone()
            },
        ] {
            assert!(
                matches!(bad.check(), Err(StationError::Settings(_))),
                "{bad:?}"
            );
        }
    }
}
