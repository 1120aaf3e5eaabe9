//! Gmsh .msh 1, 2.x and 4.1: `cutlab_sim::io::read_gmsh_str`.
#![no_main]

#[allow(dead_code)]
#[path = "../../tests/mutation/targets.rs"]
mod targets;

libfuzzer_sys::fuzz_target!(|data: &[u8]| {
    let _ = targets::mesh_gmsh(data);
});
