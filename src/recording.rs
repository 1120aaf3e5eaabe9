//! `cutlab recording info|recover` and `cutlab replay`.

use std::path::{Path, PathBuf};

use anyhow::{Context, bail};
use cutlab_recorder::replay::{self, ReplayOptions, Speed};
use cutlab_recorder::writer::RecordObserver;
use cutlab_recorder::{DamageKind, Recording, RerunSink, RerunTarget, recover as salvage};

/// What `--rerun` names.
#[derive(Debug, Clone, PartialEq)]
pub enum RerunArg {
    Spawn,
    Connect(Option<String>),
}

impl std::str::FromStr for RerunArg {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        match s {
            "spawn" => Ok(RerunArg::Spawn),
            "connect" => Ok(RerunArg::Connect(None)),
            _ => match s.strip_prefix("connect=") {
                Some(url) if !url.is_empty() => Ok(RerunArg::Connect(Some(url.to_owned()))),
                _ => Err(format!(
                    "--rerun takes spawn, connect or connect=URL, got {s:?}"
                )),
            },
        }
    }
}

/// The rerun target of `--rrd FILE` or `--rerun ...` (relative `.rrd` paths are resolved by
/// the caller).
pub fn rerun_target(rrd: Option<&Path>, rerun: Option<&RerunArg>) -> Option<RerunTarget> {
    match (rrd, rerun) {
        (Some(path), _) => Some(RerunTarget::File(path.to_path_buf())),
        (None, Some(RerunArg::Spawn)) => Some(RerunTarget::Spawn),
        (None, Some(RerunArg::Connect(None))) => Some(RerunTarget::connect_default()),
        (None, Some(RerunArg::Connect(Some(url)))) => Some(RerunTarget::Connect(url.clone())),
        (None, None) => None,
    }
}

pub fn info(file: &Path, json: bool) -> anyhow::Result<()> {
    let rec = Recording::open(file).with_context(|| format!("reading {}", file.display()))?;
    let pace = cutlab_scoring::from_recording::input_pace(&rec);
    if json {
        let channels: Vec<_> = rec
            .channels
            .values()
            .map(|c| serde_json::json!({ "topic": c.topic, "schema": c.schema, "encoding": c.message_encoding, "messages": c.messages }))
            .collect();
        let v = serde_json::json!({
            "file": file.display().to_string(), "bytes": rec.file_bytes, "complete": rec.complete,
            "damage": rec.damage.as_ref().map(|d| serde_json::json!({
                "byte": d.byte, "kind": damage_kind(d.kind), "reason": d.reason, "records_read": d.records_read,
            })),
            "whole": rec.is_whole(), "announced_steps": rec.announced_steps(), "steps": rec.steps.len(),
            "duration_s": rec.duration_s(),
            "input_hz": pace.map(|p| p.input_hz),
            "channels": channels, "session": rec.meta, "session_end": rec.end,
            "attachments": rec.attachments.iter().map(|a| serde_json::json!({ "name": a.0, "media_type": a.1, "bytes": a.2.len() })).collect::<Vec<_>>(),
        });
        println!("{}", serde_json::to_string_pretty(&v)?);
        return Ok(());
    }
    println!(
        "{}: {:.1} MB, {}",
        file.display(),
        rec.file_bytes as f64 * 1e-6,
        match &rec.damage {
            None if rec.is_whole() => "complete",
            Some(d) if d.kind == DamageKind::Corrupt => "DAMAGED",
            _ => "INCOMPLETE",
        }
    );
    if let Some(why) = rec.shortfall() {
        if let Some(d) = &rec.damage {
            println!("  reading stopped after {} records", d.records_read);
        }
        println!("  {why}");
        if let Some(n) = rec.announced_steps() {
            println!(
                "  {} of the {n} simulation steps its summary announces are readable",
                rec.steps.len()
            );
        }
        println!(
            "  (`cutlab recording recover {}` writes a complete copy of what is readable)",
            file.display()
        );
    }
    println!("  duration {:.3} s", rec.duration_s());
    if let Some(m) = &rec.meta {
        println!(
            "  cutlab {}, scene {}{}, device {}, seed {}, trainee {:?}, exercise {:?}, {} clock, servo period {} us, sim step {} us",
            m.cutlab_version,
            m.provenance.scene,
            m.provenance
                .min_tets
                .map(|n| format!(" (min {n} tets)"))
                .unwrap_or_default(),
            m.provenance.device,
            m.provenance.seed,
            m.provenance.trainee,
            m.provenance.exercise,
            m.clock,
            m.period_nanos / 1000,
            m.time_step_nanos / 1000
        );
    }
    if let Some(p) = pace {
        println!(
            "  input: the hand reached the simulation {:.0} times a second while it moved ({:.1} s){}",
            p.input_hz,
            p.moving_s,
            if p.lagged() {
                ": the station lagged"
            } else {
                ""
            }
        );
    }
    println!(
        "  {:<18} {:<26} {:<10} {:>10}",
        "channel", "schema", "encoding", "messages"
    );
    for c in rec.channels.values() {
        println!(
            "  {:<18} {:<26} {:<10} {:>10}",
            c.topic, c.schema, c.message_encoding, c.messages
        );
    }
    for (name, media, bytes) in &rec.attachments {
        println!("  attachment {name} ({media}, {} bytes)", bytes.len());
    }
    match &rec.end {
        Some(end) => println!(
            "  session end: {}",
            end.iter()
                .map(|(k, v)| format!("{k}={v}"))
                .collect::<Vec<_>>()
                .join(", ")
        ),
        None => println!("  no session-end record (the session was interrupted)"),
    }
    Ok(())
}

pub fn recover(file: &Path, out: Option<&Path>) -> anyhow::Result<()> {
    let out: PathBuf = out
        .map(Path::to_path_buf)
        .unwrap_or_else(|| file.with_extension("recovered.mcap"));
    let r =
        salvage::recover(file, &out).with_context(|| format!("recovering {}", file.display()))?;
    if r.input_complete {
        println!(
            "{} was complete; copied {} messages to {}",
            file.display(),
            r.messages,
            out.display()
        );
    } else {
        println!(
            "salvaged {} messages ({} metadata, {} attachments) up to {:.3} s into {}",
            r.messages,
            r.metadata,
            r.attachments,
            r.last_log_time.unwrap_or(0) as f64 * 1e-9,
            out.display()
        );
        if let Some(d) = &r.damage {
            println!("  the input {d}");
        }
        if let Some(n) = r.announced_messages {
            println!(
                "  its summary announces {n} messages: {} lost",
                n.saturating_sub(r.messages)
            );
        }
    }
    Ok(())
}

/// Session log time of the last step a replay re-simulated, s (0 before any).
fn verified_to_s(rec: &Recording, r: &replay::ReplayReport) -> f64 {
    let first = r.resumed_at.map_or(0, |k| k.step as usize + 1);
    let period = rec.meta.as_ref().map_or(1_000_000, |m| m.period_nanos);
    (first + r.steps as usize)
        .checked_sub(1)
        .and_then(|i| rec.steps.get(i))
        .map_or(0.0, |s| (s.tick * period) as f64 * 1e-9)
}

fn damage_kind(kind: DamageKind) -> &'static str {
    match kind {
        DamageKind::EndsEarly => "ends_early",
        DamageKind::Corrupt => "corrupt",
    }
}

#[derive(Debug)]
pub struct ReplayArgs {
    pub speed: Speed,
    pub from_s: Option<f64>,
    pub resimulate: bool,
    pub to_s: Option<f64>,
    pub keep_going: bool,
    /// Accept a recording that is not whole: verify what is readable.
    pub partial: bool,
    pub jobs: usize,
    pub json: bool,
    pub rerun: Option<RerunTarget>,
}

pub fn replay(file: &Path, a: ReplayArgs) -> anyhow::Result<()> {
    let rec = Recording::open(file).with_context(|| format!("reading {}", file.display()))?;
    let shortfall = rec.shortfall();
    if let Some(why) = &shortfall {
        eprintln!(
            "warning: {} is not whole ({why}); replaying what is readable",
            file.display()
        );
    }
    if let Some(m) = rec
        .metadata
        .iter()
        .find(|m| m.0 == salvage::RECOVERED_METADATA)
    {
        let lost = m.1.get("damage").map_or("", String::as_str);
        eprintln!("note: a recovered copy (its source {lost}); it holds only what was salvaged");
    }
    let observer = match &a.rerun {
        Some(target) => {
            let plan = rec.plan()?;
            let meta = rec.meta()?;
            let sink = RerunSink::of_session(
                target,
                meta.period_nanos,
                meta.blade_length_m,
                plan.as_ref(),
            )
            .context("starting the rerun logger")?;
            Some(Box::new(sink) as Box<dyn RecordObserver>)
        }
        None => None,
    };
    let options = ReplayOptions {
        speed: Some(a.speed),
        from_s: a.from_s,
        to_s: a.to_s,
        observer,
        keep_going: a.keep_going,
        resimulate: a.resimulate,
        jobs: a.jobs,
    };
    let r = replay::replay(&rec, options).context("replaying")?;
    let resumed_at_s = r.resumed_at.map(|k| k.session_s);
    if a.json {
        let v = serde_json::json!({
            "verified": r.verified(), "resumed_at_s": resumed_at_s, "steps": r.steps, "threads": r.jobs, "keyframes_checked": r.keyframes_checked, "keyframes_matched": r.keyframes_matched,
            "cuts_recorded": r.cuts_recorded, "cuts_replayed": r.cuts_replayed, "divergences": r.divergences,
            "first_divergence": r.first_divergence.as_ref().map(|d| d.to_string()),
            "simulated_s": r.simulated_s, "wall_s": r.wall_s, "speed": r.speed(),
            "whole": shortfall.is_none(), "verified_to_s": verified_to_s(&rec, &r), "announced_s": rec.readable_s().1,
            "final_state_hash": format!("{:016x}", r.final_hash.state),
        });
        println!("{}", serde_json::to_string_pretty(&v)?);
    } else {
        if let Some(k) = r.resumed_at {
            println!(
                "resumed at the keyframe of step {} ({:.3} s; its hashes equal)",
                k.step, k.session_s
            );
        }
        println!(
            "replayed {} steps ({:.2} s of session) on {} thread{} in {:.2} s wall: {:.1}x real time",
            r.steps,
            r.simulated_s,
            r.jobs,
            if r.jobs == 1 { "" } else { "s" },
            r.wall_s,
            r.speed()
        );
        println!(
            "  keyframes: {} of {} hashes equal; cuts: {} replayed, {} recorded",
            r.keyframes_matched, r.keyframes_checked, r.cuts_replayed, r.cuts_recorded
        );
    }
    match &r.first_divergence {
        // a recording that is not whole verifies only what is readable: said, and an error
        // unless that was asked for
        None if r.keyframes_checked > 0 && shortfall.is_some() => {
            let upto = match rec.readable_s().1 {
                Some(total) => format!("{:.2} of {total:.2} s", verified_to_s(&rec, &r)),
                None => format!("{:.2} s of an unknown total", verified_to_s(&rec, &r)),
            };
            let why = rec
                .damage
                .as_ref()
                .map_or_else(|| shortfall.unwrap_or_default(), ToString::to_string);
            if a.partial {
                if !a.json {
                    println!(
                        "  verified up to {upto}: bit-exact there; the rest is unreadable ({why})"
                    );
                }
                Ok(())
            } else {
                bail!(
                    "verified only up to {upto}: {} is not whole ({why}); --partial accepts a partial replay",
                    file.display()
                )
            }
        }
        None if r.keyframes_checked > 0 => {
            if !a.json {
                println!("  verified: the replay is bit-exact");
            }
            Ok(())
        }
        // a window chosen with --from/--to may hold no keyframe: nothing to check there
        None if a.from_s.is_some() || a.to_s.is_some() => {
            if !a.json {
                println!("  no keyframe in the replayed window: its steps were not checked");
            }
            Ok(())
        }
        None => bail!("no keyframe in the recording: nothing was verified"),
        Some(d) => bail!(
            "the replay diverged ({} divergences); first at {d}",
            r.divergences
        ),
    }
}
