//! cutlab: the command line. Thin commands that wire the crates together.

mod assess_cli;
mod demo;
mod demo_seed;
mod evidence_cli;
mod hub_cli;
mod kinematics;
mod localise_choice;
mod motion_metrics;
mod plan_cli;
mod recording;
mod scene_info;
mod serve;
mod session;

use std::path::PathBuf;

use clap::{Parser, Subcommand};
use cutlab_haptics::TimeStep;
use localise_choice::Localise;

/// Training and assessment platform for surgical soft-tissue cutting.
// no Debug: it holds the hub token
#[derive(Parser)]
#[command(name = "cutlab", version, about)]
struct Cli {
    #[command(subcommand)]
    command: Command,
    /// The assessment database: an SQLite file or a `postgres://` URL (else $CUTLAB_DB, else
    /// ./cutlab.db).
    #[arg(long, global = true)]
    db: Option<cutlab_assessor::DbLocation>,
    /// The recording store an attempt's recordings are put into when it ends (besides the
    /// station's disk), and the dashboard serves them from: a folder or `s3://bucket/prefix`
    /// (else $CUTLAB_RECORDINGS, else the folder recordings/ beside an SQLite database).
    #[arg(long, global = true)]
    recordings: Option<String>,
    /// The hub this station sends its ended attempts to (after each attempt, and with
    /// `cutlab sync`): the hub's dashboard URL (else $CUTLAB_HUB, else none).
    #[arg(long, global = true)]
    hub: Option<String>,
    /// This station's token for the hub (`cutlab hub token create` on the hub; else
    /// $CUTLAB_HUB_TOKEN).
    #[arg(long, global = true)]
    hub_token: Option<String>,
}

impl Cli {
    /// `--recordings`, else `$CUTLAB_RECORDINGS` if set and not empty, else the folder
    /// `recordings/` beside an SQLite database (in the working directory for PostgreSQL).
    fn recordings(&self) -> Option<String> {
        let given = self.recordings.clone().or_else(|| {
            std::env::var(cutlab_assessor::recordings::RECORDINGS_ENV)
                .ok()
                .filter(|v| !v.trim().is_empty())
        });
        given.or_else(|| {
            let db = cutlab_assessor::default_db(self.db.as_ref());
            Some(beside_db(&db, "recordings").display().to_string())
        })
    }
}

/// The folder `name` beside an SQLite database's file (in the working directory for
/// PostgreSQL): where recordings and attempts' files are kept by default.
pub fn beside_db(db: &cutlab_assessor::DbLocation, name: &str) -> PathBuf {
    db.sqlite_path()
        .and_then(std::path::Path::parent)
        .unwrap_or(std::path::Path::new("."))
        .join(name)
}

/// How an OpenIGTLink device (`igtl:PORT`) sends the force back.
#[derive(Debug, clap::Args)]
struct IgtlArgs {
    /// With an `igtl:PORT` device: how the force goes back, `point` (a POINT message) or
    /// `transform` (the force as a TRANSFORM's translation, what PLUS Toolkit's OpenHaptics
    /// device takes).
    #[arg(long, default_value = "point")]
    force_output: cutlab_haptics::device::ForceOutput,
    /// With an `igtl:PORT` device: the force message's device name (PLUS Toolkit takes
    /// `ForceTo<reference frame>`, e.g. `ForceToRef`).
    #[arg(long, default_value = cutlab_haptics::device::igtl::FORCE_DEVICE_NAME)]
    force_name: String,
    /// With an `igtl:PORT` device: a second tool on the same connection, the second hand's
    /// grasper: the device name of its TRANSFORMs (e.g. `GrasperToRef`); a STRING named it
    /// with `Jaws` appended closes (`1`) or opens (`0`) the jaws; its force goes back named
    /// it with `Force` appended.
    #[arg(long)]
    igtl_grasper: Option<String>,
}

impl IgtlArgs {
    fn options(self) -> cutlab_haptics::device::IgtlOptions {
        cutlab_haptics::device::IgtlOptions {
            force_output: self.force_output,
            force_device_name: self.force_name,
            grasper: self
                .igtl_grasper
                .map(|name| cutlab_haptics::device::IgtlToolNames::grasper(&name)),
        }
    }
}

#[derive(Debug, Subcommand)]
enum Command {
    /// Build the default scene, settle it, run a scripted scalpel stroke and report.
    Demo {
        /// Directory for the results (`.vtu` meshes).
        #[arg(long, default_value = "out/demo")]
        out: PathBuf,
        /// Resolution of the chest wall: at least this many tetrahedra.
        #[arg(long)]
        min_tets: Option<usize>,
        /// The scene: `chest-wall` (the paper's springs) or `chest-wall-fem` (co-rotational
        /// finite elements), or another chest-wall-like scene.
        #[arg(long, default_value = "chest-wall")]
        scene: String,
        /// Then serve the web dashboard on this address (e.g. 127.0.0.1:8080) with the demo
        /// accounts, cohort, curriculum and simulated attempts (recordings in OUT/attempts)
        /// in the database (`--db`).
        #[arg(long)]
        addr: Option<String>,
    },
    /// The web dashboard on the assessment database (`--db`): progress, curriculum,
    /// supervision, replay review, JSON API.
    Serve {
        /// Address to listen on.
        #[arg(long, default_value = "127.0.0.1:8080")]
        addr: String,
        /// First create the demo accounts, cohort, curriculum and attempts (simulated, about
        /// a minute; recordings in demo-attempts/ beside the database; see the README).
        #[arg(long)]
        demo: bool,
        /// A device the station offers besides the page's pointer (repeatable): expert,
        /// intermediate, novice, level:L (a synthetic trainee cuts, the trainee watches),
        /// csv:PATH, recording:PATH or igtl:PORT (a tracker or haptic bridge).
        #[arg(long = "station-device")]
        station_devices: Vec<session::DeviceArg>,
        /// The station's simulation step: ms (0.1-10), `auto` or `scene`, as for `session`.
        #[arg(long, default_value = "scene")]
        station_time_step_ms: TimeStep,
        /// How long a station attempt waits for its page (a reload, a lost network, a hidden
        /// tab) before it ends incomplete, s (1-3600); shorter gaps pause the blade.
        #[arg(long, default_value_t = 30.0)]
        absence_s: f64,
        #[command(flatten)]
        igtl: IgtlArgs,
        /// Mark the session cookies `Secure`: for a dashboard reached over HTTPS (a proxy in
        /// front that ends TLS). Also $CUTLAB_SECURE_COOKIES=1.
        #[arg(long, env = "CUTLAB_SECURE_COOKIES")]
        secure_cookies: bool,
        /// The address people reach this dashboard at (`https://cutlab.example.org`), from
        /// which the links it hands out are built; else from each request's own address and
        /// scheme. Also $CUTLAB_PUBLIC_URL.
        #[arg(long, env = "CUTLAB_PUBLIC_URL")]
        public_url: Option<cutlab_dashboard::PublicUrl>,
    },
    /// The trainee station on this PC for one trainee: serves the dashboard on this machine
    /// and opens the station page in the browser, logged in through a one-time link (a new
    /// trainee is added without a password).
    Station {
        /// The trainee (e.g. ana).
        #[arg(long)]
        trainee: String,
        /// Address to listen on (port 0: any free port).
        #[arg(long, default_value = "127.0.0.1:8080")]
        addr: String,
        /// A device offered besides the page's pointer (repeatable), as for `serve`.
        #[arg(long)]
        device: Vec<session::DeviceArg>,
        /// The simulation step: ms (0.1-10), `scene`, or `auto` (the smallest that keeps real
        /// time on this PC, measured at each start), as for `session`.
        #[arg(long, default_value = "auto")]
        time_step_ms: TimeStep,
        /// How long an attempt waits for its page before it ends incomplete, s, as for
        /// `serve`.
        #[arg(long, default_value_t = 30.0)]
        absence_s: f64,
        #[command(flatten)]
        igtl: IgtlArgs,
        /// Only print the station's link (no browser is opened).
        #[arg(long)]
        no_browser: bool,
    },
    /// Run one training session: a device drives the scalpel through the 1 kHz servo loop
    /// while the simulation runs; prints a summary and writes DIR/final.vtu.
    Session(Box<SessionArgs>),
    /// Session recordings (MCAP): what is in one, and salvaging one cut short.
    Recording {
        #[command(subcommand)]
        command: RecordingCommand,
    },
    /// Re-simulate a recorded session from its inputs and check every keyframe's state hash
    /// bit for bit; reports the first divergence precisely.
    Replay {
        /// The recording (DIR/session.mcap of `cutlab session`).
        file: PathBuf,
        /// max (as fast as possible), realtime, or a factor of real time (e.g. 4).
        #[arg(long, default_value = "max")]
        speed: cutlab_recorder::replay::Speed,
        /// Play from this session time, s: the replay resumes at the last keyframe before it
        /// (checked against the keyframe's hashes) and re-simulates from there, unpaced until
        /// this time.
        #[arg(long)]
        from: Option<f64>,
        /// With --from: re-simulate (and check) every step before it instead of resuming at
        /// a keyframe.
        #[arg(long, requires = "from")]
        resimulate: bool,
        /// Stop after this session time, s.
        #[arg(long)]
        to: Option<f64>,
        /// Count every divergence instead of stopping at the first.
        #[arg(long)]
        keep_going: bool,
        /// Accept a recording that is damaged or cut short: verify the readable part and say
        /// up to when (without it, such a replay ends with an error).
        #[arg(long)]
        partial: bool,
        /// Threads replaying the stretches between keyframes side by side (0: one per core);
        /// an unpaced replay without rerun output only.
        #[arg(long, default_value_t = 0)]
        jobs: usize,
        /// Export the played part to this `.rrd` file.
        #[arg(long, conflicts_with = "rerun")]
        rrd: Option<PathBuf>,
        /// Stream the played part to a rerun viewer: spawn or connect[=URL].
        #[arg(long)]
        rerun: Option<recording::RerunArg>,
        /// Machine-readable output.
        #[arg(long)]
        json: bool,
    },
    /// Scenes: built-in ones and scene files.
    Scene {
        #[command(subcommand)]
        command: SceneCommand,
    },
    /// Planning: candidate incisions cut in the simulation and compared by their field.
    Plan {
        #[command(subcommand)]
        command: plan_cli::PlanCommand,
    },
    /// Send this station's queue (ended attempts and their recordings) to its hub (--hub).
    Sync,
    /// A hub's stations: the tokens they upload with.
    Hub {
        #[command(subcommand)]
        command: hub_cli::HubCommand,
    },
    /// Benchmarks that print figures.
    Bench {
        #[command(subcommand)]
        command: cutlab_bench::BenchCommand,
    },
    #[command(flatten)]
    Assess(assess_cli::AssessCommand),
}

#[derive(Debug, Subcommand)]
enum RecordingCommand {
    /// Channels, message counts, duration, metadata and whether the file is complete.
    Info {
        file: PathBuf,
        /// Machine-readable output.
        #[arg(long)]
        json: bool,
    },
    /// Copy everything readable of a recording cut short (up to its last complete chunk) into
    /// a new, complete file.
    Recover {
        file: PathBuf,
        /// The new file (default: FILE with `.recovered.mcap`).
        #[arg(long)]
        out: Option<PathBuf>,
    },
}

#[derive(Debug, Subcommand)]
enum SceneCommand {
    /// Counts, volume, mass, bounding box and mesh quality of a scene or mesh file.
    Info {
        /// A built-in scene (chest-wall, sheet, bar, body-wall, skin-block, thorax, gauze), a scene file (.toml/.json) or a mesh file.
        scene: String,
        /// Resolution of a generated mesh: at least this many tetrahedra.
        #[arg(long)]
        min_tets: Option<usize>,
        /// Machine-readable output.
        #[arg(long)]
        json: bool,
    },
    /// List the built-in scenes.
    List,
}

fn parse_clock(
    s: &str,
) -> Result<cutlab_haptics::servo::Clock, cutlab_haptics::servo::UnknownClock> {
    s.parse()
}

fn main() -> std::process::ExitCode {
    stdout_errors_end_quietly();
    match run() {
        Ok(()) => std::process::ExitCode::SUCCESS,
        Err(e) => {
            // the whole chain on one line, without a backtrace: errors are for users
            eprintln!("error: {}", one_line(&e));
            std::process::ExitCode::FAILURE
        }
    }
}

/// The error and its causes on one line, each said once: a cause whose text is already in
/// the line (an error that shows its source, `#[error("database: {0}")]`) is not repeated.
fn one_line(e: &anyhow::Error) -> String {
    let mut out = String::new();
    for cause in e.chain() {
        let text = cause.to_string();
        if out.contains(&text) {
            continue;
        }
        if !out.is_empty() {
            out.push_str(": ");
        }
        out.push_str(&text);
    }
    out
}

/// `print!` panics when stdout is gone (`cutlab scene list | head -1`). Such a panic ends
/// the process like a Unix tool: quietly with status 141 on a closed pipe, with a one-line
/// error and status 1 on any other write error. (The SIGPIPE signal itself stays ignored, as
/// Rust sets it, so that the dashboard and the OpenIGTLink device see a closed socket as an
/// error instead of being killed.) Every other panic goes to the default hook.
fn stdout_errors_end_quietly() {
    let default = std::panic::take_hook();
    std::panic::set_hook(Box::new(move |info| {
        let payload = info.payload();
        let message = payload
            .downcast_ref::<String>()
            .map(String::as_str)
            .or_else(|| payload.downcast_ref::<&str>().copied());
        match message {
            Some(m) if m.starts_with("failed printing to stdout") => {
                if m.contains("Broken pipe") {
                    std::process::exit(141);
                }
                eprintln!("error: {m}");
                std::process::exit(1);
            }
            _ => default(info),
        }
    }));
}

/// `cutlab session`'s arguments.
#[derive(Debug, clap::Args)]
struct SessionArgs {
    /// A built-in scene (chest-wall, sheet, bar, body-wall, skin-block, thorax, gauze) or a scene/mesh file; by
    /// default the exercise's (with `--exercise`), else chest-wall.
    #[arg(long)]
    scene: Option<String>,
    /// Resolution of a generated mesh: at least this many tetrahedra.
    #[arg(long)]
    min_tets: Option<usize>,
    /// The simulation step: ms (0.1-10, a whole number of servo periods), `scene` (the
    /// scene's own), or `auto` (the smallest of 1, 2, 4, 5, 10 ms whose loaded step takes at
    /// most 70 % of it on this machine, measured at the start): longer steps keep a big
    /// mesh in real time at some cost in accuracy.
    #[arg(long, default_value = "scene")]
    time_step_ms: TimeStep,
    /// expert | intermediate | novice (synthetic trainee), level:L (a trainee between them,
    /// 0 novice to 1 expert), pointer:steady | pointer:sloppy | pointer:lagging (a person's
    /// hand model on the station's pointer; lagging: on a page held back to 7 Hz), csv:PATH (trajectory file), recording:PATH (the hand of a
    /// recorded session, played back) or igtl:PORT (OpenIGTLink server).
    #[arg(long, default_value = "expert")]
    device: session::DeviceArg,
    #[command(flatten)]
    igtl: IgtlArgs,
    /// live (real time) or virtual (as fast as possible, same ticks).
    #[arg(long, default_value = "virtual", value_parser = parse_clock)]
    clock: cutlab_haptics::servo::Clock,
    /// Session length in seconds.
    #[arg(long, default_value_t = 10.0)]
    duration: f64,
    /// Seed of the synthetic trainee.
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Directory for final.vtu and summary.json.
    #[arg(long, default_value = "out/session")]
    out: PathBuf,
    /// Do not ask for real-time priority for the servo thread.
    #[arg(long)]
    no_realtime: bool,
    /// A keyframe of the full simulation state every this many seconds.
    #[arg(long, default_value_t = 1.0)]
    keyframe_every: f64,
    /// The tissue surface is recorded this many times per second (0: never).
    #[arg(long, default_value_t = 10.0)]
    surface_hz: f64,
    /// Also write DIR/session.rrd for the rerun viewer.
    #[arg(long, conflicts_with = "rerun")]
    rrd: bool,
    /// Stream to a rerun viewer: spawn (start one) or connect[=URL].
    #[arg(long)]
    rerun: Option<recording::RerunArg>,
    /// The trainee at the station: the attempt is stored as running when the session
    /// starts, then scored against `--exercise` (or marked incomplete if it fails).
    #[arg(long)]
    trainee: Option<String>,
    /// The exercise attempted (with --trainee).
    #[arg(long, default_value = cutlab_assessor::store::BUILTIN_EXERCISE, requires = "trainee")]
    exercise: String,
    /// Simulate only near the scalpel and the disturbance it causes (default thresholds;
    /// the recording keeps them, so the replay is localised too): `auto` where
    /// `cutlab bench perf` measured it to pay on this scene and size (docs/bench/perf.md),
    /// `on` (also plain `--localise`), `off`.
    #[arg(long, value_enum, default_value_t = Localise::Auto, num_args = 0..=1, default_missing_value = "on")]
    localise: Localise,
    /// A synthetic trainee uses both hands: its other hand's grasper holds the tissue beside
    /// the incision and draws it as its skill does (an expert close beside the line, away
    /// from it and up, to the end; a novice far off, towards the line, letting go part way).
    #[arg(long, conflicts_with = "grasp_at_mm")]
    second_hand: bool,
    /// A second hand on a grasper: where its jaws close on the tissue, mm (`X,Y,Z`). The hand
    /// reaches there, closes the jaws at 1.2 s, draws the tissue by `--grasp-pull-mm` and holds
    /// it (its pose, jaws and pull are recorded).
    #[arg(long, value_parser = parse_mm3, value_name = "X,Y,Z")]
    grasp_at_mm: Option<[f64; 3]>,
    /// How far and where the grasper draws the held tissue, mm (`DX,DY,DZ`).
    #[arg(long, value_parser = parse_mm3, value_name = "DX,DY,DZ", default_value = "0,0,5", requires = "grasp_at_mm")]
    grasp_pull_mm: [f64; 3],
    /// When the grasper opens its jaws and lifts away, s (default: it holds to the end).
    #[arg(long, requires = "grasp_at_mm")]
    grasp_release_s: Option<f64>,
}

/// Three finite numbers in millimetres, `X,Y,Z`.
fn parse_mm3(text: &str) -> Result<[f64; 3], String> {
    let v: Vec<f64> = text
        .split(',')
        .map(|c| c.trim().parse::<f64>())
        .collect::<Result<_, _>>()
        .map_err(|e| format!("{text:?}: three numbers X,Y,Z in mm ({e})"))?;
    match v.as_slice() {
        &[x, y, z] if v.iter().all(|c| c.is_finite()) => Ok([x, y, z]),
        _ => Err(format!("{text:?}: three finite numbers X,Y,Z in mm")),
    }
}

impl SessionArgs {
    /// The second hand's grasp, when asked for.
    fn grasp(&self) -> Option<cutlab_haptics::device::GraspPlan> {
        let [x, y, z] = self.grasp_at_mm?;
        let [dx, dy, dz] = self.grasp_pull_mm;
        Some(cutlab_haptics::device::GraspPlan {
            hold_m: cutlab_sim::Point3::new(x, y, z) * 1e-3,
            pull_m: cutlab_sim::Vector3::new(dx, dy, dz) * 1e-3,
            up: cutlab_sim::Vector3::z(),
            release_s: self.grasp_release_s,
        })
    }

    /// The session's options; an attempt in the database `db` when a trainee is named.
    fn options(
        self,
        db: cutlab_assessor::DbLocation,
        recordings: Option<String>,
        hub: Option<cutlab_station::sync::Hub>,
    ) -> session::Options {
        let grasp = self.grasp();
        session::Options {
            scene: self.scene,
            device: self.device,
            run: cutlab_station::attempt_run::RunSettings {
                min_tets: self.min_tets,
                time_step: self.time_step_ms,
                clock: self.clock,
                duration_s: self.duration,
                realtime_priority: !self.no_realtime,
                keyframe_every_s: self.keyframe_every,
                surface_hz: self.surface_hz,
                seed: self.seed,
                grasp,
                second_hand: self.second_hand,
                igtl: self.igtl.options(),
            },
            out: self.out,
            rerun: recording::rerun_target(
                self.rrd.then_some(std::path::Path::new("session.rrd")),
                self.rerun.as_ref(),
            ),
            attempt: self.trainee.map(|trainee| session::AttemptArgs {
                db,
                recordings,
                hub,
                exercise: self.exercise,
                trainee,
                expert: false,
            }),
            localise: self.localise,
        }
    }
}

fn run() -> anyhow::Result<()> {
    tracing_subscriber::fmt()
        .with_env_filter(
            tracing_subscriber::EnvFilter::try_from_default_env()
                // PostgreSQL's notices ("... already exists, skipping") are not news
                .unwrap_or_else(|_| "info,sqlx::postgres::notice=warn".into()),
        )
        .with_writer(std::io::stderr)
        .init();
    let cli = Cli::parse();
    let recordings = cli.recordings();
    let hub = hub_cli::hub(cli.hub.as_deref(), cli.hub_token.as_deref())?;
    match cli.command {
        Command::Demo {
            out,
            min_tets,
            scene,
            addr,
        } => {
            demo::run(&out, min_tets, &scene)?;
            match addr {
                Some(addr) => serve::run(serve::Options {
                    demo: Some(&out.join("attempts")),
                    ..serve::Options::dashboard(
                        &cutlab_assessor::default_db(cli.db.as_ref()),
                        &addr,
                        recordings,
                        hub,
                    )
                }),
                None => Ok(()),
            }
        }
        Command::Serve {
            addr,
            demo,
            station_devices,
            station_time_step_ms,
            absence_s,
            igtl,
            secure_cookies,
            public_url,
        } => {
            let db = cutlab_assessor::default_db(cli.db.as_ref());
            // beside an SQLite file; in the working directory for a server
            let demo_attempts = beside_db(&db, "demo-attempts");
            serve::run(serve::Options {
                demo: demo.then_some(demo_attempts.as_path()),
                station_devices,
                station_time_step: station_time_step_ms,
                station_absence_s: absence_s,
                igtl: igtl.options(),
                secure_cookies,
                public_url,
                ..serve::Options::dashboard(&db, &addr, recordings, hub)
            })
        }
        Command::Station {
            trainee,
            addr,
            device,
            time_step_ms,
            absence_s,
            igtl,
            no_browser,
        } => {
            let db = cutlab_assessor::default_db(cli.db.as_ref());
            serve::run(serve::Options {
                station_devices: device,
                station_time_step: time_step_ms,
                station_absence_s: absence_s,
                igtl: igtl.options(),
                kiosk: Some(serve::Kiosk {
                    trainee,
                    open_browser: !no_browser,
                }),
                ..serve::Options::dashboard(&db, &addr, recordings, hub)
            })
        }
        Command::Scene {
            command:
                SceneCommand::Info {
                    scene,
                    min_tets,
                    json,
                },
        } => scene_info::run(&scene, min_tets, json),
        Command::Session(args) => session::run(&args.options(
            cutlab_assessor::default_db(cli.db.as_ref()),
            recordings.clone(),
            hub.clone(),
        )),
        Command::Recording {
            command: RecordingCommand::Info { file, json },
        } => recording::info(&file, json),
        Command::Recording {
            command: RecordingCommand::Recover { file, out },
        } => recording::recover(&file, out.as_deref()),
        Command::Replay {
            file,
            speed,
            from,
            resimulate,
            to,
            keep_going,
            partial,
            jobs,
            json,
            rrd,
            rerun,
        } => {
            let rerun = recording::rerun_target(rrd.as_deref(), rerun.as_ref());
            recording::replay(
                &file,
                recording::ReplayArgs {
                    speed,
                    from_s: from,
                    resimulate,
                    to_s: to,
                    keep_going,
                    partial,
                    jobs,
                    json,
                    rerun,
                },
            )
        }
        Command::Scene {
            command: SceneCommand::List,
        } => {
            scene_info::list();
            Ok(())
        }
        Command::Plan { command } => plan_cli::run(cli.db.as_ref(), command),
        Command::Sync => hub_cli::sync(
            &cutlab_assessor::default_db(cli.db.as_ref()),
            hub,
            recordings.as_deref(),
        ),
        Command::Hub { command } => {
            hub_cli::run(&cutlab_assessor::default_db(cli.db.as_ref()), command)
        }
        Command::Bench { command } => cutlab_bench::run(command),
        Command::Assess(command) => assess_cli::run(cli.db.as_ref(), command),
    }
}

#[cfg(test)]
mod tests {
    use super::one_line;

    #[test]
    fn a_cause_is_said_once() {
        /// An error that shows its source, as `#[error("database: {0}")]` does.
        #[derive(Debug)]
        struct Shows(std::io::Error);
        impl std::fmt::Display for Shows {
            fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
                write!(f, "database: {}", self.0)
            }
        }
        impl std::error::Error for Shows {
            fn source(&self) -> Option<&(dyn std::error::Error + 'static)> {
                Some(&self.0)
            }
        }
        let io = std::io::Error::new(std::io::ErrorKind::ConnectionRefused, "refused");
        let e = anyhow::Error::new(Shows(io)).context("opening the database x");
        assert_eq!(one_line(&e), "opening the database x: database: refused");
        let plain = anyhow::anyhow!("inner").context("outer");
        assert_eq!(one_line(&plain), "outer: inner");
    }
}
