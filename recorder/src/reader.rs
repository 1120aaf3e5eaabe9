//! Reading a recording back.
//!
//! [`Recording::open`] reads every record from the start of the file, checking chunk CRCs,
//! and stops at the first damage (a file cut short by a killed process ends inside a chunk):
//! everything up to the last complete chunk is kept, and [`Recording::damage`] says where and
//! why it stopped. A file is complete when it ends with its footer and magic.

use std::collections::{BTreeMap, HashMap};
use std::path::Path;

use cutlab_haptics::servo::ServoSample;
use cutlab_haptics::{Point3, Rotation};
use foxglove::Decode;
use mcap::read::Options;
use mcap::records::Record;

use crate::RecorderError;
use crate::channels::{
    self, KeyframeMsg, PlanMsg, SessionMeta, SimStepMsg, StateHashMsg, ToolStateMsg, TopologyMsg,
};

/// A channel as found in the file.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ChannelInfo {
    pub topic: String,
    pub schema: String,
    pub message_encoding: String,
    pub messages: u64,
}

/// Where reading stopped early, and why.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Damage {
    /// Records read before the damage.
    pub records_read: u64,
    pub reason: String,
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
    pub steps: Vec<SimStepMsg>,
    pub topology: Vec<TopologyMsg>,
    pub hashes: Vec<StateHashMsg>,
    pub keyframes: Vec<KeyframeMsg>,
    /// Surface snapshots (decoded only far enough to count them).
    pub surfaces: u64,
    /// First and last message log times, ns.
    pub log_time_range: Option<(u64, u64)>,
    /// The file ends with its footer and magic.
    pub complete: bool,
    pub damage: Option<Damage>,
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
        rec.damage = end.damage.map(|reason| Damage {
            records_read: end.records_read,
            reason,
        });
        rec.complete = end.complete;
        Ok(rec)
    }
    fn take_message(
        &mut self,
        topic: &str,
        log_time: u64,
        data: &[u8],
    ) -> Result<(), RecorderError> {
        match topic {
            channels::POSE => {
                let msg = foxglove::messages::PoseInFrame::decode(data)
                    .map_err(|e| malformed(topic, log_time, e))?;
                let (tip, rotation) =
                    channels::pose_of(&msg).map_err(|e| malformed(topic, log_time, e))?;
                let period = self
                    .meta
                    .as_ref()
                    .map_or(1_000_000, |m| m.period_nanos.max(1));
                self.poses.push((log_time / period, tip, rotation));
            }
            channels::TOOL_STATE => self.tool_states.push(parse(topic, log_time, data)?),
            channels::SIM_STEP => self.steps.push(parse(topic, log_time, data)?),
            channels::TOPOLOGY => self.topology.push(parse(topic, log_time, data)?),
            channels::STATE_HASH => self.hashes.push(parse(topic, log_time, data)?),
            channels::KEYFRAME => self.keyframes.push(parse(topic, log_time, data)?),
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

    /// An attachment's bytes by name.
    pub fn attachment(&self, name: &str) -> Option<&[u8]> {
        self.attachments
            .iter()
            .find(|a| a.0 == name)
            .map(|a| a.2.as_slice())
    }

    /// The planned incision, if attached.
    pub fn plan(&self) -> Result<Option<PlanMsg>, RecorderError> {
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
    /// tool state).
    pub fn samples(&self) -> BTreeMap<u64, ServoSample> {
        let poses: HashMap<u64, (Point3, Rotation)> =
            self.poses.iter().map(|&(t, p, r)| (t, (p, r))).collect();
        self.tool_states
            .iter()
            .filter_map(|s| poses.get(&s.tick).map(|&(p, r)| (s.tick, s.sample(p, r))))
            .collect()
    }

    /// Messages per topic.
    pub fn counts(&self) -> BTreeMap<String, u64> {
        self.channels
            .values()
            .map(|c| (c.topic.clone(), c.messages))
            .collect()
    }
}

/// How reading the records of a file ended.
#[derive(Debug, Clone, PartialEq, Eq)]
pub(crate) struct ReadEnd {
    pub records_read: u64,
    /// Why reading stopped before the end, if it did.
    pub damage: Option<String>,
    /// The file ended with its footer and magic.
    pub complete: bool,
}

/// Length of the prefix of `bytes` made of the magic and whole top-level records (opcode,
/// little-endian u64 length, body); the closing magic counts too. A record that claims more
/// bytes than the file has (a file cut short, or garbage) ends the prefix, so the MCAP parser
/// never sees it.
fn whole_records(bytes: &[u8]) -> (usize, Option<String>) {
    let magic = mcap::MAGIC.len();
    let mut at = magic;
    while at < bytes.len() {
        if bytes.len() - at == magic && &bytes[at..] == mcap::MAGIC {
            return (bytes.len(), None);
        }
        let Some(header) = bytes.get(at..at + 9) else {
            return (
                at,
                Some(format!("the file ends inside a record header at byte {at}")),
            );
        };
        let mut len = [0u8; 8];
        len.copy_from_slice(&header[1..]);
        let len = u64::from_le_bytes(len);
        match (at as u64 + 9).checked_add(len) {
            Some(end) if end <= bytes.len() as u64 => at = end as usize,
            _ => {
                return (
                    at,
                    Some(format!(
                        "the record at byte {at} (opcode 0x{:02x}) claims {len} bytes; {} are left",
                        header[0],
                        bytes.len() - at - 9
                    )),
                );
            }
        }
    }
    (at, None)
}

/// An error unless `bytes` start with the MCAP magic.
pub(crate) fn check_magic(bytes: &[u8]) -> Result<(), RecorderError> {
    if bytes.starts_with(mcap::MAGIC) {
        Ok(())
    } else {
        Err(RecorderError::NotCutlab(
            "not an MCAP file (no MCAP magic at the start)".into(),
        ))
    }
}

/// Calls `f` with every record of the file (chunks flattened, chunk CRCs checked), in file
/// order, until the first damage; `f`'s error ends the reading and is returned.
pub(crate) fn for_each_record(
    bytes: &[u8],
    mut f: impl FnMut(Record<'_>) -> Result<(), RecorderError>,
) -> Result<ReadEnd, RecorderError> {
    check_magic(bytes)?;
    let (prefix, mut damage) = whole_records(bytes);
    let readable = &bytes[..prefix];
    let mut records_read = 0u64;
    let mut footer = false;
    // The parser is given only whole records; should it still panic on a hostile record
    // inside a chunk, that is damage like any other, not a crash.
    let parsed = std::panic::catch_unwind(std::panic::AssertUnwindSafe(
        || -> Result<Option<String>, RecorderError> {
            for record in mcap::read::ChunkFlattener::new_with_options(
                readable,
                Options::IgnoreEndMagic | Options::ValidateChunkCrcs,
            )? {
                let record = match record {
                    Ok(r) => r,
                    Err(e) => return Ok(Some(e.to_string())),
                };
                records_read += 1;
                if matches!(record, Record::Footer(_)) {
                    footer = true;
                }
                f(record)?;
            }
            Ok(None)
        },
    ));
    match parsed {
        Ok(Ok(Some(e))) => damage = Some(e),
        Ok(Ok(None)) => {}
        Ok(Err(e)) => return Err(e),
        Err(_) => damage = Some("the MCAP parser failed on malformed data".into()),
    }
    let complete =
        damage.is_none() && footer && prefix == bytes.len() && bytes.ends_with(mcap::MAGIC);
    Ok(ReadEnd {
        records_read,
        damage,
        complete,
    })
}

fn parse<T: serde::de::DeserializeOwned>(
    topic: &str,
    log_time: u64,
    data: &[u8],
) -> Result<T, RecorderError> {
    serde_json::from_slice(data).map_err(|e| malformed(topic, log_time, e))
}
