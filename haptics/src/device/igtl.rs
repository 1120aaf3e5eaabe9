//! An OpenIGTLink network device (the protocol of 3D Slicer, PLUS and most image-guided
//! therapy tools), for real hardware and trackers behind a bridge.
//!
//! The device is a TCP server. A client (one at a time; a new one may connect after the last
//! left, so a session survives a reconnect) sends:
//! - `TRANSFORM` messages: the tool's pose, `world_from_tool` as the usual OpenIGTLink 3x4
//!   matrix of float32, translation in **millimetres** (the convention of Slicer and PLUS);
//! - optionally `STRING` messages with device name `Button` and content `0` or `1`: the blade
//!   button (OpenIGTLink has no buttons; without this message the blade counts as engaged and
//!   the cut force threshold alone decides when cutting starts).
//!
//! For every `TRANSFORM` received the device answers with the latest rendered force, in
//! **newtons**, in the frame the poses arrive in (the world), as one of ([`ForceOutput`],
//! chosen when the device is created: [`IgtlDevice::listen_with`] and [`IgtlOptions`]):
//! - [`ForceOutput::Point`] (the default): a `POINT` message (device name `Force`, one point
//!   named `force`, group `haptics`, its x y z the force, its diameter the force's
//!   magnitude), read by Slicer (as a markups list), pyigtl and the OpenIGTLink C++ library;
//! - [`ForceOutput::Transform`]: a `TRANSFORM` message whose translation is the force (N, not
//!   mm) and whose rotation is the identity: what PLUS Toolkit's OpenHaptics device (a
//!   Geomagic Touch behind PLUS) takes as its force input, the translation of its tool with
//!   port name `Force`, handed to OpenHaptics' `HD_CURRENT_FORCE` unchanged (in newtons, in
//!   the device's base frame: the frame of the `Stylus` poses PLUS sends, in mm). PLUS reads
//!   a TRANSFORM's device name as a transform name, `<From>To<To>`, and drops a name without
//!   `To`: for its OpenIGTLinkTracker data source `Id="Force"` with
//!   `ToolReferenceFrame="Ref"` the message must be named `ForceToRef`
//!   ([`IgtlOptions::force_device_name`]; the default `Force` suits Slicer and pyigtl).
//!
//! Packets are checked: header version 1 or 2, a printable message type, a body of at most
//! [`MAX_BODY_BYTES`], the header's CRC-64 (ECMA-182) over the body, the exact body size of a
//! TRANSFORM, finite numbers and an orthonormal right-handed rotation. A packet that fails a
//! check is dropped and counted; a header that cannot be trusted (bad version, huge body,
//! garbage type) closes the connection, since the stream can no longer be framed. Nothing a
//! client sends can panic the device or block the servo loop: all socket I/O runs on the
//! device's own thread, which hands poses to the servo loop through a triple buffer.

use std::io::{ErrorKind, Read, Write};
use std::net::{SocketAddr, TcpListener, TcpStream};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::time::{Duration, Instant};

use super::{DeviceFault, HapticDevice};
use crate::pose::BUTTON_BLADE;
use crate::{HapticsError, Point3, Rotation, ToolPose, Vector3};

/// Size of the OpenIGTLink header.
pub const HEADER_BYTES: usize = 58;
/// Largest body accepted (a TRANSFORM is 48 bytes; room for metadata of version 2).
pub const MAX_BODY_BYTES: u64 = 64 * 1024;
/// Body of a version-1 TRANSFORM: 12 float32.
pub const TRANSFORM_BODY_BYTES: usize = 48;
/// Body of one POINT element.
pub const POINT_ELEMENT_BYTES: usize = 136;

/// CRC-64 with the ECMA-182 polynomial, as OpenIGTLink uses it (MSB first, initial value 0,
/// no final xor).
pub fn crc64_ecma(bytes: &[u8]) -> u64 {
    const POLY: u64 = 0x42F0_E1EB_A9EA_3693;
    const TABLE: [u64; 256] = {
        let mut table = [0u64; 256];
        let mut i = 0;
        while i < 256 {
            let mut c = (i as u64) << 56;
            let mut k = 0;
            while k < 8 {
                c = if c & (1 << 63) != 0 {
                    (c << 1) ^ POLY
                } else {
                    c << 1
                };
                k += 1;
            }
            table[i] = c;
            i += 1;
        }
        table
    };
    bytes.iter().fold(0u64, |crc, &b| {
        TABLE[((crc >> 56) as u8 ^ b) as usize] ^ (crc << 8)
    })
}

/// A parsed OpenIGTLink header.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Header {
    /// The header version (1 or 2).
    pub version: u16,
    /// The message type (`TRANSFORM`, `POINT`...), padded with zero bytes.
    pub message_type: [u8; 12],
    /// The device name, padded with zero bytes.
    pub device_name: [u8; 20],
    /// The sender's timestamp: seconds in the high 32 bits, the fraction in the low 32.
    pub timestamp: u64,
    /// The size of the body that follows, bytes.
    pub body_bytes: u64,
    /// The CRC-64 (ECMA-182) of the body.
    pub crc: u64,
}

/// Why a packet was rejected.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
pub enum PacketError {
    /// A header version (given) other than 1 or 2.
    #[error("unsupported header version {0}")]
    Version(u16),
    /// The message type is empty or not printable ASCII padded with zeros.
    #[error("message type is not printable ASCII")]
    MessageType,
    /// The body (its size given) is larger than any message this device reads.
    #[error("body of {0} bytes exceeds the limit")]
    TooLarge(u64),
    /// The body's CRC is not the header's.
    #[error("CRC mismatch")]
    Crc,
    /// The body's size (given) is not the message type's.
    #[error("body of {0} bytes does not fit the message")]
    Size(usize),
    /// A transform with a non-finite number or a rotation part that is not a rotation.
    #[error("non-finite or non-rigid transform")]
    Transform,
}

fn trimmed(field: &[u8]) -> &[u8] {
    let end = field.iter().position(|&b| b == 0).unwrap_or(field.len());
    &field[..end]
}

impl Header {
    /// Parses and checks a header (not yet the CRC: that needs the body).
    pub fn parse(bytes: &[u8; HEADER_BYTES]) -> Result<Self, PacketError> {
        let be16 = |i: usize| u16::from_be_bytes([bytes[i], bytes[i + 1]]);
        let be64 = |i: usize| {
            let mut b = [0u8; 8];
            b.copy_from_slice(&bytes[i..i + 8]);
            u64::from_be_bytes(b)
        };
        let version = be16(0);
        if version != 1 && version != 2 {
            return Err(PacketError::Version(version));
        }
        let mut message_type = [0u8; 12];
        message_type.copy_from_slice(&bytes[2..14]);
        let t = trimmed(&message_type);
        if t.is_empty()
            || !t.iter().all(|b| b.is_ascii_graphic())
            || message_type[t.len()..].iter().any(|&b| b != 0)
        {
            return Err(PacketError::MessageType);
        }
        let mut device_name = [0u8; 20];
        device_name.copy_from_slice(&bytes[14..34]);
        let body_bytes = be64(42);
        if body_bytes > MAX_BODY_BYTES {
            return Err(PacketError::TooLarge(body_bytes));
        }
        Ok(Self {
            version,
            message_type,
            device_name,
            timestamp: be64(34),
            body_bytes,
            crc: be64(50),
        })
    }

    /// The message type without its zero padding.
    pub fn message_type(&self) -> &[u8] {
        trimmed(&self.message_type)
    }

    /// The device name without its zero padding.
    pub fn device_name(&self) -> &[u8] {
        trimmed(&self.device_name)
    }

    /// Writes a version-1 header for `body` into `out`.
    pub fn write(
        message_type: &str,
        device_name: &str,
        timestamp: u64,
        body: &[u8],
        out: &mut Vec<u8>,
    ) {
        out.extend_from_slice(&1u16.to_be_bytes());
        let mut field = [0u8; 12];
        let n = message_type.len().min(12);
        field[..n].copy_from_slice(&message_type.as_bytes()[..n]);
        out.extend_from_slice(&field);
        let mut field = [0u8; 20];
        let n = device_name.len().min(20);
        field[..n].copy_from_slice(&device_name.as_bytes()[..n]);
        out.extend_from_slice(&field);
        out.extend_from_slice(&timestamp.to_be_bytes());
        out.extend_from_slice(&(body.len() as u64).to_be_bytes());
        out.extend_from_slice(&crc64_ecma(body).to_be_bytes());
    }
}

/// The content of a message body, without the version-2 extended header and metadata.
pub fn content<'a>(header: &Header, body: &'a [u8]) -> Result<&'a [u8], PacketError> {
    if crc64_ecma(body) != header.crc {
        return Err(PacketError::Crc);
    }
    if header.version == 1 {
        return Ok(body);
    }
    if body.len() < 12 {
        return Err(PacketError::Size(body.len()));
    }
    let ext = u16::from_be_bytes([body[0], body[1]]) as usize;
    let meta_header = u16::from_be_bytes([body[2], body[3]]) as usize;
    let meta_body = u32::from_be_bytes([body[4], body[5], body[6], body[7]]) as usize;
    let end = body
        .len()
        .checked_sub(meta_header.saturating_add(meta_body))
        .ok_or(PacketError::Size(body.len()))?;
    if ext < 12 || ext > end {
        return Err(PacketError::Size(body.len()));
    }
    Ok(&body[ext..end])
}

/// Decodes a TRANSFORM's content: `world_from_tool`, translation in millimetres.
pub fn decode_transform(content: &[u8]) -> Result<(Point3, Rotation), PacketError> {
    if content.len() != TRANSFORM_BODY_BYTES {
        return Err(PacketError::Size(content.len()));
    }
    let mut v = [0.0f64; 12];
    for (k, x) in v.iter_mut().enumerate() {
        let b = [
            content[4 * k],
            content[4 * k + 1],
            content[4 * k + 2],
            content[4 * k + 3],
        ];
        *x = f32::from_be_bytes(b) as f64;
    }
    if !v.iter().all(|x| x.is_finite()) {
        return Err(PacketError::Transform);
    }
    // R11 R21 R31 R12 R22 R32 R13 R23 R33 TX TY TZ: the rotation's columns, then translation.
    let m = nalgebra::Matrix3::new(v[0], v[3], v[6], v[1], v[4], v[7], v[2], v[5], v[8]);
    let orthonormal = (m.transpose() * m - nalgebra::Matrix3::identity())
        .abs()
        .max()
        < 1e-3;
    if !orthonormal || m.determinant() < 0.0 {
        return Err(PacketError::Transform);
    }
    let q = Rotation::from_rotation_matrix(&nalgebra::Rotation3::from_matrix_unchecked(m));
    let q = Rotation::new_normalize(q.into_inner());
    let tip = Point3::new(v[9], v[10], v[11]) * 1e-3;
    Ok((tip, q))
}

/// Encodes a TRANSFORM message (header + body) into `out`: the inverse of
/// [`decode_transform`] (`world_from_tool`, the tip in metres; millimetres on the wire), as a
/// tracker or a bridge sends it.
pub fn encode_transform(
    device_name: &str,
    tip_in_world: &Point3,
    world_from_tool: &Rotation,
    timestamp: u64,
    out: &mut Vec<u8>,
) {
    let m = world_from_tool.to_rotation_matrix().into_inner();
    let mut body = Vec::with_capacity(TRANSFORM_BODY_BYTES);
    // R11 R21 R31 R12 R22 R32 R13 R23 R33 (the rotation's columns), then TX TY TZ in mm
    for v in m
        .iter()
        .copied()
        .chain(tip_in_world.coords.iter().map(|c| c * 1e3))
    {
        body.extend_from_slice(&(v as f32).to_be_bytes());
    }
    out.clear();
    Header::write("TRANSFORM", device_name, timestamp, &body, out);
    out.extend_from_slice(&body);
}

/// Device name of the force message unless [`IgtlOptions::force_device_name`] says otherwise.
pub const FORCE_DEVICE_NAME: &str = "Force";
/// Longest device name of an OpenIGTLink header, bytes.
pub const DEVICE_NAME_BYTES: usize = 20;

/// How the device sends the rendered force back (see the module documentation).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum ForceOutput {
    /// A `POINT` message: x y z the force in newtons (Slicer, pyigtl).
    #[default]
    Point,
    /// A `TRANSFORM` message: identity rotation, translation the force in newtons (PLUS
    /// Toolkit's OpenHaptics device).
    Transform,
}

impl ForceOutput {
    /// Encodes `force_newtons` as this kind of message named `device_name` into `out`.
    pub fn encode(
        self,
        device_name: &str,
        force_newtons: &Vector3,
        timestamp: u64,
        out: &mut Vec<u8>,
    ) {
        match self {
            ForceOutput::Point => encode_force_point(device_name, force_newtons, timestamp, out),
            ForceOutput::Transform => {
                encode_force_transform(device_name, force_newtons, timestamp, out)
            }
        }
    }

    /// Size of one encoded force message (header + body), bytes.
    pub fn message_bytes(self) -> usize {
        HEADER_BYTES
            + match self {
                ForceOutput::Point => POINT_ELEMENT_BYTES,
                ForceOutput::Transform => TRANSFORM_BODY_BYTES,
            }
    }
}

impl std::fmt::Display for ForceOutput {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            ForceOutput::Point => "point",
            ForceOutput::Transform => "transform",
        })
    }
}

impl std::str::FromStr for ForceOutput {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        match s {
            "point" => Ok(ForceOutput::Point),
            "transform" => Ok(ForceOutput::Transform),
            _ => Err(format!(
                "unknown force output {s:?} (expected point or transform)"
            )),
        }
    }
}

/// Settings of an [`IgtlDevice`] chosen when it is created.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct IgtlOptions {
    /// The kind of message the force goes back as.
    pub force_output: ForceOutput,
    /// Device name of the force message: 1 to 20 printable ASCII characters (default
    /// `Force`; PLUS needs `<Id>To<ToolReferenceFrame>`, e.g. `ForceToRef`).
    pub force_device_name: String,
    /// A second tool on the same connection, the second hand's grasper
    /// ([`IgtlDevice::take_grasper`]); `None`: every `TRANSFORM` is the scalpel's.
    pub grasper: Option<IgtlToolNames>,
}

/// The names a second tool goes by on an OpenIGTLink connection.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct IgtlToolNames {
    /// Device name of its `TRANSFORM`s (PLUS: `<Id>To<ToolReferenceFrame>`, e.g.
    /// `GrasperToRef`); a `STRING` named this with `Jaws` appended (`GrasperToRefJaws`)
    /// and content `1` or `0` closes or opens its jaws.
    pub pose: String,
    /// Device name of its force message (sent as [`IgtlOptions::force_output`] says).
    pub force: String,
}

impl IgtlToolNames {
    /// A grasper whose poses come named `pose` and whose force goes back as `<pose>Force`.
    pub fn grasper(pose: &str) -> Self {
        Self {
            pose: pose.to_owned(),
            force: format!("{pose}Force"),
        }
    }

    /// The device name of the `STRING` that opens and closes the jaws.
    pub fn jaws(&self) -> String {
        format!("{}Jaws", self.pose)
    }
}

impl Default for IgtlOptions {
    /// A `POINT` named `Force`: what the device always sent before the choice existed.
    fn default() -> Self {
        Self {
            force_output: ForceOutput::Point,
            force_device_name: FORCE_DEVICE_NAME.to_owned(),
            grasper: None,
        }
    }
}

impl IgtlOptions {
    /// What PLUS Toolkit's OpenHaptics device takes: a `TRANSFORM` named
    /// `ForceTo<reference_frame>`, for an OpenIGTLinkTracker device with
    /// `ToolReferenceFrame="<reference_frame>"` and a data source `Id="Force"`.
    pub fn plus_openhaptics(reference_frame: &str) -> Self {
        Self {
            force_output: ForceOutput::Transform,
            force_device_name: format!("ForceTo{reference_frame}"),
            grasper: None,
        }
    }

    /// Checks the device names (each must fit the header and be printable, the grasper's
    /// differ from the force's).
    pub fn check(&self) -> Result<(), HapticsError> {
        let check = |what: &str, name: &str| {
            let b = name.as_bytes();
            if b.is_empty() || b.len() > DEVICE_NAME_BYTES || !b.iter().all(u8::is_ascii_graphic) {
                return Err(HapticsError::Config(format!(
                    "OpenIGTLink {what} device name {name:?}: 1 to {DEVICE_NAME_BYTES} printable ASCII characters without spaces"
                )));
            }
            Ok(())
        };
        check("force", &self.force_device_name)?;
        if let Some(g) = &self.grasper {
            check("grasper", &g.pose)?;
            check("grasper force", &g.force)?;
            check("grasper jaws", &g.jaws())?;
            if g.pose == self.force_device_name || g.force == self.force_device_name {
                return Err(HapticsError::Config(format!(
                    "OpenIGTLink grasper device name {:?}: the force message's name",
                    g.pose
                )));
            }
        }
        Ok(())
    }
}

/// Encodes the force as a `POINT` message named `Force` (header + body) into `out`.
pub fn encode_force(force_newtons: &Vector3, timestamp: u64, out: &mut Vec<u8>) {
    encode_force_point(FORCE_DEVICE_NAME, force_newtons, timestamp, out);
}

/// Encodes the force as a `TRANSFORM` message named `device_name` (header + body) into
/// `out`: identity rotation, translation the force in **newtons** (not millimetres: read back
/// with [`decode_transform`], which takes millimetres, the "tip" is the force / 1000).
pub fn encode_force_transform(
    device_name: &str,
    force_newtons: &Vector3,
    timestamp: u64,
    out: &mut Vec<u8>,
) {
    let mut body = [0u8; TRANSFORM_BODY_BYTES];
    // R11 R21 R31 R12 R22 R32 R13 R23 R33 (the identity's columns), then TX TY TZ
    let identity = [1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0];
    for (k, v) in identity
        .into_iter()
        .chain(force_newtons.iter().copied())
        .enumerate()
    {
        body[4 * k..4 * k + 4].copy_from_slice(&(v as f32).to_be_bytes());
    }
    out.clear();
    Header::write("TRANSFORM", device_name, timestamp, &body, out);
    out.extend_from_slice(&body);
}

/// Encodes the force as a `POINT` message named `device_name` (header + body) into `out`.
pub fn encode_force_point(
    device_name: &str,
    force_newtons: &Vector3,
    timestamp: u64,
    out: &mut Vec<u8>,
) {
    let mut body = [0u8; POINT_ELEMENT_BYTES];
    body[..5].copy_from_slice(b"force");
    body[64..71].copy_from_slice(b"haptics");
    body[96..100].copy_from_slice(&[255, 0, 0, 255]);
    for k in 0..3 {
        body[100 + 4 * k..104 + 4 * k].copy_from_slice(&(force_newtons[k] as f32).to_be_bytes());
    }
    body[112..116].copy_from_slice(&(force_newtons.norm() as f32).to_be_bytes());
    out.clear();
    Header::write("POINT", device_name, timestamp, &body, out);
    out.extend_from_slice(&body);
}

/// OpenIGTLink timestamp of now: seconds since 1970 in the high 32 bits, fraction in the low.
fn timestamp_now() -> u64 {
    let now = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .unwrap_or_default();
    let frac = ((now.subsec_nanos() as u64) << 32) / 1_000_000_000;
    ((now.as_secs() & 0xffff_ffff) << 32) | frac
}

/// What the network thread hands the servo loop.
#[derive(Debug, Clone, Copy, Default)]
struct Received {
    pose: ToolPose,
    /// Nanoseconds since the device's epoch when the pose arrived; 0: never.
    at_nanos: u64,
}

/// Counters of the network thread.
#[derive(Debug, Default)]
pub struct IgtlCounters {
    /// Connections accepted.
    pub connections: AtomicU64,
    /// Transforms received and taken as poses.
    pub transforms: AtomicU64,
    /// Force messages sent.
    pub forces_sent: AtomicU64,
    /// Packets rejected (a bad header, CRC or body), and forces that could not be sent.
    pub rejected: AtomicU64,
    /// Well-formed messages of types the device does not read.
    pub ignored: AtomicU64,
}

/// The servo loop's end of one tool: its latest pose, the force for it.
#[derive(Debug)]
struct ToolEnd {
    poses: triple_buffer::Output<Received>,
    forces: triple_buffer::Input<Vector3>,
    connected: Arc<AtomicBool>,
    epoch: Instant,
}

impl ToolEnd {
    fn read(&mut self, stale_after_nanos: u64) -> Result<ToolPose, DeviceFault> {
        let r = *self.poses.read();
        if !self.connected.load(Ordering::Acquire) || r.at_nanos == 0 {
            return Err(DeviceFault::Disconnected);
        }
        let now = self.epoch.elapsed().as_nanos() as u64;
        let age_nanos = now.saturating_sub(r.at_nanos);
        if age_nanos > stale_after_nanos {
            return Err(DeviceFault::Stale { age_nanos });
        }
        Ok(r.pose)
    }

    fn write_force(&mut self, force_newtons: Vector3) -> Result<(), DeviceFault> {
        self.forces.write(force_newtons);
        if self.connected.load(Ordering::Acquire) {
            Ok(())
        } else {
            Err(DeviceFault::Disconnected)
        }
    }
}

/// The network thread's end of one tool: where its poses go, its force, its button (the
/// `STRING` named `button_name` sets `button` to `pressed` on `1`, to 0 on `0`).
struct ToolSource {
    poses: triple_buffer::Input<Received>,
    forces: triple_buffer::Output<Vector3>,
    button: u32,
    pressed: u32,
    button_name: String,
}

/// A tool's two ends: its button's `STRING` named `button_name` presses `pressed`; the
/// button starts as `button`.
fn tool_ends(
    connected: &Arc<AtomicBool>,
    epoch: Instant,
    (button_name, pressed, button): (String, u32, u32),
) -> (ToolEnd, ToolSource) {
    let (pose_in, poses) = triple_buffer::triple_buffer(&Received::default());
    let (forces, force_out) = triple_buffer::triple_buffer(&Vector3::zeros());
    let end = ToolEnd {
        poses,
        forces,
        connected: connected.clone(),
        epoch,
    };
    let source = ToolSource {
        poses: pose_in,
        forces: force_out,
        button,
        pressed,
        button_name,
    };
    (end, source)
}

/// The OpenIGTLink device (see the module documentation).
#[derive(Debug)]
pub struct IgtlDevice {
    name: String,
    address: SocketAddr,
    tool: ToolEnd,
    stop: Arc<AtomicBool>,
    counters: Arc<IgtlCounters>,
    /// A pose older than this is stale.
    pub stale_after_nanos: u64,
    force_output: ForceOutput,
    grasper: Option<IgtlGrasper>,
    thread: Option<std::thread::JoinHandle<()>>,
}

/// The second tool of an OpenIGTLink connection, the second hand's grasper
/// ([`IgtlOptions::grasper`], [`IgtlDevice::take_grasper`]): its `TRANSFORM`s are its
/// poses, its `STRING` closes the jaws ([`crate::pose::BUTTON_JAWS`]), its force goes back
/// under its own name. It lives as long as the scalpel's device keeps the connection.
#[derive(Debug)]
pub struct IgtlGrasper {
    name: String,
    tool: ToolEnd,
    /// A pose older than this is stale.
    pub stale_after_nanos: u64,
}

impl HapticDevice for IgtlGrasper {
    fn name(&self) -> &str {
        &self.name
    }

    fn read(&mut self, _tick: u64, _time_s: f64) -> Result<ToolPose, DeviceFault> {
        self.tool.read(self.stale_after_nanos)
    }

    fn write_force(&mut self, force_newtons: Vector3) -> Result<(), DeviceFault> {
        self.tool.write_force(force_newtons)
    }
}

impl IgtlDevice {
    /// Listens on `port` of every interface (port 0: any free port, see [`Self::address`]).
    pub fn listen(port: u16) -> Result<Self, HapticsError> {
        Self::listen_on(SocketAddr::from(([0, 0, 0, 0], port)))
    }

    /// Listens on `address`; the force goes back as a `POINT` named `Force`.
    pub fn listen_on(address: SocketAddr) -> Result<Self, HapticsError> {
        Self::listen_with(address, IgtlOptions::default())
    }

    /// Listens on `address`; the force goes back as `options` say.
    pub fn listen_with(address: SocketAddr, options: IgtlOptions) -> Result<Self, HapticsError> {
        options.check()?;
        let listen_err = |source| HapticsError::Listen {
            port: address.port(),
            source,
        };
        let listener = TcpListener::bind(address).map_err(listen_err)?;
        listener.set_nonblocking(true).map_err(listen_err)?;
        let address = listener.local_addr().map_err(listen_err)?;
        let connected = Arc::new(AtomicBool::new(false));
        let stop = Arc::new(AtomicBool::new(false));
        let counters = Arc::new(IgtlCounters::default());
        let epoch = Instant::now();
        // the blade engaged until its STRING says otherwise
        let (tool, scalpel) = tool_ends(
            &connected,
            epoch,
            ("Button".into(), BUTTON_BLADE, BUTTON_BLADE),
        );
        // the grasper's jaws open until theirs does
        let (grasper, second) = match &options.grasper {
            Some(names) => {
                let jaws = (names.jaws(), crate::pose::BUTTON_JAWS, 0);
                let (end, source) = tool_ends(&connected, epoch, jaws);
                let device = IgtlGrasper {
                    name: format!("igtl:{}/{}", address.port(), names.pose),
                    tool: end,
                    stale_after_nanos: 100_000_000,
                };
                (Some(device), Some((names.clone(), source)))
            }
            None => (None, None),
        };
        let server = Server {
            listener,
            scalpel,
            second,
            connected,
            stop: stop.clone(),
            counters: counters.clone(),
            epoch,
            force_output: options.force_output,
            force_device_name: options.force_device_name,
        };
        let thread = std::thread::Builder::new()
            .name("cutlab-igtl".into())
            .spawn(move || server.run())
            .map_err(|source| HapticsError::Thread {
                name: "cutlab-igtl",
                source,
            })?;
        Ok(Self {
            name: format!("igtl:{}", address.port()),
            address,
            tool,
            stop,
            counters,
            stale_after_nanos: 100_000_000,
            force_output: options.force_output,
            grasper,
            thread: Some(thread),
        })
    }

    /// The second tool's device, once ([`IgtlOptions::grasper`]; `None` without one).
    pub fn take_grasper(&mut self) -> Option<IgtlGrasper> {
        self.grasper.take()
    }

    /// The kind of message the force goes back as.
    pub fn force_output(&self) -> ForceOutput {
        self.force_output
    }

    /// The address the device listens on.
    pub fn address(&self) -> SocketAddr {
        self.address
    }

    /// Counters of messages and connections.
    pub fn counters(&self) -> &IgtlCounters {
        &self.counters
    }

    /// Whether a client is connected now.
    pub fn is_connected(&self) -> bool {
        self.tool.connected.load(Ordering::Acquire)
    }
}

impl Drop for IgtlDevice {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::Release);
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
    }
}

impl HapticDevice for IgtlDevice {
    fn name(&self) -> &str {
        &self.name
    }

    fn read(&mut self, _tick: u64, _time_s: f64) -> Result<ToolPose, DeviceFault> {
        self.tool.read(self.stale_after_nanos)
    }

    fn write_force(&mut self, force_newtons: Vector3) -> Result<(), DeviceFault> {
        self.tool.write_force(force_newtons)
    }
}

/// The network side, on its own thread.
struct Server {
    listener: TcpListener,
    scalpel: ToolSource,
    /// The second tool, by its names.
    second: Option<(IgtlToolNames, ToolSource)>,
    connected: Arc<AtomicBool>,
    stop: Arc<AtomicBool>,
    counters: Arc<IgtlCounters>,
    epoch: Instant,
    force_output: ForceOutput,
    force_device_name: String,
}

/// How long a client may take to finish a message it started.
const MESSAGE_TIMEOUT: Duration = Duration::from_secs(2);

enum Fill {
    Done,
    /// Nothing arrived (only at a message boundary).
    Idle,
    Closed,
}

impl Server {
    fn run(mut self) {
        while !self.stop.load(Ordering::Acquire) {
            match self.listener.accept() {
                Ok((stream, peer)) => {
                    self.counters.connections.fetch_add(1, Ordering::Relaxed);
                    tracing::info!("OpenIGTLink client connected from {peer}");
                    self.serve(stream);
                    self.connected.store(false, Ordering::Release);
                    tracing::warn!("OpenIGTLink client {peer} disconnected");
                }
                Err(e) if e.kind() == ErrorKind::WouldBlock => {
                    std::thread::sleep(Duration::from_millis(5))
                }
                Err(e) => {
                    tracing::warn!("OpenIGTLink accept failed: {e}");
                    std::thread::sleep(Duration::from_millis(50));
                }
            }
        }
    }

    /// Reads exactly `buf.len()` bytes, giving up when the client stalls mid-message.
    fn fill(&self, stream: &mut TcpStream, buf: &mut [u8], boundary: bool) -> Fill {
        let mut filled = 0;
        let started = Instant::now();
        while filled < buf.len() {
            if self.stop.load(Ordering::Acquire) {
                return Fill::Closed;
            }
            match stream.read(&mut buf[filled..]) {
                Ok(0) => return Fill::Closed,
                Ok(n) => filled += n,
                Err(e)
                    if matches!(
                        e.kind(),
                        ErrorKind::WouldBlock | ErrorKind::TimedOut | ErrorKind::Interrupted
                    ) =>
                {
                    if boundary && filled == 0 {
                        return Fill::Idle;
                    }
                    if started.elapsed() > MESSAGE_TIMEOUT {
                        return Fill::Closed;
                    }
                }
                Err(_) => return Fill::Closed,
            }
        }
        Fill::Done
    }

    fn serve(&mut self, mut stream: TcpStream) {
        if stream.set_nonblocking(false).is_err()
            || stream
                .set_read_timeout(Some(Duration::from_millis(20)))
                .is_err()
            || stream
                .set_write_timeout(Some(Duration::from_millis(100)))
                .is_err()
        {
            return;
        }
        let _ = stream.set_nodelay(true);
        self.connected.store(true, Ordering::Release);
        let mut header = [0u8; HEADER_BYTES];
        let mut body = vec![0u8; MAX_BODY_BYTES as usize];
        let mut reply = Vec::with_capacity(self.force_output.message_bytes());
        loop {
            match self.fill(&mut stream, &mut header, true) {
                Fill::Done => {}
                Fill::Idle => continue,
                Fill::Closed => return,
            }
            let h = match Header::parse(&header) {
                Ok(h) => h,
                Err(e) => {
                    self.counters.rejected.fetch_add(1, Ordering::Relaxed);
                    tracing::warn!(
                        "OpenIGTLink: rejected a packet ({e}); closing the connection (the stream cannot be framed)"
                    );
                    return;
                }
            };
            let body = &mut body[..h.body_bytes as usize];
            match self.fill(&mut stream, body, false) {
                Fill::Done => {}
                Fill::Idle | Fill::Closed => return,
            }
            match self.handle(&h, body) {
                Ok(Some(second)) => {
                    let (name, force_newtons) = match (&mut self.second, second) {
                        (Some((names, tool)), true) => (names.force.as_str(), *tool.forces.read()),
                        _ => (self.force_device_name.as_str(), *self.scalpel.forces.read()),
                    };
                    self.force_output
                        .encode(name, &force_newtons, timestamp_now(), &mut reply);
                    if stream.write_all(&reply).is_err() {
                        return;
                    }
                    self.counters.forces_sent.fetch_add(1, Ordering::Relaxed);
                }
                Ok(None) => {}
                Err(e) => {
                    self.counters.rejected.fetch_add(1, Ordering::Relaxed);
                    tracing::warn!(
                        "OpenIGTLink: rejected a {} message ({e})",
                        String::from_utf8_lossy(h.message_type())
                    );
                }
            }
        }
    }

    /// The tool a `TRANSFORM` named `name` moves: the second tool's by its name, else the
    /// scalpel's; true for the second.
    fn posed(&mut self, name: &[u8]) -> (&mut ToolSource, bool) {
        match &mut self.second {
            Some((names, tool)) if name == names.pose.as_bytes() => (tool, true),
            _ => (&mut self.scalpel, false),
        }
    }

    /// The tool whose button a `STRING` named `name` sets, if any.
    fn button_named(&mut self, name: &[u8]) -> Option<&mut ToolSource> {
        let second = self.second.as_mut().map(|(_, tool)| tool);
        std::iter::once(&mut self.scalpel)
            .chain(second)
            .find(|tool| tool.button_name.as_bytes() == name)
    }

    /// Handles one checked message; `Some(second)` when a force reply is due, for the
    /// second tool or the scalpel.
    fn handle(&mut self, h: &Header, body: &[u8]) -> Result<Option<bool>, PacketError> {
        let content = content(h, body)?;
        let at_nanos = (self.epoch.elapsed().as_nanos() as u64).max(1);
        match h.message_type() {
            b"TRANSFORM" => {
                let (tip, rotation) = decode_transform(content)?;
                let (tool, second) = self.posed(h.device_name());
                tool.poses.write(Received {
                    pose: ToolPose {
                        tip_in_world: tip,
                        world_from_tool: rotation,
                        buttons: tool.button,
                    },
                    at_nanos,
                });
                self.counters.transforms.fetch_add(1, Ordering::Relaxed);
                Ok(Some(second))
            }
            b"STRING" => {
                let Some(tool) = self.button_named(h.device_name()) else {
                    self.counters.ignored.fetch_add(1, Ordering::Relaxed);
                    return Ok(None);
                };
                if content.len() < 4 {
                    return Err(PacketError::Size(content.len()));
                }
                let n = u16::from_be_bytes([content[2], content[3]]) as usize;
                match content.get(4..4 + n) {
                    Some(b"1") => tool.button = tool.pressed,
                    Some(b"0") => tool.button = 0,
                    _ => return Err(PacketError::Size(content.len())),
                }
                Ok(None)
            }
            _ => {
                self.counters.ignored.fetch_add(1, Ordering::Relaxed);
                Ok(None)
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A TRANSFORM packet: identity rotation, translation in mm.
    fn transform_packet(t_mm: [f64; 3]) -> Vec<u8> {
        let mut out = Vec::new();
        encode_transform(
            "Tool",
            &(Point3::from(t_mm) * 1e-3),
            &Rotation::identity(),
            0,
            &mut out,
        );
        out
    }

    #[test]
    fn crc64_ecma_check_value() {
        // CRC-64/ECMA-182 of "123456789" (the catalogue's check value).
        assert_eq!(crc64_ecma(b"123456789"), 0x6C40_DF5F_0B49_7347);
    }

    #[test]
    fn transform_round_trip_and_rejections() {
        let p = transform_packet([10.0, -20.0, 5.0]);
        let mut hb = [0u8; HEADER_BYTES];
        hb.copy_from_slice(&p[..HEADER_BYTES]);
        let h = Header::parse(&hb).expect("header");
        assert_eq!(h.message_type(), b"TRANSFORM");
        let (tip, q) =
            decode_transform(content(&h, &p[HEADER_BYTES..]).expect("content")).expect("transform");
        assert!((tip - Point3::new(0.01, -0.02, 0.005)).norm() < 1e-9);
        assert!(q.angle() < 1e-6);

        // bad CRC
        let mut bad = p.clone();
        bad[HEADER_BYTES + 3] ^= 1;
        assert_eq!(content(&h, &bad[HEADER_BYTES..]), Err(PacketError::Crc));
        // bad version, garbage type, huge body
        let mut hv = hb;
        hv[1] = 9;
        assert_eq!(Header::parse(&hv), Err(PacketError::Version(9)));
        let mut ht = hb;
        ht[2] = 0x07;
        assert_eq!(Header::parse(&ht), Err(PacketError::MessageType));
        let mut hs = hb;
        hs[42..50].copy_from_slice(&u64::MAX.to_be_bytes());
        assert_eq!(Header::parse(&hs), Err(PacketError::TooLarge(u64::MAX)));
        // wrong size, NaN, non-rigid
        assert_eq!(decode_transform(&[0u8; 40]), Err(PacketError::Size(40)));
        let mut nan = p[HEADER_BYTES..].to_vec();
        nan[36..40].copy_from_slice(&f32::NAN.to_be_bytes());
        assert_eq!(decode_transform(&nan), Err(PacketError::Transform));
        let mut scaled = p[HEADER_BYTES..].to_vec();
        scaled[0..4].copy_from_slice(&2.0f32.to_be_bytes());
        assert_eq!(decode_transform(&scaled), Err(PacketError::Transform));
        let mut mirrored = p[HEADER_BYTES..].to_vec();
        mirrored[0..4].copy_from_slice(&(-1.0f32).to_be_bytes());
        assert_eq!(decode_transform(&mirrored), Err(PacketError::Transform));
    }

    #[test]
    fn version_2_extended_header_and_metadata_are_skipped() {
        let mut body = vec![0u8; 12];
        body[0..2].copy_from_slice(&12u16.to_be_bytes());
        body[2..4].copy_from_slice(&2u16.to_be_bytes()); // metadata header: count 0
        body[4..8].copy_from_slice(&3u32.to_be_bytes());
        let inner = &transform_packet([1.0, 2.0, 3.0])[HEADER_BYTES..];
        body.extend_from_slice(inner);
        body.extend_from_slice(&[0, 0, b'a', b'b', b'c']);
        let mut p = Vec::new();
        Header::write("TRANSFORM", "Tool", 0, &body, &mut p);
        p[1] = 2;
        let mut hb = [0u8; HEADER_BYTES];
        hb.copy_from_slice(&p[..HEADER_BYTES]);
        let h = Header::parse(&hb).expect("header");
        assert_eq!(content(&h, &body).expect("content"), inner);
        // lying sizes are rejected, not sliced out of range
        let mut lying = body.clone();
        lying[4..8].copy_from_slice(&u32::MAX.to_be_bytes());
        let mut p2 = Vec::new();
        Header::write("TRANSFORM", "Tool", 0, &lying, &mut p2);
        p2[1] = 2;
        hb.copy_from_slice(&p2[..HEADER_BYTES]);
        let h2 = Header::parse(&hb).expect("header");
        assert!(matches!(content(&h2, &lying), Err(PacketError::Size(_))));
    }

    #[test]
    fn force_is_a_point_message() {
        let mut out = Vec::new();
        encode_force(&Vector3::new(0.5, -1.0, 2.0), 0, &mut out);
        assert_eq!(out.len(), HEADER_BYTES + POINT_ELEMENT_BYTES);
        let mut hb = [0u8; HEADER_BYTES];
        hb.copy_from_slice(&out[..HEADER_BYTES]);
        let h = Header::parse(&hb).expect("header");
        assert_eq!(
            (h.message_type(), h.device_name()),
            (&b"POINT"[..], &b"Force"[..])
        );
        let c = content(&h, &out[HEADER_BYTES..]).expect("crc");
        let y = f32::from_be_bytes([c[104], c[105], c[106], c[107]]);
        assert_eq!(y, -1.0);
    }

    #[test]
    fn force_can_be_a_transform_for_plus() {
        let force = Vector3::new(0.5, -1.25, 3.0);
        let mut out = Vec::new();
        ForceOutput::Transform.encode("ForceToRef", &force, 7, &mut out);
        assert_eq!(out.len(), ForceOutput::Transform.message_bytes());
        let mut hb = [0u8; HEADER_BYTES];
        hb.copy_from_slice(&out[..HEADER_BYTES]);
        let h = Header::parse(&hb).expect("header");
        assert_eq!(
            (h.message_type(), h.device_name(), h.timestamp),
            (&b"TRANSFORM"[..], &b"ForceToRef"[..], 7)
        );
        let (t, q) = decode_transform(content(&h, &out[HEADER_BYTES..]).expect("crc"))
            .expect("a rigid transform");
        // the translation carries newtons; decode_transform reads millimetres
        assert!((t.coords * 1e3 - force).norm() < 1e-12, "{t:?}");
        assert_eq!(q, Rotation::identity());
        // the point form keeps its name and layout
        ForceOutput::Point.encode("Force", &force, 0, &mut out);
        assert_eq!(out.len(), HEADER_BYTES + POINT_ELEMENT_BYTES);
        assert_eq!(&out[2..7], b"POINT");
    }

    #[test]
    fn force_output_options_parse_and_check() {
        assert_eq!("point".parse(), Ok(ForceOutput::Point));
        assert_eq!("transform".parse(), Ok(ForceOutput::Transform));
        assert!("Transform".parse::<ForceOutput>().is_err());
        assert_eq!(ForceOutput::Transform.to_string(), "transform");
        assert!(IgtlOptions::default().check().is_ok());
        let plus = IgtlOptions::plus_openhaptics("Ref");
        assert_eq!(
            (plus.force_output, plus.force_device_name.as_str()),
            (ForceOutput::Transform, "ForceToRef")
        );
        for bad in [
            "",
            "Force To Ref",
            "ForceToAVeryLongFrameName",
            "Kraft\u{e9}",
        ] {
            let o = IgtlOptions {
                force_device_name: bad.to_owned(),
                ..IgtlOptions::default()
            };
            assert!(o.check().is_err(), "{bad:?} accepted");
        }
    }
}
