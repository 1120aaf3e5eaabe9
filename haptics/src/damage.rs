//! Harm the blade does to tissue it should not cut: the blade on bone (a rib, a cartilage:
//! tissue a scalpel does not cut, where [`cutlab_sim::cut::Cutter::stop`] stops it) and a
//! structure to spare cut (an artery: a region of [`cutlab_sim::model::Model::spare_regions`]
//! whose tetrahedra a cut split). The session records each as it happens (issue 62).

use serde::{Deserialize, Serialize};

use cutlab_sim::cut::CutEvent;
use cutlab_sim::model::Model;

/// What kind of harm.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum DamageKind {
    /// The blade came down on tissue a scalpel does not cut.
    BladeOnBone,
    /// A cut went through a structure to spare.
    SpareCut,
}

/// One harm, on one region of the mesh.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub struct TissueDamage {
    /// What happened.
    pub kind: DamageKind,
    /// The region it happened to.
    pub region: u32,
}

/// What a session remembers between steps to report each harm once: the blade on a bone once
/// per stroke (held on a rib, or sliding along its edge on and off it, over many steps, is
/// one contact until the blade leaves the tissue), a structure to spare the first time a cut
/// goes through it.
#[derive(Debug, Clone, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct DamageWatch {
    /// The regions the blade has come down on in this stroke, ascending.
    pub touched: Vec<u32>,
    /// The regions to spare already cut, ascending.
    pub spared_cut: Vec<u32>,
}

impl DamageWatch {
    /// Nothing is remembered (what a session starts with).
    pub fn is_clear(&self) -> bool {
        *self == Self::default()
    }

    /// Whether a cut on `model` may harm a structure to spare: then the cutting step keeps
    /// the regions of the tetrahedra before the cut for [`Self::after_cut`].
    pub fn watches_cuts(model: &Model) -> bool {
        !model.spare_regions.is_empty()
    }

    /// The blade stopped on `stop` (or did not) at a cutting step; the first stop on a
    /// region in this stroke is harm.
    pub fn blade_stop(&mut self, stop: Option<u32>, out: &mut Vec<TissueDamage>) {
        if let Some(region) = stop
            && let Err(at) = self.touched.binary_search(&region)
        {
            self.touched.insert(at, region);
            out.push(TissueDamage {
                kind: DamageKind::BladeOnBone,
                region,
            });
        }
    }

    /// The blade left the tissue: a stroke after it that comes down on bone is harm again.
    pub fn blade_out(&mut self) {
        self.touched.clear();
    }

    /// A cut on `model` split the tetrahedra `event.tets_removed` of the mesh whose regions
    /// were `regions_before`; a structure to spare among them, not cut before, is harm.
    pub fn after_cut(
        &mut self,
        model: &Model,
        regions_before: &[u32],
        event: &CutEvent,
        out: &mut Vec<TissueDamage>,
    ) {
        for &t in &event.tets_removed {
            let Some(&region) = regions_before.get(t as usize) else {
                continue;
            };
            if model.spare(region)
                && let Err(at) = self.spared_cut.binary_search(&region)
            {
                self.spared_cut.insert(at, region);
                out.push(TissueDamage {
                    kind: DamageKind::SpareCut,
                    region,
                });
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A blade on and off the same rib within a stroke is one contact, again after it left
    /// the tissue; a structure to spare (`after_cut`) is covered by `tests/plan_cli.rs`.
    #[test]
    fn each_harm_is_reported_once_per_stroke_or_once() {
        let mut watch = DamageWatch::default();
        let mut out = Vec::new();
        for stop in [Some(6), None, Some(6), Some(7), Some(6)] {
            watch.blade_stop(stop, &mut out);
        }
        let kinds: Vec<(DamageKind, u32)> = out.iter().map(|d| (d.kind, d.region)).collect();
        assert_eq!(
            kinds,
            [(DamageKind::BladeOnBone, 6), (DamageKind::BladeOnBone, 7)]
        );
        watch.blade_out();
        watch.blade_stop(Some(6), &mut out);
        assert_eq!(out.len(), 3);
    }
}
