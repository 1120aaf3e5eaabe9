//! Trajectory CSV: `cutlab_haptics::device::CsvDevice::parse`, then played.
#![no_main]

#[allow(dead_code)]
#[path = "../../tests/mutation/targets.rs"]
mod targets;

libfuzzer_sys::fuzz_target!(|data: &[u8]| {
    let _ = targets::trajectory_csv(data);
});
