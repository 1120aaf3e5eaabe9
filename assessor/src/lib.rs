//! cutlab-assessor: metrics, expert plans, proficiency and the SQLite store. Content arrives
//! with issue 6; it may depend on `cutlab-recorder` and the crates below it.
pub use cutlab_recorder as recorder;
