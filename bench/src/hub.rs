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
    kill_drain_s: f64,
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

    /// An ended attempt with a recording of `kib` KiB no other attempt has.
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
        self.store.finish_attempt(a.id, &[]).await?;
        Ok(())
    }
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
        "hub killed mid-upload: {} attempts queued, {} syncs interrupted; after the restart every queue empty in {:.1} s, {} attempts on the hub exactly once, {} recordings' hashes verified",
        report.kill_queued,
        report.kill_interrupted_syncs,
        report.kill_drain_s,
        report.kill_present_once,
        report.kill_hashes_verified
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

    // 2. the kill
    for s in &mut stations {
        for _ in 0..o.queued {
            s.end_attempt(o.recording_kib).await?;
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

    // every attempt of every station on the hub exactly once, its recording intact
    let recordings = RecordingStore::open(hub_recordings.to_str().context("a UTF-8 path")?)?;
    let mut present = 0;
    let mut verified = 0;
    for s in &stations {
        ensure!(
            s.store.sync_queue().await?.is_empty(),
            "a station's queue is not empty"
        );
        for a in s.store.list_attempts(None, None).await? {
            let uuid = a.uuid.clone().context("an attempt without id")?;
            let h = hub_store.attempt_by_uuid(&uuid).await?;
            ensure!(
                h.status == AttemptStatus::Complete && h.started_ns == a.started_ns,
                "attempt {uuid} is {:?} on the hub",
                h.status
            );
            present += 1;
            let key = h.recording_sha256.context("an attempt without recording")?;
            // its content hashes to its key (else an error), and is the station's file where
            // the station kept it (the attempts of the kill)
            let bytes = recordings.get(&key).await?;
            if let Ok(local) =
                tokio::fs::read(a.recording_path.as_deref().unwrap_or_default()).await
            {
                ensure!(bytes == local, "attempt {uuid}'s recording differs");
            }
            verified += 1;
        }
    }
    // each found by its id (unique on the hub) and none besides: each exactly once
    let hub_total = hub_store.list_attempts(None, None).await?.len();
    ensure!(
        hub_total == present,
        "the hub has {hub_total} attempts, the stations {present}"
    );
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
        kill_present_once: present,
        kill_hashes_verified: verified,
        kill_drain_s: drain_s,
    })
}
