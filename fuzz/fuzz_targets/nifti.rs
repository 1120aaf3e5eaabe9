//! NIfTI-1 label volumes, raw or gzipped: `cutlab_sim::segmentation::LabelVolume::read`
//! (which reads a path: each input is written to a scratch file first).
#![no_main]

use std::path::PathBuf;
use std::sync::OnceLock;

#[allow(dead_code)]
#[path = "../../tests/mutation/targets.rs"]
mod targets;

fn scratch() -> &'static PathBuf {
    static DIR: OnceLock<PathBuf> = OnceLock::new();
    DIR.get_or_init(|| {
        let dir = std::env::temp_dir().join(format!("cutlab-fuzz-nifti-{}", std::process::id()));
        std::fs::create_dir_all(&dir).expect("scratch directory");
        dir
    })
}

libfuzzer_sys::fuzz_target!(|data: &[u8]| {
    let _ = targets::nifti(data, scratch());
});
