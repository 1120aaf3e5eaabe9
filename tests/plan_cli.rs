//! `cutlab plan field` (issue 62): candidate incisions on the thorax compared by their field,
//! and refused with the field named when they are not incisions.

use std::path::PathBuf;
use std::process::Command;

fn temp(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("cutlab-plan-{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("temp dir");
    dir.join(name)
}

/// Runs `plan field` on a candidate file holding `json`: (success, stdout, stderr).
fn plan(name: &str, json: &str, more: &[&str]) -> (bool, String, String) {
    let file = temp(&format!("{name}.json"));
    std::fs::write(&file, json).expect("candidate");
    let db = temp("plan.db");
    let mut args = vec![
        "--db",
        db.to_str().expect("utf-8"),
        "plan",
        "field",
        "--incision",
        file.to_str().expect("utf-8"),
    ];
    args.extend_from_slice(more);
    let out = Command::new(env!("CARGO_BIN_EXE_cutlab"))
        .args(&args)
        .output()
        .expect("cutlab runs");
    (
        out.status.success(),
        String::from_utf8_lossy(&out.stdout).into_owned(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

/// The field of a straight candidate from `x0` to `x1` mm at `y` mm on the thorax's skin.
fn field(name: &str, x0: f64, x1: f64, y: f64) -> serde_json::Value {
    field_with(name, x0, x1, y, &[])
}

/// [`field`] with more arguments to `plan field`.
fn field_with(name: &str, x0: f64, x1: f64, y: f64, more: &[&str]) -> serde_json::Value {
    let json = format!(
        r#"{{"incision_m": [[{}, {}, 0.0], [{}, {}, 0.0]], "depth_m": 0.045}}"#,
        x0 * 1e-3,
        y * 1e-3,
        x1 * 1e-3,
        y * 1e-3
    );
    let args = [&["--scene", "thorax", "--json"], more].concat();
    let (ok, out, err) = plan(name, &json, &args);
    assert!(ok, "{err}");
    serde_json::from_str(&out).expect("a report")
}

#[test]
fn candidates_are_compared_by_what_they_show_and_what_they_damage() {
    let area = |v: &serde_json::Value| v["target_visible_area_m2"].as_f64().expect("area");
    // through the 4th intercostal space (y -10 to 5 mm), 50 mm and 20 mm long
    let long = field("long", -20.0, 30.0, -2.5);
    let short = field("short", 0.0, 20.0, -2.5);
    assert!(area(&long) > 1e-5, "{long}");
    assert!(area(&short) < area(&long), "{short} {long}");
    assert_eq!(long["damaged"], serde_json::json!([]));
    assert!((long["incision_length_m"].as_f64().expect("length") - 0.05).abs() < 1e-9);
    assert!(
        long["approach_angle_deg"]
            .as_f64()
            .is_some_and(|a| a < 20.0)
    );
    // the same length over the 4th rib: the blade stops on the bone, nothing shows
    let rib = field("rib", -20.0, 30.0, 11.5);
    assert_eq!(area(&rib), 0.0);
    assert_eq!(rib["damaged"], serde_json::json!(["rib"]));
    // medially in the space, across the internal thoracic artery
    let medial = field("medial", -40.0, 0.0, -2.5);
    assert_eq!(
        medial["damaged"],
        serde_json::json!(["internal thoracic artery"])
    );
}

/// A retractor opens the slit an unretracted intercostal incision is: the wider it spreads,
/// the more shows, up to the ribs bounding the space; a longer incision retracted the same
/// shows more than a shorter one.
#[test]
fn a_retractor_opens_the_field_up_to_the_ribs() {
    let retracted = |v: &serde_json::Value, key: &str| v["retracted"][key].as_f64().expect(key);
    let narrow = field_with("r10", -20.0, 30.0, -2.5, &["--retract-mm", "10"]);
    let wide = field_with("r20", -20.0, 30.0, -2.5, &["--retract-mm", "20"]);
    let short = field_with("r20-short", 0.0, 20.0, -2.5, &["--retract-mm", "20"]);
    let area = |v: &serde_json::Value| retracted(v, "target_visible_area_m2");
    assert!(
        area(&narrow)
            > 3.0
                * narrow["target_visible_area_m2"]
                    .as_f64()
                    .expect("unretracted"),
        "{narrow}"
    );
    assert!(area(&wide) > area(&narrow), "{wide} {narrow}");
    assert!(area(&short) < area(&wide), "{short} {wide}");
    assert_eq!(wide["retractor_width_m"].as_f64(), Some(0.02));
    // the instrument that passes is bounded by the 15 mm space, less the clearance to the ribs
    let width = retracted(&wide, "working_width_m");
    assert!(width > 0.005 && width < 0.015, "{width}");
    let (ok, _, err) = plan(
        "r-bad",
        r#"{"incision_m": [[0, 0, 0], [0.02, 0, 0]], "depth_m": 0.045}"#,
        &["--scene", "thorax", "--retract-mm", "NaN"],
    );
    assert!(!ok && err.contains("--retract-mm"), "{err}");
}

/// A blade that goes deeper than the wall behind its opening touches what lies there: the
/// lung beside the heart when the candidate runs laterally, the heart itself in the middle;
/// each is named among the damage.
#[test]
fn a_blade_too_deep_touches_the_lung_or_the_heart() {
    let deep = |name: &str, x0: f64, x1: f64, depth_m: f64| {
        let json = format!(
            r#"{{"incision_m": [[{}, -0.0025, 0.0], [{}, -0.0025, 0.0]], "depth_m": {depth_m}}}"#,
            x0 * 1e-3,
            x1 * 1e-3
        );
        let (ok, out, err) = plan(name, &json, &["--scene", "thorax", "--json"]);
        assert!(ok, "{err}");
        serde_json::from_str::<serde_json::Value>(&out).expect("a report")["damaged"].clone()
    };
    assert_eq!(
        deep("lateral", 20.0, 48.0, 0.052),
        serde_json::json!(["lung"])
    );
    assert_eq!(
        deep("middle", -20.0, 0.0, 0.056),
        serde_json::json!(["heart"])
    );
    assert_eq!(deep("enough", 20.0, 48.0, 0.045), serde_json::json!([]));
}

/// The pixels of the target's colour in a PNG picture (red over green above 3: no muscle of
/// the wall is that red).
fn target_pixels(path: &std::path::Path) -> usize {
    let bytes = std::fs::read(path).expect("the picture is written");
    let mut reader = png::Decoder::new(std::io::Cursor::new(bytes))
        .read_info()
        .expect("a PNG");
    let mut buf = vec![0; reader.output_buffer_size().expect("size")];
    let info = reader.next_frame(&mut buf).expect("a frame");
    assert_eq!(
        (info.width, info.height, info.color_type),
        (320, 320, png::ColorType::Rgb)
    );
    buf[..info.buffer_size()]
        .chunks(3)
        .filter(|p| p[0] > 40 && u32::from(p[0]) > 3 * u32::from(p[1]))
        .count()
}

/// `--picture`: the heart shows through the opened wound, more once retracted, and not at all
/// through an incision that leaves the pleura closed.
#[test]
fn the_picture_shows_the_heart_only_through_the_opened_wall() {
    let line = "[[-0.02, -0.0025, 0.0], [0.03, -0.0025, 0.0]]";
    let mut seen = Vec::new();
    for (name, depth, more) in [
        ("pic-open", 0.045, vec![]),
        ("pic-retracted", 0.045, vec!["--retract-mm", "20"]),
        ("pic-shallow", 0.01, vec!["--retract-mm", "20"]),
    ] {
        let png = temp(&format!("{name}.png"));
        let args = [
            &[
                "--scene",
                "thorax",
                "--picture",
                png.to_str().expect("utf-8"),
            ],
            &more[..],
        ]
        .concat();
        let json = format!(r#"{{"incision_m": {line}, "depth_m": {depth}}}"#);
        let (ok, _, err) = plan(name, &json, &args);
        assert!(ok, "{err}");
        seen.push(target_pixels(&png));
    }
    // about 3 pixels a millimetre at the skin: the opened slit shows tens of mm^2, retracted
    // hundreds
    assert!(seen[0] > 200, "{seen:?}");
    assert!(seen[1] > 5 * seen[0], "{seen:?}");
    assert_eq!(seen[2], 0, "{seen:?}");
}

#[test]
fn what_is_not_an_incision_is_refused_naming_the_field() {
    let line = r#"[[0.0, -0.0025, 0.0], [0.02, -0.0025, 0.0]]"#;
    for (name, json, says) in [
        (
            "one-point",
            r#"{"incision_m": [[0, 0, 0]], "depth_m": 0.01}"#.to_owned(),
            "incision_m",
        ),
        (
            "shallow",
            format!(r#"{{"incision_m": {line}, "depth_m": 0}}"#),
            "depth_m",
        ),
        (
            "off",
            r#"{"incision_m": [[0, 0, 0.05], [0.02, 0, 0.05]], "depth_m": 0.01}"#.to_owned(),
            "off the tissue",
        ),
        (
            "unknown",
            format!(r#"{{"incision_m": {line}, "depth_m": 0.01, "retract": 1}}"#),
            "unknown field",
        ),
        (
            "huge",
            r#"{"incision_m": [[0, 0, 0], [1e400, 0, 0]], "depth_m": 0.01}"#.to_owned(),
            "candidate",
        ),
    ] {
        let (ok, _, err) = plan(name, &json, &["--scene", "thorax"]);
        assert!(!ok && err.contains(says), "{name}: {err}");
    }
    let json = format!(r#"{{"incision_m": {line}, "depth_m": 0.01}}"#);
    let (ok, _, err) = plan("no-exercise", &json, &["--exercise", "no-such-exercise"]);
    assert!(!ok && err.contains("no-such-exercise"), "{err}");
    let (ok, _, err) = plan("no-scene", &json, &[]);
    assert!(!ok && err.contains("--scene"), "{err}");
}
