use cutlab_sim::reference::{Elasticity, IPC_BARS, IPC_UNIT_M, Solid, cantilever, ipc_dir, read_bar};
#[test]
fn probe() {
    for nu in [0.0, 0.3, 0.45, 0.49] {
        for b in IPC_BARS {
            let mesh = read_bar(&ipc_dir().join(b), IPC_UNIT_M).unwrap();
            let (lo, hi) = mesh.bounding_box();
            let solid = Solid { poisson_ratio: nu, ..Solid::CHEST_WALL };
            let r = cantilever(mesh, Elasticity::CorotationalFem, solid).unwrap();
            println!("nu {nu}: {b} ext {:?} err {:.1} %", hi - lo, 100.0 * r.relative_error);
        }
    }
}
