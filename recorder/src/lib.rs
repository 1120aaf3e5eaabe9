//! cutlab-recorder: session recordings and deterministic replay.
//!
//! - [`channels`]: the channels of a recording (topics, schemas, messages; documented
//!   there and in `docs/reference/recording-format.md`).
//! - [`writer`]: [`McapSink`] writes a session's records into a chunked, zstd-compressed,
//!   indexed MCAP file, flushed at least every second; [`writer::spawn`] runs it on the
//!   `cutlab-recorder` thread fed by the session's lock-free tap.
//! - [`reader`]: [`Recording`] reads a recording back (a complete one, or a damaged one up to
//!   its first damaged record).
//! - [`scan`]: walks a file's records without trusting a length in it; says where and how a
//!   file is damaged ([`Damage`]) and what its summary announces ([`Announced`]).
//! - [`recover`]: salvages a damaged recording into a complete file.
//! - [`rerun_log`]: [`RerunSink`] logs a session or a replay to a rerun `.rrd` file or a
//!   live viewer (only when asked).
//! - [`device`]: [`RecordedHand`] plays a recording's tool poses back as a haptic device.
//! - [`replay`]: re-simulates a recording from its inputs and checks every keyframe's hash
//!   bit for bit.
//!
//! May depend on `cutlab-haptics` and `cutlab-sim`; nothing below depends on it.

pub mod channels;
pub mod device;
pub mod error;
pub mod reader;
pub mod record;
pub mod recover;
pub mod replay;
pub mod rerun_log;
pub mod scan;
pub mod writer;

pub use device::RecordedHand;
pub use error::RecorderError;
pub use reader::Recording;
pub use rerun_log::{RerunLogError, RerunSink, RerunTarget};
pub use scan::{Announced, Damage, DamageKind};
pub use writer::{McapSink, WriterOptions, recording_in_use};
