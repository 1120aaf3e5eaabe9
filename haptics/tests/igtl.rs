//! The OpenIGTLink device over real sockets: hostile packets, reconnects, and interoperation
//! with pyigtl (a client nobody here wrote).

use std::io::{BufRead, BufReader, Read, Write};
use std::net::TcpStream;
use std::time::{Duration, Instant};

use cutlab_haptics::device::igtl::{
    HEADER_BYTES, Header, POINT_ELEMENT_BYTES, TRANSFORM_BODY_BYTES, content, decode_transform,
    encode_transform,
};
use cutlab_haptics::device::{DeviceFault, ForceOutput, HapticDevice, IgtlDevice, IgtlOptions};
use cutlab_haptics::{Point3, Rotation, Vector3};

fn local_device() -> IgtlDevice {
    IgtlDevice::listen_on("127.0.0.1:0".parse().expect("address")).expect("listen")
}

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

fn wait_for(mut ok: impl FnMut() -> bool) -> bool {
    let t = Instant::now();
    while t.elapsed() < Duration::from_secs(5) {
        if ok() {
            return true;
        }
        std::thread::sleep(Duration::from_millis(2));
    }
    false
}

/// Reads one force reply: the POINT's x y z.
fn read_force(stream: &mut impl Read) -> Vector3 {
    let mut reply = [0u8; HEADER_BYTES + POINT_ELEMENT_BYTES];
    stream.read_exact(&mut reply).expect("force reply");
    let f = |k: usize| {
        let i = HEADER_BYTES + 100 + 4 * k;
        f32::from_be_bytes([reply[i], reply[i + 1], reply[i + 2], reply[i + 3]]) as f64
    };
    assert_eq!(&reply[2..7], b"POINT");
    Vector3::new(f(0), f(1), f(2))
}

#[test]
fn hostile_packets_are_rejected_and_the_device_survives_reconnects() {
    let mut device = local_device();
    assert_eq!(device.read(0, 0.0), Err(DeviceFault::Disconnected));
    device.write_force(Vector3::new(0.25, 0.0, -0.5)).ok();
    let mut s = TcpStream::connect(device.address()).expect("connect");
    s.set_read_timeout(Some(Duration::from_secs(5)))
        .expect("timeout");

    // a bad CRC is dropped, the connection stays framed
    let mut bad = transform_packet([1.0, 2.0, 3.0]);
    let last = bad.len() - 1;
    bad[last] ^= 0x55;
    s.write_all(&bad).expect("send");
    // a transform with a wrong size (40 bytes, CRC right) and a non-rigid one
    let mut short = Vec::new();
    Header::write("TRANSFORM", "Tool", 0, &[0u8; 40], &mut short);
    short.extend_from_slice(&[0u8; 40]);
    s.write_all(&short).expect("send");
    // an unknown message type is ignored
    let mut status = Vec::new();
    Header::write("STATUS", "x", 0, &[0u8; 30], &mut status);
    status.extend_from_slice(&[0u8; 30]);
    s.write_all(&status).expect("send");
    // then a good one gets through and is answered with the force
    s.write_all(&transform_packet([10.0, -20.0, 30.0]))
        .expect("send");
    let f = read_force(&mut s);
    assert!((f - Vector3::new(0.25, 0.0, -0.5)).norm() < 1e-6, "{f:?}");
    let pose = device.read(1, 0.001).expect("pose");
    assert!((pose.tip_in_world - Point3::new(0.01, -0.02, 0.03)).norm() < 1e-9);
    assert!(pose.blade_engaged());
    assert_eq!(
        device
            .counters()
            .rejected
            .load(std::sync::atomic::Ordering::Relaxed),
        2
    );
    assert_eq!(
        device
            .counters()
            .ignored
            .load(std::sync::atomic::Ordering::Relaxed),
        1
    );

    // a header announcing a huge body closes the connection (the stream cannot be framed)
    let mut huge = transform_packet([0.0; 3]);
    huge[42..50].copy_from_slice(&(u64::MAX / 2).to_be_bytes());
    s.write_all(&huge[..HEADER_BYTES]).expect("send");
    let mut buf = [0u8; 1];
    assert_eq!(s.read(&mut buf).unwrap_or(0), 0, "closed by the device");
    assert!(wait_for(|| !device.is_connected()));
    assert_eq!(device.read(2, 0.002), Err(DeviceFault::Disconnected));

    // garbage bytes: closed again, no panic
    let mut g = TcpStream::connect(device.address()).expect("connect");
    g.write_all(&[0xffu8; 500]).expect("send");
    let _ = g.read(&mut buf);
    drop(g);

    // a client that stops mid-message does not hang the device; the next one is served
    let mut slow = TcpStream::connect(device.address()).expect("connect");
    slow.write_all(&transform_packet([1.0, 1.0, 1.0])[..30])
        .expect("send");
    drop(slow);

    let mut s2 = TcpStream::connect(device.address()).expect("reconnect");
    s2.set_read_timeout(Some(Duration::from_secs(5)))
        .expect("timeout");
    s2.write_all(&transform_packet([5.0, 5.0, 5.0]))
        .expect("send");
    read_force(&mut s2);
    let pose = device.read(3, 0.003).expect("pose after reconnect");
    assert!((pose.tip_in_world - Point3::new(0.005, 0.005, 0.005)).norm() < 1e-9);
    assert!(
        device
            .counters()
            .connections
            .load(std::sync::atomic::Ordering::Relaxed)
            >= 4
    );

    // the pose goes stale when the client stops sending
    device.stale_after_nanos = 20_000_000;
    assert!(wait_for(|| matches!(
        device.read(4, 0.004),
        Err(DeviceFault::Stale { .. })
    )));
}

const PYIGTL_CLIENT: &str = r#"
import json, sys, time
import numpy as np
import pyigtl

port = int(sys.argv[1])
client = pyigtl.OpenIGTLinkClient(host="127.0.0.1", port=port)
t0 = time.time()
while not client.is_connected() and time.time() - t0 < 10:
    time.sleep(0.01)
for i in range(20):
    m = np.eye(4)
    m[0:3, 0:3] = [[0, -1, 0], [1, 0, 0], [0, 0, 1]]  # 90 degrees about z
    m[0:3, 3] = [10.0 + i, 20.0, 30.0]
    client.send_message(pyigtl.TransformMessage(m, device_name="Tool"), wait=True)
    time.sleep(0.005)
msg = client.wait_for_message("Force", timeout=5)
print(json.dumps({"type": msg.message_type, "force": [float(x) for x in msg.positions[0]], "name": msg.names[0]}), flush=True)
time.sleep(1.0)
client.stop()
"#;

#[test]
fn pyigtl_client_sends_poses_and_reads_forces() {
    // .ci/run always sets this (it installs pyigtl from PyPI into a venv).
    let Some(python) = std::env::var_os("CUTLAB_PYIGTL_PYTHON") else {
        println!(
            "SKIPPED pyigtl interop: CUTLAB_PYIGTL_PYTHON is not set (run .ci/run, or point it at a python with pyigtl)"
        );
        return;
    };
    let mut device = local_device();
    device.write_force(Vector3::new(0.5, -1.25, 2.0)).ok();
    let mut child = std::process::Command::new(&python)
        .arg("-c")
        .arg(PYIGTL_CLIENT)
        .arg(device.address().port().to_string())
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::inherit())
        .spawn()
        .expect("python runs");
    let mut line = String::new();
    BufReader::new(child.stdout.take().expect("stdout"))
        .read_line(&mut line)
        .expect("a line from the client");
    // the client is still connected (it sleeps 1 s): the device has its last pose
    let pose = device.read(0, 0.0).expect("pose from pyigtl");
    assert!(
        (pose.tip_in_world - Point3::new(0.029, 0.02, 0.03)).norm() < 1e-6,
        "{pose:?}"
    );
    let x_axis = pose.world_from_tool * Vector3::x();
    assert!(
        (x_axis - Vector3::y()).norm() < 1e-6,
        "90 degrees about z: {x_axis:?}"
    );
    let status = child.wait().expect("python exits");
    assert!(status.success(), "pyigtl client failed: {line}");
    let v: serde_json::Value =
        serde_json::from_str(line.trim()).unwrap_or_else(|e| panic!("{e}: {line}"));
    assert_eq!(v["type"], "POINT");
    assert_eq!(v["name"], "force");
    let f: Vec<f64> = v["force"]
        .as_array()
        .expect("force")
        .iter()
        .map(|x| x.as_f64().expect("number"))
        .collect();
    assert_eq!(f, vec![0.5, -1.25, 2.0]);
    assert!(
        device
            .counters()
            .transforms
            .load(std::sync::atomic::Ordering::Relaxed)
            >= 20
    );
    assert_eq!(
        device
            .counters()
            .rejected
            .load(std::sync::atomic::Ordering::Relaxed),
        0,
        "pyigtl's CRC and framing are accepted"
    );
}

#[test]
fn the_force_can_go_back_as_a_transform_named_for_plus() {
    let mut device = IgtlDevice::listen_with(
        "127.0.0.1:0".parse().expect("address"),
        IgtlOptions::plus_openhaptics("Ref"),
    )
    .expect("listen");
    assert_eq!(device.force_output(), ForceOutput::Transform);
    device.write_force(Vector3::new(0.75, -1.5, 2.25)).ok();
    let mut s = TcpStream::connect(device.address()).expect("connect");
    s.set_read_timeout(Some(Duration::from_secs(5)))
        .expect("timeout");
    for k in 0..3 {
        s.write_all(&transform_packet([10.0 + k as f64, 0.0, 0.0]))
            .expect("send");
        // every pose is answered by one TRANSFORM: the force in newtons, identity rotation
        let mut reply = [0u8; HEADER_BYTES + TRANSFORM_BODY_BYTES];
        s.read_exact(&mut reply).expect("force reply");
        let mut hb = [0u8; HEADER_BYTES];
        hb.copy_from_slice(&reply[..HEADER_BYTES]);
        let h = Header::parse(&hb).expect("header");
        assert_eq!(h.message_type(), b"TRANSFORM");
        assert_eq!(h.device_name(), b"ForceToRef");
        let (t, q) = decode_transform(content(&h, &reply[HEADER_BYTES..]).expect("crc"))
            .expect("a rigid transform");
        // (decode_transform scales by 1e-3 in f64: equal to rounding)
        let f = t.coords * 1e3;
        assert!(
            (f - Vector3::new(0.75, -1.5, 2.25)).norm() < 1e-12,
            "newtons, not mm: {f:?}"
        );
        assert_eq!(q, Rotation::identity());
    }
    let pose = device.read(0, 0.0).expect("pose");
    assert!((pose.tip_in_world - Point3::new(0.012, 0.0, 0.0)).norm() < 1e-9);
    // a name PLUS or the header could not take is refused up front
    let long = IgtlOptions {
        force_device_name: "ForceToAReferenceFrameTooLong".into(),
        ..IgtlOptions::plus_openhaptics("Ref")
    };
    assert!(IgtlDevice::listen_with("127.0.0.1:0".parse().expect("address"), long).is_err());
}

const PYIGTL_FORCE_TRANSFORM_CLIENT: &str = r#"
import json, sys, time
import numpy as np
import pyigtl

port = int(sys.argv[1])
client = pyigtl.OpenIGTLinkClient(host="127.0.0.1", port=port)
t0 = time.time()
while not client.is_connected() and time.time() - t0 < 10:
    time.sleep(0.01)
for i in range(10):
    m = np.eye(4)
    m[0:3, 3] = [10.0 + i, 0.0, 0.0]
    client.send_message(pyigtl.TransformMessage(m, device_name="StylusToBase"), wait=True)
    time.sleep(0.005)
msg = client.wait_for_message("ForceToRef", timeout=5)
print(json.dumps({"type": msg.message_type, "matrix": np.asarray(msg.matrix).tolist()}), flush=True)
client.stop()
"#;

#[test]
fn pyigtl_client_reads_the_force_as_a_transform() {
    // .ci/run always sets this (it installs pyigtl from PyPI into a venv).
    let Some(python) = std::env::var_os("CUTLAB_PYIGTL_PYTHON") else {
        println!(
            "SKIPPED pyigtl force transform: CUTLAB_PYIGTL_PYTHON is not set (run .ci/run, or point it at a python with pyigtl)"
        );
        return;
    };
    let mut device = IgtlDevice::listen_with(
        "127.0.0.1:0".parse().expect("address"),
        IgtlOptions::plus_openhaptics("Ref"),
    )
    .expect("listen");
    device.write_force(Vector3::new(0.5, -1.25, 2.0)).ok();
    let out = std::process::Command::new(&python)
        .arg("-c")
        .arg(PYIGTL_FORCE_TRANSFORM_CLIENT)
        .arg(device.address().port().to_string())
        .stderr(std::process::Stdio::inherit())
        .output()
        .expect("python runs");
    let line = String::from_utf8_lossy(&out.stdout);
    assert!(out.status.success(), "pyigtl client failed: {line}");
    let v: serde_json::Value =
        serde_json::from_str(line.trim()).unwrap_or_else(|e| panic!("{e}: {line}"));
    assert_eq!(v["type"], "TRANSFORM");
    let m: Vec<Vec<f64>> = serde_json::from_value(v["matrix"].clone()).expect("4x4 matrix");
    // the force in newtons is the translation, the rotation the identity
    let translation: Vec<f64> = m.iter().take(3).map(|row| row[3]).collect();
    assert_eq!(translation, vec![0.5, -1.25, 2.0]);
    for (i, row) in m.iter().take(3).enumerate() {
        for (j, &x) in row.iter().take(3).enumerate() {
            assert_eq!(x, if i == j { 1.0 } else { 0.0 }, "rotation ({i}, {j})");
        }
    }
    assert_eq!(
        device
            .counters()
            .rejected
            .load(std::sync::atomic::Ordering::Relaxed),
        0
    );
}

/// A packet of `message_type` named `name` with `body`.
fn packet(message_type: &str, name: &str, body: &[u8]) -> Vec<u8> {
    let mut out = Vec::new();
    Header::write(message_type, name, 0, body, &mut out);
    out.extend_from_slice(body);
    out
}

/// A TRANSFORM named `name`: identity rotation, translation in mm.
fn named_transform(name: &str, t_mm: [f64; 3]) -> Vec<u8> {
    let mut out = Vec::new();
    encode_transform(
        name,
        &(Point3::from(t_mm) * 1e-3),
        &Rotation::identity(),
        0,
        &mut out,
    );
    out
}

/// A STRING named `name` saying `text` (US-ASCII).
fn string_packet(name: &str, text: &str) -> Vec<u8> {
    let mut body = 3u16.to_be_bytes().to_vec();
    body.extend((text.len() as u16).to_be_bytes());
    body.extend(text.as_bytes());
    packet("STRING", name, &body)
}

/// Reads one force reply: its device name and the POINT's x y z.
fn read_named_force(stream: &mut TcpStream) -> (String, Vector3) {
    let mut reply = [0u8; HEADER_BYTES + POINT_ELEMENT_BYTES];
    stream.read_exact(&mut reply).expect("force reply");
    let header =
        Header::parse(reply[..HEADER_BYTES].try_into().expect("a header")).expect("header");
    let name = String::from_utf8_lossy(header.device_name()).into_owned();
    (name, read_force(&mut std::io::Cursor::new(reply)))
}

/// Two tools on one connection, told apart by name: the scalpel's TRANSFORMs and its force as
/// before, the grasper's TRANSFORMs (named `Grasper`) its own device's, its jaws closed and
/// opened by the STRING `GrasperJaws`, its force back as `GrasperForce`.
#[test]
fn a_second_tool_by_name_is_the_graspers_with_its_jaws_and_its_own_force() {
    use cutlab_haptics::device::igtl::IgtlToolNames;
    let options = IgtlOptions {
        grasper: Some(IgtlToolNames::grasper("Grasper")),
        ..IgtlOptions::default()
    };
    let mut device =
        IgtlDevice::listen_with("127.0.0.1:0".parse().expect("address"), options).expect("listen");
    let mut grasper = device.take_grasper().expect("a grasper");
    assert!(device.take_grasper().is_none(), "taken once");
    device.write_force(Vector3::new(0.25, 0.0, 0.0)).ok();
    grasper.write_force(Vector3::new(0.0, 0.0, -0.5)).ok();
    let mut s = TcpStream::connect(device.address()).expect("connect");
    s.write_all(&named_transform("StylusToRef", [10.0, 20.0, 30.0]))
        .expect("send");
    let (name, f) = read_named_force(&mut s);
    assert_eq!((name.as_str(), f), ("Force", Vector3::new(0.25, 0.0, 0.0)));
    s.write_all(&named_transform("Grasper", [40.0, 50.0, 60.0]))
        .expect("send");
    let (name, f) = read_named_force(&mut s);
    assert_eq!(
        (name.as_str(), f),
        ("GrasperForce", Vector3::new(0.0, 0.0, -0.5))
    );
    let at = |d: &mut dyn HapticDevice, x_m: f64, closed: bool| {
        wait_for(|| {
            d.read(0, 0.0)
                .is_ok_and(|p| (p.tip_in_world.x - x_m).abs() < 1e-6 && p.jaws_closed() == closed)
        })
    };
    assert!(
        at(&mut grasper, 0.04, false),
        "the grasper's pose, jaws open"
    );
    assert!(
        device
            .read(0, 0.0)
            .is_ok_and(|p| (p.tip_in_world.x - 0.01).abs() < 1e-6 && p.blade_engaged())
    );
    // the jaws close on their STRING and open again on it; the scalpel's stays as it was
    s.write_all(&string_packet("GrasperJaws", "1"))
        .expect("send");
    s.write_all(&named_transform("Grasper", [41.0, 50.0, 60.0]))
        .expect("send");
    read_named_force(&mut s);
    assert!(at(&mut grasper, 0.041, true), "closed");
    s.write_all(&string_packet("GrasperJaws", "0"))
        .expect("send");
    s.write_all(&named_transform("Grasper", [42.0, 50.0, 60.0]))
        .expect("send");
    read_named_force(&mut s);
    assert!(at(&mut grasper, 0.042, false), "open again");
    assert!(
        device
            .read(0, 0.0)
            .is_ok_and(|p| !p.jaws_closed() && p.blade_engaged())
    );
    // the scalpel's own button is its STRING `Button`, apart from the jaws'
    s.write_all(&string_packet("Button", "0")).expect("send");
    s.write_all(&named_transform("StylusToRef", [11.0, 20.0, 30.0]))
        .expect("send");
    read_named_force(&mut s);
    assert!(wait_for(|| device.read(0, 0.0).is_ok_and(|p| {
        (p.tip_in_world.x - 0.011).abs() < 1e-6 && !p.blade_engaged() && !p.jaws_closed()
    })));
    assert!(
        at(&mut grasper, 0.042, false),
        "the jaws did not move with it"
    );
    // a STRING named for nothing is ignored, not taken for a button
    s.write_all(&string_packet("Elsewhere", "0")).expect("send");
    assert!(wait_for(|| device
        .counters()
        .ignored
        .load(std::sync::atomic::Ordering::Relaxed)
        >= 1));
    // names that cannot be told apart or sent are refused
    for bad in ["Force", "two words", ""] {
        let options = IgtlOptions {
            grasper: Some(IgtlToolNames::grasper(bad)),
            ..IgtlOptions::default()
        };
        assert!(options.check().is_err(), "{bad:?}");
    }
}
