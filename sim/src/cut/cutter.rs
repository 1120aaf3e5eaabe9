//! Progressive cutting: a stroke of many steps gives one continuous incision.
//!
//! Each step cuts along the surface swept by the blade over a trailing window of recent poses
//! (not only since the previous pose), projected onto its best-fit plane. Tetrahedra that the
//! blade has crossed over several steps are therefore cut whole once the blade has passed
//! them, while those at the blade's front are resolved by vertex movement; re-cutting the
//! part already cut changes nothing (its vertices lie on the plane and are already split).
//! Where the blade turns, the oldest poses of the window are left out until the swept
//! surface departs from its plane by no more than the snapping distance, and the stroke's
//! earlier cut counts as on the plane within a few times that departure (see
//! `docs/design/cutting.md`, "Strokes that turn"). A stroke that starts where the last one
//! ended (its tip within [`Cutter::rejoin_m`] of the edge's last pose, at any depth along
//! it) continues it: the blade lifted and pressed again where it was goes on cutting the
//! same incision ("Strokes that rejoin").

use std::collections::VecDeque;

use super::{
    Blade, BladeStop, CutError, CutEvent, CutOptions, CutPolygon, STOP_MARGIN_M, StrokeVertices,
    cut_remembering, stop_on_uncuttable,
};
use crate::solver::Simulation;

/// Cuts a simulation along the path of a blade, pose by pose.
#[derive(Debug, Clone)]
pub struct Cutter {
    /// The settings of every cut it makes.
    pub options: CutOptions,
    /// Length of tip path behind the blade that each step cuts along, metres.
    pub window_m: f64,
    /// How far a piece the stroke frees is lifted out of the wound, along the blade towards
    /// its handle, m; it also moves aside by its width and this much (see
    /// [`super::Specimen`]).
    pub specimen_lift_m: f64,
    /// A stroke whose first tip lies within this distance of the cutting edge's last pose in
    /// the stroke before (at any depth along the edge) continues that one, m.
    pub rejoin_m: f64,
    trail: VecDeque<Blade>,
    stroke: StrokeVertices,
    /// The stroke [`Self::end_stroke`] ended, until the next stroke's first pose.
    ended: Option<(VecDeque<Blade>, StrokeVertices)>,
    /// Where the last pose stopped on uncuttable tissue.
    stop: Option<BladeStop>,
    /// The particles a grasper's jaws hold, ascending (see [`Self::hold_in_jaws`]).
    in_jaws: Vec<u32>,
}

/// A [`Cutter`]'s state between two steps (see [`Cutter::resume_state`]).
#[derive(Debug, Clone, PartialEq, Default, serde::Serialize, serde::Deserialize)]
pub struct CutterResume {
    /// The blade's poses behind the tip, oldest first.
    pub trail: Vec<Blade>,
    /// The vertices the stroke has cut, ascending.
    pub stroke: Vec<u32>,
    /// The snapping distance derived from the mesh first cut (see
    /// [`CutOptions::snap_distance_m`]), once derived.
    pub snap_distance_m: Option<f64>,
    /// The stroke that ended before this one began (its poses and vertices, as `trail` and
    /// `stroke`): the next stroke continues it if it starts where it ended.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub ended: Option<EndedStroke>,
}

/// A stroke the blade has left (see [`CutterResume::ended`]).
#[derive(Debug, Clone, PartialEq, Default, serde::Serialize, serde::Deserialize)]
pub struct EndedStroke {
    /// The blade's poses behind its last, oldest first.
    pub trail: Vec<Blade>,
    /// The vertices the stroke cut, ascending.
    pub stroke: Vec<u32>,
}

/// A [`CutterResume`] that does not fit the mesh (or is not finite).
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
pub enum CutterResumeError {
    /// A pose of the trail or the snapping distance has a non-finite number.
    #[error("the cutter's trail or snapping distance is not finite")]
    NotFinite,
    /// A vertex of the stroke is past the end of the mesh's vertices.
    #[error("the stroke's vertex {vertex} is not one of the {vertex_count}")]
    StrokeVertex {
        /// The vertex.
        vertex: u32,
        /// How many vertices the mesh has.
        vertex_count: usize,
    },
}

impl Default for Cutter {
    fn default() -> Self {
        Self::new(CutOptions::default())
    }
}

impl Cutter {
    /// A cutter with no stroke yet, cutting along the last 10 mm of the tip's path.
    pub fn new(options: CutOptions) -> Self {
        Self {
            options,
            window_m: 0.01,
            specimen_lift_m: 0.03,
            rejoin_m: 0.0015,
            trail: VecDeque::new(),
            stroke: StrokeVertices::default(),
            ended: None,
            stop: None,
            in_jaws: Vec::new(),
        }
    }

    /// The particles a grasper's jaws hold now (ascending; empty: none): they anchor
    /// nothing, so a piece the cut frees that only they hold is freed and stays in the jaws
    /// ([`super::Specimen::in_jaws`]). Whoever holds the grasp tells the cutter before each
    /// pose; it is not part of [`Self::resume_state`].
    pub fn hold_in_jaws(&mut self, vertices: &[u32]) {
        self.in_jaws.clear();
        self.in_jaws.extend_from_slice(vertices);
    }

    /// Ends the current stroke (the blade left the tissue): the next pose starts a new one,
    /// or continues this one if its tip is within [`Self::rejoin_m`] of this one's last edge.
    pub fn end_stroke(&mut self) {
        if self.trail.is_empty() {
            return;
        }
        let trail = std::mem::take(&mut self.trail);
        let stroke = std::mem::take(&mut self.stroke);
        self.ended = Some((trail, stroke));
    }

    /// Ends the current stroke for good (a cut failed): the next pose starts a new one.
    pub fn abandon_stroke(&mut self) {
        self.trail.clear();
        self.stroke.clear();
        self.ended = None;
    }

    /// What the next [`Self::advance`] depends on: the trail of poses, the stroke's vertices
    /// and the snapping distance derived from the first mesh cut.
    pub fn resume_state(&self) -> CutterResume {
        CutterResume {
            trail: self.trail.iter().copied().collect(),
            stroke: self.stroke.members(),
            snap_distance_m: self.options.snap_distance_m,
            ended: self.ended.as_ref().map(|(trail, stroke)| EndedStroke {
                trail: trail.iter().copied().collect(),
                stroke: stroke.members(),
            }),
        }
    }

    /// Continues a stroke captured by [`Self::resume_state`] (with this cutter's other options),
    /// over a mesh of `vertex_count` vertices.
    pub fn resume(
        &mut self,
        r: &CutterResume,
        vertex_count: usize,
    ) -> Result<(), CutterResumeError> {
        let ended = r.ended.as_ref();
        let trails = || {
            r.trail
                .iter()
                .chain(ended.into_iter().flat_map(|e| &e.trail))
        };
        if !trails().all(Blade::is_finite)
            || !r.snap_distance_m.is_none_or(|d| d.is_finite() && d >= 0.0)
        {
            return Err(CutterResumeError::NotFinite);
        }
        let strokes = r
            .stroke
            .iter()
            .chain(ended.into_iter().flat_map(|e| &e.stroke));
        if let Some(&vertex) = strokes.into_iter().find(|&&v| v as usize >= vertex_count) {
            return Err(CutterResumeError::StrokeVertex {
                vertex,
                vertex_count,
            });
        }
        self.trail = r.trail.iter().copied().collect();
        self.stroke = StrokeVertices::from_members(&r.stroke);
        self.ended = ended.map(|e| {
            (
                e.trail.iter().copied().collect(),
                StrokeVertices::from_members(&e.stroke),
            )
        });
        self.options.snap_distance_m = r.snap_distance_m;
        Ok(())
    }

    /// True while a stroke is in progress.
    pub fn in_stroke(&self) -> bool {
        !self.trail.is_empty()
    }

    /// Where the blade last stopped on uncuttable tissue (see [`Self::advance`]); `None` once
    /// a pose meets none.
    pub fn stop(&self) -> Option<&BladeStop> {
        self.stop.as_ref()
    }

    /// `blade` drawn back to stop above the model's uncuttable tissue (kept in [`Self::stop`]).
    fn stopped(&mut self, sim: &Simulation, blade: Blade) -> Blade {
        let margin_m = STOP_MARGIN_M + self.options.snap_distance_m.unwrap_or(0.0);
        self.stop = stop_on_uncuttable(&sim.model, &sim.state.positions, &blade, margin_m);
        self.stop.map_or(blade, |s| s.blade)
    }

    /// Moves the blade to `blade`, cutting along its trailing swept surface. Where its edge
    /// meets uncuttable tissue (bone, cartilage) the blade is drawn back along its edge to
    /// stop above it ([`stop_on_uncuttable`]): the swept surface never crosses that tissue.
    pub fn advance(&mut self, sim: &mut Simulation, blade: Blade) -> Result<CutEvent, CutError> {
        if !blade.is_finite() {
            return Err(CutError::NonFiniteBlade);
        }
        let blade = self.stopped(sim, blade);
        // a stroke's first pose where the last stroke ended continues that stroke
        if let Some((trail, stroke)) = self.ended.take()
            && self.trail.is_empty()
            && trail
                .back()
                .is_some_and(|b| b.distance_to_edge(&blade.tip) <= self.rejoin_m)
        {
            (self.trail, self.stroke) = (trail, stroke);
        }
        // poses closer than a 32nd of the window to the one before the newest replace the
        // newest, so a hand that trembles at 1 kHz keeps the swept polygon to a few dozen
        // corners
        let min_spacing = self.window_m / 32.0;
        match self.trail.len() {
            n if n >= 2 && (blade.tip - self.trail[n - 2].tip).norm() < min_spacing => {
                self.trail[n - 1] = blade
            }
            _ => self.trail.push_back(blade),
        }
        // keep the poses within the window behind the tip (at least the previous one)
        let mut length = 0.0;
        let mut keep = 1;
        for i in (1..self.trail.len()).rev() {
            keep += 1;
            length += (self.trail[i].tip - self.trail[i - 1].tip).norm();
            if length >= self.window_m {
                break;
            }
        }
        while self.trail.len() > keep {
            self.trail.pop_front();
        }
        if self.trail.len() < 2 {
            return Ok(CutEvent::default());
        }
        // a snapping distance left open is derived from the first mesh cut and then kept in
        // the options, so that it does not shrink as the cuts refine the mesh
        if self.options.snap_distance_m.is_none() {
            self.options.snap_distance_m =
                Some(self.options.snap * sim.model.median_edge_length().unwrap_or(0.0));
        }
        // where the blade turns, the oldest poses are left out until the swept surface
        // departs from the polygon's plane by no more than the snapping distance
        let flat_enough = self.options.snap_distance_m.unwrap_or(0.0);
        let mut first = 0;
        loop {
            let mut corners: Vec<_> = self.trail.iter().skip(first).map(|b| b.tip).collect();
            corners.extend(self.trail.iter().skip(first).rev().map(Blade::heel));
            let Some(polygon) = CutPolygon::new(&corners) else {
                return Ok(CutEvent::default());
            };
            if polygon.flatness_m > flat_enough && self.trail.len() - first > 2 {
                first += 1;
                continue;
            }
            let lift_m = blade.edge_direction.normalize() * self.specimen_lift_m;
            return cut_remembering(
                sim,
                &polygon,
                &self.options,
                &mut self.stroke,
                lift_m,
                &self.in_jaws,
            );
        }
    }
}
