//! OpenIGTLink framing: `Header::parse`, `content`, `decode_transform`.
#![no_main]

#[allow(dead_code)]
#[path = "../../tests/mutation/targets.rs"]
mod targets;

libfuzzer_sys::fuzz_target!(|data: &[u8]| {
    let _ = targets::igtl(data);
});
