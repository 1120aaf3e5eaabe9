//! Meshes the liver (label 5 of `example_seg.nii.gz`) and the body wall (skeletal muscle +
//! subcutaneous fat masks) of the TotalSegmentator example and prints sizes and timings.
//!
//! `cargo run --release -p cutlab-sim --example segmentation_report`

use std::time::Instant;

use cutlab_sim::segmentation::{
    LabelVolume, MeshingOptions, NonManifold, Resample, mesh_labels_with_report,
};

const DATA: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/../data/totalsegmentator/");

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let t = Instant::now();
    let seg = LabelVolume::read(format!("{DATA}example_seg.nii.gz"))?;
    let read_seg = t.elapsed();
    let t = Instant::now();
    let wall = LabelVolume::from_mask_files(&[
        (format!("{DATA}skeletal_muscle.nii.gz"), 1),
        (format!("{DATA}subcutaneous_fat.nii.gz"), 2),
    ])?;
    let read_wall = t.elapsed();
    println!(
        "read example_seg: {:.1} ms; read + combine 2 masks: {:.1} ms",
        ms(read_seg),
        ms(read_wall)
    );
    println!(
        "{:<34} {:>8} {:>9} {:>9} {:>11} {:>8} {:>6} {:>6} {:>9}",
        "case",
        "voxels",
        "vertices",
        "tets",
        "volume cm3",
        "mesh ms",
        "nm-vx",
        "filled",
        "valid ms"
    );
    let cases: Vec<(&str, &LabelVolume, MeshingOptions)> = vec![
        ("liver", &seg, MeshingOptions::new([5])),
        (
            "liver, resample x2",
            &seg,
            MeshingOptions {
                resample: Some(Resample::Factor(2)),
                ..MeshingOptions::new([5])
            },
        ),
        (
            "liver, largest comp., fill",
            &seg,
            MeshingOptions {
                keep_largest_component: true,
                non_manifold: NonManifold::Fill,
                ..MeshingOptions::new([5])
            },
        ),
        (
            "liver, smooth 5",
            &seg,
            MeshingOptions {
                smooth_iterations: 5,
                ..MeshingOptions::new([5])
            },
        ),
        ("body wall", &wall, MeshingOptions::new([1, 2])),
        (
            "body wall, resample x2",
            &wall,
            MeshingOptions {
                resample: Some(Resample::Factor(2)),
                ..MeshingOptions::new([1, 2])
            },
        ),
        (
            "body wall, largest comp., fill",
            &wall,
            MeshingOptions {
                keep_largest_component: true,
                non_manifold: NonManifold::Fill,
                ..MeshingOptions::new([1, 2])
            },
        ),
    ];
    for (name, vol, opts) in cases {
        let t = Instant::now();
        let (mesh, report) = mesh_labels_with_report(vol, &opts)?;
        let mesh_time = t.elapsed();
        let t = Instant::now();
        let valid = mesh.validate().is_ok();
        let valid_time = t.elapsed();
        println!(
            "{:<34} {:>8} {:>9} {:>9} {:>11.2} {:>8.1} {:>6} {:>6} {:>9.1}{}",
            name,
            report.voxel_count(),
            mesh.vertex_count(),
            mesh.tet_count(),
            mesh.volume() * 1e6,
            ms(mesh_time),
            report.non_manifold_vertices,
            report.voxels_filled,
            ms(valid_time),
            if valid { "" } else { "  INVALID" },
        );
        if report.components > 0 {
            println!(
                "    {} components, {} island voxels removed",
                report.components, report.island_voxels_removed
            );
        }
        if opts.smooth_iterations > 0 {
            println!(
                "    {} smoothing moves rejected",
                report.smoothing_moves_rejected
            );
        }
    }
    Ok(())
}

fn ms(d: std::time::Duration) -> f64 {
    d.as_secs_f64() * 1e3
}
