//! `cutlab bench exercises`: each built-in exercise's session at its scene's default step, as
//! `cutlab session --exercise E` runs it (virtual clock, recorded, no surface snapshots), by
//! the synthetic expert and novice: simulated seconds per wall-clock second (1.0 keeps real
//! time) and the step's median and p99, the whole session with its recording.

use anyhow::Context;
use cutlab_assessor::store::builtins;
use cutlab_haptics::device::DeviceSpec;
use cutlab_haptics::servo::Clock;
use cutlab_sim::stats::Summary;
use cutlab_station::attempt_run::{PlanSource, Prepared, RunSettings, run_blocking};
use serde::Serialize;

/// The levels measured and their sessions' lengths (s): the novice is slower.
const LEVELS: [(&str, f64); 2] = [("expert", 12.0), ("novice", 25.0)];

#[derive(Debug, Serialize)]
struct ExerciseRow {
    exercise: &'static str,
    scene: &'static str,
    tets: usize,
    time_step_ms: f64,
    level: &'static str,
    simulated_s: f64,
    wall_s: f64,
    /// Simulated seconds per wall-clock second.
    speed: f64,
    /// One simulation step (contact, cut, step, refit), us.
    step_us: Summary,
}

/// Runs the benchmark and prints its table (or JSON).
pub fn run(json: bool, out: &std::path::Path) -> anyhow::Result<()> {
    std::fs::create_dir_all(out).with_context(|| format!("creating {}", out.display()))?;
    let rt = tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
        .context("starting the async runtime")?;
    let mut rows = Vec::new();
    for b in builtins()? {
        for (level, duration_s) in LEVELS {
            rows.push(session(&rt, &b, level, duration_s, out)?);
        }
    }
    if json {
        println!("{}", serde_json::to_string_pretty(&rows)?);
        return Ok(());
    }
    println!(
        "| exercise | scene | tets | step ms | level | simulated s | wall s | speed (x real time) | step median us | step p99 us |"
    );
    println!("|---|---|---:|---:|---|---:|---:|---:|---:|---:|");
    for r in &rows {
        println!(
            "| {} | {} | {} | {} | {} | {:.1} | {:.1} | {:.2} | {:.0} | {:.0} |",
            r.exercise,
            r.scene,
            r.tets,
            r.time_step_ms,
            r.level,
            r.simulated_s,
            r.wall_s,
            r.speed,
            r.step_us.median,
            r.step_us.p99
        );
    }
    Ok(())
}

/// The exercise's session by `level`, through the attempt run every session takes (no
/// attempt stored).
fn session(
    rt: &tokio::runtime::Runtime,
    b: &cutlab_assessor::store::Builtin,
    level: &'static str,
    duration_s: f64,
    out: &std::path::Path,
) -> anyhow::Result<ExerciseRow> {
    let settings = RunSettings {
        clock: Clock::Virtual,
        duration_s,
        realtime_priority: false,
        seed: 1,
        ..RunSettings::default()
    };
    let prepared = Prepared::new(b.scene, &settings, PlanSource::Exercise(&b.plan))
        .with_context(|| format!("preparing {}", b.name))?;
    let spec: DeviceSpec = level.parse().map_err(|e| anyhow::anyhow!("{e}"))?;
    let device = prepared.device(&spec)?;
    let tets = prepared.session.sim.model.mesh.tet_count();
    let time_step_ms = prepared.time_step_s() * 1e3;
    let mcap = out.join(format!("{}-{level}.mcap", b.name));
    let run = run_blocking(rt, prepared, device, None, &mcap, None)?;
    let report = run
        .recorded?
        .report
        .with_context(|| format!("the {level} session of {}", b.name))?;
    let steps: Vec<f64> = report.step_nanos.iter().map(|&n| n as f64 * 1e-3).collect();
    Ok(ExerciseRow {
        exercise: b.name,
        scene: b.scene,
        tets,
        time_step_ms,
        level,
        simulated_s: duration_s,
        wall_s: report.wall_s,
        speed: report.speed(),
        step_us: Summary::of(&steps),
    })
}
