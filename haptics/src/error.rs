//! Errors of the haptics crate.

use std::path::PathBuf;

/// Why a device, a session or a configuration could not be set up.
#[derive(Debug, thiserror::Error)]
pub enum HapticsError {
    #[error("{path}: {error}")]
    Io {
        path: PathBuf,
        error: std::io::Error,
    },
    #[error("{path}:{line}: {message}")]
    Csv {
        path: PathBuf,
        line: usize,
        message: String,
    },
    #[error("OpenIGTLink: cannot listen on port {port}: {source}")]
    Listen { port: u16, source: std::io::Error },
    #[error("invalid configuration: {0}")]
    Config(String),
    #[error("invalid configuration: {0}")]
    Render(#[from] crate::render::RenderSettingsError),
    #[error("scene: {0}")]
    Scene(#[from] cutlab_sim::scene::SceneError),
    #[error("the scene's tissue has no surface to touch: {0}")]
    Surface(String),
    #[error("cannot start the {name} thread: {source}")]
    Thread {
        name: &'static str,
        source: std::io::Error,
    },
    #[error("the {0} thread panicked")]
    Panicked(&'static str),
    #[error("simulation: {0}")]
    Simulation(String),
}
