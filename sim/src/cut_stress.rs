//! Strokes of any shape on the built-in tissues, shared by `sim/tests/shapes.rs`,
//! `cutlab bench stability` and `cutlab bench perf`: arcs, closed circles, S-curves and
//! zig-zags cut as a session cuts (a cut per pose), with the simulation stepped between.

use crate::cut::{Blade, Cutter, Specimen, blade};
use crate::mesh::pieces;
use crate::scene::{BuildOptions, Scene, SceneError};
use crate::solver::{Simulation, StaticSettings};
use crate::{Point3, Vector3};
use std::f64::consts::{PI, TAU};

/// Where the strokes are drawn.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum Tissue {
    /// The built-in `sheet`: 100 x 100 x 2 mm, its top at z = 2 mm; paths from its centre.
    Sheet,
    /// The built-in `chest-wall`: a slab of 150 mm radius, 15 mm thick; paths from the top
    /// of its middle.
    ChestWall,
}

impl Tissue {
    /// The built-in scene's name.
    pub fn scene(self) -> &'static str {
        match self {
            Tissue::Sheet => "sheet",
            Tissue::ChestWall => "chest-wall",
        }
    }

    /// The scene built and settled, at its own time step or at `time_step_s`.
    pub fn simulation(self, time_step_s: Option<f64>) -> Result<Simulation, SceneError> {
        let mut scene = Scene::load(self.scene(), BuildOptions::default())?;
        if let Some(dt) = time_step_s {
            scene = scene.with_time_step(dt)?;
        }
        let mut sim = scene.simulation();
        sim.settle(StaticSettings::default());
        Ok(sim)
    }

    /// The blade at `(x, y)` from the path's centre (m), its tip `depth_m` below the surface
    /// and its edge standing 10 mm above it, normal to the surface.
    pub fn blade(self, (x, y): (f64, f64), depth_m: f64) -> Blade {
        match self {
            Tissue::Sheet => blade(
                Point3::new(0.05 + x, 0.05 + y, 0.002 - depth_m),
                Vector3::z(),
                depth_m + 0.01,
            ),
            Tissue::ChestWall => Blade::normal_to_curved_slab(x, y, 0.15, depth_m, 0.01),
        }
    }
}

/// Points every `spacing_m` along a circle of radius `r_m` about the centre, from angle
/// `from` over `sweep` radians.
pub fn arc(r_m: f64, from: f64, sweep: f64, spacing_m: f64) -> Vec<(f64, f64)> {
    let n = ((r_m * sweep.abs()) / spacing_m).ceil().max(1.0) as usize;
    (0..=n)
        .map(|k| {
            let a = from + sweep * k as f64 / n as f64;
            (r_m * a.cos(), r_m * a.sin())
        })
        .collect()
}

/// Points every `spacing_m` (along x) of `y = f(x)` for x across `length_m` centred on 0.
pub fn graph(length_m: f64, spacing_m: f64, f: impl Fn(f64) -> f64) -> Vec<(f64, f64)> {
    let n = (length_m / spacing_m).ceil() as usize;
    (0..=n)
        .map(|k| {
            let x = -length_m / 2.0 + length_m * k as f64 / n as f64;
            (x, f(x))
        })
        .collect()
}

/// A zig-zag of `amplitude_m` peak to peak, a tooth every `period_m`, along x.
pub fn zigzag(amplitude_m: f64, period_m: f64, length_m: f64, spacing_m: f64) -> Vec<(f64, f64)> {
    graph(length_m, spacing_m, |x| {
        let phase = (x / period_m).rem_euclid(1.0);
        amplitude_m * (2.0 * phase).min(2.0 - 2.0 * phase) - amplitude_m / 2.0
    })
}

/// What a stroke did beyond its cuts.
#[derive(Debug, Default, Clone)]
pub struct StrokeReport {
    /// Fragments the cuts reattached.
    pub fragments_reattached: usize,
    /// Pieces the cuts freed.
    pub specimens: Vec<Specimen>,
    /// Cuts that failed (the simulation unchanged by them).
    pub failed_cuts: usize,
    /// Steps that failed (rejected by the solver).
    pub failed_steps: usize,
}

/// Cuts along `path` as a session does (a cut per pose), `steps` simulation steps after each;
/// `check` sees the simulation after each step and may stop the stroke by returning false.
pub fn stroke(
    sim: &mut Simulation,
    tissue: Tissue,
    path: &[(f64, f64)],
    depth_m: f64,
    steps: usize,
    mut check: impl FnMut(&Simulation) -> bool,
) -> StrokeReport {
    let mut cutter = Cutter::default();
    let mut out = StrokeReport::default();
    for &p in path {
        match cutter.advance(sim, tissue.blade(p, depth_m)) {
            Ok(event) => {
                out.fragments_reattached += event.fragments_reattached;
                out.specimens.extend(event.specimens);
            }
            Err(_) => out.failed_cuts += 1,
        }
        for _ in 0..steps {
            out.failed_steps += usize::from(sim.step().is_err());
            if !check(sim) {
                return out;
            }
        }
    }
    out
}

/// The shapes of [`cut_sweep`].
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum StrokeShape {
    /// A semicircle of radius 20 mm.
    Semicircle,
    /// A circle of radius 20 mm traced 1.08 times round.
    Circle,
    /// An S-curve of 10 mm amplitude over 60 mm.
    SCurve,
    /// A zig-zag of 10 mm teeth over 60 mm.
    ZigZag,
}

impl StrokeShape {
    /// Every shape.
    pub const ALL: [StrokeShape; 4] = [
        StrokeShape::Semicircle,
        StrokeShape::Circle,
        StrokeShape::SCurve,
        StrokeShape::ZigZag,
    ];

    /// Its path, a point every `spacing_m`.
    pub fn path(self, spacing_m: f64) -> Vec<(f64, f64)> {
        match self {
            StrokeShape::Semicircle => arc(0.02, 0.0, PI, spacing_m),
            StrokeShape::Circle => arc(0.02, 0.0, 1.08 * TAU, spacing_m),
            StrokeShape::SCurve => graph(0.06, spacing_m, |x| 0.01 * (x / 0.03 * TAU).sin()),
            StrokeShape::ZigZag => zigzag(0.01, 0.02, 0.06, spacing_m),
        }
    }
}

/// One cutting stress case: a shape on a tissue at a time step.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct CutStressCase {
    /// The tissue.
    pub tissue: Tissue,
    /// The stroke.
    pub shape: StrokeShape,
    /// The time step, s.
    pub time_step_s: f64,
}

/// What a cutting stress run measured.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct CutStressResult {
    /// True when a non-finite number got into the state (a bug).
    pub non_finite: bool,
    /// Steps taken.
    pub steps: u64,
    /// Steps the solver rejected (the state kept).
    pub failed_steps: usize,
    /// Cuts that failed (the simulation unchanged by them).
    pub failed_cuts: usize,
    /// Pieces at the end (tetrahedra sharing a vertex), specimens included.
    pub pieces: usize,
    /// Specimens freed.
    pub specimens: usize,
    /// Fragments reattached.
    pub fragments_reattached: usize,
    /// Tetrahedra at the end.
    pub tets: usize,
    /// Fastest particle over the run, m/s.
    pub max_speed_m_per_s: f64,
}

/// Every shape on both tissues, at time steps of 0.1, 1 and 10 ms (`quick`: 1 ms only).
pub fn cut_sweep(quick: bool) -> Vec<CutStressCase> {
    let dts: &[f64] = if quick { &[1e-3] } else { &[1e-4, 1e-3, 1e-2] };
    let mut out = Vec::new();
    for tissue in [Tissue::Sheet, Tissue::ChestWall] {
        for shape in StrokeShape::ALL {
            for &time_step_s in dts {
                out.push(CutStressCase {
                    tissue,
                    shape,
                    time_step_s,
                });
            }
        }
    }
    out
}

/// At most this many steps between two cuts of [`run_cut`] (0.1 ms steps stroke at 100 mm/s).
pub const MAX_STEPS_PER_CUT: usize = 50;

/// Runs `case`: the stroke (a cut every 0.5 mm, the blade 4 mm below the sheet's top or 6
/// mm into the chest wall, at 10 mm/s: a cut every 50 ms of simulated time, but at most
/// [`MAX_STEPS_PER_CUT`] steps) and 0.2 s after it, checking after every step that the state
/// is finite.
pub fn run_cut(case: &CutStressCase) -> Result<CutStressResult, SceneError> {
    let mut sim = case.tissue.simulation(Some(case.time_step_s))?;
    let depth_m = match case.tissue {
        Tissue::Sheet => 0.004,
        Tissue::ChestWall => 0.006,
    };
    let steps = ((0.05 / case.time_step_s).round() as usize).clamp(1, MAX_STEPS_PER_CUT);
    let mut result = CutStressResult {
        non_finite: false,
        steps: 0,
        failed_steps: 0,
        failed_cuts: 0,
        pieces: 0,
        specimens: 0,
        fragments_reattached: 0,
        tets: 0,
        max_speed_m_per_s: 0.0,
    };
    let mut check = |sim: &Simulation| {
        result.steps += 1;
        let finite = sim.state.is_finite();
        result.non_finite |= !finite;
        result.max_speed_m_per_s = result.max_speed_m_per_s.max(sim.state.max_speed());
        finite
    };
    let path = case.shape.path(0.0005);
    let mut report = stroke(&mut sim, case.tissue, &path, depth_m, steps, &mut check);
    let after = ((0.2 / case.time_step_s).round() as usize).max(1);
    for _ in 0..after {
        report.failed_steps += usize::from(sim.step().is_err());
        if !check(&sim) {
            break;
        }
    }
    Ok(CutStressResult {
        failed_steps: report.failed_steps,
        failed_cuts: report.failed_cuts,
        pieces: pieces(&sim.model.mesh, &sim.model.held).len(),
        specimens: report.specimens.len(),
        fragments_reattached: report.fragments_reattached,
        tets: sim.model.mesh.tet_count(),
        ..result
    })
}
