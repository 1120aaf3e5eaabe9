//! The recorder's errors.

use std::path::PathBuf;

/// Everything that can go wrong writing, reading, recovering or replaying a recording.
#[derive(Debug, thiserror::Error)]
pub enum RecorderError {
    #[error("{}: {error}", path.display())]
    Io {
        path: PathBuf,
        error: std::io::Error,
    },
    #[error("MCAP: {0}")]
    Mcap(#[from] mcap::McapError),
    #[error("encoding a message: {0}")]
    Encode(String),
    #[error("JSON: {0}")]
    Json(#[from] serde_json::Error),
    #[error("malformed recording: {0}")]
    Malformed(String),
    #[error("not a cutlab recording: {0}")]
    NotCutlab(String),
    #[error("replay: {0}")]
    Replay(String),
    #[error(transparent)]
    Haptics(#[from] cutlab_haptics::HapticsError),
    #[error("scene {name}: {source}")]
    Scene {
        name: String,
        source: Box<cutlab_sim::scene::SceneError>,
    },
    #[error("rerun: {0}")]
    Rerun(#[from] crate::rerun_log::RerunLogError),
}
