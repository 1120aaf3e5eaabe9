//! `cutlab serve`: the web dashboard on the assessment database (and the end of
//! `cutlab demo --addr`).

use std::path::Path;

use anyhow::Context;
use cutlab_assessor::store::Store;
use cutlab_dashboard::{AppState, Config, DEMO_ACCOUNTS};

/// Serves the dashboard on `addr` until Ctrl-C; with `demo` (a directory for recordings),
/// first makes sure the demo accounts, cohort, curriculum and simulated attempts exist (see
/// [`crate::demo_seed`]) and prints the accounts.
pub fn run(db: &Path, addr: &str, demo: Option<&Path>) -> anyhow::Result<()> {
    if let Some(dir) = demo
        && !crate::demo_seed::run(db, dir)?
    {
        println!("demo curriculum and attempts already in {}", db.display());
    }
    let rt = tokio::runtime::Builder::new_multi_thread()
        .enable_all()
        .build()
        .context("starting the async runtime")?;
    rt.block_on(async {
        let store = Store::open(db)
            .await
            .with_context(|| format!("opening the database {}", db.display()))?;
        store.ensure_builtins().await?;
        if demo.is_some() {
            println!("demo accounts (user / password / role):");
            for a in DEMO_ACCOUNTS {
                println!("  {:8} {:16} {}", a.name, a.password, a.role);
            }
        }
        let listener = tokio::net::TcpListener::bind(addr)
            .await
            .with_context(|| format!("listening on {addr}"))?;
        println!(
            "dashboard: http://{} (database {}); Ctrl-C stops it",
            listener.local_addr()?,
            db.display()
        );
        let shutdown = async {
            // no signal handler: run until killed
            if tokio::signal::ctrl_c().await.is_err() {
                std::future::pending::<()>().await;
            }
        };
        // the station's recordings beside the database, like the demo's
        let station_dir = db
            .parent()
            .unwrap_or_else(|| Path::new("."))
            .join("station-attempts");
        let config = Config {
            station: cutlab_station::StationSettings::new(station_dir),
            ..Config::default()
        };
        cutlab_dashboard::serve(listener, AppState::new(store, config)?, shutdown)
            .await
            .context("serving")?;
        anyhow::Ok(())
    })
}
