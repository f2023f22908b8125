//! The binary form of a COLMAP model (`cameras.bin`, `images.bin`, `points3D.bin`; the module
//! contract of `model` gives the layout): each reader returns its records sorted by id, or an
//! error naming the file and byte offset.

use super::*;

/// A bounds-checked little-endian reader that names the byte offset of what it cannot read.
struct Reader<'a> {
    path: &'a Path,
    bytes: Vec<u8>,
    at: usize,
}

impl<'a> Reader<'a> {
    fn open(path: &'a Path) -> Result<Self, ModelError> {
        let bytes = std::fs::read(path).map_err(|error| ModelError::Io {
            path: path.to_path_buf(),
            error,
        })?;
        Ok(Self { path, bytes, at: 0 })
    }

    fn fail(&self, what: impl Into<String>) -> ModelError {
        ModelError::Malformed {
            path: self.path.to_path_buf(),
            at: format!("byte {}", self.at),
            what: what.into(),
        }
    }

    fn take<const N: usize>(&mut self, what: &str) -> Result<[u8; N], ModelError> {
        let Some(slice) = self.bytes.get(self.at..self.at + N) else {
            return Err(self.fail(format!(
                "the file ends inside {what} ({} bytes long)",
                self.bytes.len()
            )));
        };
        let out = slice.try_into().expect("N bytes");
        self.at += N;
        Ok(out)
    }

    fn u8(&mut self, what: &str) -> Result<u8, ModelError> {
        Ok(self.take::<1>(what)?[0])
    }
    fn u32(&mut self, what: &str) -> Result<u32, ModelError> {
        self.take(what).map(u32::from_le_bytes)
    }
    fn i32(&mut self, what: &str) -> Result<i32, ModelError> {
        self.take(what).map(i32::from_le_bytes)
    }
    fn u64(&mut self, what: &str) -> Result<u64, ModelError> {
        self.take(what).map(u64::from_le_bytes)
    }
    fn f64(&mut self, what: &str) -> Result<f64, ModelError> {
        self.take(what).map(f64::from_le_bytes)
    }

    /// A count of records of at least `min_bytes` each, checked against what is left (a
    /// corrupt count must not allocate).
    fn count(&mut self, what: &str, min_bytes: usize) -> Result<usize, ModelError> {
        let n = self.u64(what)?;
        let left = (self.bytes.len() - self.at) as u64;
        if n > left / min_bytes.max(1) as u64 {
            return Err(self.fail(format!("{n} {what} cannot fit in the {left} bytes left")));
        }
        Ok(n as usize)
    }

    fn name(&mut self) -> Result<String, ModelError> {
        let rest = &self.bytes[self.at..];
        let Some(end) = rest.iter().position(|&b| b == 0) else {
            return Err(self.fail("the file ends inside an image name"));
        };
        let name = String::from_utf8(rest[..end].to_vec())
            .map_err(|_| self.fail("an image name is not UTF-8"))?;
        self.at += end + 1;
        Ok(name)
    }

    fn finish<T>(self, value: T) -> Result<T, ModelError> {
        if self.at != self.bytes.len() {
            return Err(self.fail(format!(
                "{} bytes after the last record",
                self.bytes.len() - self.at
            )));
        }
        Ok(value)
    }
}

pub(super) fn cameras(path: &Path) -> Result<Vec<ModelCamera>, ModelError> {
    let mut r = Reader::open(path)?;
    let n = r.count("cameras", 24)?;
    let mut out = Vec::with_capacity(n);
    for _ in 0..n {
        let camera_id = r.u32("a camera id")?;
        let model_at = r.at;
        let model_id = r.i32("a camera model")?;
        let Some(&(model, count)) = usize::try_from(model_id)
            .ok()
            .and_then(|k| CAMERA_MODELS.get(k))
        else {
            r.at = model_at;
            return Err(r.fail(format!(
                "camera {camera_id}: unknown camera model id {model_id}"
            )));
        };
        let width = r.u64("a width")?;
        let height = r.u64("a height")?;
        let params = (0..count)
            .map(|_| r.f64("camera parameters"))
            .collect::<Result<Vec<f64>, _>>()?;
        out.push(ModelCamera {
            camera_id,
            model: model.to_string(),
            width,
            height,
            params,
        });
    }
    r.finish(out)
}

pub(super) fn images(path: &Path) -> Result<Vec<ModelImage>, ModelError> {
    let mut r = Reader::open(path)?;
    let n = r.count("images", 73)?;
    let mut out = Vec::with_capacity(n);
    for _ in 0..n {
        let start = r.at;
        let image_id = r.u32("an image id")?;
        let mut v = [0.0; 7];
        for x in &mut v {
            *x = r.f64("a pose")?;
        }
        let camera_id = r.u32("a camera id")?;
        let name = r.name()?;
        let points = r.count("2-D points", 24)?;
        let mut triangulated = 0;
        for _ in 0..points {
            r.f64("a 2-D point")?;
            r.f64("a 2-D point")?;
            // COLMAP writes an invalid id as -1 (u64::MAX read as unsigned)
            triangulated += usize::from(r.u64("a 3-D point id")? != u64::MAX);
        }
        let Some(camera_from_model) = pose([v[0], v[1], v[2], v[3]], [v[4], v[5], v[6]]) else {
            r.at = start;
            return Err(r.fail(format!(
                "image {image_id}: the rotation is not a unit quaternion"
            )));
        };
        out.push(ModelImage {
            image_id,
            camera_id,
            name,
            camera_from_model,
            points2d: points,
            points2d_triangulated: triangulated,
        });
    }
    r.finish(out)
}

pub(super) fn points(path: &Path) -> Result<Vec<ModelPoint>, ModelError> {
    let mut r = Reader::open(path)?;
    let n = r.count("points", 51)?;
    let mut out = Vec::with_capacity(n);
    for _ in 0..n {
        let point3d_id = r.u64("a point id")?;
        let position = Point3::new(
            r.f64("a position")?,
            r.f64("a position")?,
            r.f64("a position")?,
        );
        let rgb = [r.u8("a colour")?, r.u8("a colour")?, r.u8("a colour")?];
        let error_px = r.f64("an error")?;
        let track_length = r.count("track elements", 8)?;
        for _ in 0..track_length {
            r.u32("a track element")?;
            r.u32("a track element")?;
        }
        out.push(ModelPoint {
            point3d_id,
            position,
            rgb,
            error_px,
            track_length,
        });
    }
    r.finish(out)
}
