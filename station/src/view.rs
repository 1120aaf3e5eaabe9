//! What a station's viewers see: the latest frame of the session, published by the recorder
//! thread (a [`RecordObserver`]), latest wins.
//!
//! The session's records reach the recorder thread through its lock-free tap, so publishing
//! never touches the servo or the simulation thread. Each tissue surface the tap carries
//! becomes a [`ViewFrame`] with the tool's latest pose and force; a viewer that is slow skips
//! frames (a [`tokio::sync::watch`] slot holds only the newest) and never queues them.

use std::sync::Arc;

use cutlab_haptics::render::Mode;
use cutlab_haptics::servo::ServoSample;
use cutlab_haptics::tap::{SimRecord, SurfaceSnapshot};
use cutlab_recorder::RecorderError;
use cutlab_recorder::writer::RecordObserver;
use tokio::sync::watch;

/// The surface's triangles over its vertex list, and each vertex's region (the page colours
/// the tissue by it).
#[derive(Debug, Clone, PartialEq, Eq, Default)]
pub struct Topology {
    pub vertex_count: usize,
    pub triangles: Vec<[u32; 3]>,
    pub regions: Vec<u32>,
}

/// The tissue's surface before anything touched it: the session's first surface, kept for
/// the whole session. The page measures depths from it and points on it, so a page that joins
/// a running attempt (a reload) measures as the one that saw it begin.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct RestSurface {
    pub triangles: Vec<[u32; 3]>,
    /// `x, y, z` of each vertex, m.
    pub positions_m: Vec<f32>,
}

/// One frame of the view.
#[derive(Debug, Clone, PartialEq)]
pub struct ViewFrame {
    /// The servo tick of the tool's pose and force.
    pub tick: u64,
    /// The page's time stamp of the newest pointer sample that tick consumed, ms (NaN: none).
    pub echo_ms: f64,
    /// 0 free, 1 touching, 2 cutting.
    pub mode: u8,
    pub engaged: bool,
    pub faults: u8,
    pub tip_m: [f32; 3],
    pub world_from_tool_wxyz: [f32; 4],
    pub force_newtons: [f32; 3],
    /// The second hand's grasper, in a session with one.
    pub grasper: Option<GrasperView>,
    /// The surface's vertices, `x, y, z` each, in the order of the current topology.
    pub positions_m: Vec<f32>,
}

/// The second hand's grasper in a frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct GrasperView {
    /// The jaws' centre, m.
    pub jaws_m: [f32; 3],
    /// The jaws are closed.
    pub closed: bool,
    /// The held tissue's pull on the jaws, N (0 while they hold nothing).
    pub pull_newtons: f32,
}

impl GrasperView {
    /// Its state as a frame carries it: 1 open, 2 closed on nothing, 3 holding tissue.
    pub fn state(&self) -> u8 {
        match (self.closed, self.pull_newtons > 0.0) {
            (_, true) => 3,
            (true, false) => 2,
            (false, false) => 1,
        }
    }
}

/// What the slot holds: the frame and the topology its positions belong to.
#[derive(Debug, Clone, Default)]
pub struct ViewState {
    /// The session's first surface (`None` until the session has one).
    pub rest: Option<Arc<RestSurface>>,
    pub topology: Arc<Topology>,
    pub frame: Option<Arc<ViewFrame>>,
    /// The session has ended (no frame follows).
    pub ended: bool,
}

/// The receiving side: one per viewer (clone it).
pub type ViewFeed = watch::Receiver<ViewState>;

/// Where a pointer sample's page time stamp can be found for a tick (the station's device
/// reports which sample each tick consumed).
pub trait EchoSource: Send + Sync {
    /// The page's time stamp of the newest sample consumed by tick `tick` or before, ms.
    fn echo_ms(&self, tick: u64) -> Option<f64>;
}

/// The pointer device knows which of the page's samples each tick played.
impl EchoSource for cutlab_haptics::device::PointerFeed {
    fn echo_ms(&self, tick: u64) -> Option<f64> {
        cutlab_haptics::device::PointerFeed::echo_ms(self, tick)
    }
}

/// Publishes the session's frames (the [`RecordObserver`] the station hands the recorder).
pub struct ViewPublisher {
    slot: watch::Sender<ViewState>,
    last_tick: Option<ServoSample>,
    echo: Option<Arc<dyn EchoSource>>,
}

impl std::fmt::Debug for ViewPublisher {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("ViewPublisher")
            .field("viewers", &self.slot.receiver_count())
            .finish_non_exhaustive()
    }
}

impl ViewPublisher {
    /// A publisher and the feed its viewers clone.
    pub fn new(echo: Option<Arc<dyn EchoSource>>) -> (Self, ViewFeed) {
        let (slot, feed) = watch::channel(ViewState::default());
        (
            Self {
                slot,
                last_tick: None,
                echo,
            },
            feed,
        )
    }

    fn publish(&mut self, surface: &SurfaceSnapshot) {
        let (vertices, triangles) = (&surface.vertices, &surface.triangles);
        if self.slot.borrow().rest.is_none() {
            let rest = RestSurface {
                triangles: triangles.clone(),
                positions_m: flat_f32(vertices),
            };
            self.slot
                .send_modify(|state| state.rest = Some(Arc::new(rest)));
        }
        let Some(s) = &self.last_tick else {
            return;
        };
        let q = s.pose.world_from_tool.quaternion();
        let frame = ViewFrame {
            tick: s.tick,
            echo_ms: self
                .echo
                .as_ref()
                .and_then(|e| e.echo_ms(s.tick))
                .unwrap_or(f64::NAN),
            mode: match s.render.mode {
                Mode::Free => 0,
                Mode::Touching => 1,
                Mode::Cutting => 2,
            },
            engaged: s.pose.blade_engaged(),
            faults: s.render.faults,
            tip_m: f32x3(s.pose.tip_in_world.coords.into()),
            world_from_tool_wxyz: [q.w as f32, q.i as f32, q.j as f32, q.k as f32],
            force_newtons: f32x3(s.render.force_newtons.into()),
            grasper: s.grasper.map(|g| GrasperView {
                jaws_m: f32x3(g.pose.tip_in_world.coords.into()),
                closed: g.pose.jaws_closed(),
                pull_newtons: g.pull_newtons.norm() as f32,
            }),
            positions_m: flat_f32(vertices),
        };
        self.slot.send_modify(|state| {
            if state.topology.vertex_count != vertices.len()
                || state.topology.triangles != *triangles
                || state.topology.regions != surface.regions
            {
                state.topology = Arc::new(Topology {
                    vertex_count: vertices.len(),
                    triangles: triangles.clone(),
                    regions: surface.regions.clone(),
                });
            }
            state.frame = Some(Arc::new(frame));
        });
    }
}

fn flat_f32(points: &[cutlab_haptics::Point3]) -> Vec<f32> {
    points
        .iter()
        .flat_map(|p| [p.x as f32, p.y as f32, p.z as f32])
        .collect()
}

fn f32x3(v: [f64; 3]) -> [f32; 3] {
    v.map(|x| x as f32)
}

impl RecordObserver for ViewPublisher {
    fn on_tick(&mut self, sample: &ServoSample) -> Result<(), RecorderError> {
        self.last_tick = Some(*sample);
        Ok(())
    }

    fn on_sim(&mut self, record: &SimRecord) -> Result<(), RecorderError> {
        if let SimRecord::Surface(s) = record {
            self.publish(s);
        }
        Ok(())
    }

    fn finish(self: Box<Self>) -> Result<(), RecorderError> {
        self.slot.send_modify(|state| state.ended = true);
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use cutlab_haptics::render::RenderOutput;
    use cutlab_haptics::{Point3, ToolPose, Vector3};

    use super::*;

    fn sample(tick: u64) -> ServoSample {
        ServoSample {
            tick,
            pose: ToolPose {
                tip_in_world: Point3::new(0.01, 0.02, 0.03),
                ..ToolPose::default()
            },
            render: RenderOutput {
                force_newtons: Vector3::new(0.0, 0.0, 0.5),
                proxy: Point3::origin(),
                mode: Mode::Touching,
                faults: 0,
                gain: 1.0,
            },
            grasper: None,
        }
    }

    fn surface(step: u64, triangles: Vec<[u32; 3]>) -> SimRecord {
        SimRecord::Surface(Box::new(SurfaceSnapshot {
            step,
            tick: step,
            vertices: vec![
                Point3::origin(),
                Point3::new(1.0, 0.0, 0.0),
                Point3::new(0.0, 1.0, 0.0),
            ],
            triangles,
            regions: vec![0, 0, 1],
        }))
    }

    struct Echo;
    impl EchoSource for Echo {
        fn echo_ms(&self, tick: u64) -> Option<f64> {
            Some(tick as f64 * 0.5)
        }
    }

    #[test]
    fn the_newest_frame_wins_and_topology_changes_are_new() {
        let (mut p, mut feed) = ViewPublisher::new(Some(Arc::new(Echo)));
        // no frame before the first tick, but the rest surface
        p.on_sim(&surface(0, vec![[0, 1, 2]])).expect("sim");
        assert!(feed.borrow().frame.is_none());
        let rest = feed.borrow().rest.clone().expect("the rest surface");
        assert_eq!(rest.triangles, vec![[0, 1, 2]]);
        assert_eq!(rest.positions_m.len(), 9);
        for tick in 0..10 {
            p.on_tick(&sample(tick)).expect("tick");
        }
        p.on_sim(&surface(9, vec![[0, 1, 2]])).expect("sim");
        let first = feed.borrow_and_update().topology.clone();
        p.on_tick(&sample(10)).expect("tick");
        p.on_sim(&surface(10, vec![[0, 1, 2]])).expect("sim");
        p.on_tick(&sample(11)).expect("tick");
        p.on_sim(&surface(11, vec![[0, 2, 1]])).expect("sim");
        // a viewer that did not look in between sees only the newest
        let state = feed.borrow_and_update().clone();
        let frame = state.frame.expect("a frame");
        assert_eq!((frame.tick, frame.echo_ms, frame.mode), (11, 5.5, 1));
        assert_eq!(frame.positions_m.len(), 9);
        assert_eq!(frame.force_newtons, [0.0, 0.0, 0.5]);
        assert!(!Arc::ptr_eq(&first, &state.topology));
        assert_eq!(state.topology.triangles, vec![[0, 2, 1]]);
        // the rest surface stays the first one through every change
        assert!(Arc::ptr_eq(&rest, state.rest.as_ref().expect("rest")));
        Box::new(p).finish().expect("finish");
        assert!(feed.borrow().ended);
    }
}
