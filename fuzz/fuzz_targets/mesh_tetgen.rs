//! TetGen `.node` + `.ele`: `cutlab_sim::io::read_tetgen_str`. One input holds both files,
//! split at the first NUL byte (`node \0 ele`).
#![no_main]

#[allow(dead_code)]
#[path = "../../tests/mutation/targets.rs"]
mod targets;

libfuzzer_sys::fuzz_target!(|data: &[u8]| {
    let _ = targets::mesh_tetgen_joined(data);
});
