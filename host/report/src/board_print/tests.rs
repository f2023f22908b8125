use ellipso_model::tags::{Board, BoardSpec, TagPlacementSpec};

use super::raster::rasterise;
use super::*;

fn board(centres_mm: &[[f64; 2]], sheet_mm: [f64; 2]) -> Board {
    let spec = BoardSpec {
        name: Some("test".into()),
        family: Default::default(),
        tag_size_m: 0.03,
        sheet_size_m: Some([sheet_mm[0] * 1e-3, sheet_mm[1] * 1e-3]),
        margin_m: 0.01,
        white_albedo: 0.85,
        black_albedo: 0.04,
        origin: Default::default(),
        axes: Default::default(),
        grid: None,
        tags: centres_mm
            .iter()
            .enumerate()
            .map(|(k, c)| TagPlacementSpec {
                id: k as u32,
                centre_m: [c[0] * 1e-3, c[1] * 1e-3],
                rotation_deg: if k == 1 { 30.0 } else { 0.0 },
            })
            .collect(),
    };
    Board::from_spec(&spec).expect("valid board")
}

#[test]
fn raster_matches_the_boards_own_cells_at_cell_centres() {
    let b = board(&[[40.0, 40.0], [100.0, 40.0]], [210.0, 148.0]);
    let d = layout(&b, 5.0).expect("fits");
    let dpi = 300.0;
    let img = rasterise(&d, dpi).expect("raster");
    assert_eq!((img.width, img.height), (2480, 1748));
    // sample every 0.5 mm across both tags; away from cell edges print and board agree
    let table = b.family.code_table();
    let cell_m = b.tag_size_m / f64::from(table.width_at_border);
    let mut checked = 0;
    for iy in 0..200 {
        for ix in 0..300 {
            let (x_m, y_m) = (0.01 + ix as f64 * 4e-4, 0.01 + iy as f64 * 4e-4);
            // distance to the nearest cell edge of tag 0 (unrotated): skip points near edges
            let near_edge = |v: f64, c: f64| {
                let f = ((v - c) / cell_m + 0.5 * f64::from(table.total_width)).fract();
                !(0.15..0.85).contains(&f)
            };
            if x_m > 0.07 || near_edge(x_m, 0.04) || near_edge(y_m, 0.04) {
                continue;
            }
            let albedo = b.albedo_at(&nalgebra::Point2::new(x_m, y_m));
            let px = (x_m * 1e3 * dpi / 25.4) as usize;
            let py = (y_m * 1e3 * dpi / 25.4) as usize;
            let printed_black = img.gray[py * img.width + px] < 128;
            assert_eq!(printed_black, albedo < 0.5, "at ({x_m}, {y_m}) m");
            checked += 1;
        }
    }
    assert!(checked > 1000, "{checked}");
}

#[test]
fn a_tag_in_the_printer_margin_or_a_full_sheet_is_refused() {
    // tag 0's white ring (10 cells of 3.75 mm = 37.5 mm) reaches 1.25 mm from the left edge
    let b = board(&[[20.0, 60.0]], [210.0, 148.0]);
    let err = layout(&b, 5.0).expect_err("in margin");
    assert!(
        matches!(err, PrintError::TagInMargin { id: 0, .. }),
        "{err}"
    );
    assert!(layout(&b, 1.0).is_ok());
    // a sheet filled with tags leaves no room for the scale bar
    let full: Vec<[f64; 2]> = (0..4)
        .flat_map(|r| (0..3).map(move |c| [35.0 + 45.0 * c as f64, 35.0 + 45.0 * r as f64]))
        .collect();
    let err = layout(&board(&full, [160.0, 205.0]), 5.0).expect_err("no room");
    assert!(matches!(err, PrintError::NoRoomForLabel { .. }), "{err}");
    assert!(err.to_string().contains("does not fit its paper"), "{err}");
}

#[test]
fn pdf_and_svg_are_at_physical_scale() {
    let b = board(&[[40.0, 40.0]], [210.0, 297.0]);
    let d = layout(&b, 5.0).expect("fits");
    let pdf = pdf::to_pdf(&d);
    assert!(pdf.starts_with(b"%PDF-"));
    let text = String::from_utf8_lossy(&pdf);
    // A4 in points: 595.28 × 841.89
    assert!(
        text.contains("/MediaBox [0 0 595.27"),
        "{}",
        &text[..400.min(text.len())]
    );
    assert!(text.contains("ellipso board test"));
    let svg = svg::to_svg(&d);
    assert!(svg.contains(r#"width="210mm" height="297mm" viewBox="0 0 210 297""#));
    assert!(svg.contains(">100 mm</text>"));
    assert_eq!(Format::of_path("a/B.PDF".as_ref()), Some(Format::Pdf));
    assert_eq!(Format::of_path("b.jpg".as_ref()), None);
}
