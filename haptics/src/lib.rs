//! cutlab-haptics: the trainee's hand. Owns real time: the 1 kHz servo loop, devices and
//! force rendering. Content arrives with issue 4; for now it only fixes its place in the
//! layering (it may depend on `cutlab-sim` and nothing above it).
pub use cutlab_sim as sim;
