//! `ellipso bench generalize`: the whole chain on procedurally generated scenes
//! ([`ellipso_bench::generalize::run`]); the binary keeps the flags and prints one line per
//! scene and the report's files. Seeds below 1000 are for development; the figures that count
//! are on seeds ≥ 1000, run after the last constant was chosen.

use std::ops::Range;
use std::path::PathBuf;

use ellipso_bench::generalize::GeneralizeOptions;

/// Arguments of `ellipso bench generalize`.
#[derive(Debug, clap::Args)]
pub struct GeneralizeArgs {
    /// Seeds, `START..END` (END excluded), `START..=END` or one seed. Below 1000: development
    /// seeds; the figures that count are on seeds ≥ 1000.
    #[arg(long, default_value = "1000..1020", value_parser = seeds)]
    pub seeds: Range<u64>,
    /// Image size WIDTHxHEIGHT (612x512, 1224x1024 or 2448x2048; the camera's focal length
    /// scales with it).
    #[arg(long, default_value = "612x512", value_parser = crate::cli::limits::resolution)]
    pub resolution: [u32; 2],
    /// Photos per scene.
    #[arg(long, default_value_t = 50, value_parser = crate::cli::limits::count::<u32>)]
    pub photos: u32,
    /// Work folder: each scene and its rendered session go in `seed-<N>/` (reused).
    #[arg(long, default_value = "ellipso-bench-generalize")]
    pub out: PathBuf,
    /// Scenes run at once.
    #[arg(long, default_value_t = 1, value_parser = crate::cli::limits::count::<usize>)]
    pub jobs: usize,
    /// The report (default docs/generalize.md); its JSON goes beside it (`.json`).
    #[arg(long)]
    pub report: Option<PathBuf>,
    /// Only write each seed's scene (`<out>/seed-<N>/scene.toml`) and print its path: for a
    /// capture by hand (`ellipso capture --sim`, `ellipso fit`, `ellipso bench score`).
    #[arg(long)]
    pub scenes_only: bool,
}

/// Parses `a..b`, `a..=b` or `a` into a half-open range holding at least one seed.
fn seeds(s: &str) -> Result<Range<u64>, String> {
    let num = |t: &str| {
        t.trim()
            .parse::<u64>()
            .map_err(|e| format!("seed `{t}`: {e}"))
    };
    let range = if let Some((a, b)) = s.split_once("..=") {
        num(a)?..num(b)?.saturating_add(1)
    } else if let Some((a, b)) = s.split_once("..") {
        num(a)?..num(b)?
    } else {
        let a = num(s)?;
        a..a.saturating_add(1)
    };
    if range.is_empty() {
        return Err(format!(
            "`{s}` holds no seed (END is excluded in START..END)"
        ));
    }
    Ok(range)
}

/// Runs `ellipso bench generalize`.
pub fn run(args: GeneralizeArgs) -> anyhow::Result<()> {
    let options = GeneralizeOptions {
        seeds: args.seeds,
        resolution_px: args.resolution,
        photos: args.photos,
        out: args.out,
        jobs: args.jobs,
        report: args.report,
    };
    if args.scenes_only {
        let paths =
            ellipso_bench::generalize::write_scenes(&options).map_err(super::super::out::failed)?;
        for (seed, p) in options.seeds.clone().zip(&paths) {
            let g = ellipso_sim::generate::GeneratedScene::generate(
                seed,
                ellipso_sim::generate::GenerateOptions {
                    resolution_px: options.resolution_px,
                    photo_count: options.photos,
                },
            );
            crate::outln!("{} — {}", p.display(), g.describe());
        }
        return Ok(());
    }
    let (report, path) =
        ellipso_bench::generalize::run(&options, &|line| crate::errln!("  {line}"))
            .map_err(super::super::out::failed)?;
    for s in &report.scenes {
        crate::outln!("{}", ellipso_bench::generalize::one_line(s));
    }
    crate::outln!(
        "wrote {} and {}",
        path.display(),
        path.with_extension("json").display()
    );
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::seeds;

    #[test]
    fn seed_ranges() {
        assert_eq!(seeds("1000..1020"), Ok(1000..1020));
        assert_eq!(seeds("3..=5"), Ok(3..6));
        assert_eq!(seeds("7"), Ok(7..8));
        assert!(seeds("5..5").is_err());
        assert!(seeds("x..3").is_err());
    }
}
