//! cutlab-station: the trainee station. A person sees the tissue in the browser, cuts it with a
//! pointer, pen or device, and is scored at once; the station is a view and an input of an
//! ordinary recorded session, not a second simulation.
//!
//! - [`run`]: starts an exercise's session with the station's device; the attempt is scored
//!   (or marked incomplete) the moment it ends.
//! - [`attempt_run`]: one attempt run (scene, plan, device, recorded session, score, sync),
//!   the path `cutlab session`, the station, the demo's seeding and the benches share.
//! - [`attempt`]: a session as an attempt: the plan on the tissue, the attempt scored.
//! - [`set`]: the sessions a server runs (a limit, one per trainee).
//! - [`view`]: the latest frame of a running session (surface positions, topology, tool,
//!   force), published by the recorder thread, latest wins.
//! - [`protocol`]: the WebSocket messages between the server and the page.
//!
//! May depend on `cutlab-assessor`, `cutlab-recorder`, `cutlab-haptics` and `cutlab-sim`;
//! only `cutlab-dashboard` and the CLI depend on it.

pub mod attempt;
pub mod attempt_run;
pub mod error;
pub mod protocol;
pub mod run;
pub mod set;
pub mod sync;
pub mod view;

pub use error::StationError;
pub use run::{
    Control, Ending, Input, POINTER, Running, SessionFigures, StartRequest, StationSettings,
};
pub use set::StationSet;
