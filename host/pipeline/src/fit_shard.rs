//! Sharded fits for job arrays as the subcommands run them (docs/scale.md): `ellipso fit
//! SESSION --mesh MESH --shard I/N --out PART` fits the observations and step A of the vertices
//! `v % N == I` and writes a part file ([`run_shard`]); `ellipso fit-merge PARTS… --out DIR`
//! checks that the parts belong together (every shard present once; session, mesh,
//! configuration and program agree), runs the global steps (clusters, virtual samples, pooled
//! η, final pass, held-out score) once and writes what `ellipso fit` writes ([`run_merge`]) —
//! bit-identical to an unsharded `ellipso fit --outer 1`.
//!
//! Contract: shards run at once and never track: they take the session's recorded poses and
//! refuse a session with untracked frames ([`recorded_poses`]); nothing here appends to the
//! session. Each stage's line goes to the caller's [`Say`] (stdout); nothing here prints.

use std::path::{Path, PathBuf};
use std::time::Instant;

use ellipso_fit::output::{FitRun, OutputTo, export_fit};
use ellipso_fit::session::{SessionFitConfig, finish_from_joint, solve_shard, with_session_sensor};
use ellipso_fit::shard::Shard;
use ellipso_fit::shard::merge::merge_parts;
use ellipso_fit::shard::part::{PartFile, config_hash, file_hash, session_hash};
use ellipso_model::geometry::TriangleMesh;
use ellipso_report::output::{FileFormat, OutputDir, OutputFile};
use ellipso_run_error::{Context, RunError, Say};
use ellipso_session::reader::Session;
use nalgebra::Isometry3;

/// The recorded poses, refusing to track: shards run at once and must not append to the log.
pub fn recorded_poses(
    session: &Session,
    say: &dyn Say,
) -> Result<Vec<(u64, Isometry3<f64>)>, RunError> {
    let check = crate::poses::checked_frames(session, say)?;
    let stale = ellipso_session::provenance::stale_outcomes(
        &session.poses(),
        &check,
        &session.manifest.boards,
    );
    ellipso_run_error::ensure!(
        stale.is_empty(),
        "{}: {} frames' recorded tracking is stale ({}); a sharded fit does not track (its \
         shards run at once): run `ellipso mesh {}` once first (it tracks them again)",
        session.dir.display(),
        stale.len(),
        crate::poses::stale_list(&stale),
        session.dir.display()
    );
    let untracked = ellipso_vision::process::untracked_frames(session);
    ellipso_run_error::ensure!(
        untracked.is_empty(),
        "{}: {} complete frames have no pose yet; a sharded fit does not track (its shards run \
         at once): run `ellipso mesh {}` once first (it tracks and records the poses, and \
         carves the mesh the shards fit)",
        session.dir.display(),
        untracked.len(),
        session.dir.display()
    );
    let poses = session.poses().tracked();
    ellipso_run_error::ensure!(
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
pub fn claim_part(out: &Path, inputs: &[&Path]) -> Result<OutputFile, RunError> {
    Ok(OutputFile::claim(out, "fit", PART, inputs, None)?)
}

/// What one shard wrote.
pub struct ShardRun {
    /// Its part file, as shown.
    pub part: PathBuf,
    /// Its vertices.
    pub vertices: usize,
    /// Its samples.
    pub samples: u64,
    /// Wall time of the shard, seconds.
    pub wall_s: f64,
    /// Observation time, seconds.
    pub observe_s: f64,
    /// Step A time, seconds.
    pub joint_s: f64,
}

/// The inputs of one shard: the session (and its path as given), the mesh (and its file).
pub struct ShardInputs<'a> {
    /// The opened session.
    pub session: &'a Session,
    /// The session's folder as given (recorded, resolved, in the part file).
    pub session_dir: &'a Path,
    /// The mesh file (its hash and resolved path go into the part file).
    pub mesh_path: &'a Path,
    /// The mesh read from it.
    pub mesh: &'a TriangleMesh,
}

/// `ellipso fit --shard`: one shard's part file, written to the claimed `out`.
pub fn run_shard(
    inputs: ShardInputs<'_>,
    out: &OutputFile,
    shard: Shard,
    config: SessionFitConfig,
    say: &dyn Say,
) -> Result<ShardRun, RunError> {
    let ShardInputs {
        session,
        session_dir,
        mesh_path,
        mesh,
    } = inputs;
    let started = Instant::now();
    let poses = recorded_poses(session, say)?;
    let config = with_session_sensor(session, &config);
    let solve = solve_shard(session, mesh, &poses, &config, shard, &mut |stage| {
        say.out(format_args!("  {stage}…"))
    })?;
    let part = PartFile {
        // the workspace's one version: every crate of the program shares it
        program_version: env!("CARGO_PKG_VERSION").to_string(),
        shard,
        session_hash: session_hash(session)?,
        mesh_hash: file_hash(mesh_path)?,
        config_hash: config_hash(&config),
        session_dir: std::fs::canonicalize(session_dir).unwrap_or(session_dir.to_path_buf()),
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
    Ok(ShardRun {
        part: out.shown().to_path_buf(),
        vertices: part.set.vertices.len(),
        samples: part.report.samples,
        wall_s: started.elapsed().as_secs_f64(),
        observe_s: part.observe_s,
        joint_s: part.joint_s,
    })
}

/// What `ellipso fit-merge` is given.
pub struct MergeRequest<'a> {
    /// The part files of every shard, in any order.
    pub parts: &'a [PathBuf],
    /// The output folder (what `ellipso fit` writes).
    pub out: &'a Path,
    /// Frame id of the pictures' view (default: the first fitted frame).
    pub view: Option<u64>,
    /// The session folder, where it is not at the path the shards recorded.
    pub session: Option<&'a Path>,
    /// The mesh file, where it is not at the path the shards recorded.
    pub mesh: Option<&'a Path>,
}

/// `ellipso fit-merge`: checks the parts, runs the global steps once, writes and commits the
/// output folder; returns where it is and what was written.
pub fn run_merge(request: &MergeRequest<'_>, say: &dyn Say) -> Result<(PathBuf, FitRun), RunError> {
    let started = Instant::now();
    // the output is claimed first; the parts (and a given session or mesh) are its inputs
    let mut inputs: Vec<&Path> = request.parts.iter().map(PathBuf::as_path).collect();
    inputs.extend(request.session);
    inputs.extend(request.mesh);
    let out = OutputDir::claim(request.out, "fit", &inputs)?;
    let mut parts = Vec::with_capacity(request.parts.len());
    for path in request.parts {
        parts.push((path.clone(), PartFile::read(path)?));
    }
    let merged = merge_parts(parts)?;
    let head = &merged.first;
    let session_dir = request
        .session
        .map_or(head.session_dir.clone(), Path::to_path_buf);
    let session = ellipso_session::reader::open(&session_dir)?;
    let hash = session_hash(&session)?;
    ellipso_run_error::ensure!(
        hash == head.session_hash,
        "{}: the session's hash is {hash:016x} but the shards fitted {:016x}: it changed since, or \
         is another session",
        session_dir.display(),
        head.session_hash
    );
    let mesh_path = request
        .mesh
        .map_or(head.mesh_path.clone(), Path::to_path_buf);
    let mesh_hash = file_hash(&mesh_path)?;
    ellipso_run_error::ensure!(
        mesh_hash == head.mesh_hash,
        "{}: the mesh file's hash is {mesh_hash:016x} but the shards fitted {:016x}",
        mesh_path.display(),
        head.mesh_hash
    );
    let mesh = TriangleMesh::load(&mesh_path)
        .with_context(|| format!("loading mesh {}", mesh_path.display()))?;
    let poses = recorded_poses(&session, say)?;
    say.out(format_args!(
        "merging {} shards: {} vertices, {} samples",
        merged.shard_seconds.len(),
        merged.extraction.samples.vertices.len(),
        merged.extraction.report.samples
    ));
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
        &mut |stage| say.out(format_args!("  {stage}…")),
    )?;
    // The shards' seconds, summed (CPU-seconds of the array, not its wall time).
    fit.outcome.times.observe_s = observe_s;
    fit.outcome.times.joint_s = joint_s;
    let run = export_fit(
        &session,
        &poses,
        fit,
        OutputTo {
            dir: out.path(),
            publish: &|p| out.published(p),
        },
        request.view,
        started,
        None,
        say,
    )?;
    Ok((out.commit()?, run))
}
