//! Fixtures for the tests of the crates above this one (feature `test-support`, off in every
//! build that is not a test): a small session rendered from a scene of spheres on a board, one
//! definition for the mesh and COLMAP tests.

use std::path::{Path, PathBuf};

use nalgebra::Isometry3;

use crate::render::RenderOptions;
use crate::scene::Scene;

/// A white-ish matte material: close to the board's white paper (albedo 0.85), the case a naive
/// "looks like the board" test gets wrong.
pub const WHITE: &str = "eta = 1.5\nsigma_s = 0.3\nsigma_ss = 0.45\nrho_s = 0.2\n\
                         rho_ss = [0.02, 0.02, 0.02]\nrho_d = [0.7, 0.7, 0.7]";

/// Sphere objects `(centre, radius)` in a scene with `views` cameras on two rings around
/// `(0, 0, 0.03)` at 0.32 m, rendered at `width × height` into a new session under `dir`.
/// Returns the session directory, the scene and the true poses.
pub fn render_session(
    dir: &Path,
    spheres: &[([f64; 3], f64)],
    views: usize,
    width: u32,
    height: u32,
) -> (PathBuf, Scene, Vec<(u64, Isometry3<f64>)>) {
    let board = Path::new(env!("CARGO_MANIFEST_DIR")).join("boards/base_a4.toml");
    render_session_with(dir, spheres, views, width, height, &board)
}

/// [`render_session`] on the board of file `board`.
pub fn render_session_with(
    dir: &Path,
    spheres: &[([f64; 3], f64)],
    views: usize,
    width: u32,
    height: u32,
    board: &Path,
) -> (PathBuf, Scene, Vec<(u64, Isometry3<f64>)>) {
    let objects: String = spheres
        .iter()
        .enumerate()
        .map(|(i, (c, r))| {
            format!(
                "[[objects]]\nname = \"s{i}\"\nshape = \"sphere\"\nradius_m = {r}\n\
                 pose = {{ translation_m = [{}, {}, {}] }}\nmaterial = \"white\"\n",
                c[0], c[1], c[2]
            )
        })
        .collect();
    let poses: String = (0..views)
        .map(|k| {
            let az = k as f64 * std::f64::consts::TAU / views as f64 + 0.3;
            let el = if k % 2 == 0 { 30f64 } else { 55f64 }.to_radians();
            let d = 0.32;
            format!(
                "[[capture.poses]]\nposition_m = [{}, {}, {}]\nlook_at_m = [0.0, 0.0, 0.03]\n",
                d * el.cos() * az.cos(),
                d * el.cos() * az.sin(),
                0.03 + d * el.sin()
            )
        })
        .collect();
    let f = 1.9 * f64::from(width);
    let text = format!(
        "seed = 5\nname = \"mesh_test\"\n[materials.white]\n{WHITE}\n{objects}\
         [[boards]]\nfile = \"{board}\"\npose = {{}}\n\
         [rig.camera]\nresolution_px = [{width}, {height}]\nfx_px = {f}\nfy_px = {f}\n\
         cx_px = {cx}\ncy_px = {cy}\nsensor = \"mono_polar\"\nbit_depth = 12\nexposure_us = 2500.0\n\
         [rig.flash]\noffset_m = [0.0, -0.03, 0.0]\n\
         [capture]\npath = \"explicit\"\n{poses}\n\
         [effects]\nshot_noise = {{}}\nread_noise = {{ sigma_e = 2.3 }}\nquantisation = {{}}\nsaturation = {{}}\n",
        board = board.display(),
        cx = f64::from(width) / 2.0 - 0.5,
        cy = f64::from(height) / 2.0 - 0.5,
    );
    std::fs::create_dir_all(dir).unwrap();
    let scene_path = dir.join("scene.toml");
    std::fs::write(&scene_path, text).unwrap();
    let scene = Scene::load(&scene_path).unwrap();
    let session_dir = dir.join("session");
    let options = RenderOptions {
        supersampling: 1,
        ..RenderOptions::default()
    };
    crate::record::render_session(
        &scene_path,
        &scene,
        options,
        &session_dir,
        100,
        &mut |_, _| {},
    )
    .unwrap();
    let poses = (0..scene.camera_poses.len())
        .map(|k| (100 + k as u64, scene.camera_poses[k].world_from_camera))
        .collect();
    (session_dir, scene, poses)
}
