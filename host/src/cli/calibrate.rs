//! `ellipso calibrate SESSION`: camera intrinsics and distortion (and, with `--sphere`, the
//! flash position) from a recorded session's board frames. The flags become
//! [`ellipso_vision::calibrate::session::Args`]; [`ellipso_vision::calibrate::session::run`]
//! does the work and says its report, printed here.
//!
//! `ellipso calibrate flash SESSION --sphere R,X,Y,Z --out RIG.toml`: the flash position and
//! polariser angle from a session of a glossy sphere on the board, written as the rig file's
//! `[flash]` table with its other tables kept (docs/pose.md, "Calibrating the flash").
//!
//! `ellipso calibrate sensor CAPTURES --out FILE`: the per-pixel sensor calibration (EMVA 1288
//! figures, dark levels, analysis vectors) from a captures folder
//! ([`ellipso_polar::sensor_calibration::measure`]), written as a calibration file and its
//! `.json` report beside it (docs/sensor-calibration.md).

use std::path::PathBuf;

use ellipso_vision::calibrate::highlight::Sphere;
use ellipso_vision::calibrate::session;
use ellipso_vision::track::DetectImage;

/// Arguments of `ellipso calibrate`.
#[derive(Debug, clap::Args)]
#[command(args_conflicts_with_subcommands = true, subcommand_negates_reqs = true)]
pub struct Args {
    /// `sensor`: the sensor calibration from calibration captures.
    #[command(subcommand)]
    pub what: Option<What>,
    /// Session directory (frames of AprilTag boards).
    #[arg(required = true)]
    pub session: Option<PathBuf>,
    /// Where to write the `[camera]` section.
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// Detection image.
    #[arg(long, value_enum, default_value_t = DetectImage::S0)]
    pub image: DetectImage,
    /// Also estimate k3 (needs corners out to the image corners).
    #[arg(long)]
    pub free_k3: bool,
    /// Estimate the flash position and polariser angle from highlights on a glossy sphere:
    /// RADIUS,X,Y,Z in metres, the centre in the world frame of the session's boards.
    #[arg(long, value_parser = parse_sphere, value_name = "R,X,Y,Z")]
    pub sphere: Option<Sphere>,
}

/// What else `ellipso calibrate` calibrates.
#[derive(Debug, clap::Subcommand)]
pub enum What {
    /// The flash (position and polariser angle) from a session of a glossy sphere on the board,
    /// written into the rig file's `[flash]` table (docs/pose.md, "Calibrating the flash").
    Flash(FlashArgs),
    /// The sensor (gain, read noise, black level, DSNU, PRNU, vignetting, per-pixel analysers)
    /// from a folder of dark, flat and polariser-sheet captures (`captures.json`).
    Sensor(SensorArgs),
}

/// Arguments of `ellipso calibrate flash`.
#[derive(Debug, clap::Args)]
pub struct FlashArgs {
    /// Session directory: frames of the glossy sphere on the tag board, the sphere at different
    /// places in the image and two distances.
    pub session: PathBuf,
    /// The sphere: RADIUS,X,Y,Z in metres, the centre in the world frame of the session's boards.
    #[arg(long, value_parser = parse_sphere, value_name = "R,X,Y,Z")]
    pub sphere: Sphere,
    /// The rig file whose `[flash]` table is written (its other tables kept; created when
    /// missing). Default `SESSION/calibration/flash.toml`.
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// Detection image.
    #[arg(long, value_enum, default_value_t = DetectImage::S0)]
    pub image: DetectImage,
}

/// Arguments of `ellipso calibrate sensor`.
#[derive(Debug, clap::Args)]
pub struct SensorArgs {
    /// Captures folder (`captures.json` and its frames).
    pub captures: PathBuf,
    /// The calibration file to write (a `.json` report is written beside it).
    #[arg(long)]
    pub out: PathBuf,
}

/// Parses `R,X,Y,Z` (metres) into a sphere.
pub fn parse_sphere(s: &str) -> Result<Sphere, String> {
    let v: Vec<f64> = s
        .split(',')
        .map(|p| p.trim().parse::<f64>().map_err(|e| format!("'{p}': {e}")))
        .collect::<Result<_, _>>()?;
    let [radius_m, x, y, z] = v[..] else {
        return Err(format!("expected R,X,Y,Z (4 numbers), got {}", v.len()));
    };
    if !(radius_m.is_finite() && radius_m > 0.0 && [x, y, z].iter().all(|c| c.is_finite())) {
        return Err(format!(
            "radius {radius_m} must be positive and the centre finite"
        ));
    }
    Ok(Sphere {
        radius_m,
        centre_m: nalgebra::Point3::new(x, y, z),
    })
}

/// Runs `ellipso calibrate`.
pub fn run(args: Args) -> anyhow::Result<()> {
    match args.what {
        Some(What::Sensor(a)) => return sensor(a),
        Some(What::Flash(a)) => {
            let options = session::Args {
                session: a.session,
                out: a.out,
                image: a.image,
                free_k3: false,
                sphere: Some(a.sphere),
                flash_only: true,
            };
            return session::run(&options, &super::out::Printed)
                .map(|_| ())
                .map_err(super::out::failed);
        }
        None => {}
    }
    let Some(session) = args.session else {
        anyhow::bail!(
            "calibrate: give a session directory, `flash SESSION --sphere R,X,Y,Z`, or `sensor CAPTURES --out FILE`"
        );
    };
    let options = session::Args {
        session,
        out: args.out,
        image: args.image,
        free_k3: args.free_k3,
        sphere: args.sphere,
        flash_only: false,
    };
    session::run(&options, &super::out::Printed)
        .map(|_| ())
        .map_err(super::out::failed)
}

fn sensor(args: SensorArgs) -> anyhow::Result<()> {
    use anyhow::Context;
    use ellipso_polar::sensor_calibration::{MeasureOptions, file, measure};
    use ellipso_session::calibration_captures::CaptureSet;
    if args.out.exists() {
        anyhow::bail!(
            "{}: exists; a calibration is never written over (choose a new name)",
            args.out.display()
        );
    }
    let set = CaptureSet::read(&args.captures)?;
    let mut cal = measure(&args.captures, &set, MeasureOptions::default())
        .with_context(|| format!("{}", args.captures.display()))?;
    let id = file::write(&mut cal, &args.out)?;
    let report = args.out.with_extension("json");
    let json = serde_json::json!({
        "id": id,
        "file": args.out.file_name().map(|n| n.to_string_lossy().into_owned()),
        "header": &cal.header,
    });
    ellipso_report::atomic_file::write(&report, serde_json::to_string_pretty(&json)? + "\n")
        .with_context(|| report.display().to_string())?;
    let f = &cal.header.figures;
    crate::outln!("sensor calibration {id} written to {}", args.out.display());
    crate::outln!(
        "  gain {:.4} DN/e- ({:.3} e-/DN), read noise {:.3} e- ({:.3} DN), black level {:.2} DN, DSNU {:.3} DN",
        f.gain_dn_per_e,
        f.gain_e_per_dn,
        f.read_noise_e,
        f.read_noise_dn,
        f.black_level_dn,
        f.dsnu_dn
    );
    crate::outln!(
        "  PRNU {:.3} %, saturation {:.0} DN ({:.0} e-), vignetting cos^{:.3}, {} hot pixel(s)",
        100.0 * f.prnu_rel,
        f.saturation_dn,
        f.saturation_e,
        f.vignetting_exponent,
        f.hot_pixels
    );
    crate::outln!(
        "  extinction ratio {:?}, analyser angle errors (mean per analyser) {:?} deg, sd {:.3} deg",
        f.extinction_ratio
            .iter()
            .map(|v| (v * 10.0).round() / 10.0)
            .collect::<Vec<_>>(),
        f.analyser_angle_mean_error_deg
            .map(|v| (v * 1000.0).round() / 1000.0),
        f.analyser_angle_sd_deg
    );
    crate::outln!("  report: {}", report.display());
    Ok(())
}
