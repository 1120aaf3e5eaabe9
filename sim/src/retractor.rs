//! A wound retractor: two blades set into an incision that spread its edges to a chosen
//! width, as a surgeon opens a mini-thoracotomy to see through it (issue 62).
//!
//! The incision is a line on the skin (`line_m`, the polyline the blade was drawn along) with
//! the blade along `up`. At arc length `s` of the line (length `L`) the retractor holds the
//! wound's edges `w(s)` apart,
//!
//! `w(s) = W sqrt(1 - u^2)`, `u = 2 s / L - 1`,
//!
//! an ellipse as a ring retractor makes of a straight wound: the full width `W` at the middle,
//! nothing at the ends, where the tissue is uncut. It grips the wound's faces: the particles
//! of the boundary triangles that stand across the skin (the cut's faces) within
//! [`FACE_BAND_M`] of the line's vertical plane, each on the side its face looks away from.
//! Each is carried, held, from where it is to `±w(s)/2` from the plane along the side vector
//! `up x along` (never inwards), over the ramp's steps. Tissue a scalpel does not cut (bone,
//! cartilage) is not spread: a face particle is carried no nearer than [`BONE_CLEARANCE_M`] to
//! an uncuttable particle beside it at its depth, so an intercostal incision opens to the ribs
//! and no further (a rib spreader, which moves the bones, is not modelled).

use crate::solver::{Simulation, StepError};
use crate::{Point3, Vector3};

/// How far from the incision's plane a wound's face may lie and be gripped, m: a hand's
/// cut wanders about its line.
pub const FACE_BAND_M: f64 = 0.004;

/// How long the retractor takes to open, s.
pub const RAMP_S: f64 = 0.3;
/// How long the opened retractor holds before the wound is looked at, s.
pub const HOLD_S: f64 = 0.2;

/// How near a spread face particle comes to bone beside it, m.
pub const BONE_CLEARANCE_M: f64 = 0.001;

/// A retractor set into one incision.
#[derive(Debug, Clone, PartialEq)]
pub struct Retractor {
    /// The incision's line on the skin (m), at least two points.
    pub line_m: Vec<Point3>,
    /// The way out of the body (unit): the blade stood along it.
    pub up: Vector3,
    /// The width the retractor opens the wound's middle to, m.
    pub width_m: f64,
}

/// The particles a [`Retractor`] holds and where it carries them.
#[derive(Debug, Clone, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Grip {
    /// Held particles.
    pub vertices: Vec<u32>,
    /// Where each was when gripped (m).
    pub from_m: Vec<Point3>,
    /// Where the open retractor holds each (m).
    pub to_m: Vec<Point3>,
}

/// Where a rest point lies against the line: arc length `s`, offset along the side vector,
/// the side vector and the point of the line it is measured from.
struct Station {
    s_m: f64,
    offset_m: f64,
    side: Vector3,
    foot: Point3,
}

impl Retractor {
    /// The line's length, m.
    pub fn length_m(&self) -> f64 {
        self.line_m.windows(2).map(|w| (w[1] - w[0]).norm()).sum()
    }

    /// `p` against the nearest segment of the line, seen along `up`; `None` when it lies
    /// beyond the line's ends.
    fn station(&self, p: &Point3) -> Option<Station> {
        let flat = |v: Vector3| v - self.up * self.up.dot(&v);
        let mut best: Option<(f64, Station)> = None;
        let mut s0 = 0.0;
        for w in self.line_m.windows(2) {
            let seg = flat(w[1] - w[0]);
            let len = seg.norm();
            if len < 1e-9 {
                continue;
            }
            let along = seg / len;
            let t = along.dot(&flat(p - w[0]));
            if (0.0..=len).contains(&t) {
                let side = self.up.cross(&along);
                let foot = w[0] + along * t;
                let offset_m = side.dot(&flat(p - w[0]));
                if best.as_ref().is_none_or(|(d, _)| offset_m.abs() < *d) {
                    let s_m = s0 + t;
                    best = Some((
                        offset_m.abs(),
                        Station {
                            s_m,
                            offset_m,
                            side,
                            foot,
                        },
                    ));
                }
            }
            s0 += len;
        }
        best.map(|(_, st)| st)
    }

    /// The half-width the retractor holds at arc length `s_m`.
    fn half_width_m(&self, s_m: f64) -> f64 {
        let u = 2.0 * s_m / self.length_m() - 1.0;
        0.5 * self.width_m * (1.0 - u * u).max(0.0).sqrt()
    }

    /// Grips the wound's faces in `sim`'s current mesh and state (not the particles already
    /// held: clips, the other hand's jaws).
    pub fn grip(&self, sim: &Simulation) -> Grip {
        let model = &sim.model;
        let rest = model.mesh.positions();
        let edge = model.median_edge_length().unwrap_or(0.005);
        let faces = self.face_normals(sim);
        let mut on_bone = vec![false; rest.len()];
        for (t, tet) in model.mesh.tets().iter().enumerate() {
            if model.uncuttable(t) {
                tet.iter().for_each(|&v| on_bone[v as usize] = true);
            }
        }
        let bone: Vec<Point3> = (0..rest.len())
            .filter(|&v| on_bone[v])
            .map(|v| rest[v])
            .collect();
        let mut grip = Grip::default();
        for (v, p) in rest.iter().enumerate() {
            let normal = faces[v];
            if on_bone[v] || model.held[v] || normal == Vector3::zeros() {
                continue;
            }
            let Some(st) = self.station(p).filter(|st| st.offset_m.abs() < FACE_BAND_M) else {
                continue;
            };
            // a face looks into the wound: towards the other side
            let looks = st.side.dot(&normal.normalize());
            if looks.abs() < 0.5 {
                continue;
            }
            let sign = -looks.signum();
            let mut half = self.half_width_m(st.s_m);
            for b in &bone {
                let d = b - p;
                let beside = (b - st.foot).dot(&st.side) * sign;
                if beside > 0.0 && (d - st.side * d.dot(&st.side)).norm() < edge {
                    half = half.min(beside - BONE_CLEARANCE_M);
                }
            }
            let now = sim.state.positions[v];
            let out = st.side.dot(&(now - st.foot)) * sign;
            if half > out {
                grip.vertices.push(v as u32);
                grip.from_m.push(now);
                grip.to_m.push(now + st.side * (sign * (half - out)));
            }
        }
        grip
    }

    /// Per particle, the area-weighted outward normal (at rest) of the boundary triangles
    /// round it that stand across the skin (`|n . up| < 0.7`): the wound's faces, and the
    /// body's own sides far from any incision; zero for the others.
    fn face_normals(&self, sim: &Simulation) -> Vec<Vector3> {
        let rest = sim.model.mesh.positions();
        let mut normals = vec![Vector3::zeros(); rest.len()];
        for tri in &sim.model.mesh.topology().boundary {
            let [a, b, c] = tri.map(|v| rest[v as usize]);
            let n = (b - a).cross(&(c - a));
            let area = n.norm();
            if area > 0.0 && (n / area).dot(&self.up).abs() < 0.7 {
                tri.iter().for_each(|&v| normals[v as usize] += n);
            }
        }
        normals
    }

    /// Grips the wound, opens the retractor over [`RAMP_S`] (the gripped particles held and
    /// carried linearly, step by step) and keeps it open for [`HOLD_S`] more. The particles
    /// stay held. Returns the grip.
    pub fn open(&self, sim: &mut Simulation) -> Result<Grip, StepError> {
        let hold_steps = (HOLD_S / sim.settings.time_step_s).round() as usize;
        let mut opening = self.set(sim);
        for _ in 0..opening.ramp_steps {
            opening.carry(sim);
            sim.step()?;
        }
        for _ in 0..hold_steps {
            sim.step()?;
        }
        Ok(opening.grip)
    }

    /// Sets the retractor into a running simulation: grips the wound ([`Self::grip`]) and
    /// holds what it gripped where it is. The
    /// [`Opening`] then carries them open over [`RAMP_S`] of the simulation's steps, one
    /// [`Opening::carry`] before each step, and holds them until [`Opening::release`].
    pub fn set(&self, sim: &mut Simulation) -> Opening {
        let grip = self.grip(sim);
        sim.hold(&grip.vertices);
        sim.wake(grip.vertices.iter().copied());
        let ramp_steps = ((RAMP_S / sim.settings.time_step_s).round() as u32).max(1);
        Opening {
            grip,
            steps: 0,
            ramp_steps,
        }
    }
}

/// A [`Retractor`] set into a running simulation ([`Retractor::set`]): what it grips and how
/// far it has opened.
#[derive(Debug, Clone, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Opening {
    /// The particles held and where the open retractor holds them.
    pub grip: Grip,
    /// The steps carried so far.
    pub steps: u32,
    /// The steps the opening takes ([`RAMP_S`]).
    pub ramp_steps: u32,
}

impl Opening {
    /// Before a step: carries the gripped particles on along the ramp, linearly from where
    /// they were gripped to where the open retractor holds them (at rest once open).
    pub fn carry(&mut self, sim: &mut Simulation) {
        if self.steps >= self.ramp_steps {
            return;
        }
        self.steps += 1;
        let f = f64::from(self.steps) / f64::from(self.ramp_steps);
        let g = &self.grip;
        for (i, &v) in g.vertices.iter().enumerate() {
            if let Some(p) = sim.state.positions.get_mut(v as usize) {
                *p = g.from_m[i] + (g.to_m[i] - g.from_m[i]) * f;
                sim.state.velocities[v as usize] = Vector3::zeros();
            }
        }
    }

    /// Takes the retractor out: the gripped particles are free again, with their masses.
    pub fn release(self, sim: &mut Simulation) {
        sim.let_go(&self.grip.vertices);
    }

    /// Whether its particles are in a mesh of `vertex_count` and its numbers finite.
    pub fn fits(&self, vertex_count: usize) -> bool {
        let g = &self.grip;
        g.vertices.len() == g.from_m.len()
            && g.vertices.len() == g.to_m.len()
            && g.vertices.iter().all(|&v| (v as usize) < vertex_count)
            && g.from_m
                .iter()
                .chain(&g.to_m)
                .all(|p| p.iter().all(|c| c.is_finite()))
    }
}
