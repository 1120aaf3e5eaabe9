//! Deterministic replay: re-simulate a recording from its recorded inputs and check it.
//!
//! The replay rebuilds the scene named in the session metadata, settles it (checking the
//! initial state hash), then drives a [`SessionStepper`] — the code the session's simulation
//! thread ran — with the servo sample of exactly the tick each recorded step consumed
//! (`/sim/step`). After every step it compares what the step did with the recording: the cut
//! (`/sim/topology`, every field, bit for bit) and, at keyframes, the hashes of the state and
//! topology bits (`/sim/state_hash`). The first difference is reported precisely: the step,
//! the tick, what differed, and for a state difference the largest position difference
//! against the keyframe and the vertex where it is.
//!
//! Seeking: a replay from `from_s` restores the last keyframe before it that carries what the
//! steps after it depend on ([`KeyframeMsg::resume`]: the solver's warm start, the localised
//! region, the cutter's stroke, the last contact; the session built its surface BVH again
//! there), checks the restored state against the keyframe's hashes, and re-simulates from
//! there; the steps before that keyframe are neither run nor checked. With
//! [`ReplayOptions::resimulate`] (or without such a keyframe, as in older recordings) it
//! re-simulates every step before `from_s` as fast as possible, checking every hash on the way.

use std::collections::BTreeMap;
use std::time::{Duration, Instant};

use cutlab_haptics::servo::ServoSample;
use cutlab_haptics::stepper::{SessionStepper, StateHash, StepOutput};
use cutlab_haptics::tap::{Keyframe, SimRecord, SurfaceSnapshot, surface_due};
use cutlab_haptics::{Session, SessionConfig};
use cutlab_sim::scene::{BuildOptions, Scene};

use crate::channels::{KeyframeMsg, SessionMeta, SimStepMsg, StateHashMsg, TopologyMsg};
use crate::writer::RecordObserver;
use crate::{RecorderError, Recording};

/// How fast a replay plays.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Speed {
    /// As fast as the machine allows.
    Max,
    /// This many times real time (1: real time).
    Factor(f64),
}

/// A replay speed that is not `max`, `realtime` or a positive factor.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum SpeedError {
    #[error("speed must be max, realtime or a factor such as 4 or x4, got {given:?}")]
    NotASpeed {
        given: String,
        #[source]
        error: std::num::ParseFloatError,
    },
    #[error("speed factor must be positive, got {0:?}")]
    NotPositive(String),
}

impl std::str::FromStr for Speed {
    type Err = SpeedError;
    fn from_str(s: &str) -> Result<Self, SpeedError> {
        match s {
            "max" => Ok(Speed::Max),
            "realtime" | "real-time" => Ok(Speed::Factor(1.0)),
            _ => {
                let f: f64 =
                    s.trim_start_matches('x')
                        .parse()
                        .map_err(|error| SpeedError::NotASpeed {
                            given: s.to_owned(),
                            error,
                        })?;
                if f > 0.0 && f.is_finite() {
                    Ok(Speed::Factor(f))
                } else {
                    Err(SpeedError::NotPositive(s.to_owned()))
                }
            }
        }
    }
}

/// Settings of a replay.
#[derive(Default)]
pub struct ReplayOptions {
    pub speed: Option<Speed>,
    /// Play from this session time (s); earlier steps are re-simulated without pacing.
    pub from_s: Option<f64>,
    /// Stop after this session time (s).
    pub to_s: Option<f64>,
    /// Receives the replayed ticks and records in the played window (rerun export).
    pub observer: Option<Box<dyn RecordObserver>>,
    /// Keep going after the first divergence (count them all).
    pub keep_going: bool,
    /// Re-simulate (and check) the steps before `from_s` instead of restoring a keyframe.
    pub resimulate: bool,
    /// Threads that replay the stretches between resumable keyframes side by side (0: one
    /// per core; 1: one after the other). Used only unpaced and without an observer.
    pub jobs: usize,
}

impl std::fmt::Debug for ReplayOptions {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("ReplayOptions")
            .field("speed", &self.speed)
            .field("from_s", &self.from_s)
            .field("to_s", &self.to_s)
            .field("keep_going", &self.keep_going)
            .field("resimulate", &self.resimulate)
            .field("jobs", &self.jobs)
            .finish_non_exhaustive()
    }
}

/// The first place where the replay differs from the recording.
#[derive(Debug, Clone, PartialEq)]
pub struct Divergence {
    pub step: u64,
    pub tick: u64,
    pub what: String,
    /// For a state difference: the largest position difference against the keyframe, m, and
    /// the vertex.
    pub max_position_difference_m: Option<(f64, usize)>,
}

impl std::fmt::Display for Divergence {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "step {} (tick {}): {}", self.step, self.tick, self.what)?;
        if let Some((d, v)) = self.max_position_difference_m {
            write!(f, "; largest position difference {:.3e} m at vertex {v}", d)?;
        }
        Ok(())
    }
}

/// The keyframe a replay resumed at.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ResumedAt {
    pub step: u64,
    pub tick: u64,
    /// Session time right after the keyframe's step, s.
    pub session_s: f64,
}

/// What a replay did.
#[derive(Debug, Clone, PartialEq)]
pub struct ReplayReport {
    /// The keyframe the replay resumed at, when it sought one.
    pub resumed_at: Option<ResumedAt>,
    /// Steps re-simulated.
    pub steps: u64,
    /// Threads the steps were re-simulated on.
    pub jobs: usize,
    pub keyframes_checked: u64,
    pub keyframes_matched: u64,
    pub cuts_recorded: u64,
    pub cuts_replayed: u64,
    pub divergences: u64,
    pub first_divergence: Option<Divergence>,
    /// Session time re-simulated, s.
    pub simulated_s: f64,
    pub wall_s: f64,
    /// The final state's hash.
    pub final_hash: StateHash,
}

impl ReplayReport {
    /// Nothing replayed yet, from a state with hashes `hash`.
    fn empty(hash: StateHash) -> Self {
        Self {
            resumed_at: None,
            steps: 0,
            jobs: 1,
            keyframes_checked: 0,
            keyframes_matched: 0,
            cuts_recorded: 0,
            cuts_replayed: 0,
            divergences: 0,
            first_divergence: None,
            simulated_s: 0.0,
            wall_s: 0.0,
            final_hash: hash,
        }
    }

    /// Adds a stretch replayed on its own (in order after the ones added before).
    fn absorb(&mut self, part: ReplayReport) {
        self.steps += part.steps;
        self.keyframes_checked += part.keyframes_checked;
        self.keyframes_matched += part.keyframes_matched;
        self.cuts_recorded += part.cuts_recorded;
        self.cuts_replayed += part.cuts_replayed;
        self.divergences += part.divergences;
        self.first_divergence = self.first_divergence.take().or(part.first_divergence);
        self.simulated_s += part.simulated_s;
        self.final_hash = part.final_hash;
    }

    /// Every keyframe matched and every cut was the same.
    pub fn verified(&self) -> bool {
        self.first_divergence.is_none() && self.keyframes_checked > 0
    }

    /// Simulated seconds per wall second.
    pub fn speed(&self) -> f64 {
        self.simulated_s / self.wall_s.max(1e-12)
    }
}

/// The stepper a recording's session started from: its scene, settled, with its settings.
pub fn stepper_for(meta: &SessionMeta) -> Result<SessionStepper, RecorderError> {
    let scene = Scene::load(
        &meta.provenance.scene,
        BuildOptions {
            min_tets: meta.provenance.min_tets,
        },
    )
    .map_err(|source| RecorderError::Scene {
        name: meta.provenance.scene.clone(),
        source: Box::new(source),
    })?;
    // the session's step, when it ran with another than its scene's (`--time-step-ms`)
    let time_step_s = meta.time_step_nanos as f64 / 1e9;
    let scene = if scene.spec.solver.time_step_s == time_step_s {
        scene
    } else {
        scene
            .with_time_step(time_step_s)
            .map_err(|source| RecorderError::Scene {
                name: meta.provenance.scene.clone(),
                source: Box::new(source),
            })?
    };
    let mut session = Session::new(&scene)?;
    if meta.localisation.is_some() {
        session.sim.settings.localisation = meta.localisation;
    }
    let config = SessionConfig {
        blade_length_m: meta.blade_length_m,
        contact_reach_m: meta.contact_reach_m,
        contact_patch_radius_m: meta.contact_patch_radius_m,
        cut_step_m: meta.cut_step_m,
        collider_rebuild_every_steps: meta.collider_rebuild_every_steps,
        ..SessionConfig::default()
    };
    Ok(SessionStepper::new(session, &config))
}

/// The session of `rec` as it was at its last keyframe that can be resumed, and that
/// keyframe's tick: to go on from where the attempt ended (a retractor set in its wound).
pub fn stepper_at_last_keyframe(rec: &Recording) -> Result<(SessionStepper, u64), RecorderError> {
    let meta = rec.meta()?;
    let k = rec
        .keyframes
        .iter()
        .rev()
        .find(|k| k.resume.is_some())
        .ok_or_else(|| RecorderError::Replay("no keyframe can be resumed".into()))?;
    let mut stepper = stepper_for(meta)?;
    resume_at(&mut stepper, k)?;
    Ok((stepper, k.tick))
}

/// Restores `stepper` to keyframe `k` (which must carry its resume state) and checks it
/// against the keyframe's hashes.
fn resume_at(stepper: &mut SessionStepper, k: &KeyframeMsg) -> Result<(), RecorderError> {
    let resume = k.resume.as_ref().ok_or_else(|| {
        RecorderError::Replay(format!("the keyframe at step {} cannot be resumed", k.step))
    })?;
    let malformed =
        |e: String| RecorderError::Malformed(format!("keyframe at step {}: {e}", k.step));
    let points = |v: &[[f64; 3]]| {
        v.iter()
            .map(|&p| cutlab_sim::Point3::from(p))
            .collect::<Vec<_>>()
    };
    let mesh = cutlab_sim::TetMesh::new(
        points(&k.rest_positions_m),
        k.tets.clone(),
        k.regions.clone(),
    )
    .map_err(|e| malformed(e.to_string()))?;
    let state = cutlab_sim::model::State {
        positions: points(&k.positions_m),
        velocities: k
            .velocities_m_per_s
            .iter()
            .map(|&v| cutlab_sim::Vector3::from(v))
            .collect(),
    };
    stepper
        .resume(mesh, state, resume)
        .map_err(|e| malformed(e.to_string()))?;
    if stepper.steps() != k.step + 1 {
        return Err(malformed(format!(
            "its resume state is of step {}",
            stepper.steps().wrapping_sub(1)
        )));
    }
    Ok(())
}

/// The largest position difference between the stepper and a keyframe, and its vertex.
fn position_difference(stepper: &SessionStepper, k: &KeyframeMsg) -> Option<(f64, usize)> {
    let x = &stepper.sim.state.positions;
    if x.len() != k.positions_m.len() {
        return None;
    }
    x.iter()
        .zip(&k.positions_m)
        .map(|(p, q)| (p - cutlab_sim::Point3::from(*q)).norm())
        .enumerate()
        .map(|(i, d)| (d, i))
        .max_by(|a, b| a.0.total_cmp(&b.0))
}

/// What a replay compares each step with: the recorded cuts, keyframe hashes and keyframes.
struct Checks<'a> {
    hashes: BTreeMap<u64, &'a StateHashMsg>,
    keyframes: BTreeMap<u64, &'a KeyframeMsg>,
    cuts: BTreeMap<u64, &'a TopologyMsg>,
}

fn diverge(report: &mut ReplayReport, d: Divergence) {
    report.divergences += 1;
    if report.first_divergence.is_none() {
        report.first_divergence = Some(d);
    }
}

impl<'a> Checks<'a> {
    fn of(rec: &'a Recording) -> Self {
        Self {
            hashes: rec.hashes.iter().map(|h| (h.step, h)).collect(),
            keyframes: rec.keyframes.iter().map(|k| (k.step, k)).collect(),
            cuts: rec.topology.iter().map(|t| (t.step, t)).collect(),
        }
    }

    /// Runs recorded step `step` on `stepper` with its sample and compares what it did with
    /// the recording, counting into `report`.
    fn step(
        &self,
        stepper: &mut SessionStepper,
        step: &SimStepMsg,
        sample: &ServoSample,
        report: &mut ReplayReport,
    ) -> StepOutput {
        let (cuts, hashes, keyframes) = (&self.cuts, &self.hashes, &self.keyframes);
        let out = stepper.step(sample);
        report.steps += 1;
        let recorded_cut = cuts.get(&step.step);
        report.cuts_recorded += recorded_cut.is_some() as u64;
        report.cuts_replayed += out.cut.is_some() as u64;
        let cut_differs = match (&out.cut, recorded_cut) {
            (None, None) => None,
            (Some(_), None) => Some("the replay cut, the recording did not".to_owned()),
            (None, Some(_)) => Some("the recording cut, the replay did not".to_owned()),
            (Some((blade, event)), Some(r)) => {
                if crate::channels::BladeMsg::from(blade) != r.blade {
                    Some("the blade of the cut differs".to_owned())
                } else if *event != r.event {
                    Some(format!(
                        "the cut's topology differs ({} tets split, recorded {}; {} vertices created, recorded {})",
                        event.tets_removed.len(),
                        r.event.tets_removed.len(),
                        event.vertices_created.len(),
                        r.event.vertices_created.len()
                    ))
                } else {
                    None
                }
            }
        };
        if out.rejected != step.rejected {
            diverge(
                report,
                Divergence {
                    step: step.step,
                    tick: step.tick,
                    what: format!(
                        "step rejected: {}, recorded {}",
                        out.rejected, step.rejected
                    ),
                    max_position_difference_m: None,
                },
            );
        }
        if let Some(what) = cut_differs {
            diverge(
                report,
                Divergence {
                    step: step.step,
                    tick: step.tick,
                    what,
                    max_position_difference_m: None,
                },
            );
        }
        if let Some(h) = hashes.get(&step.step) {
            report.keyframes_checked += 1;
            let now = stepper.state_hash();
            if now == h.hash() {
                report.keyframes_matched += 1;
            } else {
                let what = format!(
                    "state hash {:016x}/{:016x} (state/topology), recorded {:016x}/{:016x}",
                    now.state, now.topology, h.state.0, h.topology.0
                );
                let max_position_difference_m = keyframes
                    .get(&step.step)
                    .and_then(|k| position_difference(stepper, k));
                diverge(
                    report,
                    Divergence {
                        step: step.step,
                        tick: step.tick,
                        what,
                        max_position_difference_m,
                    },
                );
            }
        }
        out
    }

    /// Where a replay of the window starts: at the last resumable keyframe before it (restored
    /// into `stepper` and checked: `None` if it differs), or at the settled scene when there is
    /// none or `resimulate` says so.
    fn start(
        &self,
        rec: &Recording,
        stepper: &mut SessionStepper,
        window: Window,
        resimulate: bool,
        report: &mut ReplayReport,
    ) -> Result<Option<Start>, RecorderError> {
        let seek_to = self.keyframes.values().rev().find(|k| {
            k.resume.is_some() && k.tick < window.from_tick && (k.step as usize) < rec.steps.len()
        });
        let Some(k) = seek_to.filter(|_| !resimulate) else {
            return Ok(Some(Start {
                step: 0,
                previous_tick: None,
            }));
        };
        if !self.resume(stepper, k, report)? {
            return Ok(None);
        }
        report.resumed_at = Some(ResumedAt {
            step: k.step,
            tick: k.tick,
            session_s: (k.tick + 1) as f64 * window.period_nanos as f64 * 1e-9,
        });
        Ok(Some(Start {
            step: k.step as usize + 1,
            previous_tick: Some(k.tick),
        }))
    }

    /// Restores `stepper` to keyframe `k` and checks the restored state against its hashes
    /// (a difference is counted into `report`: false).
    fn resume(
        &self,
        stepper: &mut SessionStepper,
        k: &KeyframeMsg,
        report: &mut ReplayReport,
    ) -> Result<bool, RecorderError> {
        resume_at(stepper, k)?;
        let now = stepper.state_hash();
        if now != k.hash() {
            let what = format!(
                "the state restored from the keyframe has hashes {:016x}/{:016x} (state/topology), recorded {:016x}/{:016x}",
                now.state, now.topology, k.state_hash.0, k.topology_hash.0
            );
            diverge(
                report,
                Divergence {
                    step: k.step,
                    tick: k.tick,
                    what,
                    max_position_difference_m: None,
                },
            );
            return Ok(false);
        }
        Ok(true)
    }
}

/// Record `n` of the recording's steps must be step `n`.
fn in_order(n: usize, step: &SimStepMsg) -> Result<(), RecorderError> {
    if step.step != n as u64 {
        return Err(RecorderError::Replay(format!(
            "step records out of order: record {n} is step {}",
            step.step
        )));
    }
    Ok(())
}

/// The recorded servo sample `step` consumed.
fn sample_of<'s>(
    samples: &'s BTreeMap<u64, ServoSample>,
    step: &SimStepMsg,
) -> Result<&'s ServoSample, RecorderError> {
    samples.get(&step.tick).ok_or_else(|| {
        RecorderError::Replay(format!(
            "the pose or tool state of tick {} (consumed by step {}) is missing from the recording",
            step.tick, step.step
        ))
    })
}

/// Replays `rec`; see the module documentation.
pub fn replay(rec: &Recording, mut options: ReplayOptions) -> Result<ReplayReport, RecorderError> {
    let meta = rec.meta()?;
    if rec.steps.is_empty() {
        return Err(RecorderError::Replay(
            "the recording has no simulation steps".into(),
        ));
    }
    let started = Instant::now();
    let mut stepper = stepper_for(meta)?;
    let samples = rec.samples();
    let checks = Checks::of(rec);
    let mut report = ReplayReport::empty(stepper.state_hash());
    let window = Window::of(&options, meta.period_nanos.max(1));
    let start = if settled_as_recorded(&stepper, meta, &mut report) {
        checks.start(rec, &mut stepper, window, options.resimulate, &mut report)?
    } else {
        None
    };
    if let Some(start) = start {
        let jobs = match options.jobs {
            0 => std::thread::available_parallelism().map_or(1, |n| n.get()),
            j => j,
        };
        let at_once =
            options.observer.is_none() && matches!(options.speed, None | Some(Speed::Max));
        if jobs > 1 && at_once {
            let end_step = rec
                .steps
                .iter()
                .position(|s| s.tick > window.to_tick)
                .unwrap_or(rec.steps.len());
            let (threads, parts) = replay_in_parallel(
                rec,
                meta,
                &checks,
                &samples,
                stepper,
                start.step..end_step,
                jobs,
                options.keep_going,
            )?;
            report.jobs = threads;
            parts.into_iter().for_each(|part| report.absorb(part));
        } else {
            let run = InOrder {
                rec,
                meta,
                checks: &checks,
                samples: &samples,
                window,
            };
            run.replay(&mut stepper, &mut options, start, &mut report)?;
        }
    }
    report.wall_s = started.elapsed().as_secs_f64();
    Ok(report)
}

/// Whether the scene settled as the recorded one did (the same hashes before the first
/// step); a difference is counted into `report`.
fn settled_as_recorded(
    stepper: &SessionStepper,
    meta: &SessionMeta,
    report: &mut ReplayReport,
) -> bool {
    let initial = StateHash {
        state: meta.initial_state_hash.0,
        topology: meta.initial_topology_hash.0,
    };
    let now = stepper.state_hash();
    if now == initial {
        return true;
    }
    diverge(
        report,
        Divergence {
            step: 0,
            tick: 0,
            what: format!(
                "the settled scene {:?} differs from the recorded one before the first step (hashes {:016x}/{:016x}, recorded {:016x}/{:016x}): a different scene file or cutlab build",
                meta.provenance.scene, now.state, now.topology, initial.state, initial.topology
            ),
            max_position_difference_m: None,
        },
    );
    false
}

/// The ticks a replay plays (`from_s` to `to_s`), and the servo period.
#[derive(Debug, Clone, Copy)]
struct Window {
    from_tick: u64,
    to_tick: u64,
    period_nanos: u64,
}

impl Window {
    fn of(options: &ReplayOptions, period_nanos: u64) -> Self {
        let period = period_nanos as f64;
        Self {
            from_tick: options
                .from_s
                .map_or(0, |s| (s.max(0.0) * 1e9 / period) as u64),
            to_tick: options
                .to_s
                .map_or(u64::MAX, |s| (s.max(0.0) * 1e9 / period).ceil() as u64),
            period_nanos,
        }
    }
}

/// Where a replay starts: the first step re-simulated and the tick before it (`None`: the
/// settled scene).
#[derive(Debug, Clone, Copy)]
struct Start {
    step: usize,
    previous_tick: Option<u64>,
}

/// A replay on one thread, step after step: what an observer (a rerun log, a viewer) or a
/// pace needs.
struct InOrder<'a> {
    rec: &'a Recording,
    meta: &'a SessionMeta,
    checks: &'a Checks<'a>,
    samples: &'a BTreeMap<u64, ServoSample>,
    window: Window,
}

impl InOrder<'_> {
    /// Re-simulates the recorded steps from `start` to the window's end (or the first
    /// divergence unless `keep_going`) on `stepper`, pacing them and showing the window's
    /// ticks and steps to the observer, counting into `report`.
    fn replay(
        &self,
        stepper: &mut SessionStepper,
        options: &mut ReplayOptions,
        start: Start,
        report: &mut ReplayReport,
    ) -> Result<(), RecorderError> {
        let (window, period) = (self.window, self.window.period_nanos as f64);
        let start_tick = start.previous_tick.map_or(0, |t| t + 1);
        let mut previous_tick = start.previous_tick;
        let mut play_started: Option<(Instant, u64)> = None;
        for (n, step) in self.rec.steps.iter().enumerate().skip(start.step) {
            in_order(n, step)?;
            if step.tick > window.to_tick {
                break;
            }
            let sample = sample_of(self.samples, step)?;
            let playing = step.tick >= window.from_tick;
            // a window's first step shows the tissue too, whatever the surface rate
            let first_played = playing && play_started.is_none();
            if playing {
                let (t0, tick0) = *play_started.get_or_insert((Instant::now(), step.tick));
                if let Some(Speed::Factor(f)) = options.speed {
                    let due =
                        Duration::from_secs_f64((step.tick - tick0) as f64 * period * 1e-9 / f);
                    if let Some(wait) = (t0 + due).checked_duration_since(Instant::now()) {
                        std::thread::sleep(wait);
                    }
                }
                if let Some(o) = options.observer.as_mut() {
                    let first = previous_tick
                        .map_or(step.tick, |t| t + 1)
                        .max(window.from_tick);
                    for (_, s) in self.samples.range(first..=step.tick) {
                        o.on_tick(s)?;
                    }
                }
            }
            previous_tick = Some(step.tick);
            let out = self.checks.step(stepper, step, sample, report);
            if playing && let Some(o) = options.observer.as_mut() {
                self.observe(o.as_mut(), stepper, step, out, first_played)?;
            }
            report.simulated_s = (step.tick + 1 - start_tick) as f64 * period * 1e-9;
            if report.first_divergence.is_some() && !options.keep_going {
                break;
            }
        }
        if let Some(o) = options.observer.take() {
            o.finish()?;
        }
        report.final_hash = stepper.state_hash();
        Ok(())
    }

    /// Shows the observer what step `step` did: the step, its cut, the surface when it is
    /// due (and on the window's first step), the keyframe where the recording has one.
    fn observe(
        &self,
        o: &mut dyn RecordObserver,
        stepper: &SessionStepper,
        step: &SimStepMsg,
        out: StepOutput,
        first_played: bool,
    ) -> Result<(), RecorderError> {
        o.on_sim(&SimRecord::Step {
            step: step.step,
            tick: step.tick,
            rejected: out.rejected,
        })?;
        if let Some((blade, event)) = out.cut {
            o.on_sim(&SimRecord::Cut {
                step: step.step,
                tick: step.tick,
                blade,
                event: Box::new(event),
            })?;
        }
        for damage in out.damage {
            o.on_sim(&SimRecord::Damage {
                step: step.step,
                tick: step.tick,
                damage,
            })?;
        }
        if first_played || surface_due(step.step, self.meta.surface_every_steps) {
            o.on_sim(&SimRecord::Surface(Box::new(SurfaceSnapshot::of(
                &stepper.collider,
                &stepper.sim.state.positions,
                step.step,
                step.tick,
            ))))?;
        }
        if self.checks.hashes.contains_key(&step.step) {
            o.on_sim(&SimRecord::Keyframe(Box::new(Keyframe::of(
                stepper, step.step, step.tick,
            ))))?;
        }
        Ok(())
    }
}

/// Replays the steps `range` in stretches that begin at the settled scene or `stepper`'s
/// state (the first) and at every resumable keyframe inside it (the others, each restored and
/// checked against its hashes), on up to `jobs` threads; each stretch is checked as a
/// sequential replay checks it. Returns the threads used and the stretches' reports in order,
/// up to the first that diverged unless `keep_going`.
#[allow(clippy::too_many_arguments)]
fn replay_in_parallel(
    rec: &Recording,
    meta: &SessionMeta,
    checks: &Checks<'_>,
    samples: &BTreeMap<u64, ServoSample>,
    stepper: SessionStepper,
    range: std::ops::Range<usize>,
    jobs: usize,
    keep_going: bool,
) -> Result<(usize, Vec<ReplayReport>), RecorderError> {
    use std::sync::Mutex;
    use std::sync::atomic::{AtomicUsize, Ordering};

    for (n, step) in rec
        .steps
        .iter()
        .enumerate()
        .take(range.end)
        .skip(range.start)
    {
        in_order(n, step)?;
    }
    // (first step, the keyframe it resumes at; None: the given stepper's state)
    let mut stretches: Vec<(usize, Option<&KeyframeMsg>)> = vec![(range.start, None)];
    for k in checks.keyframes.values() {
        let first = k.step as usize + 1;
        if k.resume.is_some() && first > range.start && first < range.end {
            stretches.push((first, Some(k)));
        }
    }
    let first_stepper = Mutex::new(Some(stepper));
    let next = AtomicUsize::new(0);
    let stop_after = AtomicUsize::new(usize::MAX);
    let run = || -> Result<Vec<(usize, ReplayReport)>, RecorderError> {
        let mut done = Vec::new();
        let mut own: Option<SessionStepper> = None;
        loop {
            let i = next.fetch_add(1, Ordering::Relaxed);
            if i >= stretches.len() || i > stop_after.load(Ordering::Relaxed) {
                return Ok(done);
            }
            let (first, keyframe) = stretches[i];
            let last = stretches.get(i + 1).map_or(range.end, |s| s.0);
            let mut report = ReplayReport::empty(StateHash {
                state: 0,
                topology: 0,
            });
            let mut taken = None;
            let stepper = match keyframe {
                None => {
                    taken = first_stepper
                        .lock()
                        .map_err(|_| RecorderError::Replay("a replay thread panicked".into()))?
                        .take();
                    taken.as_mut().ok_or_else(|| {
                        RecorderError::Replay("the first stretch was taken twice".into())
                    })?
                }
                Some(k) => {
                    let stepper = match own.as_mut() {
                        Some(s) => s,
                        None => own.insert(stepper_for(meta)?),
                    };
                    checks.resume(stepper, k, &mut report)?;
                    stepper
                }
            };
            if report.first_divergence.is_none() {
                for step in &rec.steps[first..last] {
                    checks.step(stepper, step, sample_of(samples, step)?, &mut report);
                    if report.first_divergence.is_some() && !keep_going {
                        break;
                    }
                }
            }
            let begun = first.checked_sub(1).map_or(0, |p| rec.steps[p].tick + 1);
            let ticks = rec.steps[first..last]
                .last()
                .map_or(0, |s| (s.tick + 1).saturating_sub(begun));
            report.simulated_s = ticks as f64 * meta.period_nanos as f64 * 1e-9;
            report.final_hash = stepper.state_hash();
            if report.first_divergence.is_some() && !keep_going {
                stop_after.fetch_min(i, Ordering::Relaxed);
            }
            done.push((i, report));
            // the first stretch's stepper is not reused: the others resume their own
            drop(taken);
        }
    };
    let threads = jobs.min(stretches.len());
    let results: Vec<Result<Vec<(usize, ReplayReport)>, RecorderError>> =
        std::thread::scope(|scope| {
            let workers: Vec<_> = (0..threads).map(|_| scope.spawn(run)).collect();
            workers
                .into_iter()
                .map(|w| {
                    w.join().unwrap_or_else(|_| {
                        Err(RecorderError::Replay("a replay thread panicked".into()))
                    })
                })
                .collect()
        });
    let mut parts = Vec::new();
    for r in results {
        parts.extend(r?);
    }
    parts.sort_by_key(|(i, _)| *i);
    let mut out = Vec::new();
    for (_, part) in parts {
        let diverged = part.first_divergence.is_some();
        out.push(part);
        if diverged && !keep_going {
            break;
        }
    }
    Ok((threads, out))
}
