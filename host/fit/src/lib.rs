//! `ellipso-fit`: the per-vertex polarimetric SVBRDF fit of a recorded session, and its outputs.
//!
//! The fit is Sparse Ellipsometry's reconstruction
//! (docs/model.md §11), inverting the same optics the simulator renders with
//! (`ellipso_model::optics`; never a copy). `docs/fit.md` describes the whole chain.
//!
//! The chain, one module each:
//! - [`data`]: the contract between stages — per-view geometry ([`data::ViewGeometry`]),
//!   per-(vertex, view) samples in model units ([`data::Sample`]), the per-vertex bundle
//!   ([`data::VertexSamples`]) and the per-vertex result ([`data::VertexFit`]). The one place
//!   that turns a view and a vertex position into the model's geometry
//!   ([`data::ViewGeometry::geometry_at`]).
//! - [`gate`]: the sample gates (saturated, dark, grazing, non-finite, colour outliers), shared by
//!   extraction from real frames and the synthetic generator.
//! - [`inputs`]: the session's camera, poses, frame metadata and the mesh checked against
//!   physical bounds before any work (what no capture can produce is refused, named).
//! - [`observe`]: a recorded session + a mesh → samples (projection, occlusion, flash shadow,
//!   demosaiced analyser sampling, normaliser, gates), streaming one frame at a time.
//! - [`model`]: per-sample prediction (unit-albedo lobes) with exact dual-number derivatives.
//! - [`solve`]: per-vertex Levenberg–Marquardt with variable projection, uncertainty and flags.
//! - [`augment`]: clusters, per-cluster two-lobe models and virtual specular samples.
//! - [`shape`]: vertex positions updated towards the refined normals.
//! - [`neighbours`]: mesh rings and graph distances for the steps that look at a vertex's
//!   surroundings.
//! - [`complete`]: every vertex the views see gets a full parameter set — its material's values
//!   where its own samples leave a parameter open, flagged `FromMaterial`.
//! - [`materials`]: per material, the η a fit reports (the text report's lines and
//!   `fit-summary.json`'s `materials`).
//! - [`pipeline`]: steps A (joint solve), B (augmentation), C (final passes), timed.
//! - [`holdout`]: the held-out views no step sees, and the re-render error on them.
//! - [`session`]: the outer loop on a recorded session (observe → solve → shape).
//! - [`shard`]: sharded fits for job arrays (observations and step A per shard, part files, the
//!   merge that runs the global steps once; docs/scale.md).
//! - [`synthetic`]: samples of one vertex synthesised through the renderer's radiometry (the
//!   solver's tests and benches). The simulator's truth, simulated captures and error metrics
//!   live in `ellipso-bench`: this crate does not depend on the simulator.
//! - [`export`]: the fit's outputs (PLY with per-vertex parameters, maps, Mueller grid, relit and
//!   novel views, the re-render comparison).
//! - [`output`]: a finished session fit's files as the subcommands write them (the pictures from
//!   one view and [`summary`]: `fit-summary.json`, a typed, documented schema).
#![forbid(unsafe_code)]

pub mod augment;
pub mod complete;
pub mod data;
pub mod export;
pub mod gate;
pub mod holdout;
pub mod inputs;
pub mod materials;
pub mod model;
pub mod neighbours;
pub mod observe;
pub mod output;
pub mod pipeline;
pub mod session;
pub mod shape;
pub mod shard;
pub mod solve;
pub mod summary;
pub mod synthetic;
