//! Log-log plots as SVG, drawn by hand for the benchmarks (`cutlab bench accuracy`,
//! `cutlab bench perf`): panels stacked vertically, each with decade ticks, series of points
//! (markers, a line, or both) and horizontal guides, and one legend above them.

use std::fmt::Write;

/// How a series' points are joined.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Line {
    None,
    Solid,
    Dashed,
}

/// A point with its tooltip.
#[derive(Debug, Clone)]
pub struct Point {
    pub x: f64,
    pub y: f64,
    pub title: String,
}

/// Points of one colour; in the legend under `name` unless it is empty.
#[derive(Debug, Clone)]
pub struct Series {
    pub name: String,
    pub colour: &'static str,
    pub line: Line,
    pub markers: bool,
    pub points: Vec<Point>,
}

/// One log-log panel. Points that are not positive are left out.
#[derive(Debug, Clone, Default)]
pub struct Panel {
    pub title: String,
    /// Appended to the tick labels of each axis (e.g. `" %"`).
    pub x_unit: String,
    pub y_unit: String,
    pub series: Vec<Series>,
    /// Horizontal lines at these values, labelled.
    pub guides: Vec<(f64, String)>,
}

const LEFT: f64 = 70.0;
const LEGEND_ENTRY_WIDTH: f64 = 170.0;

/// The panels one below the other, `panel_height` each, in an SVG `width` pixels wide.
pub fn log_log(width: f64, panel_height: f64, panels: &[Panel]) -> String {
    let mut legend: Vec<&Series> = Vec::new();
    for s in panels.iter().flat_map(|p| &p.series) {
        if !s.name.is_empty() && !legend.iter().any(|l| l.name == s.name) {
            legend.push(s);
        }
    }
    let per_row = (((width - LEFT) / LEGEND_ENTRY_WIDTH).floor() as usize).max(1);
    let top = 30.0 + 18.0 * (legend.len().max(1).div_ceil(per_row) - 1) as f64;
    let height = top + panel_height * panels.len() as f64 + 40.0;
    let mut s = format!(
        "<svg xmlns=\"http://www.w3.org/2000/svg\" width=\"{width}\" height=\"{height}\" font-family=\"sans-serif\" font-size=\"11\">\n<rect width=\"100%\" height=\"100%\" fill=\"white\"/>\n"
    );
    for (k, entry) in legend.iter().enumerate() {
        let x = LEFT + LEGEND_ENTRY_WIDTH * (k % per_row) as f64;
        let y = 14.0 + 18.0 * (k / per_row) as f64;
        if entry.line != Line::None {
            let _ = writeln!(
                s,
                "<line x1=\"{}\" y1=\"{y}\" x2=\"{}\" y2=\"{y}\" stroke=\"{}\"{}/>",
                x - 8.0,
                x + 8.0,
                entry.colour,
                dash(entry.line)
            );
        }
        if entry.markers || entry.line == Line::None {
            let _ = write!(
                s,
                "<circle cx=\"{x}\" cy=\"{y}\" r=\"4\" fill=\"{}\"/>",
                entry.colour
            );
        }
        let _ = writeln!(
            s,
            "<text x=\"{}\" y=\"{}\">{}</text>",
            x + 12.0,
            y + 4.0,
            entry.name
        );
    }
    let plot_w = width - LEFT - 20.0;
    for (pi, panel) in panels.iter().enumerate() {
        let y0 = top + panel_height * pi as f64;
        let ph = panel_height - 50.0;
        let shown = |p: &&Point| p.x > 0.0 && p.y > 0.0;
        let points = || {
            panel
                .series
                .iter()
                .flat_map(|s| s.points.iter().filter(shown))
        };
        if points().next().is_none() {
            continue;
        }
        let (mut xmin, mut xmax, mut ymin, mut ymax) = (
            f64::INFINITY,
            f64::NEG_INFINITY,
            f64::INFINITY,
            f64::NEG_INFINITY,
        );
        for p in points() {
            xmin = xmin.min(p.x.log10().floor());
            xmax = xmax.max(p.x.log10().ceil());
            ymin = ymin.min(p.y.log10().floor());
            ymax = ymax.max(p.y.log10().ceil());
        }
        for (g, _) in panel.guides.iter().filter(|(g, _)| *g > 0.0) {
            ymin = ymin.min(g.log10().floor());
            ymax = ymax.max(g.log10().ceil());
        }
        if xmax <= xmin {
            xmax = xmin + 1.0;
        }
        if ymax <= ymin {
            ymax = ymin + 1.0;
        }
        let px = |v: f64| LEFT + (v.log10() - xmin) / (xmax - xmin) * plot_w;
        let py = |v: f64| y0 + 20.0 + (ymax - v.log10()) / (ymax - ymin) * ph;
        let _ = writeln!(
            s,
            "<rect x=\"{LEFT}\" y=\"{}\" width=\"{plot_w}\" height=\"{ph}\" fill=\"none\" stroke=\"#888\"/>\n<text x=\"{LEFT}\" y=\"{}\">{}</text>",
            y0 + 20.0,
            y0 + 14.0,
            panel.title
        );
        for d in (xmin as i32)..=(xmax as i32) {
            let x = LEFT + (d as f64 - xmin) / (xmax - xmin) * plot_w;
            let _ = writeln!(
                s,
                "<text x=\"{x}\" y=\"{}\" text-anchor=\"middle\">1e{d}{}</text>",
                y0 + 20.0 + ph + 14.0,
                panel.x_unit
            );
        }
        for d in (ymin as i32)..=(ymax as i32) {
            let y = y0 + 20.0 + (ymax - d as f64) / (ymax - ymin) * ph;
            let _ = writeln!(
                s,
                "<text x=\"{}\" y=\"{}\" text-anchor=\"end\">1e{d}{}</text>",
                LEFT - 4.0,
                y + 4.0,
                panel.y_unit
            );
        }
        for (g, label) in panel.guides.iter().filter(|(g, _)| *g > 0.0) {
            let y = py(*g);
            let _ = writeln!(
                s,
                "<line x1=\"{LEFT}\" y1=\"{y:.1}\" x2=\"{}\" y2=\"{y:.1}\" stroke=\"#bbb\"/><text x=\"{}\" y=\"{:.1}\" text-anchor=\"end\" fill=\"#777\">{label}</text>",
                LEFT + plot_w,
                LEFT + plot_w - 4.0,
                y - 3.0
            );
        }
        for series in &panel.series {
            let points: Vec<&Point> = series.points.iter().filter(shown).collect();
            if series.line != Line::None && points.len() > 1 {
                let xy: Vec<String> = points
                    .iter()
                    .map(|p| format!("{:.1},{:.1}", px(p.x), py(p.y)))
                    .collect();
                let _ = writeln!(
                    s,
                    "<polyline points=\"{}\" fill=\"none\" stroke=\"{}\"{}/>",
                    xy.join(" "),
                    series.colour,
                    dash(series.line)
                );
            }
            if series.markers {
                for p in points {
                    let _ = writeln!(
                        s,
                        "<circle cx=\"{:.1}\" cy=\"{:.1}\" r=\"4\" fill=\"{}\"><title>{}</title></circle>",
                        px(p.x),
                        py(p.y),
                        series.colour,
                        p.title
                    );
                }
            }
        }
    }
    s.push_str("</svg>\n");
    s
}

fn dash(line: Line) -> &'static str {
    if line == Line::Dashed {
        " stroke-dasharray=\"4 3\""
    } else {
        ""
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn points_land_on_their_decades_and_non_positive_ones_are_left_out() {
        let panel = Panel {
            title: "t".into(),
            series: vec![Series {
                name: "a".into(),
                colour: "#000",
                line: Line::Solid,
                markers: true,
                points: vec![
                    Point {
                        x: 10.0,
                        y: 1.0,
                        title: "low".into(),
                    },
                    Point {
                        x: 100.0,
                        y: 10.0,
                        title: "high".into(),
                    },
                    Point {
                        x: 0.0,
                        y: 5.0,
                        title: "gone".into(),
                    },
                ],
            }],
            ..Panel::default()
        };
        let svg = log_log(290.0, 150.0, &[panel]);
        // x from 1e1 to 1e2 over 200 px from 70; y from 1e0 to 1e1 over 100 px below 50
        assert!(svg.contains("<circle cx=\"70.0\" cy=\"150.0\""), "{svg}");
        assert!(svg.contains("<circle cx=\"270.0\" cy=\"50.0\""), "{svg}");
        assert!(!svg.contains("gone"));
        assert!(svg.contains("<polyline points=\"70.0,150.0 270.0,50.0\""));
    }
}
