//! A printed sheet as an albedo texture: what a scanner or a rasterised print file looks like,
//! laid over a [`super::Board`] so the simulator renders the sheet exactly as it was printed
//! (labels, scale bar and all) instead of the board's procedural tag cells.
//!
//! Contract: the texture covers the whole sheet, pixel `(0, 0)` at the sheet's top-left corner
//! (sheet frame, see [`super::board`]), pixel centres at `(i + ½) · pitch`; gray 0 is the board's
//! black albedo and 255 its white albedo, linear in between; lookups are bilinear and clamp at
//! the sheet's edges. [`SheetTexture::new`] refuses a texture whose aspect ratio differs from
//! the sheet's by more than one pixel (a print of another sheet, or a page with margins added).

use std::sync::Arc;

/// Why a texture cannot cover a sheet.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum TextureError {
    /// Empty image or wrong buffer length.
    #[error("texture of {width_px} × {height_px} px with {len} values is not an image")]
    Size {
        /// Width in pixels.
        width_px: usize,
        /// Height in pixels.
        height_px: usize,
        /// Values given.
        len: usize,
    },
    /// The image's aspect ratio is not the sheet's.
    #[error(
        "texture of {width_px} × {height_px} px does not match the {sheet_w_m} × {sheet_h_m} m \
         sheet (expected about {expected_h_px:.0} px high for that width)"
    )]
    Aspect {
        /// Width in pixels.
        width_px: usize,
        /// Height in pixels.
        height_px: usize,
        /// Sheet width, metres.
        sheet_w_m: f64,
        /// Sheet height, metres.
        sheet_h_m: f64,
        /// Height the sheet's aspect implies.
        expected_h_px: f64,
    },
}

/// An 8-bit gray image of a whole sheet.
#[derive(Clone, Debug, PartialEq)]
pub struct SheetTexture {
    width_px: usize,
    height_px: usize,
    gray: Arc<[u8]>,
}

impl SheetTexture {
    /// A texture for a `sheet_size_m` sheet from a row-major gray image without padding.
    pub fn new(
        width_px: usize,
        height_px: usize,
        gray: Vec<u8>,
        sheet_size_m: [f64; 2],
    ) -> Result<Self, TextureError> {
        if width_px == 0 || height_px == 0 || gray.len() != width_px * height_px {
            return Err(TextureError::Size {
                width_px,
                height_px,
                len: gray.len(),
            });
        }
        // One pixel of slack: a print rounds the page to whole pixels on each axis.
        let expected_h_px = width_px as f64 * sheet_size_m[1] / sheet_size_m[0];
        if (expected_h_px - height_px as f64).abs() > 1.0 {
            return Err(TextureError::Aspect {
                width_px,
                height_px,
                sheet_w_m: sheet_size_m[0],
                sheet_h_m: sheet_size_m[1],
                expected_h_px,
            });
        }
        Ok(Self {
            width_px,
            height_px,
            gray: gray.into(),
        })
    }

    /// `[width, height]` in pixels.
    pub fn size_px(&self) -> [usize; 2] {
        [self.width_px, self.height_px]
    }

    /// Bilinear gray level in `[0, 1]` at a sheet point given as a fraction of the sheet
    /// (`u`, `v` in `[0, 1]`, clamped).
    pub fn gray_at(&self, u: f64, v: f64) -> f64 {
        let x = (u * self.width_px as f64 - 0.5).clamp(0.0, (self.width_px - 1) as f64);
        let y = (v * self.height_px as f64 - 0.5).clamp(0.0, (self.height_px - 1) as f64);
        let (x0, y0) = (x.floor() as usize, y.floor() as usize);
        let (x1, y1) = (
            (x0 + 1).min(self.width_px - 1),
            (y0 + 1).min(self.height_px - 1),
        );
        let (fx, fy) = (x - x0 as f64, y - y0 as f64);
        let g = |x: usize, y: usize| f64::from(self.gray[y * self.width_px + x]) / 255.0;
        let top = g(x0, y0) * (1.0 - fx) + g(x1, y0) * fx;
        let bottom = g(x0, y1) * (1.0 - fx) + g(x1, y1) * fx;
        top * (1.0 - fy) + bottom * fy
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn aspect_is_checked_and_lookup_is_bilinear() {
        assert!(matches!(
            SheetTexture::new(4, 4, vec![0; 16], [0.2, 0.1]),
            Err(TextureError::Aspect { .. })
        ));
        assert!(matches!(
            SheetTexture::new(4, 2, vec![0; 7], [0.2, 0.1]),
            Err(TextureError::Size { .. })
        ));
        let t = SheetTexture::new(2, 1, vec![0, 255], [0.2, 0.1]).expect("valid");
        assert_eq!(t.gray_at(0.25, 0.5), 0.0);
        assert_eq!(t.gray_at(0.75, 0.5), 1.0);
        assert!((t.gray_at(0.5, 0.5) - 0.5).abs() < 1e-12);
        assert_eq!(t.gray_at(-1.0, 2.0), 0.0);
    }
}
