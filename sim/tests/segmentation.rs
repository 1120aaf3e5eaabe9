//! Segmentation to mesh on the TotalSegmentator example data (see data/README.md).
//!
//! Header of example_seg.nii.gz and of the two masks (read by hand with a hex dump /
//! struct.unpack): dims 122 x 101 x 30, uint8, pixdim 3 mm, xyzt_units 0 (mm assumed),
//! qform_code 0, sform_code 2 with
//!   srow_x = [3, 0, 0, -177.95632934570312]
//!   srow_y = [0, 3, 0,   11.319000244140625]
//!   srow_z = [0, 0, 3,   94.3017578125]
//! Liver (label 5): 38,634 voxels, index extent x 41..=105, y 25..=86, z 0..=29.
//! Body wall: skeletal_muscle 35,293 + subcutaneous_fat 35,357 voxels (no overlap), union
//! extent x 2..=114, y 8..=93, z 0..=29.

use std::io::Read;
use std::path::{Path, PathBuf};

use cutlab_sim::segmentation::{
    LabelVolume, MeshingOptions, NonManifold, Resample, mesh_labels, mesh_labels_with_report,
};
use cutlab_sim::{ReadError, SegmentationError, TetMesh};
use nalgebra::Matrix4;

const SEG: &str = concat!(
    env!("CARGO_MANIFEST_DIR"),
    "/../data/totalsegmentator/example_seg.nii.gz"
);
const SEG_MR: &str = concat!(
    env!("CARGO_MANIFEST_DIR"),
    "/../data/totalsegmentator/example_seg_mr.nii.gz"
);
const MUSCLE: &str = concat!(
    env!("CARGO_MANIFEST_DIR"),
    "/../data/totalsegmentator/skeletal_muscle.nii.gz"
);
const FAT: &str = concat!(
    env!("CARGO_MANIFEST_DIR"),
    "/../data/totalsegmentator/subcutaneous_fat.nii.gz"
);

const VOXEL_M3: f64 = 27e-9; // (3 mm)^3
const LIVER_VOXELS: usize = 38_634;
const MUSCLE_VOXELS: usize = 35_293;
const FAT_VOXELS: usize = 35_357;

fn tmp(name: &str) -> PathBuf {
    let dir = Path::new(env!("CARGO_TARGET_TMPDIR")).join("segmentation");
    std::fs::create_dir_all(&dir).expect("temp dir");
    dir.join(name)
}

/// The decompressed bytes of example_seg.nii.gz (header at 0, data at 13168).
fn seg_bytes() -> Vec<u8> {
    let gz = std::fs::read(SEG).expect("example_seg");
    let mut out = Vec::new();
    flate2::read::GzDecoder::new(&gz[..])
        .read_to_end(&mut out)
        .expect("gunzip");
    out
}

fn put_i16(b: &mut [u8], at: usize, v: i16) {
    b[at..at + 2].copy_from_slice(&v.to_le_bytes());
}

fn put_f32(b: &mut [u8], at: usize, v: f32) {
    b[at..at + 4].copy_from_slice(&v.to_le_bytes());
}

/// Writes a little-endian NIfTI-1 file with the example header, the given dims, datatype and
/// raw data (vox_offset 352, sform as in the example).
fn write_nifti(name: &str, dims: [i16; 3], datatype: i16, bitpix: i16, data: &[u8]) -> PathBuf {
    let mut b = seg_bytes()[..352].to_vec();
    b[348..352].fill(0); // no extensions
    for (a, d) in dims.iter().enumerate() {
        put_i16(&mut b, 42 + 2 * a, *d);
    }
    put_i16(&mut b, 70, datatype);
    put_i16(&mut b, 72, bitpix);
    put_f32(&mut b, 108, 352.0);
    b.extend_from_slice(data);
    let path = tmp(name);
    std::fs::write(&path, b).expect("write");
    path
}

fn assert_rel(a: f64, b: f64, tol: f64, what: &str) {
    assert!(
        (a - b).abs() <= tol * b.abs(),
        "{what}: {a} vs {b} (rel. tol. {tol})"
    );
}

/// Validity, orientation, count, volume and regions of a plain (unresampled) voxel mesh.
fn check_voxel_mesh(mesh: &TetMesh, voxels: usize, regions: &[u32]) {
    let report = mesh.validate();
    assert!(report.is_ok(), "{report}");
    assert!(
        (0..mesh.tet_count()).all(|t| mesh.tet_volume(t) > 0.0),
        "non-positive tet"
    );
    assert_eq!(mesh.tet_count(), 6 * voxels);
    assert_rel(mesh.volume(), voxels as f64 * VOXEL_M3, 1e-9, "volume");
    assert_eq!(mesh.region_ids(), regions);
}

/// World bounding box (metres) of the voxels with index extent `lo..=hi`, from the sform:
/// corners at lo - 1/2 and hi + 1/2, x = 3 i + t (mm).
fn hand_bbox(lo: [f64; 3], hi: [f64; 3]) -> ([f64; 3], [f64; 3]) {
    let t = [
        -177.956_329_345_703_12,
        11.319_000_244_140_625,
        94.301_757_812_5,
    ];
    let f = |i: f64, a: usize| (3.0 * i + t[a]) * 1e-3;
    (
        [0, 1, 2].map(|a| f(lo[a] - 0.5, a)),
        [0, 1, 2].map(|a| f(hi[a] + 0.5, a)),
    )
}

fn assert_bbox(mesh: &TetMesh, lo: [f64; 3], hi: [f64; 3]) {
    let (mlo, mhi) = mesh.bounding_box();
    for a in 0..3 {
        assert!(
            (mlo[a] - lo[a]).abs() < 1e-9,
            "bbox min[{a}]: {} vs {}",
            mlo[a],
            lo[a]
        );
        assert!(
            (mhi[a] - hi[a]).abs() < 1e-9,
            "bbox max[{a}]: {} vs {}",
            mhi[a],
            hi[a]
        );
    }
}

#[test]
fn header_affine_is_the_sform_in_metres() {
    let vol = LabelVolume::read(SEG).expect("read");
    assert_eq!(vol.dims(), [122, 101, 30]);
    #[rustfmt::skip]
    let expected = Matrix4::new(
        3e-3, 0.0, 0.0, -0.177_956_329_345_703_12,
        0.0, 3e-3, 0.0, 0.011_319_000_244_140_625,
        0.0, 0.0, 3e-3, 0.094_301_757_812_5,
        0.0, 0.0, 0.0, 1.0,
    );
    assert!(
        (vol.world_from_voxel() - expected).amax() < 1e-12,
        "{}",
        vol.world_from_voxel()
    );
    assert_rel(vol.voxel_volume(), VOXEL_M3, 1e-12, "voxel volume");
    assert_eq!(
        vol.label_counts().iter().find(|(l, _)| *l == 5),
        Some(&(5, LIVER_VOXELS))
    );
}

#[test]
fn liver_mesh() {
    let vol = LabelVolume::read(SEG).expect("read");
    let mesh = mesh_labels(&vol, &MeshingOptions::new([5])).expect("mesh");
    check_voxel_mesh(&mesh, LIVER_VOXELS, &[5]);
    let (lo, hi) = hand_bbox([41.0, 25.0, 0.0], [105.0, 86.0, 29.0]);
    assert_bbox(&mesh, lo, hi);
}

#[test]
fn body_wall_mesh_from_masks() {
    let vol = LabelVolume::from_mask_files(&[(MUSCLE, 1), (FAT, 2)]).expect("masks");
    assert_eq!(
        vol.label_counts(),
        vec![(1, MUSCLE_VOXELS), (2, FAT_VOXELS)]
    );
    let (mesh, report) = mesh_labels_with_report(&vol, &MeshingOptions::new([1, 2])).expect("mesh");
    check_voxel_mesh(&mesh, MUSCLE_VOXELS + FAT_VOXELS, &[1, 2]);
    let per_region = |r: u32| mesh.regions().iter().filter(|&&x| x == r).count();
    assert_eq!(per_region(1), 6 * MUSCLE_VOXELS);
    assert_eq!(per_region(2), 6 * FAT_VOXELS);
    let (lo, hi) = hand_bbox([2.0, 8.0, 0.0], [114.0, 93.0, 29.0]);
    assert_bbox(&mesh, lo, hi);
    // Thin layers of 3 mm voxels touch along edges here and there; the report says so.
    assert!(report.non_manifold_vertices > 0);
}

#[test]
fn overlapping_masks_first_wins() {
    let vol = LabelVolume::from_mask_files(&[(MUSCLE, 7), (MUSCLE, 3), (FAT, 9)]).expect("masks");
    assert_eq!(
        vol.label_counts(),
        vec![(7, MUSCLE_VOXELS), (9, FAT_VOXELS)]
    );
}

/// Coarsening by 2 with a majority vote. Tet count: ~8x fewer (exactly 8x for a volume made
/// of whole 2x2x2 blocks; boundary blocks are kept or dropped by the vote). Volume: a coarse
/// voxel of 8 fine voxels v errs by at most 4v, and only in blocks mixing inside and outside,
/// which is a hard bound computed below; in practice the errors of eroded and dilated boundary
/// blocks nearly cancel (liver: -0.1 %, body wall: -0.5 %, thinner layers have relatively
/// more boundary), so 2 % is asserted as well.
#[test]
fn resampling_by_two() {
    let seg = LabelVolume::read(SEG).expect("read");
    let wall = LabelVolume::from_mask_files(&[(MUSCLE, 1), (FAT, 2)]).expect("masks");
    for (vol, labels, voxels) in [
        (&seg, vec![5], LIVER_VOXELS),
        (&wall, vec![1, 2], MUSCLE_VOXELS + FAT_VOXELS),
    ] {
        let opts = MeshingOptions {
            resample: Some(Resample::Factor(2)),
            ..MeshingOptions::new(labels.clone())
        };
        let (mesh, report) = mesh_labels_with_report(vol, &opts).expect("mesh");
        let r = mesh.validate();
        assert!(r.is_ok(), "{r}");
        assert_eq!(report.factors, [2, 2, 2]);
        assert_eq!(mesh.region_ids(), labels);
        let ratio = (6 * voxels) as f64 / mesh.tet_count() as f64;
        assert!((7.0..9.0).contains(&ratio), "tet reduction {ratio}");
        let fine = voxels as f64 * VOXEL_M3;
        // Hard bound: 4 fine voxels per mixed block.
        let sel = vol.select(&labels);
        let [nx, ny, nz] = sel.dims();
        let mut mixed = 0usize;
        for k in (0..nz).step_by(2) {
            for j in (0..ny).step_by(2) {
                for i in (0..nx).step_by(2) {
                    let mut inside = 0;
                    let mut total = 0;
                    for (di, dj, dk) in (0..8).map(|b| (b & 1, (b >> 1) & 1, b >> 2)) {
                        if i + di < nx && j + dj < ny && k + dk < nz {
                            total += 1;
                            inside += usize::from(sel.label([i + di, j + dj, k + dk]) != 0);
                        }
                    }
                    mixed += usize::from(inside > 0 && inside < total);
                }
            }
        }
        let err = (mesh.volume() - fine).abs();
        assert!(
            err <= 4.0 * VOXEL_M3 * mixed as f64,
            "volume error {err} above hard bound"
        );
        assert_rel(mesh.volume(), fine, 0.02, "resampled volume");
    }
}

#[test]
fn resample_to_spacing_rounds_to_integer_factors() {
    let vol = LabelVolume::read(SEG).expect("read");
    assert_eq!(
        Resample::Spacing([0.006, 0.0075, 0.001])
            .factors(vol.spacing())
            .expect("factors"),
        [2, 3, 1]
    );
    assert!(
        Resample::Spacing([0.0, 1.0, 1.0])
            .factors(vol.spacing())
            .is_err()
    );
    assert!(Resample::Factor(0).factors(vol.spacing()).is_err());
}

/// Rewrites example_seg with sform_code / qform_code / srow_x[0] / pixdim[0] patched.
fn patched(name: &str, patch: impl FnOnce(&mut Vec<u8>)) -> PathBuf {
    let mut b = seg_bytes();
    patch(&mut b);
    let path = tmp(name);
    std::fs::write(&path, b).expect("write");
    path
}

#[test]
fn left_handed_sform_gives_positive_tets() {
    // srow_x = [-3, 0, 0, -177.956...]: the index x axis points to the world's left.
    let path = patched("flipped_sform.nii", |b| put_f32(b, 280, -3.0));
    let vol = LabelVolume::read(&path).expect("read");
    assert!(vol.signed_voxel_volume() < 0.0);
    let mesh = mesh_labels(&vol, &MeshingOptions::new([5])).expect("mesh");
    check_voxel_mesh(&mesh, LIVER_VOXELS, &[5]);
    // x mirrored: x = -3 i + t.
    let t = -177.956_329_345_703_12;
    let (_, mut hi) = hand_bbox([41.0, 25.0, 0.0], [105.0, 86.0, 29.0]);
    let (mut lo, _) = hand_bbox([41.0, 25.0, 0.0], [105.0, 86.0, 29.0]);
    lo[0] = (-3.0 * 105.5 + t) * 1e-3;
    hi[0] = (-3.0 * 40.5 + t) * 1e-3;
    assert_bbox(&mesh, lo, hi);
}

#[test]
fn qform_and_pixdim_fallbacks() {
    let sform = LabelVolume::read(SEG).expect("read");
    // sform_code 0, qform_code 1: identity quaternion, pixdim 3, same offsets -> same affine.
    let q = patched("qform.nii", |b| {
        put_i16(b, 254, 0);
        put_i16(b, 252, 1);
    });
    let qvol = LabelVolume::read(&q).expect("read qform");
    assert!((qvol.world_from_voxel() - sform.world_from_voxel()).amax() < 1e-12);
    // qfac = pixdim[0] = -1 flips the third axis: left-handed, still positive tets.
    let qneg = patched("qform_qfac.nii", |b| {
        put_i16(b, 254, 0);
        put_i16(b, 252, 1);
        put_f32(b, 76, -1.0);
    });
    let qneg = LabelVolume::read(&qneg).expect("read qfac");
    assert!((qneg.world_from_voxel()[(2, 2)] + 3e-3).abs() < 1e-15);
    check_voxel_mesh(
        &mesh_labels(&qneg, &MeshingOptions::new([5])).expect("mesh"),
        LIVER_VOXELS,
        &[5],
    );
    // A 90 degree rotation about z: quaternion (cos 45, 0, 0, sin 45), b = c = 0, d = sqrt(1/2).
    let rot = patched("qform_rot.nii", |b| {
        put_i16(b, 254, 0);
        put_i16(b, 252, 1);
        put_f32(b, 264, std::f32::consts::FRAC_1_SQRT_2);
    });
    let rot = LabelVolume::read(&rot).expect("read rotated");
    let a = rot.world_from_voxel();
    assert!(
        (a[(0, 1)] + 3e-3).abs() < 1e-9 && (a[(1, 0)] - 3e-3).abs() < 1e-9,
        "{a}"
    );
    // Neither: plain pixdim scaling, no offset.
    let none = patched("pixdim.nii", |b| {
        put_i16(b, 254, 0);
        put_i16(b, 252, 0);
    });
    let none = LabelVolume::read(&none).expect("read pixdim");
    assert!(
        (none.world_from_voxel()
            - Matrix4::new_scaling(3e-3).map_with_location(|i, j, x| if i == 3 && j == 3 {
                1.0
            } else {
                x
            }))
        .amax()
            < 1e-15
    );
}

#[test]
fn cleanup_and_smoothing_keep_the_mesh_valid() {
    let wall = LabelVolume::from_mask_files(&[(MUSCLE, 1), (FAT, 2)]).expect("masks");
    let opts = MeshingOptions {
        keep_largest_component: true,
        non_manifold: NonManifold::Fill,
        smooth_iterations: 3,
        ..MeshingOptions::new([1, 2])
    };
    let (mesh, report) = mesh_labels_with_report(&wall, &opts).expect("mesh");
    let r = mesh.validate();
    assert!(r.is_ok(), "{r}");
    assert!(
        report.components > 1 && report.island_voxels_removed > 0,
        "{report:?}"
    );
    assert!(report.voxels_filled > 0);
    assert!(mesh.topology().boundary_non_manifold_edges().is_empty());
    let voxels = MUSCLE_VOXELS + FAT_VOXELS - report.island_voxels_removed + report.voxels_filled;
    assert_eq!(report.voxel_count(), voxels);
    assert_eq!(mesh.tet_count(), 6 * voxels);
    // Taubin smoothing moves the surface but nearly preserves the volume.
    assert_rel(
        mesh.volume(),
        voxels as f64 * VOXEL_M3,
        0.01,
        "smoothed volume",
    );
    let plain = mesh_labels(
        &wall,
        &MeshingOptions {
            smooth_iterations: 0,
            ..opts.clone()
        },
    )
    .expect("mesh");
    let moved = plain
        .positions()
        .iter()
        .zip(mesh.positions())
        .filter(|(a, b)| (*a - *b).norm() > 1e-6)
        .count();
    assert!(moved > 1000, "only {moved} vertices moved");
}

/// Two voxels touching along an edge (and a third touching the first at a vertex only).
#[test]
fn edge_and_vertex_contacts() {
    let mut labels = vec![0u32; 8];
    labels[0] = 1; // (0,0,0)
    labels[3] = 1; // (1,1,0): shares only the edge x = y = 1/2 with (0,0,0)
    let vol = LabelVolume::new([2, 2, 2], labels.clone(), Matrix4::identity()).expect("volume");
    let (mesh, report) = mesh_labels_with_report(&vol, &MeshingOptions::new([1])).expect("mesh");
    assert!(mesh.validate().is_ok());
    assert_eq!(mesh.vertex_count(), 14); // 2 x 8 corners, 2 shared
    assert!(!mesh.topology().boundary_non_manifold_edges().is_empty());
    assert_eq!(report.non_manifold_vertices, 2);
    let fill = MeshingOptions {
        non_manifold: NonManifold::Fill,
        ..MeshingOptions::new([1])
    };
    let (mesh, report) = mesh_labels_with_report(&vol, &fill).expect("mesh");
    assert!(mesh.validate().is_ok());
    assert!(mesh.topology().boundary_non_manifold_edges().is_empty());
    assert_eq!(report.voxels_filled, 2);
    // vertex contact only: (0,0,0) and (1,1,1)
    labels[3] = 0;
    labels[7] = 1;
    let vol = LabelVolume::new([2, 2, 2], labels, Matrix4::identity()).expect("volume");
    let (mesh, report) = mesh_labels_with_report(&vol, &MeshingOptions::new([1])).expect("mesh");
    assert!(mesh.validate().is_ok());
    assert_eq!((mesh.vertex_count(), report.non_manifold_vertices), (15, 1));
}

#[test]
fn empty_selection_is_an_error() {
    let vol = LabelVolume::read(SEG).expect("read");
    let err = mesh_labels(&vol, &MeshingOptions::new([200, 201])).expect_err("no voxels");
    assert!(matches!(err, SegmentationError::NoVoxels { .. }));
    assert_eq!(err.to_string(), "no voxel carries labels [200, 201]");
    assert!(matches!(
        mesh_labels(&vol, &MeshingOptions::new([])),
        Err(SegmentationError::InvalidOptions(_))
    ));
    assert!(matches!(
        mesh_labels(&vol, &MeshingOptions::new([0, 5])),
        Err(SegmentationError::InvalidOptions(_))
    ));
}

fn assert_format_error(result: Result<LabelVolume, ReadError>, path: &Path, needle: &str) {
    match result {
        Err(e @ ReadError::Format { .. }) => {
            let msg = e.to_string();
            assert!(msg.contains(&path.display().to_string()), "{msg}");
            assert!(msg.contains(needle), "{msg}");
        }
        other => panic!("expected a format error mentioning {needle:?}, got {other:?}"),
    }
}

#[test]
fn malformed_files_are_errors() {
    // Truncated gzip stream.
    let gz = std::fs::read(SEG).expect("read");
    let trunc = tmp("truncated.nii.gz");
    std::fs::write(&trunc, &gz[..gz.len() / 2]).expect("write");
    assert_format_error(LabelVolume::read(&trunc), &trunc, "gzip");
    // Corrupt gzip body.
    let mut bad = gz.clone();
    for b in &mut bad[100..200] {
        *b ^= 0x5a;
    }
    let corrupt = tmp("corrupt.nii.gz");
    std::fs::write(&corrupt, &bad).expect("write");
    assert_format_error(LabelVolume::read(&corrupt), &corrupt, "gzip");
    // Not NIfTI at all.
    let text = tmp("not_nifti.nii");
    std::fs::write(&text, "this is not an image\n".repeat(40)).expect("write");
    assert_format_error(LabelVolume::read(&text), &text, "not a NIfTI-1 file");
    let short = tmp("short.nii");
    std::fs::write(&short, b"n+1").expect("write");
    assert_format_error(LabelVolume::read(&short), &short, "not a NIfTI-1 file");
    // Uncompressed file cut inside the voxel data.
    let raw = seg_bytes();
    let cut = tmp("cut.nii");
    std::fs::write(&cut, &raw[..raw.len() - 1000]).expect("write");
    assert_format_error(LabelVolume::read(&cut), &cut, "truncated voxel data");
    // Missing file: an I/O error naming it.
    let missing = tmp("does_not_exist.nii.gz");
    match LabelVolume::read(&missing) {
        Err(e @ ReadError::Io { .. }) => assert!(e.to_string().contains("does_not_exist.nii.gz")),
        other => panic!("{other:?}"),
    }
    // Header-only pair.
    let hdr = patched("pair.hdr", |b| b[344..348].copy_from_slice(b"ni1\0"));
    assert_format_error(LabelVolume::read(&hdr), &hdr, "not supported");
}

#[test]
fn datatypes_and_dimensionality() {
    // float32 labels that are integers are accepted...
    let floats: Vec<u8> = [0.0f32, 2.0, 5.0, 1.0]
        .iter()
        .flat_map(|v| v.to_le_bytes())
        .collect();
    let p = write_nifti("float_ok.nii", [2, 2, 1], 16, 32, &floats);
    assert_eq!(
        LabelVolume::read(&p).expect("float labels").labels(),
        &[0, 2, 5, 1]
    );
    // ... fractional ones are not.
    let floats: Vec<u8> = [0.0f32, 2.5, 5.0, 1.0]
        .iter()
        .flat_map(|v| v.to_le_bytes())
        .collect();
    let p = write_nifti("float_bad.nii", [2, 2, 1], 16, 32, &floats);
    assert_format_error(LabelVolume::read(&p), &p, "[1, 0, 0] holds 2.5");
    // Negative int16 labels are errors, positive ones fine.
    let ints: Vec<u8> = [0i16, 300, -1, 4]
        .iter()
        .flat_map(|v| v.to_le_bytes())
        .collect();
    let p = write_nifti("int16.nii", [2, 2, 1], 4, 16, &ints);
    assert_format_error(LabelVolume::read(&p), &p, "holds -1");
    // Unsupported datatype (complex64 = 32).
    let p = write_nifti("complex.nii", [1, 1, 1], 32, 64, &[0; 8]);
    assert_format_error(LabelVolume::read(&p), &p, "unsupported voxel datatype");
    // 4-D with two volumes is rejected; with one volume it is 3-D.
    let mut four = seg_bytes();
    put_i16(&mut four, 40, 4);
    put_i16(&mut four, 48, 2);
    let p = tmp("four_d.nii");
    std::fs::write(&p, &four).expect("write");
    assert_format_error(LabelVolume::read(&p), &p, "a label volume must be 3-D");
    put_i16(&mut four, 48, 1);
    std::fs::write(&p, &four).expect("write");
    assert_eq!(
        LabelVolume::read(&p).expect("4-D with t = 1").dims(),
        [122, 101, 30]
    );
}

#[test]
fn mask_grid_mismatch_names_the_file() {
    match LabelVolume::from_mask_files(&[(MUSCLE, 1), (SEG_MR, 2)]) {
        Err(SegmentationError::Read(e @ ReadError::Format { .. })) => {
            let msg = e.to_string();
            assert!(
                msg.contains("example_seg_mr.nii.gz") && msg.contains("grid differs"),
                "{msg}"
            );
        }
        other => panic!("{other:?}"),
    }
    assert!(matches!(
        LabelVolume::from_mask_files(&[(MUSCLE, 0)]),
        Err(SegmentationError::InvalidOptions(_))
    ));
}

#[test]
fn mr_segmentation_meshes() {
    // sform = diag(-3, -3, 3): det > 0, but both in-plane axes point to the world's negative.
    let vol = LabelVolume::read(SEG_MR).expect("read");
    assert_eq!(vol.dims(), [117, 91, 20]);
    let liver = vol
        .label_counts()
        .iter()
        .find(|(l, _)| *l == 5)
        .map(|&(_, n)| n)
        .expect("liver");
    assert_eq!(liver, 18_480);
    let mesh = mesh_labels(&vol, &MeshingOptions::new([5])).expect("mesh");
    check_voxel_mesh(&mesh, liver, &[5]);
}
