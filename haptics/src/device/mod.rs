//! Haptic devices: where the tool's pose comes from and where the rendered force goes.

mod choice;
mod csv;
mod grasper_hand;
pub mod igtl;
pub mod pointer;
mod pointer_hand;
mod spec;
mod stylus_hand;
mod track;
mod trainee;

pub use choice::{Choice, Planning};
pub use csv::CsvDevice;
pub use grasper_hand::{GraspPlan, GrasperHand, Traction};
pub use igtl::{ForceOutput, IgtlDevice, IgtlGrasper, IgtlOptions, IgtlToolNames};
pub use pointer::{PointerDevice, PointerFeed, PointerOptions, PointerSample};
pub use pointer_hand::{HandKind, PointerHand, STEADY_PACE_M_PER_S};
pub use spec::DeviceSpec;
pub use stylus_hand::StylusHand;
pub use track::PoseTrack;
pub use trainee::{Skill, SyntheticTrainee};

use crate::{ToolPose, Vector3};

/// What a device can render.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DeviceLimits {
    /// Largest force the device renders, N (the servo loop clamps to it).
    pub max_force_newtons: f64,
    /// Largest change of force per second, N/s (the servo loop rate-limits to it).
    pub max_force_rate_newtons_per_s: f64,
}

impl Default for DeviceLimits {
    /// A typical desktop haptic device: 3.3 N peak, 0.2 N per millisecond.
    fn default() -> Self {
        Self {
            max_force_newtons: 3.3,
            max_force_rate_newtons_per_s: 200.0,
        }
    }
}

/// Why a device gave no pose this tick.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum DeviceFault {
    /// No device (not connected yet, or the connection was lost).
    Disconnected,
    /// The last pose is older than the device's staleness limit.
    Stale {
        /// How old the last pose is, ns.
        age_nanos: u64,
    },
}

impl std::fmt::Display for DeviceFault {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            DeviceFault::Disconnected => write!(f, "device disconnected"),
            DeviceFault::Stale { age_nanos } => write!(
                f,
                "device data stale ({:.1} ms old)",
                *age_nanos as f64 * 1e-6
            ),
        }
    }
}

/// A haptic device as the servo loop sees it. `read` and `write_force` are called once per
/// servo tick from the servo thread: they must not block, lock or allocate.
pub trait HapticDevice: Send + std::fmt::Debug {
    /// A short name for logs and summaries.
    fn name(&self) -> &str;

    /// What the device can render.
    fn limits(&self) -> DeviceLimits {
        DeviceLimits::default()
    }

    /// The tool's pose at servo tick `tick` (time `time_s = tick * period` since the session
    /// started). Ticks arrive in increasing order.
    fn read(&mut self, tick: u64, time_s: f64) -> Result<ToolPose, DeviceFault>;

    /// The force to render on the hand, N, world frame.
    fn write_force(&mut self, force_newtons: Vector3) -> Result<(), DeviceFault>;

    /// True when a scripted device has nothing more to play at `time_s`.
    fn finished(&self, _time_s: f64) -> bool {
        false
    }

    /// True when the person at the device ended the session (a station's Stop, a page that
    /// went away): the servo loop stops at the next tick and the session ends there, as one
    /// that ran its whole duration does. Scripted devices never do.
    fn ends_session(&self) -> bool {
        false
    }
}

impl HapticDevice for Box<dyn HapticDevice> {
    fn name(&self) -> &str {
        (**self).name()
    }
    fn limits(&self) -> DeviceLimits {
        (**self).limits()
    }
    fn read(&mut self, tick: u64, time_s: f64) -> Result<ToolPose, DeviceFault> {
        (**self).read(tick, time_s)
    }
    fn write_force(&mut self, force_newtons: Vector3) -> Result<(), DeviceFault> {
        (**self).write_force(force_newtons)
    }
    fn finished(&self, time_s: f64) -> bool {
        (**self).finished(time_s)
    }
    fn ends_session(&self) -> bool {
        (**self).ends_session()
    }
}
