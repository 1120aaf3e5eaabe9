//! cutlab-recorder: session recordings (MCAP, rerun) and deterministic replay. Content
//! arrives with issue 5; it may depend on `cutlab-haptics` and `cutlab-sim`.
pub use cutlab_haptics as haptics;

pub mod rerun_log;
pub use rerun_log::{RerunLogError, RerunSink, RerunTarget};
