//! `ellipso board …`: the AprilTag boards people print and the trigger board's firmware.
//!
//! - `board print BOARD.toml --out board.pdf|svg|png`: the board at exact physical scale with
//!   its label and a 100 mm scale bar ([`ellipso_report::board_print`]).
//! - `board new --paper a4 --tag-mm 30 --out board.toml`: designs a grid board for a paper and
//!   tag size and writes its TOML ([`new`]).
//! - `board flash FIRMWARE`: updates the trigger board's firmware over USB ([`flash`]).

pub mod flash;
pub mod new;

use std::path::PathBuf;

use anyhow::Context as _;
use ellipso_report::board_print::{self, Format};

/// Subcommands of `ellipso board`.
#[derive(Debug, clap::Subcommand)]
pub enum Args {
    /// Print a board file (sim/boards/*.toml or one `board new` wrote) as PDF, SVG or PNG.
    Print(PrintArgs),
    /// Design a grid board for a paper size and tag size; writes its TOML.
    New(new::Args),
    /// Update the trigger board's firmware over USB (STM32 DfuSe bootloader).
    Flash(flash::Args),
}

/// Arguments of `ellipso board print`.
#[derive(Debug, clap::Args)]
pub struct PrintArgs {
    /// Board TOML file.
    pub board: PathBuf,
    /// Output file; the extension picks the format: .pdf, .svg or .png.
    #[arg(long)]
    pub out: PathBuf,
    /// Resolution of a PNG, dots per inch.
    #[arg(long, default_value_t = 300.0)]
    pub dpi: f64,
    /// Border the printer leaves unprinted, mm: tags and the label must stay inside it.
    #[arg(long, default_value_t = board_print::DEFAULT_PRINTER_MARGIN_MM)]
    pub margin_mm: f64,
}

/// Runs `ellipso board …`.
pub fn run(args: Args) -> anyhow::Result<()> {
    match args {
        Args::Print(a) => print(a),
        Args::New(a) => new::run(a),
        Args::Flash(a) => flash::run(a),
    }
}

fn print(args: PrintArgs) -> anyhow::Result<()> {
    let format = Format::of_path(&args.out).with_context(|| {
        format!(
            "--out {}: the extension must be .pdf, .svg or .png",
            args.out.display()
        )
    })?;
    let board = ellipso_sim::scene::load_board_file(&args.board)?;
    let drawing = board_print::layout(&board, args.margin_mm)
        .with_context(|| format!("board {}", args.board.display()))?;
    let bytes = match format {
        Format::Pdf => board_print::pdf::to_pdf(&drawing),
        Format::Svg => board_print::svg::to_svg(&drawing).into_bytes(),
        Format::Png => {
            let img = board_print::raster::rasterise(&drawing, args.dpi)
                .with_context(|| format!("--dpi {}", args.dpi))?;
            let mut png = Vec::new();
            image::codecs::png::PngEncoder::new(&mut png)
                .write_image(
                    &img.gray,
                    img.width as u32,
                    img.height as u32,
                    image::ExtendedColorType::L8,
                )
                .context("encoding the PNG")?;
            png
        }
    };
    ellipso_report::atomic_file::write(&args.out, bytes)
        .with_context(|| format!("writing {}", args.out.display()))?;
    crate::outln!(
        "wrote {} ({:.0} × {:.0} mm, {} tags of {:.1} mm): print at 100 % (no fit-to-page) and \
         check the 100 mm scale bar with a ruler",
        args.out.display(),
        drawing.paper_mm[0],
        drawing.paper_mm[1],
        board.tags.len(),
        board.tag_size_m * 1e3
    );
    Ok(())
}

use image::ImageEncoder as _;
