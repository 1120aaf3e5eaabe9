//! A grasper's jaws closed on tissue (issue 66): the second hand, which holds, lifts and pulls
//! while the other cuts.
//!
//! Closing the jaws at the pose `world_from_jaw` takes hold of every free particle within
//! `jaw_radius_m` of the jaws' centre (the bite: through a thin sheet's whole thickness, a fold
//! of a thick one's surface). Each held particle keeps its place in the jaws' frame,
//!
//! `x_i = world_from_jaw * p_i`, `p_i = jaw_from_world(closing) * x_i(closing)`,
//!
//! and is moved there, held (infinite mass to the integrators), whenever the jaws move
//! ([`Grasp::carry`]); its velocity is the jaws' displacement over the step, so the dampers
//! between held and free particles see the pull's rate.
//!
//! The tissue pulls on the jaws with the total force on the held particles,
//!
//! `f_pull = sum_{i held} (f_int,i + m_i g)`,
//!
//! the force the springs (or elements) and dampers joining them to the tissue, and gravity on
//! them, exert: what the grasper's hand feels. It is the reaction of the held tissue: with
//! the tissue at rest, the pull on the jaws and on every other held particle (a sheet's rim)
//! sum to the tissue's weight, as Newton's third law demands. Past `slip_force_newtons` the
//! tissue slips out of the jaws ([`Grasp::slips`]); opening them lets go ([`Grasp::release`]):
//! the particles are free again with their masses and relax under the tissue's forces.

use nalgebra::Isometry3;

use crate::cut::MadeFrom;
use crate::solver::Simulation;
use crate::{Point3, Vector3};

/// How a grasper takes hold.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct GraspSettings {
    /// Free particles within this distance of the jaws' centre are held, m.
    pub jaw_radius_m: f64,
    /// A pull on the jaws stronger than this makes the tissue slip out of them, N.
    pub slip_force_newtons: f64,
}

impl Default for GraspSettings {
    /// Jaws of a 5 mm laparoscopic grasper (a bite of 3 mm radius); the tissue slips past 4 N.
    fn default() -> Self {
        Self {
            jaw_radius_m: 0.003,
            slip_force_newtons: 4.0,
        }
    }
}

/// Why the jaws took nothing.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum GraspError {
    /// The jaws' pose or the settings are not finite, or the radius is not positive.
    #[error("the jaws' pose and radius must be finite and the radius positive")]
    Invalid,
    /// No free particle lies within the jaws.
    #[error("nothing within {radius_mm:.1} mm of the jaws")]
    NothingInJaws {
        /// The jaws' radius, mm.
        radius_mm: f64,
    },
}

/// Tissue held in closed jaws.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Grasp {
    /// The held particles, ascending.
    vertices: Vec<u32>,
    /// Each held particle in the jaws' frame, m.
    in_jaw_m: Vec<Point3>,
    /// Where the jaws are now.
    world_from_jaw: Isometry3<f64>,
    settings: GraspSettings,
}

impl Grasp {
    /// Closes the jaws at `world_from_jaw` on `sim`'s tissue: every free particle within
    /// the jaws' radius is held where it is.
    pub fn close(
        sim: &mut Simulation,
        world_from_jaw: Isometry3<f64>,
        settings: GraspSettings,
    ) -> Result<Self, GraspError> {
        let r = settings.jaw_radius_m;
        if !(isometry_is_finite(&world_from_jaw) && r.is_finite() && r > 0.0) {
            return Err(GraspError::Invalid);
        }
        let centre = Point3::from(world_from_jaw.translation.vector);
        let vertices: Vec<u32> = (0..sim.model.vertex_count() as u32)
            .filter(|&v| {
                !sim.model.held[v as usize]
                    && (sim.state.positions[v as usize] - centre).norm() <= r
            })
            .collect();
        if vertices.is_empty() {
            return Err(GraspError::NothingInJaws { radius_mm: r * 1e3 });
        }
        let jaw_from_world = world_from_jaw.inverse();
        let in_jaw_m = vertices
            .iter()
            .map(|&v| jaw_from_world * sim.state.positions[v as usize])
            .collect();
        sim.hold(&vertices);
        sim.wake(vertices.iter().copied());
        Ok(Self {
            vertices,
            in_jaw_m,
            world_from_jaw,
            settings,
        })
    }

    /// Whether the grasp fits a mesh of `vertex_count` particles with every number finite
    /// (a grasp read back from a recording's keyframe).
    pub fn fits(&self, vertex_count: usize) -> bool {
        self.vertices.len() == self.in_jaw_m.len()
            && self.vertices.iter().all(|&v| (v as usize) < vertex_count)
            && self
                .in_jaw_m
                .iter()
                .all(|p| p.iter().all(|c| c.is_finite()))
            && isometry_is_finite(&self.world_from_jaw)
    }

    /// Takes into the jaws what a cut (`event`) made of the tissue in them: the copies it
    /// split off held particles (a copy stands where its original stood, so it keeps the
    /// original's place in the jaws) and the particles it created on edges between two held
    /// ones (at their place between the two). The jaws carry, feel and let go of both sides
    /// of a cut through their bite (a copy left out stayed held where the cut made it, for
    /// good), and a piece taken whole stays whole in them.
    pub fn adopt_cut(&mut self, sim: &mut Simulation, event: &crate::cut::CutEvent) {
        let made = event.made_from(&self.vertices);
        if made.is_empty() {
            return;
        }
        let mut held: std::collections::BTreeMap<u32, Point3> = self
            .vertices
            .iter()
            .copied()
            .zip(self.in_jaw_m.iter().copied())
            .collect();
        let mut created = Vec::new();
        for (v, from) in made {
            let in_jaw = match from {
                MadeFrom::Between { a, b, t } => {
                    created.push(v);
                    held[&a] + (held[&b] - held[&a]) * t
                }
                MadeFrom::CopyOf(original) => held[&original],
            };
            held.insert(v, in_jaw);
        }
        sim.hold(&created);
        (self.vertices, self.in_jaw_m) = held.into_iter().unzip();
    }

    /// Takes hold of `vertices` too, where they are (a piece a cut freed in the jaws: the
    /// jaws carry it whole from then on, and a later cut does not free it again). Particles
    /// held already, by the jaws or the scene, and ids past the mesh are left as they are.
    pub fn take_hold_of(&mut self, sim: &mut Simulation, vertices: &[u32]) {
        let jaw_from_world = self.world_from_jaw.inverse();
        let new: Vec<u32> = vertices
            .iter()
            .copied()
            .filter(|&v| {
                (v as usize) < sim.model.vertex_count()
                    && !sim.model.held[v as usize]
                    && self.vertices.binary_search(&v).is_err()
            })
            .collect();
        if new.is_empty() {
            return;
        }
        sim.hold(&new);
        let held: std::collections::BTreeMap<u32, Point3> = self
            .vertices
            .iter()
            .copied()
            .zip(self.in_jaw_m.iter().copied())
            .chain(
                new.iter()
                    .map(|&v| (v, jaw_from_world * sim.state.positions[v as usize])),
            )
            .collect();
        (self.vertices, self.in_jaw_m) = held.into_iter().unzip();
    }

    /// The held particles, ascending.
    pub fn vertices(&self) -> &[u32] {
        &self.vertices
    }

    /// Where the jaws are, as last carried.
    pub fn world_from_jaw(&self) -> &Isometry3<f64> {
        &self.world_from_jaw
    }

    /// Moves the jaws to `world_from_jaw`, carrying the held tissue with them: each held
    /// particle to its place in the jaws, its velocity the displacement over one step. A
    /// non-finite pose is ignored (the jaws stay where they were) and `false` returned.
    pub fn carry(&mut self, sim: &mut Simulation, world_from_jaw: Isometry3<f64>) -> bool {
        if !isometry_is_finite(&world_from_jaw) {
            return false;
        }
        let dt = sim.settings.time_step_s;
        for (&v, p) in self.vertices.iter().zip(&self.in_jaw_m) {
            let v = v as usize;
            if v >= sim.model.vertex_count() {
                continue;
            }
            let to = world_from_jaw * p;
            sim.state.velocities[v] = (to - sim.state.positions[v]) / dt;
            sim.state.positions[v] = to;
        }
        self.world_from_jaw = world_from_jaw;
        sim.wake(self.vertices.iter().copied());
        true
    }

    /// The tissue's pull on the jaws, N: the total force on the held particles (see the
    /// module's documentation).
    pub fn pull_newtons(&self, sim: &Simulation) -> Vector3 {
        let forces = sim.particle_forces();
        self.vertices
            .iter()
            .filter_map(|&v| forces.get(v as usize))
            .sum()
    }

    /// Whether a pull of `pull_newtons` pulls the tissue out of the jaws.
    pub fn slips(&self, pull_newtons: &Vector3) -> bool {
        pull_newtons.norm() > self.settings.slip_force_newtons
    }

    /// Opens the jaws: the held particles are free again, with their masses and the
    /// velocities they were carried at.
    pub fn release(self, sim: &mut Simulation) {
        sim.let_go(&self.vertices);
    }
}

/// Whether every number of `pose` is finite.
fn isometry_is_finite(pose: &Isometry3<f64>) -> bool {
    pose.translation.vector.iter().all(|c| c.is_finite())
        && pose.rotation.coords.iter().all(|c| c.is_finite())
}
