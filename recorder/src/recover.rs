//! Salvaging a damaged recording (cut short by a killed process or a full disk, or with wrong
//! bytes inside): every record before the first damaged one is copied into a new, complete
//! file (summary, indexes, footer), with a `cutlab.recovered` metadata record saying what was
//! lost. The damaged file is left as it is.

use std::borrow::Cow;
use std::collections::{BTreeMap, HashMap};
use std::fs::File;
use std::io::{BufWriter, Write};
use std::path::Path;

use mcap::records::{MessageHeader, Metadata, Record};

use crate::RecorderError;
use crate::scan::{Damage, check_magic, for_each_record};

/// The name of the metadata record a recovered copy carries (source, what was kept, the
/// damage).
pub const RECOVERED_METADATA: &str = "cutlab.recovered";

/// What a recovery kept.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct RecoverReport {
    pub messages: u64,
    pub metadata: u64,
    pub attachments: u64,
    /// The input already ended with a footer (nothing was lost).
    pub input_complete: bool,
    /// Where and why reading stopped early, if it did.
    pub damage: Option<Damage>,
    pub input_bytes: u64,
    /// Messages the input's summary announces (`None` when it has no readable summary).
    pub announced_messages: Option<u64>,
    /// Last log time kept, ns.
    pub last_log_time: Option<u64>,
}

/// Copies the readable part of `input` into a complete recording at `output`.
pub fn recover(input: &Path, output: &Path) -> Result<RecoverReport, RecorderError> {
    if input == output {
        return Err(RecorderError::Malformed(
            "recover writes a new file: the output must not be the input".into(),
        ));
    }
    let bytes = std::fs::read(input).map_err(|source| RecorderError::Io {
        path: input.to_owned(),
        error: source,
    })?;
    // before the output is created: a file that is no recording leaves nothing behind
    check_magic(&bytes)?;
    let file = File::create(output).map_err(|source| RecorderError::Io {
        path: output.to_owned(),
        error: source,
    })?;
    let mut w = mcap::WriteOptions::new()
        .compression(Some(mcap::Compression::Zstd))
        .profile("cutlab")
        .library(format!("cutlab {} (recovered)", env!("CARGO_PKG_VERSION")))
        .create(BufWriter::new(file))?;
    let mut report = RecoverReport {
        messages: 0,
        metadata: 0,
        attachments: 0,
        input_complete: false,
        damage: None,
        input_bytes: bytes.len() as u64,
        announced_messages: crate::scan::announced(&bytes).map(|a| a.messages.values().sum()),
        last_log_time: None,
    };
    // old id -> new id
    let mut schemas: HashMap<u16, u16> = HashMap::new();
    let mut channels: HashMap<u16, u16> = HashMap::new();
    let end = for_each_record(&bytes, |record| {
        match record {
            Record::Schema { header, data } => {
                let id = w.add_schema(&header.name, &header.encoding, &data)?;
                schemas.insert(header.id, id);
            }
            Record::Channel(c) => {
                let schema = if c.schema_id == 0 {
                    0
                } else {
                    *schemas.get(&c.schema_id).ok_or_else(|| {
                        RecorderError::Malformed(format!(
                            "channel {} names unknown schema {}",
                            c.topic, c.schema_id
                        ))
                    })?
                };
                let id = w.add_channel(schema, &c.topic, &c.message_encoding, &c.metadata)?;
                channels.insert(c.id, id);
            }
            Record::Message { header, data } => {
                let channel_id = *channels.get(&header.channel_id).ok_or_else(|| {
                    RecorderError::Malformed(format!(
                        "message on unknown channel {}",
                        header.channel_id
                    ))
                })?;
                w.write_to_known_channel(
                    &MessageHeader {
                        channel_id,
                        ..header
                    },
                    &data,
                )?;
                report.messages += 1;
                report.last_log_time = Some(
                    report
                        .last_log_time
                        .map_or(header.log_time, |t| t.max(header.log_time)),
                );
            }
            Record::Metadata(m) => {
                w.write_metadata(&m)?;
                report.metadata += 1;
            }
            Record::Attachment { header, data, .. } => {
                w.attach(&mcap::Attachment {
                    log_time: header.log_time,
                    create_time: header.create_time,
                    name: header.name,
                    media_type: header.media_type,
                    data: Cow::Borrowed(&data),
                })?;
                report.attachments += 1;
            }
            _ => {}
        }
        Ok(())
    })?;
    report.damage = end.damage;
    report.input_complete = end.complete;
    let mut note = BTreeMap::new();
    note.insert("source".to_owned(), input.display().to_string());
    note.insert("source_bytes".to_owned(), report.input_bytes.to_string());
    note.insert(
        "source_complete".to_owned(),
        report.input_complete.to_string(),
    );
    note.insert("messages_kept".to_owned(), report.messages.to_string());
    if let Some(d) = &report.damage {
        note.insert("damage".to_owned(), d.to_string());
    }
    w.write_metadata(&Metadata {
        name: RECOVERED_METADATA.into(),
        metadata: note,
    })?;
    w.finish()?;
    w.into_inner().flush().map_err(|source| RecorderError::Io {
        path: output.to_owned(),
        error: source,
    })?;
    Ok(report)
}
