//! cutlab-scoring: what a trainee is measured on, without a database. A replay, a bench or
//! another tool scores an attempt with it alone; `cutlab-assessor` keeps the results.
//!
//! - [`input`]: the samples an attempt is assessed on (filled by the recorder);
//! - [`exercise`]: exercise kinds and their plans (TOML/JSON), [`ExercisePlan::assess`];
//! - [`metrics`]: incision, path, safety and field metrics;
//! - [`proficiency`]: thresholds from experts, pass/fail, score, CUSUM;
//! - [`advice`]: the debrief's sentences;
//! - [`evidence`]: the validity evidence of an exercise's scores, by [`stats`];
//! - [`planning`]: candidate incisions' fields compared, and pictured;
//! - [`from_recording`]: an attempt's data read from its recording;
//! - [`device_class`]: the pointer or a stylus, whose thresholds are kept apart.
//!
//! SI units inside (metres, seconds, newtons); millimetres only for display.

pub mod advice;
pub mod device_class;
pub mod error;
pub mod evidence;
pub mod exercise;
pub mod from_recording;
mod geom;
pub mod incision_plan;
pub mod input;
pub mod metrics;
pub mod pace;
pub mod planning;
pub mod proficiency;
pub mod stats;

pub use device_class::DeviceClass;
pub use error::{Result, ScoreError};
pub use exercise::{ExerciseKind, ExercisePlan, IncisionPlan, Kind};
pub use from_recording::{UNTOUCHED_NOTE, attempt_data, touched_tissue};
pub use input::{
    AttemptData, CutSample, ForceSample, FreedPiece, GrasperSample, PoseSample, SurfaceMesh,
};
pub use metrics::{Better, Metric, MetricSet, MetricValue};
pub use proficiency::{CusumParams, Threshold, Thresholds, Verdict};
