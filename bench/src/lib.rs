//! cutlab-bench: the benchmarks of cutlab, out of the user-facing command line's code.
//! `cutlab bench ...` parses [`BenchCommand`] and calls [`run`]; the figures are printed, not
//! asserted. The side-by-side comparison with Rapier is `benches/peer`
//! (`cargo bench -p cutlab-bench --bench peer`).
//!
//! Shared by the benchmarks: `plot` (log-log SVG plots, drawn by hand), `stroke` (a scripted
//! tool pressing along a line), [`progress`] (the bar; the demo's seeding uses it too) and
//! `cutlab_sim::stats` (median, p99). `load` is the dashboard's load client (hyper), which
//! the dashboard library itself does not carry.

mod accuracy;
pub mod browser;
mod budget;
mod cuts;
mod dashboard;
mod exercises;
mod hub;
mod load;
mod perf;
mod plot;
pub mod progress;
mod recorder;
mod skip;
mod stability;
mod station;
mod step;
mod step_size;
mod stroke;

use std::path::PathBuf;

use clap::Subcommand;

/// `cutlab bench ...`: benchmarks that print figures.
#[derive(Debug, Subcommand)]
pub enum BenchCommand {
    /// Step time per integrator on the chest wall at about 1k, 10k and 100k tetrahedra, and
    /// the settle time of the default scene.
    Step {
        /// A reduced set (1k and 10k only, fewer steps).
        #[arg(long)]
        quick: bool,
        /// Machine-readable output.
        #[arg(long)]
        json: bool,
        /// Only these requested sizes (tets; repeatable), e.g. `--tets 100000` to profile one.
        #[arg(long)]
        tets: Vec<usize>,
        /// Only this integrator (`symplectic-euler` or `implicit-euler`).
        #[arg(long)]
        integrator: Option<cutlab_sim::solver::Integrator>,
    },
    /// Run time against error per force model (springs, springs from E, co-rotational FEM),
    /// mesh and integrator on problems with known answers: patch test, cantilever on the IPC
    /// bars, wound opening of a pre-stressed sheet, first frequency of a bar.
    Accuracy {
        /// A reduced set (coarser sheets and bars, implicit Euler only; seconds).
        #[arg(long)]
        quick: bool,
        /// Machine-readable output.
        #[arg(long)]
        json: bool,
        /// Directory for the CSV table and the SVG plot.
        #[arg(long, default_value = "out/bench-accuracy")]
        out: PathBuf,
    },
    /// Speed on large meshes: a scripted press-and-cut session on the chest wall at 10k,
    /// 50k, 100k and 200k tetrahedra and on the CT body wall, full and localised; step time,
    /// cut latency, awake particles, CG iterations, the localised error, memory; a CSV and a
    /// log-log SVG of step time against tet count.
    Perf {
        /// A reduced set (10k and 50k, short runs; about a minute).
        #[arg(long)]
        quick: bool,
        /// Machine-readable output.
        #[arg(long)]
        json: bool,
        /// Directory for the CSV table and the SVG plot.
        #[arg(long, default_value = "out/bench-perf")]
        out: PathBuf,
    },
    /// What the work a session skips would cost if it were done, on the settled chest wall at
    /// 10k and 100k tets: the surface BVH built again against refitted (or not, when the
    /// surface is still), the surface extracted again, a resting step full against localised,
    /// rerun logging of a surface snapshot.
    Skip {
        /// 10k tets only, fewer repeats.
        #[arg(long)]
        quick: bool,
        /// Machine-readable output.
        #[arg(long)]
        json: bool,
        /// Directory for the `.rrd` files the rerun measurement writes.
        #[arg(long, default_value = "out/bench-skip")]
        out: PathBuf,
    },
    /// Recorder cost per servo tick (with and without), file size per minute, writer
    /// throughput and replay speed, on a scripted chest-wall session.
    Recorder {
        /// Resolution of the chest wall (default: the default scene's).
        #[arg(long)]
        min_tets: Option<usize>,
        /// Session length, s.
        #[arg(long, default_value_t = 30.0)]
        duration: f64,
        /// Simulate only near the scalpel (recorded, so the replay is localised too).
        #[arg(long)]
        localise: bool,
        /// Machine-readable output.
        #[arg(long)]
        json: bool,
        /// Directory for the recording.
        #[arg(long, default_value = "out/bench-recorder")]
        out: PathBuf,
    },
    /// Each built-in exercise's session at its scene's default step by the synthetic expert
    /// and novice (virtual clock, recorded): simulated seconds per wall second and the step's
    /// median and p99.
    Exercises {
        /// Machine-readable output.
        #[arg(long)]
        json: bool,
        /// Directory for the sessions' recordings.
        #[arg(long, default_value = "out/bench-exercises")]
        out: PathBuf,
    },
    /// The implicit solver's tolerance against its error budget per built-in exercise's scene:
    /// the integrator's error at the scene's step (against half of it), the solve's error and
    /// CG iterations at each tolerance, and the loosest within a tenth of the integrator's.
    Budget {
        /// Machine-readable output.
        #[arg(long)]
        json: bool,
    },
    /// Sweeps of time step, stiffness, damping and mass ratio per model and integrator: where
    /// each stays stable, and whether failures are safe (an error, the state kept, no NaN).
    Stability {
        /// A reduced set.
        #[arg(long)]
        quick: bool,
        /// Machine-readable output.
        #[arg(long)]
        json: bool,
    },
    /// The trainee station in headless Chromium at each size of the chest wall: frames drawn
    /// per second, the latency from a pointer sample to the frame that shows it, bytes per
    /// second to the viewer, and the servo period's p99 deviation with and without a viewer.
    Station {
        /// Sizes of the chest wall, tets (repeatable; default 12800 and 100000).
        #[arg(long)]
        tets: Vec<usize>,
        /// Only 12,800 tets, shorter sessions.
        #[arg(long)]
        quick: bool,
        /// Seconds each measured session runs.
        #[arg(long, default_value_t = 10.0)]
        duration: f64,
        /// The simulation step: ms, `scene` (the scene's, 1 ms) or `auto` (the smallest that
        /// keeps real time here, measured at each session's start).
        #[arg(long, default_value = "scene")]
        time_step_ms: cutlab_haptics::TimeStep,
        /// Machine-readable output.
        #[arg(long)]
        json: bool,
    },
    /// Stations uploading to one hub (a `cutlab serve` process): attempts per second and the
    /// time of an upload, then the hub killed mid-upload and restarted: every attempt must
    /// be there exactly once, every recording intact.
    Hub {
        /// The folder for the hub's and the stations' databases and recordings (those of a
        /// previous run removed).
        #[arg(long, default_value = "out/bench-hub")]
        out: PathBuf,
        #[arg(long, default_value_t = 10)]
        stations: usize,
        /// Seconds of load.
        #[arg(long, default_value_t = 60.0)]
        duration: f64,
        /// The size of each attempt's recording, KiB.
        #[arg(long, default_value_t = 1024)]
        recording_kib: usize,
        /// Attempts each station has queued when the hub is killed.
        #[arg(long, default_value_t = 20)]
        queued: usize,
        /// Machine-readable output.
        #[arg(long)]
        json: bool,
    },
    /// Load on the web dashboard: TRAINEES x ATTEMPTS synthetic attempts, CLIENTS concurrent
    /// clients on the progress page and API; requests/s and latency percentiles.
    Dashboard {
        /// The database to seed and serve (reused if present): an SQLite file or a
        /// `postgres://` URL; given again, each in turn, the figures side by side.
        #[arg(long, default_value = "out/bench-dashboard/cutlab.db")]
        bench_db: Vec<cutlab_assessor::DbLocation>,
        #[arg(long, default_value_t = 100)]
        trainees: usize,
        #[arg(long, default_value_t = 50)]
        attempts: usize,
        #[arg(long, default_value_t = 200)]
        clients: usize,
        /// Seconds per target.
        #[arg(long, default_value_t = 10.0)]
        duration: f64,
        /// Machine-readable output.
        #[arg(long)]
        json: bool,
    },
}

/// Runs one benchmark.
pub fn run(command: BenchCommand) -> anyhow::Result<()> {
    match command {
        BenchCommand::Step {
            quick,
            json,
            tets,
            integrator,
        } => step::step(quick, json, &tets, integrator),
        BenchCommand::Accuracy { quick, json, out } => accuracy::run(quick, json, &out),
        BenchCommand::Stability { quick, json } => stability::run(quick, json),
        BenchCommand::Perf { quick, json, out } => perf::run(quick, json, &out),
        BenchCommand::Skip { quick, json, out } => skip::run(quick, json, &out),
        BenchCommand::Exercises { json, out } => exercises::run(json, &out),
        BenchCommand::Budget { json } => budget::run(json),
        BenchCommand::Hub {
            out,
            stations,
            duration,
            recording_kib,
            queued,
            json,
        } => hub::run(&hub::Options {
            out: &out,
            stations,
            duration_s: duration,
            recording_kib,
            queued,
            json,
        }),
        BenchCommand::Dashboard {
            bench_db,
            trainees,
            attempts,
            clients,
            duration,
            json,
        } => dashboard::run_bench(&dashboard::Options {
            dbs: &bench_db,
            trainees,
            attempts,
            clients,
            duration_s: duration,
            json,
        }),
        BenchCommand::Station {
            tets,
            quick,
            duration,
            time_step_ms,
            json,
        } => station::run(&station::Options {
            time_step: time_step_ms,
            tets: match (tets.is_empty(), quick) {
                (false, _) => tets,
                (true, true) => vec![12_800],
                (true, false) => vec![12_800, 100_000],
            },
            duration_s: if quick { duration.min(5.0) } else { duration },
            json,
        }),
        BenchCommand::Recorder {
            min_tets,
            duration,
            localise,
            json,
            out,
        } => recorder::run(min_tets, duration, localise, json, &out),
    }
}
