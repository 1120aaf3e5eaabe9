//! `--localise auto|on|off`: whether a session simulates only near the scalpel. `auto` (the
//! default) localises only where `cutlab bench perf` measured it to pay on this scene at about
//! this size: a localised step no slower than the full one at the median and at p99, the run
//! within [`MAX_ERROR`] of the full one, and the same cuts. The measurements are the checked-in
//! `docs/bench-perf.csv`, so re-running the benchmark after a change to the solver moves the
//! choice with it.

/// How a session decides on localisation.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, clap::ValueEnum)]
pub enum Localise {
    /// Where it was measured to pay (see the module's documentation).
    #[default]
    Auto,
    /// Always (the default thresholds).
    On,
    /// Never: the whole body every step.
    Off,
}

/// The measurements of `cutlab bench perf`: per scene and size, a full and a localised run.
const MEASURED: &str = include_str!("../docs/bench-perf.csv");

/// How far the localised run may be from the full one: the largest position difference over
/// the run, relative to the full run's largest displacement.
pub const MAX_ERROR: f64 = 0.05;

/// A measurement is taken for a mesh of `tets` when its size is within this factor of it.
const SIZE_FACTOR: f64 = 1.5;

/// What a session does, and why.
#[derive(Debug, Clone, PartialEq)]
pub struct Choice {
    /// Whether the session is localised.
    pub localise: bool,
    /// Why, for the session's output and summary.
    pub why: String,
}

/// One run of the measurements.
#[derive(Debug, Clone, PartialEq)]
struct Run {
    tets: usize,
    median_us: f64,
    p99_us: f64,
    error: Option<f64>,
    same_cuts: bool,
}

/// The full and the localised run of `scene` measured at the size nearest to `tets` (within
/// [`SIZE_FACTOR`]) in `csv`.
fn measured(csv: &str, scene: &str, tets: usize) -> Option<(Run, Run)> {
    let mut lines = csv.lines();
    let header: Vec<&str> = lines.next()?.split(',').collect();
    let column = |name: &str| header.iter().position(|h| *h == name);
    let (c_scene, c_tets, c_mode) = (column("scene")?, column("tets")?, column("mode")?);
    let (c_median, c_p99) = (column("step_median_us")?, column("step_p99_us")?);
    let (c_error, c_events) = (column("error")?, column("cut_events")?);
    let mut full = Vec::new();
    let mut localised = Vec::new();
    for line in lines {
        let f: Vec<&str> = line.split(',').collect();
        if f.get(c_scene) != Some(&scene) {
            continue;
        }
        let number = |c: usize| f.get(c).and_then(|v| v.parse::<f64>().ok());
        let (Some(run_tets), Some(median_us), Some(p99_us)) = (
            f.get(c_tets).and_then(|v| v.parse::<usize>().ok()),
            number(c_median),
            number(c_p99),
        ) else {
            continue;
        };
        let run = Run {
            tets: run_tets,
            median_us,
            p99_us,
            error: number(c_error),
            // `bench perf`'s verdicts: "identical", "same topology", "diverged at ..."
            same_cuts: matches!(f.get(c_events), Some(&"identical" | &"same topology")),
        };
        match f.get(c_mode) {
            Some(&"full") => full.push(run),
            // the default thresholds only (`localised x10` is a coarser variant)
            Some(&"localised") => localised.push(run),
            _ => {}
        }
    }
    let distance = |t: usize| (t as f64 / tets.max(1) as f64).ln().abs();
    let full = full
        .into_iter()
        .filter(|r| distance(r.tets) <= SIZE_FACTOR.ln())
        .min_by(|a, b| distance(a.tets).total_cmp(&distance(b.tets)))?;
    let localised = localised.into_iter().find(|r| r.tets == full.tets)?;
    Some((full, localised))
}

/// Whether a session on `scene` with `tets` tetrahedra is localised, by `setting` and the
/// measurements in `csv` (`docs/bench-perf.csv` by [`choose`]); `auto` follows a scene file
/// that asks for localisation (`scene_localises`).
fn choose_from(
    csv: &str,
    setting: Localise,
    scene: &str,
    tets: usize,
    scene_localises: bool,
) -> Choice {
    match setting {
        Localise::On => Choice {
            localise: true,
            why: "--localise on".into(),
        },
        Localise::Off => Choice {
            localise: false,
            why: "--localise off".into(),
        },
        Localise::Auto if scene_localises => Choice {
            localise: true,
            why: "auto: the scene's solver settings localise".into(),
        },
        Localise::Auto => match measured(csv, scene, tets) {
            None => Choice {
                localise: false,
                why: format!("auto: not measured on {scene} near {tets} tets (cutlab bench perf)"),
            },
            Some((full, local)) => {
                let median = local.median_us / full.median_us;
                let p99 = local.p99_us / full.p99_us;
                let error = local.error.unwrap_or(f64::INFINITY);
                let pays = median <= 1.0 && p99 <= 1.0 && error <= MAX_ERROR && local.same_cuts;
                Choice {
                    localise: pays,
                    why: format!(
                        "auto: measured on {scene} at {} tets, a localised step {median:.2}x the full one at the median and {p99:.2}x at p99, {:.1} % off the full run{}; it pays at <= 1x, <= 1x and <= {:.0} % with the same cuts",
                        full.tets,
                        100.0 * error,
                        if local.same_cuts { "" } else { ", other cuts" },
                        100.0 * MAX_ERROR
                    ),
                }
            }
        },
    }
}

/// Whether a session on `scene` with `tets` tetrahedra is localised, and why; `auto` follows
/// a scene file that asks for localisation (`scene_localises`).
pub fn choose(setting: Localise, scene: &str, tets: usize, scene_localises: bool) -> Choice {
    choose_from(MEASURED, setting, scene, tets, scene_localises)
}

#[cfg(test)]
mod tests {
    use super::*;

    const CSV: &str = "scene,tets,mode,step_median_us,step_p99_us,error,cut_events\n\
        wall,10000,full,800,1400,,\n\
        wall,10000,localised,700,1300,0.04,identical\n\
        wall,50000,full,3000,7000,,\n\
        wall,50000,localised,2000,9000,0.03,same topology\n\
        wall,100000,full,7000,14000,,\n\
        wall,100000,localised,3000,12000,0.2,diverged at 200 ms\n\
        wall,100000,localised x10,700,2000,0.3,diverged at 40 ms\n";

    #[test]
    fn auto_localises_only_where_it_was_measured_to_pay() {
        // faster at the median and p99, 4 % off, the same cuts
        let c = choose_from(CSV, Localise::Auto, "wall", 12_000, false);
        assert!(c.localise, "{}", c.why);
        assert!(
            c.why.contains("10000 tets") && c.why.contains("4.0 %"),
            "{}",
            c.why
        );
        // slower at p99
        let c = choose_from(CSV, Localise::Auto, "wall", 50_000, false);
        assert!(!c.localise && c.why.contains("1.29x at p99"), "{}", c.why);
        // too far off, other cuts (the coarse variant is not the default's measurement)
        let c = choose_from(CSV, Localise::Auto, "wall", 90_000, false);
        assert!(!c.localise && c.why.contains("other cuts"), "{}", c.why);
        // no measurement near the size, or of the scene
        for (scene, tets) in [("wall", 400_000), ("wall", 2_000), ("sheet", 10_000)] {
            let c = choose_from(CSV, Localise::Auto, scene, tets, false);
            assert!(!c.localise && c.why.contains("not measured"), "{}", c.why);
        }
        // asked for: as asked
        assert!(choose_from(CSV, Localise::On, "sheet", 10, false).localise);
        assert!(!choose_from(CSV, Localise::Off, "wall", 12_000, false).localise);
        // a scene file that asks for it: auto follows it, off still wins
        let c = choose_from(CSV, Localise::Auto, "sheet", 10, true);
        assert!(
            c.localise && c.why.contains("scene's solver settings"),
            "{}",
            c.why
        );
        assert!(!choose_from(CSV, Localise::Off, "sheet", 10, true).localise);
        // a malformed table decides nothing
        let c = choose_from("garbage", Localise::Auto, "wall", 12_000, false);
        assert!(!c.localise);
    }

    #[test]
    fn the_checked_in_measurements_are_read() {
        // the chest wall is measured at several sizes: auto gives a measured reason there
        let c = choose(Localise::Auto, "chest-wall", 12_768, false);
        assert!(
            c.why.contains("measured on chest-wall at 12768 tets"),
            "{}",
            c.why
        );
    }
}
