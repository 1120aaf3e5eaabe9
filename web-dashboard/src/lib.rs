//! cutlab-dashboard: the instructors' and trainees' web application (axum). Content
//! arrives with issue 7; it may depend on `cutlab-assessor` and the crates below it.
pub use cutlab_assessor as assessor;
