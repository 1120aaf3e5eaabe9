//! End-to-end: the real `cutlab` binary.

use std::process::Command;

fn cutlab(args: &[&str]) -> (bool, String, String) {
    let out = Command::new(env!("CARGO_BIN_EXE_cutlab"))
        .args(args)
        .output()
        .expect("cutlab runs");
    (
        out.status.success(),
        String::from_utf8_lossy(&out.stdout).into_owned(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

#[test]
fn scene_info_json_of_the_default_scene() {
    let (ok, out, err) = cutlab(&["scene", "info", "chest-wall", "--json"]);
    assert!(ok, "{err}");
    let v: serde_json::Value = serde_json::from_str(&out).expect("json");
    assert!(v["tets"].as_u64().expect("tets") >= 10_000);
    assert_eq!(v["valid"], true);
    assert!(v["quality"]["min_dihedral_deg"].as_f64().expect("angle") > 30.0);
}

#[test]
fn scene_info_reads_bare_mesh_files() {
    let path = concat!(env!("CARGO_MANIFEST_DIR"), "/data/sofa/liver.msh");
    let (ok, out, err) = cutlab(&["scene", "info", path, "--json"]);
    assert!(ok, "{err}");
    let v: serde_json::Value = serde_json::from_str(&out).expect("json");
    assert_eq!(v["tets"], 596);
    assert_eq!(v["vertices"], 181);
    assert_eq!(v["notes"], serde_json::json!([]));
    // a TetGen pair with a vertex no tetrahedron uses: loaded without it, and said so
    let dir = std::env::temp_dir().join(format!("cutlab-cli-notes-{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("dir");
    std::fs::write(
        dir.join("t.node"),
        "5 3 0 0\n0 0 0 0\n1 1 0 0\n2 0 1 0\n3 0 0 1\n4 9 9 9\n",
    )
    .expect("node");
    std::fs::write(dir.join("t.ele"), "1 4 0\n0 0 1 2 3\n").expect("ele");
    let node = dir.join("t.node");
    let (ok, out, err) = cutlab(&["scene", "info", node.to_str().expect("utf8")]);
    let _ = std::fs::remove_dir_all(&dir);
    assert!(ok, "{err}");
    assert!(out.contains("vertices   4"), "{out}");
    assert!(
        out.contains("note") && out.contains("dropped 1 vertices no tetrahedron uses"),
        "{out}"
    );
}

#[test]
fn bad_scene_arguments_give_a_clear_error() {
    let (ok, _, err) = cutlab(&["scene", "info", "no-such-scene"]);
    assert!(!ok);
    assert!(err.contains("unknown scene \"no-such-scene\""), "{err}");
    assert!(!err.contains("panicked"), "{err}");
}

#[test]
fn demo_cuts_the_chest_wall_and_writes_the_result() {
    let dir = std::env::temp_dir().join(format!("cutlab-demo-{}", std::process::id()));
    let (ok, out, err) = cutlab(&[
        "demo",
        "--min-tets",
        "3000",
        "--out",
        dir.to_str().expect("utf8"),
    ]);
    assert!(ok, "{err}");
    assert!(out.contains("widest gap"), "{out}");
    let gap_mm: f64 = out
        .lines()
        .find_map(|l| l.trim().strip_prefix("widest gap "))
        .and_then(|l| l.trim_end_matches(" mm").parse().ok())
        .expect("gap figure");
    assert!(gap_mm > 0.5, "the wound opens under tension: {gap_mm} mm");
    let mesh = cutlab_sim::io::read_mesh(&dir.join("final.vtu")).expect("final.vtu reads back");
    assert!(mesh.tet_count() > 1500);
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn session_runs_a_synthetic_trainee_on_the_virtual_clock_and_writes_the_result() {
    let dir = std::env::temp_dir().join(format!("cutlab-session-{}", std::process::id()));
    let args = [
        "session",
        "--scene",
        "chest-wall",
        "--min-tets",
        "1500",
        "--device",
        "expert",
        "--clock",
        "virtual",
        "--duration",
        "2.5",
        "--seed",
        "3",
        "--out",
        dir.to_str().expect("utf8"),
    ];
    let (ok, out, err) = cutlab(&args);
    assert!(ok, "{err}");
    assert!(out.contains("ticks 2500, sim steps 2500"), "{out}");
    assert!(out.contains("non-finite values 0"), "{out}");
    let summary: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("summary.json")).expect("summary"))
            .expect("json");
    let max_force = summary["max_force_newtons"].as_f64().expect("max force");
    assert!(max_force > 0.1 && max_force <= 3.3, "{max_force}");
    // `--localise auto`, the default: no measurement of the chest wall near 1.5k tets
    assert_eq!(summary["localised"], false);
    let why = summary["localisation"].as_str().unwrap_or_default();
    assert!(why.starts_with("auto: not measured on chest-wall"), "{why}");
    assert!(
        out.contains("localisation: off (auto: not measured"),
        "{out}"
    );
    let mesh = cutlab_sim::io::read_mesh(&dir.join("final.vtu")).expect("final.vtu reads back");
    assert!(mesh.tet_count() >= 1500);
    let steps = std::fs::read_to_string(dir.join("steps.csv")).expect("steps.csv");
    assert_eq!(steps.lines().count(), 2501);
    assert_eq!(
        steps.lines().nth(2500),
        Some("2499,2499"),
        "virtual clock: step n consumed tick n"
    );
    // the same seed gives the same session, bit for bit
    let (ok, _, err) = cutlab(&args);
    assert!(ok, "{err}");
    let again: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("summary.json")).expect("summary"))
            .expect("json");
    assert_eq!(summary["state_hash"], again["state_hash"]);
    assert_eq!(summary["force_hash"], again["force_hash"]);
    // a plain `--localise` asks for it
    let (ok, _, err) = cutlab(&[&args[..], &["--localise"]].concat());
    assert!(ok, "{err}");
    let localised: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("summary.json")).expect("summary"))
            .expect("json");
    assert_eq!(localised["localised"], true);
    assert_eq!(localised["localisation"], "--localise on");
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn bad_session_arguments_give_a_clear_error() {
    let cases: [(&[&str], &str); 10] = [
        (
            &["session", "--scene", "no-such-scene", "--duration", "1"],
            "unknown scene \"no-such-scene\"",
        ),
        (
            &["session", "--device", "surgeon"],
            "unknown device \"surgeon\"",
        ),
        (
            &[
                "session",
                "--device",
                "csv:/no/such/file.csv",
                "--min-tets",
                "500",
                "--duration",
                "0.1",
            ],
            "/no/such/file.csv",
        ),
        (&["session", "--device", "igtl:99999"], "port number"),
        (&["session", "--clock", "sundial"], "unknown clock"),
        (
            &["session", "--duration=-1"],
            "duration must be between 0 and 86400",
        ),
        (
            &["session", "--time-step-ms", "20", "--min-tets", "500"],
            "outside 0.1-10 ms",
        ),
        (
            &["session", "--time-step-ms", "NaN", "--min-tets", "500"],
            "not `NaN`",
        ),
        (
            &["session", "--time-step-ms", "fast", "--min-tets", "500"],
            "`auto`, `scene` or milliseconds",
        ),
        (
            &["session", "--time-step-ms", "2.5", "--min-tets", "500"],
            "whole number of servo periods",
        ),
    ];
    for (args, expected) in cases {
        let (ok, _, err) = cutlab(args);
        assert!(!ok, "{args:?}");
        assert!(err.contains(expected), "{args:?}: {err}");
        assert!(!err.contains("panicked"), "{err}");
    }
}

#[test]
fn a_station_absence_out_of_range_is_refused() {
    for args in [
        &["serve", "--absence-s", "0"][..],
        &["serve", "--absence-s", "NaN"],
        &[
            "station",
            "--trainee",
            "ana",
            "--absence-s",
            "9000",
            "--no-browser",
        ],
    ] {
        let (ok, _, err) = cutlab(args);
        assert!(!ok, "{args:?}");
        assert!(
            err.contains("--absence-s must be between 1 and 3600"),
            "{args:?}: {err}"
        );
    }
}

#[test]
fn session_reports_a_port_in_use() {
    let listener = std::net::TcpListener::bind("0.0.0.0:0").expect("bind");
    let port = listener.local_addr().expect("addr").port().to_string();
    let device = format!("igtl:{port}");
    let (ok, _, err) = cutlab(&[
        "session",
        "--scene",
        "no-such-scene",
        "--device",
        &device,
        "--duration",
        "0.1",
        "--out",
        "/tmp/cutlab-port-test",
    ]);
    assert!(!ok);
    assert!(
        err.contains(&format!("cannot listen on port {port}")),
        "{err}"
    );
}

#[test]
fn session_plays_a_csv_trajectory() {
    let dir = std::env::temp_dir().join(format!("cutlab-session-csv-{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("dir");
    let csv = dir.join("stroke.csv");
    // down onto the top of the chest wall (z = 0 at x = 0), press 4 mm in, slide 10 mm
    std::fs::write(
        &csv,
        "# a short stroke\nt_s, x_m, y_m, z_m, qw, qx, qy, qz, button\n0.0, 0, 0, 0.02, 1, 0, 0, 0, 0\n0.5, 0, 0, -0.004, 1, 0, 0, 0, 1\n1.0, 0.01, 0, -0.004, 1, 0, 0, 0, 1\n",
    )
    .expect("csv");
    let device = format!("csv:{}", csv.display());
    let out = dir.join("out");
    let (ok, stdout, err) = cutlab(&[
        "session",
        "--scene",
        "chest-wall",
        "--min-tets",
        "1500",
        "--device",
        &device,
        "--duration",
        "1.2",
        "--out",
        out.to_str().expect("utf8"),
    ]);
    assert!(ok, "{err}");
    assert!(stdout.contains("ticks 1200, sim steps 1200"), "{stdout}");
    let summary: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("summary.json")).expect("summary"))
            .expect("json");
    assert!(
        summary["max_force_newtons"].as_f64().expect("force") > 0.05,
        "the stroke pressed on the wall: {summary}"
    );
    // a malformed trajectory is a clear error
    std::fs::write(
        &csv,
        "t_s, x_m, y_m, z_m, qw, qx, qy, qz, button\n0.0, 0, 0, oops, 1, 0, 0, 0, 0\n",
    )
    .expect("csv");
    let (ok, _, err) = cutlab(&["session", "--device", &device, "--duration", "1"]);
    assert!(!ok);
    assert!(
        err.contains("stroke.csv:2: column 4 (z_m): `oops` is not a number"),
        "{err}"
    );
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn a_session_recording_is_inspected_replayed_and_recovered_from_the_command_line() {
    let dir = std::env::temp_dir().join(format!("cutlab-recording-{}", std::process::id()));
    let d = dir.to_str().expect("utf8");
    let (ok, _, err) = cutlab(&[
        "session",
        "--min-tets",
        "3000",
        "--duration",
        "3",
        "--seed",
        "5",
        "--out",
        d,
        "--rrd",
    ]);
    assert!(ok, "{err}");
    let mcap = dir.join("session.mcap");
    let m = mcap.to_str().expect("utf8");
    assert!(
        dir.join("session.rrd")
            .metadata()
            .expect("session.rrd")
            .len()
            > 1000
    );

    let (ok, out, err) = cutlab(&["recording", "info", m, "--json"]);
    assert!(ok, "{err}");
    let v: serde_json::Value = serde_json::from_str(&out).expect("json");
    assert_eq!(v["complete"], true);
    let pose = v["channels"]
        .as_array()
        .expect("channels")
        .iter()
        .find(|c| c["topic"] == "/tool/pose")
        .expect("pose channel")
        .clone();
    assert_eq!(
        (pose["messages"].as_u64(), pose["schema"].as_str()),
        (Some(3000), Some("foxglove.PoseInFrame"))
    );
    assert_eq!(v["session"]["seed"], 5);

    let (ok, out, err) = cutlab(&["replay", m, "--json"]);
    assert!(ok, "{err}");
    let r: serde_json::Value = serde_json::from_str(&out).expect("json");
    assert_eq!(
        (
            r["verified"].as_bool(),
            r["keyframes_checked"].as_u64(),
            r["steps"].as_u64()
        ),
        (Some(true), Some(3), Some(3000))
    );

    // scored against the built-in exercise on a fresh database
    let db = dir.join("cutlab.db");
    let (ok, out, err) = cutlab(&[
        "--db",
        db.to_str().expect("utf8"),
        "assess",
        m,
        "--trainee",
        "tess",
        "--json",
    ]);
    assert!(ok, "{err}");
    let a: serde_json::Value = serde_json::from_str(&out).expect("json");
    assert!(
        a["score"]
            .as_f64()
            .is_some_and(|s| (-1.0..=1.0).contains(&s)),
        "{a}"
    );
    let time = a["metrics"]
        .as_array()
        .expect("metrics")
        .iter()
        .find(|m| m["key"] == "time_s")
        .expect("time_s")["value"]
        .as_f64();
    // the task time: the hand moves from its start until it holds still after the stroke,
    // within the 3 s recorded
    assert!(time.is_some_and(|t| t > 1.5 && t < 3.0), "{time:?}");
    assert_eq!(a["proficiency"]["attempts"], 1);

    // a recording cut short (a killed process): info says so, recover salvages it, the
    // salvaged part replays bit for bit
    let bytes = std::fs::read(&mcap).expect("bytes");
    let short = dir.join("short.mcap");
    std::fs::write(&short, &bytes[..bytes.len() * 3 / 4]).expect("write");
    let s = short.to_str().expect("utf8");
    let (ok, out, err) = cutlab(&["recording", "info", s]);
    assert!(ok, "{err}");
    assert!(
        out.contains("INCOMPLETE") && out.contains("recording recover"),
        "{out}"
    );
    let fixed = dir.join("fixed.mcap");
    let (ok, out, err) = cutlab(&[
        "recording",
        "recover",
        s,
        "--out",
        fixed.to_str().expect("utf8"),
    ]);
    assert!(ok, "{err}");
    assert!(out.contains("salvaged"), "{out}");
    let (ok, out, err) = cutlab(&["recording", "info", fixed.to_str().expect("utf8"), "--json"]);
    assert!(ok, "{err}");
    assert_eq!(
        serde_json::from_str::<serde_json::Value>(&out).expect("json")["complete"],
        true
    );
    let (ok, out, err) = cutlab(&["replay", fixed.to_str().expect("utf8")]);
    assert!(ok, "{err}");
    assert!(out.contains("bit-exact"), "{out}");

    // one chunk's CRC wrong in the middle of a complete file: damage, not a file cut short;
    // the replay verifies only what is readable, so it fails unless --partial accepts that,
    // and the attempt scored from it says it was
    let mut damaged = bytes.clone();
    let chunks: Vec<usize> = cutlab_recorder::scan::record_spans(&bytes)
        .filter(|s| s.opcode == 0x06)
        .map(|s| s.at)
        .collect();
    assert!(chunks.len() >= 3, "chunks at {chunks:?}");
    // a chunk in the middle: records before it and after it
    let chunk = chunks[chunks.len() / 2];
    damaged[chunk + 9 + 24] ^= 0x01;
    let bad = dir.join("bad.mcap");
    std::fs::write(&bad, &damaged).expect("write");
    let b = bad.to_str().expect("utf8");
    let (ok, out, err) = cutlab(&["recording", "info", b]);
    assert!(ok, "{err}");
    assert!(
        out.contains("DAMAGED") && out.contains(&format!("damaged at byte {chunk} (chunk CRC)")),
        "{out}"
    );
    let (ok, _, err) = cutlab(&["replay", b]);
    assert!(!ok, "a damaged recording does not pass as verified");
    assert!(
        err.contains("verified only up to") && err.contains("--partial"),
        "{err}"
    );
    let (ok, out, err) = cutlab(&["replay", b, "--partial"]);
    assert!(ok, "{err}");
    assert!(
        out.contains("verified up to") && out.contains(" of 3.00 s"),
        "{out}"
    );
    let (ok, out, err) = cutlab(&[
        "--db",
        db.to_str().expect("utf8"),
        "assess",
        b,
        "--trainee",
        "tess",
        "--json",
    ]);
    assert!(ok, "{err}");
    let a: serde_json::Value = serde_json::from_str(&out).expect("json");
    assert!(
        a["note"]
            .as_str()
            .is_some_and(|n| n.starts_with("Scored from a damaged recording: damaged at byte")),
        "{a}"
    );

    // not a recording at all
    let junk = dir.join("junk.mcap");
    std::fs::write(&junk, "hello").expect("write");
    let (ok, _, err) = cutlab(&["recording", "info", junk.to_str().expect("utf8")]);
    assert!(
        !ok && err.contains("not an MCAP file") && !err.contains("panicked"),
        "{err}"
    );
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn output_into_a_closed_pipe_or_a_full_disk_ends_without_a_panic() {
    // a pipe whose reader is gone: the first write fails with EPIPE
    let (reader, writer) = std::io::pipe().expect("pipe");
    drop(reader);
    let out = Command::new(env!("CARGO_BIN_EXE_cutlab"))
        .args(["scene", "list"])
        .stdout(writer)
        .output()
        .expect("cutlab runs");
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(141), "{err}");
    assert!(!err.contains("panicked"), "{err}");
    if let Ok(full) = std::fs::OpenOptions::new().write(true).open("/dev/full") {
        let out = Command::new(env!("CARGO_BIN_EXE_cutlab"))
            .args(["scene", "list"])
            .stdout(full)
            .output()
            .expect("cutlab runs");
        let err = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(1), "{err}");
        assert!(
            err.starts_with("error: failed printing to stdout") && !err.contains("panicked"),
            "{err}"
        );
    }
}

#[test]
fn bench_step_narrows_to_one_size_and_integrator() {
    let (ok, out, err) = cutlab(&[
        "bench",
        "step",
        "--quick",
        "--json",
        "--tets",
        "1000",
        "--integrator",
        "implicit-euler",
    ]);
    assert!(ok, "{err}");
    let v: serde_json::Value = serde_json::from_str(&out).expect("json");
    let rows = v["steps"].as_array().expect("the step rows");
    // the springs and the finite elements, both by implicit Euler, at the one size asked for
    assert_eq!(rows.len(), 2, "{out}");
    // narrowed to one size: no cut-heavy strokes
    assert_eq!(v["strokes"].as_array().map(Vec::len), Some(0), "{out}");
    assert!(
        rows.iter()
            .all(|r| r["requested_tets"] == 1000 && r["integrator"] == "implicit-euler"),
        "{out}"
    );
    let (ok, _, err) = cutlab(&["bench", "step", "--integrator", "leapfrog"]);
    assert!(!ok && err.contains("unknown integrator"), "{err}");
}

#[test]
fn bench_skip_measures_each_skipped_piece_of_work() {
    let dir = std::env::temp_dir().join(format!("cutlab-bench-skip-{}", std::process::id()));
    let dir_arg = dir.to_str().expect("utf-8 temp dir");
    let (ok, out, err) = cutlab(&["bench", "skip", "--quick", "--json", "--out", dir_arg]);
    assert!(ok, "{err}");
    let rows: Vec<serde_json::Value> = serde_json::from_str(&out).expect("json");
    assert_eq!(rows.len(), 1, "{out}");
    let r = &rows[0];
    let particles = r["particles"].as_f64().expect("particles");
    assert!(r["surface_triangles"].as_u64().expect("triangles") > 0);
    // the resting tool keeps only its neighbourhood awake
    let awake = r["localised_awake"].as_f64().expect("awake");
    assert!(
        awake > 0.0 && awake < particles / 4.0,
        "{awake} of {particles}"
    );
    for key in [
        "bvh_rebuild_ms",
        "bvh_refit_ms",
        "bvh_refit_still_ms",
        "surface_extract_ms",
        "step_full_ms",
        "step_localised_ms",
    ] {
        assert!(r[key]["count"].as_u64().expect("count") > 0, "{key}: {out}");
    }
    // the rerun measurement wrote a real .rrd file
    let rrd = std::fs::read_dir(&dir)
        .expect("out dir")
        .filter_map(Result::ok)
        .find(|e| e.path().extension().is_some_and(|x| x == "rrd"));
    let rrd = rrd.expect("an .rrd file");
    assert!(rrd.metadata().expect("metadata").len() > 1000);
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn station_serves_one_trainee_through_a_one_time_link() {
    use std::io::{BufRead, BufReader, Read, Write};
    let dir = std::env::temp_dir().join(format!("cutlab-cli-station-{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("dir");
    let mut child = Command::new(env!("CARGO_BIN_EXE_cutlab"))
        .args(["--db", dir.join("k.db").to_str().expect("utf8")])
        .args(["station", "--trainee", "zoe", "--addr", "127.0.0.1:0"])
        .args(["--device", "expert", "--no-browser"])
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::null())
        .spawn()
        .expect("cutlab station");
    let mut lines = BufReader::new(child.stdout.take().expect("stdout")).lines();
    let mut printed = String::new();
    let url = loop {
        let line = lines.next().expect("a line").expect("utf8");
        printed.push_str(&line);
        printed.push('\n');
        if let Some(url) = line.strip_prefix("station for zoe: ") {
            break url.to_owned();
        }
    };
    assert!(printed.contains("added trainee zoe"), "{printed}");
    let rest = url.strip_prefix("http://").expect("a link");
    let (host, path) = rest.split_at(rest.find('/').expect("a path"));
    let get = |path: &str| {
        let mut s = std::net::TcpStream::connect(host).expect("connect");
        write!(
            s,
            "GET {path} HTTP/1.1\r\nHost: {host}\r\nConnection: close\r\n\r\n"
        )
        .expect("send");
        let mut answer = String::new();
        s.read_to_string(&mut answer).expect("read");
        answer
    };
    let first = get(path);
    let second = get(path);
    let _ = child.kill();
    let _ = child.wait();
    let _ = std::fs::remove_dir_all(&dir);
    assert!(first.starts_with("HTTP/1.1 303"), "{first}");
    assert!(
        first.contains("location: /station") && first.contains("cutlab_session="),
        "{first}"
    );
    assert!(
        second.starts_with("HTTP/1.1 403"),
        "the link works once: {second}"
    );
}

#[test]
fn a_longer_simulation_step_is_recorded_and_replayed_bit_exact() {
    let out = std::env::temp_dir().join(format!("cutlab-cli-step4-{}", std::process::id()));
    let out_s = out.to_str().expect("utf8");
    let (ok, stdout, err) = cutlab(&[
        "session",
        "--time-step-ms",
        "4",
        "--min-tets",
        "1500",
        "--duration",
        "3",
        "--out",
        out_s,
    ]);
    assert!(ok, "{err}");
    // 4 servo ticks per simulation step, none skipped on the virtual clock
    assert!(
        stdout.contains(
            "ticks 3000, sim steps 750 (largest skip ahead of the step's own tick: 0 ticks)"
        ),
        "{stdout}"
    );
    let mcap = out.join("session.mcap");
    let (ok, stdout, err) = cutlab(&["replay", mcap.to_str().expect("utf8")]);
    let _ = std::fs::remove_dir_all(&out);
    assert!(ok && stdout.contains("bit-exact"), "{stdout}{err}");
}

/// `--time-step-ms auto` measures this machine, says what it chose and why, and records the
/// step it chose, so the replay is bit-exact whatever another machine would choose.
#[test]
fn an_automatic_simulation_step_is_said_recorded_and_replayed_bit_exact() {
    let out = std::env::temp_dir().join(format!("cutlab-cli-auto-{}", std::process::id()));
    let out_s = out.to_str().expect("utf8");
    let (ok, stdout, err) = cutlab(&[
        "session",
        "--time-step-ms",
        "auto",
        "--min-tets",
        "1500",
        "--duration",
        "2",
        "--out",
        out_s,
    ]);
    assert!(ok, "{err}");
    let said = stdout
        .lines()
        .find(|l| l.starts_with("simulation step: "))
        .unwrap_or_else(|| panic!("{stdout}"));
    assert!(said.contains("a loaded step took"), "{said}");
    let mcap = out.join("session.mcap");
    let (ok, stdout, err) = cutlab(&["replay", mcap.to_str().expect("utf8")]);
    let _ = std::fs::remove_dir_all(&out);
    assert!(ok && stdout.contains("bit-exact"), "{stdout}{err}");
}

#[test]
fn an_unreachable_or_malformed_database_ends_with_one_clear_line() {
    // nothing listens on port 1; the password never shows
    let (ok, _, err) = cutlab(&[
        "--db",
        "postgres://ann:s3cret@127.0.0.1:1/cutlab",
        "user",
        "list",
    ]);
    assert!(!ok);
    let lines: Vec<&str> = err.lines().collect();
    assert_eq!(lines.len(), 1, "{err}");
    assert!(lines[0].starts_with("error: opening the database"), "{err}");
    assert!(
        lines[0].contains("postgres://ann:***@127.0.0.1:1/cutlab"),
        "{err}"
    );
    assert!(lines[0].contains("refused"), "{err}");
    assert!(!err.contains("s3cret") && !err.contains("panick"), "{err}");
    let (ok, _, err) = cutlab(&["--db", "postgres://h:notaport/x", "user", "list"]);
    assert!(!ok);
    assert_eq!(err.lines().count(), 1, "{err}");
    assert!(err.contains("port"), "{err}");
}

#[test]
fn an_unreachable_recording_store_ends_with_one_clear_line() {
    let dir = tempfile::tempdir().expect("folder");
    let db = dir.path().join("cutlab.db");
    // an S3 endpoint where nothing listens: the command stops as it starts, in seconds
    let out = Command::new(env!("CARGO_BIN_EXE_cutlab"))
        .args(["--db", db.to_str().expect("utf-8")])
        .args(["--recordings", "s3://cutlab-recordings/centre-a"])
        .args(["serve", "--addr", "127.0.0.1:0"])
        .env("AWS_ENDPOINT", "http://127.0.0.1:1")
        .env("AWS_ALLOW_HTTP", "true")
        .env("AWS_ACCESS_KEY_ID", "station")
        .env("AWS_SECRET_ACCESS_KEY", "not-a-secret-that-shows")
        .env("AWS_REGION", "us-east-1")
        .output()
        .expect("cutlab runs");
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success(), "{err}");
    let lines: Vec<&str> = err.lines().filter(|l| l.starts_with("error")).collect();
    assert_eq!(lines.len(), 1, "{err}");
    assert!(
        lines[0].starts_with("error: opening the recording store")
            && lines[0].contains("s3://cutlab-recordings/centre-a"),
        "{err}"
    );
    assert!(
        !err.contains("not-a-secret") && !err.contains("panick"),
        "{err}"
    );
    // and a folder that cannot be made is said as plainly
    let file = dir.path().join("a-file");
    std::fs::write(&file, b"not a folder").expect("file");
    let (ok, _, err) = cutlab(&[
        "--db",
        db.to_str().expect("utf-8"),
        "--recordings",
        file.join("recordings").to_str().expect("utf-8"),
        "serve",
        "--addr",
        "127.0.0.1:0",
    ]);
    assert!(!ok);
    assert_eq!(
        err.lines().filter(|l| l.starts_with("error")).count(),
        1,
        "{err}"
    );
    assert!(err.contains("opening the recording store"), "{err}");
}

#[test]
fn an_attempt_keeps_its_recordings_in_the_store_beside_the_database() {
    let dir = tempfile::tempdir().expect("folder");
    let db = dir.path().join("cutlab.db");
    let out = dir.path().join("tess-1");
    let (ok, _, err) = cutlab(&[
        "--db",
        db.to_str().expect("utf-8"),
        "session",
        "--device",
        "expert",
        "--clock",
        "virtual",
        "--duration",
        "1",
        "--min-tets",
        "3000",
        "--out",
        out.to_str().expect("utf-8"),
        "--trainee",
        "tess",
    ]);
    assert!(ok, "{err}");
    // the default store: recordings/ beside the SQLite file, the file under its SHA-256
    let bytes = std::fs::read(out.join("session.mcap")).expect("recording");
    let key = cutlab_assessor::recordings::sha256_hex(&bytes);
    let kept = std::fs::read(dir.path().join("recordings").join("sha256").join(&key))
        .expect("in the store");
    assert_eq!(kept, bytes);
}

#[test]
fn names_with_control_or_reordering_characters_are_refused_on_the_command_line() {
    let dir = tempfile::tempdir().expect("dir");
    let db = dir.path().join("t.db");
    let db = db.to_str().expect("utf8");
    let long = "x".repeat(100_000);
    for bad in ["spring\u{1b}[2J", "rtl\u{202e}txt", long.as_str()] {
        let (ok, _, err) = cutlab(&["--db", db, "cohort", "add", "--name", bad]);
        assert!(!ok, "{bad:.20} was taken");
        assert!(
            err.contains("a cohort's name") && err.len() < 500,
            "one clear line: {err}"
        );
    }
    let (ok, out, err) = cutlab(&["--db", db, "cohort", "add", "--name", "spring 2027"]);
    assert!(ok, "{out}{err}");
}

#[test]
fn a_session_of_a_locked_exercise_is_refused_in_the_stations_words_until_opened() {
    let dir = tempfile::tempdir().expect("folder");
    let db = dir.path().join("locks.db");
    let db = db.to_str().expect("utf8");
    let out = dir.path().join("session");
    let session = |trainee: &str| {
        cutlab(&[
            "--db",
            db,
            "session",
            "--trainee",
            trainee,
            "--exercise",
            "pattern-cutting",
            "--duration",
            "0.2",
            "--surface-hz",
            "0",
            "--out",
            out.to_str().expect("utf8"),
        ])
    };
    // a new trainee has not reached proficiency in the chest wall, before it in cutting-basics
    let (ok, _, err) = session("zed");
    assert!(!ok, "a locked exercise ran");
    assert!(
        err.contains("pattern-cutting is locked in the cutting-basics curriculum")
            && err.contains("an instructor can open it early"),
        "{err}"
    );
    assert!(!out.join("session.mcap").exists(), "nothing is recorded");
    // a trainee cannot open it, an instructor can
    let open = |by: &str| {
        cutlab(&[
            "--db",
            db,
            "user",
            "open",
            "--name",
            "zed",
            "--exercise",
            "pattern-cutting",
            "--by",
            by,
            "--reason",
            "ready early",
        ])
    };
    let (ok, _, err) = open("zed");
    assert!(
        !ok && err.contains("only an instructor or an admin"),
        "{err}"
    );
    let (ok, _, err) = cutlab(&[
        "--db",
        db,
        "user",
        "add",
        "--name",
        "dr-lee",
        "--role",
        "instructor",
    ]);
    assert!(ok, "{err}");
    let (ok, said, err) = open("dr-lee");
    assert!(
        ok && said.contains("pattern-cutting is open to zed"),
        "{err}"
    );
    let (ok, _, err) = session("zed");
    assert!(ok, "{err}");
    assert!(out.join("session.mcap").is_file());
}

/// A second hand on a grasper from the command line: it holds the gauze beside the scalpel's
/// line, its grasp is said and summarised, the recording replays bit-exact; bad grasps are
/// refused before anything runs.
#[test]
fn a_session_with_a_grasper_holds_the_gauze_and_replays_bit_exact() {
    let dir = tempfile::tempdir().expect("temp dir");
    let out = dir.path().to_str().expect("utf-8");
    let (ok, stdout, err) = cutlab(&[
        "session",
        "--scene",
        "gauze",
        "--device",
        "expert",
        "--duration",
        "2",
        "--clock",
        "virtual",
        "--grasp-at-mm",
        "50,58,0.8",
        "--grasp-pull-mm",
        "0,0,4",
        "--out",
        out,
    ]);
    assert!(ok, "{err}");
    assert!(stdout.contains("grasper: 1 grasp(s), held 0.8"), "{stdout}");
    let summary: serde_json::Value = serde_json::from_str(
        &std::fs::read_to_string(dir.path().join("summary.json")).expect("summary"),
    )
    .expect("json");
    let grasper = &summary["grasper"];
    assert_eq!(grasper["grasps"], 1, "{summary}");
    assert!(
        grasper["max_pull_newtons"]
            .as_f64()
            .is_some_and(|n| n > 0.0),
        "{summary}"
    );
    let mcap = dir.path().join("session.mcap");
    let (ok, stdout, err) = cutlab(&["replay", mcap.to_str().expect("utf-8")]);
    assert!(
        ok && stdout.contains("verified: the replay is bit-exact"),
        "{stdout}{err}"
    );
    scored_with_the_second_hands_handling(dir.path(), &mcap);

    for (args, says) in [
        (vec!["--grasp-at-mm", "50,nan,0.8"], "three finite numbers"),
        (vec!["--grasp-at-mm", "50,58"], "three finite numbers"),
        (vec!["--grasp-pull-mm", "0,0,4"], "--grasp-at-mm"),
        (
            vec!["--grasp-at-mm", "50,58,0.8", "--grasp-release-s=-1"],
            "release time",
        ),
        (
            vec!["--second-hand", "--grasp-at-mm", "50,58,0.8"],
            "cannot be used with",
        ),
        (
            vec!["--second-hand", "--device", "pointer:steady"],
            "a synthetic trainee's",
        ),
    ] {
        let mut all = vec![
            "session",
            "--scene",
            "gauze",
            "--duration",
            "1",
            "--clock",
            "virtual",
            "--out",
            out,
        ];
        all.extend(args);
        let (ok, _, err) = cutlab(&all);
        assert!(!ok && err.contains(says), "{all:?}: {err}");
    }
}

/// The two-handed recording `mcap` scored as an attempt at a line across the gauze (a
/// database in `dir`): the metrics say how the grasper held the tissue, and the trainee's
/// xAPI statements carry them.
fn scored_with_the_second_hands_handling(dir: &std::path::Path, mcap: &std::path::Path) {
    let db = dir.join("cutlab.db");
    let db = db.to_str().expect("utf-8");
    let plan = dir.join("line.toml");
    std::fs::write(
        &plan,
        "entry_m = [0.03, 0.05, 0.0008]\nexit_m = [0.07, 0.05, 0.0008]\ndepth_m = 0.0015\n\
         viewpoint_m = [0.05, 0.05, 0.15]\n",
    )
    .expect("plan written");
    let plan = plan.to_str().expect("utf-8");
    let (ok, _, err) = cutlab(&[
        "--db",
        db,
        "exercise",
        "add",
        "--name",
        "gauze-line",
        "--scene",
        "gauze",
        "--plan",
        plan,
    ]);
    assert!(ok, "{err}");
    let (ok, out, err) = cutlab(&[
        "--db",
        db,
        "assess",
        mcap.to_str().expect("utf-8"),
        "--trainee",
        "alice",
        "--exercise",
        "gauze-line",
        "--json",
    ]);
    assert!(ok, "{err}");
    let v: serde_json::Value = serde_json::from_str(&out).expect("json");
    let metric = |key: &str| {
        v["metrics"]
            .as_array()
            .and_then(|m| m.iter().find(|m| m["key"] == key))
            .map(|m| m["value"].clone())
            .unwrap_or_else(|| panic!("{key} missing: {v}"))
    };
    assert_eq!(metric("grasps"), 1.0, "{v}");
    assert_eq!(metric("grasp_slips"), 0.0, "{v}");
    assert!(
        metric("peak_traction_n").as_f64().is_some_and(|n| n > 0.0),
        "{v}"
    );
    let (ok, out, err) = cutlab(&["--db", db, "export", "xapi", "--trainee", "alice"]);
    assert!(ok, "{err}");
    assert!(out.contains("/metric/peak_traction_n"), "{out}");
}
