//! The planning page's skin map: the tissue seen from above as an SVG in millimetres of the
//! scene's [`SkinMap`] (`x` along the map, `y` up it; SVG's `y` is `-y`), with the landmarks
//! marked on the skin, the target's outline beneath it and the expert's line. The candidates'
//! lines are drawn on it by `static/planning.js` from the form's fields.

use cutlab_scoring::exercise::field::FieldPlan;
use cutlab_scoring::planning::SkinMap;
use maud::{Markup, html};

/// Room around the tissue, mm.
const MARGIN_MM: f64 = 6.0;

/// `p` on the map as SVG coordinates, mm.
fn svg_mm(map: &SkinMap, p: &[f64; 3]) -> [f64; 2] {
    let [a, b] = map.across(p);
    [a * 1e3, -b * 1e3]
}

fn points(map: &SkinMap, line: &[[f64; 3]]) -> String {
    line.iter()
        .map(|p| {
            let [x, y] = svg_mm(map, p);
            format!("{x:.2},{y:.2}")
        })
        .collect::<Vec<_>>()
        .join(" ")
}

/// The map of `plan` on `map`.
pub fn map_svg(plan: &FieldPlan, map: &SkinMap) -> Markup {
    let (lo, hi) = map.extent_m();
    let (x0, x1) = (lo[0] * 1e3, hi[0] * 1e3);
    let (y0, y1) = (-hi[1] * 1e3, -lo[1] * 1e3);
    let view = format!(
        "{:.1} {:.1} {:.1} {:.1}",
        x0 - MARGIN_MM,
        y0 - MARGIN_MM,
        x1 - x0 + 2.0 * MARGIN_MM,
        y1 - y0 + 2.0 * MARGIN_MM
    );
    let [cx, cy] = svg_mm(map, &plan.target_centre_m);
    let expert = points(map, &plan.incision_m);
    html! {
        figure class="skin-map" {
            svg id="skin-map" xmlns="http://www.w3.org/2000/svg" viewBox=(view) role="img" aria-label="The skin seen from above: drag to draw a candidate incision" {
                rect class="tissue" x=(x0) y=(y0) width=(x1 - x0) height=(y1 - y0) {}
                ellipse class="target" cx=(cx) cy=(cy) rx=(plan.target_radii_m[0] * 1e3) ry=(plan.target_radii_m[1] * 1e3) {}
                @for line in &plan.landmarks_m {
                    polyline class="landmark" points=(points(map, line)) {}
                }
                polyline class="expert" points=(expert) {}
                g id="candidate-lines" {}
                line id="drag-line" class="candidate dragging" x1="0" y1="0" x2="0" y2="0" visibility="hidden" {}
            }
            figcaption {
                span class="key expert" { "expert's line" } " "
                span class="key landmark" { "landmarks on the skin" } " "
                span class="key target" { "the target beneath" }
                br;
                (format!("{:.0} × {:.0} mm of skin; drag on it to draw the chosen candidate.", x1 - x0, y1 - y0))
            }
        }
    }
}
