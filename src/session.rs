//! `cutlab session`: one training session: a device drives the scalpel through the 1 kHz
//! servo loop while the simulation runs at its fixed step; prints a summary and writes the
//! final tissue, `summary.json` and `steps.csv` (the servo tick each simulation step consumed).
//! The run itself is the one every attempt takes ([`cutlab_station::attempt_run`]); this
//! module adds the localisation choice, the printing and the files.

use std::path::{Path, PathBuf};

use anyhow::{Context, bail};
use cutlab_assessor::recordings::RecordingStore;
use cutlab_assessor::{DbLocation, Store};
use cutlab_haptics::device::DeviceSpec;
use cutlab_haptics::servo::{Clock, PeriodStats};
use cutlab_haptics::{SessionReport, StepChoice};
use cutlab_recorder::RerunTarget;
use cutlab_recorder::record::RecordedSession;
use cutlab_recorder::writer::RecordObserver;
use cutlab_sim::Vector3;
use cutlab_sim::io::PointData;
use cutlab_sim::solver::LocalisationSettings;
use cutlab_sim::stats::Summary;
use cutlab_station::attempt::{Admitted, Finished};
use cutlab_station::attempt_run::{
    self, AttemptSpec, AttemptStore, PlanSource, Prepared, RunResult, RunSettings,
};
use cutlab_station::sync::Hub;

use crate::localise_choice::{self, Localise};

/// What `--device` names (parsed by [`DeviceSpec`]).
pub type DeviceArg = DeviceSpec;

/// The scene of a session that names neither a scene nor an exercise.
pub const DEFAULT_SCENE: &str = "chest-wall";

/// Options of `cutlab session`.
#[derive(Debug)]
pub struct Options {
    /// The scene; `None`: the exercise's (with `attempt`), else `chest-wall`.
    pub scene: Option<String>,
    pub device: DeviceArg,
    /// How the session runs (step, clock, duration, seed, keyframes, surface rate).
    pub run: RunSettings,
    pub out: PathBuf,
    /// Also log to rerun (a relative `.rrd` path is in `out`).
    pub rerun: Option<RerunTarget>,
    /// Store the session as an attempt and score it.
    pub attempt: Option<AttemptArgs>,
    /// Whether to simulate only near the scalpel (the default localisation thresholds).
    pub localise: Localise,
}

/// The attempt a session is (`--trainee`, `--exercise`, `--db`).
#[derive(Debug)]
pub struct AttemptArgs {
    pub db: DbLocation,
    /// The recording store (`--recordings`) the attempt's recordings are put into.
    pub recordings: Option<String>,
    /// The hub the attempt is sent to once it ends (`--hub`).
    pub hub: Option<Hub>,
    pub exercise: String,
    pub trainee: String,
    /// An expert's reference attempt (its metrics set the exercise's thresholds).
    pub expert: bool,
}

/// A session that ran: what it was and how it went, for the caller to print or keep.
#[derive(Debug)]
pub struct SessionRun {
    pub scene: String,
    pub tets: usize,
    /// The scene file's notes (what its reader let pass).
    pub notes: Vec<String>,
    pub step_choice: Option<StepChoice>,
    pub localisation: localise_choice::Choice,
    pub device: String,
    pub mcap: PathBuf,
    /// The push and the depth at which the blade goes in (N, mm).
    pub cut_threshold_newtons: f64,
    pub cut_depth_mm: f64,
    pub result: RunResult,
}

/// `cutlab session`: runs the session, prints what it did, writes its files.
pub fn run(o: &Options) -> anyhow::Result<()> {
    o.run.check()?;
    // a device that needs no scene first: a bad file or a busy port is said at once
    let device = attempt_run::open_device(&o.device, &o.run.igtl)?;
    if let (DeviceSpec::Igtl(_), Some(d)) = (&o.device, &device) {
        println!(
            "OpenIGTLink device {} listening (TRANSFORM in, mm; {:?} {:?} out, N)",
            d.scalpel.name(),
            o.run.igtl.force_output,
            o.run.igtl.force_device_name
        );
        if let (Some(g), Some(names)) = (&d.grasper, &o.run.igtl.grasper) {
            println!(
                "  and a grasper, {}: TRANSFORM {:?}, jaws STRING {:?}, force {:?}",
                g.name(),
                names.pose,
                names.jaws(),
                names.force
            );
        }
    }
    let s = run_session(o, device)?;
    for note in &s.notes {
        println!("note: {note}");
    }
    if let Some(choice) = &s.step_choice {
        println!("simulation step: {choice}");
    }
    let on = if s.localisation.localise { "on" } else { "off" };
    println!("localisation: {on} ({})", s.localisation.why);
    let report = match &s.result.recorded {
        Ok(recorded) => recorded.report.as_ref().map(|r| (recorded, r)),
        Err(e) => {
            print_attempt(o, &s)?;
            bail!("recording {}: {e}", s.mcap.display());
        }
    };
    let (recorded, r) = match report {
        Ok(both) => both,
        Err(e) => {
            print_attempt(o, &s)?;
            bail!("running the session: {e}");
        }
    };
    if let Err(e) = &s.result.observer {
        bail!("{e}");
    }
    let f = Figures::of(r);
    print_report(o, &s, recorded, r, &f);
    write_outputs(o, &s, r, &f)?;
    print_attempt(o, &s)
}

/// The session of `o` with `device` (else the one `o` names, made for the plan): the scene
/// prepared, localised as `o` says, recorded into `o.out` (and to rerun), as an attempt when
/// `o` says, scored and sent to the hub. Prints nothing.
pub fn run_session(
    o: &Options,
    device: Option<cutlab_haptics::Hands>,
) -> anyhow::Result<SessionRun> {
    let rt = tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
        .context("starting the async runtime")?;
    let db = match &o.attempt {
        Some(a) => Some(rt.block_on(open_store(a))?),
        None => None,
    };
    let who = o.attempt.as_ref().map(|a| AttemptSpec {
        exercise: a.exercise.clone(),
        trainee: a.trainee.clone(),
        expert: a.expert,
        mode: None,
        device: o.device.to_string(),
    });
    // the curriculum's lock is checked before the scene is built (the station's words)
    let admitted = match (&db, &who) {
        (Some((store, _)), Some(w)) => Some(rt.block_on(w.admit(store))?),
        _ => None,
    };
    let source = admitted
        .as_ref()
        .map_or(PlanSource::AcrossScene, |a| PlanSource::Exercise(a.plan()));
    let scene = match (&o.scene, &admitted) {
        (Some(s), _) => s.clone(),
        (None, Some(a)) => a.exercise().scene.clone(),
        (None, None) => DEFAULT_SCENE.into(),
    };
    let prepared = Prepared::new(&scene, &o.run, source);
    if let Some(e) = admitted.as_ref().map(Admitted::exercise) {
        // the scene as given or as it names itself
        let built = prepared.as_ref().ok().map(|p| p.scene.spec.name.as_str());
        if e.scene != scene && built != Some(e.scene.as_str()) {
            bail!(
                "exercise {} is on the scene {}, not {scene}: pass --scene {} or none",
                e.name,
                e.scene,
                e.scene
            );
        }
    }
    let mut prepared = prepared.with_context(|| format!("preparing scene {scene:?}"))?;
    let localisation = localise(&mut prepared, o.localise);
    let device = match device {
        Some(d) => d,
        None => prepared.device(&o.device)?,
    };
    let mcap = attempt_run::session_mcap(&o.out)?;
    let observer = match &o.rerun {
        Some(RerunTarget::File(rrd)) => {
            Some(prepared.rerun_sink(&RerunTarget::File(o.out.join(rrd)))?)
        }
        Some(target) => Some(prepared.rerun_sink(target)?),
        None => None,
    }
    .map(|sink| Box::new(sink) as Box<dyn RecordObserver>);
    let scene = &prepared.scene;
    let (name, tets, notes) = (
        scene.spec.name.clone(),
        scene.model.mesh.tet_count(),
        scene.read_notes.iter().map(ToString::to_string).collect(),
    );
    let (cut_threshold_newtons, cut_depth_mm) = (
        prepared.config.render.cut_threshold_newtons,
        scene.spec.cut_depth_mm,
    );
    let step_choice = prepared.step_choice.clone();
    let device_name = device.scalpel.name().to_owned();
    let at = db.as_ref().map(|(store, recordings)| AttemptStore {
        store,
        recordings: recordings.as_ref(),
        hub: o.attempt.as_ref().and_then(|a| a.hub.as_ref()),
    });
    let result = attempt_run::run_blocking(
        &rt,
        prepared,
        device,
        at.as_ref()
            .zip(who.as_ref())
            .zip(admitted.as_ref())
            .map(|((at, w), a)| (at, w, a)),
        &mcap,
        observer,
    );
    if let Some((store, _)) = db {
        rt.block_on(store.close());
    }
    Ok(SessionRun {
        scene: name,
        tets,
        notes,
        step_choice,
        localisation,
        device: device_name,
        mcap,
        cut_threshold_newtons,
        cut_depth_mm,
        result: result?,
    })
}

/// Localises the prepared session as `setting` says: `on` with the default thresholds, `auto`
/// where it was measured to pay (keeping the scene's own thresholds when it has them).
fn localise(prepared: &mut Prepared, setting: Localise) -> localise_choice::Choice {
    let scene_settings = prepared.session.sim.settings.localisation;
    let choice = localise_choice::choose(
        setting,
        &prepared.scene.spec.name,
        prepared.scene.model.mesh.tet_count(),
        scene_settings.is_some(),
    );
    prepared.session.sim.settings.localisation = match (choice.localise, setting) {
        (false, _) => None,
        (true, Localise::Auto) => scene_settings.or(Some(LocalisationSettings::default())),
        (true, _) => Some(LocalisationSettings::default()),
    };
    choice
}

/// The attempt's database (its built-in exercises there) and recording store: a store that
/// does not answer stops the session before it starts.
async fn open_store(a: &AttemptArgs) -> anyhow::Result<(Store, Option<RecordingStore>)> {
    let store = Store::open(&a.db)
        .await
        .with_context(|| format!("opening the database {}", a.db))?;
    store.ensure_builtins().await?;
    let recordings = RecordingStore::connect_if(a.recordings.as_deref())
        .await
        .context("opening the recording store")?;
    Ok((store, recordings))
}

/// What a session's summary states of its timing, worked out once for the printout and the
/// file: the servo's periods, the simulation step's times (us), CG iterations per step.
struct Figures {
    period: PeriodStats,
    step_us: Summary,
    cg_per_step: f64,
}

impl Figures {
    fn of(r: &SessionReport) -> Self {
        let steps_us: Vec<f64> = r.step_nanos.iter().map(|&n| n as f64 * 1e-3).collect();
        Self {
            period: r.servo.period_stats(r.period_nanos),
            step_us: Summary::of(&steps_us),
            cg_per_step: r.stats.cg_iterations as f64 / r.sim_steps.max(1) as f64,
        }
    }
}

/// What the session did, printed.
fn print_report(
    o: &Options,
    s: &SessionRun,
    recorded: &RecordedSession,
    r: &SessionReport,
    f: &Figures,
) {
    let clock = clock_name(o.run.clock);
    let mode = if s.localisation.localise {
        "localised"
    } else {
        "whole body"
    };
    println!(
        "session: scene {} ({} tets), device {} (seed {}), {clock} clock, {:.1} s, {mode}",
        s.scene, s.tets, s.device, o.run.seed, o.run.duration_s
    );
    let max_lag = r.largest_skip_ahead_ticks();
    println!(
        "  ticks {}, sim steps {} (largest skip ahead of the step's own tick: {max_lag} ticks)",
        r.servo.ticks, r.sim_steps
    );
    println!(
        "  cut length {:.1} mm ({} cutting steps, {} tets split, {} unresolved, {} failed); {} tets now; the blade went in {} time(s)",
        r.stats.cut_length_m * 1e3,
        r.stats.cut_steps,
        r.stats.tets_split,
        r.stats.unresolved_cuts,
        r.stats.failed_cuts,
        r.simulation.model.mesh.tet_count(),
        r.servo.blade_entries
    );
    println!(
        "  pieces cut free: {} specimen(s) lifted out; {} fragment(s) left attached",
        r.stats.specimens, r.stats.fragments_reattached
    );
    println!(
        "  max force {:.2} N; non-finite values {}; fault ticks {} (faded out {}); dropped samples {}; rejected sim steps {}",
        r.servo.max_force_newtons,
        r.servo.non_finite_count,
        r.servo.fault_ticks,
        r.servo.faded_ticks,
        r.servo.dropped_samples,
        r.stats.rejected_steps
    );
    if o.run.grasp.is_some() {
        println!(
            "  grasper: {} grasp(s), held {:.2} s, strongest pull {:.2} N, slipped {} time(s)",
            r.stats.grasps,
            r.stats.grasp_steps as f64 * r.simulation.settings.time_step_s,
            r.stats.max_grasp_pull_newtons,
            r.stats.grasp_slips
        );
    }
    if r.servo.blade_entries == 0 {
        println!(
            "  the blade never entered the tissue: the largest push, {:.2} N, stayed under the scene's cut threshold of {:.2} N (`cut_threshold_newtons`), and the tip never pressed {:.1} mm in (`cut_depth_mm`), with the blade engaged",
            r.servo.max_force_newtons, s.cut_threshold_newtons, s.cut_depth_mm
        );
    }
    print_servo(o, r, &f.period);
    let st = &f.step_us;
    println!(
        "  sim step (contact, cut, step, refit): median {:.0} us, p99 {:.0} us, max {:.0} us; CG iterations per step {:.1}",
        st.median, st.p99, st.max, f.cg_per_step
    );
    println!(
        "  speed: {:.2} simulated s per wall s ({:.2} s wall)",
        r.speed(),
        r.wall_s
    );
    let w = &recorded.write;
    println!(
        "  recording {}: {} messages, {:.1} MB of payload, writer busy {:.2} s; dropped tick records {}",
        s.mcap.display(),
        w.messages.values().sum::<u64>(),
        w.payload_bytes as f64 * 1e-6,
        w.busy_s,
        r.servo.dropped_records
    );
}

/// The servo's periods and priority (live clock), and its work per tick.
fn print_servo(o: &Options, r: &SessionReport, p: &PeriodStats) {
    if o.run.clock == Clock::Live {
        println!(
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
            Some(Ok(())) => println!("  servo thread at real-time priority (SCHED_FIFO)"),
            Some(Err(e)) => println!("  real-time priority not permitted ({e}); normal priority"),
            None => println!("  real-time priority not requested"),
        }
    }
    println!(
        "  servo work per tick: mean {:.1} us, max {:.1} us",
        p.mean_work_us, p.max_work_us
    );
}

fn clock_name(clock: Clock) -> &'static str {
    if clock == Clock::Live {
        "live"
    } else {
        "virtual"
    }
}

/// `final.vtu` (the deformed tissue with its displacement), `summary.json` and `steps.csv`
/// (which servo tick each simulation step consumed: what a replay feeds back) in `o.out`.
fn write_outputs(
    o: &Options,
    s: &SessionRun,
    r: &SessionReport,
    f: &Figures,
) -> anyhow::Result<()> {
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
    let p = &f.period;
    let summary = serde_json::json!({
        "scene": s.scene, "tets": s.tets, "device": s.device, "seed": o.run.seed, "clock": clock_name(o.run.clock),
        "localised": s.localisation.localise, "localisation": s.localisation.why,
        "duration_s": o.run.duration_s, "ticks": r.servo.ticks, "sim_steps": r.sim_steps,
        "cut_length_mm": r.stats.cut_length_m * 1e3, "blade_entries": r.servo.blade_entries, "tets_split": r.stats.tets_split, "max_force_newtons": r.servo.max_force_newtons,
        "non_finite": r.servo.non_finite_count, "fault_ticks": r.servo.fault_ticks, "dropped_samples": r.servo.dropped_samples,
        "period_us": { "mean": p.mean_us, "p50": p.p50_us, "p99": p.p99_us, "p99_deviation": p.p99_deviation_us,
                       "max_deviation": p.max_deviation_us, "missed_deadlines": p.missed_deadlines, "max_lateness": p.max_lateness_us },
        "sim_step_us": f.step_us, "cg_iterations_per_step": f.cg_per_step, "speed": r.speed(), "wall_s": r.wall_s,
        "state_hash": format!("{:016x}", r.state_hash), "force_hash": format!("{:016x}", r.servo.force_hash),
        "grasper": o.run.grasp.map(|_| serde_json::json!({
            "grasps": r.stats.grasps, "held_s": r.stats.grasp_steps as f64 * r.simulation.settings.time_step_s,
            "max_pull_newtons": r.stats.max_grasp_pull_newtons, "slips": r.stats.grasp_slips,
        })),
    });
    write_json(&o.out.join("summary.json"), &summary)?;
    let mut steps = String::with_capacity(16 * r.tick_of_step.len() + 16);
    steps.push_str("step,tick\n");
    for (n, t) in r.tick_of_step.iter().enumerate() {
        steps.push_str(&format!("{n},{t}\n"));
    }
    let steps_path = o.out.join("steps.csv");
    std::fs::write(&steps_path, steps)
        .with_context(|| format!("writing {}", steps_path.display()))?;
    println!("wrote {}, summary.json and steps.csv", path.display());
    Ok(())
}

/// How the attempt ended (scored, with its outcome; or incomplete) and what the hub took.
fn print_attempt(o: &Options, s: &SessionRun) -> anyhow::Result<()> {
    let (Some(a), Some((id, finished))) = (&o.attempt, &s.result.attempt) else {
        return Ok(());
    };
    println!(
        "attempt {id} of {} at {} (database {})",
        a.trainee, a.exercise, a.db
    );
    match finished {
        Ok(Finished::Scored(outcome, values)) => {
            crate::assess_cli::print_outcome(outcome, values, false)?;
        }
        Ok(Finished::Incomplete(why)) => println!("attempt {id} marked incomplete: {why}"),
        Err(e) => bail!("finishing attempt {id}: {e}"),
    }
    match (&s.result.sync, &a.hub) {
        (Some(Ok(r)), Some(hub)) => println!(
            "sent to the hub {}: {} attempt(s), {} left queued",
            hub.url(),
            r.uploaded + r.already,
            r.refused.len()
        ),
        // a hub that is down leaves the attempt queued, not the session failed
        (Some(Err(e)), _) => eprintln!("warning: {e}"),
        _ => {}
    }
    Ok(())
}

fn write_json(path: &Path, v: &serde_json::Value) -> anyhow::Result<()> {
    std::fs::write(path, serde_json::to_string_pretty(v)?)
        .with_context(|| format!("writing {}", path.display()))
}
