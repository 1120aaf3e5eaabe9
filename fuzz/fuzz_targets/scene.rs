//! Scene files: `cutlab_sim::scene::parse_spec` (JSON when the input starts with `{`, else TOML).
#![no_main]

#[allow(dead_code)]
#[path = "../../tests/mutation/targets.rs"]
mod targets;

libfuzzer_sys::fuzz_target!(|data: &[u8]| {
    let _ = targets::scene(data);
});
