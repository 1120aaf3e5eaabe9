//! `cutlab sync` (a station sends its queue to its hub) and `cutlab hub token` (a hub's
//! station tokens).

use anyhow::Context;
use clap::Subcommand;
use cutlab_assessor::DbLocation;
use cutlab_assessor::recordings::RecordingStore;
use cutlab_assessor::store::{Store, iso8601};
use cutlab_station::sync::{HUB_ENV, HUB_TOKEN_ENV, Hub};

#[derive(Debug, Subcommand)]
pub enum HubCommand {
    /// The tokens of the stations that may upload attempts to this hub.
    Token {
        #[command(subcommand)]
        command: TokenCommand,
    },
}

#[derive(Debug, Subcommand)]
pub enum TokenCommand {
    /// A new station and its token, printed once (the hub keeps only its hash).
    Create { name: String },
    /// Revoke a station's token: its uploads get 401 from now on.
    Revoke { name: String },
    /// The stations, with when their token was made, last used, revoked.
    List,
}

/// A variable's value when set and not empty.
fn env(name: &str) -> Option<String> {
    std::env::var(name).ok().filter(|v| !v.trim().is_empty())
}

/// The hub of `--hub`/`--hub-token` (else `$CUTLAB_HUB`/`$CUTLAB_HUB_TOKEN`); `None` when
/// no hub is named.
pub fn hub(url: Option<&str>, token: Option<&str>) -> anyhow::Result<Option<Hub>> {
    let Some(url) = url.map(str::to_owned).or_else(|| env(HUB_ENV)) else {
        return Ok(None);
    };
    let token = token.map(str::to_owned).or_else(|| env(HUB_TOKEN_ENV));
    Ok(Some(Hub::new(&url, token.as_deref().unwrap_or_default())?))
}

fn runtime() -> anyhow::Result<tokio::runtime::Runtime> {
    tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
        .context("starting the async runtime")
}

async fn open(db: &DbLocation) -> anyhow::Result<Store> {
    Store::open(db)
        .await
        .with_context(|| format!("opening the database {db}"))
}

/// `cutlab sync`: the station's queue to its hub, once.
pub fn sync(db: &DbLocation, hub: Option<Hub>, recordings: Option<&str>) -> anyhow::Result<()> {
    let hub = hub.with_context(|| format!("no hub: name one with --hub or ${HUB_ENV}"))?;
    runtime()?.block_on(async {
        let store = open(db).await?;
        let recordings = RecordingStore::connect_if(recordings)
            .await
            .context("opening the recording store")?;
        let result = cutlab_station::sync::sync(&store, &hub, recordings.as_ref()).await;
        store.close().await;
        let report = result?;
        println!(
            "{}: {} attempt(s) sent, {} already there, {} left queued",
            hub.url(),
            report.uploaded,
            report.already,
            report.refused.len()
        );
        for (id, why) in &report.refused {
            println!("  attempt {id}: {why}");
        }
        anyhow::ensure!(
            report.refused.is_empty(),
            "{} attempt(s) refused by the hub or missing here (queued; see above)",
            report.refused.len()
        );
        Ok(())
    })
}

/// `cutlab hub ...`.
pub fn run(db: &DbLocation, command: HubCommand) -> anyhow::Result<()> {
    runtime()?.block_on(async {
        let store = open(db).await?;
        let HubCommand::Token { command } = command;
        let result = match command {
            TokenCommand::Create { name } => store.create_station_token(&name).await.map(|t| {
                println!("station {name}: its token (shown once; give it to the station as --hub-token or ${HUB_TOKEN_ENV}):");
                println!("{t}");
            }),
            TokenCommand::Revoke { name } => store
                .revoke_station_token(&name)
                .await
                .map(|()| println!("station {name}: token revoked")),
            TokenCommand::List => store.list_station_tokens().await.map(|list| {
                for s in list {
                    let when = |ns: Option<i64>| ns.map_or_else(|| "-".to_owned(), iso8601);
                    println!(
                        "{:<20} made {}  last used {}  revoked {}",
                        s.name,
                        iso8601(s.created_ns),
                        when(s.last_used_ns),
                        when(s.revoked_ns)
                    );
                }
            }),
        };
        store.close().await;
        Ok(result?)
    })
}
