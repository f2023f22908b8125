//! Printable AprilTag boards: one drawing of a board's sheet (tag cells, a label with the
//! board's name, family, ids and sizes, and a 100 mm scale bar to check the printer's scale),
//! written as PDF ([`pdf`]), SVG ([`svg`]) or a PNG raster at a chosen dpi ([`raster`]).
//!
//! Contract:
//! - The page is the board's sheet (`sheet_size_m`), at exact physical scale: 1 mm on paper is
//!   1 mm of the board frame. Coordinates of the drawing are sheet millimetres, origin at the
//!   page's top-left corner, x right, y down (the board's sheet frame, `ellipso_model::tags`).
//! - Every format draws the same [`Drawing`]: black convex quads on white, and text lines.
//! - A board must fit its paper: every tag with its white outer ring lies inside the printer's
//!   unprinted border (`margin_mm`), and the label block (label and scale bar) finds a place
//!   that overlaps no tag. Otherwise [`PrintError`] says which tag or what is missing.
//!
//! Text is ASCII only, so the PDF can use the viewer's built-in Helvetica without embedding a
//! font; the raster draws it with the bundled font of [`crate::font`].

pub mod pdf;
pub mod raster;
pub mod svg;

use ellipso_model::tags::{Board, TagCells};

/// Height of the label's text, mm: about 7 pt type, legible on the bench.
pub const TEXT_MM: f64 = 2.5;
/// Length of the scale bar, mm: long enough that a 1 % printer scaling error is 1 mm, which a
/// ruler shows.
pub const SCALE_BAR_MM: f64 = 100.0;
/// Height of the scale bar, mm.
pub const SCALE_BAR_HEIGHT_MM: f64 = 4.0;
/// Unprinted border most office printers leave, mm (default of `--margin-mm`).
pub const DEFAULT_PRINTER_MARGIN_MM: f64 = 5.0;

/// Why a board cannot be printed on its sheet.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum PrintError {
    /// A tag reaches into the printer's unprinted border or off the sheet.
    #[error(
        "tag {id} with its white border reaches {edge_mm:.1} mm from the paper's edge, inside the \
         printer's {margin_mm} mm unprinted margin: the board does not fit its {paper_w_mm:.0} × \
         {paper_h_mm:.0} mm paper (move the tag in, shrink the tags or use larger paper)"
    )]
    TagInMargin {
        /// The tag.
        id: u32,
        /// Its closest approach to the paper's edge, mm (negative: off the paper).
        edge_mm: f64,
        /// The printer margin, mm.
        margin_mm: f64,
        /// Paper width, mm.
        paper_w_mm: f64,
        /// Paper height, mm.
        paper_h_mm: f64,
    },
    /// No free place for the label and the scale bar.
    #[error(
        "no free {w_mm:.0} × {h_mm:.0} mm area for the label and the {SCALE_BAR_MM} mm scale bar \
         on the {paper_w_mm:.0} × {paper_h_mm:.0} mm paper (inside the {margin_mm} mm printer \
         margin, clear of the tags): the board does not fit its paper"
    )]
    NoRoomForLabel {
        /// Width the label block needs, mm.
        w_mm: f64,
        /// Height the label block needs, mm.
        h_mm: f64,
        /// Paper width, mm.
        paper_w_mm: f64,
        /// Paper height, mm.
        paper_h_mm: f64,
        /// The printer margin, mm.
        margin_mm: f64,
    },
    /// A bad printer margin.
    #[error("the printer margin must be a length ≥ 0 mm, got {0}")]
    Margin(f64),
}

/// A filled black convex quadrilateral, corners in order, sheet mm.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Quad(pub [[f64; 2]; 4]);

/// A line of text, left-aligned at `x_mm`, its baseline at `baseline_mm`.
#[derive(Debug, Clone, PartialEq)]
pub struct Text {
    /// Left end, mm.
    pub x_mm: f64,
    /// Baseline, mm from the top.
    pub baseline_mm: f64,
    /// Cap-to-descender size (the font size), mm.
    pub size_mm: f64,
    /// ASCII text.
    pub text: String,
}

/// Everything printed on the page.
#[derive(Debug, Clone, PartialEq)]
pub struct Drawing {
    /// Paper `[width, height]`, mm.
    pub paper_mm: [f64; 2],
    /// Black shapes (tag cells, scale bar).
    pub quads: Vec<Quad>,
    /// Text lines.
    pub texts: Vec<Text>,
}

/// Rough width of ASCII text in a sans-serif face: 0.6 em per character (Helvetica and DejaVu
/// Sans average about 0.55 em; the margin keeps long labels clear of tags).
fn text_width_mm(text: &str, size_mm: f64) -> f64 {
    0.6 * size_mm * text.chars().count() as f64
}

/// The ids of a board written compactly: `0-15` for a run, commas between runs.
fn id_ranges(mut ids: Vec<u32>) -> String {
    ids.sort_unstable();
    let mut out: Vec<String> = Vec::new();
    let mut k = 0;
    while k < ids.len() {
        let mut j = k;
        while j + 1 < ids.len() && ids[j + 1] == ids[j] + 1 {
            j += 1;
        }
        out.push(if j == k {
            ids[k].to_string()
        } else {
            format!("{}-{}", ids[k], ids[j])
        });
        k = j + 1;
    }
    out.join(",")
}

/// The drawing of `board` on its sheet with a printer that leaves `margin_mm` unprinted.
pub fn layout(board: &Board, margin_mm: f64) -> Result<Drawing, PrintError> {
    if !(margin_mm.is_finite() && margin_mm >= 0.0) {
        return Err(PrintError::Margin(margin_mm));
    }
    let paper_mm = [board.sheet_size_m[0] * 1e3, board.sheet_size_m[1] * 1e3];
    let table = board.family.code_table();
    let cell_mm = board.tag_size_m * 1e3 / f64::from(table.width_at_border);
    let total_mm = f64::from(table.total_width) * cell_mm;
    let mut quads = Vec::new();
    // Each tag's bounding box on the sheet (with its white ring), for the label placement.
    let mut boxes: Vec<[f64; 4]> = Vec::new();
    for tag in &board.tags {
        let c = tag.centre_sheet_m() * 1e3;
        let (sin, cos) = tag.rotation_rad().sin_cos();
        // tag-local (x right, y down) to sheet: the rotation `Board::albedo_at` inverts
        let to_sheet = |lx: f64, ly: f64| [c.x + cos * lx - sin * ly, c.y + sin * lx + cos * ly];
        let r = 0.5 * total_mm * (cos.abs() + sin.abs());
        let bbox = [c.x - r, c.y - r, c.x + r, c.y + r];
        let edge_mm = bbox[0]
            .min(bbox[1])
            .min(paper_mm[0] - bbox[2])
            .min(paper_mm[1] - bbox[3]);
        if edge_mm < margin_mm - 1e-9 {
            return Err(PrintError::TagInMargin {
                id: tag.id,
                edge_mm,
                margin_mm,
                paper_w_mm: paper_mm[0],
                paper_h_mm: paper_mm[1],
            });
        }
        boxes.push(bbox);
        let cells = board
            .tag_cells(tag.id)
            .unwrap_or_else(|| unreachable!("a built board holds the cells of its tags"));
        push_tag_quads(cells, cell_mm, total_mm, &to_sheet, &mut quads);
    }
    let ids = id_ranges(board.tags.iter().map(|t| t.id).collect());
    let line1 = format!(
        "ellipso board {} | {} | ids {ids}",
        board
            .name
            .as_deref()
            .unwrap_or("(unnamed)")
            .chars()
            .map(|c| if c.is_ascii_graphic() || c == ' ' {
                c
            } else {
                '?'
            })
            .collect::<String>(),
        board.family.name()
    );
    let line2 = format!(
        "tag {:.2} mm (black border) | sheet {:.0} x {:.0} mm | print at 100 %",
        board.tag_size_m * 1e3,
        paper_mm[0],
        paper_mm[1]
    );
    let bar_label = format!("{SCALE_BAR_MM:.0} mm");
    let gap = 0.5 * TEXT_MM;
    let block_w = text_width_mm(&line1, TEXT_MM)
        .max(text_width_mm(&line2, TEXT_MM))
        .max(SCALE_BAR_MM + gap + text_width_mm(&bar_label, TEXT_MM));
    let block_h = 2.0 * (TEXT_MM + gap) + SCALE_BAR_HEIGHT_MM;
    // Clear of tags by one tag cell: the detector needs white around each tag's outer ring.
    let clear = cell_mm;
    let free = |x: f64, y: f64| {
        boxes.iter().all(|b| {
            x + block_w + clear <= b[0]
                || b[2] + clear <= x
                || y + block_h + clear <= b[1]
                || b[3] + clear <= y
        })
    };
    let Some((x, y)) = first_free_place(&free, paper_mm, margin_mm, [block_w, block_h]) else {
        return Err(PrintError::NoRoomForLabel {
            w_mm: block_w,
            h_mm: block_h,
            paper_w_mm: paper_mm[0],
            paper_h_mm: paper_mm[1],
            margin_mm,
        });
    };
    let mut texts = vec![
        Text {
            x_mm: x,
            baseline_mm: y + TEXT_MM,
            size_mm: TEXT_MM,
            text: line1,
        },
        Text {
            x_mm: x,
            baseline_mm: y + 2.0 * TEXT_MM + gap,
            size_mm: TEXT_MM,
            text: line2,
        },
    ];
    // Scale bar: ten 10 mm segments, alternately solid and outlined, under the label.
    let bar_top = y + 2.0 * (TEXT_MM + gap);
    let bar_bottom = bar_top + SCALE_BAR_HEIGHT_MM;
    push_scale_bar(x, bar_top, bar_bottom, &mut quads);
    texts.push(Text {
        x_mm: x + SCALE_BAR_MM + gap,
        baseline_mm: bar_bottom,
        size_mm: TEXT_MM,
        text: bar_label,
    });
    Ok(Drawing {
        paper_mm,
        quads,
        texts,
    })
}

/// The black cells of one tag as quads on the sheet, mm: each run of black cells in a row is
/// one quad (no seams between cells). `to_sheet` maps tag-local mm (x right, y down, origin at
/// the tag's centre) to the sheet.
fn push_tag_quads(
    cells: &TagCells,
    cell_mm: f64,
    total_mm: f64,
    to_sheet: &dyn Fn(f64, f64) -> [f64; 2],
    quads: &mut Vec<Quad>,
) {
    let n = cells.width;
    for row in 0..n {
        // runs of black cells in a row become one quad (no seams between cells)
        let mut col = 0;
        while col < n {
            if cells.is_white(col, row) {
                col += 1;
                continue;
            }
            let start = col;
            while col < n && !cells.is_white(col, row) {
                col += 1;
            }
            let x0 = start as f64 * cell_mm - 0.5 * total_mm;
            let x1 = col as f64 * cell_mm - 0.5 * total_mm;
            let y0 = row as f64 * cell_mm - 0.5 * total_mm;
            let y1 = y0 + cell_mm;
            quads.push(Quad([
                to_sheet(x0, y0),
                to_sheet(x1, y0),
                to_sheet(x1, y1),
                to_sheet(x0, y1),
            ]));
        }
    }
}

/// The label block's place, mm: scanning from the bottom-left in 1 mm steps, the first
/// top-left corner (bottom rows first) inside the margins where `free` holds; `None` when
/// there is none. `block_mm`: the block's width and height.
fn first_free_place(
    free: &dyn Fn(f64, f64) -> bool,
    paper_mm: [f64; 2],
    margin_mm: f64,
    [block_w, block_h]: [f64; 2],
) -> Option<(f64, f64)> {
    let (x_max, y_max) = (
        paper_mm[0] - margin_mm - block_w,
        paper_mm[1] - margin_mm - block_h,
    );
    let mut place = None;
    let mut y = y_max;
    'scan: while y >= margin_mm {
        let mut x = margin_mm;
        while x <= x_max {
            if free(x, y) {
                place = Some((x, y));
                break 'scan;
            }
            x += 1.0;
        }
        y -= 1.0;
    }
    place
}

/// Ten 10 mm segments from `x`, mm, between `bar_top` and `bar_bottom`, alternately solid and
/// outlined, and the end tick at 100 mm.
fn push_scale_bar(x: f64, bar_top: f64, bar_bottom: f64, quads: &mut Vec<Quad>) {
    let rect = |x0: f64, y0: f64, x1: f64, y1: f64| Quad([[x0, y0], [x1, y0], [x1, y1], [x0, y1]]);
    let line_mm = 0.2;
    for k in 0..10 {
        let x0 = x + f64::from(k) * SCALE_BAR_MM / 10.0;
        let x1 = x0 + SCALE_BAR_MM / 10.0;
        if k % 2 == 0 {
            quads.push(rect(x0, bar_top, x1, bar_bottom));
        } else {
            quads.push(rect(x0, bar_top, x1, bar_top + line_mm));
            quads.push(rect(x0, bar_bottom - line_mm, x1, bar_bottom));
        }
    }
    // end ticks mark the exact 0 and 100 mm positions
    quads.push(rect(
        x + SCALE_BAR_MM - line_mm,
        bar_top,
        x + SCALE_BAR_MM,
        bar_bottom,
    ));
}

/// Output formats, chosen by the file's extension.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Format {
    /// `.pdf`
    Pdf,
    /// `.svg`
    Svg,
    /// `.png`
    Png,
}

impl Format {
    /// The format a path's extension names (case-insensitive), if any.
    pub fn of_path(path: &std::path::Path) -> Option<Self> {
        let ext = path.extension()?.to_str()?.to_ascii_lowercase();
        match ext.as_str() {
            "pdf" => Some(Self::Pdf),
            "svg" => Some(Self::Svg),
            "png" => Some(Self::Png),
            _ => None,
        }
    }
}

#[cfg(test)]
mod tests;
