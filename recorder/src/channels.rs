//! The channels of a cutlab recording: topics, schemas, and the messages of the channels
//! with cutlab's own (JSON) schemas.
//!
//! | topic | schema (encoding) | rate | content |
//! |---|---|---|---|
//! | `/tool/pose` | `foxglove.PoseInFrame` (protobuf) | every servo tick | scalpel tip (m) and `world_from_tool` |
//! | `/tool/state` | `cutlab.ToolState` (JSON) | every servo tick | rendered force (N), proxy, contact mode, buttons, faults, gain |
//! | `/sim/step` | `cutlab.SimStep` (JSON) | every simulation step | which servo tick the step consumed |
//! | `/sim/topology` | `cutlab.TopologyEvent` (JSON) | every cut | the blade and every topology change |
//! | `/sim/state_hash` | `cutlab.StateHash` (JSON) | every keyframe | hashes of the state and topology bits |
//! | `/sim/keyframe` | `cutlab.Keyframe` (JSON) | every N steps and the last | positions, velocities, rest positions, tets |
//! | `/tissue/surface` | `foxglove.SceneUpdate` (protobuf) | visual rate | the deformed tissue surface (triangles) |
//!
//! Log time of every message: the servo tick times the servo period (session time, ns from
//! the session's start; the wall-clock start is in the metadata). Metadata record
//! `cutlab.session` (cutlab version, scene, seed, trainee, exercise, device, the stepper's
//! settings, the initial state hash), `cutlab.session_end` (written on a clean finish), and
//! attachments `scene.json` (the scene spec) and `plan.json` (the planned incision).
//!
//! Floats in the JSON channels are written in their shortest round-trip form, so reading
//! them back gives the same bits (replay depends on it); 64-bit hashes are hex strings.

use serde::{Deserialize, Serialize};

use cutlab_haptics::render::{Mode, RenderOutput};
use cutlab_haptics::servo::ServoSample;
use cutlab_haptics::stepper::StateHash;
use cutlab_haptics::stepper::StepperResume;
use cutlab_haptics::tap::Keyframe;
use cutlab_haptics::{Point3, Rotation, ToolPose, Vector3};
use cutlab_sim::cut::{Blade, CutEvent};

use crate::RecorderError;

pub const POSE: &str = "/tool/pose";
pub const TOOL_STATE: &str = "/tool/state";
pub const SIM_STEP: &str = "/sim/step";
pub const TOPOLOGY: &str = "/sim/topology";
pub const STATE_HASH: &str = "/sim/state_hash";
pub const KEYFRAME: &str = "/sim/keyframe";
pub const SURFACE: &str = "/tissue/surface";
pub const DAMAGE: &str = "/sim/damage";
/// The second hand's grasper: its pose (a `PoseInFrame`, the jaws' centre) and its state
/// (JSON [`GrasperStateMsg`]), written only by a session with a grasper.
pub const GRASPER_POSE: &str = "/tool/grasper/pose";
pub const GRASPER_STATE: &str = "/tool/grasper/state";
/// The grasper's state channel: schema name and JSON schema.
pub const GRASPER_STATE_SCHEMA: (&str, &str) = (
    "cutlab.GrasperState",
    r#"{"type":"object","properties":{"tick":{"type":"integer"},"buttons":{"type":"integer"},"pull_newtons":{"type":"array","items":{"type":"number"}}}}"#,
);

/// Frame of every pose and surface: the tissue's world frame.
pub const WORLD_FRAME: &str = "world";

/// Metadata record names and attachment names.
pub const SESSION_METADATA: &str = "cutlab.session";
pub const SESSION_END_METADATA: &str = "cutlab.session_end";
pub const SCENE_ATTACHMENT: &str = "scene.json";
pub const PLAN_ATTACHMENT: &str = "plan.json";

/// The JSON-schema channels: topic, schema name, JSON schema.
pub const JSON_CHANNELS: [(&str, &str, &str); 6] = [
    (
        TOOL_STATE,
        "cutlab.ToolState",
        r#"{"type":"object","properties":{"tick":{"type":"integer"},"force_newtons":{"type":"array","items":{"type":"number"}},"proxy_m":{"type":"array","items":{"type":"number"}},"mode":{"type":"string","enum":["free","touching","cutting"]},"buttons":{"type":"integer"},"faults":{"type":"integer"},"gain":{"type":"number"}}}"#,
    ),
    (
        SIM_STEP,
        "cutlab.SimStep",
        r#"{"type":"object","properties":{"step":{"type":"integer"},"tick":{"type":"integer"},"rejected":{"type":"boolean"}}}"#,
    ),
    (
        TOPOLOGY,
        "cutlab.TopologyEvent",
        r#"{"type":"object","properties":{"step":{"type":"integer"},"tick":{"type":"integer"},"blade":{"type":"object"},"event":{"type":"object","properties":{"tets_removed":{"type":"array"},"tets_added":{"type":"array"},"tets_relinked":{"type":"array"},"vertices_created":{"type":"array"},"vertices_moved":{"type":"array"},"vertices_split":{"type":"array"},"springs_removed":{"type":"array"},"springs_added":{"type":"array"}}}}}"#,
    ),
    (
        STATE_HASH,
        "cutlab.StateHash",
        r#"{"type":"object","properties":{"step":{"type":"integer"},"tick":{"type":"integer"},"state":{"type":"string"},"topology":{"type":"string"}}}"#,
    ),
    (
        KEYFRAME,
        "cutlab.Keyframe",
        r#"{"type":"object","properties":{"step":{"type":"integer"},"tick":{"type":"integer"},"state_hash":{"type":"string"},"topology_hash":{"type":"string"},"positions_m":{"type":"array"},"velocities_m_per_s":{"type":"array"},"rest_positions_m":{"type":"array"},"tets":{"type":"array"},"regions":{"type":"array"}}}"#,
    ),
    (
        DAMAGE,
        "cutlab.TissueDamage",
        r#"{"type":"object","properties":{"step":{"type":"integer"},"tick":{"type":"integer"},"kind":{"type":"string","enum":["blade-on-bone","spare-cut"]},"region":{"type":"integer"}}}"#,
    ),
];

/// `/tool/state`: what the servo loop rendered at one tick.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct ToolStateMsg {
    pub tick: u64,
    pub force_newtons: [f64; 3],
    pub proxy_m: [f64; 3],
    pub mode: ModeName,
    pub buttons: u32,
    pub faults: u8,
    pub gain: f64,
}

/// `/tool/grasper/state`: the grasper's buttons at one tick ([`cutlab_haptics::pose::BUTTON_JAWS`]:
/// the jaws closed) and the held tissue's pull on its jaws (N; zero while they hold nothing,
/// and in recordings made before it was written).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct GrasperStateMsg {
    pub tick: u64,
    pub buttons: u32,
    #[serde(default)]
    pub pull_newtons: [f64; 3],
}

/// The contact mode as written.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum ModeName {
    Free,
    Touching,
    Cutting,
}

impl From<Mode> for ModeName {
    fn from(m: Mode) -> Self {
        match m {
            Mode::Free => ModeName::Free,
            Mode::Touching => ModeName::Touching,
            Mode::Cutting => ModeName::Cutting,
        }
    }
}

impl From<ModeName> for Mode {
    fn from(m: ModeName) -> Self {
        match m {
            ModeName::Free => Mode::Free,
            ModeName::Touching => Mode::Touching,
            ModeName::Cutting => Mode::Cutting,
        }
    }
}

impl ToolStateMsg {
    pub fn of(sample: &ServoSample) -> Self {
        let r = &sample.render;
        Self {
            tick: sample.tick,
            force_newtons: r.force_newtons.into(),
            proxy_m: r.proxy.coords.into(),
            mode: r.mode.into(),
            buttons: sample.pose.buttons,
            faults: r.faults,
            gain: r.gain,
        }
    }

    /// The servo sample of this tick, given the tick's pose (from `/tool/pose`).
    pub fn sample(&self, tip_in_world: Point3, world_from_tool: Rotation) -> ServoSample {
        ServoSample {
            tick: self.tick,
            pose: ToolPose {
                tip_in_world,
                world_from_tool,
                buttons: self.buttons,
            },
            render: RenderOutput {
                force_newtons: Vector3::from(self.force_newtons),
                proxy: Point3::from(self.proxy_m),
                mode: self.mode.into(),
                faults: self.faults,
                gain: self.gain,
            },
            grasper: None,
        }
    }
}

/// `/sim/step`: step `step` consumed servo tick `tick`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub struct SimStepMsg {
    pub step: u64,
    pub tick: u64,
    pub rejected: bool,
}

/// The blade of a cut, as written.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct BladeMsg {
    pub tip_m: [f64; 3],
    pub edge_direction: [f64; 3],
    pub depth_m: f64,
}

impl From<&Blade> for BladeMsg {
    fn from(b: &Blade) -> Self {
        Self {
            tip_m: b.tip.coords.into(),
            edge_direction: b.edge_direction.into(),
            depth_m: b.depth_m,
        }
    }
}

impl From<&BladeMsg> for Blade {
    fn from(b: &BladeMsg) -> Self {
        Self {
            tip: Point3::from(b.tip_m),
            edge_direction: Vector3::from(b.edge_direction),
            depth_m: b.depth_m,
        }
    }
}

/// `/sim/damage`: harm step `step` did to tissue it should not cut
/// (`cutlab_haptics::damage`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub struct TissueDamageMsg {
    pub step: u64,
    pub tick: u64,
    pub kind: cutlab_haptics::damage::DamageKind,
    pub region: u32,
}

/// `/sim/topology`: the cut step `step` made.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TopologyMsg {
    pub step: u64,
    pub tick: u64,
    pub blade: BladeMsg,
    pub event: CutEvent,
}

/// A 64-bit hash as written (hex: JSON readers lose integers above 2^53).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Hex(pub u64);

impl Serialize for Hex {
    fn serialize<S: serde::Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        s.serialize_str(&format!("{:016x}", self.0))
    }
}

impl<'de> Deserialize<'de> for Hex {
    fn deserialize<D: serde::Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        let s = String::deserialize(d)?;
        u64::from_str_radix(&s, 16)
            .map(Hex)
            .map_err(serde::de::Error::custom)
    }
}

/// `/sim/state_hash`: the hashes of a keyframe.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub struct StateHashMsg {
    pub step: u64,
    pub tick: u64,
    pub state: Hex,
    pub topology: Hex,
}

impl StateHashMsg {
    pub fn hash(&self) -> StateHash {
        StateHash {
            state: self.state.0,
            topology: self.topology.0,
        }
    }
}

/// `/sim/keyframe`: the full simulation state after step `step`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct KeyframeMsg {
    pub step: u64,
    pub tick: u64,
    pub state_hash: Hex,
    pub topology_hash: Hex,
    pub positions_m: Vec<[f64; 3]>,
    pub velocities_m_per_s: Vec<[f64; 3]>,
    pub rest_positions_m: Vec<[f64; 3]>,
    pub tets: Vec<[u32; 4]>,
    pub regions: Vec<u32>,
    /// What else the steps after this one depend on (the solver's warm start, the localised
    /// region, the cutter's stroke, the last contact): a replay seeks here without
    /// re-simulating. Absent in older recordings and at the last step.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub resume: Option<StepperResume>,
}

impl From<&Keyframe> for KeyframeMsg {
    fn from(k: &Keyframe) -> Self {
        Self {
            step: k.step,
            tick: k.tick,
            state_hash: Hex(k.hash.state),
            topology_hash: Hex(k.hash.topology),
            positions_m: k.positions.iter().map(|p| p.coords.into()).collect(),
            velocities_m_per_s: k.velocities.iter().map(|&v| v.into()).collect(),
            rest_positions_m: k.rest_positions.iter().map(|p| p.coords.into()).collect(),
            tets: k.tets.clone(),
            regions: k.regions.clone(),
            resume: k.resume.clone(),
        }
    }
}

impl KeyframeMsg {
    pub fn hash(&self) -> StateHash {
        StateHash {
            state: self.state_hash.0,
            topology: self.topology_hash.0,
        }
    }
}

/// Who and what a recording is of (the session metadata that is not a setting).
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
pub struct Provenance {
    /// Built-in scene name or scene file, as given (a replay loads it again).
    pub scene: String,
    #[serde(default)]
    pub min_tets: Option<usize>,
    pub seed: u64,
    pub trainee: String,
    pub exercise: String,
    pub device: String,
}

/// The session's settings a replay needs, and who did what (metadata `cutlab.session`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SessionMeta {
    pub cutlab_version: String,
    #[serde(flatten)]
    pub provenance: Provenance,
    pub clock: String,
    pub period_nanos: u64,
    pub time_step_nanos: u64,
    pub duration_s: f64,
    pub blade_length_m: f64,
    pub contact_reach_m: f64,
    pub contact_patch_radius_m: f64,
    pub cut_step_m: f64,
    pub keyframe_every_steps: u64,
    /// The session built its surface BVH again every this many steps (0, in older
    /// recordings: only after cuts); a replay does the same.
    #[serde(default)]
    pub collider_rebuild_every_steps: u64,
    pub surface_every_steps: u64,
    /// The simulation's localisation, when it ran localised (absent in older recordings:
    /// the scene's own solver settings).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub localisation: Option<cutlab_sim::solver::LocalisationSettings>,
    /// Hash of the settled scene before the first step.
    pub initial_state_hash: Hex,
    pub initial_topology_hash: Hex,
    /// Wall-clock start, seconds since the Unix epoch.
    pub started_unix_s: f64,
}

impl SessionMeta {
    /// As an MCAP metadata map (every value a string; floats in round-trip form).
    pub fn to_map(&self) -> Result<std::collections::BTreeMap<String, String>, RecorderError> {
        let value = serde_json::to_value(self)?;
        let mut map = std::collections::BTreeMap::new();
        if let serde_json::Value::Object(fields) = value {
            for (k, v) in fields {
                let s = match v {
                    serde_json::Value::String(s) => s,
                    serde_json::Value::Null => continue,
                    other => other.to_string(),
                };
                map.insert(k, s);
            }
        }
        Ok(map)
    }

    /// From an MCAP metadata map (numbers parsed back from their strings).
    pub fn from_map(
        map: &std::collections::BTreeMap<String, String>,
    ) -> Result<Self, RecorderError> {
        let mut fields = serde_json::Map::new();
        for (k, v) in map {
            let numeric = !matches!(
                k.as_str(),
                "cutlab_version"
                    | "scene"
                    | "trainee"
                    | "exercise"
                    | "device"
                    | "clock"
                    | "initial_state_hash"
                    | "initial_topology_hash"
            );
            let value = if numeric {
                serde_json::from_str(v).map_err(|e| {
                    RecorderError::Malformed(format!("session metadata {k}={v:?}: {e}"))
                })?
            } else {
                serde_json::Value::String(v.clone())
            };
            fields.insert(k.clone(), value);
        }
        serde_json::from_value(serde_json::Value::Object(fields))
            .map_err(|e| RecorderError::Malformed(format!("session metadata: {e}")))
    }
}

/// Protobuf pose of a tick.
pub fn pose_message(pose: &ToolPose, log_time_nanos: u64) -> foxglove::messages::PoseInFrame {
    use foxglove::messages::{Pose, PoseInFrame, Quaternion, Vector3 as FVector3};
    let q = pose.world_from_tool.quaternion();
    PoseInFrame {
        timestamp: Some(timestamp(log_time_nanos)),
        frame_id: WORLD_FRAME.to_owned(),
        pose: Some(Pose {
            position: Some(FVector3 {
                x: pose.tip_in_world.x,
                y: pose.tip_in_world.y,
                z: pose.tip_in_world.z,
            }),
            orientation: Some(Quaternion {
                x: q.i,
                y: q.j,
                z: q.k,
                w: q.w,
            }),
        }),
    }
}

/// A foxglove timestamp from session nanoseconds.
pub fn timestamp(nanos: u64) -> foxglove::messages::Timestamp {
    let sec = (nanos / 1_000_000_000).min(u32::MAX as u64) as u32;
    foxglove::messages::Timestamp::new(sec, (nanos % 1_000_000_000) as u32)
}

/// The tip and orientation of a decoded pose.
pub fn pose_of(msg: &foxglove::messages::PoseInFrame) -> Result<(Point3, Rotation), RecorderError> {
    let pose = msg
        .pose
        .as_ref()
        .ok_or_else(|| RecorderError::Malformed("pose without a pose".into()))?;
    let p = pose
        .position
        .as_ref()
        .ok_or_else(|| RecorderError::Malformed("pose without a position".into()))?;
    let q = pose
        .orientation
        .as_ref()
        .ok_or_else(|| RecorderError::Malformed("pose without an orientation".into()))?;
    // Exactly the recorded components: no renormalisation (replay needs the same bits).
    let rotation = Rotation::new_unchecked(nalgebra::Quaternion::new(q.w, q.x, q.y, q.z));
    Ok((Point3::new(p.x, p.y, p.z), rotation))
}

/// The tissue surface as a Foxglove scene entity (a triangle list).
pub fn surface_message(
    vertices: &[Point3],
    triangles: &[[u32; 3]],
    log_time_nanos: u64,
) -> foxglove::messages::SceneUpdate {
    use foxglove::messages::{
        Color, Point3 as FPoint3, SceneEntity, SceneUpdate, TriangleListPrimitive,
    };
    let points = vertices
        .iter()
        .map(|p| FPoint3 {
            x: p.x,
            y: p.y,
            z: p.z,
        })
        .collect();
    let indices = triangles.iter().flatten().copied().collect();
    SceneUpdate {
        deletions: Vec::new(),
        entities: vec![SceneEntity {
            timestamp: Some(timestamp(log_time_nanos)),
            frame_id: WORLD_FRAME.to_owned(),
            id: "tissue".to_owned(),
            frame_locked: true,
            triangles: vec![TriangleListPrimitive {
                points,
                indices,
                color: Some(Color {
                    r: 0.85,
                    g: 0.45,
                    b: 0.42,
                    a: 1.0,
                }),
                ..Default::default()
            }],
            ..Default::default()
        }],
    }
}
