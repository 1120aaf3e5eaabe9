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
    let plan = concat!(env!("CARGO_MANIFEST_DIR"), "/assessor/examples/plan.toml");
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
