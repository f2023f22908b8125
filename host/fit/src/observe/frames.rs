//! Where an extraction gets each posed frame's analyser pixels: the [`FrameImages`] source and
//! the session's recorded mosaics ([`MosaicFrames`]).
//!
//! Contract:
//! - [`MosaicFrames::load`] reads PNG → raw mosaic → superpixel demosaic → [`DnImage`]
//!   (sampled at the analysers' lattice positions or the tile centres, [`super::SamplePoint`]).
//! - **Without a cache** ([`MosaicFrames::new`]) it does so each time it is asked: nothing is
//!   kept between reads, so an extraction holds at most its frames in flight.
//! - **With a cache** ([`MosaicFrames::caching`], what a fit's outer loop uses: it extracts the
//!   same frames once per iteration) each frame's [`DnImage`] is kept after its first read,
//!   cropped to the part an extraction samples — the rectangle around the mesh's projected
//!   vertices, grown by [`CACHE_MARGIN_FRACTION`] of its size and [`CACHE_MARGIN_PX`] so that
//!   a surface update's moves stay inside it. A later read whose rectangle the crop does not
//!   cover ([`DnImage::covers`]) decodes the frame again and replaces the crop; a frame that
//!   would take the cache past its byte budget is not kept. A crop samples bit-identically to
//!   the whole frame, so an extraction's result does not depend on the cache (tested). Measured
//!   on the demo session (docs/fit-observe.md "Frame cache"): the decode was 37 % of a
//!   four-iteration fit's CPU time and becomes one read per frame; the crops of its 135
//!   frames hold 73 MB where the whole DN images would hold 635 MB.
//! - An unreadable frame is never cached: each read reports it again.
//! - **Sensor calibration.** With `ObserveConfig::sensor_calibration` the frames are read at the
//!   calibration's black level and each superpixel through its own analysis matrix, written
//!   back as the session's modelled analysers would record it
//!   ([`ellipso_polar::sensor_calibration::CalibratedDemosaic`]); without one, exactly the
//!   plain superpixel demosaic at `dark_level_dn`.

use std::collections::HashMap;
use std::sync::{Arc, Mutex};

use ellipso_model::mosaic::SensorLayout;
use ellipso_polar::PolarConfig;
use ellipso_polar::demosaic::{DemosaicMethod, demosaic};
use ellipso_polar::frame::RawFrame;
use ellipso_polar::sensor_calibration::CalibratedDemosaic;
use ellipso_session::reader::{FrameEntry, Session};

use super::image::{AnalyserPixels, DnImage, PixelRect, SampleKernel};
use super::{ObserveConfig, ObserveError, SamplePoint};

/// A cached crop is the sampled rectangle grown by this fraction of its larger side…
pub const CACHE_MARGIN_FRACTION: f64 = 0.1;
/// …plus this many raw pixels on every side.
pub const CACHE_MARGIN_PX: f64 = 16.0;

/// Where an extraction gets each posed frame's analyser pixels.
pub trait FrameImages: Sync {
    /// The analyser pixels of `entry` (a complete, lit frame of the session) and the bytes
    /// held while they are in use (beyond [`FrameImages::held_bytes`]). `region` holds every
    /// raw pixel position the extraction will sample (`None`: none; the frame is still read,
    /// so an unreadable one is reported). An unreadable frame is an `Err` with the reason,
    /// and the extraction skips it.
    fn load(
        &self,
        entry: &FrameEntry,
        region: Option<&PixelRect>,
    ) -> Result<(Box<dyn AnalyserPixels + '_>, usize), String>;

    /// Bytes kept between reads (a cache), 0 when nothing is.
    fn held_bytes(&self) -> usize {
        0
    }
}

/// The session's recorded frames (see the module contract).
pub struct MosaicFrames<'a> {
    session: &'a Session,
    layout: SensorLayout,
    polar: PolarConfig,
    sample_point: SamplePoint,
    sample_kernel: SampleKernel,
    cache: Option<Cache>,
    /// The calibrated demosaic (`None`: the plain one).
    calibrated: Option<CalibratedDemosaic>,
}

/// Cropped frames by frame id, and their bytes.
struct Cache {
    budget_bytes: usize,
    state: Mutex<CacheState>,
}

#[derive(Default)]
struct CacheState {
    frames: HashMap<u64, Arc<DnImage>>,
    bytes: usize,
}

impl<'a> MosaicFrames<'a> {
    /// The recorded frames of `session` read with `config`'s dark level and sample point,
    /// decoded at every read.
    pub fn new(session: &'a Session, config: &ObserveConfig) -> Result<Self, ObserveError> {
        let layout = session.manifest.sensor.layout;
        let mut polar = PolarConfig {
            demosaic: DemosaicMethod::Superpixel,
            dark_level_dn: config.dark_level_dn,
            ..PolarConfig::default()
        };
        let calibrated = config.sensor_calibration.as_ref().map(|cal| {
            let modelled = session
                .manifest
                .rig
                .as_ref()
                .and_then(|r| r.analyser_extinction_ratio);
            CalibratedDemosaic::new(std::sync::Arc::clone(cal), modelled)
        });
        if let Some(c) = &calibrated {
            polar = c.config(&polar).map_err(|e| ObserveError::Manifest {
                path: session.dir.join(ellipso_session::paths::MANIFEST),
                what: format!("sensor calibration {}: {e}", c.calibration().id()),
            })?;
        }
        Ok(Self {
            session,
            layout,
            polar,
            sample_point: config.sample_point,
            sample_kernel: config.sample_kernel,
            cache: None,
            calibrated,
        })
    }

    /// [`MosaicFrames::new`] keeping each frame's sampled part between reads, up to
    /// `config.frame_cache_bytes` (0: no cache).
    pub fn caching(session: &'a Session, config: &ObserveConfig) -> Result<Self, ObserveError> {
        let mut frames = Self::new(session, config)?;
        if config.frame_cache_bytes > 0 {
            frames.cache = Some(Cache {
                budget_bytes: usize::try_from(config.frame_cache_bytes).unwrap_or(usize::MAX),
                state: Mutex::new(CacheState::default()),
            });
        }
        Ok(frames)
    }

    /// The whole frame, decoded, and the bytes held while decoding it.
    fn decode(&self, entry: &FrameEntry) -> Result<(DnImage, usize), String> {
        let (w, h, px) = self.session.load_frame(entry).map_err(|e| e.to_string())?;
        let bit_depth = self.session.manifest.sensor.bit_depth;
        let raw = RawFrame::new(w, h, bit_depth, self.layout, px)
            .map_err(|e| format!("{}: {e}", entry.path.display()))?;
        let levels = self.polar.levels(&raw).map_err(|e| e.to_string())?;
        let analysers = match &self.calibrated {
            Some(c) => c.demosaic(&raw, &levels).map_err(|e| e.to_string())?,
            None => demosaic(&raw, &levels, DemosaicMethod::Superpixel),
        };
        let image = DnImage::new(
            &raw,
            &analysers,
            &levels,
            self.sample_point,
            self.sample_kernel,
        );
        // Held together at this point: the raw frame, the demosaic (4 f32 planes and a mask
        // byte per band and superpixel) and its DN copy.
        let superpixels = analysers.bands.first().map_or(0, |b| b.mask.data().len());
        let bytes = raw.data_dn().len() * 2
            + analysers.bands.len() * superpixels * (4 * 4 + 1)
            + image.bytes();
        Ok((image, bytes))
    }
}

/// The rectangle a cached crop keeps for `region` (see the module contract).
fn kept_region(region: &PixelRect) -> PixelRect {
    let side = (region.max[0] - region.min[0]).max(region.max[1] - region.min[1]);
    region.grown(CACHE_MARGIN_PX + CACHE_MARGIN_FRACTION * side.max(0.0))
}

impl FrameImages for MosaicFrames<'_> {
    fn load(
        &self,
        entry: &FrameEntry,
        region: Option<&PixelRect>,
    ) -> Result<(Box<dyn AnalyserPixels + '_>, usize), String> {
        let Some(cache) = &self.cache else {
            let (image, bytes) = self.decode(entry)?;
            return Ok((Box::new(image), bytes));
        };
        let id = entry.frame_id;
        let hit = {
            let state = cache.state.lock().unwrap_or_else(|p| p.into_inner());
            state.frames.get(&id).cloned()
        };
        if let Some(image) = hit.filter(|i| region.is_none_or(|r| i.covers(r))) {
            return Ok((Box::new(image), 0));
        }
        let (image, bytes) = self.decode(entry)?;
        // Nothing sampled: keep the smallest crop (a later read with a region decodes again).
        let keep = region.map_or(
            PixelRect {
                min: [0.0; 2],
                max: [0.0; 2],
            },
            kept_region,
        );
        let crop = Arc::new(image.crop(&keep));
        let mut state = cache.state.lock().unwrap_or_else(|p| p.into_inner());
        let old = state.frames.get(&id).map_or(0, |i| i.bytes());
        let total = state.bytes - old + crop.bytes();
        if total <= cache.budget_bytes {
            state.frames.insert(id, Arc::clone(&crop));
            state.bytes = total;
        }
        drop(state);
        Ok((Box::new(crop), bytes))
    }

    fn held_bytes(&self) -> usize {
        self.cache.as_ref().map_or(0, |c| {
            c.state.lock().unwrap_or_else(|p| p.into_inner()).bytes
        })
    }
}
