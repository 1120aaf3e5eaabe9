//! The simulation step against its error, for `cutlab bench accuracy`: the expert's
//! press-and-cut session on the chest wall (springs and finite elements, the virtual clock,
//! the servo at 1 kHz throughout) with simulation steps of 1, 2, 4 and 10 ms. Error: the
//! length of the incision made (what the assessor scores first) against the 1 ms run's,
//! relative; run time per simulated second. What `--time-step-ms` trades. (The final
//! positions are no measure: which lip of the wound a vertex ends on changes with the cut's
//! exact topology, so their largest difference is the wound's width at any step size.)

use std::time::Instant;

use anyhow::Context;
use cutlab_haptics::device::{Skill, SyntheticTrainee};
use cutlab_haptics::{Session, SessionConfig, SessionReport};
use cutlab_sim::scene::{BuildOptions, Scene};

use crate::accuracy::AccuracyRow;

/// The steps compared, ms (the first is the reference).
pub const STEPS_MS: [u32; 4] = [1, 2, 4, 10];

/// The session's length, s.
const DURATION_S: f64 = 6.0;

fn session(scene: &Scene, step_ms: u32) -> anyhow::Result<(SessionReport, f64)> {
    let scene = scene.clone().with_time_step(f64::from(step_ms) / 1e3)?;
    let session = Session::new(&scene)?;
    let plan = session.plan_across_top(0.06, 0.008)?;
    let mut config = SessionConfig {
        duration_s: DURATION_S,
        ..SessionConfig::default()
    };
    config.render = config.render.with_scene_cut(&scene.spec);
    let hand = SyntheticTrainee::new(
        "expert",
        plan,
        Skill::preset("expert").context("the expert preset")?,
        1,
    )?
    .expecting_cut_of(&config.render);
    let t = Instant::now();
    let report = session.run(Box::new(hand), &config)?;
    Ok((report, t.elapsed().as_secs_f64()))
}

/// The rows of `scene_name` (a chest wall) at `tets` tets.
pub fn rows(
    scene_name: &str,
    model: &'static str,
    tets: usize,
) -> anyhow::Result<Vec<AccuracyRow>> {
    let scene = Scene::load(
        scene_name,
        BuildOptions {
            min_tets: Some(tets),
        },
    )?;
    let (reference, _) = session(&scene, STEPS_MS[0])?;
    let length_ref = reference.stats.cut_length_m;
    let mut rows = Vec::new();
    for step_ms in STEPS_MS {
        let (report, wall_s) = session(&scene, step_ms)?;
        let length = report.stats.cut_length_m;
        rows.push(AccuracyRow {
            problem: "press-and-cut session, step size",
            model,
            tets: scene.model.mesh.tet_count(),
            solver: format!("implicit-euler {step_ms} ms"),
            wall_ms: 1e3 * wall_s / DURATION_S,
            wall_kind: "per simulated s",
            error: (length - length_ref).abs() / length_ref.max(f64::MIN_POSITIVE),
            value: length,
            analytic: length_ref,
        });
    }
    Ok(rows)
}
