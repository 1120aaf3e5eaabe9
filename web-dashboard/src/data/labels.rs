//! How a metric is shown to people: its display name and display unit, from its stable SI
//! key (`entry_error_m` → "Entry error", mm), as the assessor's catalogue defines them
//! ([`METRICS`](cutlab_scoring::metrics::METRICS)); the JSON API keeps the keys and SI values.

use cutlab_scoring::metrics::{display_unit, metric};

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

/// How the metric `key`, stored in the SI unit `si_unit`, is shown: as the catalogue says
/// ([`METRICS`](cutlab_scoring::metrics::METRICS)), else (a key the catalogue does not have) as itself in its SI unit's display
/// unit.
pub fn label<'a>(key: &'a str, si_unit: &'a str) -> Label<'a> {
    let (name, (factor, unit)) = match metric(key) {
        Some(m) => (m.label, m.display()),
        None => (key, display_unit(si_unit)),
    };
    Label { name, unit, factor }
}

/// How an attempt was made, in words (the attempts tables, the attempt's page): the station's
/// mode, or, for an attempt run without the station (`cutlab session`, the demo's seeding),
/// that it was scripted.
pub fn mode_words(mode: Option<&str>) -> &str {
    match mode {
        Some(m) => m,
        None => "scripted, no station",
    }
}

/// The device an attempt was made with, in words: the stored name (`level:0.4`, `expert`,
/// `pointer:steady`) says what it is in the CLI's terms, which an instructor need not know.
pub fn device_words(device: &str) -> String {
    let d = device.trim();
    if let Some(level) = d.strip_prefix("level:") {
        return format!("synthetic trainee, skill {level} (0 novice, 1 expert)");
    }
    if let Some(hand) = d.strip_prefix("pointer:") {
        return format!("hand model on the pointer ({hand})");
    }
    if let Some(what) = d.strip_prefix("recording of ") {
        return format!("replayed recording of {}", device_words(what));
    }
    match d {
        "expert" | "intermediate" | "novice" => format!("synthetic {d}"),
        "pointer" => "pointer (station page)".to_owned(),
        _ if d.starts_with("csv:") => "trajectory file".to_owned(),
        _ if d.starts_with("igtl:") => "tracked device (OpenIGTLink)".to_owned(),
        _ => d.to_owned(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use cutlab_scoring::metrics;

    #[test]
    fn every_catalogue_metric_has_a_name_in_a_unit_of_its_si_unit() {
        for m in metrics::all() {
            let l = label(m.key, m.unit);
            assert_ne!(l.name, m.key, "{} has no display name", m.key);
            // the shown unit is a scaling of the SI unit, by the factor it names
            let ok = match (m.unit, l.unit) {
                ("m", "mm") => l.factor == 1e3,
                ("m^2", "mm²") => l.factor == 1e6,
                ("m^3", "mm³") => l.factor == 1e9,
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
        let mut names: Vec<_> = metrics::all().map(|m| m.label).collect();
        names.sort_unstable();
        names.dedup();
        assert_eq!(
            names.len(),
            metrics::all().count(),
            "two metrics with one name"
        );
    }

    #[test]
    fn devices_and_modes_are_said_in_words() {
        assert_eq!(
            device_words("level:1"),
            "synthetic trainee, skill 1 (0 novice, 1 expert)"
        );
        assert_eq!(device_words("expert"), "synthetic expert");
        assert_eq!(
            device_words("pointer:steady"),
            "hand model on the pointer (steady)"
        );
        assert_eq!(
            device_words("recording of pointer"),
            "replayed recording of pointer (station page)"
        );
        assert_eq!(device_words("igtl:18944"), "tracked device (OpenIGTLink)");
        assert_eq!(device_words("haptic arm 2"), "haptic arm 2");
        assert_eq!(mode_words(None), "scripted, no station");
        assert_eq!(mode_words(Some("exam")), "exam");
    }

    #[test]
    fn an_unknown_key_shows_as_itself_in_its_display_unit() {
        let l = label("new_metric_m", "m");
        assert_eq!((l.name, l.unit, l.factor), ("new_metric_m", "mm", 1e3));
        assert_eq!(label("x", "1").with_unit(), "x");
        assert_eq!(label("entry_error_m", "m").with_unit(), "Entry error (mm)");
    }
}
