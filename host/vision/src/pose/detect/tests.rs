//! Detector tests: a tag rendered by the library itself (`apriltag_to_image`), warped into an
//! image through a known homography with 8×8 supersampling, must be detected with its corners
//! within 0.3 px of the truth in the integer-centre convention, in the documented order.

use super::*;
use crate::pose::homography::apply_homography;
use nalgebra::Matrix3;

/// The 10×10 cell image of tag36h11 `id` (1-cell white ring, black border at cells 1..9).
pub(crate) fn tag36h11_cells(id: i32) -> (usize, Vec<u8>) {
    // SAFETY: the family is created and destroyed here; `apriltag_to_image` returns a fresh
    // image (id < ncodes = 587) that we copy out of and destroy before returning.
    unsafe {
        let fam = apriltag_sys::tag36h11_create();
        assert!(!fam.is_null());
        let im = apriltag_sys::apriltag_to_image(fam, id);
        assert!(!im.is_null());
        let (w, h, stride) = (
            (*im).width as usize,
            (*im).height as usize,
            (*im).stride as usize,
        );
        assert_eq!(w, h);
        let mut cells = Vec::with_capacity(w * h);
        for y in 0..h {
            cells.extend_from_slice(std::slice::from_raw_parts((*im).buf.add(y * stride), w));
        }
        apriltag_sys::image_u8_destroy(im);
        apriltag_sys::tag36h11_destroy(fam);
        (w, cells)
    }
}

/// Renders the tag into a `size`×`size` image; `image_from_tag` maps continuous tag-cell
/// coordinates (cell m covers [m, m+1)) to pixels in the integer-centre convention.
fn render(image_from_tag: &Matrix3<f64>, cells: &(usize, Vec<u8>), size: usize) -> Vec<u8> {
    let (n, cells) = cells;
    let tag_from_image = image_from_tag.try_inverse().unwrap();
    let (dark, light, background) = (25.0, 235.0, 200.0);
    let ss = 8;
    let mut img = vec![0u8; size * size];
    for j in 0..size {
        for i in 0..size {
            let mut acc = 0.0;
            for sy in 0..ss {
                for sx in 0..ss {
                    let u = i as f64 - 0.5 + (sx as f64 + 0.5) / ss as f64;
                    let v = j as f64 - 0.5 + (sy as f64 + 0.5) / ss as f64;
                    let [x, y] = apply_homography(&tag_from_image, [u, v]).unwrap();
                    let inside = x >= 0.0 && y >= 0.0 && x < *n as f64 && y < *n as f64;
                    acc += if inside {
                        if cells[y as usize * n + x as usize] > 127 {
                            light
                        } else {
                            dark
                        }
                    } else {
                        background
                    };
                }
            }
            img[j * size + i] = (acc / (ss * ss) as f64).round() as u8;
        }
    }
    img
}

fn check_detection(image_from_tag: Matrix3<f64>, id: i32, decimation: f32) {
    let size = 480;
    let cells = tag36h11_cells(id);
    let img = render(&image_from_tag, &cells, size);
    let mut det = TagDetector::new(DetectorConfig {
        decimation,
        threads: 1,
        ..Default::default()
    })
    .unwrap();
    let found = det.detect(&img, size, size).unwrap();
    assert_eq!(found.len(), 1, "expected exactly one tag, got {found:?}");
    let d = found[0];
    assert_eq!(
        (d.id, d.hamming, d.family),
        (id as u32, 0, TagFamily::Tag36h11)
    );
    // Outer black square in cell coordinates, in the documented order: bottom-left,
    // bottom-right, top-right, top-left (cell y grows downward).
    let truth_cells = [[1.0, 9.0], [9.0, 9.0], [9.0, 1.0], [1.0, 1.0]];
    for (k, (got, cell)) in d.corners_px.iter().zip(truth_cells).enumerate() {
        let truth = apply_homography(&image_from_tag, cell).unwrap();
        let err = (got[0] - truth[0]).hypot(got[1] - truth[1]);
        assert!(
            err <= 0.3,
            "corner {k}: detected {got:?}, true {truth:?}, error {err:.3} px"
        );
    }
}

#[test]
fn upright_tag_corners_within_0_3_px() {
    // 36 px per cell, origin offset by a fraction of a pixel.
    let h = Matrix3::new(36.0, 0.0, 60.3, 0.0, 36.0, 75.7, 0.0, 0.0, 1.0);
    check_detection(h, 42, 1.0);
}

#[test]
fn perspective_rotated_tag_corners_within_0_3_px() {
    let (c, s) = (0.35f64.cos(), 0.35f64.sin());
    let h = Matrix3::new(
        34.0 * c,
        -30.0 * s,
        150.2,
        34.0 * s,
        30.0 * c,
        90.6,
        2.0e-3,
        -1.5e-3,
        1.0,
    );
    check_detection(h, 7, 2.0);
}

#[test]
fn rejects_bad_settings_and_buffers() {
    for bad in [
        DetectorConfig {
            decimation: 0.5,
            ..Default::default()
        },
        DetectorConfig {
            threads: 0,
            ..Default::default()
        },
        DetectorConfig {
            blur_sigma: f32::NAN,
            ..Default::default()
        },
        DetectorConfig {
            max_hamming: 4,
            ..Default::default()
        },
    ] {
        assert!(matches!(
            TagDetector::new(bad),
            Err(DetectError::InvalidSetting { .. })
        ));
    }
    let mut det = TagDetector::new(DetectorConfig::default()).unwrap();
    assert!(matches!(
        det.detect(&[0u8; 10], 4, 4),
        Err(DetectError::BufferSize { .. })
    ));
    assert!(matches!(
        det.detect(&[], 0, 4),
        Err(DetectError::ImageSize { .. })
    ));
    // An empty scene has no tags.
    assert!(
        det.detect(&vec![128u8; 64 * 64], 64, 64)
            .unwrap()
            .is_empty()
    );
}

/// Issue 46 item 1: the library's quad search read unallocated memory (a segfault) on images
/// under 3 px tall after decimation. Every size is now either searched or refused by name.
#[test]
fn tiny_images_are_refused_not_crashed_on() {
    for decimation in [1.0_f32, 1.5, 2.0, 3.0] {
        let mut d = TagDetector::new(DetectorConfig {
            decimation,
            ..Default::default()
        })
        .unwrap();
        for (w, h) in [
            (1, 1),
            (2, 2),
            (4, 4),
            (8, 4),
            (32, 2),
            (2, 32),
            (8192, 1),
            (1, 8192),
            (8, 8),
            (9, 9),
            (16, 5),
            (64, 16),
        ] {
            let gray: Vec<u8> = (0..w * h).map(|i| (i * 37 % 251) as u8).collect();
            match d.detect(&gray, w, h) {
                Ok(tags) => assert!(tags.is_empty()),
                Err(e) => {
                    assert_eq!(
                        e,
                        DetectError::TooSmall {
                            width: w,
                            height: h
                        }
                    );
                    assert!(w.min(h) < MIN_TAG_SIDE_PX || decimation >= 2.0, "{w}×{h}");
                    assert!(e.to_string().contains(&format!("{w}×{h} px")));
                }
            }
        }
    }
}
