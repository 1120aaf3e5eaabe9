//! The expert plan in the exercise forms: labelled fields for the main values of the plan's
//! kind ([`ExerciseKind::form_fields`]: for an incision its entry, exit, viewpoint, depth,
//! tolerance, corridor and force limit), or the whole plan as TOML or JSON (typed, or loaded
//! from a file by `static/plan.js`), and what every key of a plan means, on the page itself
//! (there is no reference page on plans).
//!
//! What the handlers accept: a non-empty `plan` text is the plan, as before; else the fields
//! present are applied over a base plan (the exercise's, or the built-in one for a new
//! exercise) by its kind ([`ExerciseKind::with_fields`]); a field left as shown keeps the
//! base's exact value.

use std::collections::HashMap;

use cutlab_scoring::exercise::FormField;
use cutlab_scoring::{ExerciseKind, ExercisePlan};
use maud::{Markup, html};

use crate::error::AppError;

/// Field `i` of `plan` as shown (up to 6 decimals, no trailing zeros).
fn shown(plan: &dyn ExerciseKind, i: usize) -> String {
    let f = &plan.form_fields()[i];
    let s = format!("{:.6}", plan.field(i) * f.factor);
    let s = s.trim_end_matches('0').trim_end_matches('.');
    if s == "-0" { "0" } else { s }.to_owned()
}

fn id(f: &FormField) -> String {
    format!("plan-{}", f.name)
}

/// The fields in runs: consecutive fields of one group (a point's x, y, z) together.
fn runs(fields: &[FormField]) -> Vec<(Option<&'static str>, Vec<usize>)> {
    let mut out: Vec<(Option<&'static str>, Vec<usize>)> = Vec::new();
    for (i, f) in fields.iter().enumerate() {
        match out.last_mut() {
            Some((g, run)) if f.group.is_some() && *g == f.group => run.push(i),
            _ => out.push((f.group, vec![i])),
        }
    }
    out
}

/// The labelled fields of `plan`'s kind, showing its values.
pub fn plan_fields(plan: &ExercisePlan) -> Markup {
    let kind = plan.kind_plan();
    let fields = kind.form_fields();
    html! {
        fieldset class="plan-fields" {
            legend { "Expert plan (" (plan.kind().as_str()) ")" }
            p class="muted" { "Positions in mm in the scene's frame (z up); see “The plan's fields” below." }
            @for (group, run) in runs(fields) {
                @if let Some(legend) = group {
                    fieldset class="point" {
                        legend { (legend) " (" (fields[run[0]].unit) ")" }
                        @for i in run {
                            label for=(id(&fields[i])) { (fields[i].label) } " "
                            input type="number" step="any" required size="8" id=(id(&fields[i])) name=(fields[i].name) value=(shown(kind, i)); " "
                        }
                    }
                } @else {
                    @for i in run {
                        p {
                            label for=(id(&fields[i])) { (fields[i].label) " (" (fields[i].unit) ")" } " "
                            input type="number" step="any" min="0" required size="8" id=(id(&fields[i])) name=(fields[i].name) value=(shown(kind, i));
                        }
                    }
                }
            }
            p class="muted" { (kind.form_note()) }
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

/// What every key of a plan of `plan`'s kind means (TOML / JSON keys, SI units).
pub fn plan_reference(plan: &ExercisePlan) -> Markup {
    html! {
        details class="plan-reference" {
            summary { "The plan's fields" }
            p { "A plan is TOML or JSON (JSON when it starts with “{”) with these keys; SI units (metres, newtons). Lateral distances are measured seen from above, along the normal." }
            table {
                thead { tr { th { "Key" } th { "Unit" } th { "Meaning" } } }
                tbody {
                    tr { td { code { "kind" } } td { "text" } td { "the kind of exercise: " (cutlab_scoring::Kind::ALL.map(|k| k.as_str()).join(", ")) " (default incision)" } }
                    @for k in plan.kind_plan().keys() { tr { td { code { (k.key) } } td { (k.unit) } td { (k.meaning) } } }
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
    base: &ExercisePlan,
) -> Result<Option<ExercisePlan>, AppError> {
    if !text.trim().is_empty() {
        return super::parse_plan(text).map(Some);
    }
    let kind = base.kind_plan();
    let fields = kind.form_fields();
    if !fields.iter().any(|f| form.contains_key(f.name)) {
        return Ok(None);
    }
    let mut changed = Vec::new();
    for (i, f) in fields.iter().enumerate() {
        let Some(given) = form.get(f.name).map(|v| v.trim()) else {
            continue;
        };
        if given == shown(kind, i) {
            continue; // as shown: the base's exact value
        }
        let v = given
            .parse::<f64>()
            .ok()
            .filter(|v| v.is_finite())
            .ok_or_else(|| AppError::BadRequest(format!("{}: not a number", f.name)))?;
        changed.push((i, v / f.factor));
    }
    if changed.is_empty() {
        return Ok(Some(base.clone()));
    }
    Ok(Some(kind.with_fields(&changed)?))
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
        let base = ExercisePlan::chest_wall().unwrap();
        let fields = base.kind_plan().form_fields();
        // every field as the page shows it: the same plan, bit for bit
        let shown_form: HashMap<String, String> = (0..fields.len())
            .map(|i| (fields[i].name.to_owned(), shown(base.kind_plan(), i)))
            .collect();
        assert_eq!(fields[2].name, "entry_z_mm");
        assert_eq!(shown(base.kind_plan(), 2), "-3.031");
        let incision = |p: Option<ExercisePlan>| p.unwrap().into_incision().unwrap();
        let base_incision = base.as_incision().unwrap();
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
        let p = incision(plan_from_form("", &f, &base).unwrap());
        assert_eq!((p.depth_m, p.force_limit_n), (0.005, 0.9));
        assert_eq!(p.incision_m, base_incision.incision_m);
        // the exit moved: a straight line from entry to the new exit
        f.insert("exit_x_mm".into(), "40".into());
        let p = incision(plan_from_form("", &f, &base).unwrap());
        assert_eq!(p.exit_m[0], 0.04);
        assert_eq!(p.incision_m, vec![base_incision.entry_m, p.exit_m]);
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
        let p = incision(
            plan_from_form(
                r#"{"entry_m":[0,0,0],"exit_m":[0.05,0,0],"depth_m":0.004,"viewpoint_m":[0,0,0.1]}"#,
                &shown_form,
                &base,
            )
            .unwrap(),
        );
        assert_eq!(p.depth_m, 0.004);
    }
}
