//! The recording tap: what a session hands to a recorder, through bounded lock-free queues.
//!
//! - the servo thread pushes every tick's [`ServoSample`] (pose, force, contact state) into
//!   a wait-free SPSC queue; it never waits: a full queue drops the record and counts it
//!   (`ServoReport::dropped_records`), so a slow disk can never delay a tick;
//! - the simulation thread pushes [`SimRecord`]s: which tick each step consumed, every cut's
//!   topology event, keyframes of the full state and the tissue surface at visual rate. It
//!   waits for room when the queue is full (a recording must not lose a topology change),
//!   and gives up on the recorder if the consumer is gone.
//!
//! The consumer side ([`TapFeed`]) belongs to the recorder's writer thread.

use cutlab_sim::cut::{Blade, CutEvent};

use crate::Point3;
use crate::collision::SurfaceCollider;
use crate::servo::{Backoff, ServoSample};
use crate::stepper::{SessionStepper, StateHash, StepperResume};

/// How much a session records, and the queue sizes.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TapSettings {
    /// A keyframe (the full state and its hash) every this many simulation steps (and after
    /// the last step); the session's surface BVH is built again at each (see
    /// [`crate::SessionConfig::collider_rebuild_every_steps`]).
    pub keyframe_every_steps: u64,
    /// The tissue surface after the first step and every this many simulation steps
    /// (0: never); see [`surface_due`].
    pub surface_every_steps: u64,
    /// Capacity of the tick queue, records (a 1 kHz servo fills 1,000 per second).
    pub tick_capacity: usize,
    /// Capacity of the simulation queue, records.
    pub sim_capacity: usize,
}

/// Whether step `step` records the tissue surface, at one surface every `every_steps` steps
/// (0: never): after the first step too, so that a recording shows the tissue from its first
/// frame. The session and a replay that logs to rerun both follow this rule.
pub fn surface_due(step: u64, every_steps: u64) -> bool {
    every_steps > 0 && (step == 0 || (step + 1).is_multiple_of(every_steps))
}

impl Default for TapSettings {
    fn default() -> Self {
        Self {
            keyframe_every_steps: 1000,
            surface_every_steps: 33,
            tick_capacity: 1 << 16,
            sim_capacity: 1 << 14,
        }
    }
}

/// The full simulation state at one step: what a viewer seeks to, and what a replay checks
/// (through `hash`).
#[derive(Debug, Clone, PartialEq)]
pub struct Keyframe {
    /// The simulation step.
    pub step: u64,
    /// The servo tick that step consumed.
    pub tick: u64,
    /// The hash of the state's bits.
    pub hash: StateHash,
    /// Positions of the vertices, m.
    pub positions: Vec<Point3>,
    /// Velocities of the vertices, m/s.
    pub velocities: Vec<cutlab_sim::Vector3>,
    /// Reference (rest) positions of the vertices.
    pub rest_positions: Vec<Point3>,
    /// The mesh's tetrahedra.
    pub tets: Vec<[u32; 4]>,
    /// The region id of each tetrahedron.
    pub regions: Vec<u32>,
    /// What else the steps after this one depend on, when the stepper can say
    /// ([`SessionStepper::resume_state`]): with it a replay seeks here without re-simulating.
    pub resume: Option<StepperResume>,
}

impl Keyframe {
    /// The stepper's state after step `step` (which consumed tick `tick`).
    pub fn of(stepper: &SessionStepper, step: u64, tick: u64) -> Self {
        let sim = &stepper.sim;
        let mesh = &sim.model.mesh;
        Self {
            resume: stepper.resume_state(),
            step,
            tick,
            hash: StateHash::of(sim),
            positions: sim.state.positions.clone(),
            velocities: sim.state.velocities.clone(),
            rest_positions: mesh.positions().to_vec(),
            tets: mesh.tets().to_vec(),
            regions: mesh.regions().to_vec(),
        }
    }
}

/// The deformed tissue surface: triangles over its own vertex list.
#[derive(Debug, Clone, PartialEq)]
pub struct SurfaceSnapshot {
    /// The simulation step.
    pub step: u64,
    /// The servo tick that step consumed.
    pub tick: u64,
    /// Positions of the surface's vertices, m.
    pub vertices: Vec<Point3>,
    /// The triangles, over `vertices`.
    pub triangles: Vec<[u32; 3]>,
    /// The region of each vertex ([`SurfaceCollider::vertex_regions`]).
    pub regions: Vec<u32>,
}

impl SurfaceSnapshot {
    /// The collider's surface at `positions` (the mesh's vertex positions).
    pub fn of(collider: &SurfaceCollider, positions: &[Point3], step: u64, tick: u64) -> Self {
        Self {
            step,
            tick,
            vertices: collider
                .vertex_ids()
                .iter()
                .map(|&v| positions[v as usize])
                .collect(),
            triangles: collider.triangles().to_vec(),
            regions: collider.vertex_regions().to_vec(),
        }
    }
}

/// One record of the simulation thread.
#[derive(Debug, Clone, PartialEq)]
pub enum SimRecord {
    /// Step `step` consumed the sample of servo tick `tick`.
    Step {
        /// The step.
        step: u64,
        /// The tick.
        tick: u64,
        /// Whether the simulation rejected the step (the state was kept).
        rejected: bool,
    },
    /// The cut step `step` made.
    Cut {
        /// The step.
        step: u64,
        /// The tick that step consumed.
        tick: u64,
        /// The blade's pose at the cut.
        blade: Blade,
        /// Everything the cut changed.
        event: Box<CutEvent>,
    },
    /// Harm step `step` did to tissue that should not be cut.
    Damage {
        /// The step.
        step: u64,
        /// The tick that step consumed.
        tick: u64,
        /// What was harmed.
        damage: crate::damage::TissueDamage,
    },
    /// The full state at a step.
    Keyframe(Box<Keyframe>),
    /// The tissue surface at a step.
    Surface(Box<SurfaceSnapshot>),
}

/// The producer side, held by the session.
#[derive(Debug)]
pub struct RecordTap {
    /// How much is recorded, and the queue sizes.
    pub settings: TapSettings,
    pub(crate) ticks: rtrb::Producer<ServoSample>,
    pub(crate) sim: rtrb::Producer<SimRecord>,
}

/// The consumer side, held by the recorder's writer thread. A queue whose producer is gone
/// (`is_abandoned`) and empty has ended.
#[derive(Debug)]
pub struct TapFeed {
    /// Every servo tick's sample.
    pub ticks: rtrb::Consumer<ServoSample>,
    /// The simulation thread's records.
    pub sim: rtrb::Consumer<SimRecord>,
}

impl TapFeed {
    /// Both producers are gone and both queues are empty: nothing more will come.
    pub fn ended(&self) -> bool {
        self.ticks.is_abandoned()
            && self.ticks.is_empty()
            && self.sim.is_abandoned()
            && self.sim.is_empty()
    }
}

/// A tap and its feed. The tick queue is written through once here, so the servo loop never
/// page-faults on it.
pub fn tap(settings: TapSettings) -> (RecordTap, TapFeed) {
    let (mut ticks_in, mut ticks_out) = rtrb::RingBuffer::new(settings.tick_capacity.max(2));
    while ticks_in.push(ServoSample::default()).is_ok() {}
    while ticks_out.pop().is_ok() {}
    let (sim_in, sim_out) = rtrb::RingBuffer::new(settings.sim_capacity.max(2));
    (
        RecordTap {
            settings,
            ticks: ticks_in,
            sim: sim_in,
        },
        TapFeed {
            ticks: ticks_out,
            sim: sim_out,
        },
    )
}

impl RecordTap {
    /// Pushes a simulation record, waiting for room; false when the recorder is gone.
    pub(crate) fn push_sim(sim: &mut rtrb::Producer<SimRecord>, mut record: SimRecord) -> bool {
        let mut backoff = Backoff::default();
        loop {
            match sim.push(record) {
                Ok(()) => return true,
                Err(rtrb::PushError::Full(r)) => {
                    if sim.is_abandoned() {
                        return false;
                    }
                    record = r;
                    backoff.wait();
                }
            }
        }
    }
}
