//! `cutlab session`: one training session: a device drives the scalpel through the 1 kHz
//! servo loop while the simulation runs at its fixed step; prints a summary and writes the
//! final tissue, `summary.json` and `steps.csv` (the servo tick each simulation step consumed).

use std::net::SocketAddr;
use std::path::{Path, PathBuf};

use anyhow::{Context, bail};
use cutlab_assessor::recordings::RecordingStore;
use cutlab_assessor::{DbLocation, ExpertPlan};
use cutlab_haptics::device::{
    CsvDevice, DeviceSpec, ForceOutput, HapticDevice, IgtlDevice, IgtlOptions, PointerHand,
    SyntheticTrainee,
};
use cutlab_haptics::servo::Clock;
use cutlab_haptics::tap::TapSettings;
use cutlab_haptics::{Session, SessionConfig, TimeStep};
use cutlab_recorder::record::{self, Provenance, RecordSettings};
use cutlab_recorder::{RecordedHand, Recording, RerunTarget, WriterOptions};
use cutlab_sim::Vector3;
use cutlab_sim::io::PointData;
use cutlab_sim::scene::{BuildOptions, Scene};
use cutlab_sim::solver::LocalisationSettings;
use cutlab_sim::stats::Summary;

use cutlab_assessor::Store;
use cutlab_station::attempt::{self, Finished};

use crate::localise_choice::{self, Localise};

/// `println!` unless `quiet`.
macro_rules! say {
    ($quiet:expr, $($arg:tt)*) => {
        if !$quiet {
            println!($($arg)*);
        }
    };
}

/// What `--device` names (parsed by [`DeviceSpec`]).
pub type DeviceArg = DeviceSpec;

/// Options of `cutlab session`.
#[derive(Debug)]
pub struct Options {
    pub scene: String,
    pub min_tets: Option<usize>,
    /// The simulation step.
    pub time_step: TimeStep,
    pub device: DeviceArg,
    /// How an OpenIGTLink device sends the force back.
    pub igtl: IgtlOptions,
    pub clock: Clock,
    pub duration_s: f64,
    pub seed: u64,
    pub out: PathBuf,
    pub realtime_priority: bool,
    /// Keyframe interval, s.
    pub keyframe_every_s: f64,
    /// Surface recording rate, Hz (0: never).
    pub surface_hz: f64,
    /// Also log to rerun (a relative `.rrd` path is in `out`).
    pub rerun: Option<RerunTarget>,
    /// Store the session as an attempt and score it.
    pub attempt: Option<AttemptArgs>,
    /// Whether to simulate only near the scalpel (the default localisation thresholds).
    pub localise: Localise,
    /// Print nothing (the demo's seeding runs many sessions).
    pub quiet: bool,
}

/// The attempt a session is (`--trainee`, `--exercise`, `--db`).
#[derive(Debug)]
pub struct AttemptArgs {
    pub db: DbLocation,
    /// The recording store (`--recordings`) the attempt's recordings are put into.
    pub recordings: Option<String>,
    /// The hub the attempt is sent to once it ends (`--hub`).
    pub hub: Option<cutlab_station::sync::Hub>,
    pub exercise: String,
    pub trainee: String,
    /// An expert's reference attempt (its metrics set the exercise's thresholds).
    pub expert: bool,
}

/// The open attempt of a session, and the runtime its database needs.
struct OpenAttempt {
    rt: tokio::runtime::Runtime,
    store: Store,
    id: i64,
    quiet: bool,
    /// Where the recordings go once the attempt ends (besides `--out`).
    recordings: Option<RecordingStore>,
    hub: Option<cutlab_station::sync::Hub>,
    /// The attempt's lock, let go once it has ended.
    lock: attempt::AttemptLock,
}

impl OpenAttempt {
    /// Starts the attempt made with `device` (as the user named it).
    fn start(a: &AttemptArgs, device: &str, recording: &Path, quiet: bool) -> anyhow::Result<Self> {
        let rt = tokio::runtime::Builder::new_current_thread()
            .enable_all()
            .build()
            .context("starting the async runtime")?;
        // held until the attempt has ended, so that no sweep takes it for a dead one
        let lock = attempt::AttemptLock::hold(recording)?;
        let (store, id, recordings) = rt.block_on(async {
            let store = Store::open(&a.db)
                .await
                .with_context(|| format!("opening the database {}", a.db))?;
            store.ensure_builtins().await?;
            // before the attempt starts: a store that does not answer stops the session here
            let recordings = RecordingStore::connect_if(a.recordings.as_deref())
                .await
                .context("opening the recording store")?;
            let attempt = store
                .start_recorded_attempt(&a.exercise, &a.trainee, recording, a.expert)
                .await?;
            store.set_attempt_setup(attempt.id, None, device).await?;
            anyhow::Ok((store, attempt.id, recordings))
        })?;
        say!(
            quiet,
            "attempt {id} of {} at {} (running; database {})",
            a.trainee,
            a.exercise,
            a.db
        );
        Ok(Self {
            rt,
            store,
            id,
            quiet,
            recordings,
            hub: a.hub.clone(),
            lock,
        })
    }

    /// Scores the attempt from its recording, or marks it incomplete when the session failed.
    fn finish(self, outcome: Result<&Path, String>) -> anyhow::Result<()> {
        let Self {
            rt,
            store,
            id,
            quiet,
            recordings,
            hub,
            lock,
        } = self;
        rt.block_on(async {
            // the path the station's attempts take too
            let result =
                match attempt::finish_attempt(&store, id, outcome, recordings.as_ref()).await {
                    Ok(Finished::Scored(o, values)) if !quiet => {
                        crate::assess_cli::print_outcome(&o, &values, false)
                    }
                    Ok(Finished::Scored(..)) => Ok(()),
                    Ok(Finished::Incomplete(why)) => {
                        say!(quiet, "attempt {id} marked incomplete: {why}");
                        Ok(())
                    }
                    Err(e) => Err(anyhow::Error::new(e).context(format!("finishing attempt {id}"))),
                };
            drop(lock);
            if let Some(hub) = &hub {
                // a hub that is down leaves the attempt queued, not the session failed
                match cutlab_station::sync::sync_new(&store, hub, recordings.as_ref()).await {
                    Ok(r) => say!(
                        quiet,
                        "sent to the hub {}: {} attempt(s), {} left queued",
                        hub.url(),
                        r.uploaded + r.already,
                        r.refused.len()
                    ),
                    Err(e) => eprintln!("warning: {e}"),
                }
            }
            store.close().await;
            result
        })
    }
}

pub fn run(o: &Options) -> anyhow::Result<()> {
    if !(o.duration_s > 0.0 && o.duration_s <= 86_400.0) {
        bail!(
            "--duration must be between 0 and 86400 seconds, got {}",
            o.duration_s
        );
    }
    // Devices that need no scene first: a bad file or a busy port is reported at once.
    let mut device: Option<Box<dyn HapticDevice>> = match &o.device {
        DeviceArg::Trainee { .. } | DeviceArg::PointerHand(_) => None,
        DeviceArg::Csv(path) => Some(Box::new(
            CsvDevice::open(path).context("reading the trajectory")?,
        )),
        DeviceArg::Recording(path) => {
            let recording = Recording::open(path)
                .with_context(|| format!("reading the recording {}", path.display()))?;
            Some(Box::new(RecordedHand::new(&recording).with_context(
                || format!("playing the hand of {}", path.display()),
            )?))
        }
        DeviceArg::Igtl(port) => {
            let d =
                IgtlDevice::listen_with(SocketAddr::from(([0, 0, 0, 0], *port)), o.igtl.clone())?;
            say!(
                o.quiet,
                "OpenIGTLink device listening on {} (TRANSFORM in, mm; {} {:?} out, N)",
                d.address(),
                match d.force_output() {
                    ForceOutput::Point => "POINT",
                    ForceOutput::Transform => "TRANSFORM",
                },
                o.igtl.force_device_name
            );
            Some(Box::new(d))
        }
    };
    let scene = Scene::load(
        &o.scene,
        BuildOptions {
            min_tets: o.min_tets,
        },
    )
    .with_context(|| format!("loading scene {:?}", o.scene))?;
    for note in &scene.read_notes {
        say!(o.quiet, "note: {note}");
    }
    let (scene, mut session, choice) =
        Session::at_time_step(scene, o.time_step).context("preparing the session")?;
    if let Some(choice) = choice {
        say!(o.quiet, "simulation step: {choice}");
    }
    let scene_settings = session.sim.settings.localisation;
    let localisation = localise_choice::choose(
        o.localise,
        &scene.spec.name,
        scene.model.mesh.tet_count(),
        scene_settings.is_some(),
    );
    say!(
        o.quiet,
        "localisation: {} ({})",
        if localisation.localise { "on" } else { "off" },
        localisation.why
    );
    // `on` with the default thresholds; `auto` keeps the scene's own when it has them
    session.sim.settings.localisation = match (localisation.localise, o.localise) {
        (false, _) => None,
        (true, Localise::Auto) => scene_settings.or(Some(LocalisationSettings::default())),
        (true, _) => Some(LocalisationSettings::default()),
    };
    // The planned incision (what a synthetic trainee follows; recorded with every session):
    // the exercise's expert plan when the session is an attempt, else 60 mm across the
    // tissue in the scene's `incision` directions.
    let expert_plan = o
        .attempt
        .as_ref()
        .map(|a| exercise_plan(a, &o.scene, &scene.spec.name))
        .transpose()?;
    let plan = match &expert_plan {
        Some(p) => attempt::plan_on_tissue(&session, p)
            .map_err(anyhow::Error::new)
            .context("projecting the exercise's plan onto the tissue"),
        None => {
            // the scene's incision directions were checked when it was built
            let (up, along) = scene.spec.incision.unit().map_err(anyhow::Error::msg)?;
            let (lo, hi) = scene.model.mesh.bounding_box();
            let depth_m = (0.4 * (hi - lo).dot(&up.abs())).min(0.008);
            session
                .plan_across(&up, &along, 0.06, depth_m)
                .context("planning the incision across the tissue")
        }
    };
    let mut config = SessionConfig {
        clock: o.clock,
        duration_s: o.duration_s,
        realtime_priority: o.realtime_priority,
        ..SessionConfig::default()
    };
    config.render = config.render.with_scene_cut(&scene.spec);
    if let DeviceArg::Trainee { name, skill } = &o.device {
        let trainee = SyntheticTrainee::new(
            name,
            plan.as_ref().map_err(|e| anyhow::anyhow!("{e:#}"))?.clone(),
            *skill,
            o.seed,
        )?;
        device = Some(Box::new(trainee.expecting_cut_of(&config.render)));
    }
    if let DeviceArg::PointerHand(kind) = &o.device {
        let plan = plan.as_ref().map_err(|e| anyhow::anyhow!("{e:#}"))?;
        device = Some(Box::new(PointerHand::new(*kind, plan, o.seed)?));
    }
    let device = device.context("no device")?;
    let device_name = device.name().to_owned();
    let tets = scene.model.mesh.tet_count();
    if !(o.keyframe_every_s > 0.0
        && o.keyframe_every_s.is_finite()
        && o.surface_hz >= 0.0
        && o.surface_hz.is_finite())
    {
        bail!("--keyframe-every must be positive and --surface-hz non-negative");
    }
    let step_s = session.sim.settings.time_step_s;
    let keyframe_every_steps = ((o.keyframe_every_s / step_s).round() as u64).max(1);
    // the surface BVH is built again at every keyframe, so that a replay can resume at each
    config.collider_rebuild_every_steps = keyframe_every_steps;
    let settings = RecordSettings {
        tap: TapSettings {
            keyframe_every_steps,
            surface_every_steps: if o.surface_hz > 0.0 {
                ((1.0 / (o.surface_hz * step_s)).round() as u64).max(1)
            } else {
                0
            },
            ..TapSettings::default()
        },
        writer: WriterOptions::default(),
    };
    std::fs::create_dir_all(&o.out).with_context(|| format!("creating {}", o.out.display()))?;
    let mcap_path = o.out.join("session.mcap");
    let (trainee, exercise) = o
        .attempt
        .as_ref()
        .map_or((String::new(), String::new()), |a| {
            (a.trainee.clone(), a.exercise.clone())
        });
    let provenance = Provenance {
        scene: o.scene.clone(),
        min_tets: o.min_tets,
        seed: o.seed,
        trainee,
        exercise,
        device: device_name.clone(),
    };
    let observer = match &o.rerun {
        Some(target) => {
            let target = match target {
                RerunTarget::File(rrd) => RerunTarget::File(o.out.join(rrd)),
                other => other.clone(),
            };

            Some(crate::recording::rerun_sink(
                &target,
                config.period_nanos,
                config.blade_length_m,
                plan.as_ref().ok(),
            )?)
        }
        None => None,
    };
    let attempt = o
        .attempt
        .as_ref()
        .map(|a| OpenAttempt::start(a, &o.device.to_string(), &mcap_path, o.quiet))
        .transpose()?;
    let recorded = match record::run_recorded(
        session,
        device,
        &config,
        &provenance,
        plan.as_ref().ok(),
        &scene.spec,
        &mcap_path,
        settings,
        observer,
    ) {
        Ok(r) => r,
        Err(e) => {
            if let Some(a) = attempt {
                a.finish(Err(format!("recording failed: {e}")))?;
            }
            return Err(anyhow::Error::new(e).context(format!("recording {}", mcap_path.display())));
        }
    };
    if let Some(observer) = recorded.observer {
        observer.finish().context("finishing the rerun log")?;
    }
    let r = match recorded.report {
        Ok(r) => r,
        Err(e) => {
            if let Some(a) = attempt {
                a.finish(Err(format!("the session failed: {e}")))?;
            }
            return Err(anyhow::Error::new(e).context("running the session"));
        }
    };

    let clock = if o.clock == Clock::Live {
        "live"
    } else {
        "virtual"
    };
    say!(
        o.quiet,
        "session: scene {} ({tets} tets), device {device_name} (seed {}), {clock} clock, {:.1} s, {}",
        scene.spec.name,
        o.seed,
        o.duration_s,
        if localisation.localise {
            "localised"
        } else {
            "whole body"
        }
    );
    let max_lag = r.largest_skip_ahead_ticks();
    say!(
        o.quiet,
        "  ticks {}, sim steps {} (largest skip ahead of the step's own tick: {max_lag} ticks)",
        r.servo.ticks,
        r.sim_steps
    );
    say!(
        o.quiet,
        "  cut length {:.1} mm ({} cutting steps, {} tets split, {} unresolved, {} failed); {} tets now; the blade went in {} time(s)",
        r.stats.cut_length_m * 1e3,
        r.stats.cut_steps,
        r.stats.tets_split,
        r.stats.unresolved_cuts,
        r.stats.failed_cuts,
        r.simulation.model.mesh.tet_count(),
        r.servo.blade_entries
    );
    say!(
        o.quiet,
        "  pieces cut free: {} specimen(s) lifted out; {} fragment(s) left attached",
        r.stats.specimens,
        r.stats.fragments_reattached
    );
    say!(
        o.quiet,
        "  max force {:.2} N; non-finite values {}; fault ticks {} (faded out {}); dropped samples {}; rejected sim steps {}",
        r.servo.max_force_newtons,
        r.servo.non_finite_count,
        r.servo.fault_ticks,
        r.servo.faded_ticks,
        r.servo.dropped_samples,
        r.stats.rejected_steps
    );
    if r.servo.blade_entries == 0 {
        say!(
            o.quiet,
            "  the blade never entered the tissue: the largest push, {:.2} N, stayed under the scene's cut threshold of {:.2} N (`cut_threshold_newtons`), and the tip never pressed {:.1} mm in (`cut_depth_mm`), with the blade engaged",
            r.servo.max_force_newtons,
            config.render.cut_threshold_newtons,
            scene.spec.cut_depth_mm
        );
    }
    let p = r.servo.period_stats(r.period_nanos);
    if o.clock == Clock::Live {
        say!(
            o.quiet,
            "  servo period: mean {:.1} us, p50 {:.1} us, p99 {:.1} us; deviation from 1 ms p99 {:.1} us, max {:.1} us; missed deadlines {}; latest tick start {:.1} us after its deadline",
            p.mean_us,
            p.p50_us,
            p.p99_us,
            p.p99_deviation_us,
            p.max_deviation_us,
            p.missed_deadlines,
            p.max_lateness_us
        );
        match &r.servo.realtime_priority {
            Some(Ok(())) => say!(o.quiet, "  servo thread at real-time priority (SCHED_FIFO)"),
            Some(Err(e)) => say!(
                o.quiet,
                "  real-time priority not permitted ({e}); normal priority"
            ),
            None => say!(o.quiet, "  real-time priority not requested"),
        }
    }
    say!(
        o.quiet,
        "  servo work per tick: mean {:.1} us, max {:.1} us",
        p.mean_work_us,
        p.max_work_us
    );
    let steps_us: Vec<f64> = r.step_nanos.iter().map(|&n| n as f64 * 1e-3).collect();
    let s = Summary::of(&steps_us);
    say!(
        o.quiet,
        "  sim step (contact, cut, step, refit): median {:.0} us, p99 {:.0} us, max {:.0} us; CG iterations per step {:.1}",
        s.median,
        s.p99,
        s.max,
        r.stats.cg_iterations as f64 / r.sim_steps.max(1) as f64
    );
    say!(
        o.quiet,
        "  speed: {:.2} simulated s per wall s ({:.2} s wall)",
        r.speed(),
        r.wall_s
    );

    let w = &recorded.write;
    say!(
        o.quiet,
        "  recording {}: {} messages, {:.1} MB of payload, writer busy {:.2} s; dropped tick records {}",
        mcap_path.display(),
        w.messages.values().sum::<u64>(),
        w.payload_bytes as f64 * 1e-6,
        w.busy_s,
        r.servo.dropped_records
    );
    let sim = &r.simulation;
    let deformed = cutlab_sim::TetMesh::new(
        sim.state.positions.clone(),
        sim.model.mesh.tets().to_vec(),
        sim.model.mesh.regions().to_vec(),
    )?;
    let displacement: Vec<Vector3> = sim
        .state
        .positions
        .iter()
        .zip(sim.model.mesh.positions())
        .map(|(p, q)| p - q)
        .collect();
    let path = o.out.join("final.vtu");
    cutlab_sim::io::write_vtu(
        &path,
        &deformed,
        &[("displacement", PointData::Vector(&displacement))],
    )
    .with_context(|| format!("writing {}", path.display()))?;
    let summary = serde_json::json!({
        "scene": scene.spec.name, "tets": tets, "device": device_name, "seed": o.seed, "clock": clock,
        "localised": localisation.localise, "localisation": localisation.why,
        "duration_s": o.duration_s, "ticks": r.servo.ticks, "sim_steps": r.sim_steps,
        "cut_length_mm": r.stats.cut_length_m * 1e3, "blade_entries": r.servo.blade_entries, "tets_split": r.stats.tets_split, "max_force_newtons": r.servo.max_force_newtons,
        "non_finite": r.servo.non_finite_count, "fault_ticks": r.servo.fault_ticks, "dropped_samples": r.servo.dropped_samples,
        "period_us": { "mean": p.mean_us, "p50": p.p50_us, "p99": p.p99_us, "p99_deviation": p.p99_deviation_us,
                       "max_deviation": p.max_deviation_us, "missed_deadlines": p.missed_deadlines, "max_lateness": p.max_lateness_us },
        "sim_step_us": s, "cg_iterations_per_step": r.stats.cg_iterations as f64 / r.sim_steps.max(1) as f64, "speed": r.speed(), "wall_s": r.wall_s,
        "state_hash": format!("{:016x}", r.state_hash), "force_hash": format!("{:016x}", r.servo.force_hash),
    });
    write_json(&o.out.join("summary.json"), &summary)?;
    // which servo tick each simulation step consumed (what a replay feeds back)
    let mut steps = String::with_capacity(16 * r.tick_of_step.len() + 16);
    steps.push_str("step,tick\n");
    for (n, t) in r.tick_of_step.iter().enumerate() {
        steps.push_str(&format!("{n},{t}\n"));
    }
    let steps_path = o.out.join("steps.csv");
    std::fs::write(&steps_path, steps)
        .with_context(|| format!("writing {}", steps_path.display()))?;
    say!(
        o.quiet,
        "wrote {}, summary.json and steps.csv",
        path.display()
    );
    if let Some(a) = attempt {
        a.finish(Ok(&mcap_path))?;
    }
    Ok(())
}

/// The expert plan of the attempt's exercise, whose scene must be the session's.
fn exercise_plan(a: &AttemptArgs, scene_arg: &str, scene_name: &str) -> anyhow::Result<ExpertPlan> {
    let rt = tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
        .context("starting the async runtime")?;
    rt.block_on(async {
        let store = Store::open(&a.db)
            .await
            .with_context(|| format!("opening the database {}", a.db))?;
        store.ensure_builtins().await?;
        let e = store.exercise_by_name(&a.exercise).await?;
        let plan = store.exercise_plan(e.id).await?;
        store.close().await;
        if e.scene != scene_arg && e.scene != scene_name {
            bail!(
                "exercise {} is on the scene {}, not {scene_arg}: pass --scene {}",
                e.name,
                e.scene,
                e.scene
            );
        }
        Ok(plan)
    })
}

fn write_json(path: &Path, v: &serde_json::Value) -> anyhow::Result<()> {
    std::fs::write(path, serde_json::to_string_pretty(v)?)
        .with_context(|| format!("writing {}", path.display()))
}
