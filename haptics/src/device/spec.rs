//! [`DeviceSpec`]: a device named in text (`cutlab session --device`, the station's devices),
//! parsed once for every command that takes one.

use std::path::PathBuf;

use super::Skill;

/// A device as a user names it: `expert`, `intermediate`, `novice`, `level:L` (a synthetic
/// trainee), `pointer:steady`, `pointer:sloppy` or `pointer:lagging` (a person's hand model on the station's
/// pointer, [`super::PointerHand`]), `stylus:steady` or `stylus:sloppy` (the same on a 3D stylus,
/// [`super::StylusHand`]), `csv:PATH` (a trajectory file), `recording:PATH` (a recorded session's hand) or
/// `igtl:PORT` (an OpenIGTLink tracker or haptic bridge listening on that port).
#[derive(Debug, Clone, PartialEq)]
pub enum DeviceSpec {
    /// A synthetic trainee following the plan.
    Trainee {
        /// A preset's name or `level:L`.
        name: String,
        /// Its hand.
        skill: Skill,
    },
    /// A person's hand model on the station's pointer.
    PointerHand(super::HandKind),
    /// A person's hand model on a 3D stylus ([`super::StylusHand`]).
    StylusHand(super::HandKind),
    /// A trajectory file (see [`super::CsvDevice`]).
    Csv(PathBuf),
    /// An OpenIGTLink tracker or haptic bridge connecting to this port.
    Igtl(u16),
    /// A recorded session's hand, played back.
    Recording(PathBuf),
}

impl std::str::FromStr for DeviceSpec {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        if let Some(skill) = Skill::preset(s) {
            return Ok(DeviceSpec::Trainee {
                name: s.to_owned(),
                skill,
            });
        }
        if let Some(level) = s.strip_prefix("level:") {
            let skill = level
                .parse::<f64>()
                .ok()
                .and_then(Skill::at_level)
                .ok_or_else(|| {
                    format!(
                        "level: needs a skill level from 0 (novice) to 1 (expert), got {level:?}"
                    )
                })?;
            return Ok(DeviceSpec::Trainee {
                name: s.to_owned(),
                skill,
            });
        }
        if let Some(kind) = s.strip_prefix("pointer:") {
            return super::HandKind::parse(kind)
                .map(DeviceSpec::PointerHand)
                .ok_or_else(|| {
                    format!("pointer: needs a hand, steady, sloppy or lagging, got {kind:?}")
                });
        }
        if let Some(kind) = s.strip_prefix("stylus:") {
            return super::HandKind::parse(kind)
                .filter(|k| *k != super::HandKind::Lagging)
                .map(DeviceSpec::StylusHand)
                .ok_or_else(|| format!("stylus: needs a hand, steady or sloppy, got {kind:?}"));
        }
        if let Some(path) = s.strip_prefix("csv:") {
            if path.is_empty() {
                return Err("csv: needs a file path, e.g. csv:stroke.csv".into());
            }
            return Ok(DeviceSpec::Csv(PathBuf::from(path)));
        }
        if let Some(path) = s.strip_prefix("recording:") {
            if path.is_empty() {
                return Err(
                    "recording: needs a session recording, e.g. recording:out/session/session.mcap"
                        .into(),
                );
            }
            return Ok(DeviceSpec::Recording(PathBuf::from(path)));
        }
        if let Some(port) = s.strip_prefix("igtl:") {
            return port
                .parse::<u16>()
                .map(DeviceSpec::Igtl)
                .map_err(|_| format!("igtl: needs a port number 0-65535, got {port:?}"));
        }
        Err(format!(
            "unknown device {s:?} (expected expert, intermediate, novice, level:L, pointer:steady, pointer:sloppy, pointer:lagging, stylus:steady, stylus:sloppy, csv:PATH, recording:PATH or igtl:PORT)"
        ))
    }
}

/// The text the spec was parsed from (`expert`, `level:0.4`, `csv:stroke.csv`, `igtl:18944`).
impl std::fmt::Display for DeviceSpec {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            DeviceSpec::Trainee { name, .. } => f.write_str(name),
            DeviceSpec::PointerHand(kind) => write!(f, "pointer:{}", kind.as_str()),
            DeviceSpec::StylusHand(kind) => write!(f, "stylus:{}", kind.as_str()),
            DeviceSpec::Csv(path) => write!(f, "csv:{}", path.display()),
            DeviceSpec::Igtl(port) => write!(f, "igtl:{port}"),
            DeviceSpec::Recording(path) => write!(f, "recording:{}", path.display()),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn specs_parse_and_print_back() {
        for text in [
            "expert",
            "novice",
            "level:0.25",
            "pointer:steady",
            "pointer:sloppy",
            "pointer:lagging",
            "stylus:steady",
            "stylus:sloppy",
            "csv:a.csv",
            "igtl:18944",
            "recording:r.mcap",
        ] {
            let spec: DeviceSpec = text.parse().expect(text);
            assert_eq!(spec.to_string(), text);
        }
        assert!(matches!(
            "level:0.25".parse(),
            Ok(DeviceSpec::Trainee { .. })
        ));
        for bad in ["level:", "level:1.5", "level:NaN", "level:x"] {
            assert!(
                bad.parse::<DeviceSpec>()
                    .is_err_and(|e| e.contains("level")),
                "{bad}"
            );
        }
        for bad in [
            "igtl:70000",
            "csv:",
            "recording:",
            "mouse",
            "pointer:",
            "pointer:shaky",
            "stylus:lagging",
            "stylus:",
        ] {
            assert!(bad.parse::<DeviceSpec>().is_err(), "{bad}");
        }
    }
}
