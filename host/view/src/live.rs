//! The live view of a session ([`start_live`]): its follower ([`crate::follow`]) and the server
//! ([`crate::server`]) showing it, started together for `ellipso view SESSION` and
//! `ellipso capture --view`.
//!
//! Contract: the session may not exist yet (the follower waits for it); dropping the
//! [`LiveView`] stops both. Nothing here prints: the caller says the page's URL.

use std::path::PathBuf;

use ellipso_run_error::RunError;

use crate::follow::{self, FollowConfig, Follower};
use crate::server::{self, Content, ServerConfig, ViewServer};

/// A live view: the follower and its server (dropping it stops both).
pub struct LiveView {
    /// The server.
    pub server: ViewServer,
    _follower: Follower,
}

/// Starts the live view of `session` (which may not exist yet): coverage on `mesh` (default a
/// dome), poses tracked for frames without one when `track`.
pub fn start_live(
    session: PathBuf,
    mesh: Option<PathBuf>,
    track: bool,
    serve: ServerConfig,
) -> Result<LiveView, RunError> {
    let mut config = FollowConfig::new(session);
    config.mesh = mesh;
    config.track = track;
    let (hub, follower) = follow::spawn(config)?;
    let server = server::start(serve, Content::Live(hub))?;
    Ok(LiveView {
        server,
        _follower: follower,
    })
}
