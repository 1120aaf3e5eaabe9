//! A scripted scalpel stroke for the benchmarks: the tool slides along a straight line over
//! the tissue and presses on the surface it faces. The press is a force of fixed magnitude
//! spread over the surface particles within `radius_m` of the tool (across the press
//! direction; 4 mm, or 3/4 of the median edge on a coarse mesh), with weights
//! `(1 - r / radius)^2`. Only the surface facing the tool is pressed,
//! and only the particles near the line are considered, so a step costs the same on a large
//! mesh as on a small one. Forces go through `Simulation::add_external_force`, which tells a
//! localised step which particles are loaded.

use cutlab_sim::cut::CutEvent;
use cutlab_sim::solver::Simulation;
use cutlab_sim::{Point3, Vector3};

/// Spacing of the samples of the surface along the stroke, m.
const TRACK_SPACING_M: f64 = 0.001;
/// Surface particles this much deeper than the outermost ones under the line are not pressed, m.
const LAYER_M: f64 = 0.005;

/// A straight stroke from `start` to `end` (only their position across the press direction
/// matters: the tool follows the surface) over `duration_s`, pressing with `force_newtons`
/// along `direction`.
#[derive(Debug, Clone)]
pub struct Stroke {
    pub duration_s: f64,
    pub force_newtons: f64,
    direction: Vector3,
    radius_m: f64,
    /// The surface under the line at the start, sampled every `TRACK_SPACING_M`.
    track: Vec<Point3>,
    /// Free surface particles facing the tool within the radius of the line, ascending.
    surface: Vec<u32>,
    weights: Vec<(u32, f64)>,
}

impl Stroke {
    /// A stroke over the free surface of `sim`'s mesh as it is now (e.g. settled).
    pub fn new(
        sim: &Simulation,
        start: Point3,
        end: Point3,
        direction: Vector3,
        duration_s: f64,
        force_newtons: f64,
    ) -> Self {
        let direction = direction.normalize();
        // 4 mm, or more on a coarse mesh, so that the tool always has particles under it
        let median_edge = sim.model.median_edge_length().unwrap_or(0.0);
        let radius_m = (0.75 * median_edge).max(0.004);
        let across = |d: Vector3| d - direction * d.dot(&direction);
        let x = &sim.state.positions;
        // outward normals of the boundary vertices (area-weighted), from the current positions
        let mut normal = vec![Vector3::zeros(); x.len()];
        for tri in &sim.model.mesh.topology().boundary {
            let [a, b, c] = tri.map(|v| x[v as usize]);
            let n = (b - a).cross(&(c - a));
            for v in tri {
                normal[*v as usize] += n;
            }
        }
        let line = across(end - start);
        // where along the line a point lies (0 to 1), and how far across from it
        let along = |p: &Point3| {
            if line.norm_squared() > 0.0 {
                (across(p - start).dot(&line) / line.norm_squared()).clamp(0.0, 1.0)
            } else {
                0.0
            }
        };
        let near_line = |p: &Point3| (across(p - start) - line * along(p)).norm();
        let reach = radius_m + TRACK_SPACING_M;
        let facing: Vec<u32> = (0..x.len() as u32)
            .filter(|&v| {
                let n = normal[v as usize];
                !sim.model.held[v as usize]
                    && n.norm() > 0.0
                    && -n.normalize().dot(&direction) > 0.5
                    && near_line(&x[v as usize]) < reach
            })
            .collect();
        // the surface under the line: at each sample, the outermost facing particles around
        // (within `LAYER_M` of the outermost; deeper ones face the tool from behind the tissue,
        // e.g. across a body cavity), their heights weighted (1 - r / reach)^2
        let samples = ((end - start).norm() / TRACK_SPACING_M).ceil().max(1.0) as usize;
        let track: Vec<Point3> = (0..=samples)
            .map(|i| {
                let p = start + (end - start) * (i as f64 / samples as f64);
                let around: Vec<(f64, f64)> = facing
                    .iter()
                    .map(|&v| x[v as usize] - p)
                    .map(|d| (across(d).norm(), d.dot(&direction)))
                    .filter(|(r, _)| *r < reach)
                    .collect();
                let outermost = around.iter().map(|a| a.1).fold(f64::INFINITY, f64::min);
                let (mut sum, mut total) = (0.0, 0.0);
                for &(r, h) in around.iter().filter(|a| a.1 < outermost + LAYER_M) {
                    let w = (1.0 - r / reach).powi(2);
                    sum += w * h;
                    total += w;
                }
                p + direction * if total > 0.0 { sum / total } else { 0.0 }
            })
            .collect();
        let mut stroke = Self {
            duration_s,
            force_newtons,
            direction,
            radius_m,
            track,
            surface: Vec::new(),
            weights: Vec::new(),
        };
        // the particles pressed: the facing ones near the surface under the line
        stroke.surface = facing
            .into_iter()
            .filter(|&v| {
                let p = x[v as usize];
                let under = stroke.tip_at(along(&p) * duration_s);
                (p - under).dot(&direction).abs() < LAYER_M
            })
            .collect();
        stroke
    }

    /// The unit press direction (into the tissue).
    pub fn direction(&self) -> Vector3 {
        self.direction
    }

    /// Free surface particles the stroke may press.
    pub fn surface_count(&self) -> usize {
        self.surface.len()
    }

    /// The surface point under the tool at time `t_s` after the stroke began (clamped to the
    /// stroke), on the surface as it was when the stroke was made.
    pub fn tip_at(&self, t_s: f64) -> Point3 {
        let u = (t_s / self.duration_s).clamp(0.0, 1.0) * (self.track.len() - 1) as f64;
        let i = (u.floor() as usize).min(self.track.len().saturating_sub(2));
        match self.track.get(i + 1) {
            Some(next) => self.track[i] + (next - self.track[i]) * (u - i as f64),
            None => self.track[i],
        }
    }

    /// Sets the external forces of `sim` for time `t_s`; returns the surface point under the
    /// tool as it is now (the pressed particles' mean height, weighted as the force; the
    /// stroke's track where none are pressed).
    pub fn apply(&mut self, sim: &mut Simulation, t_s: f64) -> Point3 {
        sim.clear_external_forces();
        let tip = self.tip_at(t_s);
        if t_s > self.duration_s {
            return tip;
        }
        self.weights.clear();
        let (mut total, mut height) = (0.0, 0.0);
        for &v in &self.surface {
            let d = sim.state.positions[v as usize] - tip;
            let r = (d - self.direction * d.dot(&self.direction)).norm();
            if r < self.radius_m {
                let w = (1.0 - r / self.radius_m).powi(2);
                self.weights.push((v, w));
                total += w;
                height += w * d.dot(&self.direction);
            }
        }
        if total == 0.0 {
            return tip;
        }
        for &(v, w) in &self.weights {
            sim.add_external_force(v, self.direction * (self.force_newtons * w / total));
        }
        tip + self.direction * (height / total)
    }

    /// Follows a cut: the copies of split surface particles are pressed like their originals.
    pub fn cut(&mut self, event: &CutEvent) {
        let copies: Vec<u32> = event
            .vertices_split
            .iter()
            .filter(|s| self.surface.binary_search(&s.original).is_ok())
            .map(|s| s.copy)
            .collect();
        if !copies.is_empty() {
            self.surface.extend(copies);
            self.surface.sort_unstable();
            self.surface.dedup();
        }
    }
}
