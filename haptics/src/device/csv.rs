//! A trajectory file device: plays a CSV of timed poses.
//!
//! Format (one header line, then one row per sample; `#` starts a comment line; blank lines
//! are skipped):
//!
//! ```text
//! t_s, x_m, y_m, z_m, qw, qx, qy, qz, button
//! 0.000, -0.030, 0.0, 0.015, 1, 0, 0, 0, 0
//! 0.500, -0.030, 0.0, -0.005, 1, 0, 0, 0, 1
//! ```
//!
//! `t_s` is the time since the session started (seconds, strictly increasing, finite, >= 0);
//! `x_m y_m z_m` the blade's tip in the world (metres); `qw qx qy qz` the tool's orientation
//! (`world_from_tool`, any non-zero length: normalised on reading); `button` the buttons' bits:
//! 0, 1 (the blade engaged), 4 (the wound retractor held) or 5 (both). Between rows the position is interpolated linearly and the orientation by
//! normalised linear interpolation; before the first row the first pose holds, after the last
//! the last.

use std::path::Path;

use super::track::PoseTrack;
use super::{DeviceFault, HapticDevice};
use crate::pose::{BUTTON_BLADE, BUTTON_RETRACT};
use crate::{HapticsError, Point3, Rotation, ToolPose, Vector3};

/// The header line the format requires (spaces around the commas are optional).
pub const CSV_HEADER: [&str; 9] = ["t_s", "x_m", "y_m", "z_m", "qw", "qx", "qy", "qz", "button"];

/// Largest file accepted (a 1 kHz trajectory of an hour is about 200 MB; this is a file device
/// for scripted sessions, not a recording format).
const MAX_BYTES: u64 = 256 << 20;

/// Plays the poses of a CSV trajectory file.
#[derive(Debug, Clone)]
pub struct CsvDevice {
    name: String,
    track: PoseTrack,
}

impl CsvDevice {
    /// Reads and checks the whole file.
    pub fn open(path: &Path) -> Result<Self, HapticsError> {
        let io = |source| HapticsError::Io {
            path: path.to_path_buf(),
            error: source,
        };
        let size = std::fs::metadata(path).map_err(io)?.len();
        if size > MAX_BYTES {
            return Err(HapticsError::Csv {
                path: path.to_path_buf(),
                line: 0,
                message: format!("file is {size} bytes; at most {MAX_BYTES} accepted"),
            });
        }
        let text = std::fs::read_to_string(path).map_err(io)?;
        Self::parse(&text, path)
    }

    /// Parses CSV text; `path` names the source in errors.
    pub fn parse(text: &str, path: &Path) -> Result<Self, HapticsError> {
        let err = |line: usize, message: String| HapticsError::Csv {
            path: path.to_path_buf(),
            line,
            message,
        };
        let mut header_seen = false;
        let mut times_s = Vec::new();
        let mut poses = Vec::new();
        for (i, raw) in text.lines().enumerate() {
            let line = i + 1;
            let content = raw.trim();
            if content.is_empty() || content.starts_with('#') {
                continue;
            }
            let fields: Vec<&str> = content.split(',').map(str::trim).collect();
            if !header_seen {
                if fields != CSV_HEADER {
                    return Err(err(
                        line,
                        format!(
                            "expected the header `{}`, found `{content}`",
                            CSV_HEADER.join(", ")
                        ),
                    ));
                }
                header_seen = true;
                continue;
            }
            if fields.len() != CSV_HEADER.len() {
                return Err(err(
                    line,
                    format!(
                        "expected {} fields, found {}",
                        CSV_HEADER.len(),
                        fields.len()
                    ),
                ));
            }
            let mut v = [0.0; 9];
            for (k, f) in fields.iter().enumerate() {
                v[k] = f.parse::<f64>().map_err(|_| {
                    err(
                        line,
                        format!(
                            "column {} ({}): `{f}` is not a number",
                            k + 1,
                            CSV_HEADER[k]
                        ),
                    )
                })?;
                if !v[k].is_finite() {
                    return Err(err(
                        line,
                        format!("column {} ({}): `{f}` is not finite", k + 1, CSV_HEADER[k]),
                    ));
                }
            }
            let t = v[0];
            if t < 0.0 {
                return Err(err(line, format!("t_s must not be negative, got {t}")));
            }
            if let Some(&previous) = times_s.last()
                && t <= previous
            {
                return Err(err(
                    line,
                    format!("t_s must increase strictly: {t} after {previous}"),
                ));
            }
            let mut q = nalgebra::Quaternion::new(v[4], v[5], v[6], v[7]);
            if q.norm() < 1e-9 {
                return Err(err(
                    line,
                    "the quaternion qw qx qy qz has zero length".into(),
                ));
            }
            if !q.norm().is_finite() {
                // finite components whose squares overflow (e.g. 1e300 1e300 0 0): scaled
                // first, or normalising would give the zero quaternion
                q /= q.coords.amax();
            }
            let buttons = match fields[8] {
                "0" => 0,
                "1" => BUTTON_BLADE,
                "4" => BUTTON_RETRACT,
                "5" => BUTTON_BLADE | BUTTON_RETRACT,
                other => {
                    return Err(err(
                        line,
                        format!("column 9 (button): expected 0, 1, 4 or 5, got `{other}`"),
                    ));
                }
            };
            times_s.push(t);
            poses.push(ToolPose {
                tip_in_world: Point3::new(v[1], v[2], v[3]),
                world_from_tool: Rotation::from_quaternion(q),
                buttons,
            });
        }
        if !header_seen {
            return Err(err(
                0,
                format!(
                    "empty file: expected the header `{}`",
                    CSV_HEADER.join(", ")
                ),
            ));
        }
        if poses.is_empty() {
            return Err(err(0, "no samples after the header".into()));
        }
        let name = format!("csv:{}", path.display());
        Ok(Self {
            name,
            track: PoseTrack::new(times_s, poses),
        })
    }

    /// Number of samples.
    pub fn len(&self) -> usize {
        self.track.len()
    }

    /// Whether the trajectory has no poses.
    pub fn is_empty(&self) -> bool {
        self.track.is_empty()
    }

    /// Time of the last sample, s.
    pub fn duration_s(&self) -> f64 {
        self.track.duration_s()
    }

    /// The interpolated pose at `time_s` (moves the cursor; O(1) for increasing times).
    pub fn pose_at(&mut self, time_s: f64) -> ToolPose {
        self.track.pose_at(time_s)
    }
}

impl HapticDevice for CsvDevice {
    fn name(&self) -> &str {
        &self.name
    }

    fn read(&mut self, _tick: u64, time_s: f64) -> Result<ToolPose, DeviceFault> {
        Ok(self.pose_at(time_s))
    }

    fn write_force(&mut self, _force_newtons: Vector3) -> Result<(), DeviceFault> {
        Ok(())
    }

    fn finished(&self, time_s: f64) -> bool {
        time_s > self.duration_s()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn parse(text: &str) -> Result<CsvDevice, String> {
        CsvDevice::parse(text, Path::new("t.csv")).map_err(|e| e.to_string())
    }

    const GOOD: &str = "# a stroke\nt_s, x_m, y_m, z_m, qw, qx, qy, qz, button\n0, 0, 0, 0.01, 1, 0, 0, 0, 0\n\n1.0, 0.02, 0, -0.004, 1, 0, 0, 0, 1\n";

    #[test]
    fn reads_and_interpolates() {
        let mut d = parse(GOOD).expect("good file");
        assert_eq!(d.len(), 2);
        let p = d.read(500, 0.5).expect("pose");
        assert!((p.tip_in_world - Point3::new(0.01, 0.0, 0.003)).norm() < 1e-12);
        assert_eq!(p.buttons, 0);
        assert_eq!(d.read(1000, 1.0).expect("pose").buttons, 1);
        assert!(d.finished(1.5) && !d.finished(0.9));
    }

    /// Found for the mutation test (tests/fuzz-regressions/trajectory_csv/, issue 32): finite
    /// values whose arithmetic overflows gave a zero "unit" quaternion and an infinite tip.
    #[test]
    fn huge_but_finite_values_give_finite_poses() {
        let header = "t_s,x_m,y_m,z_m,qw,qx,qy,qz,button\n";
        let mut d = parse(&format!(
            "{header}0, 0, 0, 0, 1e300, 1e300, 0, 0, 0\n1, 0, 0, 0, 1, 0, 0, 0, 1\n"
        ))
        .expect("a long quaternion is normalised");
        let q = d.pose_at(0.0).world_from_tool;
        assert!((q.quaternion().norm() - 1.0).abs() < 1e-12, "{q:?}");
        assert!(
            (q.angle() - std::f64::consts::FRAC_PI_2).abs() < 1e-12,
            "{q:?}"
        );
        let mut d = parse(&format!(
            "{header}0, -1e308, 0, 0, 1, 0, 0, 0, 0\n1, 1e308, 0, 0, 1, 0, 0, 0, 1\n"
        ))
        .expect("finite values");
        for t in [0.0, 0.25, 0.5, 0.75, 1.0] {
            let tip = d.pose_at(t).tip_in_world;
            assert!(tip.iter().all(|c| c.is_finite()), "{t}: {tip:?}");
        }
        assert_eq!(d.pose_at(0.5).tip_in_world.x, 0.0);
    }

    #[test]
    fn malformed_files_name_file_line_and_problem() {
        let cases = [
            ("", "empty file"),
            ("t, x, y\n", "t.csv:1: expected the header"),
            ("t_s, x_m, y_m, z_m, qw, qx, qy, qz, button\n", "no samples"),
            (
                "t_s,x_m,y_m,z_m,qw,qx,qy,qz,button\n0, 0, 0, 0, 1, 0, 0\n",
                "t.csv:2: expected 9 fields, found 7",
            ),
            (
                "t_s,x_m,y_m,z_m,qw,qx,qy,qz,button\n0, 0, abc, 0, 1, 0, 0, 0, 0\n",
                "t.csv:2: column 3 (y_m): `abc` is not a number",
            ),
            (
                "t_s,x_m,y_m,z_m,qw,qx,qy,qz,button\n0, 0, NaN, 0, 1, 0, 0, 0, 0\n",
                "not finite",
            ),
            (
                "t_s,x_m,y_m,z_m,qw,qx,qy,qz,button\n1, 0, 0, 0, 1, 0, 0, 0, 0\n1, 0, 0, 0, 1, 0, 0, 0, 0\n",
                "t.csv:3: t_s must increase strictly",
            ),
            (
                "t_s,x_m,y_m,z_m,qw,qx,qy,qz,button\n0, 0, 0, 0, 0, 0, 0, 0, 0\n",
                "zero length",
            ),
            (
                "t_s,x_m,y_m,z_m,qw,qx,qy,qz,button\n0, 0, 0, 0, 1, 0, 0, 0, 2\n",
                "expected 0, 1, 4 or 5",
            ),
            (
                "t_s,x_m,y_m,z_m,qw,qx,qy,qz,button\n-1, 0, 0, 0, 1, 0, 0, 0, 0\n",
                "must not be negative",
            ),
        ];
        for (text, expected) in cases {
            let e = parse(text).expect_err(text);
            assert!(e.contains(expected), "{text:?}: {e}");
        }
        let e = CsvDevice::open(Path::new("/no/such/file.csv"))
            .expect_err("missing")
            .to_string();
        assert!(e.contains("/no/such/file.csv"), "{e}");
    }
}
