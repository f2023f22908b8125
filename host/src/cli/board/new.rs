//! `ellipso board new`: a grid board designed for a paper size and a tag size.
//!
//! Layout rule: the printable area is the paper less the printer margin on every side, less a
//! strip at the bottom for the label and the scale bar; tags sit on a square grid whose pitch
//! is the tag's outer size (its white ring included) plus one tag cell of extra white, the
//! least the board validation accepts with a margin of one cell; the grid is centred. The
//! board written is checked by the same layout `board print` runs, so what `new` writes prints.

use std::path::PathBuf;

use anyhow::{Context as _, bail};
use ellipso_model::tags::{Board, BoardSpec, GridSpec, TagFamily};
use ellipso_report::board_print;

/// Paper sizes by name, portrait `[width, height]` in mm (ISO 216 and US letter).
const PAPERS: &[(&str, [f64; 2])] = &[
    ("a5", [148.0, 210.0]),
    ("a4", [210.0, 297.0]),
    ("a3", [297.0, 420.0]),
    ("letter", [215.9, 279.4]),
];

/// Arguments of `ellipso board new`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// Paper: a5, a4, a3, letter, or WIDTHxHEIGHT in mm (e.g. 300x200).
    #[arg(long, default_value = "a4")]
    pub paper: String,
    /// Turn the paper sideways.
    #[arg(long)]
    pub landscape: bool,
    /// Tag size, mm: the outer edge of the black border (AprilTag's tag size).
    #[arg(long, default_value_t = 30.0)]
    pub tag_mm: f64,
    /// Tag family: tag36h11, tag25h9 or tag16h5.
    #[arg(long, default_value = "tag36h11")]
    pub family: String,
    /// Id of the first tag (ids run row by row); keep boards of one scene apart.
    #[arg(long, default_value_t = 0)]
    pub first_id: u32,
    /// Border the printer leaves unprinted, mm.
    #[arg(long, default_value_t = board_print::DEFAULT_PRINTER_MARGIN_MM)]
    pub margin_mm: f64,
    /// Name printed on the board.
    #[arg(long)]
    pub name: Option<String>,
    /// Where to write the board TOML.
    #[arg(long)]
    pub out: PathBuf,
}

/// Parses `--paper`.
pub fn paper_mm(name: &str) -> anyhow::Result<[f64; 2]> {
    if let Some((_, size)) = PAPERS.iter().find(|(n, _)| n.eq_ignore_ascii_case(name)) {
        return Ok(*size);
    }
    let parsed = name
        .split_once(['x', 'X'])
        .and_then(|(w, h)| Some([w.trim().parse::<f64>().ok()?, h.trim().parse::<f64>().ok()?]));
    match parsed {
        Some([w, h]) if w.is_finite() && h.is_finite() && w > 0.0 && h > 0.0 => Ok([w, h]),
        _ => bail!(
            "--paper {name}: expected one of a5, a4, a3, letter or WIDTHxHEIGHT in mm (e.g. \
             300x200)"
        ),
    }
}

/// The board spec `args` describe (validated by the print layout).
pub fn design(args: &Args) -> anyhow::Result<BoardSpec> {
    let mut paper = paper_mm(&args.paper)?;
    if args.landscape {
        paper.swap(0, 1);
    }
    let family: TagFamily = toml::Value::String(args.family.clone())
        .try_into()
        .map_err(|_| {
            anyhow::anyhow!(
                "--family {}: expected tag36h11, tag25h9 or tag16h5",
                args.family
            )
        })?;
    if !(args.tag_mm.is_finite() && args.tag_mm > 0.0) {
        bail!("--tag-mm {}: must be a positive size in mm", args.tag_mm);
    }
    let table = family.code_table();
    let cell_mm = args.tag_mm / f64::from(table.width_at_border);
    let outer_mm = f64::from(table.total_width) * cell_mm;
    let pitch_mm = outer_mm + cell_mm;
    // label strip: two text lines, the scale bar and gaps (see board_print::layout)
    let label_mm =
        2.0 * 1.5 * board_print::TEXT_MM + board_print::SCALE_BAR_HEIGHT_MM + 2.0 * cell_mm;
    let usable = [
        paper[0] - 2.0 * args.margin_mm,
        paper[1] - 2.0 * args.margin_mm - label_mm,
    ];
    let count = |len: f64| {
        if len < outer_mm {
            0
        } else {
            1 + ((len - outer_mm) / pitch_mm).floor() as u32
        }
    };
    let (cols, rows) = (count(usable[0]), count(usable[1]));
    if cols == 0 || rows == 0 {
        bail!(
            "--tag-mm {}: a tag with its white border is {outer_mm:.1} mm, more than the \
             {:.0} × {:.0} mm left of the {:.0} × {:.0} mm paper after the {} mm printer margin \
             and the label strip: the board does not fit its paper",
            args.tag_mm,
            usable[0].max(0.0),
            usable[1].max(0.0),
            paper[0],
            paper[1],
            args.margin_mm
        );
    }
    let n = (cols * rows) as usize;
    if args.first_id as usize + n > table.len() {
        bail!(
            "--first-id {}: {cols} × {rows} tags need ids up to {}, but {} has ids 0..{}",
            args.first_id,
            args.first_id as usize + n - 1,
            family.name(),
            table.len() - 1
        );
    }
    let grid_w = outer_mm + f64::from(cols - 1) * pitch_mm;
    let first_centre_mm = [
        0.5 * (paper[0] - grid_w) + 0.5 * outer_mm,
        args.margin_mm + 0.5 * outer_mm,
    ];
    let spec = BoardSpec {
        name: Some(args.name.clone().unwrap_or_else(|| {
            format!(
                "{}_{}{}_{:.0}mm",
                family.name(),
                args.paper.to_ascii_lowercase(),
                if args.landscape { "_landscape" } else { "" },
                args.tag_mm
            )
        })),
        family,
        tag_size_m: args.tag_mm * 1e-3,
        sheet_size_m: Some([paper[0] * 1e-3, paper[1] * 1e-3]),
        margin_m: args.margin_mm * 1e-3,
        white_albedo: 0.85,
        black_albedo: 0.04,
        origin: Default::default(),
        axes: Default::default(),
        grid: Some(GridSpec {
            cols,
            rows,
            spacing_m: pitch_mm * 1e-3,
            first_id: args.first_id,
            ids: None,
            first_centre_m: Some([first_centre_mm[0] * 1e-3, first_centre_mm[1] * 1e-3]),
        }),
        tags: Vec::new(),
    };
    let board = Board::from_spec(&spec).map_err(|e| anyhow::anyhow!("designed board: {e}"))?;
    board_print::layout(&board, args.margin_mm)?;
    Ok(spec)
}

/// Runs `ellipso board new`.
pub fn run(args: Args) -> anyhow::Result<()> {
    let spec = design(&args)?;
    let grid = spec.grid.as_ref().map_or((0, 0), |g| (g.cols, g.rows));
    let header = format!(
        "# AprilTag board written by `ellipso board new` ({} tags of {} mm on {} paper{}).\n\
         # Print it with `ellipso board print THIS.toml --out board.pdf` at 100 % (no \
         fit-to-page).\n\
         # Sheet frame: origin at the top-left corner of the paper, x right, y down, metres.\n",
        grid.0 * grid.1,
        args.tag_mm,
        args.paper,
        if args.landscape { ", landscape" } else { "" }
    );
    let body = toml::to_string(&spec).context("writing the board as TOML")?;
    ellipso_report::atomic_file::write(&args.out, format!("{header}{body}"))
        .with_context(|| format!("writing {}", args.out.display()))?;
    crate::outln!(
        "wrote {}: {} × {} tags of {} mm ({}, ids {}..{})",
        args.out.display(),
        grid.0,
        grid.1,
        args.tag_mm,
        spec.family.name(),
        args.first_id,
        args.first_id + grid.0 * grid.1 - 1
    );
    Ok(())
}
