//! `Plane<T>`: a row-major 2-D image of one quantity (rows grow downward).
//!
//! Contract: `data.len() == width * height` always holds (the fields are private and every
//! constructor keeps it), so row accessors never panic for `y < height`.

/// A row-major image plane.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Plane<T> {
    width: usize,
    height: usize,
    data: Vec<T>,
}

impl<T: Copy + Default> Plane<T> {
    /// A `width × height` plane filled with `T::default()`.
    pub fn new(width: usize, height: usize) -> Plane<T> {
        Plane {
            width,
            height,
            data: vec![T::default(); width * height],
        }
    }

    /// Makes this a `width × height` plane, reusing the allocation when it is large enough.
    /// Contents are unspecified afterwards (callers overwrite every element).
    pub fn reshape(&mut self, width: usize, height: usize) {
        self.width = width;
        self.height = height;
        self.data.resize(width * height, T::default());
    }
}

impl<T> Plane<T> {
    /// Wraps `data`, or returns `None` when its length is not `width * height`.
    pub fn from_vec(width: usize, height: usize, data: Vec<T>) -> Option<Plane<T>> {
        (width.checked_mul(height) == Some(data.len())).then_some(Plane {
            width,
            height,
            data,
        })
    }

    /// Width in pixels.
    pub fn width(&self) -> usize {
        self.width
    }

    /// Height in pixels.
    pub fn height(&self) -> usize {
        self.height
    }

    /// All pixels, row-major.
    pub fn data(&self) -> &[T] {
        &self.data
    }

    /// All pixels, row-major, mutable.
    pub fn data_mut(&mut self) -> &mut [T] {
        &mut self.data
    }

    /// The pixel at `(x, y)`, or `None` outside the plane.
    pub fn get(&self, x: usize, y: usize) -> Option<&T> {
        if x < self.width && y < self.height {
            self.data.get(y * self.width + x)
        } else {
            None
        }
    }

    /// Row `y` (`None` when `y >= height`).
    pub fn row(&self, y: usize) -> Option<&[T]> {
        self.data.chunks_exact(self.width.max(1)).nth(y)
    }

    /// Rows top to bottom.
    pub fn rows(&self) -> std::slice::ChunksExact<'_, T> {
        self.data.chunks_exact(self.width.max(1))
    }

    /// Mutable rows top to bottom.
    pub fn rows_mut(&mut self) -> std::slice::ChunksExactMut<'_, T> {
        self.data.chunks_exact_mut(self.width.max(1))
    }

    /// Consumes the plane, returning its row-major data.
    pub fn into_vec(self) -> Vec<T> {
        self.data
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rows_and_pixels_agree() {
        let p = Plane::from_vec(3, 2, vec![0, 1, 2, 10, 11, 12]).expect("3×2");
        assert_eq!(p.get(2, 1), Some(&12));
        assert_eq!(p.get(3, 0), None);
        assert_eq!(p.row(1), Some(&[10, 11, 12][..]));
        assert_eq!(p.row(2), None);
        assert_eq!(p.rows().count(), 2);
        assert!(Plane::from_vec(3, 2, vec![0; 5]).is_none());
    }

    #[test]
    fn reshape_reuses_and_resizes() {
        let mut p: Plane<f32> = Plane::new(4, 4);
        p.reshape(2, 3);
        assert_eq!((p.width(), p.height(), p.data().len()), (2, 3, 6));
    }
}
