//! cutlab-assessor: what a trainee is measured on, and where it is kept.
//!
//! - [`input`]: the samples an attempt is assessed on (filled by the recorder);
//! - [`exercise`]: exercise kinds and their plans (TOML/JSON), [`ExercisePlan::assess`];
//! - [`metrics`]: incision, path, safety and field metrics;
//! - [`proficiency`]: thresholds from experts, pass/fail, score, CUSUM;
//! - [`device_class`]: the pointer or a stylus, whose thresholds are kept apart;
//! - [`store`]: the SQLite database (sqlx);
//! - [`xapi`]: xAPI statements of a trainee's attempts.
//!
//! SI units inside (metres, seconds, newtons); millimetres only for display.

pub mod advice;
pub mod device_class;
pub mod error;
pub mod evidence;
pub mod exercise;
pub mod from_recording;
mod geom;
pub mod input;
pub mod metrics;
pub mod pace;
pub mod planning;
pub mod proficiency;
pub mod recordings;

pub use device_class::DeviceClass;
pub use error::{AssessError, Result};
pub use exercise::{ExerciseKind, ExercisePlan, IncisionPlan, Kind};
pub use from_recording::{UNTOUCHED_NOTE, attempt_data, touched_tissue};
pub use input::{AttemptData, CutSample, ForceSample, FreedPiece, PoseSample, SurfaceMesh};
pub use metrics::{Better, Metric, MetricSet, MetricValue};
pub use proficiency::{CusumParams, Threshold, Thresholds, Verdict};
pub mod store;
pub mod xapi;

pub use store::{DbLocation, Store, default_db};
