//! Salvaging MCAP recordings: `cutlab_recorder::recover::recover` (which reads and writes
//! paths: each input is written to a scratch file first). Needs `--features mcap`.
#![no_main]

use std::path::PathBuf;
use std::sync::OnceLock;

#[allow(dead_code)]
#[path = "../../tests/mutation/recording_targets.rs"]
mod recording_targets;

fn scratch() -> &'static PathBuf {
    static DIR: OnceLock<PathBuf> = OnceLock::new();
    DIR.get_or_init(|| {
        let dir = std::env::temp_dir().join(format!("cutlab-fuzz-recover-{}", std::process::id()));
        std::fs::create_dir_all(&dir).expect("scratch directory");
        dir
    })
}

libfuzzer_sys::fuzz_target!(|data: &[u8]| {
    let _ = recording_targets::mcap_recover(data, scratch());
});
