//! Errors of the haptics crate.

use std::path::PathBuf;

/// Why a device, a session or a configuration could not be set up.
#[derive(Debug, thiserror::Error)]
pub enum HapticsError {
    /// A file could not be read.
    #[error("{path}: {error}")]
    Io {
        /// The file.
        path: PathBuf,
        /// What the operating system said.
        error: std::io::Error,
    },
    /// A line of a trajectory CSV could not be parsed.
    #[error("{path}:{line}: {message}")]
    Csv {
        /// The file.
        path: PathBuf,
        /// The line, counted from 1.
        line: usize,
        /// What is wrong with it.
        message: String,
    },
    /// The OpenIGTLink device could not listen on its port.
    #[error("OpenIGTLink: cannot listen on port {port}: {source}")]
    Listen {
        /// The port.
        port: u16,
        /// What the operating system said.
        source: std::io::Error,
    },
    /// A setting out of range (says which).
    #[error("invalid configuration: {0}")]
    Config(String),
    /// A force-rendering setting out of range.
    #[error("invalid configuration: {0}")]
    Render(#[from] crate::render::RenderSettingsError),
    /// The scene could not be loaded or built.
    #[error("scene: {0}")]
    Scene(#[from] cutlab_sim::scene::SceneError),
    /// The tissue has no boundary surface a tool could touch.
    #[error("the scene's tissue has no surface to touch: {0}")]
    Surface(String),
    /// A session thread could not be started.
    #[error("cannot start the {name} thread: {source}")]
    Thread {
        /// The thread's name.
        name: &'static str,
        /// What the operating system said.
        source: std::io::Error,
    },
    /// A session thread (named) panicked.
    #[error("the {0} thread panicked")]
    Panicked(&'static str),
    /// The simulation failed (settling, a step).
    #[error("simulation: {0}")]
    Simulation(String),
}
