//! Walking the records of a recording that may be damaged, without trusting a length in it.
//!
//! Every reader of recordings (the [`Recording`](crate::Recording) reader, recovery, replay,
//! the assessor and the dashboard's trace, all through [`for_each_record`]) goes through here,
//! so one place decides what a corrupt length may make the process allocate:
//!
//! - a top-level record is passed to the MCAP parser only when the file holds all the bytes its
//!   length claims ([`record_spans`]);
//! - a record inside a chunk, and a chunk's decompressed size, may not exceed
//!   [`record_length_limit`] of the file's size, so a flipped bit in a chunk's
//!   `uncompressed_size` is an error ("damaged at byte N"), never an allocation of exabytes;
//! - a chunk's CRC is checked before any of its records is handed on, so the records of a
//!   damaged chunk are never read as if they were good;
//! - every length inside a record (a string, a map, an attachment's data) is checked to fit
//!   the record before the MCAP parser, which reserves a declared length, sees it.
//!
//! Damage is either the file ending early (a killed process, a full disk: [`DamageKind::EndsEarly`])
//! or bytes that are wrong ([`DamageKind::Corrupt`]), each with the offset of the top-level record
//! where reading stopped.

use std::collections::BTreeMap;
use std::fmt;

use mcap::records::Record;
use mcap::sans_io::linear_reader::{LinearReadEvent, LinearReader, LinearReaderOptions};

use crate::RecorderError;

/// Opcodes of the MCAP records this module looks at by hand (MCAP specification, "Records").
const OP_FOOTER: u8 = 0x02;
const OP_CHANNEL: u8 = 0x04;
const OP_STATISTICS: u8 = 0x0b;
/// Opcode and length of a record.
const RECORD_HEADER_BYTES: usize = 9;
/// The footer's body: summary start, summary offset start (u64 each), summary CRC (u32).
const FOOTER_BODY_BYTES: usize = 20;

/// The largest record (or decompressed chunk) a file of `file_bytes` may contain: 64 times the
/// file's size (zstd on cutlab's JSON and protobuf messages stays far below that), at least
/// 64 MiB and at most 1 GiB, so no corrupt length can ask for more.
pub fn record_length_limit(file_bytes: usize) -> usize {
    const MIB: usize = 1 << 20;
    file_bytes.saturating_mul(64).clamp(64 * MIB, 1024 * MIB)
}

/// Whether reading stopped because the file ends early or because its bytes are wrong.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum DamageKind {
    /// The file ends inside a record or without its footer: cut short (a killed process, a
    /// full disk). What comes before is as it was written.
    EndsEarly,
    /// A record in the file is wrong: a chunk's CRC fails, a length runs past a file that does
    /// end with its footer, a record does not parse.
    Corrupt,
}

/// Where reading stopped early, and why.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Damage {
    /// Records read before the damage.
    pub records_read: u64,
    /// Offset of the top-level record (often a chunk) where reading stopped, bytes.
    pub byte: u64,
    pub kind: DamageKind,
    /// What was wrong there, e.g. "chunk CRC".
    pub reason: String,
}

impl fmt::Display for Damage {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self.kind {
            DamageKind::EndsEarly => {
                write!(f, "ends early at byte {} ({})", self.byte, self.reason)
            }
            DamageKind::Corrupt => write!(f, "damaged at byte {} ({})", self.byte, self.reason),
        }
    }
}

/// How reading the records of a file ended.
#[derive(Debug, Clone, PartialEq, Eq)]
pub(crate) struct ReadEnd {
    pub records_read: u64,
    /// Why reading stopped before the end, if it did.
    pub damage: Option<Damage>,
    /// The file ended with its footer and magic, and nothing in it was damaged.
    pub complete: bool,
}

/// A top-level record of a file, as its framing (opcode and length) gives it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct RecordSpan {
    /// Offset of the record's opcode, bytes.
    pub at: usize,
    pub opcode: u8,
    /// The length of the body its header claims, bytes.
    pub len: u64,
    /// Offset just past its body; `None` when the file ends before that.
    pub end: Option<usize>,
}

/// The top-level records of `bytes` after the opening magic, from their framing alone
/// (opcode, little-endian u64 length, body), up to the closing magic; a record whose length
/// runs past the end of the file is the last one yielded. Nothing is parsed or allocated.
pub fn record_spans(bytes: &[u8]) -> impl Iterator<Item = RecordSpan> + '_ {
    spans_from(bytes, mcap::MAGIC.len())
}

/// [`record_spans`] from offset `start` on.
fn spans_from(bytes: &[u8], start: usize) -> impl Iterator<Item = RecordSpan> + '_ {
    let magic = mcap::MAGIC.len();
    let mut at = Some(start);
    std::iter::from_fn(move || {
        let here = at?;
        if bytes.len().checked_sub(here) == Some(magic) && &bytes[here..] == mcap::MAGIC {
            return None;
        }
        let (opcode, len) = record_header(bytes, here)?;
        let end = (here as u64)
            .checked_add(RECORD_HEADER_BYTES as u64)
            .and_then(|start| start.checked_add(len))
            .filter(|&end| end <= bytes.len() as u64)
            .map(|end| end as usize);
        at = end;
        Some(RecordSpan {
            at: here,
            opcode,
            len,
            end,
        })
    })
}

/// The length of the prefix of `bytes` made of the magic and whole top-level records, the
/// closing magic included, and the offset and reason of what ends it early, if anything
/// does. A record that claims more bytes than the file has ends the prefix, so the MCAP
/// parser never sees it.
fn whole_records(bytes: &[u8]) -> (usize, Option<(usize, String)>) {
    let mut prefix = mcap::MAGIC.len();
    for span in record_spans(bytes) {
        let Some(end) = span.end else {
            let left = bytes.len() - span.at - RECORD_HEADER_BYTES;
            let why = format!(
                "a record (opcode 0x{:02x}) claims {} bytes; {left} are left",
                span.opcode, span.len
            );
            return (span.at, Some((span.at, why)));
        };
        prefix = end;
    }
    if bytes.len() - prefix == mcap::MAGIC.len() && &bytes[prefix..] == mcap::MAGIC {
        (bytes.len(), None)
    } else if prefix < bytes.len() {
        let why = "the file ends inside a record header".to_owned();
        (prefix, Some((prefix, why)))
    } else {
        (prefix, None)
    }
}

/// The opcode and length of the record at `at`, if the file holds its header.
fn record_header(bytes: &[u8], at: usize) -> Option<(u8, u64)> {
    let header = bytes.get(at..at.checked_add(RECORD_HEADER_BYTES)?)?;
    let len = u64::from_le_bytes(header[1..].try_into().ok()?);
    Some((header[0], len))
}

/// The offset of the top-level record of `bytes` that holds byte `pos` (the magic counts as
/// the record at 0).
fn record_holding(bytes: &[u8], pos: usize) -> usize {
    if pos < mcap::MAGIC.len() {
        return 0;
    }
    record_spans(bytes)
        .take_while(|s| s.at <= pos)
        .last()
        .map_or(mcap::MAGIC.len(), |s| s.at)
}

/// Reads the length-prefixed fields of a record's body without allocating, to check that each
/// length fits what is left (the MCAP parser reserves a declared length before reading it).
struct Fields<'a>(&'a [u8]);

impl<'a> Fields<'a> {
    fn skip(&mut self, n: usize) -> Option<&'a [u8]> {
        let (head, rest) = self.0.split_at_checked(n)?;
        self.0 = rest;
        Some(head)
    }
    fn len_u32(&mut self) -> Option<usize> {
        let b = self.skip(4)?;
        usize::try_from(u32::from_le_bytes(b.try_into().ok()?)).ok()
    }
    fn len_u64(&mut self) -> Option<usize> {
        let b = self.skip(8)?;
        usize::try_from(u64::from_le_bytes(b.try_into().ok()?)).ok()
    }
    /// A string or a byte array with a u32 length.
    fn string(&mut self) -> Option<()> {
        let n = self.len_u32()?;
        self.skip(n).map(|_| ())
    }
    /// A map of strings to strings with a u32 byte length.
    fn string_map(&mut self) -> Option<()> {
        let n = self.len_u32()?;
        let mut map = Fields(self.skip(n)?);
        while !map.0.is_empty() {
            map.string()?;
            map.string()?;
        }
        Some(())
    }
    /// A map of fixed-size entries with a u32 byte length.
    fn fixed_map(&mut self, entry: usize) -> Option<()> {
        let n = self.len_u32()?;
        (n % entry == 0).then_some(())?;
        self.skip(n).map(|_| ())
    }
}

/// Whether every length inside a record of `opcode` fits its body (MCAP specification,
/// "Records"); records without lengths inside pass.
fn lengths_fit(opcode: u8, body: &[u8]) -> bool {
    let mut f = Fields(body);
    let fit = match opcode {
        // header: profile, library
        0x01 => f.string().and_then(|()| f.string()),
        // schema: id, name, encoding, data
        0x03 => f
            .skip(2)
            .and_then(|_| f.string())
            .and_then(|()| f.string())
            .and_then(|()| f.string()),
        // channel: id, schema id, topic, message encoding, metadata
        0x04 => f
            .skip(4)
            .and_then(|_| f.string())
            .and_then(|()| f.string())
            .and_then(|()| f.string_map()),
        // message index: channel id, (log time, offset) pairs
        0x07 => f.skip(2).and_then(|_| f.fixed_map(16)),
        // chunk index: times, offset, length, message index offsets, index length,
        // compression, sizes
        0x08 => f
            .skip(32)
            .and_then(|_| f.fixed_map(10))
            .and_then(|()| f.skip(8))
            .and_then(|_| f.string()),
        // attachment: times, name, media type, data (u64 length)
        0x09 => f
            .skip(16)
            .and_then(|_| f.string())
            .and_then(|()| f.string())
            .and_then(|()| f.len_u64())
            .and_then(|n| f.skip(n).map(|_| ())),
        // attachment index: offset, length, times, data size, name, media type
        0x0a => f
            .skip(40)
            .and_then(|_| f.string())
            .and_then(|()| f.string()),
        // statistics: counts and times, then message counts per channel
        0x0b => f.skip(42).and_then(|_| f.fixed_map(10)),
        // metadata: name, metadata
        0x0c => f.string().and_then(|()| f.string_map()),
        // metadata index: offset, length, name
        0x0d => f.skip(16).and_then(|_| f.string()),
        _ => Some(()),
    };
    fit.is_some()
}

/// A short name for what the MCAP parser found wrong.
fn reason_of(e: &mcap::McapError) -> String {
    match e {
        mcap::McapError::BadChunkCrc { .. } => "chunk CRC".into(),
        other => other.to_string(),
    }
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

/// Calls `f` with every record of the file (chunks flattened, each chunk's CRC checked before
/// its records are handed on), in file order, until the first damage.
///
/// A [`RecorderError::Malformed`] from `f` (a record whose content does not decode) is damage
/// at that record like any other: reading stops there and what came before is kept. Any other
/// error of `f` (writing the recovered copy, say) ends the reading and is returned.
pub(crate) fn for_each_record(
    bytes: &[u8],
    mut f: impl FnMut(Record<'_>) -> Result<(), RecorderError>,
) -> Result<ReadEnd, RecorderError> {
    check_magic(bytes)?;
    let (prefix, framing) = whole_records(bytes);
    let readable = &bytes[..prefix];
    let mut records_read = 0u64;
    let mut footer = false;
    // Bytes handed to the parser so far: it asks for the bytes of one record at a time, so the
    // last of them lies in the record being parsed when it fails.
    let mut fed = 0usize;
    let mut stopped: Option<(usize, String)> = None;
    let mut reader = LinearReader::new_with_options(
        LinearReaderOptions::default()
            .with_skip_end_magic(true)
            .with_prevalidate_chunk_crcs(true)
            .with_record_length_limit(record_length_limit(bytes.len())),
    );
    // The parser is given only whole records within the limits; should it still panic on a
    // hostile record, that is damage like any other, not a crash.
    let parsed = std::panic::catch_unwind(std::panic::AssertUnwindSafe(
        || -> Result<(), RecorderError> {
            while let Some(event) = reader.next_event() {
                let here = fed.saturating_sub(1);
                match event {
                    Ok(LinearReadEvent::ReadRequest(need)) => {
                        let n = need.min(readable.len() - fed);
                        reader.insert(n).copy_from_slice(&readable[fed..fed + n]);
                        reader.notify_read(n);
                        fed += n;
                    }
                    Ok(LinearReadEvent::Record { opcode, data }) => {
                        if !lengths_fit(opcode, data) {
                            let why = format!(
                                "a length inside a record (opcode 0x{opcode:02x}) runs past it"
                            );
                            stopped = Some((here, why));
                            return Ok(());
                        }
                        let record = match mcap::parse_record(opcode, data) {
                            Ok(r) => r,
                            Err(e) => {
                                stopped = Some((here, reason_of(&e)));
                                return Ok(());
                            }
                        };
                        footer |= matches!(record, Record::Footer(_));
                        match f(record) {
                            Ok(()) => records_read += 1,
                            Err(RecorderError::Malformed(why)) => {
                                stopped = Some((here, why));
                                return Ok(());
                            }
                            Err(e) => return Err(e),
                        }
                    }
                    Err(e) => {
                        stopped = Some((here, reason_of(&e)));
                        return Ok(());
                    }
                }
            }
            Ok(())
        },
    ));
    match parsed {
        Ok(result) => result?,
        Err(_) => {
            let here = fed.saturating_sub(1);
            stopped = Some((here, "the MCAP parser failed on malformed data".into()));
        }
    }
    let ends_with_footer = bytes.ends_with(mcap::MAGIC) && footer_at_end(bytes).is_some();
    let damage = match (stopped, framing) {
        (Some((pos, reason)), _) => Some(Damage {
            records_read,
            byte: record_holding(bytes, pos) as u64,
            kind: DamageKind::Corrupt,
            reason,
        }),
        // a length that runs past the end of a file that does end with its footer is wrong
        (None, Some((at, reason))) => Some(Damage {
            records_read,
            byte: at as u64,
            kind: if ends_with_footer {
                DamageKind::Corrupt
            } else {
                DamageKind::EndsEarly
            },
            reason,
        }),
        (None, None) if !footer || !bytes.ends_with(mcap::MAGIC) => Some(Damage {
            records_read,
            byte: prefix as u64,
            kind: DamageKind::EndsEarly,
            reason: if footer {
                "the file ends without its closing magic".into()
            } else {
                "the file ends without its footer".into()
            },
        }),
        (None, None) => None,
    };
    Ok(ReadEnd {
        records_read,
        complete: damage.is_none(),
        damage,
    })
}

/// The footer's summary start and the offset of the footer record, if `bytes` end with a
/// well-formed footer and the closing magic.
fn footer_at_end(bytes: &[u8]) -> Option<(usize, usize)> {
    let magic = mcap::MAGIC.len();
    let at = bytes
        .len()
        .checked_sub(magic + RECORD_HEADER_BYTES + FOOTER_BODY_BYTES)?;
    if at < magic || !bytes.ends_with(mcap::MAGIC) {
        return None;
    }
    match record_header(bytes, at)? {
        (OP_FOOTER, len) if len == FOOTER_BODY_BYTES as u64 => {}
        _ => return None,
    }
    let body = &bytes[at + RECORD_HEADER_BYTES..];
    let summary_start = u64::from_le_bytes(body[..8].try_into().ok()?);
    let summary_start = usize::try_from(summary_start).ok()?;
    Some((summary_start, at))
}

/// What a file's summary section says the file holds: written when the session ended, so a
/// file damaged in the middle still says how much it had.
#[derive(Debug, Clone, PartialEq, Eq, Default)]
pub struct Announced {
    /// Messages per topic.
    pub messages: BTreeMap<String, u64>,
    /// Log time of the first and of the last message, ns.
    pub message_start_time: u64,
    pub message_end_time: u64,
}

/// The summary section's channels and statistics, when the file ends with a footer whose
/// summary CRC holds; `None` for a file cut short, without a summary or with a damaged one.
pub(crate) fn announced(bytes: &[u8]) -> Option<Announced> {
    let (start, footer) = footer_at_end(bytes)?;
    if start < mcap::MAGIC.len() || start >= footer {
        return None;
    }
    // The summary CRC covers the summary section and the footer up to the CRC itself.
    let crc_end = footer + RECORD_HEADER_BYTES + 16;
    let saved = u32::from_le_bytes(bytes[crc_end..crc_end + 4].try_into().ok()?);
    if saved != 0 && crc32fast::hash(&bytes[start..crc_end]) != saved {
        return None;
    }
    std::panic::catch_unwind(|| {
        let mut topics: BTreeMap<u16, String> = BTreeMap::new();
        let mut statistics = None;
        for span in spans_from(bytes, start).take_while(|s| s.at < footer) {
            let body = &bytes[span.at + RECORD_HEADER_BYTES..span.end?];
            if (span.opcode == OP_CHANNEL || span.opcode == OP_STATISTICS)
                && lengths_fit(span.opcode, body)
            {
                match mcap::parse_record(span.opcode, body).ok()? {
                    Record::Channel(c) => {
                        topics.insert(c.id, c.topic);
                    }
                    Record::Statistics(s) => statistics = Some(s),
                    _ => {}
                }
            }
        }
        let s = statistics?;
        let messages = s
            .channel_message_counts
            .iter()
            .filter_map(|(id, &n)| Some((topics.get(id)?.clone(), n)))
            .collect();
        Some(Announced {
            messages,
            message_start_time: s.message_start_time,
            message_end_time: s.message_end_time,
        })
    })
    .ok()
    .flatten()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_limit_bounds_every_size() {
        assert_eq!(record_length_limit(0), 64 << 20);
        assert_eq!(record_length_limit(10 << 20), 640 << 20);
        assert_eq!(record_length_limit(usize::MAX), 1 << 30);
    }

    #[test]
    fn a_length_inside_a_record_must_fit_it() {
        let string = |s: &str| {
            let mut b = (s.len() as u32).to_le_bytes().to_vec();
            b.extend(s.as_bytes());
            b
        };
        let mut metadata = string("cutlab.session");
        let mut map = string("seed");
        map.extend(string("5"));
        metadata.extend((map.len() as u32).to_le_bytes());
        metadata.extend(&map);
        assert!(lengths_fit(0x0c, &metadata));
        assert!(matches!(
            mcap::parse_record(0x0c, &metadata),
            Ok(Record::Metadata(_))
        ));
        // a value's length of 3 GB inside a record of 40 bytes
        let mut bad = metadata.clone();
        let at = bad.len() - 5;
        bad[at..at + 4].copy_from_slice(&3_000_000_000u32.to_le_bytes());
        assert!(!lengths_fit(0x0c, &bad));
        // the map's own length
        let mut bad = metadata.clone();
        bad[18..22].copy_from_slice(&u32::MAX.to_le_bytes());
        assert!(!lengths_fit(0x0c, &bad));
        // an attachment whose data claims more than the record holds
        let mut attachment = vec![0u8; 16];
        attachment.extend(string("plan.json"));
        attachment.extend(string("application/json"));
        attachment.extend(u64::MAX.to_le_bytes());
        attachment.extend([0u8; 8]);
        assert!(!lengths_fit(0x09, &attachment));
        // records without lengths inside pass
        assert!(lengths_fit(0x05, &[0u8; 30]));
    }

    #[test]
    fn the_record_holding_a_byte_is_found_by_its_framing() {
        let mut bytes = mcap::MAGIC.to_vec();
        for len in [3u64, 5] {
            bytes.push(0x0c);
            bytes.extend(len.to_le_bytes());
            bytes.extend(std::iter::repeat_n(0u8, len as usize));
        }
        assert_eq!(record_holding(&bytes, 2), 0);
        assert_eq!(record_holding(&bytes, 8), 8);
        assert_eq!(record_holding(&bytes, 19), 8);
        assert_eq!(record_holding(&bytes, 20), 20);
        assert_eq!(record_holding(&bytes, bytes.len() - 1), 20);
        // a length past the end: the record that claims it
        bytes[21] = 0xff;
        assert_eq!(record_holding(&bytes, bytes.len() - 1), 20);
    }
}
