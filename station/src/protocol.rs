//! The station's WebSocket messages.
//!
//! Server to page, binary, little-endian, each starting with its kind byte; every array starts
//! at a multiple of 4 bytes so the page reads it through a `Float32Array`/`Uint32Array` view
//! without copying:
//!
//! | kind | layout |
//! |---|---|
//! | [`KIND_TOPOLOGY`] | `u8 kind, 3 pad, u32 vertices, u32 triangles, u32 × 3 × triangles, u32 × vertices regions` |
//! | [`KIND_FRAME`] | `u8 kind, u8 mode, u8 engaged, u8 faults, u32 vertices, u64 tick, f64 echo_ms, f32 × 3 tip_m, f32 × 4 world_from_tool (w, x, y, z), f32 × 3 force_newtons, u8 grasper (0 none, 1 open, 2 closed on nothing, 3 holding), 3 pad, f32 × 3 grasper_m, f32 grasper_pull_newtons, f32 × 3 × vertices positions_m` |
//! | [`KIND_REST`] | `u8 kind, 3 pad, u32 vertices, u32 triangles, u32 × 3 × triangles, f32 × 3 × vertices positions_m` |
//!
//! The rest message comes first on every connection: the session's first surface, from which
//! the page measures depths and on which it points, however late it joined. A topology
//! message comes next and again whenever the surface's triangles change (after a
//! cut); the frames that follow carry one position per vertex of the last topology. `echo_ms`
//! is the page's own time stamp of the newest pointer sample the frame's tick consumed (NaN
//! when none), so the page measures the latency from its input to the frame that shows it.
//!
//! Page to server, text, JSON ([`ClientMessage`]): pointer samples and stop. Anything else, and
//! anything longer than [`MAX_CLIENT_MESSAGE_BYTES`], is dropped and counted by the caller.

use cutlab_haptics::device::PointerSample;
use serde::Deserialize;

use crate::view::{RestSurface, Topology, ViewFrame};

/// The kind byte of a topology message.
pub const KIND_TOPOLOGY: u8 = 1;
/// The kind byte of a frame.
pub const KIND_FRAME: u8 = 2;
/// The kind byte of the rest surface's message.
pub const KIND_REST: u8 = 3;
/// Bytes of a frame before its positions.
pub const FRAME_HEADER_BYTES: usize = 4 + 4 + 8 + 8 + 12 + 16 + 12 + 4 + 12 + 4;
/// The longest text message the server reads from a page.
pub const MAX_CLIENT_MESSAGE_BYTES: usize = 1024;
/// The longest message the socket takes at all: a longer one closes the connection (the
/// socket cannot skip it), and the page connects again. Between the two, a message is read
/// and dropped, the connection kept.
pub const MAX_WIRE_MESSAGE_BYTES: usize = 1 << 20;

/// A topology message for `topology`.
pub fn encode_topology(topology: &Topology) -> Vec<u8> {
    let mut out =
        Vec::with_capacity(12 + 12 * topology.triangles.len() + 4 * topology.vertex_count);
    out.extend([KIND_TOPOLOGY, 0, 0, 0]);
    out.extend(u32_of(topology.vertex_count).to_le_bytes());
    out.extend(u32_of(topology.triangles.len()).to_le_bytes());
    for t in &topology.triangles {
        for v in t {
            out.extend(v.to_le_bytes());
        }
    }
    // one region per vertex (0 where the surface does not say)
    for v in 0..topology.vertex_count {
        let region = topology.regions.get(v).copied().unwrap_or(0);
        out.extend(region.to_le_bytes());
    }
    out
}

/// The rest surface's message for `rest`.
pub fn encode_rest(rest: &RestSurface) -> Vec<u8> {
    let mut out = Vec::with_capacity(12 + 12 * rest.triangles.len() + 4 * rest.positions_m.len());
    out.extend([KIND_REST, 0, 0, 0]);
    out.extend(u32_of(rest.positions_m.len() / 3).to_le_bytes());
    out.extend(u32_of(rest.triangles.len()).to_le_bytes());
    for v in rest.triangles.iter().flatten() {
        out.extend(v.to_le_bytes());
    }
    for x in &rest.positions_m {
        out.extend(x.to_le_bytes());
    }
    out
}

/// A frame message for `frame`.
pub fn encode_frame(frame: &ViewFrame) -> Vec<u8> {
    let mut out = Vec::with_capacity(FRAME_HEADER_BYTES + 4 * frame.positions_m.len());
    out.extend([
        KIND_FRAME,
        frame.mode,
        u8::from(frame.engaged),
        frame.faults,
    ]);
    out.extend(u32_of(frame.positions_m.len() / 3).to_le_bytes());
    out.extend(frame.tick.to_le_bytes());
    out.extend(frame.echo_ms.to_le_bytes());
    let floats =
        |out: &mut Vec<u8>, xs: &[f32]| xs.iter().for_each(|x| out.extend(x.to_le_bytes()));
    floats(&mut out, &frame.tip_m);
    floats(&mut out, &frame.world_from_tool_wxyz);
    floats(&mut out, &frame.force_newtons);
    let g = frame.grasper;
    out.extend([g.map_or(0, |g| g.state()), 0, 0, 0]);
    floats(&mut out, &g.map_or([0.0; 3], |g| g.jaws_m));
    floats(&mut out, &[g.map_or(0.0, |g| g.pull_newtons)]);
    floats(&mut out, &frame.positions_m);
    out
}

fn u32_of(n: usize) -> u32 {
    u32::try_from(n).unwrap_or(u32::MAX)
}

/// What a page sends.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(tag = "type", rename_all = "snake_case", deny_unknown_fields)]
pub enum ClientMessage {
    /// One pointer or pen sample: where the cursor meets the tissue and what the trainee does
    /// there (checked by the pointer device: a NaN faults it, an absurd value is dropped).
    Pointer(PointerSample),
    /// One sample of the second hand's grasper (a touch, on a session started with a second
    /// hand): the point under it on the tissue, the jaws lifted `-depth_m` off the surface,
    /// closed while `blade_engaged` (the button or the touch is held). Checked as a pointer
    /// sample is.
    Grasper(PointerSample),
    /// The trainee pressed Stop.
    Stop {},
}

/// Why a message from a page was dropped.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum ClientMessageError {
    #[error("a message of {0} bytes (at most {MAX_CLIENT_MESSAGE_BYTES})")]
    TooLong(usize),
    #[error("not a station message: {0}")]
    Malformed(String),
}

/// Reads one text message of a page.
pub fn decode_client(text: &str) -> Result<ClientMessage, ClientMessageError> {
    if text.len() > MAX_CLIENT_MESSAGE_BYTES {
        return Err(ClientMessageError::TooLong(text.len()));
    }
    serde_json::from_str(text).map_err(|e| ClientMessageError::Malformed(e.to_string()))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn f32_at(b: &[u8], at: usize) -> f32 {
        f32::from_le_bytes(b[at..at + 4].try_into().expect("4 bytes"))
    }

    #[test]
    fn a_frame_is_laid_out_as_documented() {
        let frame = ViewFrame {
            tick: 1234,
            echo_ms: 56.5,
            mode: 2,
            engaged: true,
            faults: 0,
            tip_m: [0.1, 0.2, 0.3],
            world_from_tool_wxyz: [1.0, 0.0, 0.0, 0.0],
            force_newtons: [0.0, 0.5, -1.0],
            grasper: Some(crate::view::GrasperView {
                jaws_m: [0.4, 0.5, 0.6],
                closed: true,
                pull_newtons: 0.25,
            }),
            positions_m: vec![1.0, 2.0, 3.0, 4.0, 5.0, 6.0],
        };
        let b = encode_frame(&frame);
        assert_eq!(b.len(), FRAME_HEADER_BYTES + 6 * 4);
        assert_eq!(&b[..4], &[KIND_FRAME, 2, 1, 0]);
        assert_eq!(u32::from_le_bytes(b[4..8].try_into().expect("4")), 2);
        assert_eq!(u64::from_le_bytes(b[8..16].try_into().expect("8")), 1234);
        assert_eq!(f64::from_le_bytes(b[16..24].try_into().expect("8")), 56.5);
        assert_eq!(f32_at(&b, 24), 0.1);
        assert_eq!(f32_at(&b, 36), 1.0);
        assert_eq!(f32_at(&b, 52 + 8), -1.0);
        // the grasper holding (3), its jaws, its pull
        assert_eq!(&b[64..68], &[3, 0, 0, 0]);
        assert_eq!(f32_at(&b, 68), 0.4);
        assert_eq!(f32_at(&b, 80), 0.25);
        let without = encode_frame(&ViewFrame {
            grasper: None,
            ..frame.clone()
        });
        assert_eq!((without.len(), without[64]), (b.len(), 0));
        assert_eq!(FRAME_HEADER_BYTES % 4, 0);
        assert_eq!(f32_at(&b, FRAME_HEADER_BYTES), 1.0);
        assert_eq!(f32_at(&b, b.len() - 4), 6.0);
    }

    #[test]
    fn a_topology_lists_its_triangles_and_regions() {
        let t = Topology {
            vertex_count: 4,
            triangles: vec![[0, 1, 2], [2, 1, 3]],
            regions: vec![1, 1, 2, 5],
        };
        let b = encode_topology(&t);
        assert_eq!(b.len(), 12 + 24 + 16);
        assert_eq!(b[0], KIND_TOPOLOGY);
        let words: Vec<u32> = b[4..]
            .chunks(4)
            .map(|c| u32::from_le_bytes(c.try_into().expect("4")))
            .collect();
        assert_eq!(words, [4, 2, 0, 1, 2, 2, 1, 3, 1, 1, 2, 5]);
    }

    #[test]
    fn the_rest_surface_lists_its_triangles_then_its_positions() {
        let rest = RestSurface {
            triangles: vec![[0, 1, 2]],
            positions_m: vec![0.0, 0.5, 1.0, 1.5, 2.0, 2.5, 3.0, 3.5, 4.0],
        };
        let b = encode_rest(&rest);
        assert_eq!(b.len(), 12 + 12 + 36);
        assert_eq!(&b[..4], &[KIND_REST, 0, 0, 0]);
        let words: Vec<u32> = b[4..24]
            .chunks(4)
            .map(|c| u32::from_le_bytes(c.try_into().expect("4")))
            .collect();
        assert_eq!(words, [3, 1, 0, 1, 2]);
        assert_eq!(f32_at(&b, 24), 0.0);
        assert_eq!(f32_at(&b, 28), 0.5);
        assert_eq!(f32_at(&b, b.len() - 4), 4.0);
    }

    #[test]
    fn pages_send_samples_and_stop_and_nothing_else() {
        let m = decode_client(
            r#"{"type":"pointer","t_ms":12.5,"surface_in_world_m":[0,0.01,0.02],"depth_m":0.004,"blade_engaged":true}"#,
        )
        .expect("a sample");
        assert!(matches!(m, ClientMessage::Pointer(p) if p.blade_engaged && p.depth_m == 0.004));
        let g = decode_client(
            r#"{"type":"grasper","t_ms":5,"surface_in_world_m":[0,0,0],"depth_m":-0.004,"blade_engaged":true}"#,
        )
        .expect("a grasper sample");
        assert!(matches!(g, ClientMessage::Grasper(p) if p.blade_engaged && p.depth_m == -0.004));
        assert_eq!(
            decode_client(r#"{"type":"stop"}"#).expect("stop"),
            ClientMessage::Stop {}
        );
        for bad in [
            "",
            "{}",
            r#"{"type":"teleport"}"#,
            r#"{"type":"pointer","t_ms":1}"#,
            r#"{"type":"pointer","t_ms":1,"surface_in_world_m":[0,0],"depth_m":0,"blade_engaged":false}"#,
            r#"{"type":"stop","extra":1}"#,
        ] {
            assert!(
                matches!(decode_client(bad), Err(ClientMessageError::Malformed(_))),
                "{bad}"
            );
        }
        let long = format!(r#"{{"type":"stop","pad":"{}"}}"#, "x".repeat(2000));
        assert!(matches!(
            decode_client(&long),
            Err(ClientMessageError::TooLong(_))
        ));
    }
}
