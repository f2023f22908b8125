//! OpenEXR float images: results that must stay numbers (Stokes planes, parameter maps, float
//! renders) written beside the viewing PNGs, in the format renderers and compositors read.
//!
//! Contract: a [`FloatImage`] is `width × height` pixels, row-major from the top-left, with any
//! number of named channels of `f32` (or `u32`, for bit masks) samples; names are unique,
//! non-empty ASCII without control characters. [`FloatImage::write`] encodes one single-part
//! scan-line file, ZIP-compressed (lossless), channels sorted by name as OpenEXR requires, and
//! writes it whole or not at all ([`crate::atomic_file`]); [`FloatImage::read`] reads any
//! single-part scan-line or tiled file back (its first layer, full resolution). Channel names
//! follow the OpenEXR layer convention `LAYER.CHANNEL` (`S0.R`), the names Mitsuba 3 gives
//! its Stokes and AOV channels, so a reader groups them. Pure Rust (the `exr` crate).

use std::path::Path;

use exr::prelude::{
    AnyChannel, AnyChannels, Encoding, FlatSamples, Image, Layer, LayerAttributes, ReadChannels,
    ReadLayers, SmallVec, Text, WritableImage,
};

/// The samples of one channel.
#[derive(Clone, Debug, PartialEq)]
pub enum Samples {
    /// 32-bit floats (every value, NaN and ±inf included, is kept).
    F32(Vec<f32>),
    /// 32-bit unsigned integers (bit masks).
    U32(Vec<u32>),
}

impl Samples {
    fn len(&self) -> usize {
        match self {
            Self::F32(v) => v.len(),
            Self::U32(v) => v.len(),
        }
    }

    /// The samples as `f32`, when they are floats.
    pub fn as_f32(&self) -> Option<&[f32]> {
        match self {
            Self::F32(v) => Some(v),
            Self::U32(_) => None,
        }
    }
}

/// One named channel.
#[derive(Clone, Debug, PartialEq)]
pub struct Channel {
    /// Its name, e.g. `S0.R`.
    pub name: String,
    /// `width × height` samples, row-major.
    pub samples: Samples,
}

/// A multi-channel float image (see the module doc).
#[derive(Clone, Debug, PartialEq)]
pub struct FloatImage {
    /// Columns.
    pub width: usize,
    /// Rows.
    pub height: usize,
    /// The channels, in the order they were added (a file read back lists them by name).
    pub channels: Vec<Channel>,
}

/// Errors of building, writing or reading an EXR image.
#[derive(Debug, thiserror::Error)]
pub enum ExrError {
    /// The image has no pixels.
    #[error("an EXR image needs at least one pixel (got {width}×{height})")]
    Empty {
        /// Columns.
        width: usize,
        /// Rows.
        height: usize,
    },
    /// A channel's sample count is not `width × height`.
    #[error("EXR channel `{name}` has {got} samples, the {width}×{height} image needs {expected}")]
    Shape {
        /// Channel name.
        name: String,
        /// Samples given.
        got: usize,
        /// `width × height`.
        expected: usize,
        /// Columns.
        width: usize,
        /// Rows.
        height: usize,
    },
    /// A channel name is empty, not ASCII, or repeated.
    #[error("EXR channel name `{name}`: {reason}")]
    Name {
        /// The name.
        name: String,
        /// What is wrong with it.
        reason: &'static str,
    },
    /// The image has no channel.
    #[error("an EXR image needs at least one channel")]
    NoChannels,
    /// Encoding, decoding or writing failed.
    #[error("{path}: {message}")]
    File {
        /// The file.
        path: String,
        /// Cause.
        message: String,
    },
}

impl FloatImage {
    /// An image without channels; [`Self::push_f32`] and [`Self::push_u32`] add them.
    pub fn new(width: usize, height: usize) -> Result<Self, ExrError> {
        if width == 0 || height == 0 {
            return Err(ExrError::Empty { width, height });
        }
        Ok(Self {
            width,
            height,
            channels: Vec::new(),
        })
    }

    /// Adds a float channel; its length must be `width × height` and its name new.
    pub fn push_f32(&mut self, name: &str, samples: Vec<f32>) -> Result<&mut Self, ExrError> {
        self.push(name, Samples::F32(samples))
    }

    /// Adds an unsigned-integer channel (bit masks); as [`Self::push_f32`].
    pub fn push_u32(&mut self, name: &str, samples: Vec<u32>) -> Result<&mut Self, ExrError> {
        self.push(name, Samples::U32(samples))
    }

    fn push(&mut self, name: &str, samples: Samples) -> Result<&mut Self, ExrError> {
        let bad = |reason| ExrError::Name {
            name: name.to_string(),
            reason,
        };
        if name.is_empty() {
            return Err(bad("empty"));
        }
        if !name.bytes().all(|b| b.is_ascii_graphic()) {
            return Err(bad("only printable ASCII without spaces"));
        }
        if name.len() > 255 {
            return Err(bad("longer than 255 bytes"));
        }
        if self.channel(name).is_some() {
            return Err(bad("already in the image"));
        }
        let expected = self.width * self.height;
        if samples.len() != expected {
            return Err(ExrError::Shape {
                name: name.to_string(),
                got: samples.len(),
                expected,
                width: self.width,
                height: self.height,
            });
        }
        self.channels.push(Channel {
            name: name.to_string(),
            samples,
        });
        Ok(self)
    }

    /// The samples of channel `name`.
    pub fn channel(&self, name: &str) -> Option<&Samples> {
        self.channels
            .iter()
            .find(|c| c.name == name)
            .map(|c| &c.samples)
    }

    /// The float samples of channel `name`.
    pub fn f32_channel(&self, name: &str) -> Option<&[f32]> {
        self.channel(name).and_then(Samples::as_f32)
    }

    /// The bytes of the EXR file (module doc); `path` only names the file in errors.
    pub fn encode(&self, path: &Path) -> Result<Vec<u8>, ExrError> {
        if self.channels.is_empty() {
            return Err(ExrError::NoChannels);
        }
        let list: SmallVec<[AnyChannel<FlatSamples>; 4]> = self
            .channels
            .iter()
            .map(|c| {
                let samples = match &c.samples {
                    Samples::F32(v) => FlatSamples::F32(v.clone()),
                    Samples::U32(v) => FlatSamples::U32(v.clone()),
                };
                AnyChannel::new(Text::new_or_panic(&c.name), samples)
            })
            .collect();
        let layer = Layer::new(
            (self.width, self.height),
            LayerAttributes::default(),
            Encoding::SMALL_LOSSLESS,
            AnyChannels::sort(list),
        );
        let mut bytes = std::io::Cursor::new(Vec::new());
        Image::from_layer(layer)
            .write()
            .to_buffered(&mut bytes)
            .map_err(|e| ExrError::File {
                path: path.display().to_string(),
                message: format!("encoding OpenEXR: {e}"),
            })?;
        Ok(bytes.into_inner())
    }

    /// Writes the image to `path` whole or not at all.
    pub fn write(&self, path: &Path) -> Result<(), ExrError> {
        let bytes = self.encode(path)?;
        crate::atomic_file::write(path, bytes).map_err(|e| ExrError::File {
            path: path.display().to_string(),
            message: e.to_string(),
        })
    }

    /// Reads the first layer of an EXR file at full resolution (f16 channels widen to f32).
    pub fn read(path: &Path) -> Result<Self, ExrError> {
        let fail = |message: String| ExrError::File {
            path: path.display().to_string(),
            message,
        };
        let image = exr::prelude::read()
            .no_deep_data()
            .largest_resolution_level()
            .all_channels()
            .first_valid_layer()
            .all_attributes()
            .from_file(path)
            .map_err(|e| fail(format!("not a readable OpenEXR file: {e}")))?;
        let layer = image.layer_data;
        let (width, height) = (layer.size.0, layer.size.1);
        let mut out = Self::new(width, height).map_err(|e| fail(e.to_string()))?;
        for c in layer.channel_data.list {
            let samples = match c.sample_data {
                FlatSamples::F16(v) => Samples::F32(v.into_iter().map(f32::from).collect()),
                FlatSamples::F32(v) => Samples::F32(v),
                FlatSamples::U32(v) => Samples::U32(v),
            };
            out.push(&c.name.to_string(), samples)
                .map_err(|e| fail(e.to_string()))?;
        }
        Ok(out)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sample_image() -> FloatImage {
        let mut image = FloatImage::new(3, 2).unwrap();
        image
            .push_f32("S0.R", vec![0.0, 1.5, -2.0, f32::INFINITY, 1e-30, 7.0])
            .unwrap()
            .push_f32("DoLP", vec![0.1, 0.2, 0.3, 0.4, 0.5, 0.6])
            .unwrap()
            .push_u32("mask", vec![0, 1, 2, 4, 8, 255])
            .unwrap();
        image
    }

    #[test]
    fn a_written_image_reads_back_bit_for_bit_with_its_names() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("t.exr");
        let image = sample_image();
        image.write(&path).unwrap();
        let bytes = std::fs::read(&path).unwrap();
        assert_eq!(
            &bytes[..4],
            &[0x76, 0x2f, 0x31, 0x01],
            "OpenEXR magic number"
        );
        let back = FloatImage::read(&path).unwrap();
        assert_eq!((back.width, back.height), (3, 2));
        for c in &image.channels {
            assert_eq!(back.channel(&c.name), Some(&c.samples), "{}", c.name);
        }
        // the file lists channels by name, as OpenEXR requires
        let names: Vec<&str> = back.channels.iter().map(|c| c.name.as_str()).collect();
        assert_eq!(names, ["DoLP", "S0.R", "mask"]);
        assert!(back.f32_channel("mask").is_none() && back.f32_channel("DoLP").is_some());
    }

    #[test]
    fn bad_shapes_and_names_are_refused_with_the_channel_named() {
        let mut image = FloatImage::new(2, 2).unwrap();
        let e = image.push_f32("S1", vec![0.0; 3]).unwrap_err().to_string();
        assert!(
            e.contains("`S1`") && e.contains("3 samples") && e.contains("4"),
            "{e}"
        );
        image.push_f32("S1", vec![0.0; 4]).unwrap();
        assert!(matches!(
            image.push_f32("S1", vec![0.0; 4]),
            Err(ExrError::Name { .. })
        ));
        assert!(image.push_f32("", vec![0.0; 4]).is_err());
        assert!(image.push_f32("a b", vec![0.0; 4]).is_err());
        assert!(matches!(FloatImage::new(0, 4), Err(ExrError::Empty { .. })));
        let empty = FloatImage::new(1, 1).unwrap();
        assert!(matches!(
            empty.encode(Path::new("x.exr")),
            Err(ExrError::NoChannels)
        ));
    }

    #[test]
    fn unreadable_files_are_named() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("junk.exr");
        std::fs::write(&path, b"not an exr").unwrap();
        let e = FloatImage::read(&path).unwrap_err().to_string();
        assert!(e.contains("junk.exr") && e.contains("OpenEXR"), "{e}");
    }
}
