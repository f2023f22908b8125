//! `ellipso calibrate SESSION`: camera intrinsics and distortion (and, with `--sphere`, the
//! flash position) from a recorded session's board frames. The flags become
//! [`ellipso_vision::calibrate::session::Args`]; [`ellipso_vision::calibrate::session::run`]
//! does the work and says its report, printed here.

use std::path::PathBuf;

use ellipso_vision::calibrate::highlight::Sphere;
use ellipso_vision::calibrate::session;
use ellipso_vision::track::DetectImage;

/// Arguments of `ellipso calibrate`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// Session directory (frames of AprilTag boards).
    pub session: PathBuf,
    /// Where to write the `[camera]` section.
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// Detection image.
    #[arg(long, value_enum, default_value_t = DetectImage::S0)]
    pub image: DetectImage,
    /// Also estimate k3 (needs corners out to the image corners).
    #[arg(long)]
    pub free_k3: bool,
    /// Estimate the flash position from highlights on a glossy sphere: RADIUS,X,Y,Z in metres,
    /// the centre in the world frame of the session's boards.
    #[arg(long, value_parser = parse_sphere, value_name = "R,X,Y,Z")]
    pub sphere: Option<Sphere>,
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
    let options = session::Args {
        session: args.session,
        out: args.out,
        image: args.image,
        free_k3: args.free_k3,
        sphere: args.sphere,
    };
    session::run(&options, &super::out::Printed).map_err(super::out::failed)
}
