//! Reading a recording back.
//!
//! [`Recording::open`] reads every record from the start of the file, checking chunk CRCs,
//! and stops at the first damage (a file cut short by a killed process ends inside a chunk; a
//! flipped bit fails a chunk's CRC): everything before the damaged record is kept, and
//! [`Recording::damage`] says where and why it stopped ([`crate::scan`] bounds what a corrupt
//! length may allocate). A file is complete when it ends with its footer and magic and nothing
//! in it is damaged; [`Recording::announced`] is what its summary says it holds, read from the
//! end of the file, so a file damaged in the middle still tells how much was lost.

use std::collections::{BTreeMap, HashMap};
use std::path::Path;

use cutlab_haptics::plan::Plan;
use cutlab_haptics::servo::{GrasperTick, ServoSample};
use cutlab_haptics::{Point3, Rotation, ToolPose};
use foxglove::Decode;
use mcap::records::Record;

use crate::RecorderError;
use crate::channels::{
    self, KeyframeMsg, SessionMeta, SimStepMsg, StateHashMsg, ToolStateMsg, TopologyMsg,
};
use crate::scan::{Announced, Damage, for_each_record};

/// A channel as found in the file.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ChannelInfo {
    pub topic: String,
    pub schema: String,
    pub message_encoding: String,
    pub messages: u64,
}

/// A recording, read back.
#[derive(Debug, Default)]
pub struct Recording {
    pub meta: Option<SessionMeta>,
    /// The `cutlab.session_end` metadata (present when the session ended cleanly).
    pub end: Option<BTreeMap<String, String>>,
    /// Every metadata record, in order.
    pub metadata: Vec<(String, BTreeMap<String, String>)>,
    /// `(name, media type, bytes)`.
    pub attachments: Vec<(String, String, Vec<u8>)>,
    /// Channels by id.
    pub channels: BTreeMap<u16, ChannelInfo>,
    /// Pose of every recorded tick: `(tick, tip, world_from_tool)`.
    pub poses: Vec<(u64, Point3, Rotation)>,
    pub tool_states: Vec<ToolStateMsg>,
    /// The grasper's poses (tick, jaws' centre, orientation), in a session with one.
    pub grasper_poses: Vec<(u64, Point3, Rotation)>,
    /// The grasper's states, in a session with one.
    pub grasper_states: Vec<channels::GrasperStateMsg>,
    pub steps: Vec<SimStepMsg>,
    pub topology: Vec<TopologyMsg>,
    pub hashes: Vec<StateHashMsg>,
    pub keyframes: Vec<KeyframeMsg>,
    /// Harm done to tissue that should not be cut, in order.
    pub tissue_damage: Vec<channels::TissueDamageMsg>,
    /// Surface snapshots (decoded only far enough to count them).
    pub surfaces: u64,
    /// First and last message log times, ns.
    pub log_time_range: Option<(u64, u64)>,
    /// The file ends with its footer and magic, and nothing in it is damaged.
    pub complete: bool,
    pub damage: Option<Damage>,
    /// What the file's summary says it holds (absent in a file cut short).
    pub announced: Option<Announced>,
    pub file_bytes: u64,
}

fn malformed(topic: &str, log_time: u64, e: impl std::fmt::Display) -> RecorderError {
    RecorderError::Malformed(format!(
        "{topic} message at {:.3} s: {e}",
        log_time as f64 * 1e-9
    ))
}

impl Recording {
    pub fn open(path: &Path) -> Result<Self, RecorderError> {
        let bytes = std::fs::read(path).map_err(|source| RecorderError::Io {
            path: path.to_owned(),
            error: source,
        })?;
        Self::from_bytes(&bytes)
    }

    pub fn from_bytes(bytes: &[u8]) -> Result<Self, RecorderError> {
        let mut rec = Recording {
            file_bytes: bytes.len() as u64,
            ..Default::default()
        };
        let mut schemas: HashMap<u16, String> = HashMap::new();
        let end = for_each_record(bytes, |record| {
            match record {
                Record::Schema { header, .. } => {
                    schemas.insert(header.id, header.name);
                }
                Record::Channel(c) => {
                    let schema = schemas.get(&c.schema_id).cloned().unwrap_or_default();
                    rec.channels.entry(c.id).or_insert(ChannelInfo {
                        topic: c.topic,
                        schema,
                        message_encoding: c.message_encoding,
                        messages: 0,
                    });
                }
                Record::Message { header, data } => {
                    let Some(channel) = rec.channels.get_mut(&header.channel_id) else {
                        return Err(RecorderError::Malformed(format!(
                            "message on unknown channel {}",
                            header.channel_id
                        )));
                    };
                    channel.messages += 1;
                    let topic = channel.topic.clone();
                    rec.log_time_range = Some(match rec.log_time_range {
                        None => (header.log_time, header.log_time),
                        Some((a, b)) => (a.min(header.log_time), b.max(header.log_time)),
                    });
                    rec.take_message(&topic, header.log_time, &data)?;
                }
                Record::Metadata(m) => {
                    if m.name == channels::SESSION_METADATA {
                        rec.meta = Some(SessionMeta::from_map(&m.metadata)?);
                    } else if m.name == channels::SESSION_END_METADATA {
                        rec.end = Some(m.metadata.clone());
                    }
                    rec.metadata.push((m.name, m.metadata));
                }
                Record::Attachment { header, data, .. } => {
                    rec.attachments
                        .push((header.name, header.media_type, data.into_owned()))
                }
                _ => {}
            }
            Ok(())
        })?;
        rec.damage = end.damage;
        rec.complete = end.complete;
        rec.announced = crate::scan::announced(bytes);
        Ok(rec)
    }
    fn take_message(
        &mut self,
        topic: &str,
        log_time: u64,
        data: &[u8],
    ) -> Result<(), RecorderError> {
        match topic {
            channels::POSE | channels::GRASPER_POSE => {
                let msg = foxglove::messages::PoseInFrame::decode(data)
                    .map_err(|e| malformed(topic, log_time, e))?;
                let (tip, rotation) =
                    channels::pose_of(&msg).map_err(|e| malformed(topic, log_time, e))?;
                let period = self
                    .meta
                    .as_ref()
                    .map_or(1_000_000, |m| m.period_nanos.max(1));
                let pose = (log_time / period, tip, rotation);
                match topic {
                    channels::POSE => self.poses.push(pose),
                    _ => self.grasper_poses.push(pose),
                }
            }
            channels::GRASPER_STATE => self.grasper_states.push(parse(topic, log_time, data)?),
            channels::TOOL_STATE => self.tool_states.push(parse(topic, log_time, data)?),
            channels::SIM_STEP => self.steps.push(parse(topic, log_time, data)?),
            channels::TOPOLOGY => self.topology.push(parse(topic, log_time, data)?),
            channels::STATE_HASH => self.hashes.push(parse(topic, log_time, data)?),
            channels::KEYFRAME => self.keyframes.push(parse(topic, log_time, data)?),
            channels::DAMAGE => self.tissue_damage.push(parse(topic, log_time, data)?),
            channels::SURFACE => self.surfaces += 1,
            _ => {}
        }
        Ok(())
    }

    /// The session metadata, or a clear error when the file has none.
    pub fn meta(&self) -> Result<&SessionMeta, RecorderError> {
        self.meta
            .as_ref()
            .ok_or_else(|| RecorderError::NotCutlab("no cutlab.session metadata".into()))
    }

    /// The pieces the session's cuts freed, with the step and tick that freed each, in order.
    pub fn specimens(&self) -> impl Iterator<Item = (u64, u64, &cutlab_sim::cut::Specimen)> {
        self.topology
            .iter()
            .flat_map(|t| t.event.specimens.iter().map(move |s| (t.step, t.tick, s)))
    }

    /// An attachment's bytes by name.
    pub fn attachment(&self, name: &str) -> Option<&[u8]> {
        self.attachments
            .iter()
            .find(|a| a.0 == name)
            .map(|a| a.2.as_slice())
    }

    /// What the hand followed, if attached.
    pub fn plan(&self) -> Result<Option<Plan>, RecorderError> {
        self.attachment(channels::PLAN_ATTACHMENT)
            .map(|b| {
                serde_json::from_slice(b)
                    .map_err(|e| RecorderError::Malformed(format!("plan attachment: {e}")))
            })
            .transpose()
    }

    /// Seconds between the first and the last message.
    pub fn duration_s(&self) -> f64 {
        self.log_time_range
            .map_or(0.0, |(a, b)| (b - a) as f64 * 1e-9)
    }

    /// The servo sample of every recorded tick, by tick (a tick needs both its pose and its
    /// tool state; its grasper, in a session with one, both the grasper's pose and state).
    pub fn samples(&self) -> BTreeMap<u64, ServoSample> {
        let poses: HashMap<u64, (Point3, Rotation)> =
            self.poses.iter().map(|&(t, p, r)| (t, (p, r))).collect();
        let grasper_poses: HashMap<u64, (Point3, Rotation)> = self
            .grasper_poses
            .iter()
            .map(|&(t, p, r)| (t, (p, r)))
            .collect();
        let grasper: HashMap<u64, GrasperTick> = self
            .grasper_states
            .iter()
            .filter_map(|s| {
                grasper_poses
                    .get(&s.tick)
                    .map(|&(tip_in_world, world_from_tool)| {
                        let pose = ToolPose {
                            tip_in_world,
                            world_from_tool,
                            buttons: s.buttons,
                        };
                        let pull_newtons = s.pull_newtons.into();
                        (s.tick, GrasperTick { pose, pull_newtons })
                    })
            })
            .collect();
        self.tool_states
            .iter()
            .filter_map(|s| {
                let &(tip, rotation) = poses.get(&s.tick)?;
                let mut sample = s.sample(tip, rotation);
                sample.grasper = grasper.get(&s.tick).copied();
                Some((s.tick, sample))
            })
            .collect()
    }

    /// Simulation steps the file's summary announces (`None` without a readable summary).
    pub fn announced_steps(&self) -> Option<u64> {
        let a = self.announced.as_ref()?;
        Some(a.messages.get(channels::SIM_STEP).copied().unwrap_or(0))
    }

    /// Everything the session wrote was read: the file is complete, nothing in it is damaged,
    /// and every step its summary announces is here.
    pub fn is_whole(&self) -> bool {
        self.complete
            && self.damage.is_none()
            && self
                .announced_steps()
                .is_none_or(|n| n == self.steps.len() as u64)
    }

    /// Log time of the last message read and of the last the summary announces, s.
    pub fn readable_s(&self) -> (f64, Option<f64>) {
        let read = self.log_time_range.map_or(0.0, |(_, b)| b as f64 * 1e-9);
        let announced = self
            .announced
            .as_ref()
            .map(|a| a.message_end_time as f64 * 1e-9);
        (read, announced)
    }

    /// What is missing from a recording that is not whole, in a line ("damaged at byte N
    /// (chunk CRC); 1.80 of 3.00 s readable"); `None` for a whole one.
    pub fn shortfall(&self) -> Option<String> {
        if self.is_whole() {
            return None;
        }
        let why = match &self.damage {
            Some(d) => d.to_string(),
            None => format!(
                "{} of the {} steps its summary announces are readable",
                self.steps.len(),
                self.announced_steps().unwrap_or(0)
            ),
        };
        Some(match self.readable_s() {
            (read, Some(total)) => format!("{why}; {read:.2} of {total:.2} s readable"),
            (read, None) => format!("{why}; {read:.2} s readable, the total is unknown"),
        })
    }

    /// Messages per topic.
    pub fn counts(&self) -> BTreeMap<String, u64> {
        self.channels
            .values()
            .map(|c| (c.topic.clone(), c.messages))
            .collect()
    }
}

fn parse<T: serde::de::DeserializeOwned>(
    topic: &str,
    log_time: u64,
    data: &[u8],
) -> Result<T, RecorderError> {
    serde_json::from_slice(data).map_err(|e| malformed(topic, log_time, e))
}
