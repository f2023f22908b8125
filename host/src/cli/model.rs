//! `ellipso model …`: inspect the polarimetric model (Fresnel, diffuse DoP, Mueller matrices)
//! and plot the degree of polarisation.
//!
//! Contract: every subcommand validates its flags and reports a bad one in a single error line
//! naming the flag; `--json` prints one JSON object on stdout, otherwise readable tables. The
//! numbers come from `ellipso_sim::optics`, the same code the simulator and the fit use.
//! Frames of `mueller`: light frame z = −to_light, camera frame z = to_camera, y = the given up
//! vector (default world +y) orthogonalised against z, x = y × z; when the up vector is parallel
//! to z the world axis least aligned with z is used instead.

use std::path::PathBuf;

use anyhow::{Context, Result, bail};
use ellipso_sim::optics::fresnel::brewster_angle_rad;
use ellipso_sim::optics::measure::dop_diffuse_with_d_eta;
use ellipso_sim::optics::pbrdf::{Geometry, PbrdfParams, evaluate};
use ellipso_sim::optics::{Frame, FresnelTerms, Mueller, Vec3};
use serde_json::{Value, json};

use crate::report::{LegendPosition, LinePlot, Stroke, plot::PALETTE};

/// Arguments of `ellipso model`.
#[derive(Debug, clap::Args)]
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
    /// Refractive index relative to air (≥ 1).
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
    /// Refractive index relative to air (≥ 1).
    #[arg(long)]
    pub eta: f64,
    /// Specular GGX roughness σ_s ∈ [0, 1].
    #[arg(long = "sigma-s")]
    pub sigma_s: f64,
    /// Single-scattering GGX roughness σ_ss ∈ [σ_s, 1].
    #[arg(long = "sigma-ss")]
    pub sigma_ss: f64,
    /// Specular albedo ρ_s (monochrome, ≥ 0).
    #[arg(long = "rho-s")]
    pub rho_s: f64,
    /// Single-scattering albedo R,G,B (each ≥ 0).
    #[arg(long = "rho-ss", value_parser = parse_triple, value_name = "R,G,B")]
    pub rho_ss: [f64; 3],
    /// Diffuse albedo R,G,B (each ≥ 0).
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
            let v = fresnel_json(a.eta, a.theta_deg)?;
            if a.json {
                println!("{v}");
            } else {
                println!(
                    "Fresnel, dielectric η = {} at θ = {}° (Brewster {:.4}°)",
                    a.eta,
                    a.theta_deg,
                    brewster_angle_rad(a.eta).to_degrees()
                );
                for key in [
                    "rs", "rp", "r_plus", "r_minus", "r_cross", "t_plus", "t_minus",
                ] {
                    println!("  {key:<8} {:>12.6}", v[key].as_f64().unwrap_or(f64::NAN));
                }
            }
        }
        ModelCommand::Dop(a) => {
            let v = dop_json(a.eta, a.theta_deg)?;
            if a.json {
                println!("{v}");
            } else {
                println!("Diffuse DoP at η = {}, θ_o = {}°", a.eta, a.theta_deg);
                println!(
                    "  dop        {:>12.6}",
                    v["dop"].as_f64().unwrap_or(f64::NAN)
                );
                println!(
                    "  d_dop_d_eta {:>11.6}",
                    v["d_dop_d_eta"].as_f64().unwrap_or(f64::NAN)
                );
            }
        }
        ModelCommand::Mueller(a) => {
            let v = mueller_json(&a)?;
            if a.json {
                println!("{v}");
            } else {
                print_mueller_tables(&v);
            }
        }
        ModelCommand::Plot(a) => {
            dop_plot()
                .save_png(&a.out)
                .with_context(|| format!("--out {}", a.out.display()))?;
            println!("wrote {}", a.out.display());
        }
    }
    Ok(())
}

fn check_eta(eta: f64) -> Result<()> {
    if !eta.is_finite() || eta < 1.0 {
        bail!("--eta must be a finite number >= 1 (dielectric in air), got {eta}");
    }
    Ok(())
}

fn check_theta(theta_deg: f64) -> Result<()> {
    if !theta_deg.is_finite() || !(0.0..=90.0).contains(&theta_deg) {
        bail!("--theta-deg must be in [0, 90], got {theta_deg}");
    }
    Ok(())
}

/// `ellipso model fresnel --json`: {"rs","rp","r_plus","r_minus","r_cross","t_plus","t_minus"}.
pub fn fresnel_json(eta: f64, theta_deg: f64) -> Result<Value> {
    check_eta(eta)?;
    check_theta(theta_deg)?;
    let f = FresnelTerms::dielectric(theta_deg.to_radians().cos(), eta);
    Ok(json!({
        "rs": f.r_s, "rp": f.r_p, "r_plus": f.r_plus(), "r_minus": f.r_minus(),
        "r_cross": f.r_cross(), "t_plus": f.t_plus(), "t_minus": f.t_minus(),
    }))
}

/// `ellipso model dop --json`: {"dop", "d_dop_d_eta"}.
pub fn dop_json(eta: f64, theta_deg: f64) -> Result<Value> {
    check_eta(eta)?;
    check_theta(theta_deg)?;
    let (dop, d) = dop_diffuse_with_d_eta(theta_deg.to_radians().cos(), eta);
    Ok(json!({ "dop": dop, "d_dop_d_eta": d }))
}

fn matrix_json(m: &Mueller<f64>) -> Value {
    json!(m.m)
}

/// `ellipso model mueller --json`: the lobes per channel plus the frames used.
pub fn mueller_json(a: &MuellerArgs) -> Result<Value> {
    check_eta(a.eta)?;
    for (flag, v) in [("--sigma-s", a.sigma_s), ("--sigma-ss", a.sigma_ss)] {
        if !v.is_finite() || !(0.0..=1.0).contains(&v) {
            bail!("{flag} must be in [0, 1], got {v}");
        }
    }
    if a.sigma_s > a.sigma_ss {
        bail!(
            "--sigma-s ({}) must not exceed --sigma-ss ({})",
            a.sigma_s,
            a.sigma_ss
        );
    }
    if !a.rho_s.is_finite() || a.rho_s < 0.0 {
        bail!("--rho-s must be a finite number >= 0, got {}", a.rho_s);
    }
    for (flag, v) in [("--rho-ss", a.rho_ss), ("--rho-d", a.rho_d)] {
        if v.iter().any(|x| *x < 0.0) {
            bail!(
                "--{} components must be >= 0, got {:?}",
                flag.trim_start_matches('-'),
                v
            );
        }
    }
    let direction = |flag: &str, v: [f64; 3]| -> Result<Vec3<f64>> {
        Vec3::from_f64(v)
            .normalized_or_none(1e-24)
            .with_context(|| format!("{flag} must be a non-zero vector, got {v:?}"))
    };
    let normal = direction("--normal", a.normal)?;
    let to_light = direction("--to-light", a.to_light)?;
    let to_camera = direction("--to-camera", a.to_camera)?;
    let default_up = [0.0, 1.0, 0.0];
    let light_frame = Frame::light(to_light, Vec3::from_f64(a.light_up.unwrap_or(default_up)))?;
    let camera_frame = Frame::camera(to_camera, Vec3::from_f64(a.camera_up.unwrap_or(default_up)))?;
    let g = Geometry::new(normal, to_light, to_camera, light_frame, camera_frame)?;
    let p = PbrdfParams {
        eta: a.eta,
        sigma_s: a.sigma_s,
        sigma_ss: a.sigma_ss,
        rho_s: a.rho_s,
        rho_ss: a.rho_ss,
        rho_d: a.rho_d,
    };
    p.validate()?;
    let lobes = evaluate(&g, &p);
    let frame = |f: &Frame<f64>| json!({ "x": f.x.re(), "y": f.y.re(), "z": f.z.re() });
    Ok(json!({
        "diffuse": lobes.diffuse.iter().map(matrix_json).collect::<Vec<_>>(),
        "specular": matrix_json(&lobes.specular),
        "single_scattering": lobes.single_scattering.iter().map(matrix_json).collect::<Vec<_>>(),
        "total": (0..3).map(|c| matrix_json(&lobes.total(c))).collect::<Vec<_>>(),
        "light_frame": frame(&g.light_frame),
        "camera_frame": frame(&g.camera_frame),
        "cos_theta": { "i": g.cos_theta_i, "o": g.cos_theta_o, "h": g.cos_theta_h, "d": g.cos_theta_d },
        "front_facing": g.front_facing,
    }))
}

fn print_matrix(title: &str, m: &Value) {
    println!("  {title}");
    for row in m.as_array().into_iter().flatten() {
        let cells: Vec<String> = row
            .as_array()
            .into_iter()
            .flatten()
            .map(|x| format!("{:>13.6e}", x.as_f64().unwrap_or(f64::NAN) + 0.0))
            .collect();
        println!("    [{}]", cells.join(" "));
    }
}

fn print_mueller_tables(v: &Value) {
    println!("Mueller matrices, light frame → camera frame, row-major (s_cam = P·s_light / d²)");
    for key in ["light_frame", "camera_frame"] {
        println!(
            "  {key}: x {} y {} z {}",
            v[key]["x"], v[key]["y"], v[key]["z"]
        );
    }
    println!("  cosθ: {}", v["cos_theta"]);
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

/// The docs plot: diffuse DoP (solid, against exit angle θ_o) and specular DoP = R−/R+ for
/// unpolarised light (dashed, against incidence angle θ_d) for η ∈ {1.3, 1.5, 1.7, 2.3}.
pub fn dop_plot() -> LinePlot {
    let angles: Vec<f64> = (0..=360).map(|k| f64::from(k) * 0.25).collect();
    let mut plot = LinePlot::new("DoP vs angle: diffuse (solid) and specular (dashed)")
        .x_label("angle to normal, deg (diffuse: exit angle; specular: incidence)")
        .y_label("degree of polarisation")
        .legend(LegendPosition::TopLeft)
        .x_range(0.0, 90.0)
        .y_range(0.0, 1.0)
        .size(1100, 720);
    for (k, eta) in [1.3, 1.5, 1.7, 2.3].into_iter().enumerate() {
        let color = PALETTE[k];
        let diffuse = angles
            .iter()
            .map(|&t| (t, dop_diffuse_with_d_eta(t.to_radians().cos(), eta).0));
        plot = plot.series_styled(
            format!("diffuse  eta {eta}"),
            diffuse,
            Stroke::solid(color, 3),
        );
        let specular = angles.iter().map(|&t| {
            let f = FresnelTerms::dielectric(t.to_radians().cos(), eta);
            let r = f.r_plus();
            (t, if r > 0.0 { f.r_minus().abs() / r } else { 0.0 })
        });
        plot = plot.series_styled(
            format!("specular eta {eta}"),
            specular,
            Stroke {
                color,
                thickness: 2,
                dash: Some((10.0, 6.0)),
            },
        );
    }
    plot
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

    #[test]
    fn fresnel_json_reproduces_the_reference_table() {
        // optics.md §10.1, η = 1.5, θ = 60°.
        let v = fresnel_json(1.5, 60.0).unwrap();
        let want = [
            ("rs", -0.420204),
            ("rp", -0.042449),
            ("r_plus", 0.089187),
            ("r_minus", 0.087385),
            ("r_cross", 0.017837),
            ("t_plus", 0.910813),
            ("t_minus", -0.087385),
        ];
        for (k, w) in want {
            let got = v[k].as_f64().unwrap();
            assert!((got - w).abs() < 6e-7, "{k}: {got} vs {w}");
        }
        assert_eq!(v.as_object().unwrap().len(), 7);
    }

    #[test]
    fn dop_json_matches_table_and_bad_flags_are_named() {
        let v = dop_json(1.5, 45.0).unwrap();
        assert!((v["dop"].as_f64().unwrap() - 0.043983).abs() < 1e-6);
        assert!(v["d_dop_d_eta"].as_f64().unwrap() > 0.0);
        assert!(
            dop_json(0.9, 45.0)
                .unwrap_err()
                .to_string()
                .contains("--eta")
        );
        assert!(
            fresnel_json(1.5, 91.0)
                .unwrap_err()
                .to_string()
                .contains("--theta-deg")
        );
        assert!(
            fresnel_json(f64::NAN, 10.0)
                .unwrap_err()
                .to_string()
                .contains("--eta")
        );
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
    fn mueller_json_has_the_documented_shape_and_physics() {
        let v = mueller_json(&mueller_args(&[]).unwrap()).unwrap();
        assert_eq!(v["diffuse"].as_array().unwrap().len(), 3);
        assert_eq!(v["specular"].as_array().unwrap().len(), 4);
        assert_eq!(v["single_scattering"][2][3].as_array().unwrap().len(), 4);
        let m00 = |key: &str, c: usize| v[key][c][0][0].as_f64().unwrap();
        let total: f64 =
            m00("diffuse", 0) + v["specular"][0][0].as_f64().unwrap() + m00("single_scattering", 0);
        assert!((m00("total", 0) - total).abs() < 1e-12);
        assert!(m00("diffuse", 0) > m00("diffuse", 2), "ρ_d is coloured");
    }

    #[test]
    fn mueller_bad_input_names_the_flag() {
        let err = |extra: &[&str]| -> String {
            match mueller_args(extra) {
                Err(e) => e.to_string(),
                Ok(a) => mueller_json(&a).unwrap_err().to_string(),
            }
        };
        assert!(err(&["--normal", "0,0,0"]).contains("--normal"));
        assert!(err(&["--to-light", "nan,0,1"]).contains("--to-light"));
        assert!(err(&["--to-camera", "1,2"]).contains("--to-camera"));
        assert!(err(&["--eta", "0.5"]).contains("--eta"));
        assert!(err(&["--sigma-s", "1.5"]).contains("--sigma-s"));
        assert!(err(&["--sigma-s", "0.6"]).contains("--sigma-ss"));
        assert!(err(&["--rho-d", "0.1,-1,0"]).contains("--rho-d"));
    }

    #[test]
    fn dop_plot_renders() {
        let c = dop_plot().render().unwrap();
        assert_eq!((c.width(), c.height()), (1100, 720));
    }
}
