//! The station's errors.

/// Everything that can stop a station session from starting or finishing.
#[derive(Debug, thiserror::Error)]
pub enum StationError {
    #[error(transparent)]
    Assess(#[from] cutlab_assessor::AssessError),
    #[error(transparent)]
    Recorder(#[from] cutlab_recorder::RecorderError),
    #[error(transparent)]
    Haptics(#[from] cutlab_haptics::HapticsError),
    #[error(transparent)]
    Scene(#[from] cutlab_sim::scene::SceneError),
    #[error("{what}: {source}")]
    Io {
        what: String,
        source: std::io::Error,
    },
    /// The exercise's plan does not fit its scene.
    #[error("the exercise's plan: {0}")]
    Plan(String),
    /// Settings that make no session (a duration, a rate), or a log that cannot start.
    #[error("{0}")]
    Settings(String),
    /// The device asked for is not one this station has.
    #[error("{0}")]
    NoSuchDevice(String),
    /// The trainee has not reached the exercise in a curriculum with progression.
    #[error("{0}")]
    Locked(String),
    /// The station takes no more sessions now (one per trainee, a limit per server).
    #[error("{0}")]
    Busy(String),
}
