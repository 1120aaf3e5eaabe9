//! How a metric is shown to people: its display name and display unit, from its stable SI
//! key (`entry_error_m` → "Entry error", mm). One table ([`LABELS`]) for every page; the
//! JSON API keeps the keys and SI values. A key not in the table shows as itself, in the
//! display unit of its SI unit ([`display_unit`]).

/// A metric as shown: a name, a unit (empty for counts and scores) and the factor from the
/// stored SI value to the shown one.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Label<'a> {
    pub name: &'a str,
    pub unit: &'a str,
    pub factor: f64,
}

impl Label<'_> {
    /// "Entry error (mm)", or the name alone without a unit.
    pub fn with_unit(&self) -> String {
        if self.unit.is_empty() {
            self.name.to_owned()
        } else {
            format!("{} ({})", self.name, self.unit)
        }
    }
}

/// `(key, name, unit, factor)`: the stored SI value times `factor` is shown in `unit`.
pub const LABELS: &[(&str, &str, &str, f64)] = &[
    ("entry_error_m", "Entry error", "mm", 1e3),
    ("exit_error_m", "Exit error", "mm", 1e3),
    ("length_error_m", "Length error", "mm", 1e3),
    ("lateral_mean_m", "Lateral deviation (mean)", "mm", 1e3),
    ("lateral_rms_m", "Lateral deviation (RMS)", "mm", 1e3),
    ("lateral_max_m", "Lateral deviation (max)", "mm", 1e3),
    (
        "fraction_cut_in_tolerance",
        "Cut within tolerance",
        "%",
        100.0,
    ),
    ("direction_error_deg", "Direction error", "°", 1.0),
    ("depth_error_m", "Depth error (mean)", "mm", 1e3),
    ("depth_rms_error_m", "Depth error (RMS)", "mm", 1e3),
    ("approach_error_deg", "Approach angle error", "°", 1.0),
    ("time_s", "Task time", "s", 1.0),
    ("path_length_m", "Path length", "mm", 1e3),
    ("economy_of_motion", "Economy of motion", "", 1.0),
    ("idle_time_s", "Idle time", "s", 1.0),
    ("movements", "Movements", "", 1.0),
    ("angular_path_rad", "Tool rotation", "rad", 1.0),
    ("ldlj", "Smoothness (LDLJ)", "", 1.0),
    ("sparc", "Smoothness (SPARC)", "", 1.0),
    (
        "ldlj_per_movement",
        "Smoothness per movement (LDLJ)",
        "",
        1.0,
    ),
    (
        "sparc_per_movement",
        "Smoothness per movement (SPARC)",
        "",
        1.0,
    ),
    ("peak_force_n", "Peak force", "N", 1.0),
    ("mean_force_n", "Mean force", "N", 1.0),
    (
        "time_above_force_limit_s",
        "Time above force limit",
        "s",
        1.0,
    ),
    ("excessive_force_events", "Excessive force events", "", 1.0),
    ("cut_outside_corridor_m", "Cut outside corridor", "mm", 1e3),
    (
        "cut_area_outside_corridor_m2",
        "Cut area outside corridor",
        "mm²",
        1e6,
    ),
    ("target_visible_fraction", "Target visible", "%", 100.0),
    ("opening_width_m", "Opening width", "mm", 1e3),
    ("opening_area_m2", "Opening area", "mm²", 1e6),
];

/// How the metric `key`, stored in the SI unit `si_unit`, is shown.
pub fn label<'a>(key: &'a str, si_unit: &'a str) -> Label<'a> {
    match LABELS.iter().find(|(k, ..)| *k == key) {
        Some(&(_, name, unit, factor)) => Label { name, unit, factor },
        None => {
            let (factor, unit) = display_unit(si_unit);
            Label {
                name: key,
                unit,
                factor,
            }
        }
    }
}

/// How a stored SI unit is shown when the metric has no row in [`LABELS`]: the factor and
/// the display unit (metres as millimetres).
pub fn display_unit(unit: &str) -> (f64, &str) {
    match unit {
        "m" => (1e3, "mm"),
        "m^2" => (1e6, "mm²"),
        "deg" => (1.0, "°"),
        "1" => (1.0, ""),
        other => (1.0, other),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use cutlab_assessor::metrics::METRICS;

    #[test]
    fn every_catalogue_metric_has_a_name_in_a_unit_of_its_si_unit() {
        for m in METRICS {
            let l = label(m.key, m.unit);
            assert_ne!(l.name, m.key, "{} has no display name", m.key);
            // the shown unit is a scaling of the SI unit, by the factor it names
            let ok = match (m.unit, l.unit) {
                ("m", "mm") => l.factor == 1e3,
                ("m^2", "mm²") => l.factor == 1e6,
                ("1", "%") => l.factor == 100.0,
                ("deg", "°") | ("1", "") => l.factor == 1.0,
                (si, shown) => si == shown && l.factor == 1.0,
            };
            assert!(
                ok,
                "{}: {} shown as {} x{}",
                m.key, m.unit, l.unit, l.factor
            );
        }
        assert_eq!(
            LABELS.len(),
            METRICS.len(),
            "a row for a metric that is gone"
        );
        let mut names: Vec<_> = LABELS.iter().map(|r| r.1).collect();
        names.sort_unstable();
        names.dedup();
        assert_eq!(names.len(), LABELS.len(), "two metrics with one name");
    }

    #[test]
    fn an_unknown_key_shows_as_itself_in_its_display_unit() {
        let l = label("new_metric_m", "m");
        assert_eq!((l.name, l.unit, l.factor), ("new_metric_m", "mm", 1e3));
        assert_eq!(label("x", "1").with_unit(), "x");
        assert_eq!(label("entry_error_m", "m").with_unit(), "Entry error (mm)");
    }
}
