//! Device classes: what kind of hand an attempt's numbers come from, so that they are judged
//! against experts who used the same kind (docs/decisions.md, "Thresholds per device class").
//!
//! - [`DeviceClass::Pointer`]: the station page's mouse, pen or touch (`pointer`), and the
//!   person's hand model played through it (`pointer:steady`, `pointer:sloppy`). The blade
//!   plunges to a set depth when the button goes down and follows a 2D cursor on the surface:
//!   its time, path, movements and smoothness are a person's at a desk.
//! - [`DeviceClass::Stylus`]: every other device, a hand in 3D (a haptic stylus or a tracker
//!   over OpenIGTLink, a trajectory file, a recording, the synthetic trainees), and an attempt
//!   whose device was not recorded (one from before, or assessed from a file).

use serde::{Deserialize, Serialize};

/// See the module documentation.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum DeviceClass {
    /// The station page's pointer.
    Pointer,
    /// A hand in 3D, or an unrecorded device.
    Stylus,
}

impl DeviceClass {
    /// Every class.
    pub const ALL: [Self; 2] = [Self::Pointer, Self::Stylus];

    /// The class of the device an attempt or a recording names (`attempts.device`, as the
    /// station or the session names it; `recording of D` is D's hand played again).
    pub fn of(device: Option<&str>) -> Self {
        let Some(mut d) = device.map(str::trim) else {
            return Self::Stylus;
        };
        while let Some(rest) = d.strip_prefix("recording of ") {
            d = rest.trim();
        }
        if d == "pointer" || d.starts_with("pointer:") {
            Self::Pointer
        } else {
            Self::Stylus
        }
    }

    /// `pointer` or `stylus`, as stored.
    pub fn as_str(self) -> &'static str {
        match self {
            Self::Pointer => "pointer",
            Self::Stylus => "stylus",
        }
    }

    /// The class [`Self::as_str`] names.
    pub fn parse(s: &str) -> Option<Self> {
        Self::ALL.into_iter().find(|c| c.as_str() == s)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_page_and_its_hand_model_are_pointers_every_other_device_a_stylus() {
        for d in [
            "pointer",
            "pointer:steady",
            "pointer:sloppy",
            "recording of pointer",
        ] {
            assert_eq!(DeviceClass::of(Some(d)), DeviceClass::Pointer, "{d}");
        }
        for d in [
            Some("expert"),
            Some("igtl:18944"),
            Some("csv:pointer.csv"),
            Some("pointers"),
            None,
        ] {
            assert_eq!(DeviceClass::of(d), DeviceClass::Stylus, "{d:?}");
        }
        for c in DeviceClass::ALL {
            assert_eq!(DeviceClass::parse(c.as_str()), Some(c));
        }
        assert_eq!(DeviceClass::parse("mouse"), None);
    }
}
