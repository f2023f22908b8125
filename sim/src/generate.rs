//! Procedurally generated scenes for the generalisation bench (`ellipso bench generalize`):
//! from one seed, an object of a drawn shape and 2–8 materials of real, measured refractive
//! index on the base board, and a capture path — written as an ordinary scene file the
//! simulator, `ellipso capture --sim` and the benches read.
//!
//! Contract:
//! - [`GeneratedScene::generate`] depends only on the seed and the [`GenerateOptions`]
//!   (ChaCha8 seeded; options change the camera, never the draws), so seed N is the same scene
//!   on every machine. Seeds below [`HELD_OUT_SEED_MIN`] are for development; the figures that
//!   count are measured on seeds at or above it, after the last constant was chosen.
//! - What a seed draws: the shape ([`shape::ShapeKind`]: bumpy blob, creased solid with flat
//!   faces, blob with a concave bowl); 2–8 distinct rows of the measured table
//!   ([`materials::TABLE`]: η 1.33–2.42, each row cited); per material a specular roughness σs
//!   log-uniform in [0.05, 0.5] (σss = σs · U[1.5, 3], capped at 1), ρs U[0.5, 1], a grey ρss
//!   U[0.03, 0.2] and a diffuse colour from [`PALETTE`]; with probability ½ a same-colour pair
//!   (two materials of one ρd and different η); with probability 0.6 one patch of 2–4 % of the
//!   surface (else every patch ≥ [`MIN_PATCH_FRACTION`]); with probability 0.15 a dark object
//!   (every ρd scaled to ≤ 0.06) and, independently, with probability 0.2 a dark board (white
//!   print albedo 0.20 instead of 0.85); the capture path (spiral orbit or hand-held walk, ½
//!   each); the object's turn about the vertical and its size (largest radius 32–45 mm). The
//!   object rests on the board (its lowest vertex at z = 0).
//! - The camera is the demo's (fx 3478 px at 2448 × 2048) scaled to the chosen resolution, with
//!   the demo's flash and sensor effects (shot and read noise, quantisation, saturation,
//!   polariser extinction); `photo_count` photos.
//! - [`GeneratedScene::write`] writes `scene.toml`, `object.ply` (the unit mesh with a `region`
//!   per vertex, region k = material k) and `board.toml` into one folder; the scene refers to
//!   the other two relatively, so the folder can move.

pub mod materials;
pub mod shape;

use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use ellipso_model::geometry::TriangleMesh;
use ellipso_model::geometry::ply::{PlyFormat, write_ply};
use rand::seq::SliceRandom;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

use crate::scene::MaterialSpec;
use materials::{TABLE, TableMaterial};
use shape::ShapeKind;

/// Seeds at or above this are held out: their figures are the bench's result (module doc).
pub const HELD_OUT_SEED_MIN: u64 = 1000;

/// Smallest patch a scene may have, share of the surface area (issue 42: "patches down to
/// 2 %"). The grown patch overshoots its target by less than one vertex's area.
pub const MIN_PATCH_FRACTION: f64 = 0.02;

/// Icosphere subdivisions of the generated meshes: 2562 vertices, as the shipped blob — one
/// vertex per ≈ 2.4 mm² at the largest size, so a 2 % patch holds ≈ 50 vertices.
pub const SUBDIVISIONS: u32 = 4;

/// Diffuse colours (linear RGB albedo) a material's ρd is drawn from: red, white, blue, green,
/// yellow, grey, orange, near-black.
pub const PALETTE: [[f64; 3]; 8] = [
    [0.60, 0.10, 0.08],
    [0.75, 0.73, 0.70],
    [0.05, 0.20, 0.45],
    [0.10, 0.45, 0.12],
    [0.70, 0.60, 0.10],
    [0.30, 0.30, 0.30],
    [0.80, 0.35, 0.05],
    [0.04, 0.04, 0.045],
];

/// The demo camera's focal length at its full resolution, px (`sim/scenes/demo.toml`).
const DEMO_FX_PX: f64 = 3478.0;
/// The demo camera's full width, px.
const DEMO_WIDTH_PX: f64 = 2448.0;

/// What the bench chooses, not the seed.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct GenerateOptions {
    /// Image size, px (the demo's 2448 × 2048, or a binned 1224 × 1024, 612 × 512).
    pub resolution_px: [u32; 2],
    /// Photos along the path.
    pub photo_count: u32,
}

impl Default for GenerateOptions {
    fn default() -> Self {
        Self {
            resolution_px: [612, 512],
            photo_count: 50,
        }
    }
}

/// The capture path a seed drew.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum GeneratedPath {
    /// The demo's two-turn spiral orbit at 0.45 m.
    Orbit,
    /// A seeded hand-held walk, 0.4–0.6 m, with jitter.
    HandHeld,
}

/// One drawn material.
#[derive(Clone, Debug, PartialEq)]
pub struct GeneratedMaterial {
    /// The table row (its name is the scene's material name).
    pub row: TableMaterial,
    /// Parameters (η from the row, the rest drawn).
    pub params: MaterialSpec,
    /// Target share of the surface area.
    pub fraction: f64,
}

/// A scene drawn from a seed (module doc).
#[derive(Clone, Debug)]
pub struct GeneratedScene {
    /// The seed.
    pub seed: u64,
    /// The options it was drawn with.
    pub options: GenerateOptions,
    /// The shape.
    pub shape: ShapeKind,
    /// Materials; region k of [`Self::mesh`] is material k.
    pub materials: Vec<GeneratedMaterial>,
    /// Indices of a same-colour pair.
    pub same_colour: Option<[usize; 2]>,
    /// Every ρd scaled dark.
    pub dark_object: bool,
    /// The board is printed dark.
    pub dark_board: bool,
    /// Capture path.
    pub path: GeneratedPath,
    /// The unit mesh with per-vertex regions.
    pub mesh: TriangleMesh,
    /// Metres per mesh unit.
    pub scale: f64,
    /// Turn about the vertical, degrees.
    pub turn_deg: f64,
    /// Height of the object frame's origin above the board, m (lowest vertex at 0).
    pub lift_m: f64,
}

impl GeneratedScene {
    /// Draws the scene of `seed` (module doc).
    pub fn generate(seed: u64, options: GenerateOptions) -> Self {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let shape = ShapeKind::ALL[rng.random_range(0..ShapeKind::ALL.len())];
        let radius = shape.radius(&mut rng);
        let (positions, faces) = shape::radial_mesh(SUBDIVISIONS, &*radius);
        let count = rng.random_range(2..=8usize);
        let mut rows: Vec<TableMaterial> = TABLE.to_vec();
        rows.shuffle(&mut rng);
        rows.truncate(count);
        let fractions = draw_fractions(&mut rng, count);
        let dark_object = rng.random_bool(0.15);
        let dark_board = rng.random_bool(0.2);
        let mut materials: Vec<GeneratedMaterial> = rows
            .into_iter()
            .zip(&fractions)
            .map(|(row, &fraction)| GeneratedMaterial {
                row,
                params: draw_finish(&mut rng, row.eta, dark_object),
                fraction,
            })
            .collect();
        let same_colour = rng.random_bool(0.5).then(|| {
            let a = rng.random_range(0..count);
            let b = (a + rng.random_range(1..count)) % count;
            materials[b].params.rho_d = materials[a].params.rho_d;
            [a, b]
        });
        let regions = shape::grow_patches(&positions, &faces, &fractions, &mut rng);
        let path = if rng.random_bool(0.5) {
            GeneratedPath::Orbit
        } else {
            GeneratedPath::HandHeld
        };
        let turn_deg = rng.random_range(0.0..360.0);
        let largest_radius_m = rng.random_range(0.032..0.045);
        let max_r = positions
            .iter()
            .map(|p| p.coords.norm())
            .fold(0.0, f64::max);
        let min_z = positions.iter().map(|p| p.z).fold(f64::INFINITY, f64::min);
        let scale = largest_radius_m / max_r;
        let mesh = TriangleMesh::new(positions, None, Some(regions), faces)
            .unwrap_or_else(|e| unreachable!("radial meshes are valid by construction: {e}"));
        Self {
            seed,
            options,
            shape,
            materials,
            same_colour,
            dark_object,
            dark_board,
            path,
            mesh,
            scale,
            turn_deg,
            lift_m: -min_z * scale,
        }
    }

    /// Whether the seed is held out ([`HELD_OUT_SEED_MIN`]).
    pub fn held_out(&self) -> bool {
        self.seed >= HELD_OUT_SEED_MIN
    }

    /// Area share of each material's region as grown.
    pub fn region_fractions(&self) -> Vec<f64> {
        let areas = shape::vertex_areas(self.mesh.positions(), self.mesh.triangles());
        let total: f64 = areas.iter().sum();
        let mut out = vec![0.0; self.materials.len()];
        for (a, r) in areas.iter().zip(self.mesh.regions().unwrap_or(&[])) {
            out[*r as usize] += a / total;
        }
        out
    }

    /// One line saying what the seed drew.
    pub fn describe(&self) -> String {
        format!(
            "seed {}: {} · {} materials (η {}) · {}{}{}{}",
            self.seed,
            self.shape.name(),
            self.materials.len(),
            self.materials
                .iter()
                .map(|m| format!("{:.3}", m.params.eta))
                .collect::<Vec<_>>()
                .join(", "),
            match self.path {
                GeneratedPath::Orbit => "orbit",
                GeneratedPath::HandHeld => "hand-held walk",
            },
            if self.same_colour.is_some() {
                " · same-colour pair"
            } else {
                ""
            },
            if self.dark_object {
                " · dark object"
            } else {
                ""
            },
            if self.dark_board {
                " · dark board"
            } else {
                ""
            },
        )
    }

    /// The scene file's text (module doc); `mesh` and `board` are the files it refers to.
    pub fn scene_toml(&self, mesh: &str, board: &str) -> String {
        let [w, h] = self.options.resolution_px;
        let f = DEMO_FX_PX * f64::from(w) / DEMO_WIDTH_PX;
        let mut t = String::new();
        let _ = writeln!(
            t,
            "# Generated by ellipso-sim's scene generator (seed {}); do not edit: regenerate.\n\
             seed = {}\nname = \"generated-{}\"\ndescription = \"{}\"\n",
            self.seed,
            self.seed,
            self.seed,
            self.describe()
        );
        for m in &self.materials {
            let p = &m.params;
            let _ = writeln!(
                t,
                "# {}\n[materials.{}]\neta = {}\nsigma_s = {}\nsigma_ss = {}\nrho_s = {}\n\
                 rho_ss = {:?}\nrho_d = {:?}\n",
                m.row.source, m.row.name, p.eta, p.sigma_s, p.sigma_ss, p.rho_s, p.rho_ss, p.rho_d
            );
        }
        let regions: Vec<String> = self
            .materials
            .iter()
            .enumerate()
            .map(|(k, m)| format!("{k} = \"{}\"", m.row.name))
            .collect();
        let _ = writeln!(
            t,
            "[[objects]]\nname = \"object\"\nshape = \"mesh\"\nmesh = \"{mesh}\"\n\
             pose = {{ translation_m = [0.0, 0.0, {}], rotation_deg = [0.0, 0.0, {}] }}\n\
             scale = {}\nregions = {{ {} }}\nregion_blend = \"nearest\"\n",
            self.lift_m,
            self.turn_deg,
            self.scale,
            regions.join(", ")
        );
        let _ = writeln!(t, "[[boards]]\nfile = \"{board}\"\npose = {{}}\n");
        let _ = writeln!(
            t,
            "[rig.camera]\nresolution_px = [{w}, {h}]\nfx_px = {f}\nfy_px = {f}\ncx_px = {}\n\
             cy_px = {}\nsensor = \"colour_polar\"\nbit_depth = 12\nexposure_us = 6000.0\n\
             gain_db = 6.0\n",
            (f64::from(w) - 1.0) / 2.0,
            (f64::from(h) - 1.0) / 2.0
        );
        let _ = writeln!(
            t,
            "[rig.flash]\noffset_m = [0.0, -0.03, 0.0]\npolariser_deg = 0.0\n\
             radiant_intensity_w_per_sr = 0.5\nprofile = {{ kind = \"cos_power\", exponent = 1.0 }}\n"
        );
        let n = self.options.photo_count;
        match self.path {
            GeneratedPath::Orbit => {
                let _ = writeln!(
                    t,
                    "[capture]\npath = \"orbit\"\nphoto_count = {n}\nlook_at_m = [0.0, 0.0, 0.04]\n\
                     radius_m = 0.45\nelevation_deg = [20.0, 70.0]\nturns = 2.0\n"
                );
            }
            GeneratedPath::HandHeld => {
                let _ = writeln!(
                    t,
                    "[capture]\npath = \"random_walk\"\nphoto_count = {n}\n\
                     look_at_m = [0.0, 0.0, 0.04]\nelevation_deg = [20.0, 70.0]\n\
                     distance_m = [0.4, 0.6]\nturns = 1.5\nposition_jitter_m = 0.01\n\
                     aim_jitter_deg = 1.5\nroll_jitter_deg = 4.0\n"
                );
            }
        }
        t.push_str(
            "[effects]\nshot_noise = {}\nread_noise = { sigma_e = 2.3 }\nquantisation = {}\n\
             saturation = {}\npolariser_extinction = { ratio = 300.0 }\n",
        );
        t
    }

    /// The board file: the shipped base board, printed dark when the seed says so.
    pub fn board_toml(&self) -> String {
        let shipped = include_str!("../boards/base_a4.toml");
        if !self.dark_board {
            return shipped.to_owned();
        }
        shipped
            .lines()
            .map(|l| {
                if l.starts_with("white_albedo") {
                    "white_albedo = 0.20".to_owned()
                } else if l.starts_with("black_albedo") {
                    "black_albedo = 0.02".to_owned()
                } else {
                    l.to_owned()
                }
            })
            .collect::<Vec<_>>()
            .join("\n")
            + "\n"
    }

    /// Writes `scene.toml`, `object.ply` and `board.toml` into `dir` (created); returns the
    /// scene file's path.
    pub fn write(&self, dir: &Path) -> std::io::Result<PathBuf> {
        std::fs::create_dir_all(dir)?;
        std::fs::write(
            dir.join("object.ply"),
            write_ply(&self.mesh, PlyFormat::BinaryLittleEndian, false),
        )?;
        std::fs::write(dir.join("board.toml"), self.board_toml())?;
        let scene = dir.join("scene.toml");
        std::fs::write(&scene, self.scene_toml("object.ply", "board.toml"))?;
        Ok(scene)
    }
}

/// Area shares of `count` patches (module doc): with probability 0.6 one patch of 2–4 %, the
/// rest from weights U[0.5, 1.5] over what is left, each at least [`MIN_PATCH_FRACTION`].
fn draw_fractions(rng: &mut ChaCha8Rng, count: usize) -> Vec<f64> {
    let small = rng.random_bool(0.6).then(|| rng.random_range(0.02..0.04));
    let rest_count = count - usize::from(small.is_some());
    let rest_share = 1.0 - small.unwrap_or(0.0);
    let weights: Vec<f64> = (0..rest_count)
        .map(|_| rng.random_range(0.5..1.5))
        .collect();
    let sum: f64 = weights.iter().sum();
    let mut out: Vec<f64> = small.into_iter().collect();
    out.extend(
        weights
            .iter()
            .map(|w| (rest_share * w / sum).max(MIN_PATCH_FRACTION)),
    );
    let total: f64 = out.iter().sum();
    // The floor can only add share (at most count · 2 %); renormalise the large ones.
    if total > 1.0 {
        let excess = total - 1.0;
        let big: f64 = out.iter().filter(|&&f| f > 0.1).sum();
        for f in out.iter_mut().filter(|f| **f > 0.1) {
            *f -= excess * *f / big;
        }
    }
    out.shuffle(rng);
    out
}

/// A material's finish (module doc) around the measured `eta`.
fn draw_finish(rng: &mut ChaCha8Rng, eta: f64, dark: bool) -> MaterialSpec {
    let sigma_s = (rng.random_range(0.05f64.ln()..0.5f64.ln())).exp();
    let sigma_ss = (sigma_s * rng.random_range(1.5..3.0)).min(1.0);
    let rho_ss = rng.random_range(0.03..0.2);
    let colour = PALETTE[rng.random_range(0..PALETTE.len())];
    let brightness = rng.random_range(0.8..1.1);
    let rho_d = colour.map(|c| {
        let v: f64 = (c * brightness).min(0.95);
        if dark { v * 0.06 / 0.95 } else { v }
    });
    let round = |v: f64| (v * 1e4).round() / 1e4;
    MaterialSpec {
        eta,
        sigma_s: round(sigma_s),
        sigma_ss: round(sigma_ss.max(sigma_s)),
        rho_s: round(rng.random_range(0.5..1.0)),
        rho_ss: [round(rho_ss); 3],
        rho_d: rho_d.map(round),
    }
}

#[cfg(test)]
mod tests;
