//! `ellipso model …`: inspect the polarimetric model (Fresnel, diffuse DoP, Mueller matrices)
//! and plot the degree of polarisation.
//!
//! The numbers, their ranges and frames are [`ellipso_model::optics::inspect`]'s (its doc is the
//! contract; a bad flag is one error line naming it and its range), the plot is
//! [`ellipso_report::dop_plot`]; the binary keeps the flags and prints: `--json` one JSON object
//! on stdout, otherwise readable tables.

use std::path::PathBuf;

use anyhow::{Context, Result};
use ellipso_model::optics::fresnel::brewster_angle_rad;
use ellipso_model::optics::inspect::{self, MuellerInputs};
use ellipso_model::optics::pbrdf::PbrdfParams;
use serde_json::Value;

/// Working examples of every subcommand, shown by `ellipso model --help` (README's, kept true
/// by `host/src/quoted_commands.rs`).
pub const EXAMPLES: &str = "Examples:
  ellipso model fresnel --eta 1.5 --theta-deg 56.3
  ellipso model dop --eta 1.5 --theta-deg 60
  ellipso model mueller --eta 1.5 --sigma-s 0.1 --sigma-ss 0.2 --rho-s 1 --rho-ss 0.1,0.1,0.1 \\
      --rho-d 0.5,0.4,0.3 --normal 0,0,1 --to-light 0.3,0,1 --to-camera -0.3,0,1
  ellipso model plot --out dop.png";

/// Arguments of `ellipso model`.
#[derive(Debug, clap::Args)]
#[command(after_help = EXAMPLES)]
pub struct Args {
    #[command(subcommand)]
    command: ModelCommand,
}

#[derive(Debug, clap::Subcommand)]
enum ModelCommand {
    /// Fresnel amplitudes and Mueller quantities of a dielectric at one incidence angle.
    Fresnel(AngleArgs),
    /// Diffuse degree of polarisation DoP_d(θ, η) and its η-derivative (closed form).
    Dop(AngleArgs),
    /// The 4×4 Mueller matrices of the three lobes for one geometry (light → camera frame).
    Mueller(Box<MuellerArgs>),
    /// Plot diffuse and specular DoP against angle for η ∈ {1.3, 1.5, 1.7, 2.3} as PNG.
    Plot(PlotArgs),
}

/// `--eta`, `--theta-deg`, `--json`.
#[derive(Debug, clap::Args)]
struct AngleArgs {
    /// Refractive index relative to air, [1, 5].
    #[arg(long)]
    eta: f64,
    /// Angle to the surface normal in degrees, [0, 90].
    #[arg(long = "theta-deg")]
    theta_deg: f64,
    /// Print JSON instead of a table.
    #[arg(long)]
    json: bool,
}

/// Arguments of `ellipso model mueller`.
#[derive(Debug, clap::Args)]
pub struct MuellerArgs {
    /// Refractive index relative to air, [1, 5].
    #[arg(long)]
    pub eta: f64,
    /// Specular GGX roughness σ_s ∈ [0, 1].
    #[arg(long = "sigma-s")]
    pub sigma_s: f64,
    /// Single-scattering GGX roughness σ_ss ∈ [σ_s, 1].
    #[arg(long = "sigma-ss")]
    pub sigma_ss: f64,
    /// Specular albedo ρ_s (monochrome), [0, 1000].
    #[arg(long = "rho-s")]
    pub rho_s: f64,
    /// Single-scattering albedo R,G,B, each in [0, 1000].
    #[arg(long = "rho-ss", value_parser = parse_triple, value_name = "R,G,B")]
    pub rho_ss: [f64; 3],
    /// Diffuse albedo R,G,B, each in [0, 1].
    #[arg(long = "rho-d", value_parser = parse_triple, value_name = "R,G,B")]
    pub rho_d: [f64; 3],
    /// Surface normal (world, any non-zero length).
    #[arg(long, value_parser = parse_triple, value_name = "X,Y,Z", allow_hyphen_values = true)]
    pub normal: [f64; 3],
    /// Direction surface → light (world, any non-zero length).
    #[arg(long = "to-light", value_parser = parse_triple, value_name = "X,Y,Z", allow_hyphen_values = true)]
    pub to_light: [f64; 3],
    /// Direction surface → camera (world, any non-zero length).
    #[arg(long = "to-camera", value_parser = parse_triple, value_name = "X,Y,Z", allow_hyphen_values = true)]
    pub to_camera: [f64; 3],
    /// Light-frame up vector (default world +y).
    #[arg(long = "light-up", value_parser = parse_triple, value_name = "X,Y,Z", allow_hyphen_values = true)]
    pub light_up: Option<[f64; 3]>,
    /// Camera-frame up vector = image up (default world +y).
    #[arg(long = "camera-up", value_parser = parse_triple, value_name = "X,Y,Z", allow_hyphen_values = true)]
    pub camera_up: Option<[f64; 3]>,
    /// Print JSON instead of tables.
    #[arg(long)]
    pub json: bool,
}

/// Arguments of `ellipso model plot`.
#[derive(Debug, clap::Args)]
struct PlotArgs {
    /// Output PNG path.
    #[arg(long)]
    out: PathBuf,
}

/// Parses "a,b,c" into three finite numbers.
fn parse_triple(text: &str) -> Result<[f64; 3], String> {
    let parts: Vec<&str> = text.split(',').map(str::trim).collect();
    if parts.len() != 3 {
        return Err(format!(
            "expected three comma-separated numbers, got {} value(s)",
            parts.len()
        ));
    }
    let mut out = [0.0; 3];
    for (slot, part) in out.iter_mut().zip(&parts) {
        let v: f64 = part
            .parse()
            .map_err(|_| format!("'{part}' is not a number"))?;
        if !v.is_finite() {
            return Err(format!("'{part}' is not finite"));
        }
        *slot = v;
    }
    Ok(out)
}

/// Runs `ellipso model`.
pub fn run(args: Args) -> Result<()> {
    match args.command {
        ModelCommand::Fresnel(a) => {
            let t = inspect::fresnel(a.eta, a.theta_deg).map_err(anyhow::Error::new)?;
            if a.json {
                crate::outln!("{}", serde_json::to_value(t)?);
            } else {
                crate::outln!(
                    "Fresnel, dielectric η = {} at θ = {}° (Brewster {:.4}°)",
                    a.eta,
                    a.theta_deg,
                    brewster_angle_rad(a.eta).to_degrees()
                );
                for (key, v) in [
                    ("rs", t.rs),
                    ("rp", t.rp),
                    ("r_plus", t.r_plus),
                    ("r_minus", t.r_minus),
                    ("r_cross", t.r_cross),
                    ("t_plus", t.t_plus),
                    ("t_minus", t.t_minus),
                ] {
                    crate::outln!("  {key:<8} {v:>12.6}");
                }
            }
        }
        ModelCommand::Dop(a) => {
            let t = inspect::dop(a.eta, a.theta_deg).map_err(anyhow::Error::new)?;
            if a.json {
                crate::outln!("{}", serde_json::to_value(t)?);
            } else {
                crate::outln!("Diffuse DoP at η = {}, θ_o = {}°", a.eta, a.theta_deg);
                crate::outln!("  dop        {:>12.6}", t.dop);
                crate::outln!("  d_dop_d_eta {:>11.6}", t.d_dop_d_eta);
            }
        }
        ModelCommand::Mueller(a) => {
            let v =
                serde_json::to_value(inspect::mueller(&a.inputs()).map_err(anyhow::Error::new)?)?;
            if a.json {
                crate::outln!("{v}");
            } else {
                print_mueller_tables(&v);
            }
        }
        ModelCommand::Plot(a) => {
            // a PNG name, never inside a session, never over a file that is not a PNG
            let out = ellipso_report::output::OutputFile::claim(
                &a.out,
                "model-plot",
                ellipso_report::output::FileFormat::PNG,
                &[],
                None,
            )?;
            ellipso_report::dop_plot::dop_plot()
                .save_png(out.path())
                .with_context(|| format!("--out {}", a.out.display()))?;
            crate::outln!("wrote {}", a.out.display());
        }
    }
    Ok(())
}

impl MuellerArgs {
    /// The flags as the library takes them.
    fn inputs(&self) -> MuellerInputs {
        MuellerInputs {
            params: PbrdfParams {
                eta: self.eta,
                sigma_s: self.sigma_s,
                sigma_ss: self.sigma_ss,
                rho_s: self.rho_s,
                rho_ss: self.rho_ss,
                rho_d: self.rho_d,
            },
            normal: self.normal,
            to_light: self.to_light,
            to_camera: self.to_camera,
            light_up: self.light_up,
            camera_up: self.camera_up,
        }
    }
}

fn print_matrix(title: &str, m: &Value) {
    crate::outln!("  {title}");
    for row in m.as_array().into_iter().flatten() {
        let cells: Vec<String> = row
            .as_array()
            .into_iter()
            .flatten()
            .map(|x| format!("{:>13.6e}", x.as_f64().unwrap_or(f64::NAN) + 0.0))
            .collect();
        crate::outln!("    [{}]", cells.join(" "));
    }
}

fn print_mueller_tables(v: &Value) {
    crate::outln!(
        "Mueller matrices, light frame → camera frame, row-major (s_cam = P·s_light / d²)"
    );
    for key in ["light_frame", "camera_frame"] {
        crate::outln!(
            "  {key}: x {} y {} z {}",
            v[key]["x"],
            v[key]["y"],
            v[key]["z"]
        );
    }
    crate::outln!("  cosθ: {}", v["cos_theta"]);
    let channels = ["R", "G", "B"];
    for (key, name) in [
        ("diffuse", "diffuse P^d"),
        ("single_scattering", "single scattering P^ss"),
        ("total", "total P"),
    ] {
        for (c, ch) in channels.iter().enumerate() {
            print_matrix(&format!("{name} [{ch}]"), &v[key][c]);
        }
    }
    print_matrix("specular P^s (monochrome)", &v["specular"]);
}

#[cfg(test)]
mod tests {
    use super::*;
    use clap::Parser;

    #[derive(Debug, Parser)]
    struct Cli {
        #[command(flatten)]
        args: Args,
    }

    fn mueller_args(extra: &[&str]) -> Result<MuellerArgs, clap::Error> {
        let mut argv = vec![
            "model",
            "mueller",
            "--eta",
            "1.5",
            "--sigma-s",
            "0.2",
            "--sigma-ss",
            "0.5",
            "--rho-s",
            "1",
            "--rho-ss",
            "0.1,0.1,0.1",
            "--rho-d",
            "0.5,0.4,0.3",
            "--normal",
            "0,0,1",
            "--to-light",
            "0.1,0,1",
            "--to-camera",
            "-0.1,0,1",
            "--json",
        ];
        argv.extend_from_slice(extra);
        let cli = Cli::try_parse_from(argv)?;
        match cli.args.command {
            ModelCommand::Mueller(m) => Ok(*m),
            other => panic!("parsed {other:?}"),
        }
    }

    #[test]
    fn mueller_flags_parse_and_a_bad_one_is_named() {
        let t = inspect::mueller(&mueller_args(&[]).unwrap().inputs()).unwrap();
        assert!(
            t.diffuse[0][0][0] > t.diffuse[2][0][0],
            "--rho-d is read per channel"
        );
        let err = |extra: &[&str]| match mueller_args(extra) {
            Err(e) => e.to_string(),
            Ok(a) => inspect::mueller(&a.inputs()).unwrap_err().to_string(),
        };
        assert!(err(&["--normal", "0,0,0"]).contains("--normal"));
        assert!(err(&["--to-light", "nan,0,1"]).contains("--to-light"));
        assert!(err(&["--to-camera", "1,2"]).contains("--to-camera"));
    }

    #[test]
    fn json_keys_are_the_documented_ones() {
        let v = serde_json::to_value(inspect::fresnel(1.5, 60.0).unwrap()).unwrap();
        assert_eq!(v.as_object().unwrap().len(), 7);
        let a = mueller_args(&[]).unwrap();
        let v = serde_json::to_value(inspect::mueller(&a.inputs()).unwrap()).unwrap();
        assert_eq!(v["specular"].as_array().unwrap().len(), 4);
        assert_eq!(v["single_scattering"][2][3].as_array().unwrap().len(), 4);
    }
}
