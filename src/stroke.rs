//! A scripted scalpel stroke for the demo and the benchmarks: the tip slides along a straight
//! line over the tissue surface and presses on it. The press is a force of fixed magnitude
//! spread over the free surface particles within `radius_m` of the tip's track point, with
//! weights `(1 - r / radius)^2`. (Collision and cutting arrive with the haptics and cutting
//! issues; this is a deterministic load that exercises the solver like a tool does.)

use cutlab_sim::solver::Simulation;
use cutlab_sim::{Point3, Vector3};

/// A straight stroke from `start` to `end` over `duration_s`, pressing with `force_newtons`
/// along `direction`.
#[derive(Debug, Clone)]
pub struct Stroke {
    pub start: Point3,
    pub end: Point3,
    pub duration_s: f64,
    pub force_newtons: f64,
    pub direction: Vector3,
    pub radius_m: f64,
    surface: Vec<u32>,
    weights: Vec<(u32, f64)>,
}

impl Stroke {
    /// A stroke over the surface vertices of `sim`'s mesh.
    pub fn new(sim: &Simulation, start: Point3, end: Point3, duration_s: f64, force_newtons: f64) -> Self {
        let surface = sim
            .model
            .mesh
            .topology()
            .boundary_vertices()
            .into_iter()
            .filter(|&v| !sim.model.held[v as usize])
            .collect();
        Self {
            start,
            end,
            duration_s,
            force_newtons,
            direction: -Vector3::z(),
            radius_m: 0.004,
            surface,
            weights: Vec::new(),
        }
    }

    /// The tip position at time `t_s` after the stroke began (clamped to the stroke).
    pub fn tip_at(&self, t_s: f64) -> Point3 {
        let u = (t_s / self.duration_s).clamp(0.0, 1.0);
        self.start + (self.end - self.start) * u
    }

    /// Sets the external forces of `sim` for time `t_s`; returns the pressed particles' count.
    pub fn apply(&mut self, sim: &mut Simulation, t_s: f64) -> usize {
        let tip = self.tip_at(t_s);
        self.weights.clear();
        let mut total = 0.0;
        for &v in &self.surface {
            let p = sim.state.positions[v as usize];
            // distance in the plane across the press direction
            let d = p - tip;
            let r = (d - self.direction * d.dot(&self.direction)).norm();
            if r < self.radius_m && d.dot(&self.direction) > -0.01 {
                let w = (1.0 - r / self.radius_m).powi(2);
                self.weights.push((v, w));
                total += w;
            }
        }
        sim.clear_external_forces();
        let pressing = t_s <= self.duration_s;
        if pressing && total > 0.0 {
            let f = sim.external_forces_mut();
            for &(v, w) in &self.weights {
                f[v as usize] = self.direction * (self.force_newtons * w / total);
            }
        }
        if pressing { self.weights.len() } else { 0 }
    }
}
