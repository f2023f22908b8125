//! `ellipso view PATH`: the local web page — live capture for a session directory, fitted
//! material for a fit directory (or `fit.ply`). `docs/view.md` is the guide.
//!
//! Prints the page's URL (with its per-run token) on stdout and serves until interrupted.
//! The live mode is [`ellipso_view::live::start_live`], which `ellipso capture --view` calls too.

use std::net::{IpAddr, SocketAddr};
use std::path::PathBuf;
use std::sync::Arc;

use anyhow::Context;

use ellipso_view::follow;
use ellipso_view::live::start_live;
use ellipso_view::material::{self, MaterialMesh};
use ellipso_view::security::{DEFAULT_BIND, Token};
use ellipso_view::server::{self, Content, MaterialPayload, ServerConfig};

/// Arguments of `ellipso view`.
#[derive(Debug, Clone, clap::Args)]
pub struct Args {
    /// A session directory (live view, follows it while a capture writes it) or a fit directory
    /// / `fit.ply` (fitted material).
    pub path: PathBuf,
    /// Object mesh (OBJ or PLY) for the live coverage; without it coverage is shown on a dome
    /// around the object.
    #[arg(long, value_name = "MESH")]
    pub mesh: Option<PathBuf>,
    #[command(flatten)]
    pub serve: ServeArgs,
    /// Do not track poses of frames the session has none for (live mode).
    #[arg(long)]
    pub no_track: bool,
    /// PATH is a session a capture is about to create: wait for it (live mode).
    #[arg(long)]
    pub wait: bool,
}

/// Where and to whom the page is served.
#[derive(Debug, Clone, clap::Args)]
pub struct ServeArgs {
    /// Address to listen on, `IP` or `IP:PORT` (default 127.0.0.1 on a free port). Anything
    /// but loopback opens the page to the network: the token still guards it.
    #[arg(long, value_name = "ADDR", value_parser = parse_bind)]
    pub bind: Option<SocketAddr>,
    /// Also accept requests whose Host header is this name (with `--bind`; repeatable).
    #[arg(long, value_name = "NAME")]
    pub allow_host: Vec<String>,
}

impl ServeArgs {
    fn config(&self) -> ServerConfig {
        ServerConfig {
            bind: self.bind.unwrap_or(DEFAULT_BIND),
            allow_hosts: self.allow_host.clone(),
            token: Token::generate(),
        }
    }
}

fn parse_bind(s: &str) -> Result<SocketAddr, String> {
    if let Ok(a) = s.parse::<SocketAddr>() {
        return Ok(a);
    }
    s.parse::<IpAddr>()
        .map(|ip| SocketAddr::new(ip, 0))
        .map_err(|_| format!("'{s}' is not an IP address or IP:PORT"))
}

fn announce(what: &str, url: &str, addr: SocketAddr) {
    crate::outln!("ellipso view: {what}");
    if !addr.ip().is_loopback() {
        crate::outln!(
            "  listening on {addr} (not loopback: reachable from the network, token required)"
        );
    }
    crate::outln!("  open {url}");
    use std::io::Write;
    let _ = std::io::stdout().flush();
}

/// Runs `ellipso view`.
pub fn run(args: Args) -> anyhow::Result<()> {
    let path = &args.path;
    if follow::is_session(path) || (args.wait && !path.exists()) {
        let live = start_live(
            path.clone(),
            args.mesh.clone(),
            !args.no_track,
            args.serve.config(),
        )
        .map_err(super::out::failed)?;
        announce(
            &format!("live session {}", path.display()),
            live.server.url(),
            live.server.addr(),
        );
        live.server.wait();
        return Ok(());
    }
    if material::locate(path).is_some() {
        let mesh = MaterialMesh::load(path)?;
        let payload = Arc::new(MaterialPayload::new(&mesh));
        let server = server::start(args.serve.config(), Content::Material(payload))
            .context("starting the web server")?;
        announce(
            &format!(
                "fitted material {} ({} vertices, {} triangles)",
                mesh.path.display(),
                mesh.vertices.len(),
                mesh.triangles.len()
            ),
            server.url(),
            server.addr(),
        );
        server.wait();
        return Ok(());
    }
    anyhow::bail!(
        "{}: neither a session (no manifest.json) nor a fit (no fit.ply)",
        path.display()
    )
}
