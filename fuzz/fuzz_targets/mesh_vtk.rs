//! Legacy VTK: `cutlab_sim::io::read_vtk_str`.
#![no_main]

#[allow(dead_code)]
#[path = "../../tests/mutation/targets.rs"]
mod targets;

libfuzzer_sys::fuzz_target!(|data: &[u8]| {
    let _ = targets::mesh_vtk(data);
});
