//! Regenerates the procedural mesh assets under `sim/assets/`.
//!
//! Run from the workspace root: `cargo run -p ellipso-sim --example make_assets`.
//! The unit test `scene::tests::shipped_blob_matches_its_generator` checks the committed file
//! against the same parameters, so change both together.

use ellipso_sim::geometry::ply::{PlyFormat, write_ply};
use ellipso_sim::geometry::procedural::{
    BLOB_AMPLITUDE, BLOB_REGIONS, BLOB_SEED, BLOB_SUBDIVISIONS, bumpy_icosphere,
};
use std::path::Path;

fn main() -> std::io::Result<()> {
    let out = Path::new(env!("CARGO_MANIFEST_DIR")).join("assets/bumpy_blob.ply");
    let mesh = bumpy_icosphere(BLOB_SUBDIVISIONS, BLOB_AMPLITUDE, BLOB_REGIONS, BLOB_SEED);
    let bytes = write_ply(&mesh, PlyFormat::BinaryLittleEndian, false);
    std::fs::write(&out, &bytes)?;
    println!(
        "wrote {} ({} vertices, {} triangles, {} regions, {} bytes)",
        out.display(),
        mesh.positions().len(),
        mesh.triangles().len(),
        mesh.region_count(),
        bytes.len()
    );
    Ok(())
}
