//! The station's WebSocket messages, one per line, fed to a pointer device:
//! `cutlab_station::protocol::decode_client`. Needs `--features station`.
#![no_main]

#[allow(dead_code)]
#[path = "../../tests/mutation/station_targets.rs"]
mod station_targets;
#[allow(dead_code)]
#[path = "../../tests/mutation/targets.rs"]
mod targets;

libfuzzer_sys::fuzz_target!(|data: &[u8]| {
    let _ = station_targets::station_ws(data);
});
