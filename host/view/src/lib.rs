//! `ellipso-view`: the local web page of `ellipso view`, for the live capture and for the fitted material.
//!
//! Two modes, one server:
//! - **Live capture** ([`follow`]): follows a session directory as a capture writes it (in this
//!   process with `ellipso capture --view`, or another one with `ellipso view SESSION`) and shows
//!   the latest frame's s0, DoLP and AoLP ([`frame_view`]), counters, the camera path on a dome
//!   with each frame's pose status, and [`coverage`] of the object with hints.
//! - **Fitted material** ([`material`]): `fit.ply` drawn with the per-vertex pBRDF evaluated in a
//!   WebGL2 shader (`assets/pbrdf.glsl`, a port of `ellipso_model::optics`; [`check`] holds the
//!   grid it is checked on against the Rust model).
//!
//! The live mode's threads run at the lowest priority and pace their work while a capture runs
//! ([`priority`]).
//!
//! [`live`] starts the live mode's follower and server together.
//!
//! [`server`] serves both behind [`security`]: loopback by default, a per-run token, and a
//! Host-header allow-list. The page's files are embedded in the binary ([`assets`]); nothing is
//! loaded from elsewhere. `docs/view.md` is the user's guide.

pub mod assets;
pub mod check;
pub mod coverage;
pub mod follow;
pub mod frame_view;
pub mod live;
pub mod material;
pub mod priority;
pub mod security;
pub mod server;
