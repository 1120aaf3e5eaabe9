//! The `pointer` device: the trainee station's page (a mouse, a pen, a touch) as a haptic
//! device. The page finds the point under the cursor on the tissue it renders and sends it,
//! time-stamped by its own clock, with a depth and the button; this device turns those samples
//! (tens to hundreds a second, irregular) into the servo loop's pose at every 1 kHz tick.
//!
//! - Input: [`PointerSample`]s pushed through a [`PointerFeed`] (`Clone + Send + Sync`, any
//!   thread) into a bounded lock-free queue the servo thread drains without waiting; a full
//!   queue refuses the sample ([`PushError::Full`], counted). The tip is the sample's surface
//!   point moved `depth_m` into the tissue along the blade.
//! - Orientation ([`PointerOrientation`]): fixed (a scalpel pointing down into the tissue,
//!   cutting along a direction: [`scalpel_down`]) or each sample's quaternion.
//! - Output: at tick time `s` the pose at page time `s + offset - delay` ([`PointerOptions::
//!   delay_s`], 30 ms by default), linear between the two samples around it (tip), spherical
//!   (orientation), the buttons held in either; exactly a sample's pose at its time. Before
//!   the first sample: [`PointerOptions::rest_pose`], above the tissue, blade not engaged.
//! - Clocks: the first sample anchors the page clock to the session clock (its page time plays
//!   `delay` later). The two clocks drift and the network is uneven: when samples arrive after
//!   the buffer ran dry (the page sent a burst, or stalled briefly, or its clock runs slower)
//!   play goes on from the held pose and the latency grows by the gap, then drains at 5 %
//!   faster play while more than `delay` is buffered; only when the newest sample is more than
//!   [`PointerOptions::max_lag_s`] ahead of the cursor does the cursor skip forward, and
//!   never past a press or a release: it stops on the sample that changed the buttons, so a
//!   stalled page's click still happens where the hand made it. The cursor never moves back. (Skipping forward at every burst moved the blade a burst's way
//!   in one tick, and the cutting resistance, which follows the blade's speed, flipped between
//!   0 and its full value.)
//! - When samples stop the pose is held; after [`PointerOptions::timeout_s`] without a usable
//!   sample the device pauses: each tick reads as [`DeviceFault::Stale`] (the servo holds the
//!   last pose and fades the force; the cut stroke ends), counted in
//!   [`PointerCounters::paused_ticks`], until samples come again (the page was busy, hidden,
//!   or reloaded: its clock may start again from zero), when the page clock is anchored anew
//!   and the device plays on ([`PointerCounters::resumes`]). Only after
//!   [`PointerOptions::absence_s`] without a usable sample does it fault
//!   ([`PointerFault::TimedOut`]); a closed feed (Stop) faults it
//!   ([`PointerFault::Closed`], read as [`DeviceFault::Disconnected`]). Faults last: the
//!   servo loop records the tick's fault bits, `finished` and `ends_session` turn true, so
//!   the session ends at the next tick, and [`PointerFeed::push`] answers
//!   [`PushError::Faulted`].
//! - Bad input: a sample with a NaN or an infinity anywhere is dropped and counted
//!   ([`PointerCounters::non_finite`]: a page's glitch, or a hostile one, does not end the
//!   attempt; the pose is held as for a gap), as is a finite sample out of range (a surface
//!   point over 10 m from the origin, a depth outside [-0.05, 0.1] m, a pressure outside
//!   [0, 1], a quaternion far from unit length, a page clock jumping over 10 s) and one not
//!   later than the last used ([`PointerCounters`]).
//! - Force: [`HapticDevice::write_force`] keeps the latest force for the page
//!   ([`PointerFeed::latest_force_newtons`], for a force bar); [`PointerFeed::echo_ms`] tells
//!   which sample a tick had seen (the page's latency).
//!
//! Determinism: given the same samples taken at the same ticks, the poses are the same bits
//! (all arithmetic is on the samples and the tick's time). When samples arrive is not
//! deterministic (network, page, scheduler), so a live session is not reproducible from the
//! samples; the recording holds the poses this device produced each tick, and a replay uses
//! those, bit for bit, without the page.
//!
//! The device runs on the live clock: the session's time must pass as the page's does (the
//! virtual clock runs faster than real time, so every sample would arrive late).

mod feed;
mod sample;
mod timeline;

pub use feed::{PointerCounters, PointerFault, PointerFeed, PushError};
pub use sample::{
    MAX_DEPTH_M, MAX_DISTANCE_FROM_ORIGIN_M, MAX_TIME_JUMP_MS, MIN_DEPTH_M, PointerSample,
    QUATERNION_NORM_TOLERANCE, SampleCheck,
};

use std::sync::Arc;

use super::{DeviceFault, HapticDevice};
use crate::plan::Plan;
use crate::{HapticsError, Point3, Rotation, ToolPose, Vector3};
use feed::Shared;
use timeline::{Keyed, Timeline};

/// Where the tool's orientation comes from.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum PointerOrientation {
    /// Always this `world_from_tool` (samples' quaternions are checked, not used).
    Fixed(Rotation),
    /// Each sample's `world_from_tool_xyzw`; a sample without one takes `fallback`.
    PerSample {
        /// The orientation of a sample that has none.
        fallback: Rotation,
    },
}

impl Default for PointerOrientation {
    /// A scalpel pointing down -z, cutting along +x (the identity: the default scenes' up is
    /// +z).
    fn default() -> Self {
        PointerOrientation::Fixed(Rotation::identity())
    }
}

/// A scalpel pointing down into a tissue whose outward side is `up`, its sharp edge cutting
/// along `cutting` (made perpendicular to `up`): tool +z along `up` (the edge from the tip
/// towards the handle), +x along the cut. `None` when the directions are zero, not finite or
/// parallel.
pub fn scalpel_down(up: &Vector3, cutting: &Vector3) -> Option<Rotation> {
    let z = up.try_normalize(1e-12)?;
    let x = (cutting - z * z.dot(cutting)).try_normalize(1e-9)?;
    let y = z.cross(&x);
    if ![x, y, z].iter().all(|v| v.iter().all(|c| c.is_finite())) {
        return None;
    }
    let m = nalgebra::Matrix3::from_columns(&[x, y, z]);
    Some(Rotation::from_rotation_matrix(
        &nalgebra::Rotation3::from_matrix_unchecked(m),
    ))
}

/// Settings of a [`PointerDevice`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PointerOptions {
    /// How far the played pose trails the newest sample, s (covers the page's and the
    /// network's unevenness).
    pub delay_s: f64,
    /// Without a usable sample for this long the device pauses (the pose held, the force
    /// faded) until samples come again, s.
    pub timeout_s: f64,
    /// Without a usable sample for this long the device faults and the session ends, s.
    pub absence_s: f64,
    /// The cursor is anchored again once the newest sample is this far ahead of it, s (more
    /// than `delay_s`).
    pub max_lag_s: f64,
    /// Samples the feed's queue holds.
    pub queue_capacity: usize,
    /// Where the tool's orientation comes from.
    pub orientation: PointerOrientation,
    /// The pose before the first sample: above the tissue, blade not engaged (path metrics
    /// count the move from it to the first sample, so above the planned entry is best: see
    /// [`Self::above_entry`]).
    pub rest_pose: ToolPose,
    /// The button bit a sample's held button sets ([`PointerSample::blade_engaged`]):
    /// [`crate::pose::BUTTON_BLADE`] for a scalpel, [`crate::pose::BUTTON_JAWS`] for a
    /// grasper ([`Self::grasper_above`]).
    pub button: u32,
}

impl Default for PointerOptions {
    fn default() -> Self {
        Self {
            delay_s: 0.03,
            timeout_s: 0.5,
            absence_s: 30.0,
            max_lag_s: 0.3,
            queue_capacity: 256,
            orientation: PointerOrientation::default(),
            rest_pose: ToolPose {
                tip_in_world: Point3::new(0.0, 0.0, 0.1),
                ..ToolPose::default()
            },
            button: crate::pose::BUTTON_BLADE,
        }
    }
}

impl PointerOptions {
    /// The defaults, with a scalpel pointing into the tissue at `plan`'s entry and cutting
    /// along its line, at rest `plan.approach_height_m` above the entry.
    pub fn above_entry(plan: &Plan) -> Result<Self, HapticsError> {
        plan.check()?;
        let (Some(&entry), Some(&next), Some(&normal)) = (
            plan.line_m.first(),
            plan.line_m.get(1),
            plan.normals.first(),
        ) else {
            return Err(HapticsError::Config("plan: no line".into()));
        };
        let rotation = scalpel_down(&normal, &(next - entry)).ok_or_else(|| {
            HapticsError::Config("plan: the line runs along the surface normal".into())
        })?;
        Ok(Self {
            orientation: PointerOrientation::Fixed(rotation),
            rest_pose: ToolPose {
                tip_in_world: entry + normal * plan.approach_height_m,
                world_from_tool: rotation,
                buttons: 0,
            },
            ..Self::default()
        })
    }

    /// A grasper's: the jaws held closed while the button is ([`crate::pose::BUTTON_JAWS`]),
    /// oriented as [`Self::above_entry`]'s scalpel (a negative depth lifts them off the
    /// surface), at rest 30 mm above the middle of `plan`'s line, and waiting for its hand
    /// as long as a session lasts (a second hand may stay off the tissue for minutes).
    pub fn grasper_above(plan: &Plan) -> Result<Self, HapticsError> {
        let scalpel = Self::above_entry(plan)?;
        let middle = plan.line_m.len() / 2;
        let (Some(&at), Some(&normal)) = (plan.line_m.get(middle), plan.normals.get(middle)) else {
            return Err(HapticsError::Config("plan: no line".into()));
        };
        Ok(Self {
            absence_s: 3600.0,
            rest_pose: ToolPose {
                tip_in_world: at + normal * 0.03,
                ..scalpel.rest_pose
            },
            button: crate::pose::BUTTON_JAWS,
            ..scalpel
        })
    }

    /// Checks the numbers.
    pub fn check(&self) -> Result<(), HapticsError> {
        let bad = |m: &str| Err(HapticsError::Config(format!("pointer device: {m}")));
        if !(self.delay_s >= 0.0 && self.delay_s <= 1.0) {
            return bad("the delay must be in [0, 1] s");
        }
        if !(self.timeout_s > self.delay_s && self.timeout_s <= 60.0) {
            return bad("the timeout must be longer than the delay and at most 60 s");
        }
        if !(self.absence_s >= self.timeout_s && self.absence_s <= 3600.0) {
            return bad("the absence must be at least the timeout and at most 3600 s");
        }
        if !(self.max_lag_s > self.delay_s && self.max_lag_s <= 10.0) {
            return bad("the largest lag must be longer than the delay and at most 10 s");
        }
        if !(2..=1 << 16).contains(&self.queue_capacity) {
            return bad("the queue holds 2 to 65536 samples");
        }
        let rotation_ok = |r: &Rotation| r.coords.iter().all(|c| c.is_finite());
        let orientation_ok = match &self.orientation {
            PointerOrientation::Fixed(r) => rotation_ok(r),
            PointerOrientation::PerSample { fallback } => rotation_ok(fallback),
        };
        if !orientation_ok || !self.rest_pose.is_finite() {
            return bad("the orientation and the rest pose must be finite");
        }
        Ok(())
    }
}

/// The pointer device (see the module documentation).
#[derive(Debug)]
pub struct PointerDevice {
    options: PointerOptions,
    samples: rtrb::Consumer<PointerSample>,
    shared: Arc<Shared>,
    timeline: Timeline,
    /// Session time of the last usable sample, s.
    last_usable_s: Option<f64>,
    /// The latest usable sample's page time, ms (the order check).
    last_t_ms: Option<f64>,
    /// Session time when the fault began, s.
    faulted_at_s: Option<f64>,
    fault: Option<PointerFault>,
    /// No usable sample for longer than the timeout: the pose held until samples return.
    paused: bool,
    last_pose: ToolPose,
}

impl PointerDevice {
    /// A device and the feed the page pushes its samples through.
    pub fn new(options: PointerOptions) -> Result<(Self, PointerFeed), HapticsError> {
        options.check()?;
        let (producer, consumer) = rtrb::RingBuffer::new(options.queue_capacity);
        let shared = Arc::new(Shared::new());
        let feed = PointerFeed::new(producer, shared.clone(), options.queue_capacity);
        let device = Self {
            timeline: Timeline::new(
                options.queue_capacity + 2,
                options.delay_s * 1e3,
                options.max_lag_s * 1e3,
            ),
            samples: consumer,
            shared,
            last_usable_s: None,
            last_t_ms: None,
            faulted_at_s: None,
            fault: None,
            paused: false,
            last_pose: options.rest_pose,
            options,
        };
        Ok((device, feed))
    }

    /// The options the device was made with.
    pub fn options(&self) -> &PointerOptions {
        &self.options
    }

    /// Why the device stopped, if it did.
    pub fn fault(&self) -> Option<PointerFault> {
        self.fault
    }

    /// The device's counters (shared with its feed).
    pub fn counters(&self) -> &PointerCounters {
        &self.shared.counters
    }

    /// The latest force written, N (what [`PointerFeed::latest_force_newtons`] reads).
    pub fn latest_force_newtons(&self) -> Vector3 {
        self.shared.force()
    }

    fn fail(&mut self, fault: PointerFault, time_s: f64) -> DeviceFault {
        if self.fault.is_none() {
            self.fault = Some(fault);
            self.faulted_at_s = Some(time_s);
            self.shared.set_fault(fault);
        }
        self.fault_now(time_s)
    }

    /// The fault as the servo loop reads it.
    fn fault_now(&self, time_s: f64) -> DeviceFault {
        match self.fault {
            Some(PointerFault::TimedOut) => {
                let since_s = self.last_usable_s.unwrap_or(0.0);
                DeviceFault::Stale {
                    age_nanos: ((time_s - since_s).max(0.0) * 1e9) as u64,
                }
            }
            _ => DeviceFault::Disconnected,
        }
    }

    /// The sample as a pose (the tip `depth_m` into the tissue along the blade).
    fn keyed(&self, s: &PointerSample) -> Keyed {
        let rotation = match self.options.orientation {
            PointerOrientation::Fixed(r) => r,
            PointerOrientation::PerSample { fallback } => s
                .world_from_tool_xyzw
                .map(|[x, y, z, w]| Rotation::new_normalize(nalgebra::Quaternion::new(w, x, y, z)))
                .unwrap_or(fallback),
        };
        let surface = Point3::from(s.surface_in_world_m);
        Keyed {
            t_ms: s.t_ms,
            pose: ToolPose {
                tip_in_world: surface - (rotation * Vector3::z()) * s.depth_m,
                world_from_tool: rotation,
                buttons: if s.blade_engaged {
                    self.options.button
                } else {
                    0
                } | if s.retractor && self.options.button == crate::pose::BUTTON_BLADE {
                    crate::pose::BUTTON_RETRACT
                } else {
                    0
                },
            },
        }
    }

    /// Takes what the queue holds, dropping (and counting) what is not usable; true when a
    /// usable sample was taken.
    fn drain(&mut self, tick: u64, time_s: f64) -> bool {
        let counters = &self.shared.counters;
        let mut taken = false;
        while let Ok(s) = self.samples.pop() {
            match s.check() {
                SampleCheck::NonFinite => {
                    PointerCounters::add(&counters.non_finite);
                    continue;
                }
                SampleCheck::Absurd => {
                    PointerCounters::add(&counters.dropped_invalid);
                    continue;
                }
                SampleCheck::Usable => {}
            }
            if self.paused {
                // back after a pause: the page's clock may have started again (a reload)
                self.paused = false;
                self.last_t_ms = None;
                self.timeline.restart();
                PointerCounters::add(&counters.resumes);
            }
            if let Some(last_ms) = self.last_t_ms {
                if !(s.t_ms > last_ms) {
                    PointerCounters::add(&counters.dropped_out_of_order);
                    continue;
                }
                if s.t_ms - last_ms > MAX_TIME_JUMP_MS {
                    PointerCounters::add(&counters.dropped_invalid);
                    continue;
                }
            }
            PointerCounters::add(&counters.accepted);
            self.last_t_ms = Some(s.t_ms);
            let k = self.keyed(&s);
            self.timeline.push(k);
            taken = true;
        }
        if taken {
            self.last_usable_s = Some(time_s);
            if let Some(t_ms) = self.last_t_ms {
                self.shared.echo(tick, t_ms);
            }
        }
        taken
    }
}

impl HapticDevice for PointerDevice {
    fn name(&self) -> &str {
        "pointer"
    }

    fn read(&mut self, tick: u64, time_s: f64) -> Result<ToolPose, DeviceFault> {
        if self.fault.is_some() {
            return Err(self.fault_now(time_s));
        }
        let taken = self.drain(tick, time_s);
        if self.samples.is_abandoned() && self.samples.is_empty() {
            return Err(self.fail(PointerFault::Closed, time_s));
        }
        let Some(last_usable_s) = self.last_usable_s else {
            return Ok(self.options.rest_pose);
        };
        let gap_s = time_s - last_usable_s;
        if gap_s > self.options.absence_s {
            return Err(self.fail(PointerFault::TimedOut, time_s));
        }
        if gap_s > self.options.timeout_s {
            self.paused = true;
            PointerCounters::add(&self.shared.counters.paused_ticks);
            return Err(DeviceFault::Stale {
                age_nanos: (gap_s * 1e9) as u64,
            });
        }
        let advance = self.timeline.advance(time_s * 1e3, taken);
        let counters = &self.shared.counters;
        if advance.reanchored {
            PointerCounters::add(&counters.reanchors);
        }
        if advance.held {
            PointerCounters::add(&counters.held_ticks);
        }
        if let Some(pose) = self.timeline.pose() {
            self.last_pose = pose;
        }
        Ok(self.last_pose)
    }

    fn write_force(&mut self, force_newtons: Vector3) -> Result<(), DeviceFault> {
        self.shared.write_force(&force_newtons);
        match self.fault {
            Some(_) => Err(DeviceFault::Disconnected),
            None => Ok(()),
        }
    }

    /// True once the device faulted: it has nothing more to play.
    fn finished(&self, _time_s: f64) -> bool {
        self.fault.is_some()
    }

    /// True once the device faulted (the feed closed, the page was away past the absence or
    /// sent a NaN): it gives no pose again, so the servo loop ends the session at the next
    /// tick (the faulted tick is recorded with its fault bits).
    fn ends_session(&self) -> bool {
        self.fault.is_some()
    }
}
