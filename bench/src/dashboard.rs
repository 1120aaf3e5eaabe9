//! `cutlab bench dashboard`: `--trainees` x `--attempts` synthetic scored attempts, the
//! dashboard on a loopback port in this process, and `--clients` concurrent keep-alive
//! clients on the progress page and on the progress API for `--duration` seconds each:
//! requests per second and latency percentiles (goal: p99 under 50 ms).

use std::path::Path;
use std::time::{Duration, Instant};

use anyhow::Context;
use cutlab_assessor::store::Store;
use cutlab_dashboard::seed::{LOAD_INSTRUCTOR, seed_load};
use cutlab_dashboard::{AppState, Config};

use crate::load::{LoadReport, login, run};

pub struct Options<'a> {
    pub db: &'a Path,
    pub trainees: usize,
    pub attempts: usize,
    pub clients: usize,
    pub duration_s: f64,
    pub json: bool,
}

pub fn run_bench(o: &Options<'_>) -> anyhow::Result<()> {
    anyhow::ensure!(
        o.duration_s > 0.0 && o.duration_s.is_finite(),
        "--duration must be > 0"
    );
    anyhow::ensure!(
        o.clients > 0 && o.trainees > 0,
        "--clients and --trainees must be > 0"
    );
    let rt = tokio::runtime::Builder::new_multi_thread()
        .enable_all()
        .build()
        .context("starting the async runtime")?;
    rt.block_on(async {
        let store = Store::open(o.db)
            .await
            .with_context(|| format!("opening {}", o.db.display()))?;
        let t0 = Instant::now();
        let ids = seed_load(&store, o.trainees, o.attempts).await?;
        eprintln!(
            "seeded {} trainees x {} attempts in {} ({:.1} s)",
            ids.len(),
            o.attempts,
            o.db.display(),
            t0.elapsed().as_secs_f64()
        );
        let listener = tokio::net::TcpListener::bind("127.0.0.1:0").await?;
        let addr = listener.local_addr()?;
        let (stop, stopped) = tokio::sync::oneshot::channel::<()>();
        let server = tokio::spawn(cutlab_dashboard::serve(
            listener,
            AppState::new(store, Config::default())?,
            async move {
                let _ = stopped.await;
            },
        ));
        let cookie = login(addr, LOAD_INSTRUCTOR.name, LOAD_INSTRUCTOR.password).await?;
        let d = Duration::from_secs_f64(o.duration_s);
        let pages: Vec<String> = ids.iter().map(|id| format!("/trainees/{id}")).collect();
        let api: Vec<String> = ids
            .iter()
            .map(|id| format!("/api/trainees/{id}/progress"))
            .collect();
        // warm up (connections, caches), then measure
        run(
            addr,
            "warm-up",
            &pages,
            &cookie,
            o.clients,
            Duration::from_secs(1),
        )
        .await;
        let reports = vec![
            run(
                addr,
                "progress page /trainees/{id}",
                &pages,
                &cookie,
                o.clients,
                d,
            )
            .await,
            run(
                addr,
                "progress API /api/trainees/{id}/progress",
                &api,
                &cookie,
                o.clients,
                d,
            )
            .await,
        ];
        let _ = stop.send(());
        let _ = server.await;
        print(&reports, o.json)
    })
}

fn print(reports: &[LoadReport], json: bool) -> anyhow::Result<()> {
    if json {
        println!("{}", serde_json::to_string_pretty(reports)?);
        return Ok(());
    }
    println!(
        "| target | clients | requests | errors | req/s | p50 ms | p90 ms | p99 ms | max ms | KB/answer |"
    );
    println!("|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|");
    for r in reports {
        println!(
            "| {} | {} | {} | {} | {:.0} | {:.1} | {:.1} | {:.1} | {:.1} | {:.1} |",
            r.target,
            r.clients,
            r.requests,
            r.errors,
            r.requests_per_s,
            r.p50_ms,
            r.p90_ms,
            r.p99_ms,
            r.max_ms,
            r.mean_bytes / 1e3
        );
    }
    Ok(())
}
