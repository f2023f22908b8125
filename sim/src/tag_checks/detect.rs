//! Test helper: run the real AprilTag detector (the `apriltag` dev-dependency) on an 8-bit image.
//!
//! Returns `(id, corners)` per detection with hamming 0, corners shifted by −0.5 px into the
//! OpenCV convention (pixel centres at integers), in AprilTag's corner order.

/// Detects tag36h11 tags in a row-major `w × h` grey image.
pub(crate) fn detect_tag36h11(gray: &[u8], w: usize, h: usize) -> Vec<(u32, [[f64; 2]; 4])> {
    detect(ellipso_model::tags::TagFamily::Tag36h11, gray, w, h)
}

/// Detects tags of `family` in a row-major `w × h` grey image.
pub(crate) fn detect(
    family: ellipso_model::tags::TagFamily,
    gray: &[u8],
    w: usize,
    h: usize,
) -> Vec<(u32, [[f64; 2]; 4])> {
    let fam = match family {
        ellipso_model::tags::TagFamily::Tag36h11 => apriltag::Family::tag_36h11(),
        ellipso_model::tags::TagFamily::Tag25h9 => apriltag::Family::tag_25h9(),
        ellipso_model::tags::TagFamily::Tag16h5 => apriltag::Family::tag_16h5(),
    };
    let mut det = apriltag::DetectorBuilder::new()
        .add_family_bits(fam, 1)
        .build()
        .expect("detector builds");
    det.set_thread_number(1);
    let mut img =
        apriltag::Image::zeros_with_alignment(w, h, apriltag::image_buf::DEFAULT_ALIGNMENT_U8)
            .expect("image allocates");
    let stride = img.stride();
    for y in 0..h {
        img.as_slice_mut()[y * stride..y * stride + w].copy_from_slice(&gray[y * w..(y + 1) * w]);
    }
    det.detect(&img)
        .into_iter()
        .filter(|d| d.hamming() == 0)
        .map(|d| (d.id() as u32, d.corners().map(|[x, y]| [x - 0.5, y - 0.5])))
        .collect()
}
