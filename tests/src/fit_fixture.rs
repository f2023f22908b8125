//! Fit fixtures: the sphere scene's object as a mesh file for `ellipso fit --mesh`, and a small
//! `fit.ply` for viewer tests — an icosphere of radius 40 mm at z = 40 mm with plausible fitted
//! values that vary over the surface, a few flagged vertices and one with wild values (as a fit
//! under rework may write), written by the export's own writer.

use std::path::{Path, PathBuf};

use ellipso_fit::data::{FitFlag, VertexFit};
use ellipso_fit::export::ply::write_fit_ply;
use ellipso_model::geometry::TriangleMesh;
use ellipso_model::geometry::ply::{PlyFormat, write_ply};
use ellipso_model::geometry::procedural::icosphere;
use ellipso_model::optics::pbrdf::PbrdfParams;
use nalgebra::Point3;

/// The sphere scene's object (radius 40 mm at z = 40 mm) as an icosphere mesh, written to
/// `dir/sphere.ply` (binary PLY); returns the path.
pub fn sphere_mesh(dir: &Path) -> PathBuf {
    let (dirs, faces) = icosphere(2);
    let pos = dirs
        .iter()
        .map(|d| Point3::new(0.0, 0.0, 0.04) + d.into_inner() * 0.04)
        .collect();
    let mesh = TriangleMesh::new(pos, None, None, faces).unwrap();
    let path = dir.join("sphere.ply");
    std::fs::write(
        &path,
        write_ply(&mesh, PlyFormat::BinaryLittleEndian, false),
    )
    .unwrap();
    path
}

/// Writes `dir/fit.ply` and returns its directory.
pub fn write_fit_dir(dir: &Path) -> PathBuf {
    let (dirs, faces) = icosphere(3);
    let pos: Vec<_> = dirs
        .iter()
        .map(|d| Point3::new(0.0, 0.0, 0.04) + d.into_inner() * 0.04)
        .collect();
    let mesh = TriangleMesh::new(pos, None, None, faces).unwrap();
    let fits: Vec<VertexFit> = dirs
        .iter()
        .enumerate()
        .map(|(v, d)| {
            let x = d.x * 0.5 + 0.5;
            let mut fit = VertexFit {
                vertex: v as u32,
                params: PbrdfParams {
                    eta: 1.35 + 0.4 * x,
                    sigma_s: 0.12,
                    sigma_ss: 0.35,
                    rho_s: 1.2,
                    rho_ss: [0.05, 0.04, 0.03],
                    rho_d: [0.55 * x + 0.05, 0.25, 0.6 * (1.0 - x) + 0.05],
                },
                normal_world: d.into_inner().into(),
                std_error: [0.02; 10],
                normal_std_error_deg: 0.8,
                samples_used: 40,
                cost: 1.0,
                iterations: 6,
                flags: vec![],
                eta_unpooled: None,
                eta_prior_only: false,
                gates: Default::default(),
            };
            if d.z < -0.8 {
                fit.flags = vec![FitFlag::TooFewViews];
                fit.samples_used = 2;
            }
            if v == 7 {
                // wild values from a fit under rework: the viewer must grey this, not blow out
                fit.params.eta = 1e6;
                fit.params.rho_d = [5e4, 5e4, 5e4];
                fit.std_error = [f64::INFINITY; 10];
            }
            fit
        })
        .collect();
    std::fs::create_dir_all(dir).unwrap();
    write_fit_ply(&dir.join("fit.ply"), &mesh, &fits, None).unwrap();
    dir.to_path_buf()
}
