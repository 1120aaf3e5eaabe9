//! The parser entry points that damaged input is fed to, one function per parser: the
//! mutation test (`tests/mutation.rs`) and the cargo-fuzz targets (`fuzz/`) both call these,
//! so both mean the same thing by "the Gmsh reader" or "the OpenIGTLink framing". The
//! recordings' parsers are in `recording_targets.rs` (the fuzz targets of the other parsers
//! are built without the recorder and its dependencies).
//!
//! Each returns `Ok` when the parser accepted the input and `Err` (the parser's message) when
//! it refused it; both are fine. A panic is a bug, and so is an accepted input whose result
//! breaks what the parser promises (a non-finite position or pose): those are checked with
//! `assert!` here, so they count as failures too.

use std::path::Path;

/// What one input did: accepted, or refused with the parser's message.
pub type Outcome = Result<(), String>;

fn text(data: &[u8]) -> std::borrow::Cow<'_, str> {
    // as the file readers do: invalid UTF-8 is replaced, not rejected
    String::from_utf8_lossy(data)
}

fn check_mesh(mesh: &cutlab_sim::TetMesh) {
    assert!(mesh.tet_count() > 0, "an accepted mesh has tetrahedra");
    assert!(
        mesh.positions()
            .iter()
            .all(|p| p.iter().all(|c| c.is_finite())),
        "an accepted mesh has finite positions"
    );
    let n = mesh.vertex_count();
    assert!(
        mesh.tets().iter().flatten().all(|&v| (v as usize) < n),
        "an accepted mesh's tetrahedra refer to its vertices"
    );
    assert_eq!(mesh.regions().len(), mesh.tet_count());
}

fn mesh(result: Result<cutlab_sim::TetMesh, cutlab_sim::ReadError>) -> Outcome {
    let mesh = result.map_err(|e| e.to_string())?;
    check_mesh(&mesh);
    Ok(())
}

/// Legacy VTK (`cutlab_sim::io::read_vtk_str`).
pub fn mesh_vtk(data: &[u8]) -> Outcome {
    mesh(cutlab_sim::io::read_vtk_str(
        &text(data),
        Path::new("fuzz.vtk"),
    ))
}

/// VTK XML (`cutlab_sim::io::read_vtu_str`).
pub fn mesh_vtu(data: &[u8]) -> Outcome {
    mesh(cutlab_sim::io::read_vtu_str(
        &text(data),
        Path::new("fuzz.vtu"),
    ))
}

/// Gmsh `.msh` 1, 2.x and 4.1 (`cutlab_sim::io::read_gmsh_str`).
pub fn mesh_gmsh(data: &[u8]) -> Outcome {
    mesh(cutlab_sim::io::read_gmsh_str(
        &text(data),
        Path::new("fuzz.msh"),
    ))
}

/// TetGen `.node` + `.ele` (`cutlab_sim::io::read_tetgen_str`).
pub fn mesh_tetgen(node: &[u8], ele: &[u8]) -> Outcome {
    mesh(cutlab_sim::io::read_tetgen_str(
        &text(node),
        Path::new("fuzz.node"),
        &text(ele),
        Path::new("fuzz.ele"),
    ))
}

/// TetGen with both files in one input, split at the first NUL byte (for libFuzzer, which
/// hands over one byte string): `node \0 ele`.
pub fn mesh_tetgen_joined(data: &[u8]) -> Outcome {
    let (node, ele) = match data.iter().position(|&b| b == 0) {
        Some(i) => (&data[..i], &data[i + 1..]),
        None => (data, &[][..]),
    };
    mesh_tetgen(node, ele)
}

/// A NIfTI-1 label volume, raw or gzipped (`cutlab_sim::segmentation::LabelVolume::read`,
/// which reads a path: the bytes are written to `dir/input.nii` first).
pub fn nifti(data: &[u8], dir: &Path) -> Outcome {
    let path = dir.join("input.nii");
    std::fs::write(&path, data).map_err(|e| format!("cannot write {}: {e}", path.display()))?;
    let volume = cutlab_sim::segmentation::LabelVolume::read(&path).map_err(|e| e.to_string())?;
    let [nx, ny, nz] = volume.dims();
    assert_eq!(volume.labels().len(), nx * ny * nz);
    assert!(volume.world_from_voxel().iter().all(|x| x.is_finite()));
    Ok(())
}

/// A scene file (`cutlab_sim::scene::parse_spec`): JSON when it starts with `{`, else TOML.
pub fn scene(data: &[u8]) -> Outcome {
    let json = data.trim_ascii_start().starts_with(b"{");
    let path = Path::new(if json { "fuzz.json" } else { "fuzz.toml" });
    cutlab_sim::scene::parse_spec(&text(data), path)
        .map(|_| ())
        .map_err(|e| e.to_string())
}

/// A trajectory CSV (`cutlab_haptics::device::CsvDevice::parse`); an accepted file is
/// played at a few times, and its poses must be finite rigid motions.
pub fn trajectory_csv(data: &[u8]) -> Outcome {
    use cutlab_haptics::device::CsvDevice;
    let mut device =
        CsvDevice::parse(&text(data), Path::new("fuzz.csv")).map_err(|e| e.to_string())?;
    let end = device.duration_s();
    for t in [-1.0, 0.0, 0.25 * end, 0.5 * end, end, end + 1.0] {
        let pose = device.pose_at(t);
        check_rigid(
            &pose.tip_in_world,
            &pose.world_from_tool,
            &format!("at {t}: {pose:?}"),
        );
    }
    Ok(())
}

/// OpenIGTLink framing as the device's network thread does it (`Header::parse`, `content`,
/// `decode_transform` of `cutlab_haptics::device::igtl`): a packet is a 58-byte header and
/// its body. The packet is read as it is and again with its body size and CRC made to match
/// (so damage behind the CRC reaches the body's decoding), and the bytes after the header are
/// also decoded as a bare TRANSFORM body.
pub fn igtl(data: &[u8]) -> Outcome {
    use cutlab_haptics::device::igtl::{self, HEADER_BYTES};
    let as_is = igtl_packet(data);
    let mut fixed = data.to_vec();
    if fixed.len() >= HEADER_BYTES {
        let body_len = (fixed.len() - HEADER_BYTES) as u64;
        fixed[42..50].copy_from_slice(&body_len.to_be_bytes());
        let crc = igtl::crc64_ecma(&fixed[HEADER_BYTES..]);
        fixed[50..58].copy_from_slice(&crc.to_be_bytes());
    }
    let restamped = igtl_packet(&fixed);
    if let Some(body) = data.get(HEADER_BYTES..) {
        check_transform(igtl::decode_transform(body));
    }
    as_is.and(restamped)
}

fn check_transform(
    decoded: Result<
        (cutlab_haptics::Point3, cutlab_haptics::Rotation),
        cutlab_haptics::device::igtl::PacketError,
    >,
) {
    if let Ok((tip, rotation)) = decoded {
        check_rigid(&tip, &rotation, &format!("{tip:?} {rotation:?}"));
    }
}

/// What an accepted pose must be: a finite tip and a unit rotation (`what` names it).
pub fn check_rigid(tip: &cutlab_haptics::Point3, rotation: &cutlab_haptics::Rotation, what: &str) {
    assert!(tip.iter().all(|c| c.is_finite()), "a finite tip {what}");
    let q = rotation.quaternion();
    assert!(
        q.coords.iter().all(|c| c.is_finite()) && (q.norm() - 1.0).abs() < 1e-6,
        "a unit rotation {what}"
    );
}

fn igtl_packet(data: &[u8]) -> Outcome {
    use cutlab_haptics::device::igtl::{self, HEADER_BYTES};
    let mut header = [0u8; HEADER_BYTES];
    let n = data.len().min(HEADER_BYTES);
    header[..n].copy_from_slice(&data[..n]);
    let h = igtl::Header::parse(&header).map_err(|e| e.to_string())?;
    let _ = (h.message_type(), h.device_name());
    // the network thread reads exactly body_bytes (at most MAX_BODY_BYTES) after the header
    let rest = data.get(HEADER_BYTES..).unwrap_or_default();
    let body = usize::try_from(h.body_bytes)
        .ok()
        .and_then(|len| rest.get(..len))
        .ok_or_else(|| format!("short body: {} of {} bytes", rest.len(), h.body_bytes))?;
    let content = igtl::content(&h, body).map_err(|e| e.to_string())?;
    if h.message_type() == b"TRANSFORM" {
        let decoded = igtl::decode_transform(content);
        check_transform(decoded);
        decoded.map_err(|e| e.to_string())?;
    }
    Ok(())
}
