//! Recording a session: the session runs as usual while its tap feeds the writer thread, and
//! the file is finished with the session's end figures — also when the session fails, so an
//! interrupted session never loses its recording.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use cutlab_haptics::plan::Plan;
use cutlab_haptics::tap::{self, TapSettings};
use cutlab_haptics::{Hands, HapticsError, Session, SessionConfig, SessionReport, StateHash};

use crate::RecorderError;
pub use crate::channels::Provenance;
use crate::channels::{self, Hex, SessionMeta};
use crate::writer::{self, McapSink, RecordObserver, WriteStats, WriterOptions};

/// How much to record.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct RecordSettings {
    pub tap: TapSettings,
    pub writer: WriterOptions,
}

/// A recorded session.
pub struct RecordedSession {
    /// The session's report, or why it failed (the recording is finished either way).
    pub report: Result<SessionReport, HapticsError>,
    pub write: WriteStats,
    pub path: PathBuf,
    /// The observer, handed back to be finished by its owner.
    pub observer: Option<Box<dyn RecordObserver>>,
}

impl std::fmt::Debug for RecordedSession {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("RecordedSession")
            .field("report", &self.report)
            .field("write", &self.write)
            .field("path", &self.path)
            .finish_non_exhaustive()
    }
}

/// Runs `session` with `hands` (the scalpel's device, or it and a grasper's, whose pose and
/// state go to their own channels, `/tool/grasper/...`), recording it to `path` (MCAP), and
/// every record to `observer` too.
#[allow(clippy::too_many_arguments)]
pub fn run_recorded(
    session: Session,
    hands: impl Into<Hands>,
    config: &SessionConfig,
    provenance: &Provenance,
    plan: Option<&Plan>,
    scene_spec: &cutlab_sim::scene::SceneSpec,
    path: &Path,
    settings: RecordSettings,
    observer: Option<Box<dyn RecordObserver>>,
) -> Result<RecordedSession, RecorderError> {
    let meta = meta_of(&session, config, provenance, settings);
    let mut attachments = vec![(
        channels::SCENE_ATTACHMENT,
        "application/json",
        json(scene_spec)?,
    )];
    if let Some(plan) = plan {
        attachments.push((channels::PLAN_ATTACHMENT, "application/json", json(plan)?));
    }
    let sink = McapSink::create(path, &meta, &attachments, settings.writer)?;
    let (tap, feed) = tap::tap(settings.tap);
    let writer = writer::spawn(sink, feed, observer).map_err(|source| RecorderError::Io {
        path: path.to_owned(),
        error: source,
    })?;
    let report = session.run_recorded(hands, config, Some(tap));
    let (sink, observer) = writer
        .join()
        .map_err(|_| RecorderError::Encode("the recorder thread panicked".into()))??;
    let mut end = BTreeMap::new();
    match &report {
        Ok(r) => {
            end.insert("status".to_owned(), "complete".to_owned());
            end.insert("ticks".to_owned(), r.servo.ticks.to_string());
            end.insert("sim_steps".to_owned(), r.sim_steps.to_string());
            end.insert(
                "dropped_tick_records".to_owned(),
                r.servo.dropped_records.to_string(),
            );
            end.insert(
                "dropped_samples".to_owned(),
                r.servo.dropped_samples.to_string(),
            );
            end.insert("tets_split".to_owned(), r.stats.tets_split.to_string());
            end.insert("cut_length_m".to_owned(), r.stats.cut_length_m.to_string());
            end.insert(
                "final_state_hash".to_owned(),
                format!("{:016x}", r.state_hash),
            );
            end.insert("wall_s".to_owned(), r.wall_s.to_string());
        }
        Err(e) => {
            end.insert("status".to_owned(), "failed".to_owned());
            end.insert("error".to_owned(), e.to_string());
        }
    }
    let write = sink.finish(&end)?;
    Ok(RecordedSession {
        report,
        write,
        path: path.to_owned(),
        observer,
    })
}

/// The session metadata a recording of `session` carries.
fn meta_of(
    session: &Session,
    config: &SessionConfig,
    provenance: &Provenance,
    settings: RecordSettings,
) -> SessionMeta {
    let initial = StateHash::of(&session.sim);
    SessionMeta {
        cutlab_version: env!("CARGO_PKG_VERSION").to_owned(),
        provenance: provenance.clone(),
        clock: format!("{:?}", config.clock).to_lowercase(),
        period_nanos: config.period_nanos,
        time_step_nanos: (session.sim.settings.time_step_s * 1e9).round() as u64,
        duration_s: config.duration_s,
        blade_length_m: config.blade_length_m,
        contact_reach_m: config.contact_reach_m,
        contact_patch_radius_m: config.contact_patch_radius_m,
        cut_step_m: config.cut_step_m,
        keyframe_every_steps: settings.tap.keyframe_every_steps,
        collider_rebuild_every_steps: config.collider_rebuild_every_steps,
        surface_every_steps: settings.tap.surface_every_steps,
        localisation: session.sim.settings.localisation,
        initial_state_hash: Hex(initial.state),
        initial_topology_hash: Hex(initial.topology),
        started_unix_s: std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .map_or(0.0, |d| d.as_secs_f64()),
    }
}

fn json<T: serde::Serialize>(v: &T) -> Result<Vec<u8>, RecorderError> {
    Ok(serde_json::to_vec_pretty(v)?)
}

/// Records `duration_s` (simulated) of the synthetic expert (seeded by `seed`) cutting a
/// 60 mm, 8 mm deep incision across `scene`'s top, on the virtual clock, to `path`: a real,
/// whole recording in a moment, for the tests and benchmarks that need one (a hub that
/// scores what it takes, say).
pub fn record_expert(
    scene: &cutlab_sim::scene::Scene,
    scene_name: &str,
    duration_s: f64,
    seed: u64,
    path: &Path,
) -> Result<SessionReport, RecorderError> {
    use cutlab_haptics::device::{Skill, SyntheticTrainee};
    let session = Session::new(scene)?;
    let plan = session.plan_across_top(0.06, 0.008)?;
    let skill = Skill::preset("expert")
        .ok_or_else(|| RecorderError::Malformed("no expert preset".into()))?;
    let device = Box::new(SyntheticTrainee::new("expert", plan.clone(), skill, seed)?);
    let config = SessionConfig {
        clock: cutlab_haptics::servo::Clock::Virtual,
        duration_s,
        ..SessionConfig::default()
    };
    let provenance = Provenance {
        scene: scene_name.into(),
        seed,
        device: "expert".into(),
        ..Provenance::default()
    };
    let recorded = run_recorded(
        session,
        device,
        &config,
        &provenance,
        Some(&plan),
        &scene.spec,
        path,
        RecordSettings::default(),
        None,
    )?;
    Ok(recorded.report?)
}
