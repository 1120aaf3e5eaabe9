//! cutlab-assessor: where what a trainee is measured on is kept. The scoring itself
//! (exercise kinds, metrics, proficiency) is `cutlab-scoring`, which needs no database.
//!
//! - [`store`]: the database (sqlx): users, exercises and their plans, attempts, scores,
//!   curricula, cohorts, the hub's stations;
//! - [`recordings`]: the attempts' recordings in an object store;
//! - [`xapi`]: xAPI statements of a trainee's attempts.

pub mod error;
pub mod recordings;
pub mod store;
pub mod xapi;

pub use error::{AssessError, Result};
pub use store::{DbLocation, Store, default_db};
