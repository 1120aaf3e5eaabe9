//! An attempt's recordings: downloads of its `.mcap` and `.rrd`, and replay review in rerun's
//! own web viewer, served by this process from the `re_web_viewer_server` crate's embedded
//! build (wasm + JavaScript, shipped in that crate's crates.io package: nothing is fetched
//! from the network).
//!
//! Only the attempt's stored recording path (and the `.rrd` beside it) is ever served: the
//! routes take an attempt id, never a path.

use std::io::Write as _;
use std::sync::OnceLock;

use axum::Router;
use axum::body::{Body, Bytes};
use axum::extract::{RawQuery, State};
use axum::http::{HeaderMap, HeaderValue, StatusCode, header};
use axum::response::{IntoResponse, Response};
use axum::routing::get;
use maud::html;
use re_web_viewer_server::WebViewerData;

use cutlab_recorder::rerun_log::TIMELINE_SIM_TIME;

use crate::AppState;
use crate::access::visible_attempt;
use crate::auth::CurrentUser;
use crate::data::debrief;
use crate::error::AppError;
use crate::extract::{Id, Path};
use crate::pages::{attempt, layout};

/// rerun's web viewer files, read once.
#[derive(Debug)]
pub struct Viewer {
    files: Option<Vec<ViewerFile>>,
}

/// One file of the viewer, and its gzip form once a browser has asked for it.
#[derive(Debug)]
struct ViewerFile {
    name: &'static str,
    mime: &'static str,
    bytes: Bytes,
    /// Compressed on the first request that accepts gzip, then kept: the 42 MB wasm goes out
    /// as about 14 MB (docs/decisions.md, "The replay viewer goes out compressed").
    gzip: OnceLock<Bytes>,
}

impl ViewerFile {
    fn new(name: &'static str, mime: &'static str, bytes: Bytes) -> Self {
        Self {
            name,
            mime,
            bytes,
            gzip: OnceLock::new(),
        }
    }

    /// Worth compressing: the script and the wasm (the rest are small or compressed already).
    fn compresses(&self) -> bool {
        self.bytes.len() > 16 * 1024 && !self.mime.starts_with("image/")
    }

    /// The gzip form, compressed by the first caller (others wait for it).
    fn gzipped(&self) -> Bytes {
        self.gzip
            .get_or_init(|| {
                let mut gz = flate2::write::GzEncoder::new(
                    Vec::with_capacity(self.bytes.len() / 3),
                    flate2::Compression::default(),
                );
                // writing to a Vec cannot fail
                let _ = gz.write_all(&self.bytes);
                Bytes::from(gz.finish().unwrap_or_default())
            })
            .clone()
    }
}

impl Viewer {
    /// The viewer embedded in `re_web_viewer_server` (none if that build has no assets).
    pub fn load() -> Self {
        match WebViewerData::load(None) {
            Ok(d) => Self {
                files: Some(vec![
                    ViewerFile::new(
                        "index.html",
                        "text/html; charset=utf-8",
                        Bytes::from(offline_index(d.index_html())),
                    ),
                    ViewerFile::new("re_viewer.js", "text/javascript", copy(d.viewer_js())),
                    ViewerFile::new(
                        "re_viewer_bg.wasm",
                        "application/wasm",
                        copy(d.viewer_wasm()),
                    ),
                    ViewerFile::new("favicon.ico", "image/x-icon", copy(d.favicon())),
                    ViewerFile::new(
                        "apple-touch-icon.png",
                        "image/png",
                        copy(d.apple_touch_icon()),
                    ),
                    ViewerFile::new("sw.js", "text/javascript", copy(d.sw_js())),
                ]),
            },
            Err(e) => {
                tracing::error!("rerun web viewer unavailable: {e}");
                Self { files: None }
            }
        }
    }

    pub fn available(&self) -> bool {
        self.files.is_some()
    }

    fn file(&self, name: &str) -> Option<&ViewerFile> {
        self.files.as_ref()?.iter().find(|f| f.name == name)
    }
}

fn copy(bytes: &[u8]) -> Bytes {
    Bytes::copy_from_slice(bytes)
}

/// How the viewer's `index.html` hands its app to the page: rerun 0.36 passes `start()`'s
/// result (nothing) to `on_app_started`, which stores it as `window._handle`; we pass the
/// `WebHandle` itself, so the replay page can move the viewer's time cursor to a note.
const APP_STARTED: (&str, &str) = (
    ".then(on_app_started)",
    ".then(() => on_app_started(handle))",
);

/// The viewer's `index.html` without its links to Google's font servers (the viewer draws its
/// own text; offline, those requests would only fail), its `WebHandle` in `window._handle`.
fn offline_index(html: &[u8]) -> Vec<u8> {
    let text = String::from_utf8_lossy(html).replace(APP_STARTED.0, APP_STARTED.1);
    let mut out = String::with_capacity(text.len());
    let mut rest: &str = &text;
    while let Some(start) = rest.find("<link") {
        let Some(len) = rest[start..].find('>') else {
            break;
        };
        let tag = &rest[start..start + len + 1];
        out.push_str(&rest[..start]);
        if !(tag.contains("fonts.googleapis.com") || tag.contains("fonts.gstatic.com")) {
            out.push_str(tag);
        }
        rest = &rest[start + len + 1..];
    }
    out.push_str(rest);
    out.into_bytes()
}

pub fn router() -> Router<AppState> {
    Router::new()
        .route("/attempts/{id}/recording.mcap", get(mcap))
        .route("/attempts/{id}/recording.rrd", get(rrd))
        .route("/attempts/{id}/replay", get(replay_page))
        .route(
            "/static/replay.js",
            get(|| async {
                crate::pages::static_file("text/javascript", include_str!("pages/static/replay.js"))
            }),
        )
        .route(
            "/attempts/{id}/grant/{grant}/recording.rrd",
            get(granted_rrd),
        )
        .route("/viewer/", get(viewer_index))
        .route("/viewer/{file}", get(viewer_file))
}

/// Which of an attempt's two recordings.
#[derive(Debug, Clone, Copy)]
enum Kind {
    Mcap,
    Rrd,
}

async fn mcap(
    State(state): State<AppState>,
    user: CurrentUser,
    Id(id): Id,
    headers: HeaderMap,
) -> Result<Response, AppError> {
    let a = visible_attempt(&state, &user, id).await?;
    send_recording(&state, &a, Kind::Mcap, &headers).await
}

async fn rrd(
    State(state): State<AppState>,
    user: CurrentUser,
    Id(id): Id,
    headers: HeaderMap,
) -> Result<Response, AppError> {
    let a = visible_attempt(&state, &user, id).await?;
    send_recording(&state, &a, Kind::Rrd, &headers).await
}

/// The `.rrd` for rerun's web viewer, which fetches without cookies: the path carries a
/// grant issued by the replay page (see [`crate::auth::grants`]).
async fn granted_rrd(
    State(state): State<AppState>,
    Path((id, grant)): Path<(i64, String)>,
    headers: HeaderMap,
) -> Result<Response, AppError> {
    let Some(g) = state.grants().check(id, &grant) else {
        return Err(AppError::NotFound);
    };
    // the grant ends with the login it was issued in
    if !crate::auth::sessions::alive_by_prefix(&state, g.user_id, &g.session_ref).await? {
        return Err(AppError::NotFound);
    }
    let a = state.store().get_attempt(id).await?;
    send_recording(&state, &a, Kind::Rrd, &headers).await
}

/// An attempt's recording as an attachment named by us (`attempt-N.ext`, never the stored
/// path): from the recording store when the attempt has a key there and the server has a
/// store, else from the recorded path. A `Range: bytes=...` request gets that part (206).
async fn send_recording(
    state: &AppState,
    a: &cutlab_assessor::store::Attempt,
    kind: Kind,
    headers: &HeaderMap,
) -> Result<Response, AppError> {
    let (key, ext) = match kind {
        Kind::Mcap => (a.recording_sha256.as_deref(), "mcap"),
        Kind::Rrd => (a.rrd_sha256.as_deref(), "rrd"),
    };
    let name = format!("attempt-{}.{ext}", a.id);
    let range = headers.get(header::RANGE).and_then(|v| v.to_str().ok());
    if let (Some(key), Some(store)) = (key, state.config().recordings.as_ref()) {
        match send_object(store, key, &name, range).await {
            // not in this server's store: the file, if this machine has it
            Err(AppError::NotFound) => {}
            other => return other,
        }
    }
    // the attempt's own files, the only ones ever served for it
    let (mcap, rrd) = a.recording_files().ok_or(AppError::NotFound)?;
    let path = match kind {
        Kind::Mcap => mcap,
        Kind::Rrd => rrd,
    };
    send_file(&path, &name, range).await
}

/// The part of a `len`-byte body a `Range` header asks for: `Ok(None)` for the whole (no
/// header, or one this server does not answer in part: several ranges, other units),
/// `Err(())` for a range past the end (416).
fn requested_range(range: Option<&str>, len: u64) -> Result<Option<std::ops::Range<u64>>, ()> {
    let Some(spec) = range.and_then(|r| r.trim().strip_prefix("bytes=")) else {
        return Ok(None);
    };
    if spec.contains(',') {
        return Ok(None);
    }
    let Some((first, last)) = spec.split_once('-') else {
        return Ok(None);
    };
    let (first, last) = (first.trim(), last.trim());
    let r = match (first.parse::<u64>(), last.parse::<u64>()) {
        // bytes=a-b
        (Ok(a), Ok(b)) if a <= b => a..b.saturating_add(1).min(len),
        // bytes=a-
        (Ok(a), Err(_)) if last.is_empty() => a..len,
        // bytes=-n: the last n
        (Err(_), Ok(n)) if first.is_empty() => len.saturating_sub(n)..len,
        _ => return Ok(None),
    };
    if r.start >= len || r.is_empty() {
        return Err(());
    }
    Ok(Some(r))
}

/// The response's headers and status for `range` of a `len`-byte body.
fn ranged(
    body: Body,
    len: u64,
    range: Option<&std::ops::Range<u64>>,
    download_name: &str,
) -> Response {
    let mut r = body.into_response();
    let h = r.headers_mut();
    h.insert(
        header::CONTENT_TYPE,
        HeaderValue::from_static("application/octet-stream"),
    );
    h.insert(header::ACCEPT_RANGES, HeaderValue::from_static("bytes"));
    if let Ok(v) = HeaderValue::from_str(&format!("attachment; filename=\"{download_name}\"")) {
        h.insert(header::CONTENT_DISPOSITION, v);
    }
    match range {
        Some(part) => {
            h.insert(
                header::CONTENT_LENGTH,
                HeaderValue::from(part.end - part.start),
            );
            if let Ok(v) =
                HeaderValue::from_str(&format!("bytes {}-{}/{len}", part.start, part.end - 1))
            {
                h.insert(header::CONTENT_RANGE, v);
            }
            *r.status_mut() = StatusCode::PARTIAL_CONTENT;
        }
        None => {
            h.insert(header::CONTENT_LENGTH, HeaderValue::from(len));
        }
    }
    r
}

/// 416 for a range past the end of a `len`-byte body.
fn unsatisfiable(len: u64) -> Response {
    let mut r = StatusCode::RANGE_NOT_SATISFIABLE.into_response();
    if let Ok(v) = HeaderValue::from_str(&format!("bytes */{len}")) {
        r.headers_mut().insert(header::CONTENT_RANGE, v);
    }
    r
}

/// A regular file, streamed (the part a range asks for).
async fn send_file(
    path: &std::path::Path,
    download_name: &str,
    range: Option<&str>,
) -> Result<Response, AppError> {
    use tokio::io::{AsyncReadExt, AsyncSeekExt};
    let mut file = match tokio::fs::File::open(path).await {
        Ok(f) => f,
        Err(_) => return Err(AppError::NotFound),
    };
    let meta = file.metadata().await.map_err(|_| AppError::NotFound)?;
    if !meta.is_file() {
        return Err(AppError::NotFound);
    }
    let len = meta.len();
    let Ok(part) = requested_range(range, len) else {
        return Ok(unsatisfiable(len));
    };
    let body = match &part {
        Some(p) => {
            file.seek(std::io::SeekFrom::Start(p.start))
                .await
                .map_err(|e| AppError::Internal(format!("reading a recording: {e}")))?;
            Body::from_stream(tokio_util::io::ReaderStream::new(
                file.take(p.end - p.start),
            ))
        }
        None => Body::from_stream(tokio_util::io::ReaderStream::new(file)),
    };
    Ok(ranged(body, len, part.as_ref(), download_name))
}

/// An object of the recording store (the part a range asks for; the whole is checked against
/// its key before a byte is sent).
async fn send_object(
    store: &cutlab_assessor::recordings::RecordingStore,
    key: &str,
    download_name: &str,
    range: Option<&str>,
) -> Result<Response, AppError> {
    let len = store.size(key).await?;
    let Ok(part) = requested_range(range, len) else {
        return Ok(unsatisfiable(len));
    };
    let body = match &part {
        Some(p) => store.get_range(key, p.clone()).await?,
        None => store.get(key).await?,
    };
    Ok(ranged(Body::from(body), len, part.as_ref(), download_name))
}

/// The viewer's URL opening attempt `id`'s `.rrd` through `grant`.
pub fn viewer_url(origin: &str, id: i64, grant: &str) -> String {
    let rrd = format!("{origin}/attempts/{id}/grant/{grant}/recording.rrd");
    let q: String = form_urlencoded::Serializer::new(String::new())
        .append_pair("url", &rrd)
        .finish();
    format!("/viewer/?{q}&hide_welcome_screen")
}

/// The replay page of attempt `id`, naming the moment `at_ns` (a review note's) if given.
pub fn replay_url(id: i64, at_ns: Option<i64>) -> String {
    match at_ns {
        Some(at) => format!("/attempts/{id}/replay?at={}", at as f64 / 1e9),
        None => format!("/attempts/{id}/replay"),
    }
}

/// The replay in rerun's viewer with the attempt's notes below it and, for instructors, a form
/// that pins a note to a moment. `?at=` (seconds, a note's link) names the moment to look at:
/// rerun 0.36's web viewer takes no start time for a file it fetches over HTTP (its `#when=`
/// fragment is ignored there), so our `static/replay.js` moves its time cursor there through
/// the viewer's `WebHandle` once the file has loaded that far (and to a note's moment when
/// one is clicked); the page also names the moment.
async fn replay_page(
    State(state): State<AppState>,
    user: CurrentUser,
    headers: HeaderMap,
    Id(id): Id,
    RawQuery(query): RawQuery,
) -> Result<Response, AppError> {
    let at_ns = match form_urlencoded::parse(query.unwrap_or_default().as_bytes())
        .find(|(k, _)| k == "at")
    {
        Some((_, v)) => debrief::parse_moment(&v)?,
        None => None,
    };
    let a = visible_attempt(&state, &user, id).await?;
    let notes = debrief::comments(&state, id).await?;
    let has_rrd = crate::data::attempt::RecordingFiles::of(&state, &a).rrd;
    let origin = crate::origin::request_origin(&headers, state.config());
    let body = html! {
        p { a href=(format!("/attempts/{id}")) { "Back to attempt " (id) } " · " a href=(format!("/attempts/{id}/recording.rrd")) { "Download .rrd" } }
        @if !state.viewer().available() {
            p class="fail" { "This build has no rerun web viewer." }
        } @else if !has_rrd {
            p class="fail" { "Attempt " (id) " has no .rrd recording (record with " code { "cutlab session --rrd" } ")." }
        } @else if let Some(origin) = origin {
            @if let Some(at) = at_ns {
                p id="moment-hint" class="moment-hint" { "Note at " strong { (debrief::moment_label(at)) } ": the viewer opens there, paused (timeline " code { (TIMELINE_SIM_TIME) } ", +" (format!("{:.3}", at as f64 / 1e9)) " s)." }
            }
            iframe id="replay" class="replay" title="rerun viewer" data-timeline=(TIMELINE_SIM_TIME) data-at-ns=[at_ns] src=(viewer_url(&origin, id, &state.grants().issue(id, user.id(), &user.0.token_hash))) {}
            script src="/static/replay.js" {}
        } @else {
            p class="fail" { "Cannot tell the viewer where this server is (no usable Host header)." }
        }
        h2 { "Notes" }
        @if notes.is_empty() { p class="muted" { "No notes yet." } }
        @for c in &notes { (attempt::comment_markup(id, c, has_rrd)) }
        @if user.is_staff() { (attempt::comment_form(&user, id, true)) }
    };
    Ok(layout::page(&format!("Replay of attempt {id}"), Some(&user), body).into_response())
}

async fn viewer_index(
    State(state): State<AppState>,
    _user: CurrentUser,
    headers: HeaderMap,
) -> Result<Response, AppError> {
    serve_viewer_file(&state, "index.html", &headers).await
}

async fn viewer_file(
    State(state): State<AppState>,
    _user: CurrentUser,
    Path(file): Path<String>,
    headers: HeaderMap,
) -> Result<Response, AppError> {
    serve_viewer_file(&state, &file, &headers).await
}

async fn serve_viewer_file(
    state: &AppState,
    name: &str,
    request: &HeaderMap,
) -> Result<Response, AppError> {
    let file = state.viewer().file(name).ok_or(AppError::NotFound)?;
    let mut headers = HeaderMap::new();
    headers.insert(header::CONTENT_TYPE, HeaderValue::from_static(file.mime));
    headers.insert(
        header::CACHE_CONTROL,
        HeaderValue::from_static("private, max-age=3600"),
    );
    if !file.compresses() {
        return Ok((headers, file.bytes.clone()).into_response());
    }
    headers.insert(header::VARY, HeaderValue::from_static("accept-encoding"));
    if !accepts_gzip(request) {
        return Ok((headers, file.bytes.clone()).into_response());
    }
    let (state, name) = (state.clone(), file.name);
    let body = tokio::task::spawn_blocking(move || {
        state
            .viewer()
            .file(name)
            .map(ViewerFile::gzipped)
            .unwrap_or_default()
    })
    .await
    .map_err(|e| AppError::Internal(format!("compressing the viewer: {e}")))?;
    headers.insert(header::CONTENT_ENCODING, HeaderValue::from_static("gzip"));
    Ok((headers, body).into_response())
}

/// Whether a request's `Accept-Encoding` takes gzip (with a non-zero weight).
fn accepts_gzip(request: &HeaderMap) -> bool {
    request
        .get_all(header::ACCEPT_ENCODING)
        .iter()
        .filter_map(|v| v.to_str().ok())
        .flat_map(|v| v.split(','))
        .any(|coding| {
            let mut parts = coding.split(';').map(str::trim);
            let name = parts.next().unwrap_or_default();
            let zero = parts.any(|p| {
                p.strip_prefix("q=")
                    .and_then(|q| q.parse::<f64>().ok())
                    .is_some_and(|q| q <= 0.0)
            });
            (name.eq_ignore_ascii_case("gzip") || name == "*") && !zero
        })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ranges_this_server_answers() {
        assert_eq!(requested_range(None, 100), Ok(None));
        assert_eq!(requested_range(Some("bytes=0-9"), 100), Ok(Some(0..10)));
        assert_eq!(requested_range(Some("bytes=90-"), 100), Ok(Some(90..100)));
        assert_eq!(requested_range(Some("bytes=-10"), 100), Ok(Some(90..100)));
        assert_eq!(
            requested_range(Some("bytes=50-500"), 100),
            Ok(Some(50..100))
        );
        assert_eq!(requested_range(Some("bytes=100-"), 100), Err(()));
        assert_eq!(requested_range(Some("bytes=-0"), 100), Err(()));
        // several ranges, other units, nonsense: the whole body
        assert_eq!(requested_range(Some("bytes=0-1,5-6"), 100), Ok(None));
        assert_eq!(requested_range(Some("items=0-1"), 100), Ok(None));
        assert_eq!(requested_range(Some("bytes=9-1"), 100), Ok(None));
        assert_eq!(requested_range(Some("bytes=x-y"), 100), Ok(None));
    }

    #[test]
    fn the_viewer_index_loses_only_the_font_links() {
        let html = b"<head><link rel=\"icon\" href=\"favicon.ico\" /><link rel=\"preconnect\" href=\"https://fonts.googleapis.com\" /><link\n href=\"https://fonts.googleapis.com/css2\"\n rel=\"stylesheet\"\n /></head>";
        let out = String::from_utf8(offline_index(html)).unwrap();
        assert_eq!(
            out,
            "<head><link rel=\"icon\" href=\"favicon.ico\" /></head>"
        );
    }

    #[test]
    fn the_embedded_viewer_is_there_and_offline() {
        let v = Viewer::load();
        assert!(v.available(), "re_web_viewer_server ships the viewer");
        let wasm = &v.file("re_viewer_bg.wasm").expect("the wasm").bytes;
        assert!(wasm.len() > 1_000_000 && wasm.starts_with(b"\0asm"));
        let index = String::from_utf8_lossy(&v.file("index.html").expect("index").bytes);
        assert!(index.contains("re_viewer.js") && !index.contains("fonts.googleapis.com"));
        // the viewer's handle reaches the page (the replay page moves its time cursor)
        assert!(
            index.contains(APP_STARTED.1) && !index.contains(APP_STARTED.0),
            "rerun's index.html changed: the replay page cannot reach the viewer's WebHandle"
        );
    }

    #[test]
    fn the_wasm_goes_out_compressed_to_a_browser_that_takes_gzip() {
        let v = Viewer::load();
        let wasm = v.file("re_viewer_bg.wasm").expect("the wasm");
        assert!(wasm.compresses() && !v.file("favicon.ico").expect("icon").compresses());
        let gz = wasm.gzipped();
        assert!(
            gz.len() < wasm.bytes.len() / 2,
            "{} of {}",
            gz.len(),
            wasm.bytes.len()
        );
        let mut back = Vec::new();
        std::io::Read::read_to_end(&mut flate2::read::GzDecoder::new(&gz[..]), &mut back)
            .expect("gunzip");
        assert!(back == wasm.bytes, "the gzip form holds the same wasm");
    }

    #[test]
    fn gzip_is_sent_only_where_the_browser_takes_it() {
        let accepts = |v: &[&str]| {
            let mut h = HeaderMap::new();
            for v in v {
                h.append(header::ACCEPT_ENCODING, HeaderValue::from_str(v).unwrap());
            }
            accepts_gzip(&h)
        };
        assert!(accepts(&["gzip, deflate, br, zstd"]));
        assert!(accepts(&["br", "GZIP;q=0.5"]));
        assert!(accepts(&["*"]));
        assert!(!accepts(&[]));
        assert!(!accepts(&["br, deflate"]));
        assert!(!accepts(&["gzip;q=0, br"]));
        assert!(!accepts(&["x-gzip-ish"]));
    }

    #[test]
    fn viewer_url_encodes_the_rrd_url() {
        assert_eq!(
            viewer_url("http://127.0.0.1:8080", 7, "1-2-ab"),
            "/viewer/?url=http%3A%2F%2F127.0.0.1%3A8080%2Fattempts%2F7%2Fgrant%2F1-2-ab%2Frecording.rrd&hide_welcome_screen"
        );
    }
}
