//! What an attempt is assessed on: plain samples the recorder fills from a session (SI units:
//! metres, seconds, newtons).

use serde::{Deserialize, Serialize};

/// The tool's pose at one instant.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct PoseSample {
    /// Time since the start of the session (s).
    pub t_s: f64,
    /// The blade tip in world coordinates (m).
    pub tip_m: [f64; 3],
    /// The tool's orientation, unit quaternion `[w, x, y, z]`.
    pub quat_wxyz: [f64; 4],
    /// Whether the blade is in cutting mode (in the tissue and pressed beyond the cut threshold).
    pub blade_engaged: bool,
}

/// The force rendered to the trainee's hand at one instant.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct ForceSample {
    /// Time since the start of the session (s).
    pub t_s: f64,
    /// The force on the hand (N), world coordinates.
    pub force_newtons: [f64; 3],
    /// The tool touches the tissue.
    pub touching: bool,
    /// The tool is cutting.
    pub cutting: bool,
}

/// The blade at one cut the simulation made (one per cut step, e.g. every 0.5 mm of travel).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct CutSample {
    /// Time since the start of the session (s).
    pub t_s: f64,
    /// The blade tip (m).
    pub tip_m: [f64; 3],
    /// The cutting edge's direction (unit, pointing from the tip along the edge).
    pub edge_dir: [f64; 3],
    /// The tip's penetration below the tissue surface at this cut (m), measured along the
    /// plan's outward normal: `(s - tip) . n` with `s` the surface point above the tip. The
    /// recorder fills it from the simulation's surface (or, lacking it, with
    /// [`crate::metrics::incision::depth_below_plan`]); positive inside the tissue.
    pub depth_m: f64,
    /// The blade's stroke this sample belongs to, when the recorder knows it: strokes are
    /// numbered in time order, a new one each time the blade enters the tissue again, so two
    /// samples of one stroke were cut without the blade leaving the tissue however far apart
    /// they are (a device that skips forward, ticks not recorded). `None` when unknown: the
    /// metrics then start a new stroke where consecutive samples are more than
    /// [`crate::metrics::incision::STROKE_GAP_M`] apart.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub stroke: Option<u32>,
}

/// A piece of tissue a cut freed (a specimen), when it was freed and its size at rest.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct FreedPiece {
    /// Time since the start of the session (s).
    pub t_s: f64,
    /// Its volume at rest (m^3).
    pub volume_m3: f64,
    /// Its surface at rest, the outer surface and the cut's (m^2).
    pub surface_m2: f64,
}

/// The tissue's boundary surface (deformed, after the cut), for the field-of-view metrics.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct SurfaceMesh {
    /// Vertex positions (m).
    pub vertices_m: Vec<[f64; 3]>,
    /// Triangles as indices into `vertices_m`, counter-clockwise seen from outside.
    pub triangles: Vec<[u32; 3]>,
}

impl SurfaceMesh {
    /// The boundary of `sim`'s tissue as it is now.
    pub fn of(sim: &cutlab_sim::solver::Simulation) -> Self {
        Self {
            vertices_m: sim
                .state
                .positions
                .iter()
                .map(|p| [p.x, p.y, p.z])
                .collect(),
            triangles: sim.model.mesh.topology().boundary.clone(),
        }
    }
}

/// Everything one attempt is assessed on.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct AttemptData {
    /// Tool poses in time order (any rate; the path metrics resample).
    pub poses: Vec<PoseSample>,
    /// Rendered forces in time order.
    pub forces: Vec<ForceSample>,
    /// The cuts in time order.
    pub cuts: Vec<CutSample>,
    /// The pieces the cuts freed, in time order.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub freed: Vec<FreedPiece>,
    /// The deformed tissue surface at the end of the attempt, if recorded.
    #[serde(default)]
    pub surface: Option<SurfaceMesh>,
    /// The device the attempt was made with, as the recording names it (`pointer`, `expert`,
    /// `recording of pointer`...), if known: some metrics measure what only some devices let
    /// the trainee choose ([`crate::metrics::incision::device_sets_approach`]).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub device: Option<String>,
    /// The tissue's surface after a retractor spread the wound at the end of the attempt,
    /// where the exercise measures the field so.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub retracted_surface: Option<SurfaceMesh>,
    /// Harm done to tissue that should not be cut, in time order.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub damage: Vec<DamageEvent>,
    /// The second hand's grasper in time order, when the attempt was made with one.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub grasper: Vec<GrasperSample>,
}

/// The second hand's grasper at one instant.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct GrasperSample {
    /// Time since the start of the session (s).
    pub t_s: f64,
    /// The jaws' centre in world coordinates (m).
    pub jaws_m: [f64; 3],
    /// The jaws are closed.
    pub closed: bool,
    /// The held tissue's pull on the jaws (N, world coordinates): zero while they hold
    /// nothing.
    pub pull_newtons: [f64; 3],
}

impl GrasperSample {
    /// Whether the jaws hold tissue (it pulls on them).
    pub fn holds(&self) -> bool {
        self.pull_newtons != [0.0; 3]
    }
}

/// Harm done to tissue that should not be cut, as the session recorded it.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct DamageEvent {
    /// Time since the start of the session (s).
    pub t_s: f64,
    /// What happened: `blade-on-bone` (the blade came down on a rib or a cartilage) or
    /// `spare-cut` (a structure to spare was cut).
    pub kind: cutlab_haptics::damage::DamageKind,
    /// What it happened to: the scene's name for the region (`rib`, `internal thoracic
    /// artery`), else `region N`.
    pub structure: String,
}
