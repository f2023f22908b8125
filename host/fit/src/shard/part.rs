//! The part file a shard writes (`ellipso fit --shard I/N --out PART`) and the merge reads.
//!
//! Layout (little-endian): the 16-byte magic `ELLIPSO-FITPART\n`, the format version (u32), the
//! body's length (u64), the body ([`PartFile`] in postcard, exact f32/f64 bits), and the body's
//! CRC-64/XZ (u64). A file that is cut short, has another magic or version, or whose body does
//! not match its CRC is refused with the reason.
//!
//! The part records what must agree between shards: the session's hash ([`session_hash`]:
//! manifest, event log, and every frame's id, completeness and size), the mesh file's hash, the
//! configuration's hash ([`config_hash`]: every setting but the thread count, which changes no
//! result) and the program version.

use std::path::{Path, PathBuf};

use crc::{CRC_64_XZ, Crc, Table};

use super::Shard;
use crate::data::{SampleSet, VertexFit};
use crate::observe::ObserveReport;
use crate::session::SessionFitConfig;
use ellipso_session::reader::Session;

/// The first bytes of every part file.
pub const MAGIC: &[u8; 16] = b"ELLIPSO-FITPART\n";
/// The format version this build writes and reads (3: the extraction report counts the
/// narrow-kernel samples it admitted).
pub const VERSION: u32 = 3;

/// Slice-by-16 tables (the same checksum as the byte-wise table, several times faster: every
/// frame file of a session is hashed by every stage that reads it).
const CRC64: Crc<u64, Table<16>> = Crc::<u64, Table<16>>::new(&CRC_64_XZ);

/// What one shard hands the merge.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct PartFile {
    /// The `ellipso` version that wrote it.
    pub program_version: String,
    /// Which shard.
    pub shard: Shard,
    /// [`session_hash`] of the session.
    pub session_hash: u64,
    /// CRC-64 of the mesh file's bytes.
    pub mesh_hash: u64,
    /// [`config_hash`] of `config`.
    pub config_hash: u64,
    /// The session directory as the shard was given it.
    pub session_dir: PathBuf,
    /// The mesh file as the shard was given it.
    pub mesh_path: PathBuf,
    /// Vertices of the whole mesh.
    pub mesh_vertices: u32,
    /// The fit's settings (the sensor model from the session already applied).
    pub config: SessionFitConfig,
    /// The shard's observations of the fitted frames: every view, its own vertices.
    pub set: SampleSet,
    /// The extraction report of those observations.
    pub report: ObserveReport,
    /// Step A's result per vertex of `set.vertices`.
    pub fits: Vec<VertexFit>,
    /// The shard's observations of the held-out frames (`None`: none held out).
    pub held_out: Option<SampleSet>,
    /// Seconds of extraction in the shard.
    pub observe_s: f64,
    /// Seconds of step A in the shard.
    pub joint_s: f64,
}

/// Why a part file cannot be written or read.
#[derive(Debug, thiserror::Error)]
pub enum PartError {
    /// The file system refused.
    #[error("{}: {source}", path.display())]
    Io {
        /// The file.
        path: PathBuf,
        /// What the system said.
        source: std::io::Error,
    },
    /// The bytes are not a part file of this format.
    #[error("{}: not a usable part file: {what}", path.display())]
    Format {
        /// The file.
        path: PathBuf,
        /// What is wrong.
        what: String,
    },
}

impl PartFile {
    /// The file's bytes (see the module doc).
    pub fn to_bytes(&self) -> Vec<u8> {
        let body = postcard::to_stdvec(self).expect("a part serialises (no map keys, no I/O)");
        let mut out = Vec::with_capacity(body.len() + 36);
        out.extend_from_slice(MAGIC);
        out.extend_from_slice(&VERSION.to_le_bytes());
        out.extend_from_slice(&(body.len() as u64).to_le_bytes());
        out.extend_from_slice(&body);
        out.extend_from_slice(&CRC64.checksum(&body).to_le_bytes());
        out
    }

    /// Parses a part file's bytes; `path` names it in errors.
    pub fn from_bytes(bytes: &[u8], path: &Path) -> Result<Self, PartError> {
        let bad = |what: String| PartError::Format {
            path: path.to_path_buf(),
            what,
        };
        if bytes.len() < 28 || &bytes[..16] != MAGIC {
            return Err(bad(
                "it does not start with the part-file magic (write it with `ellipso fit --shard`)"
                    .into(),
            ));
        }
        let version = u32::from_le_bytes(bytes[16..20].try_into().expect("4 bytes"));
        if version != VERSION {
            return Err(bad(format!(
                "format version {version}, this build reads {VERSION}: merge with the ellipso \
                 that wrote the parts"
            )));
        }
        let len = u64::from_le_bytes(bytes[20..28].try_into().expect("8 bytes"));
        let expected = usize::try_from(len)
            .ok()
            .and_then(|l| l.checked_add(36))
            .ok_or_else(|| bad(format!("body length {len} is impossible")))?;
        if bytes.len() != expected {
            return Err(bad(format!(
                "{} bytes but the header says {expected}: the file is cut short or has trailing \
                 bytes (did the shard finish?)",
                bytes.len()
            )));
        }
        let body = &bytes[28..28 + len as usize];
        let crc = u64::from_le_bytes(bytes[expected - 8..].try_into().expect("8 bytes"));
        if CRC64.checksum(body) != crc {
            return Err(bad(
                "its checksum does not match: the file is corrupt".into()
            ));
        }
        let part: PartFile =
            postcard::from_bytes(body).map_err(|e| bad(format!("body does not decode: {e}")))?;
        // the shard as written by `--shard I/N`, which refuses I ≥ N and N = 0
        if part.shard.count == 0 || part.shard.index >= part.shard.count {
            return Err(bad(format!(
                "its shard {} is impossible (the index must be below the count): not a part \
                 `ellipso fit --shard` wrote",
                part.shard
            )));
        }
        if part.fits.len() != part.set.vertices.len() {
            return Err(bad(format!(
                "{} step-A results for {} vertices",
                part.fits.len(),
                part.set.vertices.len()
            )));
        }
        Ok(part)
    }

    /// Writes the part atomically (a half-written part is never seen under `path`).
    pub fn write(&self, path: &Path) -> Result<(), PartError> {
        ellipso_report::atomic_file::write(path, self.to_bytes()).map_err(|source| PartError::Io {
            path: path.to_path_buf(),
            source,
        })
    }

    /// Reads and checks a part file. The read is bounded by the header: a regular file only,
    /// at most the 28 header bytes plus the body length they state plus the checksum (and one
    /// byte more, so trailing bytes are seen).
    pub fn read(path: &Path) -> Result<Self, PartError> {
        use ellipso_model::file_io::{check_regular, read_bounded};
        use std::io::Read;
        let io = |source| PartError::Io {
            path: path.to_path_buf(),
            source,
        };
        check_regular(path, u64::MAX).map_err(io)?;
        let mut head = Vec::with_capacity(28);
        std::fs::File::open(path)
            .and_then(|f| f.take(28).read_to_end(&mut head))
            .map_err(io)?;
        let cap = if head.len() == 28 && &head[..16] == MAGIC {
            u64::from_le_bytes(head[20..28].try_into().expect("8 bytes")).saturating_add(37)
        } else {
            28
        };
        let bytes = read_bounded(path, cap).or_else(|e| {
            // longer than the header says: read as much as it may hold and let the check say so
            if e.kind() == std::io::ErrorKind::InvalidData {
                let mut b = Vec::new();
                std::fs::File::open(path)
                    .and_then(|f| f.take(cap).read_to_end(&mut b))
                    .map_err(io)?;
                Ok(b)
            } else {
                Err(io(e))
            }
        })?;
        Self::from_bytes(&bytes, path)
    }
}

/// CRC-64/XZ of a file's bytes (a mesh: bounded as a mesh is).
pub fn file_hash(path: &Path) -> Result<u64, PartError> {
    ellipso_model::file_io::read_bounded(path, ellipso_model::file_io::caps::MESH)
        .map(|b| CRC64.checksum(&b))
        .map_err(|source| PartError::Io {
            path: path.to_path_buf(),
            source,
        })
}

/// The session's identity for the merge's check: CRC-64/XZ over the manifest's and the event
/// log's bytes and every frame's id, completeness and file size (frames are not read whole: a
/// job array must not re-read the whole capture to agree on it).
pub fn session_hash(session: &Session) -> Result<u64, PartError> {
    let mut digest = CRC64.digest();
    for name in [
        ellipso_session::paths::MANIFEST,
        ellipso_session::paths::EVENTS,
    ] {
        let path = session.dir.join(name);
        let cap = if name == ellipso_session::paths::MANIFEST {
            ellipso_model::file_io::caps::MANIFEST
        } else {
            ellipso_model::file_io::caps::EVENT_LOG
        };
        match ellipso_model::file_io::read_bounded(&path, cap) {
            Ok(bytes) => {
                digest.update(&(bytes.len() as u64).to_le_bytes());
                digest.update(&bytes);
            }
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => digest.update(&[0xff; 8]),
            Err(source) => return Err(PartError::Io { path, source }),
        }
    }
    for f in &session.frames {
        let size = std::fs::metadata(&f.path)
            .map_err(|source| PartError::Io {
                path: f.path.clone(),
                source,
            })?
            .len();
        digest.update(&f.frame_id.to_le_bytes());
        digest.update(&[u8::from(f.complete)]);
        digest.update(&size.to_le_bytes());
    }
    Ok(digest.finalize())
}

/// CRC-64/XZ of the configuration's postcard bytes with the thread count cleared (results do
/// not depend on it).
pub fn config_hash(config: &SessionFitConfig) -> u64 {
    let mut c = config.clone();
    c.observe.threads = None;
    CRC64.checksum(&postcard::to_stdvec(&c).expect("a config serialises"))
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;
    use crate::data::{Sample, VertexSamples};

    /// A small part of a 5-vertex mesh (shared with the merge's tests).
    pub(crate) fn part(shard: Shard) -> PartFile {
        let vertices: Vec<VertexSamples> = shard
            .vertices(5)
            .map(|v| VertexSamples {
                vertex: v as u32,
                position_world: [v as f64, 0.1, 0.2],
                normal_world: [0.0, 0.0, 1.0],
                samples: vec![Sample {
                    view: 0,
                    channels: [[0.1, 0.2, f32::MIN_POSITIVE, 0.4]; 3],
                    normaliser: 123.25,
                }],
                gates: Default::default(),
            })
            .collect();
        let fits = vertices
            .iter()
            .map(|v| VertexFit {
                vertex: v.vertex,
                params: ellipso_model::optics::pbrdf::PbrdfParams {
                    eta: 1.5 + f64::EPSILON,
                    sigma_s: 0.1,
                    sigma_ss: 0.3,
                    rho_s: 0.5,
                    rho_ss: [0.1; 3],
                    rho_d: [0.2; 3],
                },
                normal_world: [0.0, 0.0, 1.0],
                std_error: [f64::INFINITY; 10],
                normal_std_error_deg: 1.0,
                samples_used: 1,
                cost: 0.5,
                iterations: 3,
                flags: vec![crate::data::FitFlag::TooFewViews],
                eta_unpooled: None,
                eta_prior_only: false,
                gates: Default::default(),
            })
            .collect();
        PartFile {
            program_version: "test".into(),
            shard,
            session_hash: 1,
            mesh_hash: 2,
            config_hash: config_hash(&SessionFitConfig::default()),
            session_dir: "session".into(),
            mesh_path: "mesh.ply".into(),
            mesh_vertices: 5,
            config: SessionFitConfig::default(),
            set: SampleSet {
                views: vec![crate::data::ViewGeometry {
                    frame_id: 7,
                    camera_position_world: [0.0, 0.0, 0.5],
                    camera_up_world: [0.0, 1.0, 0.0],
                    flash_position_world: [0.03, 0.0, 0.5],
                    polariser_axis_world: Some([1.0, 0.0, 0.0]),
                    camera_axis_world: None,
                }],
                colour: true,
                vertices,
                rings: Vec::new(),
            },
            report: ObserveReport::default(),
            fits,
            held_out: None,
            observe_s: 1.0,
            joint_s: 2.0,
        }
    }

    #[test]
    fn a_part_round_trips_bit_exactly() {
        let p = part(Shard::new(1, 2).unwrap());
        let bytes = p.to_bytes();
        assert_eq!(PartFile::from_bytes(&bytes, Path::new("x")).unwrap(), p);
    }

    #[test]
    fn truncated_corrupt_and_foreign_files_are_refused_with_the_reason() {
        let bytes = part(Shard::ALL).to_bytes();
        let why = |b: &[u8]| {
            PartFile::from_bytes(b, Path::new("p.part"))
                .unwrap_err()
                .to_string()
        };
        assert!(why(&bytes[..bytes.len() - 1]).contains("cut short"));
        let mut flipped = bytes.clone();
        flipped[40] ^= 1;
        assert!(why(&flipped).contains("checksum"));
        assert!(why(b"ply\nformat ascii 1.0\n........").contains("magic"));
        let mut other = bytes.clone();
        other[16] = 9;
        assert!(why(&other).contains("version 9"));
        assert!(why(&bytes[..10]).starts_with("p.part: "));
        // a part whose shard index is not below its count, checksum and all valid (issue 28,
        // case 5: the merge indexed by it and panicked)
        let mut impossible = part(Shard::ALL);
        impossible.shard = Shard { index: 5, count: 2 };
        assert!(why(&impossible.to_bytes()).contains("shard 5/2 is impossible"));
    }

    #[test]
    fn reading_is_bounded_by_the_header_and_refuses_special_files() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("p.part");
        let mut bytes = part(Shard::ALL).to_bytes();
        bytes.extend_from_slice(&[0u8; 4096]);
        std::fs::write(&p, &bytes).unwrap();
        let e = PartFile::read(&p).unwrap_err().to_string();
        assert!(e.contains("trailing"), "{e}");
        let e = PartFile::read(Path::new("/dev/zero"))
            .unwrap_err()
            .to_string();
        assert!(e.contains("character device"), "{e}");
    }

    #[test]
    fn the_config_hash_ignores_threads_and_sees_every_setting() {
        let a = SessionFitConfig::default();
        let mut threads = a.clone();
        threads.observe.threads = Some(3);
        assert_eq!(config_hash(&a), config_hash(&threads));
        let mut prior = a.clone();
        prior.fit.solver.normal_prior_deg = 11.0;
        assert_ne!(config_hash(&a), config_hash(&prior));
    }
}
