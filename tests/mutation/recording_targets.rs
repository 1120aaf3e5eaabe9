//! The recordings' parsers that damaged input is fed to (see `targets.rs`): reading an MCAP
//! recording whole, and salvaging one.

use std::path::Path;

/// What one input did: accepted, or refused with the parser's message.
pub type Outcome = Result<(), String>;

/// An MCAP recording read whole (`cutlab_recorder::Recording::from_bytes`); an accepted one
/// is asked for what the commands show (metadata, samples, counts, plan, duration).
pub fn mcap_read(data: &[u8]) -> Outcome {
    let recording = cutlab_recorder::Recording::from_bytes(data).map_err(|e| e.to_string())?;
    let _ = recording.meta().map(|m| format!("{m:?}"));
    let _ = recording.plan();
    let _ = (
        recording.samples().len(),
        recording.counts(),
        recording.duration_s(),
        recording.readable_s(),
        recording.shortfall(),
        recording.announced_steps(),
        recording.is_whole(),
    );
    Ok(())
}

/// Salvaging an MCAP recording (`cutlab_recorder::recover::recover`, which reads and writes
/// paths: `dir/input.mcap` to `dir/recovered.mcap`); what it writes is read back.
pub fn mcap_recover(data: &[u8], dir: &Path) -> Outcome {
    let input = dir.join("input.mcap");
    let output = dir.join("recovered.mcap");
    std::fs::write(&input, data).map_err(|e| format!("cannot write {}: {e}", input.display()))?;
    let _ = std::fs::remove_file(&output);
    cutlab_recorder::recover::recover(&input, &output).map_err(|e| e.to_string())?;
    let _ = cutlab_recorder::Recording::open(&output).map(|r| r.samples().len());
    Ok(())
}
