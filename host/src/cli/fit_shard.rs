//! Sharded fits for job arrays (docs/scale.md): `ellipso fit SESSION --mesh MESH --shard I/N
//! --out PART` fits the observations and step A of the vertices `v % N == I` and writes a part
//! file; `ellipso fit-merge PARTS… --out DIR` checks that the parts belong together (every shard
//! present once; session, mesh, configuration and program agree), runs the global steps
//! (clusters, virtual samples, pooled η, final pass, held-out score) once and writes what
//! `ellipso fit` writes — bit-identical to an unsharded `ellipso fit --outer 1`.

use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::Context;
use ellipso_fit::observe::poses_from_session;
use ellipso_fit::session::{SessionFitConfig, finish_from_joint, solve_shard};
use ellipso_fit::shard::Shard;
use ellipso_fit::shard::merge::merge_parts;
use ellipso_fit::shard::part::{PartFile, config_hash, file_hash, session_hash};
use ellipso_model::geometry::TriangleMesh;
use ellipso_report::output::{FileFormat, OutputDir, OutputFile};
use ellipso_session::reader::Session;

/// The recorded poses, refusing to track: shards run at once and must not append to the log.
fn recorded_poses(session: &Session) -> anyhow::Result<Vec<(u64, nalgebra::Isometry3<f64>)>> {
    let untracked = ellipso_vision::process::untracked_frames(session);
    anyhow::ensure!(
        untracked.is_empty(),
        "{}: {} complete frames have no pose yet; a sharded fit does not track (its shards run \
         at once): run `ellipso mesh {}` once first (it tracks and records the poses, and \
         carves the mesh the shards fit)",
        session.dir.display(),
        untracked.len(),
        session.dir.display()
    );
    let poses = poses_from_session(session);
    anyhow::ensure!(
        !poses.is_empty(),
        "{}: no frame has a pose",
        session.dir.display()
    );
    Ok(poses)
}

/// The part file format: `.part`, starting with the part magic.
const PART: FileFormat = FileFormat {
    name: "fit part",
    extensions: &["part"],
    magic: ellipso_fit::shard::part::MAGIC,
};

/// Claims the part file a shard writes (before its work starts).
pub fn claim_part(out: &Path, inputs: &[&Path]) -> anyhow::Result<OutputFile> {
    Ok(OutputFile::claim(out, "fit", PART, inputs, None)?)
}

/// `ellipso fit --shard`: one shard's part file.
pub fn run_shard(
    session: &Session,
    session_arg: &Path,
    mesh_path: &Path,
    mesh: &TriangleMesh,
    out: &OutputFile,
    shard: Shard,
    config: SessionFitConfig,
) -> anyhow::Result<()> {
    let started = Instant::now();
    let poses = recorded_poses(session)?;
    let config = super::fit::with_session_sensor(session, &config);
    let solve = solve_shard(session, mesh, &poses, &config, shard, &mut |stage| {
        crate::outln!("  {stage}…")
    })?;
    let part = PartFile {
        program_version: env!("CARGO_PKG_VERSION").to_string(),
        shard,
        session_hash: session_hash(session)?,
        mesh_hash: file_hash(mesh_path)?,
        config_hash: config_hash(&config),
        session_dir: std::fs::canonicalize(session_arg).unwrap_or(session_arg.to_path_buf()),
        mesh_path: std::fs::canonicalize(mesh_path).unwrap_or(mesh_path.to_path_buf()),
        mesh_vertices: u32::try_from(mesh.positions().len())
            .context("the mesh has more vertices than a part file indexes")?,
        config,
        set: solve.extraction.samples,
        report: solve.extraction.report,
        fits: solve.fits,
        held_out: solve.held_out,
        observe_s: solve.observe_s,
        joint_s: solve.joint_s,
    };
    part.write(out.path())?;
    crate::outln!(
        "shard {shard}: {} vertices, {} samples in {:.1} s (observations {:.1} s, step A {:.1} s) → {}",
        part.set.vertices.len(),
        part.report.samples,
        started.elapsed().as_secs_f64(),
        part.observe_s,
        part.joint_s,
        out.shown().display()
    );
    Ok(())
}

/// Arguments of `ellipso fit-merge`.
#[derive(Debug, clap::Args)]
pub struct MergeArgs {
    /// The part files of every shard (`ellipso fit --shard I/N --out PART`), in any order.
    #[arg(required = true)]
    pub parts: Vec<PathBuf>,
    /// Output directory (what `ellipso fit` writes).
    #[arg(long)]
    pub out: PathBuf,
    /// Frame id of the view the pictures are rendered from (default: the first fitted frame).
    #[arg(long)]
    pub view: Option<u64>,
    /// The session directory, where it is not at the path the shards recorded (another mount).
    #[arg(long)]
    pub session: Option<PathBuf>,
    /// The mesh file, where it is not at the path the shards recorded.
    #[arg(long)]
    pub mesh: Option<PathBuf>,
}

/// Runs `ellipso fit-merge`.
pub fn run_merge(args: MergeArgs) -> anyhow::Result<()> {
    let started = Instant::now();
    // the output is claimed first; the parts (and a given session or mesh) are its inputs
    let mut inputs: Vec<&Path> = args.parts.iter().map(PathBuf::as_path).collect();
    inputs.extend(args.session.as_deref());
    inputs.extend(args.mesh.as_deref());
    let out = OutputDir::claim(&args.out, "fit", &inputs)?;
    let mut parts = Vec::with_capacity(args.parts.len());
    for path in &args.parts {
        parts.push((path.clone(), PartFile::read(path)?));
    }
    let merged = merge_parts(parts)?;
    let head = &merged.first;
    let session_dir = args.session.clone().unwrap_or(head.session_dir.clone());
    let session = ellipso_session::reader::open(&session_dir)?;
    let hash = session_hash(&session)?;
    anyhow::ensure!(
        hash == head.session_hash,
        "{}: the session's hash is {hash:016x} but the shards fitted {:016x}: it changed since, or \
         is another session",
        session_dir.display(),
        head.session_hash
    );
    let mesh_path = args.mesh.clone().unwrap_or(head.mesh_path.clone());
    let mesh_hash = file_hash(&mesh_path)?;
    anyhow::ensure!(
        mesh_hash == head.mesh_hash,
        "{}: the mesh file's hash is {mesh_hash:016x} but the shards fitted {:016x}",
        mesh_path.display(),
        head.mesh_hash
    );
    let mesh = TriangleMesh::load(&mesh_path)
        .with_context(|| format!("loading mesh {}", mesh_path.display()))?;
    let poses = recorded_poses(&session)?;
    crate::outln!(
        "merging {} shards: {} vertices, {} samples",
        merged.shard_seconds.len(),
        merged.extraction.samples.vertices.len(),
        merged.extraction.report.samples
    );
    let config = merged.config().clone();
    let (observe_s, joint_s) = merged
        .shard_seconds
        .iter()
        .fold((0.0, 0.0), |a, s| (a.0 + s.0, a.1 + s.1));
    let mut fit = finish_from_joint(
        &session,
        &mesh,
        &poses,
        merged.extraction,
        merged.fits,
        merged.held_out,
        &config,
        &mut |stage| crate::outln!("  {stage}…"),
    )?;
    // The shards' seconds, summed (CPU-seconds of the array, not its wall time).
    fit.outcome.times.observe_s = observe_s;
    fit.outcome.times.joint_s = joint_s;
    let result = super::fit::export_fit(
        &session,
        &poses,
        fit,
        super::fit::OutputTo {
            dir: out.path(),
            publish: &|p| out.published(p),
        },
        args.view,
        started,
        None,
    )?;
    let published = out.commit()?;
    super::fit::print_results(&published, &result, false);
    Ok(())
}
