//! Charts as inline SVG, drawn by us (no fonts or scripts needed): a plot area with axes and
//! ticks, and layers (lines, points, horizontal bands and lines). Every text goes through
//! maud, so it is escaped. Styling is by CSS class (`static/style.css`).

use maud::{Markup, html};

/// Something drawn in a chart's data coordinates.
#[derive(Debug, Clone)]
pub enum Layer {
    /// A polyline; `None` values break it.
    Line {
        points: Vec<(f64, Option<f64>)>,
        class: &'static str,
    },
    /// Markers, each with its own class (e.g. pass / fail).
    Points {
        points: Vec<(f64, f64, &'static str)>,
    },
    /// A horizontal band between two values.
    HBand {
        low: f64,
        high: f64,
        class: &'static str,
    },
    /// A horizontal line with a label at its right end.
    HLine {
        y: f64,
        class: &'static str,
        label: String,
    },
    /// A short text just right of a point (a line's name at its last point).
    Text { x: f64, y: f64, text: String },
}

/// A chart: title, axis labels and layers; ranges from the data unless given.
#[derive(Debug, Clone)]
pub struct Chart {
    pub title: String,
    pub x_label: String,
    pub y_label: String,
    pub layers: Vec<Layer>,
    pub width: f64,
    pub height: f64,
    /// Forces the y range to include these values.
    pub y_include: Vec<f64>,
    /// Same scale on both axes (top views).
    pub equal_aspect: bool,
    /// A legend in the right margin: `(class of the line, label)` per entry.
    pub legend: Vec<(&'static str, String)>,
    /// Ticks on the x axis at whole numbers only (attempt numbers).
    pub integer_x: bool,
    /// Named positions on the x axis (groups), shown instead of numbers; the x range spans
    /// them with half a step each side.
    pub categories: Vec<(f64, String)>,
}

const MARGIN_L: f64 = 58.0;
const MARGIN_R: f64 = 70.0;
const MARGIN_T: f64 = 26.0;
const MARGIN_B: f64 = 40.0;

impl Chart {
    pub fn new(
        title: impl Into<String>,
        x_label: impl Into<String>,
        y_label: impl Into<String>,
    ) -> Self {
        Self {
            title: title.into(),
            x_label: x_label.into(),
            y_label: y_label.into(),
            layers: Vec::new(),
            width: 460.0,
            height: 240.0,
            y_include: Vec::new(),
            equal_aspect: false,
            legend: Vec::new(),
            integer_x: false,
            categories: Vec::new(),
        }
    }

    /// Names the x positions `x` (groups) and ticks the axis with them only.
    pub fn category(mut self, x: f64, name: impl Into<String>) -> Self {
        self.categories.push((x, name.into()));
        self
    }

    /// Ticks the x axis at whole numbers only (for counts such as attempt numbers).
    pub fn integer_x(mut self) -> Self {
        self.integer_x = true;
        self
    }

    /// Adds a legend entry: a short line of `class`, then `label`.
    pub fn legend(mut self, class: &'static str, label: impl Into<String>) -> Self {
        self.legend.push((class, label.into()));
        self
    }

    pub fn layer(mut self, l: Layer) -> Self {
        self.layers.push(l);
        self
    }

    pub(crate) fn ranges(&self) -> ((f64, f64), (f64, f64)) {
        let (mut xs, mut ys): (Vec<f64>, Vec<f64>) = (Vec::new(), self.y_include.clone());
        for l in &self.layers {
            match l {
                Layer::Line { points, .. } => {
                    for (x, y) in points {
                        xs.push(*x);
                        ys.extend(y.iter());
                    }
                }
                Layer::Points { points } => {
                    for (x, y, _) in points {
                        xs.push(*x);
                        ys.push(*y);
                    }
                }
                Layer::HBand { low, high, .. } => ys.extend([*low, *high]),
                Layer::HLine { y, .. } => ys.push(*y),
                Layer::Text { .. } => {}
            }
        }
        let x = if self.categories.is_empty() {
            span(&xs)
        } else {
            let c: Vec<f64> = self.categories.iter().map(|c| c.0).collect();
            let (lo, hi) = c
                .iter()
                .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), x| {
                    (a.min(*x), b.max(*x))
                });
            (lo - 0.5, hi + 0.5)
        };
        (x, span(&ys))
    }

    /// The SVG element.
    pub fn render(&self) -> Markup {
        let ((mut x0, mut x1), (mut y0, mut y1)) = self.ranges();
        let (pw, ph) = (
            self.width - MARGIN_L - MARGIN_R,
            self.height - MARGIN_T - MARGIN_B,
        );
        if self.equal_aspect {
            // widen the narrower range so one unit is as long on both axes
            let (sx, sy) = ((x1 - x0) / pw, (y1 - y0) / ph);
            if sx > sy {
                let c = 0.5 * (y0 + y1);
                (y0, y1) = (c - 0.5 * sx * ph, c + 0.5 * sx * ph);
            } else {
                let c = 0.5 * (x0 + x1);
                (x0, x1) = (c - 0.5 * sy * pw, c + 0.5 * sy * pw);
            }
        }
        let px = |x: f64| MARGIN_L + (x - x0) / (x1 - x0) * pw;
        let py = |y: f64| MARGIN_T + (1.0 - (y - y0) / (y1 - y0)) * ph;
        let clamp_y = |y: f64| py(y.clamp(y0, y1));
        html! {
            svg class="chart" xmlns="http://www.w3.org/2000/svg" width=(fmt(self.width)) height=(fmt(self.height)) viewBox=(format!("0 0 {} {}", fmt(self.width), fmt(self.height))) role="img" {
                title { (self.title) }
                text class="chart-title" x=(fmt(MARGIN_L)) y="16" { (self.title) }
                rect class="plot-area" x=(fmt(MARGIN_L)) y=(fmt(MARGIN_T)) width=(fmt(pw)) height=(fmt(ph)) {}
                @for t in ticks(y0, y1, false) {
                    line class="grid" x1=(fmt(MARGIN_L)) x2=(fmt(MARGIN_L + pw)) y1=(fmt(py(t))) y2=(fmt(py(t))) {}
                    text class="tick" x=(fmt(MARGIN_L - 4.0)) y=(fmt(py(t) + 4.0)) text-anchor="end" { (tick_label(t)) }
                }
                @if self.categories.is_empty() {
                    @for t in ticks(x0, x1, self.integer_x) {
                        text class="tick" x=(fmt(px(t))) y=(fmt(MARGIN_T + ph + 14.0)) text-anchor="middle" { (tick_label(t)) }
                    }
                }
                @for (x, name) in &self.categories {
                    text class="tick" x=(fmt(px(*x))) y=(fmt(MARGIN_T + ph + 14.0)) text-anchor="middle" { (name) }
                }
                text class="axis-label" x=(fmt(MARGIN_L + pw / 2.0)) y=(fmt(self.height - 6.0)) text-anchor="middle" { (self.x_label) }
                text class="axis-label" transform=(format!("translate(12 {}) rotate(-90)", fmt(MARGIN_T + ph / 2.0))) text-anchor="middle" { (self.y_label) }
                @if !self.legend.is_empty() {
                    g class="legend" {
                        @for (i, (class, label)) in self.legend.iter().enumerate() {
                            @let y = MARGIN_T + 8.0 + 14.0 * i as f64;
                            line class=(class) x1=(fmt(MARGIN_L + pw + 4.0)) x2=(fmt(MARGIN_L + pw + 20.0)) y1=(fmt(y)) y2=(fmt(y)) {}
                            text x=(fmt(MARGIN_L + pw + 23.0)) y=(fmt(y + 3.5)) { (label) }
                        }
                    }
                }
                @for l in &self.layers {
                    @match l {
                        Layer::HBand { low, high, class } => {
                            rect class=(class) x=(fmt(MARGIN_L)) width=(fmt(pw)) y=(fmt(clamp_y(*high))) height=(fmt((clamp_y(*low) - clamp_y(*high)).max(0.0))) {}
                        }
                        Layer::HLine { y, class, label } => {
                            line class=(class) x1=(fmt(MARGIN_L)) x2=(fmt(MARGIN_L + pw)) y1=(fmt(clamp_y(*y))) y2=(fmt(clamp_y(*y))) {}
                            text class=(format!("{class}-label")) x=(fmt(MARGIN_L + pw + 4.0)) y=(fmt(clamp_y(*y) + 4.0)) { (label) }
                        }
                        Layer::Text { x, y, text } => {
                            text class="end-label" x=(fmt(px(*x) + 4.0)) y=(fmt(clamp_y(*y) + 3.0)) { (text) }
                        }
                        Layer::Line { points, class } => {
                            @for run in runs(points) {
                                polyline class=(class) points=(run.iter().map(|(x, y)| format!("{},{}", fmt(px(*x)), fmt(py(*y)))).collect::<Vec<_>>().join(" ")) {}
                            }
                        }
                        Layer::Points { points } => {
                            @for (x, y, class) in points {
                                circle class=(class) cx=(fmt(px(*x))) cy=(fmt(py(*y))) r="3.5" {}
                            }
                        }
                    }
                }
            }
        }
    }
}

/// The unbroken stretches of a line.
fn runs(points: &[(f64, Option<f64>)]) -> Vec<Vec<(f64, f64)>> {
    let mut out = vec![Vec::new()];
    for (x, y) in points {
        match y {
            Some(y) if y.is_finite() && x.is_finite() => {
                if let Some(r) = out.last_mut() {
                    r.push((*x, *y));
                }
            }
            _ => out.push(Vec::new()),
        }
    }
    out.retain(|r| !r.is_empty());
    out
}

/// `(min, max)` of the finite values, padded; `(0, 1)` when there are none.
fn span(v: &[f64]) -> (f64, f64) {
    let (lo, hi) = v
        .iter()
        .filter(|x| x.is_finite())
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), x| {
            (a.min(*x), b.max(*x))
        });
    if !lo.is_finite() {
        return (0.0, 1.0);
    }
    if hi - lo < 1e-12 * lo.abs().max(1.0) {
        let pad = if lo == 0.0 { 1.0 } else { 0.1 * lo.abs() };
        return (lo - pad, hi + pad);
    }
    let pad = 0.05 * (hi - lo);
    (lo - pad, hi + pad)
}

/// About five round tick values within `[lo, hi]`; with `integer`, whole numbers only (a
/// step of at least 1).
fn ticks(lo: f64, hi: f64, integer: bool) -> Vec<f64> {
    let range = hi - lo;
    if !(range > 0.0) || !range.is_finite() {
        return Vec::new();
    }
    let raw = range / 5.0;
    let mag = 10f64.powf(raw.log10().floor());
    let step = [1.0, 2.0, 5.0, 10.0]
        .iter()
        .map(|m| m * mag)
        .find(|s| range / s <= 6.0)
        .unwrap_or(10.0 * mag);
    let step = if integer { step.max(1.0) } else { step };
    let first = (lo / step).ceil() as i64;
    let last = (hi / step).floor() as i64;
    (first..=last).map(|i| i as f64 * step).collect()
}

fn tick_label(v: f64) -> String {
    let a = v.abs();
    if a == 0.0 {
        "0".into()
    } else if !(1e-3..1e5).contains(&a) {
        format!("{v:.1e}")
    } else if a >= 100.0 || (v.fract() == 0.0) {
        format!("{v:.0}")
    } else {
        let s = format!("{v:.3}");
        s.trim_end_matches('0').trim_end_matches('.').to_owned()
    }
}

/// A coordinate with two decimals (SVG attribute text).
fn fmt(v: f64) -> String {
    if v.is_finite() {
        format!("{v:.2}")
    } else {
        "0".into()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ticks_are_round_and_inside() {
        assert_eq!(ticks(0.0, 10.0, false), vec![0.0, 2.0, 4.0, 6.0, 8.0, 10.0]);
        let t = ticks(-0.37, 1.21, false);
        assert!(
            t.iter().all(|v| (-0.37..=1.21).contains(v)) && t.len() >= 3,
            "{t:?}"
        );
        assert!(ticks(1.0, 1.0, false).is_empty());
        assert!(ticks(f64::NAN, 1.0, false).is_empty());
    }

    #[test]
    fn integer_ticks_are_whole_numbers() {
        // two attempts, padded: 0.95 .. 2.05 (decimal ticks would be 1, 1.2, ... 2)
        assert_eq!(ticks(0.95, 2.05, true), vec![1.0, 2.0]);
        assert_eq!(ticks(0.9, 3.1, true), vec![1.0, 2.0, 3.0]);
        assert_eq!(ticks(0.5, 1.5, true), vec![1.0]);
        assert_eq!(ticks(0.0, 40.0, true), ticks(0.0, 40.0, false));
        assert!(ticks(0.95, 2.05, false).iter().any(|t| t.fract() != 0.0));
        for (lo, hi) in [(0.1, 0.9), (0.65, 8.35), (-3.3, 17.2), (0.99, 1.01)] {
            assert!(
                ticks(lo, hi, true).iter().all(|t| t.fract() == 0.0),
                "{lo} {hi}"
            );
        }
        // in the SVG: the x labels of an attempt chart
        let svg = Chart::new("t", "attempt", "v")
            .integer_x()
            .layer(Layer::Line {
                points: vec![(1.0, Some(0.3)), (2.0, Some(0.5))],
                class: "series",
            })
            .render()
            .into_string();
        assert!(svg.contains(">1</text>") && svg.contains(">2</text>"));
        assert!(
            !svg.contains(">1.5</text>") && !svg.contains(">1.2</text>"),
            "{svg}"
        );
    }

    #[test]
    fn text_is_escaped_and_gaps_break_lines() {
        let svg = Chart::new("<script>x</script>", "n", "v")
            .layer(Layer::Line {
                points: vec![
                    (1.0, Some(1.0)),
                    (2.0, None),
                    (3.0, Some(2.0)),
                    (4.0, Some(3.0)),
                ],
                class: "series",
            })
            .render()
            .into_string();
        assert!(!svg.contains("<script>"));
        assert!(svg.contains("&lt;script&gt;"));
        // one point alone, then a run of two: two polylines
        assert_eq!(svg.matches("<polyline").count(), 2, "{svg}");
    }
}
