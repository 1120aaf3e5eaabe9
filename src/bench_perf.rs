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

use std::path::Path;
use std::time::Instant;

use anyhow::Context;
use cutlab_sim::cut::{Blade, CutError, CutEvent, Cutter};
use cutlab_sim::scene::{BuildOptions, Scene};
use cutlab_sim::solver::{LocalisationSettings, Simulation, StaticSettings};
use cutlab_sim::{Point3, Vector3};
use serde::Serialize;

use crate::plot;
use crate::stats::Summary;
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
/// The thresholds of the extra, coarser localised run, times the defaults.
const COARSE: f64 = 10.0;

/// One scene and size.
#[derive(Debug, Clone, Copy)]
struct Case {
    scene: &'static str,
    min_tets: Option<usize>,
    /// Out of the tissue, where the tool comes from.
    up: [f64; 3],
    /// Along the incision.
    along: [f64; 3],
    /// Also a localised run with thresholds `COARSE` times the defaults.
    coarse: bool,
}

fn cases(quick: bool) -> Vec<Case> {
    let chest = |n: usize, coarse: bool| Case { scene: "chest-wall", min_tets: Some(n), up: [0.0, 0.0, 1.0], along: [1.0, 0.0, 0.0], coarse };
    // the body wall as scanned: z runs head to foot, +y is anterior; a midline incision
    let body = Case { scene: "body-wall", min_tets: None, up: [0.0, 1.0, 0.0], along: [0.0, 0.0, 1.0], coarse: false };
    if quick {
        vec![chest(10_000, false), chest(50_000, true)]
    } else {
        vec![chest(10_000, false), chest(50_000, false), chest(100_000, true), chest(200_000, false), body]
    }
}

/// How long the stroke lasts and the time after it, s.
fn timing(quick: bool) -> (f64, f64) {
    if quick { (0.4, 0.1) } else { (1.6, 0.4) }
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
            Mode::Localised(f) if f == 1.0 => "localised".into(),
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
    /// The simulation step alone, us.
    pub step_us: Summary,
    /// The cuts that changed the tissue (`Cutter::advance`), us.
    pub cut_us: Summary,
    /// The whole 1 ms simulated step: cut (if any), the tool's force, the step, us.
    pub whole_step_us: Summary,
    pub unresolved_cuts: usize,
    pub tets_split: usize,
    pub cg_iterations_mean: f64,
    /// After the first cut: the mean of the 10 steps that follow each cut.
    pub cg_iterations_after_cut_mean: f64,
    pub awake_mean: f64,
    /// Localised runs: the largest position difference from the full run over the compared
    /// steps, relative to the full run's largest displacement.
    pub error: Option<f64>,
    /// Localised runs: steps compared (while the vertex counts and cuts agree).
    pub compared_steps: Option<usize>,
    /// Localised runs: `identical`, `same topology` (positions of the cut differ) or where the
    /// cuts diverged.
    pub cut_events: Option<String>,
}

/// Simulation state of one size, counted from the public API, and the peak memory.
#[derive(Debug, Clone, Serialize)]
pub struct MemoryRow {
    pub scene: &'static str,
    pub tets: usize,
    /// Positions and velocities (capacities).
    pub state_bytes: usize,
    /// Masses, inverse masses, held flags, springs (capacities).
    pub model_bytes: usize,
    /// Mesh positions, tets, regions and its topology (lengths).
    pub mesh_bytes: usize,
    pub bytes_per_tet: f64,
    /// VmHWM after building and settling this size alone, bytes (None: unavailable).
    pub peak_settled_bytes: Option<u64>,
    /// VmHWM after the runs of this size side by side, bytes.
    pub peak_runs_bytes: Option<u64>,
}

/// A simulation driven by the script.
struct Run {
    mode: Mode,
    sim: Simulation,
    cutter: Cutter,
    stroke: Stroke,
    last_cut_tip: Option<Point3>,
    step_us: Vec<f64>,
    cut_us: Vec<f64>,
    whole_us: Vec<f64>,
    unresolved: usize,
    tets_split: usize,
    cg: usize,
    /// CG iterations of the 10 steps after each cut, and how many such steps.
    cg_after_cut: (usize, usize),
    steps_since_cut: Option<usize>,
    awake: usize,
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
            step_us: Vec::new(),
            cut_us: Vec::new(),
            whole_us: Vec::new(),
            unresolved: 0,
            tets_split: 0,
            cg: 0,
            cg_after_cut: (0, 0),
            steps_since_cut: None,
            awake: 0,
        }
    }

    /// Step `k` of the script: while the stroke lasts, cut (every `CUT_STEP_M` of travel) and
    /// press, the tool the focus; then the tool lifts. Returns the cut that changed the tissue.
    fn step(&mut self, k: usize) -> anyhow::Result<Option<CutEvent>> {
        let t = k as f64 * self.sim.settings.time_step_s;
        let whole = Instant::now();
        let mut made = None;
        if t <= self.stroke.duration_s {
            let down = self.stroke.direction();
            let tip = self.stroke.tip_at(t) + down * DEPTH_M;
            if self.last_cut_tip.is_none_or(|p| (tip - p).norm() >= CUT_STEP_M) {
                self.last_cut_tip = Some(tip);
                let blade = Blade { tip, edge_direction: -down, depth_m: BLADE_M };
                let tc = Instant::now();
                match self.cutter.advance(&mut self.sim, blade) {
                    Ok(ev) if !ev.is_empty() => {
                        self.cut_us.push(tc.elapsed().as_secs_f64() * 1e6);
                        self.tets_split += ev.tets_removed.len();
                        self.stroke.cut(&ev);
                        self.steps_since_cut = Some(0);
                        made = Some(ev);
                    }
                    Ok(_) => {}
                    Err(CutError::Unresolved(_)) => self.unresolved += 1,
                    Err(e) => return Err(e).with_context(|| format!("cut at step {k}")),
                }
            }
            self.sim.set_focus(&[tip]);
        } else if self.cutter.in_stroke() {
            self.cutter.end_stroke();
            self.sim.set_focus(&[]);
        }
        self.stroke.apply(&mut self.sim, t);
        let ts = Instant::now();
        let report = self.sim.step().with_context(|| format!("{} step {k}", self.mode.name()))?;
        let end = Instant::now();
        self.step_us.push((end - ts).as_secs_f64() * 1e6);
        self.whole_us.push((end - whole).as_secs_f64() * 1e6);
        self.cg += report.cg_iterations;
        self.awake += report.awake_particles;
        if let Some(s) = self.steps_since_cut.as_mut() {
            if *s < 10 {
                self.cg_after_cut.0 += report.cg_iterations;
                self.cg_after_cut.1 += 1;
            }
            *s += 1;
        }
        Ok(made)
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
        && a.vertices_created.iter().map(|v| (v.id, v.edge)).eq(b.vertices_created.iter().map(|v| (v.id, v.edge)))
        && a.vertices_moved.iter().map(|v| v.id).eq(b.vertices_moved.iter().map(|v| v.id))
}

fn max_distance(a: &[Point3], b: &[Point3]) -> f64 {
    a.iter().zip(b).map(|(p, q)| (p - q).norm()).fold(0.0, f64::max)
}

/// How a localised run compares with the full one, step by step.
#[derive(Debug, Default)]
struct Comparison {
    worst_m: f64,
    compared: usize,
    positions_differ: bool,
    diverged_at: Option<usize>,
}

impl Comparison {
    fn step(&mut self, k: usize, full: (&Run, &Option<CutEvent>), local: (&Run, &Option<CutEvent>)) {
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
            self.diverged_at = Some(k);
            return;
        }
        self.worst_m = self.worst_m.max(max_distance(a, b));
        self.compared += 1;
    }

    fn verdict(&self, dt: f64) -> String {
        match self.diverged_at {
            Some(k) => format!("diverged at {:.0} ms", k as f64 * dt * 1e3),
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

/// Resets VmHWM to the current RSS (Linux: `5` to `/proc/self/clear_refs`); false when not
/// possible (the peak is then the process's so far).
fn reset_peak() -> bool {
    std::fs::write("/proc/self/clear_refs", "5").is_ok()
}

/// The simulation state reachable through the public API. Not counted: the solver's scratch
/// (the implicit system and CG vectors, the localised sub-body), private to `Simulation`.
fn memory(scene: &'static str, sim: &Simulation) -> MemoryRow {
    fn cap<T>(v: &Vec<T>) -> usize {
        v.capacity() * std::mem::size_of::<T>()
    }
    fn len<T>(v: &[T]) -> usize {
        std::mem::size_of_val(v)
    }
    let m = &sim.model;
    let topo = m.mesh.topology();
    let csr = |c: &cutlab_sim::mesh::Csr| 4 * (c.rows() + 1 + (0..c.rows()).map(|i| c.row(i).len()).sum::<usize>());
    let state_bytes = cap(&sim.state.positions) + cap(&sim.state.velocities) + len(sim.external_forces());
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
        + cap(&topo.tet_edges)
        + cap(&topo.faces)
        + cap(&topo.face_tets)
        + cap(&topo.tet_faces)
        + cap(&topo.boundary)
        + cap(&topo.boundary_face_ids)
        + cap(&topo.overshared_faces)
        + csr(&topo.vertex_tets)
        + csr(&topo.edge_tets);
    let tets = m.mesh.tet_count();
    MemoryRow {
        scene,
        tets,
        state_bytes,
        model_bytes,
        mesh_bytes,
        bytes_per_tet: (state_bytes + model_bytes + mesh_bytes) as f64 / tets as f64,
        peak_settled_bytes: None,
        peak_runs_bytes: None,
    }
}

/// Builds, settles and runs one case; returns its rows and memory.
fn run_case(case: Case, quick: bool, bar: &indicatif::ProgressBar) -> anyhow::Result<(Vec<PerfRow>, MemoryRow)> {
    let (stroke_s, after_s) = timing(quick);
    let label = |tets: usize| format!("{} {}k tets", case.scene, tets / 1000);
    let peak_resettable = reset_peak();
    bar.set_message(format!("{}: building and settling", case.scene));
    let scene = Scene::load(case.scene, BuildOptions { min_tets: case.min_tets }).with_context(|| format!("building {}", case.scene))?;
    let mut settled = scene.simulation();
    let report = settled.settle(StaticSettings::default());
    anyhow::ensure!(report.converged, "settling {} did not converge: {report:?}", case.scene);
    let tets = settled.model.mesh.tet_count();
    let mut mem = memory(case.scene, &settled);
    mem.peak_settled_bytes = vm_hwm_bytes();

    // the incision: through the middle of the bounding box, on the surface facing `up`
    let x = &settled.state.positions;
    let (lo, hi) = x.iter().fold((x[0], x[0]), |(lo, hi), p| (lo.inf(p), hi.sup(p)));
    let centre = lo + (hi - lo) / 2.0;
    let (up, along) = (Vector3::from(case.up), Vector3::from(case.along));
    let half = 0.5 * SPEED_M_PER_S * stroke_s;
    let stroke = Stroke::new(&settled, centre - along * half, centre + along * half, -up, stroke_s, PRESS_N);
    anyhow::ensure!(stroke.surface_count() > 0, "{}: no free surface facing {up:?} along the incision", case.scene);

    let mut modes = vec![Mode::Full, Mode::Localised(1.0)];
    if case.coarse {
        modes.push(Mode::Localised(COARSE));
    }
    let mut runs: Vec<Run> = modes.iter().map(|&m| Run::new(&settled, &stroke, m)).collect();
    let start = settled.state.positions.clone();
    drop(settled);
    let mut comparisons: Vec<Comparison> = (1..runs.len()).map(|_| Comparison::default()).collect();
    let steps = ((stroke_s + after_s) / runs[0].sim.settings.time_step_s).round() as usize;
    let mut peak_m = 0.0f64;
    bar.set_message(format!("{}: {}", label(tets), modes.iter().map(|m| m.name()).collect::<Vec<_>>().join(", ")));
    for k in 0..steps {
        let events: Vec<Option<CutEvent>> = runs.iter_mut().map(|r| r.step(k)).collect::<anyhow::Result<_>>()?;
        let full = &runs[0].sim.state.positions;
        peak_m = peak_m.max(max_distance(&full[..start.len()], &start));
        for (j, c) in comparisons.iter_mut().enumerate() {
            c.step(k, (&runs[0], &events[0]), (&runs[j + 1], &events[j + 1]));
        }
        bar.inc(1);
    }
    mem.peak_runs_bytes = vm_hwm_bytes();
    if !peak_resettable {
        tracing::warn!("could not reset the peak memory (/proc/self/clear_refs): peaks are the process's so far");
    }
    let dt = runs[0].sim.settings.time_step_s;
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
                steps,
                step_us: Summary::of(&r.step_us),
                cut_us: Summary::of(&r.cut_us),
                whole_step_us: Summary::of(&r.whole_us),
                unresolved_cuts: r.unresolved,
                tets_split: r.tets_split,
                cg_iterations_mean: r.cg as f64 / steps as f64,
                cg_iterations_after_cut_mean: r.cg_after_cut.0 as f64 / r.cg_after_cut.1.max(1) as f64,
                awake_mean: r.awake as f64 / steps as f64,
                error: comparison.map(|c| if peak_m > 0.0 { c.worst_m / peak_m } else { 0.0 }),
                compared_steps: comparison.map(|c| c.compared),
                cut_events: comparison.map(|c| c.verdict(dt)),
            }
        })
        .collect();
    Ok((rows, mem))
}

/// Runs the benchmark; writes `out/perf.csv` and `out/perf.svg`.
pub fn run(quick: bool, json: bool, out: &Path) -> anyhow::Result<()> {
    let cases = cases(quick);
    let (stroke_s, after_s) = timing(quick);
    let steps_per_case = ((stroke_s + after_s) / 1e-3_f64).round() as u64;
    let bar = crate::progress::bar(steps_per_case * cases.len() as u64, json);
    let mut rows = Vec::new();
    let mut memory = Vec::new();
    for &case in &cases {
        let (r, m) = run_case(case, quick, &bar)?;
        rows.extend(r);
        memory.push(m);
    }
    bar.finish_and_clear();

    std::fs::create_dir_all(out).with_context(|| format!("creating {}", out.display()))?;
    let csv_path = out.join("perf.csv");
    std::fs::write(&csv_path, csv(&rows)).with_context(|| format!("writing {}", csv_path.display()))?;
    let svg_path = out.join("perf.svg");
    std::fs::write(&svg_path, svg(&rows)).with_context(|| format!("writing {}", svg_path.display()))?;
    let goals = goals(&rows);
    if json {
        let doc = serde_json::json!({
            "threads": 1,
            "session": session_text(stroke_s, after_s),
            "rows": rows,
            "memory": memory,
            "goals": goals,
        });
        println!("{}", serde_json::to_string_pretty(&doc)?);
        return Ok(());
    }
    println!("{}; single thread (no parallelism yet)", session_text(stroke_s, after_s));
    println!();
    println!("| scene | tets | mode | step median us | step p99 us | whole step p99 us | cuts | cut median us | cut p99 us | awake | CG it. | CG it. after a cut | error % | cut events |");
    println!("|---|---:|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---|");
    for r in &rows {
        println!(
            "| {} | {} | {} | {:.0} | {:.0} | {:.0} | {} | {:.0} | {:.0} | {:.0} | {:.1} | {:.1} | {} | {} |",
            r.scene,
            r.tets,
            r.mode,
            r.step_us.median,
            r.step_us.p99,
            r.whole_step_us.p99,
            r.cut_us.count,
            r.cut_us.median,
            r.cut_us.p99,
            r.awake_mean,
            r.cg_iterations_mean,
            r.cg_iterations_after_cut_mean,
            r.error.map_or("".into(), |e| format!("{:.3}", 100.0 * e)),
            r.cut_events.as_deref().unwrap_or(""),
        );
    }
    println!();
    println!("| scene | tets | state + model + mesh bytes per tet | peak after settling MB | peak with the runs MB |");
    println!("|---|---:|---:|---:|---:|");
    let mb = |b: Option<u64>| b.map_or("?".into(), |b| format!("{:.0}", b as f64 / 1e6));
    for m in &memory {
        println!("| {} | {} | {:.0} | {} | {} |", m.scene, m.tets, m.bytes_per_tet, mb(m.peak_settled_bytes), mb(m.peak_runs_bytes));
    }
    println!();
    for g in &goals {
        println!("goal, {}: {:.0} us, {}", g.goal, g.measured_us, if g.met { "met" } else { "NOT met" });
    }
    println!("wrote {} and {}", csv_path.display(), svg_path.display());
    Ok(())
}

fn session_text(stroke_s: f64, after_s: f64) -> String {
    format!(
        "1 ms steps, implicit Euler: a {:.0} mm incision in {stroke_s} s ({PRESS_N} N press, tip {:.0} mm deep, a cut every {:.1} mm), then {after_s} s; the 1 ms step p99 includes its cut",
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
    let at_100k = |mode: &str| rows.iter().find(|r| r.scene == "chest-wall" && r.requested_tets == Some(100_000) && r.mode == mode);
    let mut goals = Vec::new();
    if let Some(r) = at_100k("localised") {
        let us = r.whole_step_us.p99;
        goals.push(Goal { goal: "localised 100k, p99 of the 1 ms step with its cut < 1 ms", measured_us: us, met: us < 1e3 });
    }
    if let Some(r) = at_100k("full") {
        let us = r.step_us.p99;
        goals.push(Goal { goal: "full 100k, p99 of the step < 10 ms", measured_us: us, met: us < 1e4 });
    }
    goals
}

fn csv(rows: &[PerfRow]) -> String {
    let mut s = String::from(
        "scene,tets,tets_after,particles,mode,steps,step_median_us,step_p99_us,whole_step_median_us,whole_step_p99_us,cuts,cut_median_us,cut_p99_us,cut_max_us,unresolved_cuts,tets_split,cg_iterations_mean,cg_iterations_after_cut_mean,awake_mean,error,compared_steps,cut_events\n",
    );
    for r in rows {
        s.push_str(&format!(
            "{},{},{},{},{},{},{:.1},{:.1},{:.1},{:.1},{},{:.1},{:.1},{:.1},{},{},{:.2},{:.2},{:.1},{},{},{}\n",
            r.scene,
            r.tets,
            r.tets_after,
            r.particles,
            r.mode,
            r.steps,
            r.step_us.median,
            r.step_us.p99,
            r.whole_step_us.median,
            r.whole_step_us.p99,
            r.cut_us.count,
            r.cut_us.median,
            r.cut_us.p99,
            r.cut_us.max,
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
fn svg(rows: &[PerfRow]) -> String {
    let chest: Vec<&PerfRow> = rows.iter().filter(|r| r.scene == "chest-wall").collect();
    let series = |name: &str, colour: &'static str, line: plot::Line, mode: &str, value: fn(&PerfRow) -> f64| plot::Series {
        name: name.into(),
        colour,
        line,
        markers: true,
        points: chest
            .iter()
            .filter(|r| r.mode == mode)
            .map(|r| plot::Point { x: r.tets as f64, y: value(r), title: format!("{name}, {} tets: {:.0} us", r.tets, value(r)) })
            .collect(),
    };
    let panel = plot::Panel {
        title: "chest wall: step time, us (log), against tetrahedra (log); single thread".into(),
        x_unit: String::new(),
        y_unit: " us".into(),
        series: vec![
            series("full, median", "#1f77b4", plot::Line::Solid, "full", |r| r.step_us.median),
            series("full, p99", "#1f77b4", plot::Line::Dashed, "full", |r| r.step_us.p99),
            series("localised, median", "#d62728", plot::Line::Solid, "localised", |r| r.step_us.median),
            series("localised, p99", "#d62728", plot::Line::Dashed, "localised", |r| r.step_us.p99),
            series("localised, p99 with cut", "#ff7f0e", plot::Line::Dashed, "localised", |r| r.whole_step_us.p99),
        ],
        guides: vec![(1e3, "1 ms: 1 kHz".into()), (1e4, "10 ms".into())],
    };
    plot::log_log(720.0, 400.0, &[panel])
}
