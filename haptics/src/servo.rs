//! The servo loop: a dedicated, named thread ticking at 1 kHz.
//!
//! Each tick reads the device, renders the force from the latest contact model (a triple
//! buffer the simulation writes), writes the force to the device and pushes the tick's sample
//! to the simulation thread (a bounded lock-free queue). Nothing in the loop allocates, locks
//! or blocks: the buffers for the statistics are allocated before the first tick, and log
//! messages go through a lock-free queue to the simulation thread, which logs them.
//!
//! Clocks:
//! - live: tick `k` starts at `start + k * period`; the thread sleeps until `spin_nanos`
//!   before the deadline, then spins; it asks for real-time priority (SCHED_FIFO) and says in
//!   the log when that is not permitted;
//! - virtual: no waiting on wall time; tick `k` starts as soon as the simulation has consumed
//!   the ticks before it (lock-step), so a session runs as fast as the machine allows with the
//!   same tick sequence, the same device reads and the same contact models: bit for bit
//!   reproducible.

use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::time::{Duration, Instant};

use cutlab_sim::stats::percentile;

use crate::device::HapticDevice;
use crate::render::{ContactModel, ForceRenderer, Mode, RenderOutput};
use crate::{Point3, ToolPose, Vector3};

/// Which clock drives the servo loop.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Clock {
    /// Real time (live sessions).
    Live,
    /// As fast as possible, same tick sequence (scripted sessions, tests).
    Virtual,
}

/// A name that is not a [`Clock`]'s.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("unknown clock {0:?} (expected live or virtual)")]
pub struct UnknownClock(pub String);

impl std::str::FromStr for Clock {
    type Err = UnknownClock;
    fn from_str(s: &str) -> Result<Self, UnknownClock> {
        match s {
            "live" => Ok(Clock::Live),
            "virtual" => Ok(Clock::Virtual),
            _ => Err(UnknownClock(s.to_owned())),
        }
    }
}

/// Settings of the servo thread.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ServoConfig {
    /// Live (real time) or virtual (as fast as possible, the same ticks).
    pub clock: Clock,
    /// The servo period, ns.
    pub period_nanos: u64,
    /// Ticks to run.
    pub ticks: u64,
    /// Spin (instead of sleeping) for the last this many nanoseconds before a deadline.
    pub spin_nanos: u64,
    /// Ask for real-time scheduling (live clock only).
    pub realtime_priority: bool,
    /// Simulation steps last this many ticks (virtual clock lock-step).
    pub ticks_per_step: u64,
}

/// One tick as the simulation (and a recorder) sees it.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct ServoSample {
    /// The tick, counted from 0.
    pub tick: u64,
    /// The device's pose (the last good one when `faults` say the device failed).
    pub pose: ToolPose,
    /// What the force renderer produced.
    pub render: RenderOutput,
    /// The second hand's grasper, when the session has one.
    pub grasper: Option<GrasperTick>,
}

/// The second hand's grasper at one tick.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct GrasperTick {
    /// Its pose (the last good one when its device failed), the jaws' centre at the tip.
    pub pose: ToolPose,
    /// The held tissue's pull on the jaws (N, world frame) as the simulation last published
    /// it, before the device's force limit: zero while the jaws hold nothing.
    pub pull_newtons: Vector3,
}

/// Something the log should hear about, sent from the servo thread without allocating.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum ServoEvent {
    /// A fault began (the force starts fading out).
    FaultBegan {
        /// The tick.
        tick: u64,
        /// The fault bits (see [`crate::render::fault`]).
        faults: u8,
    },
    /// Every fault cleared (the force ramps back in).
    FaultCleared {
        /// The tick.
        tick: u64,
    },
    /// The force has faded out completely.
    FadedOut {
        /// The tick.
        tick: u64,
    },
}

/// The channels between the servo thread and the simulation thread.
#[derive(Debug)]
pub struct ServoLinks {
    /// The latest contact model the simulation published.
    pub contact: triple_buffer::Output<ContactModel>,
    /// Each tick's sample, to the simulation.
    pub samples: rtrb::Producer<ServoSample>,
    /// Events for the log.
    pub events: rtrb::Producer<ServoEvent>,
    /// Ticks the simulation has consumed (the last consumed tick + 1).
    pub sim_ticks_done: Arc<AtomicU64>,
    /// Set when the session must end early (the simulation thread failed).
    pub abort: Arc<AtomicBool>,
    /// Every tick's sample for a recorder (never waited on: a full queue drops the record).
    pub record: Option<rtrb::Producer<ServoSample>>,
}

/// What the servo thread measured.
#[derive(Debug, Clone)]
pub struct ServoReport {
    /// Ticks run.
    pub ticks: u64,
    /// The clock the servo ran on.
    pub clock: Clock,
    /// Start of each tick after the session's start, ns.
    pub tick_start_nanos: Vec<u64>,
    /// Work per tick (read, render, write, push), ns.
    pub tick_work_nanos: Vec<u32>,
    /// Wall-clock time of the whole run, ns.
    pub wall_nanos: u64,
    /// Outcome of asking for real-time priority (`None`: not asked).
    pub realtime_priority: Option<Result<(), RealtimeError>>,
    /// The largest force magnitude sent, N.
    pub max_force_newtons: f64,
    /// Non-finite values the renderer met (poses, models or forces).
    pub non_finite_count: u64,
    /// Ticks with any fault.
    pub fault_ticks: u64,
    /// Ticks when the force was faded out completely.
    pub faded_ticks: u64,
    /// Samples the simulation could not take in time (queue full).
    pub dropped_samples: u64,
    /// Tick records a recorder could not take in time (its queue full).
    pub dropped_records: u64,
    /// Path of the blade's tip while cutting, m.
    pub blade_path_in_tissue_m: f64,
    /// Times the blade went into the tissue (one for an incision made in one stroke).
    pub blade_entries: u64,
    /// FNV-1a hash of every tick's force bits (determinism checks).
    pub force_hash: u64,
}

/// Period statistics of a live run.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct PeriodStats {
    /// Mean period between tick starts, us.
    pub mean_us: f64,
    /// Median period, us.
    pub p50_us: f64,
    /// 99th percentile of the period, us.
    pub p99_us: f64,
    /// Largest |period - nominal|, us.
    pub max_deviation_us: f64,
    /// 99th percentile of |period - nominal|, us.
    pub p99_deviation_us: f64,
    /// Ticks that started a whole period or more after their deadline.
    pub missed_deadlines: u64,
    /// Latest start after a deadline, us.
    pub max_lateness_us: f64,
    /// Mean work per tick, us.
    pub mean_work_us: f64,
    /// Largest work of a tick, us.
    pub max_work_us: f64,
}

impl ServoReport {
    /// Statistics of the periods between tick starts and of the lateness behind deadlines.
    pub fn period_stats(&self, period_nanos: u64) -> PeriodStats {
        let starts = &self.tick_start_nanos;
        if starts.len() < 2 {
            return PeriodStats::default();
        }
        let mut periods: Vec<f64> = starts
            .windows(2)
            .map(|w| (w[1] - w[0]) as f64 * 1e-3)
            .collect();
        let nominal = period_nanos as f64 * 1e-3;
        let mut deviations: Vec<f64> = periods.iter().map(|p| (p - nominal).abs()).collect();
        periods.sort_by(f64::total_cmp);
        deviations.sort_by(f64::total_cmp);
        let lateness = |k: usize| starts[k].saturating_sub(k as u64 * period_nanos);
        let missed = (0..starts.len())
            .filter(|&k| lateness(k) >= period_nanos)
            .count() as u64;
        let max_lateness = (0..starts.len()).map(lateness).max().unwrap_or(0);
        let work = &self.tick_work_nanos;
        PeriodStats {
            mean_us: periods.iter().sum::<f64>() / periods.len() as f64,
            p50_us: percentile(&periods, 0.5),
            p99_us: percentile(&periods, 0.99),
            max_deviation_us: deviations[deviations.len() - 1],
            p99_deviation_us: percentile(&deviations, 0.99),
            missed_deadlines: missed,
            max_lateness_us: max_lateness as f64 * 1e-3,
            mean_work_us: work.iter().map(|&w| w as f64).sum::<f64>() / work.len().max(1) as f64
                * 1e-3,
            max_work_us: work.iter().copied().max().unwrap_or(0) as f64 * 1e-3,
        }
    }
}

/// A buffer of `n` zeros whose memory has been written once, so the servo loop's first write
/// to each page does not page-fault (a fault takes the process's memory-map lock, which a
/// simulation thread busy allocating can hold for milliseconds).
fn prefaulted<T: Copy + Default>(n: usize) -> Vec<T> {
    let mut v = Vec::with_capacity(n);
    v.resize(n, T::default());
    for x in v.iter_mut() {
        // written element by element: a zeroed allocation may map untouched zero pages
        *x = std::hint::black_box(T::default());
    }
    v
}

/// Waiting without burning a shared core: spin briefly, then yield, then sleep in short naps.
#[derive(Debug, Default)]
pub struct Backoff(u32);

impl Backoff {
    /// Waits a little, longer the more often it was called: a spin for the first 64 calls,
    /// a yield of the thread for the next 64, then 20 us sleeps.
    pub fn wait(&mut self) {
        self.0 = self.0.saturating_add(1);
        if self.0 < 64 {
            std::hint::spin_loop();
        } else if self.0 < 128 {
            std::thread::yield_now();
        } else {
            std::thread::sleep(Duration::from_micros(20));
        }
    }
}

/// The force on the grasper's hand: the held tissue's pull on the jaws the simulation
/// published, at most `max_newtons` (nothing while the jaws hold nothing).
fn grasp_force(contact: &ContactModel, max_newtons: f64) -> Vector3 {
    let pull = contact.grasp_pull_newtons;
    let n = pull.norm();
    if !n.is_finite() {
        Vector3::zeros()
    } else if n > max_newtons && n > 0.0 {
        pull * (max_newtons / n)
    } else {
        pull
    }
}

/// Sleeps until `spin` before `deadline`, then spins to it.
fn wait_until(deadline: Instant, spin: Duration) {
    loop {
        let now = Instant::now();
        if now >= deadline {
            return;
        }
        let left = deadline - now;
        if left > spin {
            std::thread::sleep(left - spin);
        } else {
            std::hint::spin_loop();
        }
    }
}

/// Why the servo thread runs at normal priority. Shown as `thread-priority` reports it
/// (`Debug`, e.g. `OS(1)` where SCHED_FIFO is not permitted), as before it was typed.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum RealtimeError {
    /// The priority value was refused (the message given).
    #[error("{0:?}")]
    Priority(String),
    /// The operating system refused the real-time policy.
    #[error("{0:?}")]
    Os(thread_priority::Error),
}

fn try_realtime() -> Result<(), RealtimeError> {
    use thread_priority::{RealtimeThreadSchedulePolicy, ThreadPriority, ThreadSchedulePolicy};
    let priority = ThreadPriority::Crossplatform(80u8.try_into().map_err(RealtimeError::Priority)?);
    thread_priority::set_thread_priority_and_policy(
        thread_priority::thread_native_id(),
        priority,
        ThreadSchedulePolicy::Realtime(RealtimeThreadSchedulePolicy::Fifo),
    )
    .map_err(RealtimeError::Os)
}

/// Starts the servo thread (named `cutlab-servo`): `device` holds the scalpel, `grasper` (a
/// second device, read and written in the same tick) the second hand's grasper.
pub fn spawn<D: HapticDevice + 'static>(
    config: ServoConfig,
    mut device: D,
    mut grasper: Option<Box<dyn HapticDevice>>,
    mut renderer: ForceRenderer,
    mut links: ServoLinks,
) -> std::io::Result<std::thread::JoinHandle<(ServoReport, D)>> {
    std::thread::Builder::new().name("cutlab-servo".into()).spawn(move || {
        let realtime_priority = (config.clock == Clock::Live && config.realtime_priority).then(try_realtime);
        // Logged before the first tick (logging may allocate or lock; the loop never logs).
        match &realtime_priority {
            Some(Ok(())) => tracing::info!("servo thread: real-time priority (SCHED_FIFO) granted"),
            Some(Err(e)) => tracing::warn!("servo thread: real-time priority not permitted ({e}); running at normal priority"),
            None => {}
        }
        let n = config.ticks as usize;
        let mut report = ServoReport {
            ticks: 0,
            clock: config.clock,
            tick_start_nanos: prefaulted(n),
            tick_work_nanos: prefaulted(n),
            wall_nanos: 0,
            realtime_priority,
            max_force_newtons: 0.0,
            non_finite_count: 0,
            fault_ticks: 0,
            faded_ticks: 0,
            dropped_samples: 0,
            dropped_records: 0,
            blade_path_in_tissue_m: 0.0,
            blade_entries: 0,
            force_hash: 0,
        };
        let spin = Duration::from_nanos(config.spin_nanos);
        let tps = config.ticks_per_step.max(1);
        let mut last_pose = ToolPose::default();
        let mut last_grasper = ToolPose::default();
        let mut last_tip: Option<Point3> = None;
        let mut previous_faults = 0u8;
        let mut previous_gain = 1.0;
        let mut force_hash = cutlab_sim::hash::Fnv1a::default();
        let start = Instant::now();
        for tick in 0..config.ticks {
            if links.abort.load(Ordering::Acquire) || device.ends_session() {
                break;
            }
            match config.clock {
                Clock::Live => {
                    let deadline = start + Duration::from_nanos(tick * config.period_nanos);
                    wait_until(deadline, spin);
                }
                Clock::Virtual => {
                    let needed = tick / tps * tps;
                    let mut backoff = Backoff::default();
                    while links.sim_ticks_done.load(Ordering::Acquire) < needed {
                        if links.abort.load(Ordering::Acquire) {
                            break;
                        }
                        backoff.wait();
                    }
                }
            }
            let began = Instant::now();
            report.tick_start_nanos[tick as usize] = (began - start).as_nanos() as u64;
            let time_s = tick as f64 * config.period_nanos as f64 * 1e-9;
            let contact = *links.contact.read();
            let read = device.read(tick, time_s);
            if let Ok(p) = read
                && p.is_finite()
            {
                last_pose = p;
            }
            let out = renderer.update(tick, read, &contact);
            // a device that fails to take the force is noticed by its next read
            let _ = device.write_force(out.force_newtons);
            let grasper_tick = grasper.as_mut().map(|g| {
                if let Ok(p) = g.read(tick, time_s)
                    && p.is_finite()
                {
                    last_grasper = p;
                }
                let _ = g.write_force(grasp_force(&contact, g.limits().max_force_newtons));
                GrasperTick { pose: last_grasper, pull_newtons: contact.grasp_pull_newtons }
            });

            report.max_force_newtons = report.max_force_newtons.max(out.force_newtons.norm());
            out.force_newtons.iter().for_each(|&c| force_hash.f64(c));
            if out.mode == Mode::Cutting {
                match last_tip {
                    Some(t) => report.blade_path_in_tissue_m += (last_pose.tip_in_world - t).norm(),
                    None => report.blade_entries += 1,
                }
                last_tip = Some(last_pose.tip_in_world);
            } else {
                last_tip = None;
            }
            if out.faults != 0 {
                report.fault_ticks += 1;
                if out.gain == 0.0 {
                    report.faded_ticks += 1;
                }
            }
            if out.faults != previous_faults {
                let event = if out.faults == 0 { ServoEvent::FaultCleared { tick } } else { ServoEvent::FaultBegan { tick, faults: out.faults } };
                let _ = links.events.push(event);
            }
            if out.faults != 0 && out.gain == 0.0 && previous_gain > 0.0 {
                let _ = links.events.push(ServoEvent::FadedOut { tick });
            }
            previous_faults = out.faults;
            previous_gain = out.gain;
            let sample = ServoSample { tick, pose: last_pose, render: out, grasper: grasper_tick };
            if links.samples.push(sample).is_err() {
                report.dropped_samples += 1;
            }
            if let Some(record) = &mut links.record
                && record.push(sample).is_err()
            {
                report.dropped_records += 1;
            }
            report.tick_work_nanos[tick as usize] = began.elapsed().as_nanos().min(u32::MAX as u128) as u32;
            report.ticks = tick + 1;
        }
        report.wall_nanos = start.elapsed().as_nanos() as u64;
        report.force_hash = force_hash.finish();
        let done = report.ticks as usize;
        report.tick_start_nanos.truncate(done);
        report.tick_work_nanos.truncate(done);
        report.non_finite_count = renderer.non_finite_count;
        let _ = device.write_force(Vector3::zeros());
        if let Some(g) = &mut grasper {
            let _ = g.write_force(Vector3::zeros());
        }
        (report, device)
    })
}
