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

impl DamageKind {
    /// The tag recordings carry.
    pub fn as_str(self) -> &'static str {
        match self {
            DamageKind::BladeOnBone => "blade-on-bone",
            DamageKind::SpareCut => "spare-cut",
        }
    }
}

/// One harm, on one region of the mesh.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub struct TissueDamage {
    /// What happened.
    pub kind: DamageKind,
    /// The region it happened to.
    pub region: u32,
}

/// What a session remembers between steps to report each harm once: a contact with bone when
/// it begins (the blade held on a rib over many steps is one contact), a structure to spare
/// the first time a cut goes through it.
#[derive(Debug, Clone, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct DamageWatch {
    /// The region the blade rests on since an earlier step, if any.
    pub stopped_on: Option<u32>,
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

    /// The blade stopped on `stop` (or did not) at a cutting step; a new contact is harm.
    pub fn blade_stop(&mut self, stop: Option<u32>, out: &mut Vec<TissueDamage>) {
        if let Some(region) = stop
            && self.stopped_on != Some(region)
        {
            out.push(TissueDamage {
                kind: DamageKind::BladeOnBone,
                region,
            });
        }
        self.stopped_on = stop;
    }

    /// The blade left the tissue: the next contact with bone is a new one.
    pub fn blade_out(&mut self) {
        self.stopped_on = None;
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
