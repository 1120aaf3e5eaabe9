//! `cutlab motion-metrics POSES.csv`: the path metrics of a tool trajectory recorded anywhere.
//!
//! The CSV has 8 columns `t_s, x_m, y_m, z_m, qw, qx, qy, qz` (time in seconds, tip position
//! in metres, unit quaternion), any sampling rate (even uneven: the metrics resample on the
//! time column), the time increasing from row to row. A first line that is not numeric is a header; empty lines and lines starting
//! with `#` are skipped. A malformed row is an error naming its line.

use std::path::Path;

use anyhow::{Context, bail};
use cutlab_scoring::PoseSample;
use cutlab_scoring::metrics::path::{PathParams, path};

const COLUMNS: [&str; 8] = ["t_s", "x_m", "y_m", "z_m", "qw", "qx", "qy", "qz"];

/// Parses the CSV text (`name` for messages).
pub fn parse_poses(text: &str, name: &str) -> anyhow::Result<Vec<PoseSample>> {
    let mut poses = Vec::new();
    let mut seen_row = false;
    for (i, line) in text.lines().enumerate() {
        let line_no = i + 1;
        let line = line.trim();
        if line.is_empty() || line.starts_with('#') {
            continue;
        }
        let fields: Vec<&str> = line.split(',').map(str::trim).collect();
        if !seen_row {
            seen_row = true;
            if fields.first().is_some_and(|f| f.parse::<f64>().is_err()) {
                continue; // the header
            }
        }
        if fields.len() != COLUMNS.len() {
            bail!(
                "{name}:{line_no}: expected {} fields ({}), found {}",
                COLUMNS.len(),
                COLUMNS.join(", "),
                fields.len()
            );
        }
        let mut v = [0.0f64; 8];
        for (k, f) in fields.iter().enumerate() {
            v[k] = f.parse().map_err(|_| {
                anyhow::anyhow!("{name}:{line_no}: {} {f:?} is not a number", COLUMNS[k])
            })?;
            if !v[k].is_finite() {
                bail!("{name}:{line_no}: {} is not finite", COLUMNS[k]);
            }
        }
        if let Some(prev) = poses.last().map(|p: &PoseSample| p.t_s)
            && v[0] <= prev
        {
            bail!(
                "{name}:{line_no}: time {} s does not increase (previous row {prev} s)",
                v[0]
            );
        }
        if v[4..].iter().map(|q| q * q).sum::<f64>() < 1e-12 {
            bail!("{name}:{line_no}: the quaternion is zero");
        }
        poses.push(PoseSample {
            t_s: v[0],
            tip_m: [v[1], v[2], v[3]],
            quat_wxyz: [v[4], v[5], v[6], v[7]],
            blade_engaged: false,
        });
    }
    Ok(poses)
}

fn opt(v: Option<f64>, scale: f64, digits: usize) -> String {
    v.map_or_else(|| "-".to_owned(), |v| format!("{:.digits$}", v * scale))
}

pub fn run(file: &Path, json: bool) -> anyhow::Result<()> {
    let text =
        std::fs::read_to_string(file).with_context(|| format!("reading {}", file.display()))?;
    let poses = parse_poses(&text, &file.display().to_string())?;
    let m = path(&poses, &PathParams::default()).with_context(|| format!("{}", file.display()))?;
    if json {
        let mut v = serde_json::to_value(&m)?;
        v["samples"] = poses.len().into();
        v["file"] = file.display().to_string().into();
        println!("{}", serde_json::to_string_pretty(&v)?);
        return Ok(());
    }
    println!("{}: {} poses", file.display(), poses.len());
    println!("{:<22} {:>12}  unit", "metric", "value");
    let rows: [(&str, String, &str); 11] = [
        ("time", format!("{:.3}", m.time_s), "s"),
        ("path length", format!("{:.1}", m.path_length_m * 1e3), "mm"),
        ("economy of motion", opt(m.economy_of_motion, 1.0, 3), ""),
        ("idle time", format!("{:.3}", m.idle_time_s), "s"),
        ("movements", m.movements.to_string(), ""),
        (
            "peak speed",
            format!("{:.1}", m.peak_speed_m_s * 1e3),
            "mm/s",
        ),
        ("angular path", format!("{:.3}", m.angular_path_rad), "rad"),
        ("LDLJ", opt(m.ldlj, 1.0, 3), ""),
        ("SPARC", opt(m.sparc, 1.0, 3), ""),
        ("LDLJ per movement", opt(m.ldlj_per_movement, 1.0, 3), ""),
        ("SPARC per movement", opt(m.sparc_per_movement, 1.0, 3), ""),
    ];
    for (name, value, unit) in rows {
        println!("{name:<22} {value:>12}  {unit}");
    }
    for (i, mv) in m.per_movement.iter().enumerate() {
        println!(
            "movement {:>3}: {:.3}-{:.3} s, peak {:.1} mm/s, LDLJ {}, SPARC {}",
            i + 1,
            mv.start_s,
            mv.end_s,
            mv.peak_speed_m_s * 1e3,
            opt(mv.ldlj, 1.0, 3),
            opt(mv.sparc, 1.0, 3)
        );
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn header_comments_and_errors_with_line_numbers() {
        let ok = "t_s,x_m,y_m,z_m,qw,qx,qy,qz\n# comment\n0,0,0,0,1,0,0,0\n\n0.1, 0.001, 0, 0, 1, 0, 0, 0\n";
        assert_eq!(parse_poses(ok, "p.csv").unwrap().len(), 2);
        let short = "0,0,0,0,1,0,0,0\n0.1,0,0,0,1,0,0\n";
        assert!(
            parse_poses(short, "p.csv")
                .unwrap_err()
                .to_string()
                .contains("p.csv:2: expected 8 fields")
        );
        let word = "0,0,0,0,1,0,0,0\n0.1,0,zero,0,1,0,0,0\n";
        assert!(
            parse_poses(word, "p.csv")
                .unwrap_err()
                .to_string()
                .contains("p.csv:2: y_m \"zero\" is not a number")
        );
        let back = "0.2,0,0,0,1,0,0,0\n0.1,0,0,0,1,0,0,0\n";
        assert!(
            parse_poses(back, "p.csv")
                .unwrap_err()
                .to_string()
                .contains("p.csv:2: time")
        );
        let nan = "0,0,0,NaN,1,0,0,0\n";
        assert!(
            parse_poses(nan, "p.csv")
                .unwrap_err()
                .to_string()
                .contains("p.csv:1: z_m is not finite")
        );
    }
}
