//! The per-vertex polarimetric SVBRDF fit: Sparse Ellipsometry's reconstruction
//! (optics.md §7), inverting the same optics the simulator renders with
//! (`ellipso_sim::optics`; never a copy).
//!
//! The chain, one module each:
//! - [`data`]: the contract between stages — per-view geometry ([`data::ViewGeometry`]),
//!   per-(vertex, view) samples in model units ([`data::Sample`]), the per-vertex bundle
//!   ([`data::VertexSamples`]) and the per-vertex result ([`data::VertexFit`]). The one place
//!   that turns a view and a vertex position into the model's geometry
//!   ([`data::ViewGeometry::geometry_at`]).
//!
//! - [`gate`]: the sample gates (saturated, dark, grazing, non-finite, colour outliers), shared by
//!   extraction from real frames and the synthetic generator.
//!
//! - [`observe`]: observation extraction — a recorded session, camera poses and a mesh become
//!   a [`data::SampleSet`] (visibility, flash shadows, superpixel sampling, normaliser, gates).
//!
//! Later stages (observation extraction from a session, the solver, specular augmentation,
//! the shape update, the pipeline) each consume and produce these types.

pub mod data;
pub mod gate;
pub mod observe;
