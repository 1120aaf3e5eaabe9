//! The simulation side of a session, one step per servo sample: apply the tool's reaction,
//! cut while the blade is in the tissue, advance the simulation, refit the surface and build
//! the contact model for the servo loop.
//!
//! A live session drives a [`SessionStepper`] from its simulation thread; a replay drives
//! the same stepper from the recorded samples, so a replay runs exactly the code of the
//! session it checks.

use cutlab_sim::TetMesh;
use cutlab_sim::cut::{self, Blade, CutError, CutEvent, Cutter, CutterResume};
use cutlab_sim::grasp::{Grasp, GraspSettings};
use cutlab_sim::hash::Fnv1a;
use cutlab_sim::model::State;
use cutlab_sim::solver::{ResumeState, Simulation};

use crate::collision::{SurfaceCollider, SurfaceHit};
use crate::damage::{DamageWatch, TissueDamage};
use crate::pose::BUTTON_RETRACT;
use crate::render::{ContactModel, Mode, WOUND_REACH_M, Wound};
use crate::retraction::WoundRetraction;
use crate::servo::ServoSample;
use crate::session::{Session, SessionConfig};
use crate::{HapticsError, Point3, Vector3};

/// What the stepper counted.
#[derive(Debug, Clone, Copy, PartialEq, Default, serde::Serialize, serde::Deserialize)]
pub struct StepperStats {
    /// Steps whose cut changed the tissue.
    pub cut_steps: u64,
    /// Length of the blade tip's path while it cut (sampled every `cut_step_m`), m.
    pub cut_length_m: f64,
    /// Tetrahedra the cuts split.
    pub tets_split: u64,
    /// Cuts skipped as unresolved (the next step tries again).
    pub unresolved_cuts: u64,
    /// Cuts that failed.
    pub failed_cuts: u64,
    /// Steps the simulation rejected (non-finite state).
    pub rejected_steps: u64,
    /// Conjugate-gradient iterations of the implicit solver over all steps.
    pub cg_iterations: u64,
    /// Small free pieces the cuts left attached (see `cutlab_sim::cut::CutOptions`).
    #[serde(default)]
    pub fragments_reattached: u64,
    /// Pieces the cuts freed, lifted out of the wound (`cutlab_sim::cut::Specimen`).
    #[serde(default)]
    pub specimens: u64,
    /// Steps whose blade stopped on tissue a scalpel does not cut (a rib, a cartilage:
    /// `cutlab_sim::cut::Cutter::stop`).
    #[serde(default)]
    pub blade_stops: u64,
    /// Closures of the grasper's jaws that took hold of tissue.
    #[serde(default)]
    pub grasps: u64,
    /// Times the held tissue slipped out of the jaws, pulled past their hold.
    #[serde(default)]
    pub grasp_slips: u64,
    /// The strongest pull of held tissue on the jaws, N.
    #[serde(default)]
    pub max_grasp_pull_newtons: f64,
    /// Steps the jaws held tissue.
    #[serde(default)]
    pub grasp_steps: u64,
    /// Times the trainee set the wound retractor.
    #[serde(default)]
    pub retractions: u64,
}

/// What one step did.
#[derive(Debug, Clone, PartialEq)]
pub struct StepOutput {
    /// The contact model around the proxy, for the servo loop.
    pub contact: ContactModel,
    /// The cut this step made: the blade and every topology change.
    pub cut: Option<(Blade, CutEvent)>,
    /// The simulation rejected the step (non-finite state; the state was kept).
    pub rejected: bool,
    /// The harm this step did (the blade on bone, a structure to spare cut).
    pub damage: Vec<TissueDamage>,
}

/// The simulation, its surface collider and the cutter, stepped one servo sample at a time.
#[derive(Debug)]
pub struct SessionStepper {
    /// The simulation.
    pub sim: Simulation,
    /// The tissue surface's collider, refitted after each step.
    pub collider: SurfaceCollider,
    cutter: Cutter,
    blade_length_m: f64,
    reach_m: f64,
    patch_radius_m: f64,
    cut_step_m: f64,
    patch: Vec<(u32, f64)>,
    last_hit: Option<SurfaceHit>,
    /// Where the blade went in, while it cuts (the contact the renderer started the cut on).
    cut_entry: Option<SurfaceHit>,
    last_cut_tip: Option<Point3>,
    /// The last cut that ended: where its tip last cut and where it went in
    /// ([`crate::render::ContactModel::wound`]).
    wound: Option<(Point3, SurfaceHit)>,
    /// What the steps did so far.
    pub stats: StepperStats,
    /// Steps taken.
    steps: u64,
    /// The surface's BVH is built again every this many steps (0: only after cuts): a
    /// refitted tree's shape depends on the whole past of the surface, a freshly built one
    /// only on the surface now, so the state at such a step determines the steps after it
    /// whatever the tree decides ([`Self::resume_state`]; which of two equally close triangles
    /// a closest-point query returns can follow the tree). A guarantee rather than a measured
    /// need: resuming the 30 s test session matched with refitted trees too. It also keeps the
    /// tree tight under large deformations.
    rebuild_every_steps: u64,
    /// The last step built the BVH again (rather than refitting it).
    collider_fresh: bool,
    /// What reports each harm once.
    damage: DamageWatch,
    /// What the grasper's jaws hold.
    grasp: Option<Grasp>,
    /// The grasper's jaws were closed at the last step (closed jaws take hold only as they
    /// close).
    jaws_closed: bool,
    grasp_settings: GraspSettings,
    /// The wound retractor the trainee sets.
    retraction: WoundRetraction,
}

/// What a [`SessionStepper`] carries from one step to the next beyond the simulation's state
/// and mesh: with them, [`SessionStepper::resume`] continues bit for bit (see
/// [`SessionStepper::resume_state`]).
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct StepperResume {
    /// Steps taken.
    pub steps: u64,
    /// The simulation's resume state.
    pub sim: ResumeState,
    /// The cutter's stroke.
    pub cutter: CutterResume,
    /// Where the tool touched after the last step (the next step presses there).
    pub last_hit: Option<SurfaceHit>,
    /// Where the blade went in, while it cuts (absent in recordings made before it was kept).
    #[serde(default)]
    pub cut_entry: Option<SurfaceHit>,
    /// Where the blade's tip last cut in this stroke.
    pub last_cut_tip: Option<Point3>,
    /// The last cut that ended: where its tip last cut and where it went in (absent in
    /// recordings made before it was kept).
    #[serde(default)]
    pub wound: Option<(Point3, SurfaceHit)>,
    /// What the steps did so far.
    pub stats: StepperStats,
    /// What reports each harm once (absent in recordings made before it was kept, and
    /// where nothing was harmed).
    #[serde(default, skip_serializing_if = "DamageWatch::is_clear")]
    pub damage: DamageWatch,
    /// What the grasper's jaws hold (absent where nothing is held).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub grasp: Option<Grasp>,
    /// The grasper's jaws were closed.
    #[serde(default, skip_serializing_if = "std::ops::Not::not")]
    pub jaws_closed: bool,
    /// The wound retractor: the incision so far and the opening while set (absent in
    /// recordings made before it was kept).
    #[serde(default)]
    pub retraction: WoundRetraction,
}

impl SessionStepper {
    /// Takes the settled simulation and collider of `session`, with the blade, contact and
    /// cutting settings of `config`.
    pub fn new(session: Session, config: &SessionConfig) -> Self {
        let (sim, collider) = session.into_parts();
        Self {
            sim,
            collider,
            cutter: Cutter::default(),
            blade_length_m: config.blade_length_m,
            reach_m: config.contact_reach_m,
            patch_radius_m: config.contact_patch_radius_m,
            cut_step_m: config.cut_step_m,
            patch: Vec::new(),
            last_hit: None,
            cut_entry: None,
            last_cut_tip: None,
            wound: None,
            stats: StepperStats::default(),
            steps: 0,
            rebuild_every_steps: config.collider_rebuild_every_steps,
            collider_fresh: false,
            damage: DamageWatch::default(),
            grasp: None,
            jaws_closed: false,
            grasp_settings: GraspSettings::default(),
            retraction: WoundRetraction::default(),
        }
    }

    /// Steps taken.
    pub fn steps(&self) -> u64 {
        self.steps
    }

    /// What [`Self::resume`] needs, with the simulation's state and mesh, to continue from
    /// here; None unless the last step built the surface's BVH again (see
    /// [`SessionConfig::collider_rebuild_every_steps`]), since a refitted tree cannot be rebuilt as it was.
    pub fn resume_state(&self) -> Option<StepperResume> {
        self.collider_fresh.then(|| StepperResume {
            steps: self.steps,
            sim: self.sim.resume_state(),
            cutter: self.cutter.resume_state(),
            last_hit: self.last_hit,
            cut_entry: self.cut_entry,
            last_cut_tip: self.last_cut_tip,
            wound: self.wound,
            stats: self.stats,
            damage: self.damage.clone(),
            grasp: self.grasp.clone(),
            jaws_closed: self.jaws_closed,
            retraction: self.retraction.clone(),
        })
    }

    /// Builds the surface's BVH again if the last step refitted it, so that the state here
    /// can be resumed ([`Self::resume_state`]): for a session's last keyframe, which scoring
    /// resumes (a field's retractor), and after which no step follows (one would go on from a
    /// tree the steps between keyframes do not build).
    pub fn rebuild_to_end(&mut self) {
        if self.collider_fresh {
            return;
        }
        match self.collider.rebuild(&self.sim) {
            Ok(()) => self.collider_fresh = true,
            Err(e) => tracing::error!("rebuilding the surface at the end failed: {e}"),
        }
    }

    /// Continues from a step captured by [`Self::resume_state`], with the simulation's state
    /// and mesh there. The stepper must have been made as the captured one was (scene and
    /// settings). Input that does not fit is an error and leaves the stepper unchanged.
    pub fn resume(
        &mut self,
        mesh: TetMesh,
        state: State,
        r: &StepperResume,
    ) -> Result<(), HapticsError> {
        let invalid =
            |e: String| HapticsError::Simulation(format!("resuming at step {}: {e}", r.steps));
        let n = mesh.vertex_count();
        let on_mesh = |h: &SurfaceHit| {
            h.vertices.iter().all(|&v| (v as usize) < n)
                && h.point
                    .iter()
                    .chain(h.normal.iter())
                    .chain(&h.weights)
                    .all(|c| c.is_finite())
        };
        if !r.last_hit.as_ref().is_none_or(on_mesh)
            || !r.cut_entry.as_ref().is_none_or(on_mesh)
            || !r
                .wound
                .as_ref()
                .is_none_or(|(end, h)| on_mesh(h) && end.iter().all(|c| c.is_finite()))
        {
            return Err(invalid(
                "the last contact or the cut's entry is not on the mesh".into(),
            ));
        }
        if !r
            .last_cut_tip
            .is_none_or(|p| p.iter().all(|c| c.is_finite()))
        {
            return Err(invalid("the last cut's tip is not finite".into()));
        }
        if !r.grasp.as_ref().is_none_or(|g| g.fits(n)) {
            return Err(invalid("the grasp does not fit the mesh".into()));
        }
        if !r.retraction.fits(n) {
            return Err(invalid("the retractor does not fit the mesh".into()));
        }
        let mut cutter = self.cutter.clone();
        cutter
            .resume(&r.cutter, n)
            .map_err(|e| invalid(e.to_string()))?;
        let mut sim = self.sim.clone();
        sim.resume(mesh, state, &r.sim)
            .map_err(|e| invalid(e.to_string()))?;
        let collider = SurfaceCollider::build(&sim)?;
        (self.sim, self.cutter, self.collider) = (sim, cutter, collider);
        self.last_hit = r.last_hit;
        self.cut_entry = r.cut_entry;
        self.last_cut_tip = r.last_cut_tip;
        self.wound = r.wound;
        self.stats = r.stats;
        self.damage = r.damage.clone();
        self.grasp = r.grasp.clone();
        self.jaws_closed = r.jaws_closed;
        self.retraction = r.retraction.clone();
        self.steps = r.steps;
        self.collider_fresh = true;
        Ok(())
    }

    /// The tool's reaction on the tissue, spread over the contact patch around the touched
    /// point (weights `(1 - r / R)^2` over the surface particles within `R`); the scalpel is
    /// where a localised simulation stays awake.
    fn push_on_tissue(&mut self, sample: &ServoSample) {
        let render = sample.render;
        self.sim.clear_external_forces();
        // the scalpel is where a localised simulation stays awake
        self.sim.set_focus(&[sample.pose.tip_in_world]);
        if render.mode == Mode::Touching
            && let Some(hit) = &self.last_hit
        {
            self.patch.clear();
            let mut total = 0.0;
            let x = &self.sim.state.positions;
            for &v in self.collider.vertex_ids() {
                let r = (x[v as usize] - hit.point).norm();
                if r < self.patch_radius_m && !self.sim.model.held[v as usize] {
                    let w = (1.0 - r / self.patch_radius_m).powi(2);
                    self.patch.push((v, w));
                    total += w;
                }
            }
            if total > 0.0 {
                for &(v, w) in &self.patch {
                    self.sim
                        .add_external_force(v, -(render.force_newtons * (w / total)));
                }
            }
        }
    }

    /// The second hand, before the step: jaws closing take hold of the tissue between them,
    /// closed ones carry what they hold to their pose, opening ones let go.
    fn hold(&mut self, sample: &ServoSample) {
        let Some(jaws) = sample.grasper.map(|g| g.pose) else {
            return;
        };
        let closed = jaws.jaws_closed();
        match &mut self.grasp {
            Some(grasp) if closed => {
                grasp.carry(&mut self.sim, jaws.isometry());
            }
            Some(_) => self.let_go(),
            None if closed && !self.jaws_closed => {
                // jaws closed on nothing hold nothing until they open and close again
                if let Ok(grasp) = Grasp::close(&mut self.sim, jaws.isometry(), self.grasp_settings)
                {
                    self.stats.grasps += 1;
                    self.grasp = Some(grasp);
                }
            }
            None => {}
        }
        self.jaws_closed = closed;
    }

    /// The jaws open: what they held is free again.
    fn let_go(&mut self) {
        if let Some(grasp) = self.grasp.take() {
            grasp.release(&mut self.sim);
        }
    }

    /// The second hand, after the step: the held tissue's pull on the jaws, and the tissue
    /// let go where it pulls past the jaws' hold.
    fn pull_on_jaws(&mut self) -> Vector3 {
        let Some(grasp) = &self.grasp else {
            return Vector3::zeros();
        };
        let pull = grasp.pull_newtons(&self.sim);
        self.stats.grasp_steps += 1;
        self.stats.max_grasp_pull_newtons = self.stats.max_grasp_pull_newtons.max(pull.norm());
        if grasp.slips(&pull) || !pull.iter().all(|c| c.is_finite()) {
            self.stats.grasp_slips += 1;
            self.let_go();
            return Vector3::zeros();
        }
        pull
    }

    /// One simulation step driven by `sample`.
    pub fn step(&mut self, sample: &ServoSample) -> StepOutput {
        let render = sample.render;
        self.push_on_tissue(sample);
        self.hold(sample);
        // Cutting while the renderer says the blade is in the tissue; it went in where the
        // contact model it rendered from was, or, put back into the last cut's wound, where
        // that cut went in.
        let tip = sample.pose.tip_in_world;
        if render.mode == Mode::Cutting {
            let back_in_wound = self
                .wound
                .filter(|(end, _)| (tip - end).norm() <= WOUND_REACH_M)
                .map(|(_, entry)| entry);
            self.cut_entry = self.cut_entry.or(back_in_wound).or(self.last_hit);
        } else if let Some(entry) = self.cut_entry.take()
            && let Some(end) = self.last_cut_tip
        {
            self.wound = Some((end, entry));
        }
        let mut made = None;
        let mut damage = Vec::new();
        let moved_enough = self
            .last_cut_tip
            .is_none_or(|p| (tip - p).norm() >= self.cut_step_m);
        if render.mode == Mode::Cutting && moved_enough {
            if let Some(p) = self.last_cut_tip {
                self.stats.cut_length_m += (tip - p).norm();
            }
            self.last_cut_tip = Some(tip);
            if let Some(entry) = &self.cut_entry {
                self.retraction.note_cut(&tip, &entry.point, &entry.normal);
            }
            let blade = cut::Blade {
                tip,
                edge_direction: sample.pose.edge_direction(),
                depth_m: self.blade_length_m,
            };
            let regions_before = DamageWatch::watches_cuts(&self.sim.model)
                .then(|| self.sim.model.mesh.regions().to_vec());
            let in_jaws = self.grasp.as_ref().map_or(&[][..], |g| g.vertices());
            self.cutter.hold_in_jaws(in_jaws);
            let advanced = self.cutter.advance(&mut self.sim, blade);
            let stop = self.cutter.stop().map(|s| s.region);
            self.stats.blade_stops += u64::from(stop.is_some());
            self.damage.blade_stop(stop, &mut damage);
            match advanced {
                Ok(ev) if !ev.is_empty() => {
                    if let Some(regions) = &regions_before {
                        self.damage
                            .after_cut(&self.sim.model, regions, &ev, &mut damage);
                    }
                    self.stats.cut_steps += 1;
                    self.stats.tets_split += ev.tets_removed.len() as u64;
                    self.stats.fragments_reattached += ev.fragments_reattached as u64;
                    self.stats.specimens += ev.specimens.len() as u64;
                    if let Some(grasp) = &mut self.grasp {
                        grasp.adopt_cut(&mut self.sim, &ev);
                        for s in ev.specimens.iter().filter(|s| s.in_jaws) {
                            grasp.take_hold_of(&mut self.sim, &s.vertices);
                        }
                    }
                    if let Err(e) = self.collider.rebuild(&self.sim) {
                        tracing::error!("rebuilding the surface after a cut failed: {e}");
                    }
                    made = Some((blade, ev));
                }
                Ok(_) => {}
                Err(CutError::Unresolved(_)) => self.stats.unresolved_cuts += 1,
                Err(e) => {
                    self.stats.failed_cuts += 1;
                    tracing::warn!("cut failed at tick {}: {e}; stroke ended", sample.tick);
                    self.cutter.abandon_stroke();
                }
            }
        } else if render.mode != Mode::Cutting && self.cutter.in_stroke() {
            self.cutter.end_stroke();
            self.last_cut_tip = None;
        }
        if render.mode != Mode::Cutting {
            self.damage.blade_out();
        }

        let retract = sample.pose.buttons & BUTTON_RETRACT != 0;
        self.stats.retractions += u64::from(self.retraction.update(&mut self.sim, retract));
        let stepped = self.sim.step();
        let grasp_pull_newtons = self.pull_on_jaws();
        let rejected = match &stepped {
            Ok(report) => {
                self.stats.cg_iterations += report.cg_iterations as u64;
                false
            }
            Err(e) => {
                self.stats.rejected_steps += 1;
                // the first, then every hundredth: a diverging model would flood the log
                if self.stats.rejected_steps % 100 == 1 {
                    tracing::warn!(
                        "simulation step at tick {} rejected ({} so far): {e}",
                        sample.tick,
                        self.stats.rejected_steps
                    );
                }
                true
            }
        };
        self.steps += 1;
        self.collider_fresh =
            self.rebuild_every_steps > 0 && self.steps.is_multiple_of(self.rebuild_every_steps);
        if self.collider_fresh {
            if let Err(e) = self.collider.rebuild(&self.sim) {
                tracing::error!("rebuilding the surface at step {} failed: {e}", self.steps);
                self.collider_fresh = false;
                self.collider.refit(&self.sim.state.positions);
            }
        } else {
            self.collider.refit(&self.sim.state.positions);
        }
        // the proxy, and the blade's heel in case the blade rather than its tip meets the tissue
        let probes = [render.proxy, sample.pose.blade_heel(self.blade_length_m)];
        let pressed = self
            .last_hit
            .as_ref()
            .filter(|_| render.mode == Mode::Touching);
        let (mut contact, hit) =
            self.collider
                .contact_model(&self.sim, &probes, self.reach_m, sample.tick, pressed);
        contact.at_heel = contact.valid && hit.as_ref().is_some_and(|(probe, _)| *probe == 1);
        contact.grasp_pull_newtons = grasp_pull_newtons;
        contact.cut_entry = self.cut_entry.and_then(|h| self.entry_now(&h));
        contact.blade_stop = self
            .cutter
            .stop()
            .filter(|_| render.mode == Mode::Cutting && self.cutter.in_stroke())
            .map(|s| (s.blade.tip, s.blade.edge_direction.normalize()));
        // (the entry's normal as it went in: the cut splits the entry's triangle, whose
        // normal can turn as the wound opens)
        contact.wound = self.wound.and_then(|(end_m, h)| {
            self.entry_now(&h).map(|(p, _)| Wound {
                end_m,
                entry: (p, h.normal),
            })
        });
        self.last_hit = hit.map(|(_, h)| h);
        if sample.tick.is_multiple_of(100) {
            tracing::debug!(
                "tick {} mode {:?} force {:.3} N stiffness {:.0} N/m tip z {:.2} mm plane z {:.2} mm",
                sample.tick,
                render.mode,
                render.force_newtons.norm(),
                contact.stiffness_newtons_per_m,
                tip.z * 1e3,
                contact.plane_point.z * 1e3
            );
        }
        StepOutput {
            contact,
            cut: made,
            rejected,
            damage,
        }
    }

    /// Where a cut's entry `h` is now and its normal, or None once the entry is no longer on
    /// the tissue the blade is in: a piece cut free (a pattern's disc) is lifted away and
    /// held, and a point on it would put the entry's plane wherever the piece went. Without
    /// an entry the renderer keeps the plane the blade went in by (before, a blade cutting on
    /// past the freed disc left its cut and went back into it on every other tick). Any held
    /// particle counts: the entry's triangle is the one hit before the cut split it, so its
    /// particles may lie on both sides (asking for all of them held missed the disc).
    fn entry_now(&self, h: &SurfaceHit) -> Option<(Point3, Vector3)> {
        let held = &self.sim.model.held;
        if h.vertices
            .iter()
            .any(|&v| held.get(v as usize).is_none_or(|&held| held))
        {
            return None;
        }
        h.moved(&self.sim.state.positions)
    }

    /// Hash of the simulation state's bits (positions and velocities) and of its topology
    /// (the tetrahedra): what a recording's keyframes carry and a replay checks.
    pub fn state_hash(&self) -> StateHash {
        StateHash::of(&self.sim)
    }
}

/// The bits of a simulation at one step, hashed (FNV-1a, 64 bits).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct StateHash {
    /// Positions and velocities.
    pub state: u64,
    /// Tetrahedra (vertex ids) and reference positions.
    pub topology: u64,
}

impl StateHash {
    /// The hashes (FNV-1a over the bits) of `sim`'s state and mesh.
    pub fn of(sim: &Simulation) -> Self {
        let mesh = &sim.model.mesh;
        let mut h = Fnv1a::default();
        for t in mesh.tets() {
            t.iter().for_each(|&v| h.u32(v));
        }
        for p in mesh.positions() {
            p.iter().for_each(|&c| h.f64(c));
        }
        Self {
            state: sim.state.bit_hash(),
            topology: h.finish(),
        }
    }
}
