//! Springs and dampers along the edges of the mesh.

use super::{Material, SpringStiffness};
use crate::TetMesh;

/// Whether springs `ends` come sorted by their first end (as a model's do: by edge).
pub(crate) fn sorted_by_first_end(ends: &[[u32; 2]]) -> bool {
    ends.windows(2).all(|w| w[0][0] <= w[1][0])
}

/// One spring + damper per mesh edge, stored as a structure of arrays.
#[derive(Debug, Clone, Default)]
pub struct SpringSet {
    /// First and second particle of each spring (`a < b`).
    pub ends: Vec<[u32; 2]>,
    /// Rest length `l = d (1 - s)` in metres.
    pub rest_length: Vec<f64>,
    /// Spring constant in N/m.
    pub stiffness: Vec<f64>,
    /// Damper coefficient in N s/m.
    pub damping: Vec<f64>,
}

impl SpringSet {
    /// The number of springs.
    pub fn len(&self) -> usize {
        self.ends.len()
    }

    /// Whether there are no springs.
    pub fn is_empty(&self) -> bool {
        self.ends.is_empty()
    }

    /// The springs at each of `particle_count` particles (row `i`: the springs with an end at
    /// `i`, ascending).
    pub fn by_particle(&self, particle_count: usize) -> crate::mesh::Csr {
        let mut csr = crate::mesh::Csr::default();
        self.by_particle_into(particle_count, &mut csr);
        csr
    }

    /// [`Self::by_particle`] into `csr`, in the allocations it holds.
    pub(crate) fn by_particle_into(&self, particle_count: usize, csr: &mut crate::mesh::Csr) {
        csr.refill(particle_count, || {
            self.ends
                .iter()
                .enumerate()
                .flat_map(|(e, &[a, b])| [(a, e as u32), (b, e as u32)])
        });
    }

    /// An empty set with room for `n` springs.
    pub(crate) fn with_capacity(n: usize) -> Self {
        Self {
            ends: Vec::with_capacity(n),
            rest_length: Vec::with_capacity(n),
            stiffness: Vec::with_capacity(n),
            damping: Vec::with_capacity(n),
        }
    }

    /// Appends the springs `range` of `other`.
    pub(crate) fn extend_from(&mut self, other: &Self, range: std::ops::Range<usize>) {
        self.ends.extend_from_slice(&other.ends[range.clone()]);
        self.rest_length
            .extend_from_slice(&other.rest_length[range.clone()]);
        self.stiffness
            .extend_from_slice(&other.stiffness[range.clone()]);
        self.damping.extend_from_slice(&other.damping[range]);
    }

    /// Appends a spring with `[rest length, stiffness, damping]`.
    pub(crate) fn push(&mut self, ends: [u32; 2], [rest, k, c]: [f64; 3]) {
        self.ends.push(ends);
        self.rest_length.push(rest);
        self.stiffness.push(k);
        self.damping.push(c);
    }

    /// `[rest length, stiffness, damping]` of the spring on edge `e` of `mesh`: the materials
    /// (`material_of_tet(t)`) averaged over the tets around the edge, `l = d (1 - s)`.
    pub(crate) fn edge_parameters(
        mesh: &TetMesh,
        e: usize,
        material_of_tet: &dyn Fn(usize) -> Material,
    ) -> [f64; 3] {
        let topo = mesh.topology();
        let pos = mesh.positions();
        let [a, b] = topo.edges[e];
        let d = (pos[b as usize] - pos[a as usize]).norm();
        let (mut k, mut c, mut s) = (0.0, 0.0, 0.0);
        let (mut count, mut uniform_share) = (0.0, 0.0);
        for t in topo.tets_of_edge([a, b]) {
            count += 1.0;
            let m = material_of_tet(t as usize);
            k += match m.stiffness {
                SpringStiffness::Uniform { newtons_per_metre } => {
                    uniform_share += 1.0;
                    newtons_per_metre
                }
                SpringStiffness::YoungsModulus { pascals } => {
                    pascals * mesh.tet_volume(t as usize) / (d * d)
                }
            };
            c += m.damping_newton_seconds_per_metre;
            s += m.pretension;
        }
        // Averages over the tets around the edge (sums of equal values divided by their
        // count are exact, so uniform materials give exactly their parameters).
        if uniform_share == count {
            k /= count;
        }
        let (c, s) = (c / count, s / count);
        [d * (1.0 - s), k, c]
    }

    /// Springs on every edge of `mesh`, with parameters averaged over the tetrahedra around the
    /// edge (`material_of_tet[t]` gives each tet's material). The pre-tension rule sets
    /// `l = d (1 - s)` with `d` the edge's length in the mesh's (reference) positions.
    pub fn from_mesh(mesh: &TetMesh, material_of_tet: &[Material]) -> Self {
        let topo = mesh.topology();
        let n = topo.edges.len();
        let mut set = Self {
            ends: Vec::with_capacity(n),
            rest_length: Vec::with_capacity(n),
            stiffness: Vec::with_capacity(n),
            damping: Vec::with_capacity(n),
        };
        for (e, &ends) in topo.edges.iter().enumerate() {
            set.push(
                ends,
                Self::edge_parameters(mesh, e, &|t| material_of_tet[t]),
            );
        }
        set
    }
}

#[cfg(test)]
mod tests {
    use crate::mesh::Csr;

    #[test]
    fn by_particle_lists_each_particles_springs_in_order() {
        let scene = crate::scene::Scene::load(
            "chest-wall",
            crate::scene::BuildOptions {
                min_tets: Some(1_000),
            },
        )
        .expect("built-in scene");
        let mut springs = scene.model.springs.clone();
        // and a spring from a particle to itself, listed twice in its row
        springs.push([3, 3], [0.0, 1.0, 0.0]);
        let n = scene.model.vertex_count();
        let pairs: Vec<(u32, u32)> = springs
            .ends
            .iter()
            .enumerate()
            .flat_map(|(e, &[a, b])| [(a, e as u32), (b, e as u32)])
            .collect();
        let csr = springs.by_particle(n);
        assert_eq!(csr, Csr::from_pairs(n, &pairs));
        let last = springs.len() as u32 - 1;
        assert_eq!(csr.row(3).iter().filter(|&&e| e == last).count(), 2);
        // row by row, the springs with an end there, in the springs' order
        for i in 0..n as u32 {
            let expected: Vec<u32> = springs
                .ends
                .iter()
                .enumerate()
                .flat_map(|(e, ends)| ends.iter().filter(|&&v| v == i).map(move |_| e as u32))
                .collect();
            assert_eq!(csr.row(i as usize), expected.as_slice(), "row {i}");
        }
        assert!((0..n).all(|i| csr.row(i).windows(2).all(|w| w[0] <= w[1])));
    }
}
