//! `cutlab plan field`: a candidate incision cut in the simulation and the field it gives
//! (`cutlab_scoring::planning`).

use std::path::{Path, PathBuf};

use anyhow::Context;
use clap::Subcommand;
use cutlab_assessor::store::DbLocation;
use cutlab_scoring::planning::{
    CandidateIncision, FieldReport, Opening, SkinMap, View, field_pictured,
};
use cutlab_sim::scene::{BuildOptions, Scene};

/// A picture's pixels across and down.
const PICTURE_PX: u32 = 320;

#[derive(Debug, Subcommand)]
pub enum PlanCommand {
    /// Cut a candidate incision in the simulation with a scripted stroke, let the wound open,
    /// and print the field: what of the scene's target the viewpoint sees through the opening,
    /// the working width, the incision's length, the approach angle, what was damaged.
    Field {
        /// The exercise whose scene to cut (from the database, `--db`).
        #[arg(long, conflicts_with = "scene")]
        exercise: Option<String>,
        /// A built-in scene or a scene file, instead of an exercise's.
        #[arg(long)]
        scene: Option<String>,
        /// The candidate: JSON `{"incision_m": [[x, y, z], ...], "depth_m": d}` (metres, the
        /// line on the skin).
        #[arg(long)]
        incision: PathBuf,
        /// How long the wound opens under the tissue's tension before the field is measured, s.
        #[arg(long, default_value_t = 0.5)]
        open_s: f64,
        /// Then set a retractor in the wound and spread its middle to this width, mm; the
        /// field is reported unretracted and retracted.
        #[arg(long)]
        retract_mm: Option<f64>,
        /// Also write the field as the viewpoint sees it to this PNG file: the opened wound
        /// (retracted, with `--retract-mm`) and the target through it, the whole skin framed.
        #[arg(long)]
        picture: Option<PathBuf>,
        /// Machine-readable output.
        #[arg(long)]
        json: bool,
    },
}

/// Runs a planning command; `db` is the global `--db`.
pub fn run(db: Option<&DbLocation>, command: PlanCommand) -> anyhow::Result<()> {
    let PlanCommand::Field {
        exercise,
        scene,
        incision,
        open_s,
        retract_mm,
        picture,
        json,
    } = command;
    if !(open_s.is_finite() && (0.0..=10.0).contains(&open_s)) {
        anyhow::bail!("--open-s: from 0 to 10 s, got {open_s}");
    }
    if let Some(w) = retract_mm
        && !(w.is_finite() && (0.0..=200.0).contains(&w))
    {
        anyhow::bail!("--retract-mm: from 0 to 200 mm, got {w}");
    }
    let candidate = read_candidate(&incision)?;
    candidate
        .check()
        .with_context(|| format!("the candidate {}", incision.display()))?;
    let scene_name = match (exercise, scene) {
        (Some(e), _) => scene_of_exercise(db, &e)?,
        (None, Some(s)) => s,
        (None, None) => anyhow::bail!("give the exercise (--exercise) or the scene (--scene)"),
    };
    let scene = Scene::load(&scene_name, BuildOptions::default())
        .with_context(|| format!("building the scene {scene_name}"))?;
    let opening = Opening {
        open_s,
        retract_m: retract_mm.map(|w| w * 1e-3),
    };
    let camera = match &picture {
        None => None,
        Some(_) => Some(
            SkinMap::of(&scene)?
                .camera(&scene.spec, PICTURE_PX)
                .with_context(|| format!("the scene {scene_name} has no viewpoint to picture"))?,
        ),
    };
    let (report, pictures) = field_pictured(&scene, &candidate, opening, camera.as_ref())
        .with_context(|| format!("the candidate {}", incision.display()))?;
    if let (Some(path), Some(last)) = (&picture, pictures.last()) {
        std::fs::write(path, last.png()?)
            .with_context(|| format!("writing the picture {}", path.display()))?;
    }
    if json {
        println!("{}", serde_json::to_string_pretty(&report)?);
    } else {
        print_report(&scene_name, &report);
    }
    Ok(())
}

fn read_candidate(path: &Path) -> anyhow::Result<CandidateIncision> {
    let text = std::fs::read_to_string(path)
        .with_context(|| format!("reading the candidate {}", path.display()))?;
    serde_json::from_str(&text).with_context(|| format!("the candidate {}", path.display()))
}

fn scene_of_exercise(db: Option<&DbLocation>, name: &str) -> anyhow::Result<String> {
    crate::assess_cli::on_store(db, async |store| {
        Ok(store.exercise_by_name(name).await?.scene)
    })
}

fn print_report(scene: &str, r: &FieldReport) {
    println!("field of the candidate on {scene} ({}):", r.target);
    print_view(&r.unretracted);
    println!("  incision length    {:.1} mm", r.incision_length_m * 1e3);
    if r.damaged.is_empty() {
        println!("  damaged            nothing");
    } else {
        println!("  damaged            {}", r.damaged.join(", "));
    }
    if let (Some(w), Some(v)) = (r.retractor_width_m, &r.retracted) {
        println!("retracted to {:.1} mm:", w * 1e3);
        print_view(v);
    }
}

fn print_view(v: &View) {
    println!(
        "  target seen        {:.1} mm^2 ({:.1} % of what faces the viewpoint)",
        v.target_visible_area_m2 * 1e6,
        v.target_visible_fraction * 100.0
    );
    println!("  working width      {:.1} mm", v.working_width_m * 1e3);
    match v.approach_angle_deg {
        Some(a) => println!("  approach angle     {a:.1} deg from straight in"),
        None => println!("  approach angle     - (nothing seen)"),
    }
}
