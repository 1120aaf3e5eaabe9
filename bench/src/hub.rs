//! `cutlab bench hub`: stations uploading to one hub. The hub is a `cutlab serve` process of
//! its own (this executable) on a fresh database with a folder recording store; each
//! simulated station has its own SQLite database and recordings, and in a loop ends an
//! attempt (a recording of `--recording-kib` of distinct bytes) and sends its queue with
//! `cutlab_station::sync`, the code a real station runs.
//!
//! 1. Load: `--stations` at once for `--duration` seconds: attempts per second taken by the
//!    hub, and the time of one attempt's upload (its recording, then the attempt).
//! 2. The hub killed (SIGKILL) while every station is uploading a queue of its own, then
//!    restarted; the stations sync until their queues are empty. Then every attempt must be
//!    on the hub exactly once, ended as on its station, and every recording's content must
//!    hash to its key; anything else ends the benchmark with an error.

use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

use anyhow::{Context, bail, ensure};
use cutlab_assessor::DbLocation;
use cutlab_assessor::recordings::RecordingStore;
use cutlab_assessor::store::{AttemptStatus, Role, Store};
use cutlab_sim::stats::Summary;
use cutlab_station::sync::{Hub, SyncError, sync};

pub struct Options<'a> {
    pub out: &'a Path,
    pub stations: usize,
    pub duration_s: f64,
    pub recording_kib: usize,
    /// Attempts each station has queued when the hub is killed.
    pub queued: usize,
    pub json: bool,
}

#[derive(Debug, serde::Serialize)]
struct Report {
    stations: usize,
    recording_kib: usize,
    duration_s: f64,
    attempts: usize,
    attempts_per_s: f64,
    upload_p50_ms: f64,
    upload_p99_ms: f64,
    upload_max_ms: f64,
    megabytes_per_s: f64,
    /// The kill: attempts queued over all stations, syncs the kill interrupted, attempts on
    /// the hub (each exactly once), recordings whose content hashed to their key, and the
    /// seconds from the restart until every queue was empty.
    kill_queued: usize,
    kill_interrupted_syncs: usize,
    kill_present_once: usize,
    kill_hashes_verified: usize,
    /// Complete attempts of the kill whose metrics on the hub are the station's (the hub
    /// scores them from their recordings).
    kill_scored: usize,
    /// Attempts of the kill lost or changed on their way (goal: none).
    kill_lost: usize,
    kill_drain_s: f64,
    slow: SlowReport,
    /// Attempts lost or changed by the time the hostile clients are gone (goal: none).
    slow_lost: usize,
    /// How each lost attempt was lost.
    lost: Vec<String>,
}

/// The hostile clients of phase 3 and the honest stations' uploads meanwhile.
#[derive(Debug, Default, serde::Serialize)]
struct SlowReport {
    /// Recording uploads by hostile stations whose bodies crawled (a byte every 200 ms) or
    /// stalled, how many the hub cut off (408), the last after how many seconds.
    slow_bodies: usize,
    slow_bodies_cut: usize,
    slow_cut_after_s: f64,
    /// Connections from one address that sent part of their headers and no more: refused at
    /// once past the address's cap (503), or closed by the hub's header timeout.
    unfinished_headers: usize,
    unfinished_refused: usize,
    unfinished_closed: usize,
    /// Logins whose bodies crawled (ten bytes every 500 ms), how many the hub cut off (408),
    /// the last after how many seconds.
    crawling_logins: usize,
    crawling_logins_cut: usize,
    crawling_login_cut_after_s: f64,
    /// Connections from eight addresses that sent no byte at all: refused at once past a cap
    /// (503), or closed by the header timeout, the last after how many seconds.
    idle_sockets: usize,
    idle_refused: usize,
    idle_closed: usize,
    idle_closed_after_s: f64,
    /// The honest stations' attempts meanwhile (each station from its own clients), and
    /// the time of one attempt's upload.
    honest_attempts: usize,
    honest_p50_ms: f64,
    honest_p99_ms: f64,
    honest_max_ms: f64,
}

/// The hub process.
struct HubProcess {
    child: Child,
}

impl HubProcess {
    fn start(db: &Path, recordings: &Path, port: u16, log: &Path) -> anyhow::Result<Self> {
        let exe = std::env::current_exe().context("this executable")?;
        let log = std::fs::OpenOptions::new()
            .create(true)
            .append(true)
            .open(log)
            .with_context(|| format!("{}", log.display()))?;
        let child = Command::new(exe)
            .arg("--db")
            .arg(db)
            .arg("--recordings")
            .arg(recordings)
            .args(["serve", "--addr", &format!("127.0.0.1:{port}")])
            .env_remove("CUTLAB_HUB")
            .stdin(Stdio::null())
            .stdout(log.try_clone()?)
            .stderr(log)
            .spawn()
            .context("starting the hub (cutlab serve)")?;
        let hub = Self { child };
        let t0 = Instant::now();
        while std::net::TcpStream::connect(("127.0.0.1", port)).is_err() {
            ensure!(
                t0.elapsed() < Duration::from_secs(60),
                "the hub did not listen on port {port} within 60 s"
            );
            std::thread::sleep(Duration::from_millis(50));
        }
        Ok(hub)
    }

    /// SIGKILL: no graceful anything.
    fn kill(mut self) -> anyhow::Result<()> {
        self.child.kill().context("killing the hub")?;
        self.child.wait().context("reaping the hub")?;
        Ok(())
    }
}

impl Drop for HubProcess {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

/// One simulated station: its database, folder and trainee.
struct Station {
    store: Store,
    dir: PathBuf,
    trainee: i64,
    exercise: i64,
    hub: Hub,
    made: usize,
}

impl Station {
    async fn new(k: usize, root: &Path, url: &str, token: &str) -> anyhow::Result<Self> {
        let dir = root.join(format!("station-{k}"));
        std::fs::create_dir_all(&dir)?;
        let store = Store::open(&dir.join("station.db")).await?;
        let exercise = store.ensure_builtins().await?.id;
        let trainee = store
            .create_user(&format!("bench-trainee-{k}"), Role::Trainee, None)
            .await?
            .id;
        Ok(Self {
            store,
            dir,
            trainee,
            exercise,
            hub: Hub::new(url, token)?,
            made: 0,
        })
    }

    /// Removes the last attempt's recording file.
    async fn forget_last(&self) -> anyhow::Result<()> {
        let path = self.dir.join(format!("attempt-{}.mcap", self.made));
        tokio::fs::remove_file(&path)
            .await
            .with_context(|| format!("{}", path.display()))
    }

    /// An attempt that ended incomplete, with a recording of `kib` KiB no other attempt
    /// has (the hub stores it without scoring it: the load is the upload).
    async fn end_attempt(&mut self, kib: usize) -> anyhow::Result<()> {
        self.made += 1;
        let path = self.dir.join(format!("attempt-{}.mcap", self.made));
        let seed = format!("{}:{}", self.dir.display(), self.made);
        let mut bytes = Vec::with_capacity(kib * 1024);
        let mut x = cutlab_assessor::recordings::sha256_hex(seed.as_bytes()).into_bytes();
        while bytes.len() < kib * 1024 {
            bytes.extend_from_slice(&x);
            x.rotate_left(1);
        }
        bytes.truncate(kib * 1024);
        tokio::fs::write(&path, &bytes).await?;
        let a = self
            .store
            .start_attempt(self.trainee, self.exercise, path.to_str(), false)
            .await?;
        self.store
            .mark_incomplete(a.id, Some("bench: load"))
            .await?;
        Ok(())
    }

    /// An attempt recorded a day ago (a station offline for a day), scored on the station
    /// from a real recording of its own: a copy of `base` that no other attempt has (the
    /// recorder's salvage of it, which names its source).
    async fn end_day_old_attempt(&mut self, base: &Path) -> anyhow::Result<()> {
        self.made += 1;
        let source = self.dir.join(format!("source-{}.mcap", self.made));
        let path = self.dir.join(format!("attempt-{}.mcap", self.made));
        tokio::fs::copy(base, &source).await?;
        let (from, to) = (source.clone(), path.clone());
        tokio::task::spawn_blocking(move || cutlab_recorder::recover::recover(&from, &to))
            .await??;
        tokio::fs::remove_file(&source).await?;
        let a = self
            .store
            .start_attempt(self.trainee, self.exercise, path.to_str(), false)
            .await?;
        let rec = cutlab_recorder::Recording::open(&path)?;
        self.store.score_recording(a.id, &rec).await?;
        const DAY_NS: i64 = 86_400 * 1_000_000_000;
        let minute = 60 * 1_000_000_000_i64;
        cutlab_assessor::on_db!(self.store.db(), pool => sqlx::query("UPDATE attempts SET started_ns = ended_ns - $1, ended_ns = ended_ns - $2 WHERE id = $3")
            .bind(DAY_NS + minute)
            .bind(DAY_NS)
            .bind(a.id)
            .execute(pool).await.map(|_| ()))?;
        Ok(())
    }
}

/// What [`verify`] found.
struct Verified {
    /// Attempts on the hub (each exactly once).
    present: usize,
    /// Complete attempts whose metrics on the hub are the station's.
    scored: usize,
    /// Recordings whose content hashed to their key.
    verified: usize,
    /// The attempts lost or changed on their way, with how.
    lost: Vec<String>,
}

/// Every attempt of every station on the hub exactly once, ended as on its station, a
/// complete one with the station's metrics (the hub scores it from its recording), its
/// recording intact (the station's file where the station kept it). An error if a queue is
/// not empty or a recording damaged.
async fn verify(
    stations: &[Station],
    hub_store: &Store,
    recordings: &RecordingStore,
) -> anyhow::Result<Verified> {
    let mut v = Verified {
        present: 0,
        scored: 0,
        verified: 0,
        lost: Vec::new(),
    };
    let values = |m: Vec<cutlab_assessor::store::StoredMetric>| {
        m.into_iter()
            .map(|m| (m.metric, m.value))
            .collect::<Vec<_>>()
    };
    for s in stations {
        ensure!(
            s.store.sync_queue().await?.is_empty(),
            "a station's queue is not empty"
        );
        for a in s.store.list_attempts(None, None).await? {
            let uuid = a.uuid.clone().context("an attempt without id")?;
            let Ok(h) = hub_store.attempt_by_uuid(&uuid).await else {
                v.lost.push(format!("{uuid}: not on the hub"));
                continue;
            };
            v.present += 1;
            if (h.status, h.started_ns) != (a.status, a.started_ns) {
                v.lost.push(format!(
                    "{uuid}: {:?} on the hub, {:?} on its station",
                    h.status, a.status
                ));
            } else if a.status == AttemptStatus::Complete {
                let mine = values(s.store.attempt_metrics(a.id).await?);
                if mine.is_empty() || mine != values(hub_store.attempt_metrics(h.id).await?) {
                    v.lost
                        .push(format!("{uuid}: the hub's metrics are not the station's"));
                } else {
                    v.scored += 1;
                }
            }
            let key = h.recording_sha256.context("an attempt without recording")?;
            // its content hashes to its key (else an error)
            let bytes = recordings.get(&key).await?;
            if let Ok(local) =
                tokio::fs::read(a.recording_path.as_deref().unwrap_or_default()).await
            {
                ensure!(bytes == local, "attempt {uuid}'s recording differs");
            }
            v.verified += 1;
        }
    }
    // each found by its id (unique on the hub) and none besides: each exactly once
    let hub_total = hub_store.list_attempts(None, None).await?.len();
    ensure!(
        hub_total == v.present,
        "the hub has {hub_total} attempts, the stations {}",
        v.present
    );
    Ok(v)
}

/// A connection to the hub on `port` from the loopback address `from`.
async fn connect_from(from: &str, port: u16) -> anyhow::Result<tokio::net::TcpStream> {
    let socket = tokio::net::TcpSocket::new_v4()?;
    socket.bind(format!("{from}:0").parse()?)?;
    Ok(socket.connect(([127, 0, 0, 1], port).into()).await?)
}

/// The status the hub answers on `read` within `within`; `None`: closed without one, or
/// still silent.
async fn status_within(
    read: &mut (impl tokio::io::AsyncRead + Unpin),
    within: Duration,
) -> Option<u16> {
    use tokio::io::AsyncReadExt;
    let mut got = Vec::new();
    let _ = tokio::time::timeout(within, async {
        let mut buf = [0u8; 512];
        while !got.windows(2).any(|w| w == b"\r\n") {
            match read.read(&mut buf).await {
                Ok(0) | Err(_) => return,
                Ok(n) => got.extend_from_slice(&buf[..n]),
            }
        }
    })
    .await;
    String::from_utf8_lossy(&got)
        .split(' ')
        .nth(1)
        .and_then(|c| c.parse().ok())
}

/// A request from `from` whose head is `head` and whose body crawls: `sends` chunks of
/// `chunk` bytes, one every `every`, then nothing; the hub's status and when it came.
async fn crawling_request(
    port: u16,
    from: &str,
    head: String,
    (sends, chunk, every): (usize, usize, Duration),
    t0: Instant,
) -> anyhow::Result<(Option<u16>, f64)> {
    use tokio::io::AsyncWriteExt;
    let mut s = connect_from(from, port).await?;
    s.write_all(head.as_bytes()).await?;
    let (mut read, mut write) = s.split();
    let writing = async {
        let bytes = vec![b'x'; chunk];
        for _ in 0..sends {
            if write.write_all(&bytes).await.is_err() {
                break;
            }
            tokio::time::sleep(every).await;
        }
        std::future::pending::<()>().await
    };
    let status = tokio::select! {
        s = status_within(&mut read, Duration::from_secs(120)) => s,
        () = writing => None,
    };
    Ok((status, t0.elapsed().as_secs_f64()))
}

/// A hostile station's recording upload from 127.0.0.2: 100 MiB announced, then a byte every
/// 200 ms (`crawl`) or one byte and nothing.
async fn slow_body(
    port: u16,
    token: String,
    crawl: bool,
    t0: Instant,
) -> anyhow::Result<(Option<u16>, f64)> {
    let key = cutlab_assessor::recordings::sha256_hex(b"never sent whole");
    let head = format!(
        "PUT /api/hub/recordings/{key} HTTP/1.1\r\nHost: hub\r\nAuthorization: Bearer {token}\r\nContent-Length: {}\r\n\r\n",
        100u64 << 20
    );
    let sends = if crawl { 3000 } else { 1 };
    crawling_request(
        port,
        "127.0.0.2",
        head,
        (sends, 1, Duration::from_millis(200)),
        t0,
    )
    .await
}

/// A login from 127.0.0.4 whose body crawls: 100,000 bytes announced, ten every 500 ms.
async fn crawling_login(port: u16, t0: Instant) -> anyhow::Result<(Option<u16>, f64)> {
    let head = "POST /login HTTP/1.1\r\nHost: hub\r\nContent-Type: application/x-www-form-urlencoded\r\nContent-Length: 100000\r\n\r\n".to_owned();
    crawling_request(
        port,
        "127.0.0.4",
        head,
        (1000, 10, Duration::from_millis(500)),
        t0,
    )
    .await
}

/// A connection from `from` that sends nothing at all: `true` if the hub refused it at once
/// (503), else when it closed it, s after `t0`.
async fn idle_socket(port: u16, from: String, t0: Instant) -> anyhow::Result<(bool, f64)> {
    let mut s = connect_from(&from, port).await?;
    let status = status_within(&mut s, Duration::from_secs(60)).await;
    Ok((status == Some(503), t0.elapsed().as_secs_f64()))
}

/// A connection from 127.0.0.3 that sends part of a request's headers and no more: `true`
/// if the hub refused it at once (503), `false` when it closed it.
async fn unfinished_headers(port: u16) -> anyhow::Result<bool> {
    use tokio::io::AsyncWriteExt;
    let mut s = connect_from("127.0.0.3", port).await?;
    // a refused connection may be closed before this is written
    let _ = s
        .write_all(b"PUT /api/hub/recordings/x HTTP/1.1\r\nHost: hub\r\nX-Slow: ")
        .await;
    Ok(status_within(&mut s, Duration::from_secs(60)).await == Some(503))
}

/// Results of hostile clients' connections: (status or refused, seconds after the start).
type Outcomes<T> = tokio::task::JoinSet<anyhow::Result<(T, f64)>>;

/// The hostile clients of phase 3, under way.
struct Hostile {
    slow: Outcomes<Option<u16>>,
    logins: Outcomes<Option<u16>>,
    unfinished: tokio::task::JoinSet<anyhow::Result<bool>>,
    idle: Outcomes<bool>,
}

/// Idle sockets, from each of [`IDLE_ADDRESSES`] addresses.
const IDLE_PER_ADDRESS: usize = 50;
const IDLE_ADDRESSES: usize = 8;
const CRAWLING_LOGINS: usize = 50;
const UNFINISHED: usize = 300;

impl Hostile {
    /// Four hostile stations' slow uploads (127.0.0.2), 300 unfinished requests (127.0.0.3),
    /// 50 logins whose bodies crawl (127.0.0.4) and 400 sockets that send nothing from eight
    /// addresses (127.0.0.10-17).
    async fn start(hub_store: &Store, port: u16, t0: Instant) -> anyhow::Result<Self> {
        let mut slow = tokio::task::JoinSet::new();
        for k in 0..4 {
            let token = hub_store
                .create_station_token(&format!("bench-hostile-{k}"))
                .await?;
            slow.spawn(slow_body(port, token, k != 3, t0));
        }
        let mut unfinished = tokio::task::JoinSet::new();
        for _ in 0..UNFINISHED {
            unfinished.spawn(unfinished_headers(port));
        }
        let mut logins = tokio::task::JoinSet::new();
        for _ in 0..CRAWLING_LOGINS {
            logins.spawn(crawling_login(port, t0));
        }
        let mut idle = tokio::task::JoinSet::new();
        for a in 0..IDLE_ADDRESSES {
            for _ in 0..IDLE_PER_ADDRESS {
                idle.spawn(idle_socket(port, format!("127.0.0.{}", 10 + a), t0));
            }
        }
        Ok(Self {
            slow,
            logins,
            unfinished,
            idle,
        })
    }

    /// Waits for every hostile connection's end and counts how each ended into `r`.
    async fn finish(mut self, r: &mut SlowReport) -> anyhow::Result<()> {
        (r.slow_bodies_cut, r.slow_cut_after_s) = cut_off(&mut self.slow).await?;
        (r.crawling_logins_cut, r.crawling_login_cut_after_s) = cut_off(&mut self.logins).await?;
        while let Some(done) = self.unfinished.join_next().await {
            if done?? {
                r.unfinished_refused += 1;
            } else {
                r.unfinished_closed += 1;
            }
        }
        while let Some(done) = self.idle.join_next().await {
            let (refused, at_s) = done??;
            if refused {
                r.idle_refused += 1;
            } else {
                r.idle_closed += 1;
                r.idle_closed_after_s = r.idle_closed_after_s.max(at_s);
            }
        }
        Ok(())
    }
}

/// How many of `set` the hub cut off (408), and the last after how many seconds.
async fn cut_off(set: &mut Outcomes<Option<u16>>) -> anyhow::Result<(usize, f64)> {
    let (mut cut, mut after_s) = (0, 0.0_f64);
    while let Some(done) = set.join_next().await {
        let (status, at_s) = done??;
        if status == Some(408) {
            cut += 1;
            after_s = after_s.max(at_s);
        }
    }
    Ok((cut, after_s))
}

/// Phase 3: the [`Hostile`] clients, while every station ends and sends five attempts of
/// `kib` KiB.
async fn slow_clients(
    stations: &mut Vec<Station>,
    hub_store: &Store,
    port: u16,
    kib: usize,
) -> anyhow::Result<SlowReport> {
    let t0 = Instant::now();
    let hostile = Hostile::start(hub_store, port, t0).await?;
    tokio::time::sleep(Duration::from_millis(500)).await;
    let mut honest = tokio::task::JoinSet::new();
    for mut s in std::mem::take(stations) {
        honest.spawn(async move {
            let mut ms = Vec::new();
            for _ in 0..5 {
                s.end_attempt(kib).await?;
                let t = Instant::now();
                loop {
                    match sync(&s.store, &s.hub, None).await {
                        Ok(r) => {
                            ensure!(r.refused.is_empty(), "refused: {:?}", r.refused);
                            break;
                        }
                        Err(SyncError::Unreachable { .. }) if t.elapsed().as_secs() < 120 => {
                            tokio::time::sleep(Duration::from_millis(100)).await;
                        }
                        Err(e) => return Err(e.into()),
                    }
                }
                ms.push(t.elapsed().as_secs_f64() * 1e3);
            }
            anyhow::Ok((s, ms))
        });
    }
    let mut honest_ms = Vec::new();
    while let Some(done) = honest.join_next().await {
        let (s, ms) = done??;
        honest_ms.extend(ms);
        stations.push(s);
    }
    let summary = Summary::of(&honest_ms);
    let mut report = SlowReport {
        slow_bodies: 4,
        unfinished_headers: UNFINISHED,
        crawling_logins: CRAWLING_LOGINS,
        idle_sockets: IDLE_ADDRESSES * IDLE_PER_ADDRESS,
        honest_attempts: honest_ms.len(),
        honest_p50_ms: summary.median,
        honest_p99_ms: summary.p99,
        honest_max_ms: summary.max,
        ..SlowReport::default()
    };
    hostile.finish(&mut report).await?;
    Ok(report)
}

/// A real recording of a short session (the synthetic expert on the chest wall, 0.5 s).
async fn record_base(path: &Path) -> anyhow::Result<()> {
    let path = path.to_owned();
    tokio::task::spawn_blocking(move || {
        use cutlab_sim::scene::{BuildOptions, Scene};
        let scene = Scene::load("chest-wall", BuildOptions::default())?;
        cutlab_recorder::record::record_expert(&scene, "chest-wall", 0.5, 1, &path)?;
        anyhow::Ok(())
    })
    .await?
}

fn free_port() -> anyhow::Result<u16> {
    Ok(std::net::TcpListener::bind("127.0.0.1:0")?
        .local_addr()?
        .port())
}

pub fn run(o: &Options<'_>) -> anyhow::Result<()> {
    ensure!(o.stations > 0, "--stations must be > 0");
    ensure!(
        o.duration_s > 0.0 && o.duration_s.is_finite(),
        "--duration must be > 0"
    );
    ensure!(o.recording_kib > 0, "--recording-kib must be > 0");
    // a fresh hub and fresh stations each run: this benchmark's own files only
    std::fs::create_dir_all(o.out)?;
    for entry in std::fs::read_dir(o.out)? {
        let path = entry?.path();
        let name = path
            .file_name()
            .and_then(|n| n.to_str())
            .unwrap_or_default();
        if name.starts_with("hub.db") || name == "hub.log" {
            std::fs::remove_file(&path)?;
        } else if name == "hub-recordings" || name.starts_with("station-") {
            std::fs::remove_dir_all(&path)?;
        }
    }
    let rt = tokio::runtime::Builder::new_multi_thread()
        .enable_all()
        .build()
        .context("starting the async runtime")?;
    let report = rt.block_on(bench(o))?;
    if o.json {
        println!("{}", serde_json::to_string_pretty(&report)?);
        ensure!(
            report.lost.is_empty(),
            "{} attempts lost",
            report.lost.len()
        );
        return Ok(());
    }
    println!(
        "| stations | recording KiB | attempts | attempts/s | MB/s | upload p50 ms | p99 ms | max ms |"
    );
    println!("|---:|---:|---:|---:|---:|---:|---:|---:|");
    println!(
        "| {} | {} | {} | {:.1} | {:.1} | {:.1} | {:.1} | {:.1} |",
        report.stations,
        report.recording_kib,
        report.attempts,
        report.attempts_per_s,
        report.megabytes_per_s,
        report.upload_p50_ms,
        report.upload_p99_ms,
        report.upload_max_ms
    );
    println!(
        "hub killed mid-upload of attempts recorded a day ago: {} attempts queued, {} syncs interrupted; after the restart every queue empty in {:.1} s, {} attempts on the hub exactly once, {} scored by the hub as on their station, {} recordings' hashes verified; lost: {}",
        report.kill_queued,
        report.kill_interrupted_syncs,
        report.kill_drain_s,
        report.kill_present_once,
        report.kill_scored,
        report.kill_hashes_verified,
        report.kill_lost
    );
    let w = &report.slow;
    println!(
        "hostile clients: {} slow uploads, {} cut off (the last after {:.1} s); {} unfinished requests, {} refused at once, {} closed; {} crawling logins, {} cut off (the last after {:.1} s); {} idle sockets from {IDLE_ADDRESSES} addresses, {} refused at once, {} closed (the last after {:.1} s); meanwhile {} honest attempts, upload p50 {:.1} ms, p99 {:.1} ms, max {:.1} ms; lost: {}",
        w.slow_bodies,
        w.slow_bodies_cut,
        w.slow_cut_after_s,
        w.unfinished_headers,
        w.unfinished_refused,
        w.unfinished_closed,
        w.crawling_logins,
        w.crawling_logins_cut,
        w.crawling_login_cut_after_s,
        w.idle_sockets,
        w.idle_refused,
        w.idle_closed,
        w.idle_closed_after_s,
        w.honest_attempts,
        w.honest_p50_ms,
        w.honest_p99_ms,
        w.honest_max_ms,
        report.slow_lost
    );
    for why in &report.lost {
        println!("lost: {why}");
    }
    ensure!(
        report.lost.is_empty(),
        "{} attempts lost",
        report.lost.len()
    );
    Ok(())
}

async fn bench(o: &Options<'_>) -> anyhow::Result<Report> {
    let hub_db = o.out.join("hub.db");
    let hub_recordings = o.out.join("hub-recordings");
    let log = o.out.join("hub.log");
    let port = free_port()?;
    let url = format!("http://127.0.0.1:{port}");
    let hub_store = Store::open(&DbLocation::Sqlite(hub_db.clone())).await?;
    hub_store.ensure_builtins().await?;
    let mut stations = Vec::with_capacity(o.stations);
    for k in 0..o.stations {
        let token = hub_store
            .create_station_token(&format!("bench-station-{k}"))
            .await?;
        stations.push(Station::new(k, o.out, &url, &token).await?);
    }
    let hub = HubProcess::start(&hub_db, &hub_recordings, port, &log)?;
    eprintln!(
        "hub {url} ({}), {} stations, {} KiB recordings; loading for {} s",
        hub_db.display(),
        o.stations,
        o.recording_kib,
        o.duration_s
    );

    // 1. load
    let deadline = Instant::now() + Duration::from_secs_f64(o.duration_s);
    let t0 = Instant::now();
    let mut tasks = tokio::task::JoinSet::new();
    for mut s in stations {
        let kib = o.recording_kib;
        tasks.spawn(async move {
            let mut ms = Vec::new();
            while Instant::now() < deadline {
                s.end_attempt(kib).await?;
                let t = Instant::now();
                let r = sync(&s.store, &s.hub, None).await?;
                ms.push(t.elapsed().as_secs_f64() * 1e3);
                ensure!(r.refused.is_empty(), "refused: {:?}", r.refused);
                // the station's copy is not needed again (disk: the hub keeps one of each)
                s.forget_last().await?;
            }
            anyhow::Ok((s, ms))
        });
    }
    let mut stations = Vec::new();
    let mut upload_ms = Vec::new();
    while let Some(done) = tasks.join_next().await {
        let (s, ms) = done??;
        upload_ms.extend(ms);
        stations.push(s);
    }
    let elapsed = t0.elapsed().as_secs_f64();
    let attempts = upload_ms.len();
    let upload = Summary::of(&upload_ms);

    // 2. the kill, while the stations send attempts recorded a day ago (complete, each
    // with its real recording, which the hub scores)
    let base = o.out.join("base.mcap");
    record_base(&base).await?;
    for s in &mut stations {
        for _ in 0..o.queued {
            s.end_day_old_attempt(&base).await?;
        }
    }
    let kill_queued = o.stations * o.queued;
    let mut tasks = tokio::task::JoinSet::new();
    for s in stations {
        tasks.spawn(async move {
            let r = sync(&s.store, &s.hub, None).await;
            (s, r)
        });
    }
    // once the first attempts are in, mid-way through the rest
    let hub_attempts = |store: Store| async move {
        store
            .list_attempts(None, None)
            .await
            .map(|a| a.len())
            .unwrap_or(0)
    };
    let before = hub_attempts(hub_store.clone()).await;
    let t_wait = Instant::now();
    while hub_attempts(hub_store.clone()).await < before + kill_queued / 4
        && t_wait.elapsed() < Duration::from_secs(60)
    {
        tokio::time::sleep(Duration::from_millis(5)).await;
    }
    hub.kill()?;
    let mut stations = Vec::new();
    let mut interrupted = 0;
    while let Some(done) = tasks.join_next().await {
        let (s, r) = done?;
        match r {
            Err(SyncError::Unreachable { .. }) => interrupted += 1,
            Err(e) => return Err(e.into()),
            Ok(r) => ensure!(r.refused.is_empty(), "refused: {:?}", r.refused),
        }
        stations.push(s);
    }
    ensure!(
        interrupted > 0,
        "the kill interrupted no sync: raise --queued or --recording-kib"
    );
    let _hub = HubProcess::start(&hub_db, &hub_recordings, port, &log)?;
    let t_restart = Instant::now();
    for s in &stations {
        loop {
            match sync(&s.store, &s.hub, None).await {
                Ok(r) if r.refused.is_empty() => break,
                Ok(r) => bail!("refused after the restart: {:?}", r.refused),
                Err(SyncError::Unreachable { .. }) => {
                    tokio::time::sleep(Duration::from_millis(100)).await;
                }
                Err(e) => return Err(e.into()),
            }
            ensure!(
                t_restart.elapsed() < Duration::from_secs(300),
                "queues not empty 300 s after the restart"
            );
        }
    }
    let drain_s = t_restart.elapsed().as_secs_f64();

    let recordings = RecordingStore::open(hub_recordings.to_str().context("a UTF-8 path")?)?;
    let kill = verify(&stations, &hub_store, &recordings).await?;

    // 3. hostile clients: slow bodies and unfinished headers from another address, while
    // the stations go on uploading
    let slow = slow_clients(&mut stations, &hub_store, port, o.recording_kib).await?;
    let after = verify(&stations, &hub_store, &recordings).await?;
    // the recordings only: the databases and the hub's log stay for a look
    std::fs::remove_dir_all(&hub_recordings)?;
    for s in &stations {
        for entry in std::fs::read_dir(&s.dir)? {
            let path = entry?.path();
            if path.extension().is_some_and(|e| e == "mcap") {
                std::fs::remove_file(path)?;
            }
        }
    }
    Ok(Report {
        stations: o.stations,
        recording_kib: o.recording_kib,
        duration_s: elapsed,
        attempts,
        attempts_per_s: attempts as f64 / elapsed,
        upload_p50_ms: upload.median,
        upload_p99_ms: upload.p99,
        upload_max_ms: upload.max,
        megabytes_per_s: (attempts * o.recording_kib * 1024) as f64 / elapsed / 1e6,
        kill_queued,
        kill_interrupted_syncs: interrupted,
        kill_present_once: kill.present,
        kill_scored: kill.scored,
        kill_hashes_verified: kill.verified,
        kill_lost: kill.lost.len(),
        kill_drain_s: drain_s,
        slow,
        slow_lost: after.lost.len(),
        lost: kill.lost.into_iter().chain(after.lost).collect(),
    })
}
