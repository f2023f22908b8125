//! Where an extraction gets each posed frame's analyser pixels: the [`FrameImages`] source and
//! the session's recorded mosaics ([`MosaicFrames`]).
//!
//! Contract: [`MosaicFrames::load`] reads PNG → raw mosaic → superpixel demosaic → [`DnImage`]
//! (sampled at the analysers' lattice positions or the tile centres, [`super::SamplePoint`]),
//! each time it is asked: nothing is kept between reads, so an extraction holds at most its
//! frames in flight. (Keeping the decoded raw frames between a fit's outer iterations was
//! measured on the demo session: the PNG decode is about 17 % of a one-iteration fit's CPU time,
//! but caching it cut the later extractions' load time by only 20 % on a loaded 2-core machine
//! while holding 370 MB; not kept.)

use ellipso_model::mosaic::SensorLayout;
use ellipso_polar::PolarConfig;
use ellipso_polar::demosaic::{DemosaicMethod, demosaic};
use ellipso_polar::frame::RawFrame;
use ellipso_session::reader::{FrameEntry, Session};

use super::sampler::{AnalyserPixels, DnImage, SampleKernel};
use super::{ObserveConfig, ObserveError, SamplePoint};

/// Where an extraction gets each posed frame's analyser pixels.
pub trait FrameImages: Sync {
    /// The analyser pixels of `entry` (a complete, lit frame of the session) and the bytes
    /// held while they are in use; an unreadable frame is an `Err` with the reason, and the
    /// extraction skips it.
    fn load(&self, entry: &FrameEntry) -> Result<(Box<dyn AnalyserPixels + '_>, usize), String>;
}

/// The session's recorded frames (see the module contract).
pub struct MosaicFrames<'a> {
    session: &'a Session,
    layout: SensorLayout,
    polar: PolarConfig,
    sample_point: SamplePoint,
    sample_kernel: SampleKernel,
}

impl<'a> MosaicFrames<'a> {
    /// The recorded frames of `session` read with `config`'s dark level and sample point.
    pub fn new(session: &'a Session, config: &ObserveConfig) -> Result<Self, ObserveError> {
        let layout = session.manifest.sensor.layout;
        Ok(Self {
            session,
            layout,
            polar: PolarConfig {
                demosaic: DemosaicMethod::Superpixel,
                dark_level_dn: config.dark_level_dn,
                ..PolarConfig::default()
            },
            sample_point: config.sample_point,
            sample_kernel: config.sample_kernel,
        })
    }
}

impl FrameImages for MosaicFrames<'_> {
    fn load(&self, entry: &FrameEntry) -> Result<(Box<dyn AnalyserPixels + '_>, usize), String> {
        let (w, h, px) = self.session.load_frame(entry).map_err(|e| e.to_string())?;
        let bit_depth = self.session.manifest.sensor.bit_depth;
        let raw = RawFrame::new(w, h, bit_depth, self.layout, px)
            .map_err(|e| format!("{}: {e}", entry.path.display()))?;
        let levels = self.polar.levels(&raw).map_err(|e| e.to_string())?;
        let analysers = demosaic(&raw, &levels, DemosaicMethod::Superpixel);
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
        Ok((Box::new(image), bytes))
    }
}
