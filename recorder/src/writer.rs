//! Writing a recording: [`McapSink`] encodes a session's records into an MCAP file (chunked,
//! zstd-compressed, indexed, with a summary), and [`spawn`] runs it on its own thread, fed by
//! a session's [`TapFeed`].
//!
//! Crash safety: the sink finishes its chunk and flushes the file at least every
//! `flush_interval` (default one second of wall time), so a killed process leaves a file
//! readable up to its last complete chunk (`cutlab recording recover` salvages it).

use std::borrow::Cow;
use std::collections::BTreeMap;
use std::fs::File;
use std::io::{BufWriter, Seek, Write};
use std::path::Path;
use std::time::{Duration, Instant};

use cutlab_haptics::servo::ServoSample;
use cutlab_haptics::tap::{SimRecord, TapFeed};
use foxglove::Encode;
use mcap::records::{MessageHeader, Metadata};

use crate::RecorderError;
use crate::channels::{
    self, KeyframeMsg, SessionMeta, SimStepMsg, StateHashMsg, ToolStateMsg, TopologyMsg,
};

/// Settings of the writer.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct WriterOptions {
    /// Longest wall time between two flushes to disk.
    pub flush_interval: Duration,
    /// Target size of a chunk before compression, bytes.
    pub chunk_size: u64,
}

impl Default for WriterOptions {
    fn default() -> Self {
        Self {
            flush_interval: Duration::from_secs(1),
            chunk_size: 1 << 20,
        }
    }
}

/// What was written.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct WriteStats {
    /// Messages per topic.
    pub messages: BTreeMap<String, u64>,
    /// Bytes of message payload before compression.
    pub payload_bytes: u64,
    /// Wall time spent encoding and writing, s.
    pub busy_s: f64,
    pub flushes: u64,
}

/// Channel ids of the recording.
#[derive(Debug, Clone, Copy)]
struct Ids {
    pose: u16,
    tool_state: u16,
    step: u16,
    topology: u16,
    state_hash: u16,
    keyframe: u16,
    surface: u16,
    damage: u16,
    /// The grasper's pose and state channels, added with its first tick.
    grasper: Option<(u16, u16)>,
}

/// An MCAP file being written.
pub struct McapSink<W: Write + Seek> {
    writer: mcap::Writer<W>,
    ids: Ids,
    period_nanos: u64,
    sequence: u32,
    buf: Vec<u8>,
    stats: WriteStats,
    last_flush: Instant,
    options: WriterOptions,
}

impl<W: Write + Seek> std::fmt::Debug for McapSink<W> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("McapSink")
            .field("period_nanos", &self.period_nanos)
            .field("stats", &self.stats)
            .finish_non_exhaustive()
    }
}

impl McapSink<BufWriter<File>> {
    /// Creates `path` (replacing it) and writes the header, the channels, the session
    /// metadata and the attachments `(name, media type, bytes)`.
    ///
    /// The file stays locked (an exclusive advisory lock) while the sink writes it, so another
    /// process can tell a recording being made from one whose writer died
    /// ([`recording_in_use`]); a file another sink is writing is refused, not truncated.
    pub fn create(
        path: &Path,
        meta: &SessionMeta,
        attachments: &[(&str, &str, Vec<u8>)],
        options: WriterOptions,
    ) -> Result<Self, RecorderError> {
        let io = |error| RecorderError::Io {
            path: path.to_owned(),
            error,
        };
        let file = std::fs::OpenOptions::new()
            .write(true)
            .create(true)
            .truncate(false)
            .open(path)
            .map_err(io)?;
        // a process asking whether the file is in use holds the lock for an instant: wait that
        let mut attempts = 0;
        loop {
            match file.try_lock() {
                Ok(()) => break,
                Err(std::fs::TryLockError::WouldBlock) if attempts < 20 => {
                    attempts += 1;
                    std::thread::sleep(std::time::Duration::from_millis(5));
                }
                Err(std::fs::TryLockError::WouldBlock) => {
                    return Err(io(std::io::Error::new(
                        std::io::ErrorKind::ResourceBusy,
                        "another session is recording to this file",
                    )));
                }
                Err(std::fs::TryLockError::Error(e)) => return Err(io(e)),
            }
        }
        file.set_len(0).map_err(io)?;
        Self::new(
            BufWriter::with_capacity(1 << 16, file),
            meta,
            attachments,
            options,
        )
    }
}

/// Whether a sink ([`McapSink::create`]) of any process is writing the recording at `path`
/// now: its lock is held. A process that died lets go of it, so a recording that is not in
/// use and whose session never ended was cut short.
pub fn recording_in_use(path: &Path) -> std::io::Result<bool> {
    let file = File::open(path)?;
    match file.try_lock() {
        Ok(()) => Ok(false),
        Err(std::fs::TryLockError::WouldBlock) => Ok(true),
        Err(std::fs::TryLockError::Error(e)) => Err(e),
    }
}

fn protobuf_schema<T: Encode>() -> Result<foxglove::Schema, RecorderError> {
    T::get_schema()
        .ok_or_else(|| RecorderError::Encode("a Foxglove message without a schema".into()))
}

impl<W: Write + Seek> McapSink<W> {
    pub fn new(
        out: W,
        meta: &SessionMeta,
        attachments: &[(&str, &str, Vec<u8>)],
        options: WriterOptions,
    ) -> Result<Self, RecorderError> {
        let mut writer = mcap::WriteOptions::new()
            .compression(Some(mcap::Compression::Zstd))
            .chunk_size(Some(options.chunk_size))
            .profile("cutlab")
            .library(format!("cutlab {}", env!("CARGO_PKG_VERSION")))
            .create(out)?;
        let no_meta = BTreeMap::new();
        let protobuf = |w: &mut mcap::Writer<W>,
                        schema: foxglove::Schema,
                        topic: &str|
         -> Result<u16, RecorderError> {
            let id = w.add_schema(&schema.name, &schema.encoding, &schema.data)?;
            Ok(w.add_channel(id, topic, "protobuf", &no_meta)?)
        };
        let pose = protobuf(
            &mut writer,
            protobuf_schema::<foxglove::messages::PoseInFrame>()?,
            channels::POSE,
        )?;
        let surface = protobuf(
            &mut writer,
            protobuf_schema::<foxglove::messages::SceneUpdate>()?,
            channels::SURFACE,
        )?;
        let mut json = [0u16; 6];
        for (slot, (topic, name, schema)) in json.iter_mut().zip(channels::JSON_CHANNELS) {
            let id = writer.add_schema(name, "jsonschema", schema.as_bytes())?;
            *slot = writer.add_channel(id, topic, "json", &no_meta)?;
        }
        let [tool_state, step, topology, state_hash, keyframe, damage] = json;
        writer.write_metadata(&Metadata {
            name: channels::SESSION_METADATA.into(),
            metadata: meta.to_map()?,
        })?;
        for (name, media_type, data) in attachments {
            writer.attach(&mcap::Attachment {
                log_time: 0,
                create_time: 0,
                name: (*name).to_owned(),
                media_type: (*media_type).to_owned(),
                data: Cow::Borrowed(data),
            })?;
        }
        writer.flush()?;
        Ok(Self {
            writer,
            ids: Ids {
                pose,
                tool_state,
                step,
                topology,
                state_hash,
                keyframe,
                surface,
                damage,
                grasper: None,
            },
            period_nanos: meta.period_nanos,
            sequence: 0,
            buf: Vec::with_capacity(1 << 12),
            stats: WriteStats::default(),
            last_flush: Instant::now(),
            options,
        })
    }

    fn write(&mut self, channel_id: u16, topic: &str, tick: u64) -> Result<(), RecorderError> {
        let time = tick.saturating_mul(self.period_nanos);
        self.sequence = self.sequence.wrapping_add(1);
        let header = MessageHeader {
            channel_id,
            sequence: self.sequence,
            log_time: time,
            publish_time: time,
        };
        self.writer.write_to_known_channel(&header, &self.buf)?;
        self.stats.payload_bytes += self.buf.len() as u64;
        *self.stats.messages.entry(topic.to_owned()).or_default() += 1;
        Ok(())
    }

    fn write_json<T: serde::Serialize>(
        &mut self,
        channel_id: u16,
        topic: &str,
        tick: u64,
        msg: &T,
    ) -> Result<(), RecorderError> {
        self.buf.clear();
        serde_json::to_writer(&mut self.buf, msg)?;
        self.write(channel_id, topic, tick)
    }

    fn write_protobuf<T: Encode>(
        &mut self,
        channel_id: u16,
        topic: &str,
        tick: u64,
        msg: &T,
    ) -> Result<(), RecorderError> {
        self.buf.clear();
        msg.encode(&mut self.buf)
            .map_err(|e| RecorderError::Encode(e.to_string()))?;
        self.write(channel_id, topic, tick)
    }

    /// The grasper's channels, added the first time a tick has a grasper.
    fn grasper_channels(&mut self) -> Result<(u16, u16), RecorderError> {
        if let Some(ids) = self.ids.grasper {
            return Ok(ids);
        }
        let no_meta = BTreeMap::new();
        let schema = protobuf_schema::<foxglove::messages::PoseInFrame>()?;
        let id = self
            .writer
            .add_schema(&schema.name, &schema.encoding, &schema.data)?;
        let pose = self
            .writer
            .add_channel(id, channels::GRASPER_POSE, "protobuf", &no_meta)?;
        let (name, json_schema) = channels::GRASPER_STATE_SCHEMA;
        let id = self
            .writer
            .add_schema(name, "jsonschema", json_schema.as_bytes())?;
        let state = self
            .writer
            .add_channel(id, channels::GRASPER_STATE, "json", &no_meta)?;
        self.ids.grasper = Some((pose, state));
        Ok((pose, state))
    }

    /// Records one servo tick: the pose and what the servo loop rendered.
    pub fn on_tick(&mut self, sample: &ServoSample) -> Result<(), RecorderError> {
        let began = Instant::now();
        let time = sample.tick.saturating_mul(self.period_nanos);
        self.write_protobuf(
            self.ids.pose,
            channels::POSE,
            sample.tick,
            &channels::pose_message(&sample.pose, time),
        )?;
        self.write_json(
            self.ids.tool_state,
            channels::TOOL_STATE,
            sample.tick,
            &ToolStateMsg::of(sample),
        )?;
        if let Some(grasper) = &sample.grasper {
            let (pose, state) = self.grasper_channels()?;
            self.write_protobuf(
                pose,
                channels::GRASPER_POSE,
                sample.tick,
                &channels::pose_message(&grasper.pose, time),
            )?;
            let msg = channels::GrasperStateMsg {
                tick: sample.tick,
                buttons: grasper.pose.buttons,
                pull_newtons: grasper.pull_newtons.into(),
            };
            self.write_json(state, channels::GRASPER_STATE, sample.tick, &msg)?;
        }
        self.stats.busy_s += began.elapsed().as_secs_f64();
        self.flush_if_due()
    }

    /// Records one record of the simulation thread.
    pub fn on_sim(&mut self, record: &SimRecord) -> Result<(), RecorderError> {
        let began = Instant::now();
        match record {
            &SimRecord::Step {
                step,
                tick,
                rejected,
            } => self.write_json(
                self.ids.step,
                channels::SIM_STEP,
                tick,
                &SimStepMsg {
                    step,
                    tick,
                    rejected,
                },
            )?,
            SimRecord::Cut {
                step,
                tick,
                blade,
                event,
            } => {
                let msg = TopologyMsg {
                    step: *step,
                    tick: *tick,
                    blade: blade.into(),
                    event: (**event).clone(),
                };
                self.write_json(self.ids.topology, channels::TOPOLOGY, *tick, &msg)?;
            }
            &SimRecord::Damage { step, tick, damage } => {
                let msg = channels::TissueDamageMsg {
                    step,
                    tick,
                    kind: damage.kind,
                    region: damage.region,
                };
                self.write_json(self.ids.damage, channels::DAMAGE, tick, &msg)?;
            }
            SimRecord::Keyframe(k) => {
                let hash = StateHashMsg {
                    step: k.step,
                    tick: k.tick,
                    state: channels::Hex(k.hash.state),
                    topology: channels::Hex(k.hash.topology),
                };
                self.write_json(self.ids.state_hash, channels::STATE_HASH, k.tick, &hash)?;
                self.write_json(
                    self.ids.keyframe,
                    channels::KEYFRAME,
                    k.tick,
                    &KeyframeMsg::from(&**k),
                )?;
            }
            SimRecord::Surface(s) => {
                let msg = channels::surface_message(
                    &s.vertices,
                    &s.triangles,
                    s.tick.saturating_mul(self.period_nanos),
                );
                self.write_protobuf(self.ids.surface, channels::SURFACE, s.tick, &msg)?;
            }
        }
        self.stats.busy_s += began.elapsed().as_secs_f64();
        self.flush_if_due()
    }

    fn flush_if_due(&mut self) -> Result<(), RecorderError> {
        if self.last_flush.elapsed() >= self.options.flush_interval {
            self.flush()?;
        }
        Ok(())
    }

    /// Ends the current chunk and writes everything to the file.
    pub fn flush(&mut self) -> Result<(), RecorderError> {
        self.writer.flush()?;
        self.stats.flushes += 1;
        self.last_flush = Instant::now();
        Ok(())
    }

    pub fn stats(&self) -> &WriteStats {
        &self.stats
    }

    /// Writes `end` as the `cutlab.session_end` metadata, then the summary and footer.
    pub fn finish(mut self, end: &BTreeMap<String, String>) -> Result<WriteStats, RecorderError> {
        self.writer.write_metadata(&Metadata {
            name: channels::SESSION_END_METADATA.into(),
            metadata: end.clone(),
        })?;
        self.writer.finish()?;
        self.writer
            .into_inner()
            .flush()
            .map_err(|source| RecorderError::Io {
                path: "recording".into(),
                error: source,
            })?;
        Ok(self.stats)
    }
}

/// Something else that wants every record (the rerun logger).
pub trait RecordObserver: Send {
    fn on_tick(&mut self, sample: &ServoSample) -> Result<(), RecorderError>;
    fn on_sim(&mut self, record: &SimRecord) -> Result<(), RecorderError>;
    /// Sends what is buffered and closes (the last call).
    fn finish(self: Box<Self>) -> Result<(), RecorderError> {
        Ok(())
    }
}

/// Several observers, each given every record in turn (a rerun log and a live view, say);
/// the first error ends the call, and finishing finishes every one (the first error is
/// returned).
impl RecordObserver for Vec<Box<dyn RecordObserver>> {
    fn on_tick(&mut self, sample: &ServoSample) -> Result<(), RecorderError> {
        self.iter_mut().try_for_each(|o| o.on_tick(sample))
    }
    fn on_sim(&mut self, record: &SimRecord) -> Result<(), RecorderError> {
        self.iter_mut().try_for_each(|o| o.on_sim(record))
    }
    fn finish(self: Box<Self>) -> Result<(), RecorderError> {
        let results: Vec<_> = self.into_iter().map(|o| o.finish()).collect();
        results.into_iter().collect()
    }
}

impl RecordObserver for crate::RerunSink {
    fn on_tick(&mut self, sample: &ServoSample) -> Result<(), RecorderError> {
        Ok(crate::RerunSink::on_tick(self, sample)?)
    }
    fn on_sim(&mut self, record: &SimRecord) -> Result<(), RecorderError> {
        Ok(crate::RerunSink::on_sim(self, record)?)
    }
    fn finish(self: Box<Self>) -> Result<(), RecorderError> {
        Ok(crate::RerunSink::finish(*self)?)
    }
}

/// The writer thread's result: the sink (flushed, not yet finished: the caller adds the
/// session's end metadata) and the observer.
pub type WriterOutcome<W> = (McapSink<W>, Option<Box<dyn RecordObserver>>);

/// Runs `sink` on a thread named `cutlab-recorder` until both queues of `feed` have ended;
/// records go to `observer` too. An error stops the writing, drops the feed (the session
/// goes on unrecorded and says so) and is returned by the join.
pub fn spawn<W: Write + Seek + Send + 'static>(
    mut sink: McapSink<W>,
    mut feed: TapFeed,
    mut observer: Option<Box<dyn RecordObserver>>,
) -> std::io::Result<std::thread::JoinHandle<Result<WriterOutcome<W>, RecorderError>>> {
    std::thread::Builder::new()
        .name("cutlab-recorder".into())
        .spawn(move || {
            loop {
                let mut idle = true;
                // ticks first: their queue is the one that drops when full
                while let Ok(sample) = feed.ticks.pop() {
                    idle = false;
                    sink.on_tick(&sample)?;
                    if let Some(o) = observer.as_mut() {
                        o.on_tick(&sample)?;
                    }
                }
                if let Ok(record) = feed.sim.pop() {
                    idle = false;
                    sink.on_sim(&record)?;
                    if let Some(o) = observer.as_mut() {
                        o.on_sim(&record)?;
                    }
                }
                if feed.ended() {
                    break;
                }
                if idle {
                    sink.flush_if_due()?;
                    std::thread::sleep(Duration::from_micros(500));
                }
            }
            sink.flush()?;
            Ok((sink, observer))
        })
}
