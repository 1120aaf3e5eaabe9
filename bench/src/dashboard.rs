//! `cutlab bench dashboard`: `--trainees` x `--attempts` synthetic scored attempts, the
//! dashboard on a loopback port in this process, and `--clients` concurrent keep-alive
//! clients on the progress page and on the progress API for `--duration` seconds each:
//! requests per second and latency percentiles (goal: p99 under 50 ms). Given several
//! databases (`--bench-db` again, e.g. an SQLite file and a `postgres://` URL), each is
//! seeded and loaded in turn and the figures are printed side by side.

use std::time::{Duration, Instant};

use anyhow::Context;
use cutlab_assessor::store::{DbLocation, Store};
use cutlab_dashboard::seed::{LOAD_INSTRUCTOR, seed_load};
use cutlab_dashboard::{AppState, Config};

use crate::load::{LoadReport, login, run};

pub struct Options<'a> {
    pub dbs: &'a [DbLocation],
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
    anyhow::ensure!(!o.dbs.is_empty(), "no --bench-db given");
    let rt = tokio::runtime::Builder::new_multi_thread()
        .enable_all()
        .build()
        .context("starting the async runtime")?;
    let mut all = Vec::with_capacity(o.dbs.len());
    for db in o.dbs {
        all.push(rt.block_on(load_one(o, db))?);
    }
    print(&all, o.json)
}

/// The figures of one database.
#[derive(serde::Serialize)]
struct DbReport {
    /// `SQLite` or `PostgreSQL`.
    engine: &'static str,
    /// Where (a URL's password hidden).
    database: String,
    reports: Vec<LoadReport>,
}

/// Seeds `db`, serves it and loads it.
async fn load_one(o: &Options<'_>, db: &DbLocation) -> anyhow::Result<DbReport> {
    let store = Store::open(db)
        .await
        .with_context(|| format!("opening {db}"))?;
    let engine = store.db().engine();
    let t0 = Instant::now();
    let ids = seed_load(&store, o.trainees, o.attempts).await?;
    eprintln!(
        "seeded {} trainees x {} attempts in {} ({:.1} s)",
        ids.len(),
        o.attempts,
        db,
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
    Ok(DbReport {
        engine,
        database: db.to_string(),
        reports,
    })
}

fn print(all: &[DbReport], json: bool) -> anyhow::Result<()> {
    if json {
        println!("{}", serde_json::to_string_pretty(all)?);
        return Ok(());
    }
    println!(
        "| database | target | clients | requests | errors | req/s | p50 ms | p90 ms | p99 ms | max ms | KB/answer |"
    );
    println!("|---|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|");
    for (d, r) in all
        .iter()
        .flat_map(|d| d.reports.iter().map(move |r| (d, r)))
    {
        println!(
            "| {} | {} | {} | {} | {} | {:.0} | {:.1} | {:.1} | {:.1} | {:.1} | {:.1} |",
            d.engine,
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
