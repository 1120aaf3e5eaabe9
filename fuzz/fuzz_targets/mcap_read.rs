//! MCAP recordings read whole: `cutlab_recorder::Recording::from_bytes`. Needs
//! `--features mcap`.
#![no_main]

#[allow(dead_code)]
#[path = "../../tests/mutation/recording_targets.rs"]
mod recording_targets;

libfuzzer_sys::fuzz_target!(|data: &[u8]| {
    let _ = recording_targets::mcap_read(data);
});
