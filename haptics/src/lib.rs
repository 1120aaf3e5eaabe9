//! cutlab-haptics: the trainee's hand. Owns real time: the 1 kHz servo loop, the devices and
//! force rendering, and the simulation thread that feeds the servo loop its local contact
//! model.
//!
//! - [`device`]: the [`HapticDevice`] trait and its devices: a plan-following synthetic
//!   trainee ([`device::SyntheticTrainee`]), a CSV trajectory ([`device::CsvDevice`]), an
//!   OpenIGTLink network device ([`device::IgtlDevice`], its force as a POINT or, for PLUS
//!   Toolkit, a TRANSFORM) and the station page's pointer ([`device::PointerDevice`]: samples
//!   pushed through a [`device::PointerFeed`], interpolated to the servo's ticks).
//! - [`collision`]: the tissue surface as a parry BVH, refitted as it deforms, rebuilt after
//!   cuts; the local contact model (plane, stiffness) it yields.
//! - [`render`]: the god-object proxy, spring-damper coupling, cutting resistance, cut
//!   threshold and the safety layer (clamp, rate limit, fade on faults).
//! - [`servo`]: the servo thread (1 kHz, sleep-then-spin, live or virtual clock) and its
//!   period statistics.
//! - [`session`]: a whole session: servo thread + simulation thread at a fixed step,
//!   exchanging data through lock-free queues and triple buffers.
//! - [`stepper`]: the simulation side of a session, one step per servo sample (also what a
//!   replay drives), and the state hash.
//! - [`tap`]: what a session hands a recorder (every tick, every step's tick, cuts,
//!   keyframes, the surface), through bounded lock-free queues.
//!
//! Units: SI inside (metres, newtons, seconds); durations in integer nanoseconds where
//! named `_nanos`; a tick is one servo period.

#![warn(missing_docs)]

pub mod collision;
pub mod damage;
pub mod device;
pub mod error;
pub mod hand;
pub mod landmarks;
pub mod plan;
pub mod pose;
pub mod render;
pub mod retraction;
pub mod servo;
pub mod session;
pub mod step_choice;
pub mod stepper;
pub mod tap;

pub use device::{DeviceFault, DeviceLimits, HapticDevice};
pub use error::HapticsError;
pub use pose::ToolPose;
pub use session::{Hands, Session, SessionConfig, SessionReport};
pub use step_choice::{StepChoice, TimeStep};
pub use stepper::{SessionStepper, StateHash, StepOutput};
pub use tap::{RecordTap, SimRecord, TapFeed, TapSettings};

/// 3-D point in metres.
pub type Point3 = cutlab_sim::Point3;
/// 3-D vector (metres, newtons, metres per second by context).
pub type Vector3 = cutlab_sim::Vector3;
/// Orientation of the tool in the world.
pub type Rotation = nalgebra::UnitQuaternion<f64>;
