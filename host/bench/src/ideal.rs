//! The frames of a session as an ideal polarisation sensor would have measured them: every
//! analyser of every colour band at the exact image point the fit samples, through the same
//! optics, radiometry and sensor stages as the recorded mosaic
//! ([`ellipso_sim::render::PointFrame`]) — the truth that replaces "mosaic + demosaic" (and,
//! with [`Footprint::Point`], the pixel's footprint) in the error budget.
//!
//! Contract: [`IdealFrames`] is an [`ellipso_fit::observe::FrameImages`] for a session rendered
//! from `scene` ([`crate::capture::render_session`] or a simulated capture): frame ids map to
//! capture poses by [`crate::capture::pose_index`], and each frame is lit by its recorded flash
//! energy. A sample's noise is seeded by the frame and the sampled point, so an extraction is a
//! pure function of its inputs. The "largest raw DN" of a sample is its own DN (an ideal pixel
//! is read where it is sampled; no neighbour leaks into it).

use std::collections::BTreeMap;

use ellipso_fit::observe::FrameImages;
use ellipso_fit::observe::image::{AnalyserPixels, PixelRect};
use ellipso_session::reader::{FrameEntry, Session};
use ellipso_sim::render::{Footprint, PointFrame, Renderer};

/// A session's frames seen by an ideal sensor (module doc).
pub struct IdealFrames<'r, 's> {
    renderer: &'r Renderer<'s>,
    pose_index: BTreeMap<u64, usize>,
    footprint: Footprint,
}

impl<'r, 's> IdealFrames<'r, 's> {
    /// The frames of `session`, rendered by `renderer` (built from the session's scene with
    /// the session's resolution and supersampling), with `footprint`.
    pub fn new(renderer: &'r Renderer<'s>, session: &Session, footprint: Footprint) -> Self {
        Self {
            renderer,
            pose_index: crate::capture::pose_index(session),
            footprint,
        }
    }
}

struct IdealImage<'r, 's> {
    frame: PointFrame<'r, 's>,
    footprint: Footprint,
    bands: usize,
}

impl AnalyserPixels for IdealImage<'_, '_> {
    fn band_count(&self) -> usize {
        self.bands
    }

    fn footprint_radius_px(&self) -> f64 {
        match self.footprint {
            Footprint::Pixel => 0.5,
            Footprint::Point => 0.0,
        }
    }

    fn sample(&self, pixel: [f64; 2]) -> ([[f32; 4]; 3], [[f32; 4]; 3]) {
        let seed = pixel[0].to_bits() ^ pixel[1].to_bits().rotate_left(32);
        let p = self.frame.sample(pixel, self.footprint, seed);
        (p.dn, p.dn)
    }
}

impl FrameImages for IdealFrames<'_, '_> {
    fn load(
        &self,
        entry: &FrameEntry,
        _region: Option<&PixelRect>,
    ) -> Result<(Box<dyn AnalyserPixels + '_>, usize), String> {
        let k = *self
            .pose_index
            .get(&entry.frame_id)
            .ok_or_else(|| format!("frame {} has no pose on the capture path", entry.frame_id))?;
        let frame = self
            .renderer
            .point_frame(k, entry.flash_energy_rel)
            .map_err(|e| e.to_string())?;
        let bands = frame.sample([0.0, 0.0], Footprint::Point, 0).bands;
        Ok((
            Box::new(IdealImage {
                frame,
                footprint: self.footprint,
                bands,
            }),
            0,
        ))
    }
}
