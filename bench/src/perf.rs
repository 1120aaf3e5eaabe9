//! `cutlab bench perf`: a scripted scalpel session (press and cut along the top of the tissue,
//! then a little time for the wound) on the chest wall at 10k to 200k tetrahedra and on the
//! CT-derived body wall, each size run full and localised from the same settled start; step
//! time, cut latency, the whole 1 ms step, awake particles, CG iterations, the localised run's
//! error against the full one, memory. A Markdown table (or JSON), a CSV and a log-log SVG of
//! step time against tet count.
//!
//! The runs of one size go in lock-step (a step of each, then their comparison, untimed), so
//! no run's positions need storing; each run's step starts with the caches cold, as in a
//! session where the servo thread, the surface refit and the recorder run between steps.

use std::fs::File;
use std::io::{Read, Seek, SeekFrom};
use std::path::Path;
use std::time::Instant;

use anyhow::Context;
use cutlab_sim::cut::{Blade, CutError, CutEvent, Cutter};
use cutlab_sim::model::Model;
use cutlab_sim::scene::{BuildOptions, Scene};
use cutlab_sim::solver::{LocalisationSettings, Simulation, StaticSettings};
use cutlab_sim::stats::Summary;
use cutlab_sim::{Point3, TetMesh};
use serde::Serialize;

use crate::plot;
use crate::stroke::Stroke;

/// The tool presses with this force, N ...
const PRESS_N: f64 = 0.3;
/// ... its tip this deep below the surface, m ...
const DEPTH_M: f64 = 0.003;
/// ... its cutting edge this long (reaching 5 mm above the surface), m ...
const BLADE_M: f64 = DEPTH_M + 0.005;
/// ... cutting every this much travel, m (as the haptics stepper's `cut_step_m`) ...
const CUT_STEP_M: f64 = 0.0005;
/// ... moving at this speed along the incision, m/s.
const SPEED_M_PER_S: f64 = 0.025;
/// The tool stays away for this long first, s (untimed): a localised simulation starts with
/// every particle awake, and falls asleep before the tool arrives, as in a session.
const LEAD_IN_S: f64 = 0.1;
/// The thresholds of the extra, coarser localised run, times the defaults.
const COARSE: f64 = 10.0;

/// One scene and size.
#[derive(Debug, Clone, Copy)]
struct Case {
    scene: &'static str,
    min_tets: Option<usize>,
    /// Also a localised run with thresholds `COARSE` times the defaults.
    coarse: bool,
}

/// Largest first: its peak memory is then its own (memory freed by an earlier case and kept by
/// the allocator would count in the next case's peak).
fn cases(quick: bool) -> Vec<Case> {
    // each scene's incision is its `[incision]`: across the chest wall's top along x; the body
    // wall's midline (z runs head to foot, +y is anterior)
    let chest = |n: usize, coarse: bool| Case {
        scene: "chest-wall",
        min_tets: Some(n),
        coarse,
    };
    let body = Case {
        scene: "body-wall",
        min_tets: None,
        coarse: false,
    };
    if quick {
        vec![chest(50_000, true), chest(10_000, false)]
    } else {
        vec![
            chest(200_000, false),
            chest(100_000, true),
            chest(50_000, false),
            chest(10_000, false),
            body,
        ]
    }
}

/// How long the stroke lasts and the time after it, s.
fn timing(quick: bool) -> (f64, f64) {
    if quick { (0.8, 0.2) } else { (1.6, 0.4) }
}

/// How a run simulates.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Mode {
    Full,
    /// Localised with the default thresholds times this factor.
    Localised(f64),
}

impl Mode {
    fn name(self) -> String {
        match self {
            Mode::Full => "full".into(),
            Mode::Localised(1.0) => "localised".into(),
            Mode::Localised(f) => format!("localised x{f}"),
        }
    }
}

/// One run's figures.
#[derive(Debug, Clone, Serialize)]
pub struct PerfRow {
    pub scene: &'static str,
    pub requested_tets: Option<usize>,
    pub tets: usize,
    pub tets_after: usize,
    pub particles: usize,
    pub mode: String,
    pub steps: usize,
    /// The simulation step alone, us (times less the waits for a CPU: see [`Stopwatch`]).
    pub step_us: Summary,
    /// The simulation steps right after a cut that changed the tissue, us.
    pub step_after_cut_us: Summary,
    /// The cuts that changed the tissue (`Cutter::advance`), us.
    pub cut_us: Summary,
    /// The `Cutter::advance` calls that changed nothing (the blade between edges), us.
    pub cut_idle_us: Summary,
    /// The whole 1 ms simulated step: cut (if any), the tool's force, the step, us.
    pub whole_step_us: Summary,
    /// The same in wall time, waits for a CPU included, us.
    pub step_wall_us: Summary,
    pub cut_wall_us: Summary,
    pub whole_step_wall_us: Summary,
    pub unresolved_cuts: usize,
    pub tets_split: usize,
    pub cg_iterations_mean: f64,
    /// The mean over the 10 steps from each cut on.
    pub cg_iterations_after_cut_mean: f64,
    pub awake_mean: f64,
    /// The slowest 1 % of the steps (from the p99 up): what they had in common.
    pub slowest: SlowSteps,
    /// Localised runs: the largest position difference from the full run over the compared
    /// steps, relative to the full run's largest displacement.
    pub error: Option<f64>,
    /// Localised runs: steps compared (while the vertex counts and cuts agree).
    pub compared_steps: Option<usize>,
    /// Localised runs: where and when the largest difference was.
    pub worst: Option<Worst>,
    /// Localised runs: `identical`, `same topology` (positions of the cut differ) or where the
    /// cuts diverged.
    pub cut_events: Option<String>,
}

/// The slowest steps of a run.
#[derive(Debug, Clone, Copy, Serialize)]
pub struct SlowSteps {
    pub count: usize,
    pub awake_mean: f64,
    pub cg_iterations_mean: f64,
    /// The share of them within 10 steps of a cut.
    pub after_cut_share: f64,
}

/// The largest difference of a localised run from the full one.
#[derive(Debug, Clone, Copy, Serialize)]
pub struct Worst {
    /// Time since the stroke began, ms.
    pub at_ms: f64,
    /// Time since the last cut, ms (None: before the first).
    pub since_cut_ms: Option<f64>,
    pub vertex: u32,
    /// From the blade's tip (its last position after the stroke), mm.
    pub from_tool_mm: f64,
    pub difference_mm: f64,
}

/// One size: the settle, the rebuild every cut pays, the simulation state counted from the
/// public API, and the peak memory.
#[derive(Debug, Clone, Serialize)]
pub struct SizeRow {
    pub scene: &'static str,
    pub tets: usize,
    pub particles: usize,
    pub settle_ms: f64,
    /// The mesh's topology and the model rebuilt from scratch (`TetMesh::new`,
    /// `Model::rebuild`), as every cut does whatever its size, ms (median of 5).
    pub rebuild_ms: f64,
    /// The full run's largest displacement from the settled start, mm.
    pub peak_displacement_mm: f64,
    /// Positions, velocities (capacities) and external forces.
    pub state_bytes: usize,
    /// Masses, inverse masses, held flags, springs (capacities).
    pub model_bytes: usize,
    /// Mesh positions, tets, regions and its topology (lengths).
    pub mesh_bytes: usize,
    pub bytes_per_tet: f64,
    /// The process's peak memory (VmHWM) after building and settling this size, bytes; the
    /// first (largest) size only.
    pub peak_settled_bytes: Option<u64>,
    /// The process's peak memory after the runs of this size side by side, bytes; the first
    /// size only.
    pub peak_runs_bytes: Option<u64>,
}

/// Wall time, and wall time less the time the thread waited for a CPU meanwhile (the
/// run-queue delay of `/proc/thread-self/schedstat`, which the kernel counts exactly at each
/// switch back in): on a machine shared with other work, the second is what the code itself
/// took (it cannot remove the slowdown of caches shared with that work). Without the file,
/// both are wall time.
#[derive(Debug)]
struct Stopwatch {
    schedstat: Option<File>,
    buf: Vec<u8>,
}

#[derive(Debug, Clone, Copy)]
struct Mark {
    at: Instant,
    waited_ns: u64,
}

#[derive(Debug, Clone, Copy)]
struct Took {
    wall_us: f64,
    busy_us: f64,
}

impl Stopwatch {
    fn new() -> Self {
        Self {
            schedstat: File::open("/proc/thread-self/schedstat").ok(),
            buf: Vec::with_capacity(64),
        }
    }

    /// Nanoseconds this thread has waited for a CPU so far.
    fn waited_ns(&mut self) -> u64 {
        let Some(file) = self.schedstat.as_mut() else {
            return 0;
        };
        self.buf.clear();
        if file.seek(SeekFrom::Start(0)).is_err() || file.read_to_end(&mut self.buf).is_err() {
            return 0;
        }
        std::str::from_utf8(&self.buf)
            .ok()
            .and_then(|s| s.split_whitespace().nth(1))
            .and_then(|w| w.parse().ok())
            .unwrap_or(0)
    }

    fn start(&mut self) -> Mark {
        let waited_ns = self.waited_ns();
        Mark {
            at: Instant::now(),
            waited_ns,
        }
    }

    fn stop(&mut self, mark: Mark) -> Took {
        let wall_us = mark.at.elapsed().as_secs_f64() * 1e6;
        let waited_us = self.waited_ns().saturating_sub(mark.waited_ns) as f64 / 1e3;
        Took {
            wall_us,
            busy_us: (wall_us - waited_us).max(0.0),
        }
    }
}

/// Times of one kind, us.
#[derive(Debug, Default)]
struct Timings {
    wall: Vec<f64>,
    busy: Vec<f64>,
}

impl Timings {
    fn push(&mut self, took: Took) {
        self.wall.push(took.wall_us);
        self.busy.push(took.busy_us);
    }
}

/// A simulation driven by the script.
struct Run {
    mode: Mode,
    sim: Simulation,
    cutter: Cutter,
    stroke: Stroke,
    last_cut_tip: Option<Point3>,
    clock: Stopwatch,
    step_us: Timings,
    cut_us: Timings,
    cut_idle_us: Vec<f64>,
    whole_us: Timings,
    unresolved: usize,
    tets_split: usize,
    /// Per timed step.
    records: Vec<StepRecord>,
    steps_since_cut: Option<usize>,
}

/// One timed step.
#[derive(Debug, Clone, Copy)]
struct StepRecord {
    busy_us: f64,
    awake: usize,
    cg: usize,
    /// Steps since the last cut that changed the tissue (0: this step's own cut).
    since_cut: Option<usize>,
}

impl Run {
    fn new(settled: &Simulation, stroke: &Stroke, mode: Mode) -> Self {
        let mut sim = settled.clone();
        sim.settings.localisation = match mode {
            Mode::Full => None,
            Mode::Localised(f) => Some(LocalisationSettings::default().scaled(f)),
        };
        Self {
            mode,
            sim,
            cutter: Cutter::default(),
            stroke: stroke.clone(),
            last_cut_tip: None,
            clock: Stopwatch::new(),
            step_us: Timings::default(),
            cut_us: Timings::default(),
            cut_idle_us: Vec::new(),
            whole_us: Timings::default(),
            unresolved: 0,
            tets_split: 0,
            records: Vec::new(),
            steps_since_cut: None,
        }
    }

    /// Step `k` of the script: the tool away for `LEAD_IN_S` (untimed); then while the stroke
    /// lasts, press and cut (every `CUT_STEP_M` of travel) with the blade's tip `DEPTH_M` under
    /// the surface as pressed, or at `tool` (the hand is the session's input: every run of a
    /// session follows the full run's tool), the tool the focus; then the tool lifts. Returns
    /// the cut that changed the tissue and where the blade's tip was.
    fn step(
        &mut self,
        k: usize,
        tool: Option<Point3>,
    ) -> anyhow::Result<(Option<CutEvent>, Option<Point3>)> {
        let t = k as f64 * self.sim.settings.time_step_s - LEAD_IN_S;
        if t < 0.0 {
            self.sim
                .step()
                .with_context(|| format!("{} step {k}", self.mode.name()))?;
            return Ok((None, None));
        }
        let whole = self.clock.start();
        let mut made = None;
        let surface = self.stroke.apply(&mut self.sim, t);
        let down = self.stroke.direction();
        let tip = (t <= self.stroke.duration_s).then(|| tool.unwrap_or(surface + down * DEPTH_M));
        if let Some(tip) = tip {
            if self
                .last_cut_tip
                .is_none_or(|p| (tip - p).norm() >= CUT_STEP_M)
            {
                self.last_cut_tip = Some(tip);
                let blade = Blade {
                    tip,
                    edge_direction: -down,
                    depth_m: BLADE_M,
                };
                let tc = self.clock.start();
                let cut = self.cutter.advance(&mut self.sim, blade);
                let took = self.clock.stop(tc);
                match cut {
                    Ok(ev) if !ev.is_empty() => {
                        self.cut_us.push(took);
                        self.tets_split += ev.tets_removed.len();
                        self.stroke.cut(&ev);
                        made = Some(ev);
                    }
                    Ok(_) => self.cut_idle_us.push(took.busy_us),
                    Err(CutError::Unresolved(_)) => self.unresolved += 1,
                    Err(e) => return Err(e).with_context(|| format!("cut at step {k}")),
                }
            }
            self.sim.set_focus(&[tip]);
        } else if self.cutter.in_stroke() {
            self.cutter.end_stroke();
            self.sim.set_focus(&[]);
        }
        let ts = self.clock.start();
        let report = self.sim.step();
        let took = self.clock.stop(ts);
        self.whole_us.push(self.clock.stop(whole));
        let report = report.with_context(|| format!("{} step {k}", self.mode.name()))?;
        self.step_us.push(took);
        self.steps_since_cut = match (made.is_some(), self.steps_since_cut) {
            (true, _) => Some(0),
            (false, since) => since.map(|s| s + 1),
        };
        self.records.push(StepRecord {
            busy_us: took.busy_us,
            awake: report.awake_particles,
            cg: report.cg_iterations,
            since_cut: self.steps_since_cut,
        });
        Ok((made, tip))
    }
}

/// True when two cuts changed the same tets, springs and vertices (the positions they
/// computed may differ).
fn same_topology(a: &CutEvent, b: &CutEvent) -> bool {
    a.tets_removed == b.tets_removed
        && a.tets_added == b.tets_added
        && a.tets_relinked == b.tets_relinked
        && a.vertices_split == b.vertices_split
        && a.springs_removed == b.springs_removed
        && a.springs_added == b.springs_added
        && a.vertices_created
            .iter()
            .map(|v| (v.id, v.edge))
            .eq(b.vertices_created.iter().map(|v| (v.id, v.edge)))
        && a.vertices_moved
            .iter()
            .map(|v| v.id)
            .eq(b.vertices_moved.iter().map(|v| v.id))
}

fn max_distance(a: &[Point3], b: &[Point3]) -> f64 {
    a.iter()
        .zip(b)
        .map(|(p, q)| (p - q).norm())
        .fold(0.0, f64::max)
}

/// How a localised run compares with the full one, step by step.
#[derive(Debug, Default)]
struct Comparison {
    worst_m: f64,
    worst: Option<Worst>,
    compared: usize,
    positions_differ: bool,
    /// When the cuts diverged, ms from the stroke's start.
    diverged_at: Option<f64>,
}

impl Comparison {
    /// The step `at_ms` after the stroke began, the blade's tip at `tool`.
    fn step(
        &mut self,
        at_ms: f64,
        tool: Option<Point3>,
        full: (&Run, &Option<CutEvent>),
        local: (&Run, &Option<CutEvent>),
    ) {
        if self.diverged_at.is_some() {
            return;
        }
        let agree = match (full.1, local.1) {
            (None, None) => true,
            (Some(a), Some(b)) => {
                self.positions_differ |= a != b;
                same_topology(a, b)
            }
            _ => false,
        };
        let (a, b) = (&full.0.sim.state.positions, &local.0.sim.state.positions);
        if !agree || a.len() != b.len() {
            self.diverged_at = Some(at_ms);
            return;
        }
        self.compared += 1;
        let Some((vertex, d)) = a
            .iter()
            .zip(b)
            .map(|(p, q)| (p - q).norm())
            .enumerate()
            .max_by(|x, y| x.1.total_cmp(&y.1))
        else {
            return;
        };
        if d > self.worst_m {
            self.worst_m = d;
            let since_cut = full.0.records.last().and_then(|s| s.since_cut);
            self.worst = Some(Worst {
                at_ms,
                since_cut_ms: since_cut.map(|s| s as f64 * full.0.sim.settings.time_step_s * 1e3),
                vertex: vertex as u32,
                from_tool_mm: tool.map_or(f64::NAN, |t| (a[vertex] - t).norm() * 1e3),
                difference_mm: d * 1e3,
            });
        }
    }

    fn verdict(&self) -> String {
        match self.diverged_at {
            Some(ms) => format!("diverged at {ms:.0} ms"),
            None if self.positions_differ => "same topology".into(),
            None => "identical".into(),
        }
    }
}

fn vm_hwm_bytes() -> Option<u64> {
    let status = std::fs::read_to_string("/proc/self/status").ok()?;
    let line = status.lines().find(|l| l.starts_with("VmHWM:"))?;
    let kb: u64 = line.split_whitespace().nth(1)?.parse().ok()?;
    Some(kb * 1024)
}

/// The simulation state reachable through the public API. Not counted: the solver's scratch
/// (the implicit system and CG vectors, the localised sub-body), private to `Simulation`.
fn memory(scene: &'static str, sim: &Simulation) -> SizeRow {
    fn cap<T>(v: &Vec<T>) -> usize {
        v.capacity() * std::mem::size_of::<T>()
    }
    fn len<T>(v: &[T]) -> usize {
        std::mem::size_of_val(v)
    }
    let m = &sim.model;
    let topo = m.mesh.topology();
    let csr = |c: &cutlab_sim::mesh::Csr| {
        4 * (c.rows() + 1 + (0..c.rows()).map(|i| c.row(i).len()).sum::<usize>())
    };
    let state_bytes =
        cap(&sim.state.positions) + cap(&sim.state.velocities) + len(sim.external_forces());
    let model_bytes = cap(&m.mass)
        + cap(&m.inv_mass)
        + cap(&m.held)
        + cap(&m.springs.ends)
        + cap(&m.springs.rest_length)
        + cap(&m.springs.stiffness)
        + cap(&m.springs.damping);
    let mesh_bytes = len(m.mesh.positions())
        + len(m.mesh.tets())
        + len(m.mesh.regions())
        + cap(&topo.edges)
        + cap(&topo.boundary)
        + cap(&topo.overshared_faces)
        + csr(&topo.vertex_tets);
    let tets = m.mesh.tet_count();
    SizeRow {
        scene,
        tets,
        particles: m.vertex_count(),
        settle_ms: 0.0,
        rebuild_ms: 0.0,
        peak_displacement_mm: 0.0,
        state_bytes,
        model_bytes,
        mesh_bytes,
        bytes_per_tet: (state_bytes + model_bytes + mesh_bytes) as f64 / tets as f64,
        peak_settled_bytes: None,
        peak_runs_bytes: None,
    }
}

/// The mesh's topology and the model rebuilt from scratch, as a cut does, ms (the median of
/// 5, less the waits for a CPU).
fn rebuild_ms(model: &Model) -> anyhow::Result<f64> {
    let mut copy = model.clone();
    let mesh = &model.mesh;
    let mut clock = Stopwatch::new();
    let mut times = Vec::new();
    for _ in 0..5 {
        let t = clock.start();
        let rebuilt = TetMesh::new(
            mesh.positions().to_vec(),
            mesh.tets().to_vec(),
            mesh.regions().to_vec(),
        )?;
        copy.rebuild(rebuilt, model.held.clone())?;
        times.push(clock.stop(t).busy_us / 1e3);
    }
    Ok(Summary::of(&times).median)
}

/// With `first`, the peak memory of the process too (a later case's would include what the
/// allocator kept of an earlier one).
fn run_case(
    case: Case,
    quick: bool,
    first: bool,
    bar: &indicatif::ProgressBar,
) -> anyhow::Result<(Vec<PerfRow>, SizeRow)> {
    let (stroke_s, after_s) = timing(quick);
    let label = |tets: usize| format!("{} {}k tets", case.scene, tets / 1000);
    bar.set_message(format!("{}: building and settling", case.scene));
    let scene = Scene::load(
        case.scene,
        BuildOptions {
            min_tets: case.min_tets,
        },
    )
    .with_context(|| format!("building {}", case.scene))?;
    let mut settled = scene.simulation();
    let t = Instant::now();
    let report = settled.settle(StaticSettings::default());
    let settle_ms = t.elapsed().as_secs_f64() * 1e3;
    anyhow::ensure!(
        report.converged,
        "settling {} did not converge: {report:?}",
        case.scene
    );
    let tets = settled.model.mesh.tet_count();
    let mut size = memory(case.scene, &settled);
    size.peak_settled_bytes = vm_hwm_bytes().filter(|_| first);
    size.settle_ms = settle_ms;
    size.rebuild_ms = rebuild_ms(&settled.model)?;

    // the incision: through the middle of the bounding box, on the surface facing `up`
    let x = &settled.state.positions;
    let (lo, hi) = cutlab_sim::mesh::bounding_box(x);
    let centre = lo + (hi - lo) / 2.0;
    // checked when the scene was built
    let (up, along) = scene.spec.incision.unit().map_err(anyhow::Error::msg)?;
    let half = 0.5 * SPEED_M_PER_S * stroke_s;
    let stroke = Stroke::new(
        &settled,
        centre - along * half,
        centre + along * half,
        -up,
        stroke_s,
        PRESS_N,
    );
    anyhow::ensure!(
        stroke.surface_count() > 0,
        "{}: no free surface facing {up:?} along the incision",
        case.scene
    );

    let mut modes = vec![Mode::Full, Mode::Localised(1.0)];
    if case.coarse {
        modes.push(Mode::Localised(COARSE));
    }
    let mut runs: Vec<Run> = modes
        .iter()
        .map(|&m| Run::new(&settled, &stroke, m))
        .collect();
    let start = settled.state.positions.clone();
    drop(settled);
    let mut comparisons: Vec<Comparison> = (1..runs.len()).map(|_| Comparison::default()).collect();
    let dt = runs[0].sim.settings.time_step_s;
    let mut peak_m = 0.0f64;
    let mut tool = None;
    bar.set_message(format!(
        "{}: {}",
        label(tets),
        modes
            .iter()
            .map(|m| m.name())
            .collect::<Vec<_>>()
            .join(", ")
    ));
    for k in 0..((LEAD_IN_S + stroke_s + after_s) / dt).round() as usize {
        let (first, tip) = runs[0].step(k, None)?;
        tool = tip.or(tool);
        let mut events = vec![first];
        for run in &mut runs[1..] {
            events.push(run.step(k, tip)?.0);
        }
        let full = &runs[0].sim.state.positions;
        peak_m = peak_m.max(max_distance(&full[..start.len()], &start));
        let at_ms = (k as f64 * dt - LEAD_IN_S) * 1e3;
        for (j, c) in comparisons.iter_mut().enumerate() {
            c.step(
                at_ms,
                tool,
                (&runs[0], &events[0]),
                (&runs[j + 1], &events[j + 1]),
            );
        }
        bar.inc(1);
    }
    size.peak_runs_bytes = vm_hwm_bytes().filter(|_| first);
    size.peak_displacement_mm = peak_m * 1e3;
    let rows = runs
        .iter()
        .enumerate()
        .map(|(j, r)| {
            let comparison = j.checked_sub(1).map(|i| &comparisons[i]);
            PerfRow {
                scene: case.scene,
                requested_tets: case.min_tets,
                tets,
                tets_after: r.sim.model.mesh.tet_count(),
                particles: r.sim.model.vertex_count(),
                mode: r.mode.name(),
                steps: r.step_us.busy.len(),
                step_us: Summary::of(&r.step_us.busy),
                step_after_cut_us: Summary::of(
                    &r.records
                        .iter()
                        .filter(|s| s.since_cut == Some(0))
                        .map(|s| s.busy_us)
                        .collect::<Vec<_>>(),
                ),
                cut_us: Summary::of(&r.cut_us.busy),
                cut_idle_us: Summary::of(&r.cut_idle_us),
                whole_step_us: Summary::of(&r.whole_us.busy),
                step_wall_us: Summary::of(&r.step_us.wall),
                cut_wall_us: Summary::of(&r.cut_us.wall),
                whole_step_wall_us: Summary::of(&r.whole_us.wall),
                unresolved_cuts: r.unresolved,
                tets_split: r.tets_split,
                cg_iterations_mean: mean(r.records.iter().map(|s| s.cg as f64)),
                cg_iterations_after_cut_mean: mean(
                    r.records
                        .iter()
                        .filter(|s| after_cut(s))
                        .map(|s| s.cg as f64),
                ),
                awake_mean: mean(r.records.iter().map(|s| s.awake as f64)),
                slowest: slowest(&r.records),
                error: comparison.map(|c| {
                    if peak_m > 0.0 {
                        c.worst_m / peak_m
                    } else {
                        0.0
                    }
                }),
                compared_steps: comparison.map(|c| c.compared),
                worst: comparison.and_then(|c| c.worst),
                cut_events: comparison.map(Comparison::verdict),
            }
        })
        .collect();
    Ok((rows, size))
}

fn mean(values: impl Iterator<Item = f64>) -> f64 {
    let (sum, n) = values.fold((0.0, 0usize), |(s, n), v| (s + v, n + 1));
    if n > 0 { sum / n as f64 } else { 0.0 }
}

fn after_cut(s: &StepRecord) -> bool {
    s.since_cut.is_some_and(|k| k < 10)
}

fn slowest(records: &[StepRecord]) -> SlowSteps {
    let p99 = Summary::of(&records.iter().map(|s| s.busy_us).collect::<Vec<_>>()).p99;
    let slow: Vec<&StepRecord> = records.iter().filter(|s| s.busy_us >= p99).collect();
    SlowSteps {
        count: slow.len(),
        awake_mean: mean(slow.iter().map(|s| s.awake as f64)),
        cg_iterations_mean: mean(slow.iter().map(|s| s.cg as f64)),
        after_cut_share: mean(slow.iter().map(|s| if after_cut(s) { 1.0 } else { 0.0 })),
    }
}

/// The load average of the machine (1, 5, 15 min), if known: other work competes for the cores.
fn load_average() -> Option<[f64; 3]> {
    let text = std::fs::read_to_string("/proc/loadavg").ok()?;
    let mut v = text.split_whitespace().map(|w| w.parse::<f64>().ok());
    Some([v.next()??, v.next()??, v.next()??])
}

/// Runs the benchmark; writes `out/perf.csv` and `out/perf.svg`.
pub fn run(quick: bool, json: bool, out: &Path) -> anyhow::Result<()> {
    let cases = cases(quick);
    let (stroke_s, after_s) = timing(quick);
    let steps_per_case = ((LEAD_IN_S + stroke_s + after_s) / 1e-3_f64).round() as u64;
    let bar = crate::progress::bar(steps_per_case * cases.len() as u64, json);
    let load_before = load_average();
    let mut rows = Vec::new();
    let mut sizes = Vec::new();
    for (i, &case) in cases.iter().enumerate() {
        let (r, m) = run_case(case, quick, i == 0, &bar)?;
        rows.extend(r);
        sizes.push(m);
    }
    bar.finish_and_clear();
    let load = [load_before, load_average()];
    let threads = cutlab_sim::solver::solver_threads();

    std::fs::create_dir_all(out).with_context(|| format!("creating {}", out.display()))?;
    let csv_path = out.join("perf.csv");
    std::fs::write(&csv_path, csv(&rows))
        .with_context(|| format!("writing {}", csv_path.display()))?;
    let svg_path = out.join("perf.svg");
    std::fs::write(&svg_path, svg(&rows, threads))
        .with_context(|| format!("writing {}", svg_path.display()))?;
    let goals = goals(&rows);
    if json {
        let doc = serde_json::json!({
            "solver_threads": threads,
            "session": session_text(stroke_s, after_s),
            "load_average_before_after": load,
            "rows": rows,
            "sizes": sizes,
            "goals": goals,
        });
        println!("{}", serde_json::to_string_pretty(&doc)?);
        return Ok(());
    }
    println!(
        "{}; {}",
        session_text(stroke_s, after_s),
        threads_text(threads)
    );
    if let [Some(a), Some(b)] = load {
        println!(
            "load average before {:.2}, after {:.2} (other work on the machine inflates the p99s)",
            a[0], b[0]
        );
    }
    println!();
    println!(
        "| scene | tets | mode | step median us | step p99 us | step after a cut, median us | cuts | cut median us | cut p99 us | cut call without change, median us | 1 ms step with its cut, p99 us | max us | the same p99 in wall time us | awake | CG it. | CG it. after a cut | error % | cut events |"
    );
    println!(
        "|---|---:|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---|"
    );
    for r in &rows {
        println!(
            "| {} | {} | {} | {:.0} | {:.0} | {:.0} | {} | {:.0} | {:.0} | {:.0} | {:.0} | {:.0} | {:.0} | {:.0} | {:.1} | {:.1} | {} | {} |",
            r.scene,
            r.tets,
            r.mode,
            r.step_us.median,
            r.step_us.p99,
            r.step_after_cut_us.median,
            r.cut_us.count,
            r.cut_us.median,
            r.cut_us.p99,
            r.cut_idle_us.median,
            r.whole_step_us.p99,
            r.whole_step_us.max,
            r.whole_step_wall_us.p99,
            r.awake_mean,
            r.cg_iterations_mean,
            r.cg_iterations_after_cut_mean,
            r.error.map_or("".into(), |e| format!("{:.2}", 100.0 * e)),
            r.cut_events.as_deref().unwrap_or(""),
        );
    }
    println!();
    println!(
        "| scene | tets | mode | slowest 1 % of steps: awake | CG it. | within 10 steps of a cut % | largest difference mm | at ms | after a cut ms | from the tool mm |"
    );
    println!("|---|---:|---|---:|---:|---:|---:|---:|---:|---:|");
    let opt = |v: Option<f64>, digits: usize| v.map_or(String::new(), |v| format!("{v:.digits$}"));
    for r in &rows {
        let w = r.worst.as_ref();
        println!(
            "| {} | {} | {} | {:.0} | {:.1} | {:.0} | {} | {} | {} | {} |",
            r.scene,
            r.tets,
            r.mode,
            r.slowest.awake_mean,
            r.slowest.cg_iterations_mean,
            100.0 * r.slowest.after_cut_share,
            opt(w.map(|w| w.difference_mm), 3),
            opt(w.map(|w| w.at_ms), 0),
            opt(w.and_then(|w| w.since_cut_ms), 0),
            opt(w.map(|w| w.from_tool_mm), 1),
        );
    }
    println!();
    println!(
        "| scene | tets | particles | settle ms | rebuild per cut ms | largest displacement mm | state bytes per tet | peak memory, settled MB | peak memory with the runs MB |"
    );
    println!("|---|---:|---:|---:|---:|---:|---:|---:|---:|");
    let mb = |b: Option<u64>| b.map_or(String::new(), |b| format!("{:.0}", b as f64 / 1e6));
    for m in &sizes {
        println!(
            "| {} | {} | {} | {:.0} | {:.1} | {:.1} | {:.0} | {} | {} |",
            m.scene,
            m.tets,
            m.particles,
            m.settle_ms,
            m.rebuild_ms,
            m.peak_displacement_mm,
            m.bytes_per_tet,
            mb(m.peak_settled_bytes),
            mb(m.peak_runs_bytes)
        );
    }
    println!();
    for g in &goals {
        println!(
            "goal, {}: {:.0} us, {}",
            g.goal,
            g.measured_us,
            if g.met { "met" } else { "NOT met" }
        );
    }
    println!("wrote {} and {}", csv_path.display(), svg_path.display());
    Ok(())
}

/// How many threads the solver used, for the headers.
pub(crate) fn threads_text(threads: usize) -> String {
    if threads > 1 {
        format!(
            "{threads} threads for the step from 4k particles and the cut from 20k tets on (RAYON_NUM_THREADS=1: one)"
        )
    } else {
        "single thread".into()
    }
}

fn session_text(stroke_s: f64, after_s: f64) -> String {
    format!(
        "1 ms steps, implicit Euler: after {:.0} ms without the tool (untimed), a {:.0} mm incision in {stroke_s} s ({PRESS_N} N press, tip {:.0} mm deep, a cut every {:.1} mm), then {after_s} s; the 1 ms step p99 includes its cut; times less the thread's waits for a CPU",
        LEAD_IN_S * 1e3,
        SPEED_M_PER_S * stroke_s * 1e3,
        DEPTH_M * 1e3,
        CUT_STEP_M * 1e3
    )
}

/// A goal of issue 9 on the 100k chest wall.
#[derive(Debug, Serialize)]
struct Goal {
    goal: &'static str,
    measured_us: f64,
    met: bool,
}

fn goals(rows: &[PerfRow]) -> Vec<Goal> {
    let at_100k = |mode: &str| {
        rows.iter().find(|r| {
            r.scene == "chest-wall" && r.requested_tets == Some(100_000) && r.mode == mode
        })
    };
    let mut goals = Vec::new();
    if let Some(r) = at_100k("localised") {
        let us = r.whole_step_us.p99;
        goals.push(Goal {
            goal: "localised 100k, p99 of the 1 ms step with its cut < 1 ms",
            measured_us: us,
            met: us < 1e3,
        });
    }
    if let Some(r) = at_100k("full") {
        let us = r.step_us.p99;
        goals.push(Goal {
            goal: "full 100k, p99 of the step < 10 ms",
            measured_us: us,
            met: us < 1e4,
        });
    }
    goals
}

fn csv(rows: &[PerfRow]) -> String {
    let mut s = String::from(
        "scene,tets,tets_after,particles,mode,steps,step_median_us,step_p99_us,step_after_cut_median_us,whole_step_median_us,whole_step_p99_us,whole_step_max_us,step_wall_p99_us,whole_step_wall_p99_us,cuts,cut_median_us,cut_p99_us,cut_max_us,cut_wall_p99_us,cut_idle_median_us,unresolved_cuts,tets_split,cg_iterations_mean,cg_iterations_after_cut_mean,awake_mean,error,compared_steps,cut_events\n",
    );
    for r in rows {
        s.push_str(&format!(
            "{},{},{},{},{},{},{:.1},{:.1},{:.1},{:.1},{:.1},{:.1},{:.1},{:.1},{},{:.1},{:.1},{:.1},{:.1},{:.1},{},{},{:.2},{:.2},{:.1},{},{},{}\n",
            r.scene,
            r.tets,
            r.tets_after,
            r.particles,
            r.mode,
            r.steps,
            r.step_us.median,
            r.step_us.p99,
            r.step_after_cut_us.median,
            r.whole_step_us.median,
            r.whole_step_us.p99,
            r.whole_step_us.max,
            r.step_wall_us.p99,
            r.whole_step_wall_us.p99,
            r.cut_us.count,
            r.cut_us.median,
            r.cut_us.p99,
            r.cut_us.max,
            r.cut_wall_us.p99,
            r.cut_idle_us.median,
            r.unresolved_cuts,
            r.tets_split,
            r.cg_iterations_mean,
            r.cg_iterations_after_cut_mean,
            r.awake_mean,
            r.error.map_or(String::new(), |e| format!("{e:.6}")),
            r.compared_steps.map_or(String::new(), |c| c.to_string()),
            r.cut_events.as_deref().unwrap_or(""),
        ));
    }
    s
}

/// Step time against tet count on the chest wall, median and p99, full and localised, and
/// the localised whole step (with its cut) at p99; the 1 ms and 10 ms goals as guides.
fn svg(rows: &[PerfRow], threads: usize) -> String {
    let chest: Vec<&PerfRow> = rows.iter().filter(|r| r.scene == "chest-wall").collect();
    let series = |name: &str,
                  colour: &'static str,
                  line: plot::Line,
                  mode: &str,
                  value: fn(&PerfRow) -> f64| plot::Series {
        name: name.into(),
        colour,
        line,
        markers: true,
        points: chest
            .iter()
            .filter(|r| r.mode == mode)
            .map(|r| plot::Point {
                x: r.tets as f64,
                y: value(r),
                title: format!("{name}, {} tets: {:.0} us", r.tets, value(r)),
            })
            .collect(),
    };
    let panel = plot::Panel {
        title: format!(
            "chest wall: step time, us (log), against tetrahedra (log); {}",
            threads_text(threads)
        ),
        x_unit: String::new(),
        y_unit: " us".into(),
        series: vec![
            series("full, median", "#1f77b4", plot::Line::Solid, "full", |r| {
                r.step_us.median
            }),
            series("full, p99", "#1f77b4", plot::Line::Dashed, "full", |r| {
                r.step_us.p99
            }),
            series(
                "localised, median",
                "#d62728",
                plot::Line::Solid,
                "localised",
                |r| r.step_us.median,
            ),
            series(
                "localised, p99",
                "#d62728",
                plot::Line::Dashed,
                "localised",
                |r| r.step_us.p99,
            ),
            series(
                "localised, p99 of the step with its cut",
                "#ff7f0e",
                plot::Line::Dashed,
                "localised",
                |r| r.whole_step_us.p99,
            ),
        ],
        guides: vec![(1e3, "1 ms: 1 kHz".into()), (1e4, "10 ms".into())],
    };
    plot::log_log(720.0, 400.0, &[panel])
}
