//! Headless Chromium through chromedriver (WebDriver, fantoccini): what `cutlab bench station`
//! drives, and the browser tests of the workspace (`tests/e2e_dashboard.rs`) too. Debian's
//! `chromium` and `chromium-driver` packages (`.ci/run` installs them).

use std::net::{SocketAddr, TcpListener, TcpStream};
use std::path::Path;
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

use anyhow::{Context, bail};

pub const CHROMIUM: &str = "/usr/bin/chromium";
pub const CHROMEDRIVER: &str = "/usr/bin/chromedriver";

/// The browser's programs that are not on this machine.
pub fn missing() -> Vec<&'static str> {
    [CHROMIUM, CHROMEDRIVER]
        .into_iter()
        .filter(|p| !Path::new(p).exists())
        .collect()
}

/// A running chromedriver (killed when dropped) and its port.
#[derive(Debug)]
pub struct Driver {
    child: Child,
    pub port: u16,
}

impl Drop for Driver {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

/// A port nobody listens on now.
pub fn free_port() -> anyhow::Result<u16> {
    Ok(TcpListener::bind("127.0.0.1:0")?.local_addr()?.port())
}

/// Waits until something listens on `port` of this machine, while `child` runs.
pub fn wait_for_port(
    port: u16,
    what: &str,
    child: &mut Child,
    timeout: Duration,
) -> anyhow::Result<()> {
    let deadline = Instant::now() + timeout;
    let addr = SocketAddr::from(([127, 0, 0, 1], port));
    while TcpStream::connect_timeout(&addr, Duration::from_millis(200)).is_err() {
        if let Some(status) = child.try_wait()? {
            bail!("{what} exited: {status}");
        }
        if Instant::now() > deadline {
            bail!("{what} does not listen on {port} after {timeout:?}");
        }
        std::thread::sleep(Duration::from_millis(100));
    }
    Ok(())
}

/// Starts chromedriver on a free port.
pub fn chromedriver() -> anyhow::Result<Driver> {
    let port = free_port()?;
    let child = Command::new(CHROMEDRIVER)
        .arg(format!("--port={port}"))
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()
        .with_context(|| format!("starting {CHROMEDRIVER} (apt-get install chromium-driver)"))?;
    let mut driver = Driver { child, port };
    wait_for_port(
        port,
        "chromedriver",
        &mut driver.child,
        Duration::from_secs(60),
    )?;
    Ok(driver)
}

/// A headless Chromium session with a profile of its own in `profile`, WebGL2 on the CPU
/// (SwiftShader): the station and rerun's viewer both draw with it, and Chromium no longer
/// falls back to SwiftShader by itself.
pub async fn chromium(driver: &Driver, profile: &Path) -> anyhow::Result<fantoccini::Client> {
    let profile = format!("--user-data-dir={}", profile.display());
    let args = vec![
        "--headless",
        "--no-sandbox",
        "--disable-quic",
        "--no-first-run",
        "--disable-background-networking",
        "--disable-component-update",
        "--disable-sync",
        "--window-size=1400,1000",
        "--use-angle=swiftshader",
        "--enable-unsafe-swiftshader",
        &profile,
    ];
    let mut caps = serde_json::Map::new();
    caps.insert(
        "goog:chromeOptions".into(),
        serde_json::json!({ "binary": CHROMIUM, "args": args }),
    );
    fantoccini::ClientBuilder::new(hyper_util::client::legacy::connect::HttpConnector::new())
        .capabilities(caps)
        .connect(&format!("http://127.0.0.1:{}", driver.port))
        .await
        .context("starting a headless Chromium session")
}
