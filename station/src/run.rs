//! Running a station session: an ordinary recorded [`Session`] of an exercise, driven by the
//! station's device and published to its viewers, whose attempt is scored the moment it ends
//! (through [`crate::attempt`], the path `cutlab session --trainee` takes).
//!
//! The session ends at the exercise's time limit, when the trainee presses Stop, or when the
//! page goes away (a lost device: the recording is completed and the attempt marked
//! incomplete). The session runs on threads of its own (servo, simulation, recorder); the
//! async side only starts it and waits for its end.

use std::path::PathBuf;
use std::sync::Arc;
use std::sync::OnceLock;
use std::sync::atomic::{AtomicBool, AtomicU64, AtomicUsize, Ordering};
use std::time::{Duration, Instant};

use cutlab_assessor::recordings::RecordingStore;
use cutlab_assessor::store::{Exercise, Store};
use cutlab_haptics::device::{
    DeviceFault, DeviceLimits, DeviceSpec, HapticDevice, IgtlOptions, PointerDevice, PointerFeed,
    PointerOptions,
};
use cutlab_haptics::plan::Plan;
use cutlab_haptics::servo::{Clock, PeriodStats};
use cutlab_haptics::{Hands, TimeStep, ToolPose, Vector3};
use cutlab_recorder::RerunTarget;
use cutlab_recorder::record::Provenance;
use cutlab_recorder::writer::RecordObserver;
use cutlab_scoring::{DeviceClass, ExercisePlan};
use cutlab_sim::scene::Viewpoint;
use tokio::sync::watch;

use crate::StationError;
use crate::attempt::Finished;
use crate::attempt_run::{self, AttemptSpec, OpenAttempt, PlanSource, Prepared, RunSettings};
use crate::view::{EchoSource, ViewFeed, ViewPublisher};

/// How a station runs its sessions.
#[derive(Debug, Clone)]
pub struct StationSettings {
    /// Each session's recordings go to a folder of their own in here.
    pub recordings_dir: PathBuf,
    /// The longest session (the exercise's time limit), s.
    pub duration_s: f64,
    /// Frames the viewers get per second at least (the recording's surface rate too), Hz.
    pub view_hz: f64,
    /// The scene's resolution when it is generated: at least this many tetrahedra (`None`:
    /// the scene's own).
    pub min_tets: Option<usize>,
    /// The simulation step (the scene's, a fixed one, or the smallest that keeps real time
    /// here, measured at each session's start).
    pub time_step: TimeStep,
    /// A keyframe every this many seconds (a replay resumes at each).
    pub keyframe_every_s: f64,
    /// The live clock for a person; the virtual clock for tests and benchmarks.
    pub clock: Clock,
    /// Also write the `.rrd` the dashboard's replay review opens.
    pub rrd: bool,
    /// The devices a trainee may pick besides the page's pointer (a synthetic trainee, an
    /// OpenIGTLink tracker or haptic bridge on a port of this machine), set by whoever runs
    /// the server.
    pub devices: Vec<DeviceSpec>,
    /// How an OpenIGTLink device sends the force back.
    pub igtl: IgtlOptions,
    /// The recording store the attempts' recordings are put into once they end (they stay
    /// in `recordings_dir` too); `None`: only there.
    pub recordings: Option<cutlab_assessor::recordings::RecordingStore>,
    /// The hub each ended attempt is sent to (with the rest of the queue); `None`: none.
    pub hub: Option<crate::sync::Hub>,
    /// How long a session goes on without its page (a reload, a lost network, a hidden tab
    /// that sends nothing) before it ends incomplete, s. Shorter gaps pause the blade.
    pub absence_s: f64,
    /// The seed of a synthetic trainee's or a scripted hand's variation.
    pub seed: u64,
}

impl StationSettings {
    /// Settings for a station recording into `recordings_dir`.
    pub fn new(recordings_dir: impl Into<PathBuf>) -> Self {
        Self {
            recordings_dir: recordings_dir.into(),
            duration_s: 300.0,
            view_hz: 60.0,
            min_tets: None,
            time_step: TimeStep::Scene,
            keyframe_every_s: 1.0,
            clock: Clock::Live,
            rrd: true,
            devices: Vec::new(),
            igtl: IgtlOptions::default(),
            recordings: None,
            hub: None,
            absence_s: 30.0,
            seed: 0,
        }
    }

    /// How each of the station's sessions runs (the surface recorded at least `view_hz`).
    pub fn run_settings(&self) -> RunSettings {
        RunSettings {
            min_tets: self.min_tets,
            time_step: self.time_step,
            clock: self.clock,
            duration_s: self.duration_s,
            realtime_priority: true,
            keyframe_every_s: self.keyframe_every_s,
            surface_hz: self.view_hz,
            seed: self.seed,
            igtl: self.igtl.clone(),
            // the page's second hand is a pointer feed of its own (a touch), not a plan
            grasp: None,
            second_hand: false,
        }
    }

    /// The input a trainee picked by name: [`POINTER`] or one of [`Self::devices`] as it
    /// prints.
    pub fn input_named(&self, name: &str) -> Result<Input, StationError> {
        if name == POINTER {
            return Ok(Input::Pointer);
        }
        self.devices
            .iter()
            .find(|d| d.to_string() == name)
            .map(|d| Input::Spec(d.clone()))
            .ok_or_else(|| {
                StationError::NoSuchDevice(format!(
                    "this station has no device {name:?} (it has {POINTER}{})",
                    self.devices
                        .iter()
                        .map(|d| format!(", {d}"))
                        .collect::<String>()
                ))
            })
    }
}

/// The name of the page's own pointer or pen among a station's devices.
pub const POINTER: &str = "pointer";

/// Who trains on what.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct StartRequest {
    pub exercise: String,
    pub trainee: String,
    /// Guided (the plan shown on the tissue) or exam (nothing shown); an exam-only exercise
    /// runs as an exam whatever this says.
    pub guided: bool,
    /// With the page's pointer: a second hand, the grasper, driven by the page's touch
    /// ([`Running::grasper`]).
    pub second_hand: bool,
}

/// How a running session is asked to end, and how it did. The pages that show it come and
/// go (a reload, a lost network): the session ends when the trainee presses Stop, at its time
/// limit, or when no page has been connected for longer than the absence allowed.
#[derive(Debug)]
pub struct Control {
    stop: AtomicBool,
    lost: AtomicBool,
    /// Pages connected now.
    pages: AtomicUsize,
    /// When the last page left, nanoseconds after `epoch`; [`PRESENT`] while one is
    /// connected (and before the first comes).
    away_since_nanos: AtomicU64,
    epoch: Instant,
    absence: Duration,
}

/// [`Control::away_since_nanos`] while a page is there.
const PRESENT: u64 = u64::MAX;

impl Control {
    /// A control that ends the session once no page has been there for `absence`.
    pub fn new(absence: Duration) -> Self {
        Self {
            stop: AtomicBool::new(false),
            lost: AtomicBool::new(false),
            pages: AtomicUsize::new(0),
            away_since_nanos: AtomicU64::new(PRESENT),
            epoch: Instant::now(),
            absence,
        }
    }

    /// The trainee pressed Stop.
    pub fn stop(&self) {
        self.stop.store(true, Ordering::Release);
    }

    /// The session cannot go on without its page (it could not be registered): the attempt
    /// will be incomplete.
    pub fn lose(&self) {
        self.lost.store(true, Ordering::Release);
    }

    /// A page connected (the first, or one back after a reload).
    pub fn attach(&self) {
        self.pages.fetch_add(1, Ordering::AcqRel);
        self.away_since_nanos.store(PRESENT, Ordering::Release);
    }

    /// A page went away; when it was the last (true), the absence starts counting.
    pub fn leave(&self) -> bool {
        let last = self.pages.fetch_sub(1, Ordering::AcqRel) == 1;
        if last {
            let now = u64::try_from(self.epoch.elapsed().as_nanos()).unwrap_or(PRESENT - 1);
            self.away_since_nanos.store(now, Ordering::Release);
        }
        last
    }

    /// No page has been connected for longer than the absence allowed.
    pub fn away_too_long(&self) -> bool {
        let since = self.away_since_nanos.load(Ordering::Acquire);
        since != PRESENT
            && self
                .epoch
                .elapsed()
                .as_nanos()
                .saturating_sub(u128::from(since))
                > self.absence.as_nanos()
    }

    fn should_end(&self) -> bool {
        self.stop.load(Ordering::Acquire) || self.lost() || self.away_too_long()
    }

    /// Whether the page was lost: it could not be registered, or no page came back within
    /// the absence allowed.
    pub fn lost(&self) -> bool {
        self.lost.load(Ordering::Acquire) || self.away_too_long()
    }

    /// The absence allowed.
    pub fn absence(&self) -> Duration {
        self.absence
    }
}

/// The station's device: the page's device, ended by [`Control`].
#[derive(Debug)]
struct StationDevice {
    inner: Box<dyn HapticDevice>,
    control: Arc<Control>,
}

impl HapticDevice for StationDevice {
    fn name(&self) -> &str {
        self.inner.name()
    }
    fn limits(&self) -> DeviceLimits {
        self.inner.limits()
    }
    fn read(&mut self, tick: u64, time_s: f64) -> Result<ToolPose, DeviceFault> {
        self.inner.read(tick, time_s)
    }
    fn write_force(&mut self, force_newtons: Vector3) -> Result<(), DeviceFault> {
        self.inner.write_force(force_newtons)
    }
    fn ends_session(&self) -> bool {
        self.control.should_end() || self.inner.ends_session()
    }
}

/// How a session ended, for the page's debrief.
#[derive(Debug, Clone, PartialEq)]
pub enum Ending {
    /// Scored: the attempt's id, score and verdict.
    Scored {
        attempt: i64,
        score: f64,
        passed: bool,
    },
    /// Not scored (the page went away, the session failed): why.
    Incomplete { attempt: i64, why: String },
}

/// A started session: what its page and its viewers need.
#[derive(Debug)]
pub struct Running {
    pub attempt: i64,
    pub exercise: String,
    pub trainee: String,
    /// The plan is shown (guided) or not (exam, also whenever the exercise is exam-only).
    pub guided: bool,
    /// The planned incision on the tissue (shown in guided mode).
    pub plan: Plan,
    /// Lines marked on the tissue (shown in every mode).
    pub marks: Vec<Vec<cutlab_sim::Point3>>,
    /// The colour of each region the scene gives one (linear RGB, 0 to 1).
    pub region_colours: Vec<(u32, [f64; 3])>,
    /// The name of each region the scene names (its layers: skin, fat, muscle, ...).
    pub region_names: Vec<(u32, String)>,
    /// The force the tissue should not be loaded beyond, the exercise's (N).
    pub force_limit_newtons: f64,
    /// The blade's cutting edge, the scene's (m): how deep the page lets the pointer set it.
    pub blade_length_m: f64,
    /// Where the exercise is seen from, if its scene says.
    pub viewpoint: Option<Viewpoint>,
    /// The structures behind the tissue the scene names (the heart), shown through an
    /// opening.
    pub targets: Vec<cutlab_sim::scene::Target>,
    pub feed: ViewFeed,
    /// Where the page's samples go, when the page drives the session.
    pub pointer: Option<PointerFeed>,
    /// Where the page's grasper samples go, when the session has a second hand.
    pub grasper: Option<PointerFeed>,
    pub control: Arc<Control>,
    /// `None` while the session runs.
    pub ending: watch::Receiver<Option<Ending>>,
    /// What the session measured, once it ended (before [`Self::ending`] is sent).
    pub figures: Arc<OnceLock<SessionFigures>>,
}

/// What a station session measured (for `cutlab bench station`).
#[derive(Debug, Clone)]
pub struct SessionFigures {
    /// The servo's periods.
    pub servo: PeriodStats,
    /// Simulated seconds per wall-clock second.
    pub speed: f64,
    /// Simulation steps per wall-clock second.
    pub sim_steps_per_s: f64,
    /// Tetrahedra at the start.
    pub tets: usize,
    /// The simulation step, s.
    pub time_step_s: f64,
}

/// Makes a device for the session's plan (a synthetic trainee follows it, say).
pub type DeviceFactory =
    Box<dyn FnOnce(&Plan) -> Result<Box<dyn HapticDevice>, StationError> + Send>;

/// What drives a station session.
pub enum Input {
    /// The page's pointer or pen ([`PointerDevice`]: a scalpel pointing into the tissue along
    /// the plan, at rest above its entry); its samples go through [`Running::pointer`].
    Pointer,
    /// A device of the station's (a synthetic trainee following the plan, a trajectory file,
    /// a recorded hand, an OpenIGTLink tracker or haptic bridge) with the page as its view.
    Spec(DeviceSpec),
    /// Any other device, made for the session's plan, with the page as its view.
    Device(DeviceFactory),
}

impl Input {
    /// The class of device its attempt's thresholds are for.
    fn class(&self) -> DeviceClass {
        match self {
            Input::Pointer => DeviceClass::Pointer,
            Input::Spec(spec) => DeviceClass::of(Some(&spec.to_string())),
            Input::Device(_) => DeviceClass::Stylus,
        }
    }
}

impl std::fmt::Debug for Input {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            Input::Pointer => "Pointer",
            Input::Spec(_) => "Spec",
            Input::Device(_) => "Device",
        })
    }
}

/// Starts `request`'s session driven by `input`, publishing its frames to the returned feed.
/// Returns once the session runs; the attempt is scored or marked incomplete on a thread of
/// its own when it ends.
pub async fn start(
    store: Store,
    settings: &StationSettings,
    request: StartRequest,
    input: Input,
) -> Result<Running, StationError> {
    let mode = |guided: bool| Some(if guided { "guided" } else { "exam" }.to_owned());
    let mut who = AttemptSpec {
        exercise: request.exercise.clone(),
        trainee: request.trainee.clone(),
        expert: false,
        mode: mode(request.guided),
        device: String::new(),
    };
    let admitted = who.admit(&store).await?;
    let exercise = admitted.exercise();
    let guided = request.guided && !exercise.exam_only;
    let force_limit_newtons = force_limit(&store, exercise, admitted.plan(), input.class()).await?;
    // building and settling the tissue takes a while: off the async threads
    let (scene, run) = (exercise.scene.clone(), settings.run_settings());
    let expert_plan = admitted.plan().clone();
    let prepared = tokio::task::spawn_blocking(move || {
        Prepared::new(&scene, &run, PlanSource::Exercise(&expert_plan))
    })
    .await
    .map_err(|e| StationError::Plan(format!("preparing the session: {e}")))??;
    if let Some(choice) = &prepared.step_choice {
        tracing::info!("station: simulation step {choice}");
    }
    let plan = prepared.plan()?.clone();
    // what the attempt records it was made with (a programme's own device: its name)
    let named = match &input {
        Input::Pointer => Some(POINTER.to_owned()),
        Input::Spec(spec) => Some(spec.to_string()),
        Input::Device(_) => None,
    };
    let (hands, pointer): (Hands, Option<PointerFeed>) = match input {
        Input::Pointer => {
            let options = PointerOptions {
                absence_s: settings.absence_s,
                ..PointerOptions::above_entry(&plan)?
            };
            let (device, feed) = PointerDevice::new(options)?;
            (Box::new(device).into(), Some(feed))
        }
        Input::Spec(spec) => (prepared.device(&spec)?, None),
        Input::Device(make) => (make(&plan)?.into(), None),
    };
    let Hands {
        scalpel: device,
        grasper: grasper_device,
    } = hands;
    // the page's touch, the second hand, beside its pointer
    let (grasper_device, grasper) = match (&pointer, request.second_hand) {
        (Some(_), true) => {
            let (device, feed) = PointerDevice::new(PointerOptions::grasper_above(&plan)?)?;
            (Some(Box::new(device) as Box<dyn HapticDevice>), Some(feed))
        }
        _ => (grasper_device, None),
    };
    let nanos = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0, |d| d.as_nanos());
    let dir = settings
        .recordings_dir
        .join(format!("station-{}-{nanos}", request.trainee));
    let mcap = attempt_run::session_mcap(&dir)?;
    who.mode = mode(guided);
    who.device = named.unwrap_or_else(|| device.name().to_owned());
    let open = OpenAttempt::start(&store, &who, &admitted, &mcap).await?;
    let attempt = open.id;
    let provenance = prepared.provenance(&request.trainee, &request.exercise, device.name());
    let echo = pointer
        .clone()
        .map(|feed| Arc::new(feed) as Arc<dyn EchoSource>);
    let (publisher, feed) = ViewPublisher::new(echo);
    let mut observers: Vec<Box<dyn RecordObserver>> = vec![Box::new(publisher)];
    if settings.rrd {
        let target = RerunTarget::File(dir.join("session.rrd"));
        observers.push(Box::new(prepared.rerun_sink(&target)?));
    }
    let control = Arc::new(Control::new(Duration::from_secs_f64(settings.absence_s)));
    let device = Box::new(StationDevice {
        inner: device,
        control: control.clone(),
    });
    let (ending_tx, ending) = watch::channel(None);
    let figures = Arc::new(OnceLock::new());
    let viewpoint = prepared.scene.viewpoint.clone();
    let targets = prepared.scene.targets.clone();
    let marks = prepared.marks.clone();
    let blade_length_m = prepared.config.blade_length_m;
    let region_names = prepared
        .scene
        .spec
        .materials
        .iter()
        .filter(|m| !m.name.is_empty())
        .map(|m| (m.region, m.name.clone()))
        .collect();
    let region_colours = prepared
        .scene
        .spec
        .materials
        .iter()
        .filter_map(|m| m.colour_rgb.map(|c| (m.region, c)))
        .collect();
    let thread = SessionThread {
        prepared,
        hands: Hands {
            scalpel: device,
            grasper: grasper_device,
        },
        provenance,
        mcap,
        observers,
        open,
        store,
        control: control.clone(),
        pointer: pointer.clone(),
        figures: figures.clone(),
        ending: ending_tx,
        recordings: settings.recordings.clone(),
        hub: settings.hub.clone(),
        runtime: tokio::runtime::Handle::current(),
    };
    std::thread::Builder::new()
        .name("cutlab-station".into())
        .spawn(move || thread.run())
        .map_err(|source| StationError::Io {
            what: "starting the station's session thread".into(),
            source,
        })?;
    Ok(Running {
        attempt,
        exercise: request.exercise,
        trainee: request.trainee,
        guided,
        plan,
        marks,
        region_colours,
        region_names,
        force_limit_newtons,
        blade_length_m,
        viewpoint,
        targets,
        feed,
        pointer,
        grasper,
        control,
        ending,
        figures,
    })
}

/// The limit the attempt is scored with (one source for the score and the page's force bar):
/// the exercise's peak-force threshold for the `class` of device, else its plan's force
/// limit.
async fn force_limit(
    store: &Store,
    exercise: &Exercise,
    plan: &ExercisePlan,
    class: DeviceClass,
) -> Result<f64, StationError> {
    Ok(store
        .thresholds_for(exercise.id, class)
        .await?
        .metrics
        .iter()
        .find(|t| t.key == "peak_force_n")
        .and_then(|t| t.upper)
        .unwrap_or(plan.kind_plan().force_limit_n()))
}

/// A station session's own thread: records the session, then ends its attempt, says how it
/// ended and queues it to the hub.
struct SessionThread {
    prepared: Prepared,
    hands: Hands,
    provenance: Provenance,
    mcap: PathBuf,
    observers: Vec<Box<dyn RecordObserver>>,
    open: OpenAttempt,
    store: Store,
    control: Arc<Control>,
    pointer: Option<PointerFeed>,
    figures: Arc<OnceLock<SessionFigures>>,
    ending: watch::Sender<Option<Ending>>,
    recordings: Option<RecordingStore>,
    hub: Option<crate::sync::Hub>,
    runtime: tokio::runtime::Handle,
}

impl SessionThread {
    fn run(self) {
        let attempt = self.open.id;
        let tets = self.prepared.scene.model.mesh.tet_count();
        let time_step_s = self.prepared.time_step_s();
        let mut recorded = self.prepared.record(
            self.hands,
            &self.provenance,
            &self.mcap,
            Some(Box::new(self.observers)),
        );
        if let Ok(r) = &recorded
            && let Ok(report) = &r.report
        {
            let _ = self.figures.set(SessionFigures {
                servo: report.servo.period_stats(report.period_nanos),
                speed: report.speed(),
                sim_steps_per_s: report.sim_steps as f64 / report.wall_s.max(1e-9),
                tets,
                time_step_s,
            });
        }
        if let Err(e) = attempt_run::finish_observer(&mut recorded) {
            tracing::warn!("attempt {attempt}: {e}");
        }
        // a page that went away, or a pointer that faulted (a stalled or broken page), ends the
        // session as a lost device does: the attempt is not scored
        let fault = self.pointer.as_ref().and_then(PointerFeed::fault);
        let outcome = match attempt_run::outcome_of(&recorded) {
            Ok(_) if self.control.lost() => Err(format!(
                "the station's page went away and did not come back within {:.0} s",
                self.control.absence().as_secs_f64()
            )),
            Ok(_) if let Some(fault) = fault => {
                Err(format!("the station's pointer failed: {fault}"))
            }
            other => other,
        };
        let finished = self.runtime.block_on(self.open.finish(
            &self.store,
            outcome,
            self.recordings.as_ref(),
        ));
        let ending = match finished {
            Ok(Finished::Scored(o, _)) => Ending::Scored {
                attempt,
                score: o.verdict.score,
                passed: o.verdict.pass,
            },
            Ok(Finished::Incomplete(why)) => Ending::Incomplete { attempt, why },
            Err(e) => Ending::Incomplete {
                attempt,
                why: e.to_string(),
            },
        };
        tracing::info!("station attempt {attempt} ended: {ending:?}");
        let _ = self.ending.send(Some(ending));
        if let Some(hub) = self.hub {
            let (store, recordings) = (self.store, self.recordings);
            // the queue to the hub in the background; a hub that is down only waits
            self.runtime.spawn(async move {
                match crate::sync::sync_new(&store, &hub, recordings.as_ref()).await {
                    Ok(r) => tracing::info!("sent to the hub {}: {r:?}", hub.url()),
                    Err(e) => tracing::warn!("{e}"),
                }
            });
        }
    }
}
