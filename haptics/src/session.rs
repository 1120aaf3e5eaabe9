//! A session: the servo thread (1 kHz) and the simulation thread (fixed step) running
//! together, exchanging data only through lock-free structures:
//!
//! ```text
//! device ─pose─> servo thread ──ServoSample (rtrb queue)──> simulation thread
//!                     ^                                          │
//!                     └──ContactModel (triple buffer)────────────┘
//! ```
//!
//! Simulation step `n` consumes the sample of tick `(n + 1) * ticks_per_step - 1`: with the
//! virtual clock exactly that one (lock-step, so a run is reproducible bit for bit); with the
//! live clock the newest available (a simulation that fell behind skips ahead instead of
//! lagging further, and then runs fewer steps than the session has ticks). Which tick each step consumed is recorded (`tick_of_step`), so a replay
//! can feed the same inputs. The step applies the tool's reaction force to the tissue, cuts
//! when the renderer says the blade is in the tissue, advances the simulation, refits the
//! surface BVH (rebuilt after a cut) and publishes the contact model around the proxy.

use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::time::{Duration, Instant};

use cutlab_sim::scene::Scene;
use cutlab_sim::solver::{Simulation, StaticSettings};

use crate::collision::SurfaceCollider;
use crate::device::HapticDevice;
use crate::plan::Plan;
use crate::render::{ContactModel, ForceRenderer, RenderSettings, fault};
use crate::servo::{self, Clock, ServoConfig, ServoEvent, ServoLinks, ServoReport, ServoSample};
use crate::stepper::{SessionStepper, StepperStats};
use crate::tap::{Keyframe, RecordTap, SimRecord, SurfaceSnapshot};
use crate::{HapticsError, Point3, Vector3};

/// Settings of a session.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SessionConfig {
    /// Live (real time) or virtual (as fast as possible, the same ticks).
    pub clock: Clock,
    /// How long the session runs, in simulated seconds.
    pub duration_s: f64,
    /// Servo period (default 1 ms).
    pub period_nanos: u64,
    /// Force rendering; its force limits are lowered to the device's when those are lower.
    pub render: RenderSettings,
    /// Ask for real-time scheduling of the servo thread (live clock only).
    pub realtime_priority: bool,
    /// The servo spins (instead of sleeping) for the last this many nanoseconds before a
    /// tick's deadline.
    pub spin_nanos: u64,
    /// Length of the blade's cutting edge, m.
    pub blade_length_m: f64,
    /// A surface farther than this from the proxy gives no contact model, m.
    pub contact_reach_m: f64,
    /// Radius of the patch of surface the tool's reaction force is spread over, m.
    pub contact_patch_radius_m: f64,
    /// The blade cuts again once its tip moved this far since its last cut (tremor-sized
    /// zig-zags make degenerate swept polygons), m.
    pub cut_step_m: f64,
    /// Capacity of the servo-to-simulation queue, samples.
    pub queue_capacity: usize,
    /// The surface's BVH is built again every this many simulation steps instead of refitted
    /// (0: only after cuts). A recording's keyframes at these steps can be resumed (see
    /// [`crate::stepper::SessionStepper::resume_state`]); `cutlab session` sets it to the
    /// keyframe interval.
    pub collider_rebuild_every_steps: u64,
}

impl Default for SessionConfig {
    fn default() -> Self {
        Self {
            clock: Clock::Virtual,
            duration_s: 10.0,
            period_nanos: 1_000_000,
            render: RenderSettings::default(),
            realtime_priority: true,
            spin_nanos: 200_000,
            blade_length_m: 0.02,
            contact_reach_m: 0.02,
            contact_patch_radius_m: 0.005,
            cut_step_m: 0.0005,
            queue_capacity: 8192,
            collider_rebuild_every_steps: 1000,
        }
    }
}

/// What a session did.
#[derive(Debug)]
pub struct SessionReport {
    /// What the servo thread measured.
    pub servo: ServoReport,
    /// The servo period, ns.
    pub period_nanos: u64,
    /// Servo ticks per simulation step.
    pub ticks_per_step: u64,
    /// Simulation steps taken.
    pub sim_steps: u64,
    /// The servo tick each simulation step consumed.
    pub tick_of_step: Vec<u64>,
    /// Work of each simulation step (contact, cut, step, refit), ns.
    pub step_nanos: Vec<u64>,
    /// Cuts, cut length, rejected steps, solver iterations.
    pub stats: StepperStats,
    /// Times the surface's BVH was built again (instead of refitted).
    pub collider_rebuilds: u64,
    /// Triangles of the tissue surface at the end.
    pub surface_triangles: usize,
    /// The simulation at the end.
    pub simulation: Simulation,
    /// Hash of the final state's bits.
    pub state_hash: u64,
    /// Wall-clock time the session took, s.
    pub wall_s: f64,
}

impl SessionReport {
    /// Simulated seconds per wall-clock second.
    pub fn speed(&self) -> f64 {
        self.servo.ticks as f64 * self.period_nanos as f64 * 1e-9 / self.wall_s.max(1e-12)
    }

    /// The most ticks a step's sample was taken after the step's own tick (a live simulation
    /// that fell behind skips ahead; 0 on the virtual clock).
    pub fn largest_skip_ahead_ticks(&self) -> u64 {
        self.tick_of_step
            .iter()
            .zip(0u64..)
            .map(|(&t, n)| t.saturating_sub(own_tick(n, self.ticks_per_step)))
            .max()
            .unwrap_or(0)
    }
}

/// Simulation step `n`'s own servo tick (the last of its `ticks_per_step`).
fn own_tick(n: u64, ticks_per_step: u64) -> u64 {
    (n + 1) * ticks_per_step - 1
}

/// The devices a session's hands hold: the scalpel's, and for a second hand a grasper's, read
/// and written in the same servo tick, its jaws holding the tissue while closed
/// ([`crate::stepper`]).
#[allow(missing_debug_implementations)] // devices are not `Debug`
pub struct Hands {
    /// The scalpel's device.
    pub scalpel: Box<dyn HapticDevice>,
    /// The grasper's device, in a two-handed session.
    pub grasper: Option<Box<dyn HapticDevice>>,
}

impl<D: HapticDevice + 'static> From<Box<D>> for Hands {
    /// One hand, on the scalpel.
    fn from(scalpel: Box<D>) -> Self {
        Self {
            scalpel,
            grasper: None,
        }
    }
}

impl From<Box<dyn HapticDevice>> for Hands {
    /// One hand, on the scalpel.
    fn from(scalpel: Box<dyn HapticDevice>) -> Self {
        Self {
            scalpel,
            grasper: None,
        }
    }
}

/// A scene ready for a session: settled, with its surface collider.
#[derive(Debug)]
pub struct Session {
    /// The settled simulation.
    pub sim: Simulation,
    collider: SurfaceCollider,
}

impl Session {
    /// Settles `scene` under its pre-tension and builds the surface collider.
    pub fn new(scene: &Scene) -> Result<Self, HapticsError> {
        let mut sim = scene.simulation();
        let report = sim.settle(StaticSettings::default());
        if !report.residual_newtons.is_finite() {
            return Err(HapticsError::Simulation(format!(
                "settling the scene failed: {report:?}"
            )));
        }
        // a residual under a nanonewton is round-off on a light tissue (the gauze's), not a
        // tissue still moving: nothing a hand or a score could tell
        if !report.converged && report.residual_newtons > 1e-9 {
            tracing::warn!(
                "settling stopped after {} Newton iterations at a residual of {:.1e} N (tolerance {:.1e} N); starting from there",
                report.newton_iterations,
                report.residual_newtons,
                report.tolerance_newtons
            );
        }
        let collider = SurfaceCollider::build(&sim)?;
        Ok(Self { sim, collider })
    }

    /// The tissue surface's collider, built on the settled state.
    pub fn collider(&self) -> &SurfaceCollider {
        &self.collider
    }

    /// The settled simulation and its collider.
    pub fn into_parts(self) -> (Simulation, SurfaceCollider) {
        (self.sim, self.collider)
    }

    /// A straight incision of `length_m` across the top of the tissue (along x, through the
    /// middle of its bounding box), projected onto the surface, cut `depth_m` deep.
    pub fn plan_across_top(&self, length_m: f64, depth_m: f64) -> Result<Plan, HapticsError> {
        self.plan_across(&Vector3::z(), &Vector3::x(), length_m, depth_m)
    }

    /// A straight incision of `length_m` (at most 60 % of the body's extent) along the unit
    /// direction `along`, through the middle of the body, on the surface facing the unit
    /// direction `up`: the line is drawn 10 mm beyond the body's outermost point along `up`,
    /// and each of its points dropped along `-up` onto the surface, cut `depth_m` deep.
    pub fn plan_across(
        &self,
        up: &Vector3,
        along: &Vector3,
        length_m: f64,
        depth_m: f64,
    ) -> Result<Plan, HapticsError> {
        let x = &self.sim.state.positions;
        let (lo, hi) = cutlab_sim::mesh::bounding_box(x);
        let centre = nalgebra::center(&lo, &hi);
        let (mut min_along, mut max_along, mut outermost, mut innermost) =
            (0.0_f64, 0.0_f64, 0.0_f64, 0.0_f64);
        for p in x {
            let (s, h) = ((p - centre).dot(along), (p - centre).dot(up));
            (min_along, max_along) = (min_along.min(s), max_along.max(s));
            (innermost, outermost) = (innermost.min(h), outermost.max(h));
        }
        let length = length_m.min(0.6 * (max_along - min_along));
        let samples = 33;
        let drop_m = outermost - innermost + 0.02;
        let on_surface = (0..samples)
            .map(|i| {
                let u = i as f64 / (samples - 1) as f64 - 0.5;
                let above = centre + along * (u * length) + up * (outermost + 0.01);
                self.collider.cast(&above, &-up, drop_m).ok_or_else(|| {
                    HapticsError::Surface(format!(
                        "no surface under ({:.1}, {:.1}, {:.1}) mm",
                        above.x * 1e3,
                        above.y * 1e3,
                        above.z * 1e3
                    ))
                })
            })
            .collect::<Result<Vec<_>, _>>()?;
        self.plan_along(&on_surface, up, depth_m)
    }

    /// An incision through the surface points closest to `points_m` (entry first), on a
    /// surface facing `up` (within 60 degrees), cut `depth_m` deep: how a synthetic trainee
    /// follows an exercise's expert plan.
    pub fn plan_along(
        &self,
        points_m: &[Point3],
        up: &Vector3,
        depth_m: f64,
    ) -> Result<Plan, HapticsError> {
        let mut line_m = Vec::with_capacity(points_m.len());
        let mut normals = Vec::with_capacity(points_m.len());
        for p in points_m {
            let hit = self
                .collider
                .closest(p)
                .ok_or_else(|| HapticsError::Surface("no surface near the plan".into()))?;
            if hit.normal.dot(up) < 0.5 {
                return Err(HapticsError::Surface(format!(
                    "no surface facing the plan's normal near ({:.1}, {:.1}, {:.1}) mm",
                    p.x * 1e3,
                    p.y * 1e3,
                    p.z * 1e3
                )));
            }
            line_m.push(hit.point);
            normals.push(hit.normal);
        }
        let plan = Plan {
            line_m,
            normals,
            depth_m,
            approach_height_m: 0.015,
            viewpoint_m: None,
        };
        plan.check()?;
        Ok(plan)
    }

    /// Runs the session with `device` until `config.duration_s` has passed on the clock.
    pub fn run(
        self,
        device: Box<dyn HapticDevice>,
        config: &SessionConfig,
    ) -> Result<SessionReport, HapticsError> {
        self.run_recorded(device, config, None)
    }

    /// `config` checked against this session's step: the force rendering within the device's
    /// `limits`, the simulation step in servo ticks and the session's ticks.
    fn checked(
        &self,
        config: &SessionConfig,
        limits: crate::device::DeviceLimits,
    ) -> Result<(RenderSettings, u64, u64), HapticsError> {
        let mut render = config.render;
        render.limits.max_force_newtons = render
            .limits
            .max_force_newtons
            .min(limits.max_force_newtons);
        render.limits.max_force_rate_newtons_per_s = render
            .limits
            .max_force_rate_newtons_per_s
            .min(limits.max_force_rate_newtons_per_s);
        render.period_s = config.period_nanos as f64 * 1e-9;
        render.check()?;
        if !(config.duration_s > 0.0 && config.duration_s <= 86_400.0) {
            return Err(HapticsError::Config(format!(
                "duration must be in (0, 86400] s, got {}",
                config.duration_s
            )));
        }
        if !(100_000..=100_000_000).contains(&config.period_nanos) {
            return Err(HapticsError::Config(format!(
                "servo period must be 0.1 to 100 ms, got {} ns",
                config.period_nanos
            )));
        }
        if !(config.blade_length_m > 0.0
            && config.contact_reach_m > 0.0
            && config.contact_patch_radius_m > 0.0)
            || config.queue_capacity < 2
        {
            return Err(HapticsError::Config(
                "blade length, contact reach, patch radius and queue capacity must be positive"
                    .into(),
            ));
        }
        let time_step_nanos = (self.sim.settings.time_step_s * 1e9).round() as u64;
        let ticks_per_step = (time_step_nanos / config.period_nanos).max(1);
        if ticks_per_step * config.period_nanos != time_step_nanos {
            return Err(HapticsError::Config(format!(
                "the simulation step ({} ns) must be a whole number of servo periods ({} ns)",
                time_step_nanos, config.period_nanos
            )));
        }
        let ticks = (config.duration_s * 1e9 / config.period_nanos as f64).round() as u64;
        Ok((render, ticks_per_step, ticks))
    }

    /// [`Self::run`] with `hands` (the scalpel's device, or it and a grasper's), handing every
    /// tick and every simulation record to `tap` (a recorder).
    pub fn run_recorded(
        self,
        hands: impl Into<Hands>,
        config: &SessionConfig,
        tap: Option<RecordTap>,
    ) -> Result<SessionReport, HapticsError> {
        let Hands {
            scalpel: device,
            grasper,
        } = hands.into();
        let (render, ticks_per_step, ticks) = self.checked(config, device.limits())?;

        let (contact_in, contact_out) = triple_buffer::triple_buffer(&ContactModel::default());
        let (mut samples_in, mut samples_out) = rtrb::RingBuffer::new(config.queue_capacity);
        // Touch every slot of the queue once now, so the servo loop never page-faults on it.
        while samples_in.push(ServoSample::default()).is_ok() {}
        while samples_out.pop().is_ok() {}
        let (events_in, events_out) = rtrb::RingBuffer::new(1024);
        let sim_ticks_done = Arc::new(AtomicU64::new(0));
        let abort = Arc::new(AtomicBool::new(false));
        let (record_ticks, record_sim) = match tap {
            Some(t) => (Some(t.ticks), Some((t.sim, t.settings))),
            None => (None, None),
        };
        let links = ServoLinks {
            contact: contact_out,
            samples: samples_in,
            events: events_in,
            sim_ticks_done: sim_ticks_done.clone(),
            abort: abort.clone(),
            record: record_ticks,
        };
        let servo_config = ServoConfig {
            clock: config.clock,
            period_nanos: config.period_nanos,
            ticks,
            spin_nanos: config.spin_nanos,
            realtime_priority: config.realtime_priority,
            ticks_per_step,
        };
        tracing::info!(
            "session: {} on the {} clock, {ticks} ticks of {} us, simulation step {} ticks, {} surface triangles",
            device.name(),
            if config.clock == Clock::Live {
                "live"
            } else {
                "virtual"
            },
            config.period_nanos / 1000,
            ticks_per_step,
            self.collider.triangle_count()
        );

        let started = Instant::now();
        let worker = SimWorker {
            stepper: SessionStepper::new(self, config),
            contact: contact_in,
            samples: samples_out,
            events: events_out,
            sim_ticks_done,
            clock: config.clock,
            ticks_per_step,
            period_nanos: config.period_nanos,
            record: record_sim,
        };
        let sim_abort = abort.clone();
        let sim_thread = std::thread::Builder::new()
            .name("cutlab-sim".into())
            .spawn(move || {
                let _guard = AbortOnExit(sim_abort);
                worker.run(ticks)
            })
            .map_err(|source| HapticsError::Thread {
                name: "cutlab-sim",
                source,
            })?;
        let servo_thread = match servo::spawn(
            servo_config,
            device,
            grasper,
            ForceRenderer::new(render).with_blade_length(config.blade_length_m),
            links,
        ) {
            Ok(t) => t,
            Err(source) => {
                abort.store(true, Ordering::Release);
                let _ = sim_thread.join();
                return Err(HapticsError::Thread {
                    name: "cutlab-servo",
                    source,
                });
            }
        };
        let servo_result = servo_thread.join();
        if servo_result.is_err() {
            abort.store(true, Ordering::Release);
        }
        let sim_result = sim_thread.join();
        let (servo, _device) = servo_result.map_err(|_| HapticsError::Panicked("cutlab-servo"))?;
        let outcome = sim_result.map_err(|_| HapticsError::Panicked("cutlab-sim"))?;
        let wall_s = started.elapsed().as_secs_f64();
        Ok(SessionReport {
            period_nanos: config.period_nanos,
            ticks_per_step,
            sim_steps: outcome.tick_of_step.len() as u64,
            tick_of_step: outcome.tick_of_step,
            step_nanos: outcome.step_nanos,
            stats: outcome.stepper.stats,
            collider_rebuilds: outcome.stepper.collider.rebuilds,
            surface_triangles: outcome.stepper.collider.triangle_count(),
            state_hash: outcome.stepper.sim.state.bit_hash(),
            simulation: outcome.stepper.sim,
            servo,
            wall_s,
        })
    }
}

struct AbortOnExit(Arc<AtomicBool>);

impl Drop for AbortOnExit {
    fn drop(&mut self) {
        self.0.store(true, Ordering::Release);
    }
}

struct SimWorker {
    stepper: SessionStepper,
    contact: triple_buffer::Input<ContactModel>,
    samples: rtrb::Consumer<ServoSample>,
    events: rtrb::Consumer<ServoEvent>,
    sim_ticks_done: Arc<AtomicU64>,
    clock: Clock,
    ticks_per_step: u64,
    period_nanos: u64,
    /// The recorder's queue and what to record (None: not recording, or the recorder quit).
    record: Option<(rtrb::Producer<SimRecord>, crate::tap::TapSettings)>,
}

struct SimOutcome {
    stepper: SessionStepper,
    tick_of_step: Vec<u64>,
    step_nanos: Vec<u64>,
}

impl SimWorker {
    fn log_events(&mut self) {
        while let Ok(e) = self.events.pop() {
            let ms = |tick: u64| tick as f64 * self.period_nanos as f64 * 1e-6;
            match e {
                ServoEvent::FaultBegan { tick, faults } => {
                    tracing::warn!(
                        "servo: {} at tick {tick} ({:.0} ms); fading the force out",
                        fault::describe(faults),
                        ms(tick)
                    )
                }
                ServoEvent::FaultCleared { tick } => tracing::info!(
                    "servo: fault cleared at tick {tick} ({:.0} ms); force ramps back in",
                    ms(tick)
                ),
                ServoEvent::FadedOut { tick } => {
                    tracing::warn!("servo: force faded to zero at tick {tick}")
                }
            }
        }
    }

    /// The sample for a step whose last tick is `target` (None: the servo loop has ended).
    fn next_sample(
        &mut self,
        target: u64,
        latest: &mut Option<ServoSample>,
    ) -> Option<ServoSample> {
        let mut backoff = servo::Backoff::default();
        loop {
            while let Ok(s) = self.samples.pop() {
                *latest = Some(s);
            }
            if let Some(s) = *latest
                && s.tick >= target
            {
                return Some(s);
            }
            if self.samples.is_abandoned() && self.samples.is_empty() {
                return None;
            }
            self.log_events();
            match self.clock {
                Clock::Virtual => backoff.wait(),
                Clock::Live => std::thread::sleep(Duration::from_micros(50)),
            }
        }
    }

    fn run(mut self, ticks: u64) -> SimOutcome {
        let steps = (ticks / self.ticks_per_step) as usize;
        let mut out_ticks = Vec::with_capacity(steps);
        let mut out_nanos = Vec::with_capacity(steps);
        let mut latest = None;
        for n in 0..steps as u64 {
            // The step's own tick; once a lagging live simulation skipped ahead, the tick
            // after the last one consumed (never the same tick twice).
            let own = own_tick(n, self.ticks_per_step);
            let target = match out_ticks.last() {
                Some(&last) => own.max(last + self.ticks_per_step),
                None => own,
            };
            let Some(sample) = self.next_sample(target, &mut latest) else {
                break;
            };
            let began = Instant::now();
            let out = self.stepper.step(&sample);
            self.contact.write(out.contact);
            self.sim_ticks_done
                .store(sample.tick + 1, Ordering::Release);
            out_ticks.push(sample.tick);
            out_nanos.push(began.elapsed().as_nanos() as u64);
            let last = n + 1 == steps as u64;
            self.record(n, &sample, out, last);
            self.log_events();
        }
        if let Some(&tick) = out_ticks.last()
            && out_ticks.len() < steps
            && self.record.is_some()
        {
            // ended early (the servo loop stopped): the state there is a keyframe too, one
            // that can be resumed
            let n = out_ticks.len() as u64 - 1;
            self.stepper.rebuild_to_end();
            self.push(SimRecord::Keyframe(Box::new(Keyframe::of(
                &self.stepper,
                n,
                tick,
            ))));
        }
        self.log_events();
        SimOutcome {
            stepper: self.stepper,
            tick_of_step: out_ticks,
            step_nanos: out_nanos,
        }
    }

    /// Hands step `n`'s records to the recorder, if one listens.
    fn record(
        &mut self,
        n: u64,
        sample: &ServoSample,
        out: crate::stepper::StepOutput,
        last: bool,
    ) {
        let crate::stepper::StepOutput {
            cut,
            rejected,
            damage,
            ..
        } = out;
        let Some((_, settings)) = &self.record else {
            return;
        };
        let settings = *settings;
        let tick = sample.tick;
        self.push(SimRecord::Step {
            step: n,
            tick,
            rejected,
        });
        if let Some((blade, event)) = cut {
            self.push(SimRecord::Cut {
                step: n,
                tick,
                blade,
                event: Box::new(event),
            });
        }
        for damage in damage {
            self.push(SimRecord::Damage {
                step: n,
                tick,
                damage,
            });
        }
        let every = |k: u64| k > 0 && (n + 1).is_multiple_of(k);
        if crate::tap::surface_due(n, settings.surface_every_steps) {
            let s = SurfaceSnapshot::of(
                &self.stepper.collider,
                &self.stepper.sim.state.positions,
                n,
                tick,
            );
            self.push(SimRecord::Surface(Box::new(s)));
        }
        if every(settings.keyframe_every_steps.max(1)) || last {
            if last {
                self.stepper.rebuild_to_end();
            }
            self.push(SimRecord::Keyframe(Box::new(Keyframe::of(
                &self.stepper,
                n,
                tick,
            ))));
        }
    }

    fn push(&mut self, record: SimRecord) {
        if let Some((queue, _)) = &mut self.record
            && !RecordTap::push_sim(queue, record)
        {
            tracing::error!("the recorder stopped taking records; the session goes on unrecorded");
            self.record = None;
        }
    }
}
