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
//! - [`augment`]: the paper's specular augmentation — k-means clusters of the joint solve's
//!   vertices, one two-lobe specular model per cluster, and per-vertex virtual coaxial specular
//!   samples and σ_s floors for the final passes (optics.md §7.7–§7.8).
//!
//! Later stages (observation extraction from a session, the solver, specular augmentation,
//! the shape update, the pipeline) each consume and produce these types.

pub mod augment;
pub mod data;
pub mod gate;
