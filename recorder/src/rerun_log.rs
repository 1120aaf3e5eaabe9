//! A session logged to rerun: to an `.rrd` file, to a viewer this process spawns, or to a
//! viewer already running (gRPC).
//!
//! What is logged, and on which timelines (`tick`: the servo tick, a sequence; `sim_time`:
//! `tick * period`, a duration; `step`: the simulation step, on the simulation's records only):
//!
//! | entity | archetype | when |
//! |---|---|---|
//! | `force/x`, `force/y`, `force/z`, `force/norm` | `Scalars` (N) | every tick, sent in columns |
//! | `contact/mode` | `Scalars` (0 free, 1 touching, 2 cutting) | every tick, in columns |
//! | `contact/penetration` | `Scalars` (m, tip to proxy: 0 when free or cutting) | every tick, in columns |
//! | `world/scalpel` | `Transform3D` (tip, `world_from_tool`) | ~30 Hz of ticks |
//! | `world/scalpel/blade` | `LineStrips3D` (static, in the tool frame: the tip along +z) | once |
//! | `world/proxy` | `Points3D` (the force renderer's proxy) | ~30 Hz of ticks |
//! | `world/tissue` | `Mesh3D` (f32, vertex normals) | each `SimRecord::Surface` |
//! | `world/plan` | `LineStrips3D` (static) | [`RerunSink::log_plan`] |
//! | `events` | `TextLog` | what happened to the hand's device (fault changes): the review's Events view |
//! | `engine/events` | `TextLog` | the engine's own lines: cuts, keyframes (with their hashes), rejected steps (in the file, not in the review's layout: they mean nothing to an instructor) |
//!
//! Every log carries [`review_blueprint`], the layout a review opens in (a large 3D view of
//! the tissue above the force plot and the events), and the tissue is there from the first
//! step ([`cutlab_haptics::tap::surface_due`]).
//!
//! The 1 kHz series never cost one rerun call per tick: [`RerunSink::on_tick`] appends to
//! column buffers and sends them (`send_columns`) every [`FILE_BATCH_TICKS`] ticks to a file,
//! every [`LIVE_BATCH_TICKS`] to a viewer (so its plots lag by a tenth of a second at most).
//! The blade is a static strip under `world/scalpel`, so its transform carries it: one
//! transform per visual frame is the whole cost of the scalpel.
//!
//! Nothing here runs unless a sink is built: a recorder without `--rrd`/`--rerun` holds no
//! [`RerunSink`] and pays nothing.

use cutlab_haptics::damage::DamageKind;
use std::path::PathBuf;
use std::time::Duration;

use cutlab_haptics::plan::Plan;
use cutlab_haptics::render::{Mode, fault};
use cutlab_haptics::servo::ServoSample;
use cutlab_haptics::tap::{Keyframe, SurfaceSnapshot};
use cutlab_haptics::{Point3, SimRecord, Vector3};
use cutlab_sim::cut::{Blade, CutEvent};
use rerun::{RecordingStream, RecordingStreamBuilder, RecordingStreamError};

/// Name of the sequence timeline of servo ticks.
pub const TIMELINE_TICK: &str = "tick";
/// Name of the duration timeline (`tick * period`).
pub const TIMELINE_SIM_TIME: &str = "sim_time";
/// Name of the sequence timeline of simulation steps (simulation records only).
pub const TIMELINE_STEP: &str = "step";

/// Ticks buffered before the series are sent, when writing a file.
pub const FILE_BATCH_TICKS: usize = 1000;
/// Ticks buffered before the series are sent, when streaming to a viewer.
pub const LIVE_BATCH_TICKS: usize = 100;
/// Rate of the scalpel's transform, Hz.
pub const VISUAL_RATE_HZ: f64 = 30.0;
/// How long [`RerunSink::finish`] waits for a viewer to take the last data.
pub const LIVE_FLUSH_TIMEOUT: Duration = Duration::from_secs(10);

/// Entity paths.
pub mod paths {
    pub const FORCE_X: &str = "force/x";
    pub const FORCE_Y: &str = "force/y";
    pub const FORCE_Z: &str = "force/z";
    pub const FORCE_NORM: &str = "force/norm";
    pub const CONTACT_MODE: &str = "contact/mode";
    pub const CONTACT_PENETRATION: &str = "contact/penetration";
    pub const SCALPEL: &str = "world/scalpel";
    pub const BLADE: &str = "world/scalpel/blade";
    pub const PROXY: &str = "world/proxy";
    /// The second hand's grasper: its jaws' centre, open (grey) or closed (blue).
    pub const GRASPER: &str = "world/grasper";
    pub const TISSUE: &str = "world/tissue";
    pub const PLAN: &str = "world/plan";
    pub const EVENTS: &str = "events";
    pub const ENGINE_EVENTS: &str = "engine/events";
}

/// Where a session's rerun log goes.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum RerunTarget {
    /// An `.rrd` file (created or truncated).
    File(PathBuf),
    /// A viewer started from the `rerun` executable on `PATH` (or one already listening on
    /// rerun's default port).
    Spawn,
    /// A viewer already running, by its gRPC url (see [`RerunTarget::connect_default`]).
    Connect(String),
}

impl RerunTarget {
    /// A viewer on this machine at rerun's default url (`rerun+http://127.0.0.1:9876/proxy`).
    pub fn connect_default() -> Self {
        Self::Connect(rerun::DEFAULT_CONNECT_URL.to_owned())
    }

    fn is_live(&self) -> bool {
        !matches!(self, Self::File(_))
    }
}

/// What can go wrong while logging to rerun.
#[derive(Debug, thiserror::Error)]
pub enum RerunLogError {
    /// The sink's settings make no sense.
    #[error("invalid rerun sink settings: {0}")]
    Settings(String),
    /// No viewer could be started (most often: no `rerun` executable on `PATH`).
    #[error("could not start the rerun viewer (install one, or record to a file with --rrd): {0}")]
    Spawn(#[source] rerun::SpawnError),
    /// The recording stream could not be created or refused data (file, url, chunk).
    #[error("rerun recording stream: {0}")]
    Stream(#[source] RecordingStreamError),
    /// Data could not be serialized into rerun's components.
    #[error("rerun serialization: {0}")]
    Serialization(#[from] rerun::SerializationError),
    /// The last data did not reach its destination.
    #[error("rerun flush: {0}")]
    Flush(#[from] rerun::sink::SinkFlushError),
}

impl From<RecordingStreamError> for RerunLogError {
    fn from(e: RecordingStreamError) -> Self {
        match e {
            RecordingStreamError::SpawnViewer(e) => Self::Spawn(e),
            e => Self::Stream(e),
        }
    }
}

/// The 1 kHz series waiting to be sent.
#[derive(Debug, Default)]
struct Columns {
    ticks: Vec<i64>,
    sim_time_nanos: Vec<i64>,
    force: [Vec<f64>; 4],
    mode: Vec<f64>,
    penetration: Vec<f64>,
}

impl Columns {
    fn with_capacity(n: usize) -> Self {
        let v = || Vec::with_capacity(n);
        Self {
            ticks: Vec::with_capacity(n),
            sim_time_nanos: Vec::with_capacity(n),
            force: [v(), v(), v(), v()],
            mode: v(),
            penetration: v(),
        }
    }

    fn len(&self) -> usize {
        self.ticks.len()
    }

    fn clear(&mut self) {
        self.ticks.clear();
        self.sim_time_nanos.clear();
        self.force.iter_mut().for_each(Vec::clear);
        self.mode.clear();
        self.penetration.clear();
    }
}

/// A session's rerun log. Built only when asked for; see the module documentation for what it
/// logs where.
#[derive(Debug)]
pub struct RerunSink {
    rec: RecordingStream,
    live: bool,
    period_nanos: u64,
    batch_ticks: usize,
    visual_every_ticks: u64,
    last_visual_tick: Option<u64>,
    columns: Columns,
    /// Triangles of the last surface logged: unchanged ones are not sent again.
    last_triangles: Vec<[u32; 3]>,
    rejected_steps: u64,
    /// Fault bits of the last tick: a change is an event.
    last_faults: u8,
    ticks_logged: u64,
}

impl RerunSink {
    /// Opens the log: `application` names the rerun application (e.g. `"cutlab"`),
    /// `period_nanos` is the servo period (the `sim_time` of a tick is `tick * period`),
    /// `blade_length_m` the length of the blade drawn from the tip.
    pub fn new(
        target: &RerunTarget,
        application: &str,
        period_nanos: u64,
        blade_length_m: f64,
    ) -> Result<Self, RerunLogError> {
        if period_nanos == 0 {
            return Err(RerunLogError::Settings(
                "the servo period must be positive".into(),
            ));
        }
        if !(blade_length_m > 0.0 && blade_length_m.is_finite()) {
            return Err(RerunLogError::Settings(format!(
                "the blade length must be positive and finite, got {blade_length_m} m"
            )));
        }
        // `enabled(true)`: asked for explicitly, so the `RERUN` environment variable does not
        // silently turn it off.
        let application = rerun::ApplicationId::try_new(application)
            .map_err(|e| RerunLogError::Settings(format!("application id {application:?}: {e}")))?;
        let builder = RecordingStreamBuilder::new(application).enabled(true);
        let rec = match target {
            RerunTarget::File(path) => builder.save(path)?,
            RerunTarget::Spawn => builder.spawn_opts(&rerun::SpawnOptions {
                hide_welcome_screen: true,
                ..Default::default()
            })?,
            RerunTarget::Connect(url) => builder.connect_grpc_opts(url.clone())?,
        };
        Self::with_stream(rec, target.is_live(), period_nanos, blade_length_m)
    }

    fn with_stream(
        rec: RecordingStream,
        live: bool,
        period_nanos: u64,
        blade_length_m: f64,
    ) -> Result<Self, RerunLogError> {
        // Wall-clock time means nothing in a replay: the timelines are the session's own.
        rec.set_log_time_enabled(false);
        let batch_ticks = if live {
            LIVE_BATCH_TICKS
        } else {
            FILE_BATCH_TICKS
        };
        let visual_every_ticks = ((1e9 / VISUAL_RATE_HZ) / period_nanos as f64)
            .round()
            .max(1.0) as u64;
        let sink = Self {
            rec,
            live,
            period_nanos,
            batch_ticks,
            visual_every_ticks,
            last_visual_tick: None,
            columns: Columns::with_capacity(batch_ticks),
            last_triangles: Vec::new(),
            rejected_steps: 0,
            last_faults: 0,
            ticks_logged: 0,
        };
        sink.log_static_styles(blade_length_m)?;
        send_review_blueprint(&sink.rec, None)?;
        Ok(sink)
    }

    fn log_static_styles(&self, blade_length_m: f64) -> Result<(), RerunLogError> {
        use rerun::{Color, LineStrips3D, SeriesLines, TransformAxes3D};
        let rec = &self.rec;
        let series = [
            (paths::FORCE_X, "Fx (N)", Color::from_rgb(220, 60, 60)),
            (paths::FORCE_Y, "Fy (N)", Color::from_rgb(60, 170, 60)),
            (paths::FORCE_Z, "Fz (N)", Color::from_rgb(60, 90, 220)),
            (paths::FORCE_NORM, "|F| (N)", Color::from_rgb(30, 30, 30)),
            (
                paths::CONTACT_PENETRATION,
                "penetration (m)",
                Color::from_rgb(150, 80, 200),
            ),
        ];
        for (path, name, color) in series {
            rec.log_static(
                path,
                &SeriesLines::new().with_names([name]).with_colors([color]),
            )?;
        }
        rec.log_static(
            paths::CONTACT_MODE,
            &SeriesLines::new()
                .with_names(["mode (0 free, 1 touching, 2 cutting)"])
                .with_interpolation_mode(rerun::components::InterpolationMode::StepAfter),
        )?;
        // The tool frame: origin at the tip, +z along the cutting edge, +x the cutting direction.
        let l = blade_length_m as f32;
        rec.log_static(
            paths::BLADE,
            &LineStrips3D::new([[[0.0, 0.0, 0.0], [0.0, 0.0, l]]])
                .with_radii([rerun::Radius::new_ui_points(2.0)])
                .with_colors([Color::from_rgb(200, 200, 210)]),
        )?;
        rec.log_static(paths::SCALPEL, &TransformAxes3D::new(0.5 * l))?;
        Ok(())
    }

    /// Frames the review's 3D view from `eye` (the exercise's viewpoint, [`plan_view`]); the
    /// layout is sent again with it.
    pub fn frame_view(&mut self, eye: &ReviewEye) -> Result<(), RerunLogError> {
        let ReviewEye {
            position_m,
            look_target_m,
            up,
        } = eye;
        let finite = position_m
            .iter()
            .chain(look_target_m.iter())
            .chain(up.iter().flat_map(|u| u.iter()))
            .all(|v| v.is_finite());
        let up_ok = up.is_none_or(|u| u.norm() > 1e-9);
        if !(finite && up_ok && position_m != look_target_m) {
            return Err(RerunLogError::Settings(format!(
                "a view from {position_m:?} to {look_target_m:?} (up {up:?}): two different \
                 finite points and a finite, non-zero up needed"
            )));
        }
        send_review_blueprint(&self.rec, Some(eye))
    }

    /// A session's log (application `cutlab`) with its plan logged and the view framed on it,
    /// when it has one: what `cutlab session`, the station and `cutlab replay` open.
    pub fn of_session(
        target: &RerunTarget,
        period_nanos: u64,
        blade_length_m: f64,
        plan: Option<&Plan>,
    ) -> Result<Self, RerunLogError> {
        let mut sink = Self::new(target, "cutlab", period_nanos, blade_length_m)?;
        if let Some(plan) = plan {
            sink.log_plan(plan)?;
        }
        Ok(sink)
    }

    /// The planned incision, as a static line strip (metres, world frame), and the 3D view
    /// framed on it ([`plan_view`]).
    pub fn log_plan(&mut self, plan: &Plan) -> Result<(), RerunLogError> {
        let strip: Vec<[f32; 3]> = plan.line_m.iter().map(f32x3).collect();
        self.rec.log_static(
            paths::PLAN,
            &rerun::LineStrips3D::new([strip])
                .with_radii([rerun::Radius::new_ui_points(1.5)])
                .with_colors([rerun::Color::from_rgb(40, 200, 90)]),
        )?;
        match plan_view(plan) {
            Some(eye) => self.frame_view(&eye),
            None => Ok(()),
        }
    }

    /// One servo tick: buffered; the series go out every batch, the scalpel at ~30 Hz.
    pub fn on_tick(&mut self, sample: &ServoSample) -> Result<(), RerunLogError> {
        let f = &sample.render.force_newtons;
        let c = &mut self.columns;
        c.ticks.push(to_i64(sample.tick));
        c.sim_time_nanos
            .push(to_i64(sample.tick.saturating_mul(self.period_nanos)));
        c.force[0].push(f.x);
        c.force[1].push(f.y);
        c.force[2].push(f.z);
        c.force[3].push(f.norm());
        c.mode.push(mode_value(sample.render.mode));
        c.penetration
            .push((sample.pose.tip_in_world - sample.render.proxy).norm());
        self.ticks_logged += 1;

        let faults = sample.render.faults;
        if faults != self.last_faults {
            let (text, level) = if faults == 0 {
                (
                    format!("tick {}: faults cleared", sample.tick),
                    rerun::TextLogLevel::INFO,
                )
            } else {
                (
                    format!(
                        "tick {}: fault: {} (bits {faults:#04b})",
                        sample.tick,
                        fault::describe(faults)
                    ),
                    rerun::TextLogLevel::WARN,
                )
            };
            self.last_faults = faults;
            self.set_time(sample.tick, None);
            self.rec
                .log(paths::EVENTS, &rerun::TextLog::new(text).with_level(level))?;
        }
        let due = self
            .last_visual_tick
            .is_none_or(|last| sample.tick.abs_diff(last) >= self.visual_every_ticks);
        if due {
            self.last_visual_tick = Some(sample.tick);
            self.log_tool(sample)?;
        }
        if self.columns.len() >= self.batch_ticks {
            self.send_series()?;
        }
        Ok(())
    }

    /// One record of the simulation thread.
    pub fn on_sim(&mut self, record: &SimRecord) -> Result<(), RerunLogError> {
        match record {
            SimRecord::Step {
                step,
                tick,
                rejected,
            } => {
                if *rejected {
                    self.rejected_steps += 1;
                    // The first one, then one line per hundred: a diverging simulation must
                    // not flood the log.
                    if self.rejected_steps % 100 == 1 {
                        let text = format!(
                            "step {step}: the simulation rejected the step (non-finite state; {} rejected so far)",
                            self.rejected_steps
                        );
                        self.log_event(*tick, *step, text, rerun::TextLogLevel::WARN)?;
                    }
                }
            }
            SimRecord::Cut {
                step,
                tick,
                blade,
                event,
            } => {
                let level = if event.forced_splits > 0 {
                    rerun::TextLogLevel::WARN
                } else {
                    rerun::TextLogLevel::INFO
                };
                self.log_event(*tick, *step, cut_text(*step, blade, event), level)?;
            }
            SimRecord::Damage { step, tick, damage } => {
                let what = match damage.kind {
                    DamageKind::BladeOnBone => "the blade came down on bone",
                    DamageKind::SpareCut => "a structure to spare was cut",
                };
                let text = format!("step {step}: {what} (region {})", damage.region);
                self.log_event(*tick, *step, text, rerun::TextLogLevel::WARN)?;
            }
            SimRecord::Keyframe(k) => {
                self.log_event(k.tick, k.step, keyframe_text(k), rerun::TextLogLevel::DEBUG)?;
            }
            SimRecord::Surface(s) => self.log_surface(s)?,
        }
        Ok(())
    }

    /// Sends what is buffered and waits for it to reach the file (or, at most
    /// [`LIVE_FLUSH_TIMEOUT`], the viewer). The sink goes on logging after it.
    pub fn flush(&mut self) -> Result<(), RerunLogError> {
        self.send_series()?;
        if self.live {
            self.rec.flush_with_timeout(LIVE_FLUSH_TIMEOUT)?;
        } else {
            self.rec.flush_blocking()?;
        }
        Ok(())
    }

    /// [`Self::flush`], then closes the log: a file is complete (footer written) on return.
    ///
    /// Dropping the sink instead sends what is buffered and completes the file too, but says
    /// nothing of what went wrong.
    pub fn finish(mut self) -> Result<(), RerunLogError> {
        self.flush()?;
        if !self.live {
            // A file sink writes its footer when it is torn down: now, not at some later drop.
            self.rec.finalize_deferred_sinks();
        }
        Ok(())
    }

    /// Ticks received so far.
    pub fn ticks_logged(&self) -> u64 {
        self.ticks_logged
    }

    fn set_time(&self, tick: u64, step: Option<u64>) {
        self.rec.reset_time();
        self.rec.set_time_sequence(TIMELINE_TICK, to_i64(tick));
        self.rec.set_time(
            TIMELINE_SIM_TIME,
            Duration::from_nanos(tick.saturating_mul(self.period_nanos)),
        );
        if let Some(step) = step {
            self.rec.set_time_sequence(TIMELINE_STEP, to_i64(step));
        }
    }

    fn log_tool(&self, sample: &ServoSample) -> Result<(), RerunLogError> {
        self.set_time(sample.tick, None);
        let q = sample.pose.world_from_tool.quaternion();
        let rotation =
            rerun::Quaternion::from_xyzw([q.i as f32, q.j as f32, q.k as f32, q.w as f32]);
        self.rec.log(
            paths::SCALPEL,
            &rerun::Transform3D::from_translation(f32x3(&sample.pose.tip_in_world))
                .with_quaternion(rotation),
        )?;
        let color = match sample.render.mode {
            Mode::Free => rerun::Color::from_rgb(150, 150, 150),
            Mode::Touching => rerun::Color::from_rgb(240, 180, 40),
            Mode::Cutting => rerun::Color::from_rgb(230, 40, 40),
        };
        self.rec.log(
            paths::PROXY,
            &rerun::Points3D::new([f32x3(&sample.render.proxy)])
                .with_radii([rerun::Radius::new_ui_points(4.0)])
                .with_colors([color]),
        )?;
        if let Some(g) = sample.grasper.map(|g| g.pose) {
            let color = if g.jaws_closed() {
                rerun::Color::from_rgb(40, 110, 230)
            } else {
                rerun::Color::from_rgb(150, 150, 150)
            };
            self.rec.log(
                paths::GRASPER,
                &rerun::Points3D::new([f32x3(&g.tip_in_world)])
                    .with_radii([rerun::Radius::new_ui_points(7.0)])
                    .with_colors([color]),
            )?;
        }
        Ok(())
    }

    fn send_series(&mut self) -> Result<(), RerunLogError> {
        if self.columns.len() == 0 {
            return Ok(());
        }
        let c = &self.columns;
        let series: [(&str, &Vec<f64>); 6] = [
            (paths::FORCE_X, &c.force[0]),
            (paths::FORCE_Y, &c.force[1]),
            (paths::FORCE_Z, &c.force[2]),
            (paths::FORCE_NORM, &c.force[3]),
            (paths::CONTACT_MODE, &c.mode),
            (paths::CONTACT_PENETRATION, &c.penetration),
        ];
        for (path, values) in series {
            let indexes = [
                rerun::TimeColumn::new_sequence(TIMELINE_TICK, c.ticks.iter().copied()),
                rerun::TimeColumn::new_duration_nanos(
                    TIMELINE_SIM_TIME,
                    c.sim_time_nanos.iter().copied(),
                ),
            ];
            let columns = rerun::Scalars::new(values.iter().copied()).columns_of_unit_batches()?;
            self.rec.send_columns(path, indexes, columns)?;
        }
        self.columns.clear();
        Ok(())
    }

    fn log_surface(&mut self, s: &SurfaceSnapshot) -> Result<(), RerunLogError> {
        self.set_time(s.tick, Some(s.step));
        let positions: Vec<[f32; 3]> = s.vertices.iter().map(f32x3).collect();
        let normals = vertex_normals(&s.vertices, &s.triangles);
        let mesh = if !self.last_triangles.is_empty() && self.last_triangles == s.triangles {
            // Same topology: the triangles logged before still hold (latest-at).
            rerun::Mesh3D::update_fields()
                .with_vertex_positions(positions)
                .with_vertex_normals(normals)
        } else {
            self.last_triangles.clone_from(&s.triangles);
            rerun::Mesh3D::new(positions)
                .with_vertex_normals(normals)
                .with_triangle_indices(s.triangles.iter())
                .with_albedo_factor(rerun::Rgba32::from_rgb(225, 150, 140))
        };
        self.rec.log(paths::TISSUE, &mesh)?;
        Ok(())
    }

    fn log_event(
        &self,
        tick: u64,
        step: u64,
        text: String,
        level: &str,
    ) -> Result<(), RerunLogError> {
        self.set_time(tick, Some(step));
        self.rec.log(
            paths::ENGINE_EVENTS,
            &rerun::TextLog::new(text).with_level(level),
        )?;
        Ok(())
    }
}

impl Drop for RerunSink {
    /// Sends the series still buffered (a sink dropped without [`RerunSink::finish`], e.g. held
    /// as a boxed observer); the stream itself flushes (and a file gets its footer) when it drops.
    fn drop(&mut self) {
        if let Err(e) = self.send_series() {
            tracing::warn!(
                "rerun: the last {} ticks could not be sent: {e}",
                self.columns.len()
            );
        }
    }
}

/// How the review's 3D view looks at the scene (metres, world frame).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ReviewEye {
    /// Where the eye is.
    pub position_m: Point3,
    /// The point it looks at (and orbits around).
    pub look_target_m: Point3,
    /// The screen's up in the world, if not the scene's (+z).
    pub up: Option<Vector3>,
}

/// Where a review looks at a planned incision from: at the incision's middle `c`, from the
/// direction of the exercise's viewpoint (the plan's `viewpoint_m`) or, for a plan without
/// one, along its mean outward normal. The eye stands at `d = max(1.2 L, 5 cm)` from `c` for
/// an incision of length `L`: the whole line in view and the tissue around it filling the
/// view (rerun's vertical field of view is about 55 degrees). The screen's up is `a x v` for the
/// incision's direction `a` and the viewing direction `v` (both projected apart), so the
/// incision runs across the screen, entry on the left. `None` for a plan without a usable
/// line, normal or viewpoint.
pub fn plan_view(plan: &Plan) -> Option<ReviewEye> {
    let (first, last) = (plan.line_m.first()?, plan.line_m.last()?);
    let middle = Point3::from((first.coords + last.coords) * 0.5);
    let framing_m = (1.2 * plan.length_m()).max(0.05);
    let towards_eye = match plan.viewpoint_m {
        Some(v) => (v - middle).try_normalize(1e-9)?,
        None => plan
            .normals
            .iter()
            .fold(Vector3::zeros(), |a, n| a + n)
            .try_normalize(1e-12)?,
    };
    let from_middle = towards_eye * framing_m;
    let position_m = middle + from_middle;
    let view = -from_middle.normalize();
    let along = last - first;
    let across = along - view * along.dot(&view);
    let up = across
        .try_normalize(1e-9)
        .map(|a| a.cross(&view).normalize());
    (position_m
        .iter()
        .chain(middle.iter())
        .all(|c| c.is_finite()))
    .then_some(ReviewEye {
        position_m,
        look_target_m: middle,
        up,
    })
}

/// The name of the 3D view's eye property in the blueprint (`view/<id>/EyeControls3D`).
const EYE_CONTROLS: &str = "EyeControls3D";

/// Sends [`review_blueprint`] to `rec`, made active and the default; with `eye`, its 3D view
/// looks from there.
///
/// rerun 0.36's blueprint builder has no eye controls for a 3D view, so the blueprint goes
/// first into memory, the view's `EyeControls3D` property is logged into the same blueprint
/// store, and the whole is sent with the blueprint's own activation.
fn send_review_blueprint(
    rec: &RecordingStream,
    eye: Option<&ReviewEye>,
) -> Result<(), RerunLogError> {
    use rerun::blueprint::BlueprintActivation;
    use rerun::log::LogMsg;
    let activation = BlueprintActivation {
        make_active: true,
        make_default: true,
    };
    let (blueprint, view_path) = review_layout();
    let Some(eye) = eye else {
        blueprint.send(rec, activation)?;
        return Ok(());
    };
    let application: rerun::ApplicationId = rec
        .store_info()
        .map_or_else(|| "cutlab".into(), |i| i.application_id().clone());
    let (memory, storage) = RecordingStreamBuilder::new(application.clone()).memory()?;
    blueprint.send(&memory, activation)?;
    memory.flush_blocking()?;
    let msgs = storage.take();
    let Some(command) = msgs.iter().find_map(|m| match m {
        LogMsg::BlueprintActivationCommand(c) => Some(c.clone()),
        _ => None,
    }) else {
        return Err(RerunLogError::Settings(
            "the review blueprint carries no activation".into(),
        ));
    };
    let mut layout: Vec<LogMsg> = msgs
        .into_iter()
        .filter(|m| {
            !matches!(m, LogMsg::BlueprintActivationCommand(_))
                && *m.store_id() == command.blueprint_id
        })
        .collect();
    let (eye_store, eye_storage) = RecordingStreamBuilder::new(application.clone())
        .recording_id(command.blueprint_id.recording_id().clone())
        .blueprint()
        .memory()?;
    eye_store.set_time_sequence("blueprint", 0);
    let mut controls = rerun::external::re_sdk_types::blueprint::archetypes::EyeControls3D::new()
        .with_position(f32x3(&eye.position_m))
        .with_look_target(f32x3(&eye.look_target_m));
    if let Some(up) = eye.up {
        controls = controls.with_eye_up([up.x as f32, up.y as f32, up.z as f32]);
    }
    eye_store.log(format!("{view_path}/{EYE_CONTROLS}"), &controls)?;
    eye_store.flush_blocking()?;
    layout.extend(
        eye_storage
            .take()
            .into_iter()
            .filter(|m| matches!(m, LogMsg::ArrowMsg(..))),
    );
    rec.send_blueprint(layout, command);
    Ok(())
}

/// The layout an instructor reviews a cut in, sent with every log: a large 3D view of the
/// tissue, the blade and the planned incision (`world`); below it the force and contact series
/// in one plot and the events as a compact log; the blueprint and selection panels collapsed,
/// the time panel on `sim_time`.
pub fn review_blueprint() -> rerun::blueprint::Blueprint {
    review_layout().0
}

/// [`review_blueprint`] and the blueprint path of its 3D view.
fn review_layout() -> (rerun::blueprint::Blueprint, String) {
    use rerun::blueprint::components::PanelState;
    use rerun::blueprint::{
        Blueprint, BlueprintPanel, ContainerLike, Horizontal, SelectionPanel, Spatial3DView,
        TextLogView, TimePanel, TimeSeriesView, Vertical,
    };
    let scene: ContainerLike = Spatial3DView::new("Tissue").with_origin("world").into();
    let view_path = match &scene {
        ContainerLike::View(v) => v.blueprint_path().to_string(),
        _ => String::new(),
    };
    let series = TimeSeriesView::new("Force (N) and contact")
        .with_origin("/")
        .with_contents(["force/**", "contact/**"]);
    let events = TextLogView::new("Events").with_origin(paths::EVENTS);
    let below = Horizontal::new([series.into(), events.into()]).with_column_shares([3.0, 1.0]);
    let blueprint =
        Blueprint::new(Vertical::new([scene, below.into()]).with_row_shares([3.0, 1.0]))
            .with_auto_views(false)
            .with_blueprint_panel(BlueprintPanel::new().with_state(PanelState::Collapsed))
            .with_selection_panel(SelectionPanel::new().with_state(PanelState::Collapsed))
            .with_time_panel(
                TimePanel::new()
                    .with_state(PanelState::Collapsed)
                    .with_timeline(TIMELINE_SIM_TIME),
            );
    (blueprint, view_path.trim_start_matches('/').to_owned())
}

fn to_i64(v: u64) -> i64 {
    i64::try_from(v).unwrap_or(i64::MAX)
}

fn f32x3(p: &Point3) -> [f32; 3] {
    [p.x as f32, p.y as f32, p.z as f32]
}

fn mode_value(mode: Mode) -> f64 {
    match mode {
        Mode::Free => 0.0,
        Mode::Touching => 1.0,
        Mode::Cutting => 2.0,
    }
}

/// Area-weighted vertex normals (unit; zero for a vertex on no triangle, and triangles with an
/// index out of range are skipped).
fn vertex_normals(vertices: &[Point3], triangles: &[[u32; 3]]) -> Vec<[f32; 3]> {
    let mut sums = vec![nalgebra::Vector3::<f64>::zeros(); vertices.len()];
    for t in triangles {
        let [a, b, c] = t.map(|i| i as usize);
        let (Some(pa), Some(pb), Some(pc)) = (vertices.get(a), vertices.get(b), vertices.get(c))
        else {
            continue;
        };
        // Twice the area times the unit normal: larger triangles weigh more.
        let n = (pb - pa).cross(&(pc - pa));
        for i in [a, b, c] {
            sums[i] += n;
        }
    }
    sums.iter()
        .map(|n| {
            let len = n.norm();
            if len > 0.0 && len.is_finite() {
                let u = n / len;
                [u.x as f32, u.y as f32, u.z as f32]
            } else {
                [0.0; 3]
            }
        })
        .collect()
}

/// "step 1234: cut: 12 tets split into 37, 5 vertices created, 3 moved, 2 split, ...".
fn cut_text(step: u64, blade: &Blade, e: &CutEvent) -> String {
    let mut text = format!(
        "step {step}: cut: {} tets split into {}, {} relinked, {} vertices created, {} moved, {} split, {} springs removed, {} added, {} cut faces, smallest child {:.3} of its parent; blade tip ({:.4}, {:.4}, {:.4}) m, depth {:.4} m",
        e.tets_removed.len(),
        e.tets_added.len(),
        e.tets_relinked.len(),
        e.vertices_created.len(),
        e.vertices_moved.len(),
        e.vertices_split.len(),
        e.springs_removed.len(),
        e.springs_added.len(),
        e.cut_faces,
        e.min_child_volume_fraction,
        blade.tip.x,
        blade.tip.y,
        blade.tip.z,
        blade.depth_m,
    );
    if e.forced_splits > 0 {
        text.push_str(&format!(
            "; {} edges split beyond the blade (forced)",
            e.forced_splits
        ));
    }
    text
}

fn keyframe_text(k: &Keyframe) -> String {
    format!(
        "step {}: keyframe: state hash {:016x}, topology hash {:016x}, {} vertices, {} tets",
        k.step,
        k.hash.state,
        k.hash.topology,
        k.positions.len(),
        k.tets.len()
    )
}

#[cfg(test)]
mod tests;
