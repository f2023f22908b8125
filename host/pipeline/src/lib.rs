//! `ellipso-pipeline`: the commands that take a recorded session through the pipeline, as the
//! subcommands, the demo and the benches run them — each one library function that claims its
//! output, reads and checks its inputs, runs the stages of the crates it joins and writes its
//! files whole, saying its lines to the caller's `Say` and its long steps to the caller's
//! [`steps::Steps`]; nothing here prints.
//!
//! - [`poses`]: the poses every later stage takes: the session's recorded poses, the frames
//!   without one tracked first ([`poses::poses_of`], through `ellipso-vision`).
//! - [`mesh`]: the session's mesh as the subcommands take it and write it (carved by
//!   `ellipso-mesh`; `ellipso mesh` whole: [`mesh::mesh_command`]); [`mesh_hull`]: the visual
//!   hull saved beside it, reused by `ellipso fit --mesh` on the same session.
//! - [`fit_run`]: `ellipso fit` whole (inputs checked, poses, hull or carved mesh, the fit of
//!   `ellipso-fit`, its files); [`fit_import`]: its COLMAP flags (`--poses`, `--mesh-frame`,
//!   `--mesh-model`: models read by `ellipso-colmap` and aligned); [`fit_shard`]: sharded fits
//!   (`fit --shard`, `fit-merge`).
//! - [`colmap_export`]: `ellipso export colmap` whole.
//! - [`sensor`]: the sensor calibration a session's frames are read with, or the warning
//!   naming what a hardware session is fitted with instead.
//! - [`steps`]: where a run's long steps are shown.
//!
//! Why a crate of its own: the carving (`ellipso-mesh`), the fit (`ellipso-fit`), the tracker
//! (`ellipso-vision`) and the COLMAP formats (`ellipso-colmap`) each do one thing; a command
//! joins them. None of them links the simulator, the firmware or the wire protocol, so neither
//! does a fit of a recorded session (`.ci/run` checks this crate's tree).
#![forbid(unsafe_code)]

pub mod colmap_export;
pub mod fit_import;
pub mod fit_run;
pub mod fit_shard;
pub mod mesh;
pub mod mesh_hull;
pub mod poses;
pub mod sensor;
pub mod steps;
