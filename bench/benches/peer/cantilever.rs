//! The cantilever of `cutlab_sim::reference::cantilever`, spelled out so that Rapier runs the
//! same load case: the bar clamped at its `x = min` face, the tip load `P` spread over the
//! `x = max` face by area along the larger cross dimension, `P` such that Timoshenko's
//! deflection `P L^3 / (3 E I) + P L / (kappa G A)` (`kappa = 5/6`) is 1e-3 of the length.

use cutlab_sim::reference::Solid;
use cutlab_sim::{Point3, TetMesh};

use crate::cases::end_face;

#[derive(Debug, Clone)]
pub struct CantileverLoad {
    pub clamped: Vec<u32>,
    /// `(vertex, force along the load axis, N)` on the tip face.
    pub tip: Vec<(u32, f64)>,
    /// 1 (y) or 2 (z).
    pub axis: usize,
    pub analytic_m: f64,
    /// Angular frequency of the first bending mode (Euler-Bernoulli), rad/s.
    pub first_mode_rad_per_s: f64,
}

impl CantileverLoad {
    pub fn new(mesh: &TetMesh, solid: Solid) -> Self {
        let (lo, hi) = mesh.bounding_box();
        let ext = hi - lo;
        let length = ext.x;
        let (axis, h, b) = if ext.z >= ext.y {
            (2, ext.z, ext.y)
        } else {
            (1, ext.y, ext.z)
        };
        let tol = 1e-6 * length;
        let pos = mesh.positions();
        let mut weight = vec![0.0; pos.len()];
        for tri in &mesh.topology().boundary {
            if tri.iter().all(|&v| pos[v as usize].x > hi.x - tol) {
                let [a, bb, c] = tri.map(|v| pos[v as usize]);
                let area = 0.5 * (bb - a).cross(&(c - a)).norm();
                tri.iter().for_each(|&v| weight[v as usize] += area / 3.0);
            }
        }
        let area: f64 = weight.iter().sum();
        let e = solid.youngs_modulus_pa;
        let g = e / (2.0 * (1.0 + solid.poisson_ratio));
        let inertia = b * h.powi(3) / 12.0;
        let unit = length.powi(3) / (3.0 * e * inertia) + length / (5.0 / 6.0 * g * b * h);
        let load = 1e-3 * length / unit;
        let tip = (0..pos.len() as u32)
            .filter(|&i| weight[i as usize] > 0.0)
            .map(|i| (i, load * weight[i as usize] / area))
            .collect();
        let first_mode = 1.875f64.powi(2)
            * (e * inertia / (solid.density_kg_per_m3 * b * h * length.powi(4))).sqrt();
        Self {
            clamped: end_face(mesh, lo.x),
            tip,
            axis,
            analytic_m: load * unit,
            first_mode_rad_per_s: first_mode,
        }
    }

    /// Mean displacement of the tip face along the load, m, from the current positions.
    pub fn deflection_m(&self, rest: &TetMesh, current: impl Fn(u32) -> Point3) -> f64 {
        let sum: f64 = self
            .tip
            .iter()
            .map(|&(v, _)| current(v)[self.axis] - rest.positions()[v as usize][self.axis])
            .sum();
        sum / self.tip.len().max(1) as f64
    }

    pub fn relative_error(&self, deflection_m: f64) -> f64 {
        (deflection_m - self.analytic_m).abs() / self.analytic_m
    }
}
