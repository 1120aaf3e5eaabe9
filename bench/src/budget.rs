//! `cutlab bench budget`: the implicit solver's tolerance against its error budget (issue 64),
//! per built-in exercise's scene. The integrator's own error at the scene's step is what a
//! session is already allowed; the linear solve's error must stay below a tenth of it.
//!
//! Each run settles the scene, cuts the first [`CUT_LENGTH_M`] of the exercise's expert line
//! with a scripted blade at the plan's depth (a cut every 0.5 mm at 10 mm/s, as a session
//! cuts), then lets the tissue move for [`RELAX_S`]. Errors are the largest distance between
//! two runs' final particle positions over the reference run's largest displacement from the
//! settled state, as in `docs/design/solver.md`:
//!
//! - the integrator's error `e_int`: the scene's step `h` against `h / 2`, both solved to
//!   [`REFERENCE_TOLERANCE`];
//! - the solve's error `e(tau)`: CG to relative residual `tau` against the reference, at `h`.
//!
//! The budget is `e(tau) <= e_int / 10`; the loosest `tau` within it is printed beside the
//! CG iterations per step and the steps' time. The same for the solve's velocity floor `v`
//! (it stops at the latest when `|r| <= v sqrt(sum m_i^2)`, which decides the steps near
//! rest), at the scene's tolerance. Runs are compared only where their cuts made
//! the same tetrahedra (the cutter works on the deformed tissue, so a different solve could
//! split differently); otherwise the row says so.

use std::time::Instant;

use anyhow::Context;
use cutlab_assessor::store::builtins;
use cutlab_sim::cut::{self, Cutter};
use cutlab_sim::scene::{BuildOptions, Scene};
use cutlab_sim::solver::StaticSettings;
use cutlab_sim::{Point3, Vector3};
use serde::Serialize;

/// The tolerances tried, tightest first.
pub const TOLERANCES: [f64; 5] = [1e-3, 3e-3, 1e-2, 3e-2, 1e-1];
/// The velocity floors tried, m/s, tightest first (the first is the solver's default).
pub const FLOORS: [f64; 5] = [
    cutlab_sim::solver::VELOCITY_FLOOR_M_PER_S,
    1e-9,
    1e-8,
    1e-7,
    1e-6,
];
/// The reference runs' tolerance.
const REFERENCE_TOLERANCE: f64 = 1e-10;
/// How much of the expert's line is cut, m.
const CUT_LENGTH_M: f64 = 0.02;
/// Blade travel between cuts, m, and its speed, m/s.
const CUT_STEP_M: f64 = 0.0005;
const SPEED_M_PER_S: f64 = 0.01;
/// How long the tissue moves after the last cut, s.
const RELAX_S: f64 = 0.2;
/// The blade's edge above the surface, m.
const ABOVE_M: f64 = 0.01;

/// One scene's figures.
#[derive(Debug, Serialize)]
pub struct BudgetRow {
    exercise: &'static str,
    scene: &'static str,
    time_step_ms: f64,
    /// The integrator's error: `h` against `h / 2`, relative to the largest displacement.
    integration_error: Option<f64>,
    /// Per tolerance: the solve's error (relative), CG iterations per step, step time (us).
    tolerances: Vec<ToleranceRow>,
    /// The loosest tolerance within a tenth of the integrator's error.
    within_budget: Option<f64>,
    /// The scene's tolerance now.
    scene_tolerance: f64,
    /// Per velocity floor, at the scene's tolerance: the same figures.
    floors: Vec<ToleranceRow>,
    /// The loosest velocity floor within a tenth of the integrator's error.
    floor_within_budget: Option<f64>,
    /// The scene's velocity floor now, m/s.
    scene_floor: f64,
}

/// One tolerance's or velocity floor's figures.
#[derive(Debug, Serialize)]
pub struct ToleranceRow {
    /// The relative tolerance, or the velocity floor in m/s.
    value: f64,
    /// `None`: the cuts split differently from the reference's.
    error: Option<f64>,
    cg_per_step: f64,
    step_us: f64,
}

/// What one run left.
struct Run {
    /// The positions once settled, before the first cut.
    settled: Vec<Point3>,
    /// The positions after each cut's steps and at the end.
    positions: Vec<Vec<Point3>>,
    tets: Vec<[u32; 4]>,
    cg_per_step: f64,
    step_us: f64,
}

/// Runs the benchmark and prints its table (or JSON).
pub fn run(json: bool) -> anyhow::Result<()> {
    let mut rows = Vec::new();
    for b in builtins()? {
        rows.push(scene_budget(&b).with_context(|| format!("the budget of {}", b.scene))?);
    }
    if json {
        println!("{}", serde_json::to_string_pretty(&rows)?);
        return Ok(());
    }
    type Table = fn(&BudgetRow) -> (&[ToleranceRow], f64, Option<f64>);
    let tables: [(&str, &str, Table); 2] = [
        ("tolerance", "tolerance", |r| {
            (&r.tolerances, r.scene_tolerance, r.within_budget)
        }),
        (
            "velocity floor m/s (at the scene's tolerance)",
            "velocity floor",
            |r| (&r.floors, r.scene_floor, r.floor_within_budget),
        ),
    ];
    for (column, what, table) in tables {
        println!(
            "| exercise | scene | step ms | integrator error | {column} | solve error | CG per step | step us | within budget |"
        );
        println!("|---|---|---:|---:|---:|---:|---:|---:|---|");
        for r in &rows {
            let (values, scene, loosest) = table(r);
            print_rows(r, values, scene);
            print_loosest(r, what, loosest);
        }
        println!();
    }
    Ok(())
}

/// One scene's rows of one table (by tolerance or by velocity floor; `scene` the scene's own).
fn print_rows(r: &BudgetRow, rows: &[ToleranceRow], scene: f64) {
    for t in rows {
        let within = match (t.error, r.integration_error) {
            (Some(e), Some(i)) => if e <= 0.1 * i { "yes" } else { "no" }.to_owned(),
            _ => "split differently".to_owned(),
        };
        println!(
            "| {} | {} | {} | {} | {:.0e}{} | {} | {:.1} | {:.0} | {within} |",
            r.exercise,
            r.scene,
            r.time_step_ms,
            r.integration_error
                .map_or("-".into(), |e| format!("{e:.1e}")),
            t.value,
            if t.value == scene { " (scene)" } else { "" },
            t.error.map_or("-".into(), |e| format!("{e:.1e}")),
            t.cg_per_step,
            t.step_us,
        );
    }
}

/// The line under a scene's rows: the loosest `what` within budget.
fn print_loosest(r: &BudgetRow, what: &str, loosest: Option<f64>) {
    println!(
        "| {} | | | | loosest {what} within budget: {} | | | | |",
        r.exercise,
        loosest.map_or("none".into(), |t| format!("{t:.0e}"))
    );
}

/// The budget of `b`'s scene, cut along `b`'s expert line.
fn scene_budget(b: &cutlab_assessor::store::Builtin) -> anyhow::Result<BudgetRow> {
    let scene = Scene::load(b.scene, BuildOptions::default())?;
    let h = scene.spec.solver.time_step_s;
    let hand = b.plan.kind_plan().hand_line();
    let up = Vector3::from(hand.normal);
    let line: Vec<Point3> = hand.line_m.iter().map(|&p| Point3::from(p)).collect();
    let stations = along(&line, CUT_LENGTH_M, CUT_STEP_M);
    let cut = |dt: f64, tolerance: f64, floor: f64| {
        let solve = (tolerance, floor);
        run_once(&scene, dt, solve, &stations, &up, hand.depth_m)
    };
    let floor_0 = FLOORS[0];
    let reference = cut(h, REFERENCE_TOLERANCE, floor_0)?;
    let half = cut(h / 2.0, REFERENCE_TOLERANCE, floor_0)?;
    let scale = reference
        .positions
        .iter()
        .map(|p| largest_change(&reference.settled, p))
        .fold(0.0, f64::max);
    let error = |r: &Run| {
        (r.tets == reference.tets).then(|| {
            r.positions
                .iter()
                .zip(&reference.positions)
                .map(|(a, b)| largest_change(a, b))
                .fold(0.0, f64::max)
                / scale
        })
    };
    let integration_error = error(&half);
    let scene_tolerance = scene.spec.solver.cg_relative_tolerance;
    // each row's solve: (the row's value, the relative tolerance, the velocity floor)
    let rows = |solves: &mut dyn Iterator<Item = (f64, f64, f64)>| {
        let mut out = Vec::new();
        for (value, tolerance, floor) in solves {
            let r = cut(h, tolerance, floor)?;
            out.push(ToleranceRow {
                value,
                error: error(&r),
                cg_per_step: r.cg_per_step,
                step_us: r.step_us,
            });
        }
        anyhow::Ok(out)
    };
    let tolerances = rows(&mut TOLERANCES.into_iter().map(|t| (t, t, floor_0)))?;
    let floors = rows(&mut FLOORS.into_iter().map(|f| (f, scene_tolerance, f)))?;
    let loosest = |rows: &[ToleranceRow]| {
        integration_error.and_then(|i| {
            rows.iter()
                .filter(|t| t.error.is_some_and(|e| e <= 0.1 * i))
                .map(|t| t.value)
                .fold(None, |a: Option<f64>, t| Some(a.map_or(t, |a| a.max(t))))
        })
    };
    let (within_budget, floor_within_budget) = (loosest(&tolerances), loosest(&floors));
    Ok(BudgetRow {
        exercise: b.name,
        scene: b.scene,
        time_step_ms: h * 1e3,
        integration_error,
        tolerances,
        within_budget,
        scene_tolerance,
        floors,
        floor_within_budget,
        scene_floor: scene.spec.solver.cg_velocity_floor_m_per_s,
    })
}

/// Points every `step_m` along the first `length_m` of `line`.
fn along(line: &[Point3], length_m: f64, step_m: f64) -> Vec<Point3> {
    let mut out = Vec::new();
    let mut s = 0.0;
    for w in line.windows(2) {
        let seg = (w[1] - w[0]).norm();
        while s <= seg && out.len() as f64 * step_m <= length_m {
            out.push(w[0] + (w[1] - w[0]) * (s / seg.max(1e-12)));
            s += step_m;
        }
        s -= seg;
    }
    out
}

/// The largest distance between the particles `a` and `b` share (by index; a cut adds
/// particles at the end), m.
fn largest_change(a: &[Point3], b: &[Point3]) -> f64 {
    a.iter()
        .zip(b)
        .map(|(p, q)| (p - q).norm())
        .fold(0.0, f64::max)
}

/// Settles `scene` at step `dt` and cuts through `stations` with CG tolerance and velocity
/// floor `(tolerance, floor_m_per_s)`.
fn run_once(
    scene: &Scene,
    dt: f64,
    (tolerance, floor_m_per_s): (f64, f64),
    stations: &[Point3],
    up: &Vector3,
    depth_m: f64,
) -> anyhow::Result<Run> {
    let mut sim = scene.clone().with_time_step(dt)?.simulation();
    sim.settle(StaticSettings::default());
    let settled = sim.state.positions.clone();
    sim.settings.cg_relative_tolerance = tolerance;
    sim.settings.cg_velocity_floor_m_per_s = floor_m_per_s;
    sim.settings.cg_max_iterations = 20_000;
    let per_cut = ((CUT_STEP_M / SPEED_M_PER_S) / dt).round().max(1.0) as usize;
    let relax = (RELAX_S / dt).round() as usize;
    let mut cutter = Cutter::default();
    let (mut cg, mut steps, mut busy) = (0usize, 0usize, 0.0);
    let mut step = |sim: &mut cutlab_sim::solver::Simulation| -> anyhow::Result<()> {
        let t = Instant::now();
        cg += sim.step().context("a step")?.cg_iterations;
        busy += t.elapsed().as_secs_f64();
        steps += 1;
        Ok(())
    };
    let mut positions = Vec::new();
    for p in stations {
        let blade = cut::blade(p - up * depth_m, *up, depth_m + ABOVE_M);
        match cutter.advance(&mut sim, blade) {
            Ok(_) | Err(cut::CutError::Unresolved(_)) => {}
            Err(e) => return Err(e).context("a cut"),
        }
        for _ in 0..per_cut {
            step(&mut sim)?;
        }
        positions.push(sim.state.positions.clone());
    }
    for _ in 0..relax {
        step(&mut sim)?;
    }
    positions.push(sim.state.positions.clone());
    Ok(Run {
        settled,
        positions,
        tets: sim.model.mesh.tets().to_vec(),
        cg_per_step: cg as f64 / steps.max(1) as f64,
        step_us: busy * 1e6 / steps.max(1) as f64,
    })
}
