//! The load of the timed steps, the same for both engines: the scripted press of
//! `cutlab bench step` (`src/stroke.rs`), a force of fixed magnitude spread over the free
//! surface particles within `radius_m` of a point sliding along a straight line, weights
//! `(1 - r / radius)^2`. Computed from each engine's current positions.

use cutlab_sim::model::Model;
use cutlab_sim::{Point3, Vector3};

#[derive(Debug, Clone)]
pub struct Press {
    pub start: Point3,
    pub end: Point3,
    pub duration_s: f64,
    pub force_n: f64,
    pub direction: Vector3,
    pub radius_m: f64,
    /// The free boundary vertices of the mesh the press was made for.
    surface: Vec<u32>,
}

impl Press {
    /// A press along `-z` over the free surface vertices of `model`'s mesh.
    pub fn new(model: &Model, start: Point3, end: Point3, duration_s: f64, force_n: f64) -> Self {
        let surface = model
            .mesh
            .topology()
            .boundary_vertices()
            .into_iter()
            .filter(|&v| !model.held[v as usize])
            .collect();
        Self {
            start,
            end,
            duration_s,
            force_n,
            direction: -Vector3::z(),
            radius_m: 0.004,
            surface,
        }
    }

    pub fn with_radius(mut self, radius_m: f64) -> Self {
        self.radius_m = radius_m;
        self
    }

    fn tip_at(&self, t_s: f64) -> Point3 {
        let u = (t_s / self.duration_s).clamp(0.0, 1.0);
        self.start + (self.end - self.start) * u
    }

    /// The force on each pressed vertex at time `t_s`, given the current positions
    /// (`position(v)` of vertex `v`); appended to `out` after clearing it.
    pub fn forces(
        &self,
        t_s: f64,
        position: impl Fn(u32) -> Point3,
        out: &mut Vec<(u32, Vector3)>,
    ) {
        out.clear();
        let tip = self.tip_at(t_s);
        let mut total = 0.0;
        for &v in &self.surface {
            let d = position(v) - tip;
            let r = (d - self.direction * d.dot(&self.direction)).norm();
            if r < self.radius_m && d.dot(&self.direction) > -0.01 {
                let w = (1.0 - r / self.radius_m).powi(2);
                out.push((v, Vector3::new(w, 0.0, 0.0)));
                total += w;
            }
        }
        if total <= 0.0 {
            out.clear();
            return;
        }
        for (_, f) in out.iter_mut() {
            *f = self.direction * (self.force_n * f.x / total);
        }
    }
}
