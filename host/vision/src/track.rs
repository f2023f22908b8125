//! Pose tracking: each raw frame → the camera's pose in the world, or a typed rejection.
//!
//! Runs behind the recorder (on a recorded session or a replay), never on the acquisition path,
//! so a slow detector cannot drop frames.
//!
//! Per frame:
//! 1. The detection image ([`DetectImage`], [`detection_image`]): `s0` on the full raw
//!    resolution with each mosaic phase's gain divided out ([`crate::flat_raw`]), `I0`/`I90` on
//!    the superpixel demosaic (no interpolation):
//!    `s0` by default — on matte paper boards it has twice the signal of one analyser and gave
//!    ~5× smaller rotation errors than `I90` or `I0` in `ellipso bench pose` (docs/pose.md).
//!    `I90` (cross-polarised) is the choice for glossy or laminated boards, where the flash's
//!    specular glare lives in the co-polarised `I0` and `s0`.
//! 2. Scale to 8 bits by the 99.5th percentile (AprilTag thresholds locally; the scaling only
//!    keeps the dynamic range) and detect tags.
//! 3. Corners in raw pixels: `s0`'s are already; a superpixel of a `t × t` tile at integer
//!    coordinate `u` covers raw pixels `t·u … t·u + t − 1`, so its centre is raw
//!    `t·u + (t − 1)/2`. Then each tag's sides are fitted on the raw pixels with a level per
//!    mosaic phase and its corners are their intersections ([`crate::pose::raw_edges`]): the
//!    detector's corners carry the flattened image's residual phase pattern (`I0`/`I90`: the
//!    tile's quantisation).
//! 4. Joint PnP per board over all its detected corners (IPPE + LM with distortion, flip check),
//!    keep the board with the most corners, and express the pose in the world through that
//!    board's `world_from_board`.

use ellipso_model::camera::CameraModel;
use nalgebra::{Isometry3, Point3};

use crate::pose::raw_edges::{RawImage, refine_corners};
use crate::pose::{
    BoardCorners, BoardPose, DetectError, DetectorConfig, PoseConfig, TagDetection, TagDetector,
    TagFamily, assemble_correspondences, estimate_board_pose,
};
use ellipso_polar::frame::RawFrame;
use ellipso_polar::intensity::{IntensityPlane, intensity_plane};

/// Which analyser image tags are detected on.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Serialize, serde::Deserialize)]
#[cfg_attr(feature = "clap", derive(clap::ValueEnum))]
#[serde(rename_all = "snake_case")]
pub enum DetectImage {
    /// Total intensity s0 (all four analysers): most signal; the default for matte boards.
    #[default]
    S0,
    /// Cross-polarised I90: diffuse only, the flash's specular glare suppressed (glossy boards).
    I90,
    /// Co-polarised I0: carries the specular glare.
    I0,
}

/// Settings of the tracker.
#[derive(Debug, Clone, Default)]
pub struct TrackConfig {
    /// Detection image.
    pub image: DetectImage,
    /// AprilTag detector settings.
    pub detector: DetectorConfig,
    /// Pose estimation and rejection thresholds.
    pub pose: PoseConfig,
}

/// A frame's pose.
#[derive(Debug, Clone)]
pub struct FramePose {
    /// Camera frame → world frame.
    pub world_from_camera: Isometry3<f64>,
    /// Index of the board the pose came from.
    pub board: usize,
    /// The board pose (residuals, covariance, flip margin).
    pub board_pose: BoardPose,
}

/// Why a frame has no pose.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum TrackRejection {
    /// No tag of any known board was detected.
    #[error("no tag of a known board detected")]
    NoTags,
    /// Every board's pose was rejected; the reason of the board with most corners.
    #[error("{0}")]
    Pose(String),
    /// The frame could not be processed.
    #[error("frame not processable: {0}")]
    Frame(String),
}

pub use ellipso_session::rig::TrackedBoard;

/// What tracking adds to a recorded board: its detector family.
pub trait TrackedBoardExt: Sized {
    /// The detector family of this board's tags.
    fn tag_family(&self) -> Result<TagFamily, DetectError>;
}

impl TrackedBoardExt for TrackedBoard {
    fn tag_family(&self) -> Result<TagFamily, DetectError> {
        match self.family.as_str() {
            "tag36h11" => Ok(TagFamily::Tag36h11),
            "tag25h9" => Ok(TagFamily::Tag25h9),
            "tag16h5" => Ok(TagFamily::Tag16h5),
            other => Err(DetectError::InvalidSetting {
                name: "board tag family",
                value: format!("'{other}' (tracked families: tag36h11, tag25h9, tag16h5)"),
            }),
        }
    }
}

impl BoardCorners for TrackedBoard {
    fn corners_board_m(&self, tag_id: u32) -> Option<[Point3<f64>; 4]> {
        self.corners_board_m
            .get(&tag_id)
            .map(|c| c.map(|[x, y, z]| Point3::new(x, y, z)))
    }
}

/// One AprilTag detector per tag family a set of boards uses, so every board is detected in
/// its own family (tag36h11, tag25h9 and tag16h5 boards alike).
pub struct FamilyDetectors {
    detectors: Vec<(TagFamily, TagDetector)>,
    families: Vec<TagFamily>,
}

impl FamilyDetectors {
    /// Detectors for the families of `boards` (`config.family` is replaced per family).
    pub fn new(boards: &[TrackedBoard], config: DetectorConfig) -> Result<Self, DetectError> {
        let families = boards
            .iter()
            .map(TrackedBoard::tag_family)
            .collect::<Result<Vec<_>, _>>()?;
        let mut detectors: Vec<(TagFamily, TagDetector)> = Vec::new();
        for &family in &families {
            if !detectors.iter().any(|(f, _)| *f == family) {
                let detector = TagDetector::new(DetectorConfig { family, ..config })?;
                detectors.push((family, detector));
            }
        }
        Ok(Self {
            detectors,
            families,
        })
    }

    /// Every family's detections in `frame` (see [`detect_frame`]).
    pub fn detect(
        &mut self,
        frame: &RawFrame,
        image: DetectImage,
    ) -> Result<Vec<TagDetection>, TrackRejection> {
        let mut all = Vec::new();
        for (_, detector) in &mut self.detectors {
            all.extend(detect_frame(detector, frame, image)?);
        }
        Ok(all)
    }

    /// The detections of board `index`'s family.
    pub fn of_board(&self, detections: &[TagDetection], index: usize) -> Vec<TagDetection> {
        let family = self.families[index];
        detections
            .iter()
            .filter(|d| d.family == family)
            .cloned()
            .collect()
    }
}

/// Tracks frames of one rig against a set of boards.
pub struct Tracker {
    camera: CameraModel,
    boards: Vec<TrackedBoard>,
    detectors: FamilyDetectors,
    config: TrackConfig,
}

impl Tracker {
    /// A tracker for `camera` (full raw resolution) and `boards`.
    pub fn new(
        camera: CameraModel,
        boards: Vec<TrackedBoard>,
        config: TrackConfig,
    ) -> Result<Self, DetectError> {
        let detectors = FamilyDetectors::new(&boards, config.detector)?;
        Ok(Self {
            camera,
            boards,
            detectors,
            config,
        })
    }

    /// The pose of one frame.
    pub fn track(&mut self, frame: &RawFrame) -> Result<FramePose, TrackRejection> {
        let detections = self.detectors.detect(frame, self.config.image)?;
        let mut best: Option<(usize, usize, Result<BoardPose, String>)> = None;
        for (i, placed) in self.boards.iter().enumerate() {
            let assembly =
                assemble_correspondences(&self.detectors.of_board(&detections, i), placed);
            let n = assembly.correspondences.len();
            if n == 0 || best.as_ref().is_some_and(|(_, m, _)| *m >= n) {
                continue;
            }
            let r = estimate_board_pose(&self.camera, &assembly.correspondences, &self.config.pose)
                .map_err(|e| e.to_string());
            best = Some((i, n, r));
        }
        match best {
            None => Err(TrackRejection::NoTags),
            Some((_, _, Err(reason))) => Err(TrackRejection::Pose(reason)),
            Some((board, _, Ok(board_pose))) => {
                let world_from_board = self.boards[board].world_from_board();
                let world_from_camera = world_from_board * board_pose.camera_from_board.inverse();
                Ok(FramePose {
                    world_from_camera,
                    board,
                    board_pose,
                })
            }
        }
    }
}

/// The detection image of a frame in linear DN (superpixel resolution, colour bands summed):
/// `(plane, width, height)`.
pub fn detection_plane(
    frame: &RawFrame,
    kind: DetectImage,
) -> Result<(Vec<f32>, usize, usize), TrackRejection> {
    let plane = match kind {
        DetectImage::S0 => IntensityPlane::S0,
        DetectImage::I90 => IntensityPlane::I90,
        DetectImage::I0 => IntensityPlane::I0,
    };
    intensity_plane(frame, plane).map_err(|e| TrackRejection::Frame(e.to_string()))
}

/// The 8-bit detection image of a frame and how many raw pixels one of its pixels spans: `s0`
/// at the full raw resolution (each mosaic phase's gain divided out, [`crate::flat_raw`]: the
/// board's ink and paper look the same through every phase), `I0`/`I90` on the superpixel image
/// (one analyser's pixels are a quarter of the mosaic).
pub fn detection_image(
    frame: &RawFrame,
    kind: DetectImage,
) -> Result<(Vec<u8>, usize, usize, usize), TrackRejection> {
    let (plane, w, h, span) = match kind {
        DetectImage::S0 => {
            let (plane, w, h) = crate::flat_raw::flat_raw(frame);
            (plane, w, h, 1)
        }
        _ => {
            let (plane, w, h) = detection_plane(frame, kind)?;
            (plane, w, h, frame.layout().tile_px() as usize)
        }
    };
    let mut sorted: Vec<f32> = plane.iter().copied().filter(|v| v.is_finite()).collect();
    sorted.sort_by(f32::total_cmp);
    let p995 = sorted
        .get(sorted.len().saturating_sub(1) * 995 / 1000)
        .copied()
        .unwrap_or(1.0);
    // guard: an all-dark frame maps to zeros rather than dividing by ~0
    let scale = if p995 > 1e-6 { 255.0 / p995 } else { 0.0 };
    let gray = plane
        .iter()
        .map(|v| (v * scale).clamp(0.0, 255.0) as u8)
        .collect();
    Ok((gray, w, h, span))
}

/// Detections with a corner closer than this to the image border (superpixels: tiles of the
/// raw image, whatever the detection image; outside counts as closer) are dropped. A tag cut by the border is still decoded when
/// its bits are visible, but the quad's edge fit then runs into the frame edge: on the rendered
/// calibration capture such corners were off by 2–27 px (`ellipso bench calibration`, docs/pose.md
/// §3) and made whole views outliers.
pub const BORDER_MARGIN_PX: f64 = 3.0;

/// Detects tags in a raw frame; corners and centres in raw-pixel coordinates (integer-centre
/// convention), ready for the full-resolution camera model. Tags with a corner within
/// [`BORDER_MARGIN_PX`] of the image border are left out.
pub fn detect_frame(
    detector: &mut TagDetector,
    frame: &RawFrame,
    image: DetectImage,
) -> Result<Vec<TagDetection>, TrackRejection> {
    let (gray, w, h, span) = detection_image(frame, image)?;
    // The quad search on a full-resolution image decimates by the tile besides: its quads are
    // then searched at twice the linear resolution the superpixel image gave them (what makes
    // 612×512 colour frames detectable: their superpixel image is 153×128), at a quarter of
    // the cost the full resolution would take; decoding and edges stay at full resolution.
    let tile = frame.layout().tile_px() as usize;
    let base = detector.config().decimation;
    detector.set_decimation(if span == 1 {
        base * tile as f32 / 2.0
    } else {
        base
    });
    let mut detections = detector
        .detect(&gray, w, h)
        .map_err(|e| TrackRejection::Frame(e.to_string()))?;
    // The margin is the same on the raw image whatever the detection image's resolution.
    let margin = BORDER_MARGIN_PX * (tile / span) as f64;
    let (max_x, max_y) = (w as f64 - 1.0 - margin, h as f64 - 1.0 - margin);
    detections.retain(|d| {
        d.corners_px
            .iter()
            .all(|c| (margin..=max_x).contains(&c[0]) && (margin..=max_y).contains(&c[1]))
    });
    let t = span as f64;
    let to_raw = |c: &mut [f64; 2]| {
        c[0] = t * c[0] + (t - 1.0) / 2.0;
        c[1] = t * c[1] + (t - 1.0) / 2.0;
    };
    let raw = RawImage {
        data: frame.data_dn(),
        width: frame.width() as usize,
        height: frame.height() as usize,
        tile,
    };
    for d in &mut detections {
        d.corners_px.iter_mut().for_each(to_raw);
        to_raw(&mut d.centre_px);
        // The corners fitted on the raw pixels (module doc, step 3).
        if let Some(refined) = refine_corners(&raw, &d.corners_px, d.family) {
            d.corners_px = refined;
        }
    }
    Ok(detections)
}
