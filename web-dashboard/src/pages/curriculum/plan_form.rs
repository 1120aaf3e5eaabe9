//! The expert plan in the exercise forms: labelled fields for its main values (entry, exit,
//! viewpoint in mm; depth, tolerance, corridor in mm; force limit in N), or the whole plan
//! as TOML or JSON (typed, or loaded from a file by `static/plan.js`), and what every field
//! of a plan means, on the page itself (there is no reference page on plans).
//!
//! What the handlers accept: a non-empty `plan` text is the plan, as before; else the fields
//! present are applied over a base plan (the exercise's, or the built-in one for a new
//! exercise); a field left as shown keeps the base's exact value. Changing the entry or the
//! exit replaces the planned line by the straight one between them.

use std::collections::HashMap;

use cutlab_assessor::ExpertPlan;
use maud::{Markup, html};

use crate::error::AppError;

/// Which value of the plan a field sets.
#[derive(Debug, Clone, Copy)]
enum Slot {
    Entry(usize),
    Exit(usize),
    Viewpoint(usize),
    Depth,
    Tolerance,
    Corridor,
    ForceLimit,
}

/// A field: its form name, label, display unit and factor from the plan's SI value.
struct Field {
    name: &'static str,
    label: &'static str,
    unit: &'static str,
    factor: f64,
    slot: Slot,
}

const fn mm(name: &'static str, label: &'static str, slot: Slot) -> Field {
    Field {
        name,
        label,
        unit: "mm",
        factor: 1e3,
        slot,
    }
}

/// The points, as (legend, its x, y, z fields).
const POINTS: [(&str, [Field; 3]); 3] = [
    (
        "Entry: where the incision starts, on the surface",
        [
            mm("entry_x_mm", "x", Slot::Entry(0)),
            mm("entry_y_mm", "y", Slot::Entry(1)),
            mm("entry_z_mm", "z", Slot::Entry(2)),
        ],
    ),
    (
        "Exit: where it ends",
        [
            mm("exit_x_mm", "x", Slot::Exit(0)),
            mm("exit_y_mm", "y", Slot::Exit(1)),
            mm("exit_z_mm", "z", Slot::Exit(2)),
        ],
    ),
    (
        "Viewpoint: the eye the target is seen from",
        [
            mm("viewpoint_x_mm", "x", Slot::Viewpoint(0)),
            mm("viewpoint_y_mm", "y", Slot::Viewpoint(1)),
            mm("viewpoint_z_mm", "z", Slot::Viewpoint(2)),
        ],
    ),
];

const SCALARS: [Field; 4] = [
    mm("depth_mm", "Depth below the surface", Slot::Depth),
    mm(
        "tolerance_mm",
        "Tolerance: on the line within",
        Slot::Tolerance,
    ),
    mm(
        "corridor_mm",
        "Corridor half-width: cuts beyond it damage tissue",
        Slot::Corridor,
    ),
    Field {
        name: "force_limit_n",
        label: "Force limit: forces above it count as excessive",
        unit: "N",
        factor: 1.0,
        slot: Slot::ForceLimit,
    },
];

fn fields() -> impl Iterator<Item = &'static Field> {
    POINTS.iter().flat_map(|(_, f)| f.iter()).chain(&SCALARS)
}

fn get(p: &ExpertPlan, s: Slot) -> f64 {
    match s {
        Slot::Entry(i) => p.entry_m[i],
        Slot::Exit(i) => p.exit_m[i],
        Slot::Viewpoint(i) => p.viewpoint_m[i],
        Slot::Depth => p.depth_m,
        Slot::Tolerance => p.tolerance_m,
        Slot::Corridor => p.corridor_half_width_m,
        Slot::ForceLimit => p.force_limit_n,
    }
}

fn set(p: &mut ExpertPlan, s: Slot, v: f64) {
    match s {
        Slot::Entry(i) => p.entry_m[i] = v,
        Slot::Exit(i) => p.exit_m[i] = v,
        Slot::Viewpoint(i) => p.viewpoint_m[i] = v,
        Slot::Depth => p.depth_m = v,
        Slot::Tolerance => p.tolerance_m = v,
        Slot::Corridor => p.corridor_half_width_m = v,
        Slot::ForceLimit => p.force_limit_n = v,
    }
}

/// A field's value as shown (up to 6 decimals, no trailing zeros).
fn shown(f: &Field, p: &ExpertPlan) -> String {
    let s = format!("{:.6}", get(p, f.slot) * f.factor);
    let s = s.trim_end_matches('0').trim_end_matches('.');
    if s == "-0" { "0" } else { s }.to_owned()
}

fn id(f: &Field) -> String {
    format!("plan-{}", f.name)
}

/// The labelled fields, showing `plan`'s values.
pub fn plan_fields(plan: &ExpertPlan) -> Markup {
    html! {
        fieldset class="plan-fields" {
            legend { "Expert plan" }
            p class="muted" { "Positions in mm in the scene's frame (z up); see “The plan's fields” below." }
            @for (legend, xyz) in &POINTS {
                fieldset class="point" {
                    legend { (legend) " (mm)" }
                    @for f in xyz {
                        label for=(id(f)) { (f.label) } " "
                        input type="number" step="any" required size="8" id=(id(f)) name=(f.name) value=(shown(f, plan)); " "
                    }
                }
            }
            @for f in &SCALARS {
                p {
                    label for=(id(f)) { (f.label) " (" (f.unit) ")" } " "
                    input type="number" step="any" min="0" required size="8" id=(id(f)) name=(f.name) value=(shown(f, plan));
                }
            }
            p class="muted" { "Changing the entry or the exit makes the planned line the straight one between them (a curved line needs the plan text)." }
        }
    }
}

/// The whole plan as text, typed or loaded from a file; used instead of the fields.
pub fn plan_text(max_bytes: usize) -> Markup {
    html! {
        details class="plan-text" {
            summary { "Or give the whole plan as TOML or JSON" }
            p {
                label for="plan-file" { "Load a plan file (.toml or .json) into the box" } " "
                input type="file" id="plan-file" accept=".toml,.json,text/plain,application/json,application/toml" data-into="plan-text";
            }
            p {
                label for="plan-text" { "Plan text (when filled in, it is used instead of the fields above)" } br;
                textarea id="plan-text" name="plan" rows="12" maxlength=(max_bytes) {}
            }
            p class="muted" { "An example with every field: " a href="/plans/example.toml" { "the built-in chest-wall plan (TOML)" } "." }
        }
        script src="/static/plan.js" {}
    }
}

/// What every field of a plan means (TOML / JSON keys, SI units).
pub fn plan_reference() -> Markup {
    const ROWS: &[(&str, &str, &str)] = &[
        ("name", "text", "a name for reports (optional)"),
        (
            "scene",
            "text",
            "the scene the plan is for, e.g. chest-wall (informative, optional)",
        ),
        (
            "entry_m",
            "[x, y, z] m",
            "where the incision starts, on the surface (required)",
        ),
        (
            "exit_m",
            "[x, y, z] m",
            "where it ends, on the surface (required)",
        ),
        (
            "incision_m",
            "list of [x, y, z] m",
            "the planned line on the surface from entry to exit, at least 2 points (default: the straight segment)",
        ),
        (
            "depth_m",
            "m",
            "the planned depth below the surface, > 0 (required)",
        ),
        (
            "normal",
            "[x, y, z]",
            "the surface's outward normal at the incision; depth is measured along −normal (default [0, 0, 1])",
        ),
        (
            "approach_dir",
            "[x, y, z]",
            "the direction the blade moves entering the tissue (default −normal)",
        ),
        (
            "target_m",
            "list of [x, y, z] m",
            "points on the target that must become visible through the opening (may be empty: then visibility is not measured)",
        ),
        (
            "viewpoint_m",
            "[x, y, z] m",
            "where the target is seen from (required)",
        ),
        (
            "tolerance_m",
            "m",
            "how far from the planned line still counts as on it (default 0.002)",
        ),
        (
            "corridor_half_width_m",
            "m",
            "half the width of the corridor cuts may stay in without damage (default 0.005)",
        ),
        (
            "force_limit_n",
            "N",
            "forces above it count as excessive: time above it, events (default 2.5); the pass limit on the peak force is the exercise's threshold",
        ),
    ];
    html! {
        details class="plan-reference" {
            summary { "The plan's fields" }
            p { "A plan is TOML or JSON (JSON when it starts with “{”) with these keys; SI units (metres, newtons). Lateral distances are measured seen from above, along the normal." }
            table {
                thead { tr { th { "Key" } th { "Unit" } th { "Meaning" } } }
                tbody {
                    @for (k, u, m) in ROWS { tr { td { code { (k) } } td { (u) } td { (m) } } }
                }
            }
        }
    }
}

/// The plan given by a form: its non-empty `plan` text; else `base` with the fields present
/// applied (`None` when there are none: the form said nothing about the plan).
pub fn plan_from_form(
    text: &str,
    form: &HashMap<String, String>,
    base: &ExpertPlan,
) -> Result<Option<ExpertPlan>, AppError> {
    if !text.trim().is_empty() {
        return super::parse_plan(text).map(Some);
    }
    if !fields().any(|f| form.contains_key(f.name)) {
        return Ok(None);
    }
    let mut plan = base.clone();
    let mut changed = false;
    for f in fields() {
        let Some(given) = form.get(f.name).map(|v| v.trim()) else {
            continue;
        };
        if given == shown(f, base) {
            continue; // as shown: the base's exact value
        }
        changed = true;
        let v = given
            .parse::<f64>()
            .ok()
            .filter(|v| v.is_finite())
            .ok_or_else(|| AppError::BadRequest(format!("{}: not a number", f.name)))?;
        set(&mut plan, f.slot, v / f.factor);
    }
    if !changed {
        return Ok(Some(plan));
    }
    if plan.entry_m != base.entry_m || plan.exit_m != base.exit_m {
        plan.incision_m.clear();
    }
    Ok(Some(plan.normalised()?))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn form(pairs: &[(&str, &str)]) -> HashMap<String, String> {
        pairs
            .iter()
            .map(|(k, v)| ((*k).to_owned(), (*v).to_owned()))
            .collect()
    }

    #[test]
    fn fields_as_shown_keep_the_plan_and_changed_ones_set_it() {
        let base = ExpertPlan::chest_wall().unwrap();
        // every field as the page shows it: the same plan, bit for bit
        let shown_form: HashMap<String, String> = fields()
            .map(|f| (f.name.to_owned(), shown(f, &base)))
            .collect();
        assert_eq!(shown(&POINTS[0].1[2], &base), "-3.031");
        assert_eq!(
            plan_from_form("", &shown_form, &base).unwrap(),
            Some(base.clone())
        );
        // nothing about the plan: none
        assert_eq!(
            plan_from_form(" ", &form(&[("name", "x")]), &base).unwrap(),
            None
        );
        // depth and force changed; the curved line kept (entry and exit unchanged)
        let mut f = shown_form.clone();
        f.insert("depth_mm".into(), "5".into());
        f.insert("force_limit_n".into(), "0.9".into());
        let p = plan_from_form("", &f, &base).unwrap().unwrap();
        assert_eq!((p.depth_m, p.force_limit_n), (0.005, 0.9));
        assert_eq!(p.incision_m, base.incision_m);
        // the exit moved: a straight line from entry to the new exit
        f.insert("exit_x_mm".into(), "40".into());
        let p = plan_from_form("", &f, &base).unwrap().unwrap();
        assert_eq!(p.exit_m[0], 0.04);
        assert_eq!(p.incision_m, vec![base.entry_m, p.exit_m]);
        // bad input: a message, no panic
        for (k, v) in [
            ("depth_mm", "abc"),
            ("depth_mm", "NaN"),
            ("depth_mm", "0"),
            ("tolerance_mm", "-1"),
        ] {
            let mut f = shown_form.clone();
            f.insert(k.into(), v.into());
            assert!(plan_from_form("", &f, &base).is_err(), "{k}={v}");
        }
        // the text wins over the fields
        let p = plan_from_form(
            r#"{"entry_m":[0,0,0],"exit_m":[0.05,0,0],"depth_m":0.004,"viewpoint_m":[0,0,0.1]}"#,
            &shown_form,
            &base,
        )
        .unwrap()
        .unwrap();
        assert_eq!(p.depth_m, 0.004);
    }
}
