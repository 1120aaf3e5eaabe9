//! `cutlab serve`: the web dashboard on the assessment database (and the end of
//! `cutlab demo --addr`); `cutlab station`: the same for one trainee on this PC, the station
//! page opened in the browser.

use std::path::Path;

use anyhow::Context;
use cutlab_assessor::AssessError;
use cutlab_assessor::store::{DbLocation, Role, Store};
use cutlab_dashboard::{AppState, Config, DEMO_ACCOUNTS};
use cutlab_haptics::TimeStep;
use cutlab_haptics::device::{DeviceSpec, IgtlOptions};

/// What a served dashboard runs with.
#[derive(Debug)]
pub struct Options<'a> {
    pub db: &'a DbLocation,
    pub addr: &'a str,
    /// Seed the demo first (a directory for its recordings).
    pub demo: Option<&'a Path>,
    /// The station's devices besides the page's pointer.
    pub station_devices: Vec<DeviceSpec>,
    /// The station's simulation step.
    pub station_time_step: TimeStep,
    /// How long a station attempt waits for its page, s.
    pub station_absence_s: f64,
    pub igtl: IgtlOptions,
    /// The recording store (`--recordings`): where the station puts its attempts'
    /// recordings and the dashboard serves them from.
    pub recordings: Option<String>,
    /// The hub the station sends its ended attempts to (`--hub`).
    pub hub: Option<cutlab_station::sync::Hub>,
    /// A kiosk for one trainee (`cutlab station`).
    pub kiosk: Option<Kiosk>,
    /// Session cookies marked `Secure` (`--secure-cookies`).
    pub secure_cookies: bool,
    /// The dashboard's public address (`--public-url`).
    pub public_url: Option<cutlab_dashboard::PublicUrl>,
}

impl<'a> Options<'a> {
    /// The dashboard on `db` at `addr` with the station's defaults (its pointer only, the
    /// scene's step, 30 s of absence), no demo and no kiosk.
    pub fn dashboard(
        db: &'a DbLocation,
        addr: &'a str,
        recordings: Option<String>,
        hub: Option<cutlab_station::sync::Hub>,
    ) -> Self {
        Self {
            db,
            addr,
            demo: None,
            station_devices: Vec::new(),
            station_time_step: TimeStep::Scene,
            station_absence_s: 30.0,
            igtl: IgtlOptions::default(),
            recordings,
            hub,
            kiosk: None,
            secure_cookies: false,
            public_url: None,
        }
    }
}

/// `cutlab station`: one trainee at this PC.
#[derive(Debug)]
pub struct Kiosk {
    pub trainee: String,
    /// Open the station in the default browser (else only print its link).
    pub open_browser: bool,
}

/// Serves the dashboard on `addr` until Ctrl-C; with `demo` (a directory for recordings),
/// first makes sure the demo accounts, cohort, curriculum and simulated attempts exist (see
/// [`crate::demo_seed`]) and prints the accounts; with a kiosk, logs its trainee in through a
/// one-time link (created as a trainee without a password if new) and opens it.
pub fn run(o: Options<'_>) -> anyhow::Result<()> {
    let Options { db, addr, demo, .. } = o;
    anyhow::ensure!(
        (1.0..=3600.0).contains(&o.station_absence_s),
        "--absence-s must be between 1 and 3600 s, not {}",
        o.station_absence_s
    );
    if let Some(dir) = demo
        && !crate::demo_seed::run(db, dir)?
    {
        println!("demo curriculum and attempts already in {}", db);
    }
    let rt = tokio::runtime::Builder::new_multi_thread()
        .enable_all()
        .build()
        .context("starting the async runtime")?;
    rt.block_on(async {
        let store = Store::open(db)
            .await
            .with_context(|| format!("opening the database {}", db))?;
        store.ensure_builtins().await?;
        let recordings =
            cutlab_assessor::recordings::RecordingStore::connect_if(o.recordings.as_deref())
                .await
                .context("opening the recording store")?;
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
            db
        );
        let shutdown = async {
            // no signal handler: run until killed
            if tokio::signal::ctrl_c().await.is_err() {
                std::future::pending::<()>().await;
            }
        };
        // the station's recordings beside an SQLite database, like the demo's
        let station_dir = crate::beside_db(db, "station-attempts");
        let config = Config {
            station: cutlab_station::StationSettings {
                devices: o.station_devices,
                time_step: o.station_time_step,
                absence_s: o.station_absence_s,
                igtl: o.igtl,
                recordings: recordings.clone(),
                hub: o.hub.clone(),
                ..cutlab_station::StationSettings::new(station_dir)
            },
            recordings,
            secure_cookies: o.secure_cookies,
            public_url: o.public_url.clone(),
            ..Config::default()
        };
        let state = AppState::new(store, config)?;
        // attempts left running by a station that died: ended before new ones start
        cutlab_station::attempt::end_abandoned_and_say(
            state.store(),
            state.config().recordings.as_ref(),
        )
        .await;
        if let Some(hub) = o.hub.clone() {
            // the station's queue now and every minute: a hub that was down gets it later
            println!("sending ended attempts to the hub {}", hub.url());
            tokio::spawn(cutlab_station::sync::keep_syncing(
                state.store().clone(),
                hub,
                state.config().recordings.clone(),
                cutlab_station::sync::RETRY_EVERY,
            ));
        }
        if let Some(kiosk) = &o.kiosk {
            let at = listener.local_addr()?;
            let url = format!("http://{at}{}", kiosk_link(&state, &kiosk.trainee).await?);
            println!("station for {}: {url}", kiosk.trainee);
            if kiosk.open_browser
                && let Err(e) = webbrowser::open(&url)
            {
                println!("(could not open a browser: {e}; open the link above)");
            }
        }
        cutlab_dashboard::serve(listener, state, shutdown)
            .await
            .context("serving")?;
        anyhow::Ok(())
    })
}

/// The kiosk's one-time link for `trainee`, who is created (a trainee without a password: the
/// kiosk is their only way in) if the database does not know them.
async fn kiosk_link(state: &AppState, trainee: &str) -> anyhow::Result<String> {
    let store = state.store();
    match store.user_by_name(trainee).await {
        Ok(_) => {}
        Err(AssessError::NotFound(_)) => {
            store
                .create_user(trainee, Role::Trainee, None)
                .await
                .with_context(|| format!("adding the trainee {trainee:?}"))?;
            println!("added trainee {trainee} (no password: the station's link logs them in)");
        }
        Err(e) => return Err(e).context("reading the users"),
    }
    cutlab_dashboard::auth::kiosk::issue(state, trainee)
        .await
        .map_err(|e| anyhow::anyhow!("the station's link for {trainee}: {e}"))
}
