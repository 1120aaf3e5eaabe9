//! End-to-end in a real browser: `cutlab serve --demo` on a fresh database, a recorded
//! session (`cutlab session --trainee ana --rrd`), and headless Chromium driven through
//! chromedriver (WebDriver, fantoccini): log in as the demo instructor, open a trainee's
//! progress page and see the learning-curve charts, open the recorded attempt and its replay
//! in rerun's web viewer served by the dashboard. Screenshots go to `target/e2e/`.
//!
//! Needs Debian's `chromium` and `chromium-driver` (installed by `.ci/run`). Without them the
//! test says why and passes, unless `CUTLAB_E2E` is set (CI sets it): then it fails.

use std::net::{SocketAddr, TcpListener, TcpStream};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

use fantoccini::{ClientBuilder, Locator};

const CHROMIUM: &str = "/usr/bin/chromium";
const CHROMEDRIVER: &str = "/usr/bin/chromedriver";

/// A child process killed when dropped.
struct Proc(Child);

impl Drop for Proc {
    fn drop(&mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

fn free_port() -> u16 {
    TcpListener::bind("127.0.0.1:0")
        .and_then(|l| l.local_addr())
        .map(|a| a.port())
        .expect("a free port")
}

fn wait_for_port(port: u16, what: &str, child: &mut Child, timeout: Duration) {
    let deadline = Instant::now() + timeout;
    let addr = SocketAddr::from(([127, 0, 0, 1], port));
    while TcpStream::connect_timeout(&addr, Duration::from_millis(200)).is_err() {
        if let Ok(Some(status)) = child.try_wait() {
            panic!("{what} exited: {status}");
        }
        assert!(
            Instant::now() < deadline,
            "{what} does not listen on {port}"
        );
        std::thread::sleep(Duration::from_millis(100));
    }
}

fn cutlab(db: &Path, args: &[&str]) -> Command {
    let mut c = Command::new(env!("CARGO_BIN_EXE_cutlab"));
    c.arg("--db").arg(db).args(args);
    c
}

fn artefacts() -> PathBuf {
    let target = std::env::var_os("CARGO_TARGET_DIR").map_or_else(
        || Path::new(env!("CARGO_MANIFEST_DIR")).join("target"),
        PathBuf::from,
    );
    let dir = target.join("e2e");
    std::fs::create_dir_all(&dir).expect("target/e2e");
    dir
}

#[test]
fn instructor_reviews_progress_and_replay_in_headless_chromium() {
    let missing: Vec<&str> = [CHROMIUM, CHROMEDRIVER]
        .into_iter()
        .filter(|p| !Path::new(p).exists())
        .collect();
    if !missing.is_empty() {
        assert!(
            std::env::var_os("CUTLAB_E2E").is_none(),
            "CUTLAB_E2E is set but {missing:?} are missing (apt-get install chromium chromium-driver)"
        );
        eprintln!(
            "skipped: {missing:?} missing (apt-get install chromium chromium-driver; CUTLAB_E2E=1 makes this a failure)"
        );
        return;
    }
    let tmp = std::env::temp_dir().join(format!("cutlab-e2e-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&tmp);
    std::fs::create_dir_all(&tmp).expect("temp dir");
    let db = tmp.join("cutlab.db");
    let port = free_port();
    let mut server = cutlab(
        &db,
        &["serve", "--demo", "--addr", &format!("127.0.0.1:{port}")],
    )
    .stdout(Stdio::null())
    .spawn()
    .expect("cutlab serve");
    // (--demo first simulates the demo's attempts: about a minute)
    wait_for_port(port, "cutlab serve", &mut server, Duration::from_secs(600));
    let _server = Proc(server);
    // a real recorded attempt of ana's (after the demo's)
    let out = tmp.join("session");
    let s = cutlab(
        &db,
        &[
            "session",
            "--trainee",
            "ana",
            "--rrd",
            "--min-tets",
            "1500",
            "--duration",
            "3",
            "--clock",
            "virtual",
            "--out",
            out.to_str().expect("utf8"),
        ],
    )
    .output()
    .expect("cutlab session");
    assert!(s.status.success(), "{}", String::from_utf8_lossy(&s.stderr));
    assert!(out.join("session.rrd").is_file());
    let stdout = String::from_utf8_lossy(&s.stdout);
    let attempt: i64 = stdout
        .lines()
        .find_map(|l| {
            l.strip_prefix("attempt ")?
                .split_once(" of ana")?
                .0
                .parse()
                .ok()
        })
        .unwrap_or_else(|| panic!("the session names its attempt: {stdout}"));

    let driver_port = free_port();
    let mut driver = Command::new(CHROMEDRIVER)
        .arg(format!("--port={driver_port}"))
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()
        .expect("chromedriver");
    wait_for_port(
        driver_port,
        "chromedriver",
        &mut driver,
        Duration::from_secs(60),
    );
    let _driver = Proc(driver);

    let profile = tmp.join("chromium-profile");
    let rt = tokio::runtime::Builder::new_multi_thread()
        .worker_threads(2)
        .enable_all()
        .build()
        .expect("runtime");
    rt.block_on(browse(port, driver_port, attempt, &profile, &artefacts()));
    let _ = std::fs::remove_dir_all(&tmp);
}

async fn browse(port: u16, driver_port: u16, attempt: i64, profile: &Path, shots: &Path) {
    let args = [
        "--headless",
        "--no-sandbox",
        "--disable-gpu",
        "--disable-quic",
        "--no-first-run",
        "--disable-background-networking",
        "--disable-component-update",
        "--disable-sync",
        "--window-size=1400,1000",
        &format!("--user-data-dir={}", profile.display()),
    ];
    let mut caps = serde_json::Map::new();
    caps.insert(
        "goog:chromeOptions".into(),
        serde_json::json!({ "binary": CHROMIUM, "args": args }),
    );
    let c = ClientBuilder::new(hyper_util::client::legacy::connect::HttpConnector::new())
        .capabilities(caps)
        .connect(&format!("http://127.0.0.1:{driver_port}"))
        .await
        .expect("a chromium session");
    let base = format!("http://127.0.0.1:{port}");
    let result = async {
        c.goto(&format!("{base}/login")).await?;
        c.find(Locator::Css("input[name=username]")).await?.send_keys("dr-kim").await?;
        c.find(Locator::Css("input[name=password]")).await?.send_keys("instructor-demo").await?;
        c.find(Locator::Css("form.login button")).await?.click().await?;
        c.wait().for_element(Locator::Css("table.grid")).await?;
        assert!(c.current_url().await?.path().ends_with("/cohorts"));
        c.find(Locator::LinkText("ana")).await?.click().await?;
        c.wait().for_element(Locator::Css(".learning-curves svg.chart")).await?;
        let charts = c.find_all(Locator::Css(".learning-curves svg.chart polyline")).await?;
        assert!(!charts.is_empty(), "learning curves drawn");
        let title = c.find(Locator::Css("h1")).await?.text().await?;
        assert_eq!(title, "Progress of ana");
        std::fs::write(shots.join("progress.png"), c.screenshot().await?).expect("screenshot");
        // the attempt just recorded
        c.find(Locator::Css(&format!("table tbody tr td a[href='/attempts/{attempt}']"))).await?.click().await?;
        c.wait().for_element(Locator::Id("review-replay")).await?;
        std::fs::write(shots.join("attempt.png"), c.screenshot().await?).expect("screenshot");
        let svgs = c.find_all(Locator::Css(".charts svg.chart")).await?;
        assert!(svgs.len() >= 2, "incision top view and force plot");
        c.find(Locator::Id("review-replay")).await?.click().await?;
        let frame = c.wait().for_element(Locator::Id("replay")).await?;
        let src = frame.attr("src").await?.unwrap_or_default();
        assert!(src.starts_with("/viewer/?url=") && src.contains("recording.rrd"), "{src}");
        // inside the frame: rerun's viewer page, its wasm fetched from us
        frame.enter_frame().await?;
        c.wait().for_element(Locator::Id("the_canvas_id")).await?;
        let deadline = Instant::now() + Duration::from_secs(60);
        loop {
            let fetched = c
                .execute("return performance.getEntriesByType('resource').filter(e => e.name.endsWith('re_viewer_bg.wasm') || e.name.includes('recording.rrd')).map(e => [e.name, e.responseStatus])", vec![])
                .await?;
            let entries = fetched.as_array().cloned().unwrap_or_default();
            let status_of = |suffix: &str| entries.iter().find(|e| e[0].as_str().is_some_and(|n| n.ends_with(suffix))).map(|e| e[1].as_u64());
            if status_of("recording.rrd").is_some() || Instant::now() > deadline {
                assert_eq!(status_of("re_viewer_bg.wasm"), Some(Some(200)), "the viewer's wasm was loaded: {entries:?}");
                assert_eq!(status_of("recording.rrd"), Some(Some(200)), "the viewer fetched the attempt's .rrd: {entries:?}");
                break;
            }
            tokio::time::sleep(Duration::from_millis(500)).await;
        }
        tokio::time::sleep(Duration::from_secs(3)).await;
        c.enter_parent_frame().await?;
        std::fs::write(shots.join("replay.png"), c.screenshot().await?).expect("screenshot");
        Ok::<(), fantoccini::error::CmdError>(())
    }
    .await;
    let _ = c.close().await;
    result.expect("the browser flow");
}
