//! Lumped masses, and their regularisation where cuts leave particles almost without mass.
//!
//! The paper lumps `l_i = sum over tets k around i of rho_k V_k / 4` (its equation 2). A cut
//! subdivides tetrahedra into children down to 1e-5 of their volume, so the particles it creates
//! can weigh a millionth of their neighbours while their springs keep the same stiffness: the
//! implicit step's `h^2 k / m_i` then grows by orders of magnitude and its conjugate gradients
//! slow down (110 iterations per step after a novice's cuts in 3k tets, against 7 before).
//!
//! The regularisation moves mass, never adds it. The floor `f` is the lightest particle of the
//! uncut mesh ([`Model::mass_floor_kg`](super::Model::mass_floor_kg)), so an uncut model has
//! exactly the paper's masses. A particle `i` below it (deficit `d_i = f - l_i`) receives from
//! every neighbour `j` (sharing an edge) above it
//!
//! `t_ji = min(d_i / deg_i, gamma (l_j - f) / deg_j)`, with `gamma` = [`DONATED_SHARE`],
//!
//! so `i` reaches the floor when all its neighbours can give, and a donor keeps at least `f`
//! plus half its surplus. Then `m_i = l_i + sum_j t_ji - sum_j t_ij`: the total mass is
//! conserved (to round-off).
//!
//! A particle below the floor none of whose neighbours is above it gets `m_i = f`. These are
//! the chips a crossing cut carves out (a single tetrahedron of 1e-8 kg, free of the tissue),
//! whose extra mass no other particle feels; their springs alone, against their own mass, had
//! cost the solver 180 iterations per step. [`Model::total_mass`](super::Model::total_mass)
//! stays the tissue's, `sum l_i`.
//!
//! A particle's mass depends only on the lumped masses and degrees of itself and its
//! neighbours, so a cut re-derives it only around the cut. Each `m_i` is summed over its
//! neighbours in ascending order, whichever path computes it.

use crate::TetMesh;

use super::Material;

/// `gamma`: the share of its surplus over the floor a particle may give away, in all.
pub const DONATED_SHARE: f64 = 0.5;

/// A quarter of tet `t`'s mass, `rho V / 4`: what it gives each of its vertices.
pub(super) fn quarter_mass(mesh: &TetMesh, t: usize, material: &Material) -> f64 {
    0.25 * material.density_kg_per_m3 * mesh.tet_volume(t).abs()
}

/// `l_i = sum over tets k containing i of rho_k V_k / 4` (the paper's equation 2).
pub fn lumped_masses(mesh: &TetMesh, material_of_tet: &[Material]) -> Vec<f64> {
    let mut mass = vec![0.0; mesh.vertex_count()];
    for (t, tet) in mesh.tets().iter().enumerate() {
        let quarter = quarter_mass(mesh, t, &material_of_tet[t]);
        for &v in tet {
            mass[v as usize] += quarter;
        }
    }
    mass
}

/// The regularised masses `m` of every particle from the lumped masses `lumped` of `mesh`'s
/// vertices and the floor (see the module documentation).
pub(super) fn regularised_masses(mesh: &TetMesh, lumped: &[f64], floor_kg: f64) -> Vec<f64> {
    let mut mass = lumped.to_vec();
    let mut near_deficit: Vec<u32> = Vec::new();
    let mut n = MassScratch::default();
    for (i, &l) in lumped.iter().enumerate() {
        if l < floor_kg {
            near_deficit.push(i as u32);
            neighbours(mesh, i as u32, &mut n.of_p);
            near_deficit.extend_from_slice(&n.of_p);
        }
    }
    near_deficit.sort_unstable();
    near_deficit.dedup();
    for p in near_deficit {
        mass[p as usize] = regularised_mass(mesh, lumped, floor_kg, p, &mut n);
    }
    mass
}

/// Buffers of [`regularised_mass`].
#[derive(Debug, Default)]
pub(super) struct MassScratch {
    of_p: Vec<u32>,
    of_q: Vec<u32>,
}

/// `m_p = l_p + sum over neighbours q (ascending) of what q gives p minus what p gives q`.
pub(super) fn regularised_mass(
    mesh: &TetMesh,
    lumped: &[f64],
    floor_kg: f64,
    p: u32,
    n: &mut MassScratch,
) -> f64 {
    let lp = lumped[p as usize];
    let mut m = lp;
    neighbours(mesh, p, &mut n.of_p);
    let deg_p = n.of_p.len() as f64;
    if lp < floor_kg && n.of_p.iter().all(|&q| lumped[q as usize] <= floor_kg) {
        return floor_kg;
    }
    for &q in &n.of_p {
        let lq = lumped[q as usize];
        let gives = |to_deficit: f64, deg_to: f64, from_surplus: f64, deg_from: f64| {
            (to_deficit / deg_to).min(DONATED_SHARE * from_surplus / deg_from)
        };
        if lp < floor_kg && lq > floor_kg {
            neighbours(mesh, q, &mut n.of_q);
            m += gives(floor_kg - lp, deg_p, lq - floor_kg, n.of_q.len() as f64);
        } else if lq < floor_kg && lp > floor_kg {
            neighbours(mesh, q, &mut n.of_q);
            m -= gives(floor_kg - lq, n.of_q.len() as f64, lp - floor_kg, deg_p);
        }
    }
    m
}

/// The vertices sharing an edge with `v`, ascending, into `out`.
pub(super) fn neighbours(mesh: &TetMesh, v: u32, out: &mut Vec<u32>) {
    out.clear();
    for &t in mesh.topology().vertex_tets.row(v as usize) {
        out.extend(mesh.tets()[t as usize].iter().filter(|&&w| w != v));
    }
    out.sort_unstable();
    out.dedup();
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::Point3;

    /// A unit tet `0..4`, a flat one `1 2 3 4` on its face with the apex `4` barely above it,
    /// and a small chip `5..9` apart.
    fn mesh() -> TetMesh {
        let p = |x: f64, y: f64, z: f64| Point3::new(x, y, z);
        let positions = vec![
            p(0.0, 0.0, 0.0),
            p(1.0, 0.0, 0.0),
            p(0.0, 1.0, 0.0),
            p(0.0, 0.0, 1.0),
            p(0.335, 0.335, 0.335),
            p(3.0, 0.0, 0.0),
            p(3.01, 0.0, 0.0),
            p(3.0, 0.01, 0.0),
            p(3.0, 0.0, 0.01),
        ];
        TetMesh::new(
            positions,
            vec![[0, 1, 2, 3], [1, 2, 3, 4], [5, 6, 7, 8]],
            vec![0; 3],
        )
        .expect("valid mesh")
    }

    #[test]
    fn light_particles_receive_from_their_neighbours_and_chips_are_lifted() {
        let mesh = mesh();
        let materials = vec![Material::PAPER_CHEST_WALL; mesh.tet_count()];
        let lumped = lumped_masses(&mesh, &materials);
        let floor = 0.2 * lumped[0];
        assert!(lumped[4] < 0.1 * floor, "the apex is light: {lumped:?}");
        let mass = regularised_masses(&mesh, &lumped, floor);
        // the apex: 3 neighbours (1, 2, 3) above the floor, each giving a third of its deficit
        assert!(
            (mass[4] - floor).abs() <= 1e-12 * floor,
            "{} vs {floor}",
            mass[4]
        );
        // the donors keep at least the floor and half their surplus
        for q in 1..4 {
            assert!(mass[q] >= floor + 0.5 * (lumped[q] - floor) - 1e-18 && mass[q] < lumped[q]);
        }
        // vertex 0 is no neighbour of the apex
        assert_eq!(mass[0], lumped[0]);
        // conserved over the attached particles; the chip lifted to the floor
        let (before, after) = (
            lumped[..5].iter().sum::<f64>(),
            mass[..5].iter().sum::<f64>(),
        );
        assert!(
            (after - before).abs() <= 1e-15 * before,
            "{after} vs {before}"
        );
        assert!(mass[5..].iter().all(|&m| m == floor), "{:?}", &mass[5..]);
        // each particle's mass on its own equals the whole pass
        let mut scratch = MassScratch::default();
        for p in 0..mesh.vertex_count() as u32 {
            assert_eq!(
                regularised_mass(&mesh, &lumped, floor, p, &mut scratch).to_bits(),
                mass[p as usize].to_bits()
            );
        }
        // below the lightest particle, nothing moves
        assert_eq!(
            regularised_masses(
                &mesh,
                &lumped,
                lumped.iter().copied().fold(f64::INFINITY, f64::min)
            ),
            lumped
        );
    }
}
