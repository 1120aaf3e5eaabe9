//! The simulation step a session runs at: the scene's, a given one, or the smallest that keeps
//! real time on this machine, measured when the session starts ([`TimeStep::Auto`]).
//!
//! The measurement times steps of the settled tissue while a light press of [`PRESS_NEWTONS`]
//! loads the middle of its top (a loaded step takes more CG iterations than a resting one; a
//! light press's median step is close to a session's, see `docs/decisions.md`), at each of
//! [`AUTO_STEPS_S`] from the smallest, and takes
//! the first whose median step needs at most the `budget` share of it (the rest is left for
//! cuts, the servo and a viewer beside the simulation). The choice depends on the machine, so it is recorded with the session (its
//! step is in the recording, and a replay takes it from there).

use std::fmt;
use std::str::FromStr;
use std::time::Instant;

use cutlab_sim::Vector3;
use cutlab_sim::scene::{Scene, TIME_STEP_RANGE_S};
use cutlab_sim::stats::percentile;

use crate::{HapticsError, Session};

/// The steps [`TimeStep::Auto`] tries, smallest first (whole servo periods).
pub const AUTO_STEPS_S: [f64; 5] = [1e-3, 2e-3, 4e-3, 5e-3, 10e-3];

/// The share of a step the simulation may take under [`TimeStep::Auto`] by default.
pub const AUTO_BUDGET: f64 = 0.7;

/// The press that loads the tissue while the steps are timed, N.
pub const PRESS_NEWTONS: f64 = 0.05;

/// Steps timed per candidate (after [`WARM_UP_STEPS`] untimed ones).
const TIMED_STEPS: usize = 9;
const WARM_UP_STEPS: usize = 5;

/// The simulation step of a session.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub enum TimeStep {
    /// The scene's own (its `[solver]` table).
    #[default]
    Scene,
    /// This many seconds.
    Fixed(f64),
    /// The smallest of [`AUTO_STEPS_S`] that keeps real time here, measured at the start.
    Auto,
}

impl TimeStep {
    /// The fixed step in seconds, if this is one.
    pub fn fixed_s(self) -> Option<f64> {
        match self {
            Self::Fixed(s) => Some(s),
            _ => None,
        }
    }
}

/// A time step that is neither `auto`, `scene` nor a number of milliseconds.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("a simulation step is `auto`, `scene` or milliseconds (0.1-10), not `{0}`")]
pub struct TimeStepParseError(String);

impl FromStr for TimeStep {
    type Err = TimeStepParseError;

    /// `auto`, `scene`, or milliseconds (`4`, `2.5`: checked against the scene's rules when
    /// the session starts; only its finiteness here).
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        match s.trim() {
            "auto" => Ok(Self::Auto),
            "scene" => Ok(Self::Scene),
            ms => ms
                .parse::<f64>()
                .ok()
                .filter(|ms| ms.is_finite())
                .map(|ms| Self::Fixed(ms / 1e3))
                .ok_or_else(|| TimeStepParseError(s.to_owned())),
        }
    }
}

impl fmt::Display for TimeStep {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::Scene => f.write_str("scene"),
            Self::Fixed(s) => write!(f, "{}", s * 1e3),
            Self::Auto => f.write_str("auto"),
        }
    }
}

/// One step size tried by [`Session::choose_real_time_step`].
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct StepTrial {
    /// The step, s.
    pub time_step_s: f64,
    /// The median wall time of a loaded step, s.
    pub median_step_s: f64,
}

/// What [`Session::choose_real_time_step`] measured and chose.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct StepChoice {
    /// The step chosen, s.
    pub time_step_s: f64,
    /// The share of a step the simulation was allowed.
    pub budget: f64,
    /// Whether its median step fits the budget (otherwise it is the largest step, which does
    /// not fit it either).
    pub keeps_real_time: bool,
    /// The steps tried, smallest first.
    pub trials: Vec<StepTrial>,
}

impl fmt::Display for StepChoice {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let share = format!("{:.0} %", self.budget * 100.0);
        write!(
            f,
            "{} ms ({}; a loaded step took",
            self.time_step_s * 1e3,
            if self.keeps_real_time {
                format!("the smallest whose loaded step takes at most {share} of it here")
            } else {
                format!("the largest: none tried takes at most {share} of its step here")
            }
        )?;
        for (k, t) in self.trials.iter().enumerate() {
            let sep = if k == 0 { "" } else { "," };
            write!(
                f,
                "{sep} {:.2} ms at {} ms",
                t.median_step_s * 1e3,
                t.time_step_s * 1e3
            )?;
        }
        f.write_str(")")
    }
}

impl Session {
    /// Settles `scene` at the simulation step `step` asks for: the scene's own, a fixed one
    /// (the scene is changed to it, which checks it against the scene's rules), or the one
    /// [`Self::choose_real_time_step`] measures with [`AUTO_BUDGET`] (returned with what it
    /// measured). The scene returned holds the step the session runs at.
    pub fn at_time_step(
        scene: Scene,
        step: TimeStep,
    ) -> Result<(Scene, Self, Option<StepChoice>), HapticsError> {
        let scene = match step.fixed_s() {
            Some(dt) => scene.with_time_step(dt)?,
            None => scene,
        };
        let mut session = Self::new(&scene)?;
        let choice = match step {
            TimeStep::Auto => Some(session.choose_real_time_step(AUTO_BUDGET)?),
            TimeStep::Scene | TimeStep::Fixed(_) => None,
        };
        // the scene says the step the session runs at, whoever chose it
        let scene = match &choice {
            Some(c) => scene.with_time_step(c.time_step_s)?,
            None => scene,
        };
        Ok((scene, session, choice))
    }

    /// Times loaded steps of the settled tissue at each of [`AUTO_STEPS_S`] (see the module
    /// documentation) and sets the simulation's step to the first whose median takes at most
    /// `budget` (0-1] of it, or to the largest. The session's state is left as it was.
    pub fn choose_real_time_step(&mut self, budget: f64) -> Result<StepChoice, HapticsError> {
        if !(budget > 0.0 && budget <= 1.0) {
            return Err(HapticsError::Simulation(format!(
                "a real-time budget of {budget} (0-1]"
            )));
        }
        let press = self.press_points();
        let mut trials = Vec::new();
        let mut chosen = None;
        for &dt in AUTO_STEPS_S
            .iter()
            .filter(|&&dt| (TIME_STEP_RANGE_S.0..=TIME_STEP_RANGE_S.1).contains(&dt))
        {
            let mut sim = self.sim.clone();
            sim.settings.time_step_s = dt;
            let force = press.1 * (-PRESS_NEWTONS / press.0.len().max(1) as f64);
            let mut times = Vec::with_capacity(TIMED_STEPS);
            for k in 0..WARM_UP_STEPS + TIMED_STEPS {
                sim.clear_external_forces();
                for &v in &press.0 {
                    sim.add_external_force(v, force);
                }
                let start = Instant::now();
                sim.step()
                    .map_err(|e| HapticsError::Simulation(format!("timing a step: {e}")))?;
                if k >= WARM_UP_STEPS {
                    times.push(start.elapsed().as_secs_f64());
                }
            }
            times.sort_by(f64::total_cmp);
            let median_step_s = percentile(&times, 0.5);
            trials.push(StepTrial {
                time_step_s: dt,
                median_step_s,
            });
            if median_step_s <= budget * dt {
                chosen = Some(dt);
                break;
            }
        }
        let keeps_real_time = chosen.is_some();
        let time_step_s = chosen
            .or_else(|| trials.last().map(|t| t.time_step_s))
            .unwrap_or(self.sim.settings.time_step_s);
        self.sim.settings.time_step_s = time_step_s;
        Ok(StepChoice {
            time_step_s,
            budget,
            keeps_real_time,
            trials,
        })
    }

    /// The free surface vertices nearest the middle of the tissue's top (+z), at most 12, and
    /// the direction into the tissue there (`+z`: the press pushes along `-z`).
    fn press_points(&self) -> (Vec<u32>, Vector3) {
        let sim = &self.sim;
        let x = &sim.state.positions;
        let (lo, hi) = cutlab_sim::mesh::bounding_box(x);
        let top = nalgebra::Point3::new(0.5 * (lo.x + hi.x), 0.5 * (lo.y + hi.y), hi.z);
        let mut surface: Vec<u32> = sim
            .model
            .mesh
            .topology()
            .boundary
            .iter()
            .flatten()
            .copied()
            .filter(|&v| !sim.model.held[v as usize])
            .collect();
        surface.sort_unstable();
        surface.dedup();
        surface.sort_by(|&a, &b| {
            (x[a as usize] - top)
                .norm_squared()
                .total_cmp(&(x[b as usize] - top).norm_squared())
        });
        surface.truncate(12);
        (surface, Vector3::z())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use cutlab_sim::scene::{BuildOptions, Scene};

    fn session() -> Session {
        let scene = Scene::load(
            "chest-wall",
            BuildOptions {
                min_tets: Some(500),
            },
        )
        .expect("scene");
        Session::new(&scene).expect("session")
    }

    /// A small tissue keeps real time at the smallest step with the whole step to spend; no
    /// step does on an impossible budget, and then the largest is taken. The state is kept.
    #[test]
    fn the_smallest_step_that_keeps_real_time_is_chosen() {
        let mut s = session();
        let before = s.sim.state.clone();
        let choice = s.choose_real_time_step(1.0).expect("a choice");
        assert!(choice.keeps_real_time, "{choice}");
        assert_eq!(choice.time_step_s, AUTO_STEPS_S[0]);
        assert_eq!(choice.trials.len(), 1);
        assert_eq!(s.sim.settings.time_step_s, AUTO_STEPS_S[0]);
        let choice = s.choose_real_time_step(1e-12).expect("a choice");
        assert!(!choice.keeps_real_time);
        assert_eq!(choice.time_step_s, AUTO_STEPS_S[AUTO_STEPS_S.len() - 1]);
        assert_eq!(choice.trials.len(), AUTO_STEPS_S.len());
        assert!(choice.trials.iter().all(|t| t.median_step_s > 0.0));
        assert_eq!(s.sim.settings.time_step_s, choice.time_step_s);
        assert_eq!(s.sim.state.positions, before.positions);
        assert_eq!(s.sim.step_index(), 0);
        assert!(s.choose_real_time_step(0.0).is_err());
        assert!(s.choose_real_time_step(f64::NAN).is_err());
    }

    /// Whoever chooses the step, the scene and the session agree on it: one value, not a
    /// scene's default beside a session's choice.
    #[test]
    fn the_scene_holds_the_step_the_session_runs_at() {
        let scene = || {
            Scene::load(
                "chest-wall",
                BuildOptions {
                    min_tets: Some(500),
                },
            )
            .expect("scene")
        };
        let own = scene().spec.solver.time_step_s;
        for step in [TimeStep::Scene, TimeStep::Fixed(2e-3), TimeStep::Auto] {
            let (scene, session, choice) = Session::at_time_step(scene(), step).expect("settled");
            let running = session.sim.settings.time_step_s;
            assert_eq!(scene.spec.solver.time_step_s, running, "{step}");
            match step {
                TimeStep::Scene => assert_eq!(running, own),
                TimeStep::Fixed(dt) => assert_eq!(running, dt),
                TimeStep::Auto => assert_eq!(running, choice.expect("a choice").time_step_s),
            }
        }
    }

    #[test]
    fn time_steps_parse_and_print() {
        assert_eq!("auto".parse(), Ok(TimeStep::Auto));
        assert_eq!("scene".parse(), Ok(TimeStep::Scene));
        assert_eq!("4".parse(), Ok(TimeStep::Fixed(4e-3)));
        assert!("fast".parse::<TimeStep>().is_err());
        assert!("NaN".parse::<TimeStep>().is_err());
        assert!("inf".parse::<TimeStep>().is_err());
        for s in [TimeStep::Auto, TimeStep::Scene, TimeStep::Fixed(2e-3)] {
            assert_eq!(s.to_string().parse(), Ok(s));
        }
    }
}
