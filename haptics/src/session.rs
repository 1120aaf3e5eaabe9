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

use cutlab_sim::cut::{self, CutError, Cutter};
use cutlab_sim::scene::Scene;
use cutlab_sim::solver::{Simulation, StaticSettings};

use crate::collision::{SurfaceCollider, SurfaceHit};
use crate::device::{HapticDevice, Plan};
use crate::render::{ContactModel, ForceRenderer, Mode, RenderSettings, fault};
use crate::servo::{self, Clock, ServoConfig, ServoEvent, ServoLinks, ServoReport, ServoSample};
use crate::{HapticsError, Point3};

/// Settings of a session.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SessionConfig {
    pub clock: Clock,
    pub duration_s: f64,
    /// Servo period (default 1 ms).
    pub period_nanos: u64,
    /// Force rendering; its force limits are lowered to the device's when those are lower.
    pub render: RenderSettings,
    pub realtime_priority: bool,
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
        }
    }
}

/// What a session did.
#[derive(Debug)]
pub struct SessionReport {
    pub servo: ServoReport,
    pub period_nanos: u64,
    pub sim_steps: u64,
    /// The servo tick each simulation step consumed.
    pub tick_of_step: Vec<u64>,
    /// Work of each simulation step (contact, cut, step, refit), ns.
    pub step_nanos: Vec<u64>,
    /// Steps whose cut changed the tissue, tetrahedra split, cuts skipped as unresolved and
    /// cuts that failed.
    pub cut_steps: u64,
    /// Length of the blade tip's path while it cut (sampled every `cut_step_m`), m.
    pub cut_length_m: f64,
    pub tets_split: u64,
    pub unresolved_cuts: u64,
    pub failed_cuts: u64,
    /// Steps the simulation rejected (non-finite state).
    pub rejected_steps: u64,
    /// Conjugate-gradient iterations of the implicit solver over all steps.
    pub cg_iterations: u64,
    pub collider_rebuilds: u64,
    pub surface_triangles: usize,
    /// The simulation at the end.
    pub simulation: Simulation,
    /// Hash of the final state's bits.
    pub state_hash: u64,
    pub wall_s: f64,
}

impl SessionReport {
    /// Simulated seconds per wall-clock second.
    pub fn speed(&self) -> f64 {
        self.servo.ticks as f64 * self.period_nanos as f64 * 1e-9 / self.wall_s.max(1e-12)
    }
}

/// A scene ready for a session: settled, with its surface collider.
#[derive(Debug)]
pub struct Session {
    pub sim: Simulation,
    collider: SurfaceCollider,
}

impl Session {
    /// Settles `scene` under its pre-tension and builds the surface collider.
    pub fn new(scene: &Scene) -> Result<Self, HapticsError> {
        let mut sim = scene.simulation();
        let report = sim.settle(StaticSettings::default());
        if !report.residual_newtons.is_finite() {
            return Err(HapticsError::Simulation(format!("settling the scene failed: {report:?}")));
        }
        if !report.converged {
            tracing::warn!(
                "settling stopped after {} Newton iterations at a residual of {:.1e} N (tolerance {:.1e} N); starting from there",
                report.newton_iterations, report.residual_newtons, report.tolerance_newtons
            );
        }
        let collider = SurfaceCollider::build(&sim)?;
        Ok(Self { sim, collider })
    }

    pub fn collider(&self) -> &SurfaceCollider {
        &self.collider
    }

    /// A straight incision of `length_m` across the top of the tissue (along x, through the
    /// middle of its bounding box), projected onto the surface, cut `depth_m` deep.
    pub fn plan_across_top(&self, length_m: f64, depth_m: f64) -> Result<Plan, HapticsError> {
        let x = &self.sim.state.positions;
        let (mut lo, mut hi) = (x[0], x[0]);
        for p in x {
            lo = lo.inf(p);
            hi = hi.sup(p);
        }
        let centre = nalgebra::center(&lo, &hi);
        let length = length_m.min(0.6 * (hi.x - lo.x));
        let samples = 33;
        let mut line_m = Vec::with_capacity(samples);
        let mut normals = Vec::with_capacity(samples);
        for i in 0..samples {
            let u = i as f64 / (samples - 1) as f64 - 0.5;
            let above = Point3::new(centre.x + u * length, centre.y, hi.z + 0.01);
            let hit = self.collider.closest(&above).ok_or_else(|| HapticsError::Surface("no surface below the plan".into()))?;
            if hit.normal.z < 0.5 {
                return Err(HapticsError::Surface(format!("no upward-facing surface at x = {:.1} mm", above.x * 1e3)));
            }
            line_m.push(hit.point);
            normals.push(hit.normal);
        }
        let plan = Plan { line_m, normals, depth_m, approach_height_m: 0.015 };
        plan.check()?;
        Ok(plan)
    }

    /// Runs the session with `device` until `config.duration_s` has passed on the clock.
    pub fn run(self, device: Box<dyn HapticDevice>, config: &SessionConfig) -> Result<SessionReport, HapticsError> {
        let mut render = config.render;
        let limits = device.limits();
        render.limits.max_force_newtons = render.limits.max_force_newtons.min(limits.max_force_newtons);
        render.limits.max_force_rate_newtons_per_s = render.limits.max_force_rate_newtons_per_s.min(limits.max_force_rate_newtons_per_s);
        render.period_s = config.period_nanos as f64 * 1e-9;
        render.check().map_err(HapticsError::Config)?;
        if !(config.duration_s > 0.0 && config.duration_s <= 86_400.0) {
            return Err(HapticsError::Config(format!("duration must be in (0, 86400] s, got {}", config.duration_s)));
        }
        if !(100_000..=100_000_000).contains(&config.period_nanos) {
            return Err(HapticsError::Config(format!("servo period must be 0.1 to 100 ms, got {} ns", config.period_nanos)));
        }
        if !(config.blade_length_m > 0.0 && config.contact_reach_m > 0.0 && config.contact_patch_radius_m > 0.0) || config.queue_capacity < 2 {
            return Err(HapticsError::Config("blade length, contact reach, patch radius and queue capacity must be positive".into()));
        }
        let dt_nanos = (self.sim.settings.time_step_s * 1e9).round() as u64;
        let ticks_per_step = (dt_nanos / config.period_nanos).max(1);
        if ticks_per_step * config.period_nanos != dt_nanos {
            return Err(HapticsError::Config(format!(
                "the simulation step ({} ns) must be a whole number of servo periods ({} ns)",
                dt_nanos, config.period_nanos
            )));
        }
        let ticks = (config.duration_s * 1e9 / config.period_nanos as f64).round() as u64;

        let (contact_in, contact_out) = triple_buffer::triple_buffer(&ContactModel::default());
        let (mut samples_in, mut samples_out) = rtrb::RingBuffer::new(config.queue_capacity);
        // Touch every slot of the queue once now, so the servo loop never page-faults on it.
        while samples_in.push(ServoSample::default()).is_ok() {}
        while samples_out.pop().is_ok() {}
        let (events_in, events_out) = rtrb::RingBuffer::new(1024);
        let sim_ticks_done = Arc::new(AtomicU64::new(0));
        let abort = Arc::new(AtomicBool::new(false));
        let links = ServoLinks { contact: contact_out, samples: samples_in, events: events_in, sim_ticks_done: sim_ticks_done.clone(), abort: abort.clone() };
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
            if config.clock == Clock::Live { "live" } else { "virtual" },
            config.period_nanos / 1000,
            ticks_per_step,
            self.collider.triangle_count()
        );

        let started = Instant::now();
        let worker = SimWorker {
            sim: self.sim,
            collider: self.collider,
            cutter: Cutter::default(),
            contact: contact_in,
            samples: samples_out,
            events: events_out,
            sim_ticks_done,
            clock: config.clock,
            ticks_per_step,
            blade_length_m: config.blade_length_m,
            reach_m: config.contact_reach_m,
            patch_radius_m: config.contact_patch_radius_m,
            patch: Vec::new(),
            cut_step_m: config.cut_step_m,
            period_nanos: config.period_nanos,
        };
        let sim_abort = abort.clone();
        let sim_thread = std::thread::Builder::new()
            .name("cutlab-sim".into())
            .spawn(move || {
                let _guard = AbortOnExit(sim_abort);
                worker.run(ticks)
            })
            .map_err(|source| HapticsError::Thread { name: "cutlab-sim", source })?;
        let servo_thread = match servo::spawn(servo_config, device, ForceRenderer::new(render), links) {
            Ok(t) => t,
            Err(source) => {
                abort.store(true, Ordering::Release);
                let _ = sim_thread.join();
                return Err(HapticsError::Thread { name: "cutlab-servo", source });
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
            sim_steps: outcome.tick_of_step.len() as u64,
            tick_of_step: outcome.tick_of_step,
            step_nanos: outcome.step_nanos,
            cut_steps: outcome.cut_steps,
            cut_length_m: outcome.cut_length_m,
            tets_split: outcome.tets_split,
            unresolved_cuts: outcome.unresolved_cuts,
            failed_cuts: outcome.failed_cuts,
            rejected_steps: outcome.rejected_steps,
            cg_iterations: outcome.cg_iterations,
            collider_rebuilds: outcome.collider.rebuilds,
            surface_triangles: outcome.collider.triangle_count(),
            state_hash: outcome.sim.state.bit_hash(),
            simulation: outcome.sim,
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
    sim: Simulation,
    collider: SurfaceCollider,
    cutter: Cutter,
    contact: triple_buffer::Input<ContactModel>,
    samples: rtrb::Consumer<ServoSample>,
    events: rtrb::Consumer<ServoEvent>,
    sim_ticks_done: Arc<AtomicU64>,
    clock: Clock,
    ticks_per_step: u64,
    blade_length_m: f64,
    reach_m: f64,
    patch_radius_m: f64,
    patch: Vec<(u32, f64)>,
    cut_step_m: f64,
    period_nanos: u64,
}

struct SimOutcome {
    sim: Simulation,
    collider: SurfaceCollider,
    tick_of_step: Vec<u64>,
    step_nanos: Vec<u64>,
    cut_steps: u64,
    cut_length_m: f64,
    tets_split: u64,
    unresolved_cuts: u64,
    failed_cuts: u64,
    rejected_steps: u64,
    cg_iterations: u64,
}

impl SimWorker {
    fn log_events(&mut self) {
        while let Ok(e) = self.events.pop() {
            let ms = |tick: u64| tick as f64 * self.period_nanos as f64 * 1e-6;
            match e {
                ServoEvent::FaultBegan { tick, faults } => {
                    tracing::warn!("servo: {} at tick {tick} ({:.0} ms); fading the force out", fault::describe(faults), ms(tick))
                }
                ServoEvent::FaultCleared { tick } => tracing::info!("servo: fault cleared at tick {tick} ({:.0} ms); force ramps back in", ms(tick)),
                ServoEvent::FadedOut { tick } => tracing::warn!("servo: force faded to zero at tick {tick}"),
            }
        }
    }

    /// The sample for a step whose last tick is `target` (None: the servo loop has ended).
    fn next_sample(&mut self, target: u64, latest: &mut Option<ServoSample>) -> Option<ServoSample> {
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
        let (mut cut_steps, mut tets_split, mut unresolved, mut failed, mut rejected) = (0, 0, 0, 0, 0);
        let mut cut_length = 0.0;
        let mut cg_iterations = 0u64;
        let mut latest = None;
        let mut last_hit: Option<SurfaceHit> = None;
        let mut last_cut_tip: Option<Point3> = None;
        for n in 0..steps as u64 {
            // The step's own tick; once a lagging live simulation skipped ahead, the tick
            // after the last one consumed (never the same tick twice).
            let own = (n + 1) * self.ticks_per_step - 1;
            let target = match out_ticks.last() {
                Some(&last) => own.max(last + self.ticks_per_step),
                None => own,
            };
            let Some(sample) = self.next_sample(target, &mut latest) else { break };
            let began = Instant::now();
            let render = sample.render;

            // The tool's reaction on the tissue, spread over the contact patch around the
            // touched point (weights (1 - r / R)^2 over the surface particles within R).
            self.sim.clear_external_forces();
            if render.mode == Mode::Touching
                && let Some(hit) = &last_hit
            {
                self.patch.clear();
                let mut total = 0.0;
                let x = &self.sim.state.positions;
                for &v in self.collider.vertex_ids() {
                    let r = (x[v as usize] - hit.point).norm();
                    if r < self.patch_radius_m && !self.sim.model.held[v as usize] {
                        let w = (1.0 - r / self.patch_radius_m).powi(2);
                        self.patch.push((v, w));
                        total += w;
                    }
                }
                if total > 0.0 {
                    let f = self.sim.external_forces_mut();
                    for &(v, w) in &self.patch {
                        f[v as usize] -= render.force_newtons * (w / total);
                    }
                }
            }

            // Cutting while the renderer says the blade is in the tissue.
            let moved_enough = |last: &Option<Point3>| last.is_none_or(|p| (sample.pose.tip_in_world - p).norm() >= self.cut_step_m);
            if render.mode == Mode::Cutting && moved_enough(&last_cut_tip) {
                if let Some(p) = last_cut_tip {
                    cut_length += (sample.pose.tip_in_world - p).norm();
                }
                last_cut_tip = Some(sample.pose.tip_in_world);
                let blade = cut::Blade { tip: sample.pose.tip_in_world, edge_direction: sample.pose.edge_direction(), depth_m: self.blade_length_m };
                match self.cutter.advance(&mut self.sim, blade) {
                    Ok(ev) if !ev.is_empty() => {
                        cut_steps += 1;
                        tets_split += ev.tets_removed.len() as u64;
                        if let Err(e) = self.collider.rebuild(&self.sim) {
                            tracing::error!("rebuilding the surface after a cut failed: {e}");
                        }
                    }
                    Ok(_) => {}
                    Err(CutError::Unresolved(_)) => unresolved += 1,
                    Err(e) => {
                        failed += 1;
                        tracing::warn!("cut failed at tick {}: {e}; stroke ended", sample.tick);
                        self.cutter.end_stroke();
                    }
                }
            } else if render.mode != Mode::Cutting && self.cutter.in_stroke() {
                self.cutter.end_stroke();
                last_cut_tip = None;
            }

            let stepped = self.sim.step();
            if let Ok(report) = &stepped {
                cg_iterations += report.cg_iterations as u64;
            }
            if let Err(e) = stepped {
                rejected += 1;
                // the first, then every hundredth: a diverging model would flood the log
                if rejected % 100 == 1 {
                    tracing::warn!("simulation step at tick {} rejected ({rejected} so far): {e}", sample.tick);
                }
            }
            self.collider.refit(&self.sim.state.positions);
            let (model, hit) = self.collider.contact_model(&self.sim, &render.proxy, self.reach_m, sample.tick);
            last_hit = hit;
            if sample.tick % 100 == 0 {
                tracing::debug!(
                    "tick {} mode {:?} force {:.3} N stiffness {:.0} N/m tip z {:.2} mm plane z {:.2} mm",
                    sample.tick, render.mode, render.force_newtons.norm(), model.stiffness_newtons_per_m,
                    sample.pose.tip_in_world.z * 1e3, model.plane_point.z * 1e3
                );
            }
            self.contact.write(model);
            self.sim_ticks_done.store(sample.tick + 1, Ordering::Release);
            out_ticks.push(sample.tick);
            out_nanos.push(began.elapsed().as_nanos() as u64);
            self.log_events();
        }
        self.log_events();
        SimOutcome {
            sim: self.sim,
            collider: self.collider,
            tick_of_step: out_ticks,
            step_nanos: out_nanos,
            cut_steps,
            cut_length_m: cut_length,
            tets_split,
            unresolved_cuts: unresolved,
            failed_cuts: failed,
            rejected_steps: rejected,
            cg_iterations,
        }
    }
}
