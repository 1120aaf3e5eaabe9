//! The station's WebSocket messages (`cutlab_station::protocol::decode_client`), fed to the
//! pointer device as a page's stream is: in their own file because the fuzz targets of the
//! other parsers are built without the station (see `targets.rs`, whose pose check it uses:
//! include both).

use cutlab_haptics::HapticDevice;
use cutlab_haptics::device::{PointerDevice, PointerOptions};
use cutlab_station::protocol::{ClientMessage, decode_client};

/// What one input did: accepted, or refused with the parser's message.
pub type Outcome = Result<(), String>;

/// A page's messages, one per line, read as the server reads each; the pointer samples among
/// them are pushed to a pointer device (out of order, NaN, absurd: whatever the line says),
/// which is then read over 60 ticks: a pose it gives must be a finite rigid motion (a bad
/// sample faults the device or is dropped instead). Accepted when every line was a message.
pub fn station_ws(data: &[u8]) -> Outcome {
    let text = String::from_utf8_lossy(data);
    let (mut device, feed) =
        PointerDevice::new(PointerOptions::default()).expect("the default pointer options");
    let mut refused = None;
    for line in text.lines() {
        match decode_client(line) {
            Ok(ClientMessage::Pointer(sample) | ClientMessage::Grasper(sample)) => {
                let _ = feed.push(sample);
            }
            Ok(ClientMessage::Stop {}) => {}
            Err(e) => refused = Some(e.to_string()),
        }
    }
    for tick in 0..60u64 {
        if let Ok(pose) = device.read(tick, tick as f64 * 1e-3) {
            crate::targets::check_rigid(
                &pose.tip_in_world,
                &pose.world_from_tool,
                &format!("at tick {tick}: {pose:?}"),
            );
        }
    }
    refused.map_or(Ok(()), Err)
}
