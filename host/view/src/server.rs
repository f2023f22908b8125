//! The HTTP server of `ellipso view`: axum on a small tokio runtime of its own thread.
//!
//! Contract:
//! - [`start`] binds synchronously (so a busy port or a bad address is an error at once, and the
//!   URL is known before the page opens), then serves on one background thread with a
//!   single-worker runtime: the view never takes more than that thread from a capture.
//! - Dropping the [`ViewServer`] stops it: new connections are refused at once, open requests
//!   (event streams included) are closed after [`SHUTDOWN_GRACE`], so a capture with `--view`
//!   ends even while a page is open.
//! - Every request passes [`guard`] first: exactly one `Host` header, which must pass the
//!   [`HostPolicy`], as must the authority of an absolute-form request target
//!   (`GET http://host:port/…`); and the token must match ([`Token`]); otherwise `403` with a
//!   one-line reason and nothing else.
//!   Responses carry `Cache-Control: no-store`, `Referrer-Policy: no-referrer` (the token is in
//!   the URL and must not leak through `Referer`), `X-Content-Type-Options: nosniff` and a
//!   Content-Security-Policy allowing only this origin (no CDN, nothing remote).
//! - Routes: `/` (the page of the mode), `/check` (the shader-port check page), `/assets/NAME`,
//!   `/api/info`, `/api/check/cases`, `/api/material/info`, `/api/material/mesh.bin` (fitted-material
//!   mode), `/api/live/state`, `/api/live/events` (server-sent events, at most
//!   [`LIVE_MAX_HZ`] per second, only when something changed), `/api/live/image/{s0,dolp,aolp}`,
//!   `/api/live/mesh.bin` (empty without a mesh), `/api/live/coverage.bin` (live mode).

use std::future::IntoFuture;
use std::net::{SocketAddr, TcpListener};
use std::pin::pin;
use std::sync::Arc;
use std::time::Duration;

use axum::Router;
use axum::body::Body;
use axum::extract::{Path, Request, State};
use axum::http::{HeaderValue, StatusCode, header};
use axum::middleware::{Next, from_fn_with_state};
use axum::response::sse::{Event, KeepAlive, Sse};
use axum::response::{IntoResponse, Response};
use axum::routing::get;
use futures_util::future::{Either, select};

use super::assets;
use super::follow::LiveHub;
use super::material::MaterialMesh;
use super::security::{HostPolicy, Token};

/// Most live updates per second pushed to a page.
pub const LIVE_MAX_HZ: f64 = 4.0;

/// How long a shutdown waits for open requests before it closes them (event streams never end
/// by themselves).
pub const SHUTDOWN_GRACE: Duration = Duration::from_millis(300);

/// What the server shows.
#[derive(Clone)]
pub enum Content {
    /// A fitted material (`fit.ply`).
    Material(Arc<MaterialPayload>),
    /// A session being captured or already recorded.
    Live(Arc<LiveHub>),
}

/// The fitted material, encoded once.
pub struct MaterialPayload {
    /// `/api/material/info`.
    pub info: serde_json::Value,
    /// `/api/material/mesh.bin`.
    pub mesh: Vec<u8>,
}

impl MaterialPayload {
    /// Encodes a loaded mesh.
    pub fn new(mesh: &MaterialMesh) -> Self {
        Self {
            info: mesh.info(),
            mesh: mesh.to_bytes(),
        }
    }
}

/// Server settings.
#[derive(Clone, Debug)]
pub struct ServerConfig {
    /// Address to bind (port 0: any free port).
    pub bind: SocketAddr,
    /// Extra accepted `Host` names (`--allow-host`).
    pub allow_hosts: Vec<String>,
    /// The secret (generated per run unless given).
    pub token: Token,
}

impl Default for ServerConfig {
    fn default() -> Self {
        Self {
            bind: super::security::DEFAULT_BIND,
            allow_hosts: Vec::new(),
            token: Token::generate(),
        }
    }
}

/// Errors starting the server.
#[derive(Debug, thiserror::Error)]
pub enum ServerError {
    /// Binding the address failed.
    #[error("cannot listen on {addr}: {source}")]
    Bind {
        /// The address.
        addr: SocketAddr,
        /// Cause.
        source: std::io::Error,
    },
    /// The runtime or its thread could not start.
    #[error("cannot start the web server: {0}")]
    Start(std::io::Error),
}

/// A running server; dropping it (or [`ViewServer::shutdown`]) stops it.
pub struct ViewServer {
    addr: SocketAddr,
    url: String,
    stop: Option<tokio::sync::oneshot::Sender<()>>,
    thread: Option<std::thread::JoinHandle<()>>,
}

impl ViewServer {
    /// The bound address.
    pub fn addr(&self) -> SocketAddr {
        self.addr
    }
    /// The page's URL, token included.
    pub fn url(&self) -> &str {
        &self.url
    }
    /// Blocks until the server ends (it ends only on shutdown or a fatal error).
    pub fn wait(mut self) {
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
    }
    fn stop_now(&mut self) {
        if let Some(s) = self.stop.take() {
            let _ = s.send(());
        }
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
    }
}

impl Drop for ViewServer {
    fn drop(&mut self) {
        self.stop_now();
    }
}

#[derive(Clone)]
struct AppState {
    token: Token,
    hosts: HostPolicy,
    content: Content,
}

/// Binds and starts serving `content`.
pub fn start(config: ServerConfig, content: Content) -> Result<ViewServer, ServerError> {
    let listener = TcpListener::bind(config.bind).map_err(|source| ServerError::Bind {
        addr: config.bind,
        source,
    })?;
    let addr = listener.local_addr().map_err(ServerError::Start)?;
    listener.set_nonblocking(true).map_err(ServerError::Start)?;
    let state = AppState {
        token: config.token.clone(),
        hosts: HostPolicy::new(addr, config.allow_hosts.clone()),
        content,
    };
    let host = if addr.ip().is_unspecified() {
        // the page must be opened through an address the browser can reach
        format!("127.0.0.1:{}", addr.port())
    } else {
        addr.to_string()
    };
    let url = format!("http://{host}/?token={}", config.token.as_str());
    let runtime = tokio::runtime::Builder::new_multi_thread()
        .worker_threads(1)
        .thread_name("ellipso-view")
        // the view never competes with a capture in this process (view::priority)
        .on_thread_start(|| super::priority::lower_this_thread_or_log("web server"))
        .enable_io()
        .enable_time()
        .build()
        .map_err(ServerError::Start)?;
    let (stop_tx, stop_rx) = tokio::sync::oneshot::channel::<()>();
    let app = router(state);
    let thread = std::thread::Builder::new()
        .name("ellipso-view-main".into())
        .spawn(move || {
            super::priority::lower_this_thread_or_log("web server");
            runtime.block_on(async move {
                let listener = match tokio::net::TcpListener::from_std(listener) {
                    Ok(l) => l,
                    Err(e) => {
                        tracing::error!("view server: {e}");
                        return;
                    }
                };
                // Graceful shutdown waits for every connection to close, and an event stream
                // never does: after SHUTDOWN_GRACE the open ones are dropped with the runtime.
                let stopping = Arc::new(tokio::sync::Notify::new());
                let signal = {
                    let stopping = stopping.clone();
                    async move {
                        let _ = stop_rx.await;
                        stopping.notify_one();
                    }
                };
                let serve = axum::serve(listener, app)
                    .with_graceful_shutdown(signal)
                    .into_future();
                let grace = async {
                    stopping.notified().await;
                    tokio::time::sleep(SHUTDOWN_GRACE).await;
                };
                if let Either::Left((Err(e), _)) = select(pin!(serve), pin!(grace)).await {
                    tracing::error!("view server: {e}");
                }
            });
            runtime.shutdown_timeout(Duration::from_millis(200));
        })
        .map_err(ServerError::Start)?;
    Ok(ViewServer {
        addr,
        url,
        stop: Some(stop_tx),
        thread: Some(thread),
    })
}

fn router(state: AppState) -> Router {
    Router::new()
        .route("/", get(index))
        .route("/check", get(check_page))
        .route("/assets/{name}", get(asset))
        .route("/api/info", get(info))
        .route("/api/check/cases", get(check_cases))
        .route("/api/material/info", get(material_info))
        .route("/api/material/mesh.bin", get(material_mesh))
        .route("/api/live/state", get(live_state))
        .route("/api/live/events", get(live_events))
        .route("/api/live/image/{kind}", get(live_image))
        .route("/api/live/mesh.bin", get(live_mesh))
        .route("/api/live/coverage.bin", get(live_coverage))
        .fallback(|| async { (StatusCode::NOT_FOUND, "not found\n") })
        .layer(from_fn_with_state(state.clone(), guard))
        .with_state(state)
}

/// Refuses requests with a foreign `Host` or without the token; adds the security headers.
async fn guard(State(state): State<AppState>, request: Request, next: Next) -> Response {
    // exactly one Host header: with two, a proxy and this server could each read another
    let mut hosts = request.headers().get_all(header::HOST).iter();
    let host = match (hosts.next(), hosts.next()) {
        (Some(h), None) => h.to_str().unwrap_or(""),
        (Some(_), Some(_)) => return refuse("more than one Host header"),
        (None, _) => "",
    };
    if !state.hosts.allows(host) {
        return refuse("Host header does not name this server (DNS-rebinding protection)");
    }
    // an absolute-form request target names the server too (RFC 9112 §3.2.2: it takes the
    // place of Host), so it must name this one
    if let Some(authority) = request.uri().authority()
        && !state.hosts.allows(authority.as_str())
    {
        return refuse("request target names another server (DNS-rebinding protection)");
    }
    let from_query = request.uri().query().and_then(|q| {
        q.split('&')
            .filter_map(|kv| kv.split_once('='))
            .find(|(k, _)| *k == "token")
            .map(|(_, v)| v.to_string())
    });
    let from_header = request
        .headers()
        .get(header::AUTHORIZATION)
        .and_then(|h| h.to_str().ok())
        .and_then(|h| h.strip_prefix("Bearer "))
        .map(str::to_string);
    let presented = from_query.or(from_header).unwrap_or_default();
    if !state.token.matches(&presented) {
        return refuse("missing or wrong token: open the URL `ellipso view` printed");
    }
    let mut response = next.run(request).await;
    let h = response.headers_mut();
    h.insert(header::CACHE_CONTROL, HeaderValue::from_static("no-store"));
    h.insert(
        header::REFERRER_POLICY,
        HeaderValue::from_static("no-referrer"),
    );
    h.insert(
        header::X_CONTENT_TYPE_OPTIONS,
        HeaderValue::from_static("nosniff"),
    );
    h.insert(
        header::CONTENT_SECURITY_POLICY,
        HeaderValue::from_static(
            "default-src 'self'; img-src 'self' data: blob:; style-src 'self' 'unsafe-inline'; script-src 'self'; connect-src 'self'; frame-ancestors 'none'",
        ),
    );
    response
}

fn refuse(why: &'static str) -> Response {
    (StatusCode::FORBIDDEN, format!("403 forbidden: {why}\n")).into_response()
}

fn typed(content_type: &'static str, body: impl Into<Body>) -> Response {
    ([(header::CONTENT_TYPE, content_type)], body.into()).into_response()
}

fn mode_name(content: &Content) -> &'static str {
    match content {
        Content::Material(_) => "material",
        Content::Live(_) => "live",
    }
}

async fn index(State(state): State<AppState>) -> Response {
    let page = assets::page(
        "index.html",
        mode_name(&state.content),
        state.token.as_str(),
    );
    typed("text/html; charset=utf-8", page)
}

async fn check_page(State(state): State<AppState>) -> Response {
    let page = assets::page("check.html", "check", state.token.as_str());
    typed("text/html; charset=utf-8", page)
}

async fn asset(Path(name): Path<String>) -> Response {
    match assets::get(&name) {
        Some((bytes, content_type)) => typed(content_type, bytes),
        None => (StatusCode::NOT_FOUND, "no such asset\n").into_response(),
    }
}

async fn info(State(state): State<AppState>) -> Response {
    let body = serde_json::json!({
        "mode": mode_name(&state.content),
        "software": concat!("ellipso ", env!("CARGO_PKG_VERSION")),
        "live_max_hz": LIVE_MAX_HZ,
    });
    typed("application/json", body.to_string())
}

async fn check_cases() -> Response {
    typed("application/json", super::check::payload(250).to_string())
}

fn not_in_mode(what: &str) -> Response {
    (
        StatusCode::NOT_FOUND,
        format!("{what}: not available in this mode\n"),
    )
        .into_response()
}

async fn material_info(State(state): State<AppState>) -> Response {
    match &state.content {
        Content::Material(m) => typed("application/json", m.info.to_string()),
        Content::Live(_) => not_in_mode("material"),
    }
}

async fn material_mesh(State(state): State<AppState>) -> Response {
    match &state.content {
        Content::Material(m) => typed("application/octet-stream", m.mesh.clone()),
        Content::Live(_) => not_in_mode("material"),
    }
}

fn live_hub(state: &AppState) -> Option<&Arc<LiveHub>> {
    match &state.content {
        Content::Live(hub) => Some(hub),
        Content::Material(_) => None,
    }
}

async fn live_state(State(state): State<AppState>) -> Response {
    match live_hub(&state) {
        Some(hub) => typed("application/json", hub.current().json.to_string()),
        None => not_in_mode("live"),
    }
}

async fn live_events(State(state): State<AppState>) -> Response {
    let Some(hub) = live_hub(&state) else {
        return not_in_mode("live");
    };
    let rx = hub.subscribe();
    let min_gap = Duration::from_secs_f64(1.0 / LIVE_MAX_HZ);
    // first event at once, then one per change, no more often than LIVE_MAX_HZ
    let stream = futures_util::stream::unfold((rx, true), move |(mut rx, first)| async move {
        if !first {
            tokio::time::sleep(min_gap).await;
            rx.changed().await.ok()?;
        }
        let snapshot = rx.borrow_and_update().clone();
        let event = Event::default()
            .event("state")
            .data(snapshot.json.to_string());
        Some((Ok::<_, std::convert::Infallible>(event), (rx, false)))
    });
    Sse::new(stream)
        .keep_alive(KeepAlive::default())
        .into_response()
}

async fn live_image(State(state): State<AppState>, Path(kind): Path<String>) -> Response {
    let Some(hub) = live_hub(&state) else {
        return not_in_mode("live");
    };
    let snapshot = hub.current();
    match snapshot.images.get(kind.as_str()) {
        Some(png) => typed("image/png", png.as_ref().clone()),
        None => (StatusCode::NOT_FOUND, "no such image yet\n").into_response(),
    }
}

async fn live_mesh(State(state): State<AppState>) -> Response {
    // no mesh (--mesh not given): an empty body, so the page needs no failing request to know
    let bytes = live_hub(&state)
        .and_then(|h| h.mesh_bytes())
        .map_or_else(Vec::new, |b| b.as_ref().clone());
    typed("application/octet-stream", bytes)
}

async fn live_coverage(State(state): State<AppState>) -> Response {
    match live_hub(&state) {
        Some(hub) => typed(
            "application/octet-stream",
            hub.current().coverage.as_ref().clone(),
        ),
        None => not_in_mode("live"),
    }
}
