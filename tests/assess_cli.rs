//! End-to-end: the assessment commands of the real `cutlab` binary.

use std::io::Write;
use std::path::PathBuf;
use std::process::{Command, Stdio};

fn cutlab(args: &[&str], stdin: Option<&str>) -> (bool, String, String) {
    let mut child = Command::new(env!("CARGO_BIN_EXE_cutlab"))
        .args(args)
        .env_remove("CUTLAB_DB")
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("cutlab runs");
    if let Some(text) = stdin {
        child
            .stdin
            .take()
            .expect("stdin")
            .write_all(text.as_bytes())
            .expect("write stdin");
    }
    drop(child.stdin.take());
    let out = child.wait_with_output().expect("cutlab ends");
    (
        out.status.success(),
        String::from_utf8_lossy(&out.stdout).into_owned(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

fn temp(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("cutlab-assess-cli-{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("temp dir");
    dir.join(name)
}

/// A minimum-jerk reach of 100 mm along x in 1 s, rest 0.5 s, reach back, at `hz`.
fn reach_csv(hz: f64) -> String {
    let mj = |tau: f64| {
        let t = tau.clamp(0.0, 1.0);
        0.1 * (10.0 * t.powi(3) - 15.0 * t.powi(4) + 6.0 * t.powi(5))
    };
    let mut s = String::from("t_s,x_m,y_m,z_m,qw,qx,qy,qz\n");
    let n = (2.5 * hz) as usize;
    for i in 0..=n {
        let t = i as f64 / hz;
        let x = mj(t) - mj(t - 1.5);
        s += &format!("{t},{x},0.0,0.02,1,0,0,0\n");
    }
    s
}

#[test]
fn motion_metrics_of_a_good_csv_at_two_rates() {
    let mut lengths = Vec::new();
    for hz in [60.0, 1000.0] {
        let path = temp(&format!("reach-{hz}.csv"));
        std::fs::write(&path, reach_csv(hz)).expect("write csv");
        let (ok, out, err) = cutlab(
            &["motion-metrics", path.to_str().expect("utf8"), "--json"],
            None,
        );
        assert!(ok, "{err}");
        let v: serde_json::Value = serde_json::from_str(&out).expect("json");
        assert_eq!(v["movements"], 2, "{out}");
        // the task time: the two reaches less their slow starts and ends, within the 2.5 s
        let time = v["time_s"].as_f64().expect("time");
        assert!(time > 2.1 && time < 2.5, "{time}");
        lengths.push(v["path_length_m"].as_f64().expect("length"));
        assert!(v["ldlj"].as_f64().is_some() && v["sparc"].as_f64().is_some());
        let (ok, table, err) = cutlab(&["motion-metrics", path.to_str().expect("utf8")], None);
        assert!(ok, "{err}");
        assert!(
            table.contains("path length") && table.contains("SPARC"),
            "{table}"
        );
    }
    for l in &lengths {
        assert!(
            (l - 0.2).abs() < 0.002,
            "about 200 mm at any rate: {lengths:?}"
        );
    }
}

#[test]
fn motion_metrics_names_the_line_of_a_malformed_row() {
    let path = temp("bad.csv");
    std::fs::write(
        &path,
        "t_s,x_m,y_m,z_m,qw,qx,qy,qz\n0,0,0,0,1,0,0,0\n0.01,0,0,0,1,0,0,0\n0.02,0,oops,0,1,0,0,0\n",
    )
    .expect("write");
    let (ok, _, err) = cutlab(&["motion-metrics", path.to_str().expect("utf8")], None);
    assert!(!ok);
    assert!(
        err.contains("bad.csv:4: y_m \"oops\" is not a number"),
        "{err}"
    );
    assert!(!err.contains("panicked"), "{err}");
    std::fs::write(&path, "0,0,0,0,1,0,0,0\n0.01,0,0,0,1,0\n").expect("write");
    let (ok, _, err) = cutlab(&["motion-metrics", path.to_str().expect("utf8")], None);
    assert!(!ok);
    assert!(err.contains("bad.csv:2: expected 8 fields"), "{err}");
}

#[test]
fn users_cohorts_exercises_and_xapi_on_a_fresh_database() {
    let db = temp("cli.db");
    std::fs::remove_file(&db).ok();
    let db = db.to_str().expect("utf8");
    let (ok, out, err) = cutlab(
        &[
            "user",
            "add",
            "--name",
            "alice",
            "--role",
            "trainee",
            "--password-stdin",
            "--db",
            db,
        ],
        Some("pa55word\n"),
    );
    assert!(ok, "{err}");
    assert!(out.contains("added trainee alice"), "{out}");
    let (ok, _, err) = cutlab(
        &[
            "--db", db, "user", "add", "--name", "alice", "--role", "trainee",
        ],
        None,
    );
    assert!(!ok && err.contains("exists"), "{err}");
    let (ok, _, err) = cutlab(
        &[
            "--db", db, "user", "add", "--name", "bob", "--role", "surgeon",
        ],
        None,
    );
    assert!(!ok && err.contains("unknown role"), "{err}");
    let (ok, _, err) = cutlab(
        &[
            "--db",
            db,
            "user",
            "add",
            "--name",
            "dr-k",
            "--role",
            "instructor",
            "--password",
            "x",
        ],
        None,
    );
    assert!(ok, "{err}");
    let (ok, _, err) = cutlab(
        &[
            "--db",
            db,
            "cohort",
            "add",
            "--name",
            "spring",
            "--instructor",
            "dr-k",
        ],
        None,
    );
    assert!(ok, "{err}");
    let (ok, _, err) = cutlab(
        &[
            "--db", db, "cohort", "join", "--cohort", "spring", "--user", "alice",
        ],
        None,
    );
    assert!(ok, "{err}");
    let (ok, out, _) = cutlab(&["--db", db, "cohort", "list"], None);
    assert!(ok && out.contains("spring: alice"), "{out}");
    let plan = concat!(env!("CARGO_MANIFEST_DIR"), "/scoring/examples/plan.toml");
    let (ok, out, err) = cutlab(
        &[
            "--db",
            db,
            "exercise",
            "add",
            "--name",
            "copy",
            "--scene",
            "chest-wall",
            "--plan",
            plan,
        ],
        None,
    );
    assert!(ok, "{err}");
    assert!(out.contains("added exercise copy"), "{out}");
    let (ok, out, _) = cutlab(&["--db", db, "exercise", "list"], None);
    assert!(
        ok && out.contains("chest-wall-incision") && out.contains("copy"),
        "the built-in is always there: {out}"
    );
    // the exercise and its plan, for a planning tool
    let (ok, out, err) = cutlab(
        &[
            "--db",
            db,
            "exercise",
            "show",
            "chest-wall-incision",
            "--json",
        ],
        None,
    );
    assert!(ok, "{err}");
    let v: serde_json::Value = serde_json::from_str(&out).expect("json");
    assert_eq!(v["scene"], "chest-wall", "{v}");
    assert!(
        v["plan"]["depth_m"].as_f64().is_some_and(|d| d > 0.0),
        "{v}"
    );
    assert_eq!(
        v["plan"]["viewpoint_m"].as_array().map(Vec::len),
        Some(3),
        "{v}"
    );
    let (ok, out, err) = cutlab(&["--db", db, "exercise", "show", "copy"], None);
    assert!(
        ok && out.contains("scene chest-wall") && out.contains("depth_m"),
        "{out}{err}"
    );
    let (ok, _, err) = cutlab(&["--db", db, "exercise", "show", "nobody"], None);
    assert!(
        !ok && err.contains("\"nobody\"") && err.contains("not found"),
        "{err}"
    );
    let bad_plan = temp("bad-plan.toml");
    std::fs::write(
        &bad_plan,
        "entry_m = [0, 0, 0]\nexit_m = [0, 0, 0]\ndepth_m = 0.008\nviewpoint_m = [0, 0, 1]\n",
    )
    .expect("write");
    let (ok, _, err) = cutlab(
        &[
            "--db",
            db,
            "exercise",
            "add",
            "--name",
            "bad",
            "--scene",
            "x",
            "--plan",
            bad_plan.to_str().expect("utf8"),
        ],
        None,
    );
    assert!(!ok && err.contains("shorter than 1 mm"), "{err}");
    let (ok, out, err) = cutlab(&["--db", db, "export", "xapi", "--trainee", "alice"], None);
    assert!(ok, "{err}");
    let v: serde_json::Value = serde_json::from_str(&out).expect("json");
    assert_eq!(v.as_array().map(Vec::len), Some(0), "no attempts yet");
    let (ok, _, err) = cutlab(&["--db", db, "export", "xapi", "--trainee", "nobody"], None);
    assert!(!ok && err.contains("not found"), "{err}");
    for suffix in ["", "-wal", "-shm"] {
        std::fs::remove_file(format!("{db}{suffix}")).ok();
    }
}

/// A JIGSAWS-layout folder: three experts and three novices, two trials each, two tools; an
/// expert's trial is a short smooth reach and rated high, a novice's a slow one with pauses
/// and a tremor, rated low.
fn kinematics_fixture(name: &str) -> PathBuf {
    let dir = temp(name);
    let _ = std::fs::remove_dir_all(&dir);
    let mut ratings = String::from("trial,subject,experience,rating\n");
    for (s, subject) in ["A", "B", "C", "D", "E", "F"].iter().enumerate() {
        let expert = s < 3;
        for k in 0..2 {
            let trial = format!("Task_{subject}00{}", k + 1);
            let folder = dir.join("trials").join(&trial);
            std::fs::create_dir_all(&folder).expect("trial folder");
            let (duration, tremor) = if expert {
                (2.0 + 0.1 * s as f64, 0.0)
            } else {
                (6.0 + 0.5 * s as f64, 0.002)
            };
            for (tool, sign) in [("left", 1.0), ("right", -1.0)] {
                let mut csv = String::from("t_s,x_m,y_m,z_m,qw,qx,qy,qz\n");
                let n = (duration * 30.0) as usize;
                for i in 0..=n {
                    let t = i as f64 / 30.0;
                    let u = t / duration;
                    // a minimum-jerk reach, a novice's stalling half way
                    let u = if expert {
                        u
                    } else {
                        u.min(0.5) + (u - 0.7).max(0.0) * (0.5 / 0.3)
                    };
                    let x = 0.08 * (10.0 * u.powi(3) - 15.0 * u.powi(4) + 6.0 * u.powi(5));
                    let wobble = tremor * (2.0 * std::f64::consts::PI * 9.0 * t).sin();
                    csv += &format!("{t},{},{wobble},0.01,1,0,0,0\n", sign * x);
                }
                std::fs::write(folder.join(format!("{tool}.csv")), csv).expect("write poses");
            }
            let level = if expert { "expert" } else { "novice" };
            let rating = if expert { 28 - s - k } else { 16 - s - k };
            ratings += &format!("{trial},{subject},{level},{rating}\n");
        }
    }
    std::fs::write(dir.join("ratings.csv"), ratings).expect("write ratings");
    dir
}

#[test]
fn import_kinematics_reports_groups_and_the_ratings_agreement() {
    let dir = kinematics_fixture("kinematics-ok");
    let (ok, out, err) = cutlab(
        &["import", "kinematics", dir.to_str().unwrap(), "--json"],
        None,
    );
    assert!(ok, "{err}");
    let r: serde_json::Value = serde_json::from_str(&out).expect("json");
    assert_eq!(
        (r["higher"].as_str(), r["lower"].as_str()),
        (Some("expert"), Some("novice"))
    );
    assert_eq!(r["groups"].as_array().unwrap().len(), 2);
    let measure = |key: &str| {
        r["metrics"]
            .as_array()
            .unwrap()
            .iter()
            .find(|m| m["key"] == key)
            .unwrap_or_else(|| panic!("{key}"))
            .clone()
    };
    for key in ["time_s@left", "time_s@right", "idle_time_s@left"] {
        let m = measure(key);
        assert_eq!(m["finding"], "discriminates", "{m}");
        assert_eq!(m["comparison"]["auc"], 1.0, "{m}");
    }
    assert_eq!(r["score"]["label"], "Rating");
    let rho = r["concurrent"]
        .as_array()
        .unwrap()
        .iter()
        .find(|c| c["key"] == "time_s@left")
        .unwrap()["rho"]
        .as_f64()
        .unwrap();
    assert!(rho < -0.7, "task time against the rating: {rho}");
    // leave one subject out: the task time predicts the unseen subjects' ratings
    let (ok, out, err) = cutlab(
        &[
            "import",
            "kinematics",
            dir.to_str().unwrap(),
            "--predict",
            "--json",
        ],
        None,
    );
    assert!(ok, "{err}");
    let p: serde_json::Value = serde_json::from_str(&out).expect("json");
    let time = p
        .as_array()
        .unwrap()
        .iter()
        .find(|f| f["family"] == "task time")
        .unwrap();
    assert_eq!(
        (time["subjects"].as_u64(), time["n"].as_u64()),
        (Some(6), Some(12))
    );
    // (a subject's two trials take the same time but are rated 1 apart: ties, so not 1)
    assert!(time["rho"].as_f64().unwrap() > 0.6, "{time}");
    // the text report says the same for people
    let (ok, text, err) = cutlab(&["import", "kinematics", dir.to_str().unwrap()], None);
    assert!(ok, "{err}");
    assert!(
        text.contains("Construct validity: expert against novice")
            && text.contains("Task time · left (s)"),
        "{text}"
    );
    assert!(
        text.contains("Concurrent validity") && text.contains("Pass mark (contrasting groups"),
        "{text}"
    );
}

#[test]
fn import_kinematics_refuses_bad_input_clearly() {
    let dir = kinematics_fixture("kinematics-bad");
    let run = || cutlab(&["import", "kinematics", dir.to_str().unwrap()], None);
    let ratings = std::fs::read_to_string(dir.join("ratings.csv")).unwrap();
    // a rating for a trial that is not there
    std::fs::write(
        dir.join("ratings.csv"),
        format!("{ratings}Task_Z001,Z,novice,8\n"),
    )
    .unwrap();
    let (ok, _, err) = run();
    assert!(
        !ok && err.contains("Task_Z001") && err.contains("cannot be read"),
        "{err}"
    );
    // a trial nobody rated
    std::fs::write(
        dir.join("ratings.csv"),
        ratings
            .lines()
            .filter(|l| !l.starts_with("Task_F002"))
            .collect::<Vec<_>>()
            .join("\n"),
    )
    .unwrap();
    let (ok, _, err) = run();
    assert!(
        !ok && err.contains("Task_F002") && err.contains("no row in ratings.csv"),
        "{err}"
    );
    std::fs::write(dir.join("ratings.csv"), &ratings).unwrap();
    // NaN in a pose, then a time that does not increase: the file and line named
    let poses = dir.join("trials/Task_A001/left.csv");
    let good = std::fs::read_to_string(&poses).unwrap();
    let mut lines: Vec<String> = good.lines().map(str::to_owned).collect();
    lines[3] = "0.1,NaN,0,0.01,1,0,0,0".into();
    std::fs::write(&poses, lines.join("\n")).unwrap();
    let (ok, _, err) = run();
    assert!(
        !ok && err.contains("left.csv:4: x_m is not finite"),
        "{err}"
    );
    let mut lines: Vec<String> = good.lines().map(str::to_owned).collect();
    lines[3] = lines[2].clone();
    std::fs::write(&poses, lines.join("\n")).unwrap();
    let (ok, _, err) = run();
    assert!(
        !ok && err.contains("left.csv:4: time") && err.contains("does not increase"),
        "{err}"
    );
    std::fs::write(&poses, &good).unwrap();
    // one novice trial only: the report says what it cannot compute
    let one_novice: String = ratings
        .lines()
        .filter(|l| !l.contains(",novice,") || l.starts_with("Task_D001"))
        .map(|l| format!("{l}\n"))
        .collect();
    for t in [
        "Task_D002",
        "Task_E001",
        "Task_E002",
        "Task_F001",
        "Task_F002",
    ] {
        std::fs::remove_dir_all(dir.join("trials").join(t)).unwrap();
    }
    std::fs::write(dir.join("ratings.csv"), one_novice).unwrap();
    let (ok, text, err) = run();
    assert!(ok, "{err}");
    assert!(
        text.contains("the novice group has 1 value: needs at least 2"),
        "{text}"
    );
    assert!(
        text.contains("Pass mark (contrasting groups): not computed"),
        "{text}"
    );
}

#[test]
fn evidence_of_an_exercise_and_experience_levels_from_the_command_line() {
    let db = temp("evidence.db");
    let _ = std::fs::remove_file(&db);
    let db = db.to_str().unwrap();
    let (ok, out, err) = cutlab(
        &[
            "--db",
            db,
            "user",
            "add",
            "--name",
            "kim",
            "--role",
            "instructor",
            "--experience",
            "expert",
        ],
        None,
    );
    assert!(ok, "{err}");
    assert!(out.contains("added instructor kim"));
    let (ok, _, err) = cutlab(
        &[
            "--db", db, "user", "add", "--name", "al", "--role", "trainee",
        ],
        None,
    );
    assert!(ok, "{err}");
    let (ok, out, _) = cutlab(
        &[
            "--db",
            db,
            "user",
            "experience",
            "--name",
            "al",
            "--level",
            "novice",
        ],
        None,
    );
    assert!(ok && out.contains("al is novice"), "{out}");
    let (ok, out, _) = cutlab(&["--db", db, "user", "list"], None);
    assert!(
        ok && out.contains("expert") && out.contains("novice"),
        "{out}"
    );
    let (ok, _, err) = cutlab(
        &[
            "--db",
            db,
            "user",
            "experience",
            "--name",
            "al",
            "--level",
            "surgeon",
        ],
        None,
    );
    assert!(!ok && err.contains("unknown experience level"), "{err}");
    // no attempts yet: the report says what it cannot compute; there is no pass mark to adopt
    let (ok, out, err) = cutlab(
        &["--db", db, "evidence", "--exercise", "chest-wall-incision"],
        None,
    );
    assert!(ok, "{err}");
    assert!(
        out.contains("not computed: needs attempts by people of two experience levels"),
        "{out}"
    );
    let (ok, _, err) = cutlab(
        &[
            "--db",
            db,
            "evidence",
            "--exercise",
            "chest-wall-incision",
            "--adopt",
            "--by",
            "kim",
        ],
        None,
    );
    assert!(!ok && err.contains("no pass mark to adopt"), "{err}");
    let (ok, _, err) = cutlab(
        &[
            "--db",
            db,
            "evidence",
            "--exercise",
            "chest-wall-incision",
            "--adopt",
            "--by",
            "al",
        ],
        None,
    );
    assert!(
        !ok && err.contains("only an instructor or an administrator"),
        "{err}"
    );
    let (ok, _, err) = cutlab(&["--db", db, "evidence", "--exercise", "nope"], None);
    assert!(!ok && err.contains("nope"), "{err}");
}
