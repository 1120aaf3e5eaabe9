//! `cutlab scene info`: what a scene or mesh file holds.

use anyhow::Context;
use cutlab_sim::mesh::QualityStats;
use cutlab_sim::scene::{BuildOptions, Scene};
use serde::Serialize;

#[derive(Debug, Serialize)]
struct Info {
    name: String,
    /// `springs` or `corotational-fem`.
    force_model: &'static str,
    tets: usize,
    vertices: usize,
    edges: usize,
    boundary_triangles: usize,
    regions: Vec<u32>,
    held_vertices: Option<usize>,
    volume_cm3: f64,
    mass_g: Option<f64>,
    bounding_box_min_mm: [f64; 3],
    bounding_box_max_mm: [f64; 3],
    quality: QualityStats,
    valid: bool,
    problems: String,
    /// What the mesh reader left out (unused vertices, undeclared TetGen values).
    notes: Vec<String>,
}

pub fn run(scene: &str, min_tets: Option<usize>, json: bool) -> anyhow::Result<()> {
    let built = Scene::load(scene, BuildOptions { min_tets })
        .with_context(|| format!("loading {scene}"))?;
    let m = &built.model;
    let mesh = &m.mesh;
    let (lo, hi) = mesh.bounding_box();
    let report = mesh.validate();
    let info = Info {
        name: built.spec.name.clone(),
        force_model: match m.force_model() {
            cutlab_sim::model::ForceModel::Springs => "springs",
            cutlab_sim::model::ForceModel::CorotationalFem => "corotational-fem",
        },
        tets: mesh.tet_count(),
        vertices: mesh.vertex_count(),
        edges: mesh.topology().edges.len(),
        boundary_triangles: mesh.topology().boundary.len(),
        regions: mesh.region_ids(),
        held_vertices: Some(m.held_count()),
        volume_cm3: mesh.volume() * 1e6,
        mass_g: Some(m.total_mass() * 1e3),
        bounding_box_min_mm: [lo.x, lo.y, lo.z].map(|v| v * 1e3),
        bounding_box_max_mm: [hi.x, hi.y, hi.z].map(|v| v * 1e3),
        quality: mesh.quality(),
        valid: report.is_ok(),
        problems: if report.is_ok() {
            String::new()
        } else {
            report.to_string()
        },
        notes: built.read_notes.iter().map(ToString::to_string).collect(),
    };
    if json {
        println!("{}", serde_json::to_string_pretty(&info)?);
        return Ok(());
    }
    println!("scene      {}", info.name);
    println!("model      {}", info.force_model);
    println!("tets       {}", info.tets);
    println!(
        "vertices   {} ({} held)",
        info.vertices,
        info.held_vertices.unwrap_or(0)
    );
    println!("edges      {}", info.edges);
    println!("surface    {} triangles", info.boundary_triangles);
    println!("regions    {:?}", info.regions);
    println!("volume     {:.3} cm3", info.volume_cm3);
    if let Some(g) = info.mass_g {
        println!("mass       {g:.3} g");
    }
    let [a, b, c] = info.bounding_box_min_mm;
    let [d, e, f] = info.bounding_box_max_mm;
    println!("bbox       [{a:.2}, {b:.2}, {c:.2}] .. [{d:.2}, {e:.2}, {f:.2}] mm");
    println!(
        "dihedral   min {:.2} deg, max {:.2} deg (mu mean {:.3}, max {:.3})",
        info.quality.min_dihedral_deg,
        info.quality.max_dihedral_deg,
        info.quality.mean_mu,
        info.quality.max_mu
    );
    println!(
        "validation {}",
        if info.valid {
            "ok".to_string()
        } else {
            info.problems.clone()
        }
    );
    for note in &info.notes {
        println!("note       {note}");
    }
    Ok(())
}

/// Prints the built-in scenes, one a line with its description.
pub fn list() {
    for (name, _) in cutlab_sim::scene::BUILTIN {
        let spec = cutlab_sim::scene::builtin_spec(name);
        println!(
            "{name:12} {}",
            spec.map(|s| s.description).unwrap_or_default()
        );
    }
}
