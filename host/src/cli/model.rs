//! `ellipso model …`: inspect the polarimetric model (Fresnel, diffuse DoP, Mueller matrices)
//! and plot the degree of polarisation.
//!
//! Contract: every subcommand validates its flags against documented ranges and reports a bad
//! one in a single error line naming the flag and the range; `--json` prints one JSON object on
//! stdout, otherwise readable tables. Ranges (the scene files' where they have one):
//! η ∈ [1, 5]; θ ∈ [0°, 90°]; σ_s, σ_ss ∈ [0, 1] with σ_s ≤ σ_ss; ρ_s and each ρ_ss ∈ [0, 1000];
//! each ρ_d ∈ [0, 1]; direction vectors finite and non-zero, of any length (they are normalised
//! after scaling by their largest component, so 1e-300 and 1e300 both work). A result that is
//! not finite anyway is an error, never printed. The
//! numbers come from `ellipso_model::optics`, the same code the simulator and the fit use.
//! Frames of `mueller`: light frame z = −to_light, camera frame z = to_camera, y = the given up
//! vector (default world +y) orthogonalised against z, x = y × z; when the up vector is parallel
//! to z the world axis least aligned with z is used instead.

use std::path::PathBuf;

use anyhow::{Context, Result, bail};
use ellipso_model::optics::fresnel::brewster_angle_rad;
use ellipso_model::optics::measure::dop_diffuse_with_d_eta;
use ellipso_model::optics::pbrdf::{Geometry, PbrdfParams, evaluate};
use ellipso_model::optics::{Frame, FresnelTerms, Mueller, Vec3};
use serde_json::{Value, json};

use ellipso_report::{LegendPosition, LinePlot, Stroke, plot::PALETTE};

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
            let v = fresnel_json(a.eta, a.theta_deg)?;
            if a.json {
                crate::outln!("{v}");
            } else {
                crate::outln!(
                    "Fresnel, dielectric η = {} at θ = {}° (Brewster {:.4}°)",
                    a.eta,
                    a.theta_deg,
                    brewster_angle_rad(a.eta).to_degrees()
                );
                for key in [
                    "rs", "rp", "r_plus", "r_minus", "r_cross", "t_plus", "t_minus",
                ] {
                    crate::outln!("  {key:<8} {:>12.6}", v[key].as_f64().unwrap_or(f64::NAN));
                }
            }
        }
        ModelCommand::Dop(a) => {
            let v = dop_json(a.eta, a.theta_deg)?;
            if a.json {
                crate::outln!("{v}");
            } else {
                crate::outln!("Diffuse DoP at η = {}, θ_o = {}°", a.eta, a.theta_deg);
                crate::outln!(
                    "  dop        {:>12.6}",
                    v["dop"].as_f64().unwrap_or(f64::NAN)
                );
                crate::outln!(
                    "  d_dop_d_eta {:>11.6}",
                    v["d_dop_d_eta"].as_f64().unwrap_or(f64::NAN)
                );
            }
        }
        ModelCommand::Mueller(a) => {
            let v = mueller_json(&a)?;
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
            dop_plot()
                .save_png(out.path())
                .with_context(|| format!("--out {}", a.out.display()))?;
            crate::outln!("wrote {}", a.out.display());
        }
    }
    Ok(())
}

/// Largest refractive index (the scene files' limit: no dielectric exceeds it).
pub const MAX_ETA: f64 = 5.0;
/// Largest specular and single-scattering albedo (the scene files' limit).
pub const MAX_LOBE_ALBEDO: f64 = ellipso_sim::scene::spec::MAX_LOBE_ALBEDO;

fn check_eta(eta: f64) -> Result<()> {
    if !(1.0..=MAX_ETA).contains(&eta) {
        bail!(
            "--eta must be in [1, {MAX_ETA}] (a dielectric in air; none exceeds {MAX_ETA}), got {eta}"
        );
    }
    Ok(())
}

/// Every number of `v` is finite (serde_json writes NaN and ±inf as null).
fn check_finite(v: &Value) -> Result<()> {
    let ok = match v {
        Value::Null => false,
        Value::Array(a) => return a.iter().try_for_each(check_finite),
        Value::Object(o) => return o.values().try_for_each(check_finite),
        _ => true,
    };
    if !ok {
        bail!("the model has no finite value for these inputs");
    }
    Ok(())
}

/// A direction flag: finite, non-zero, any length; normalised after scaling by the largest
/// component so neither 1e300 nor 1e-300 overflows.
fn direction(flag: &str, v: [f64; 3]) -> Result<Vec3<f64>> {
    let largest = v.iter().fold(0.0_f64, |m, x| m.max(x.abs()));
    if !largest.is_finite() {
        bail!("{flag} must be finite, got {v:?}");
    }
    if largest == 0.0 {
        bail!("{flag} must be a non-zero vector, got {v:?}");
    }
    Vec3::from_f64(v.map(|x| x / largest))
        .normalized_or_none(1e-24)
        .with_context(|| format!("{flag} must be a non-zero vector, got {v:?}"))
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
    let v = json!({
        "rs": f.r_s, "rp": f.r_p, "r_plus": f.r_plus(), "r_minus": f.r_minus(),
        "r_cross": f.r_cross(), "t_plus": f.t_plus(), "t_minus": f.t_minus(),
    });
    check_finite(&v)?;
    Ok(v)
}

/// `ellipso model dop --json`: {"dop", "d_dop_d_eta"}.
pub fn dop_json(eta: f64, theta_deg: f64) -> Result<Value> {
    check_eta(eta)?;
    check_theta(theta_deg)?;
    let (dop, d) = dop_diffuse_with_d_eta(theta_deg.to_radians().cos(), eta);
    let v = json!({ "dop": dop, "d_dop_d_eta": d });
    check_finite(&v)?;
    Ok(v)
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
    if !(a.rho_s >= 0.0 && a.rho_s <= MAX_LOBE_ALBEDO) {
        bail!("--rho-s must be in [0, {MAX_LOBE_ALBEDO}], got {}", a.rho_s);
    }
    for (flag, v, max) in [
        ("--rho-ss", a.rho_ss, MAX_LOBE_ALBEDO),
        ("--rho-d", a.rho_d, 1.0),
    ] {
        if v.iter().any(|x| !(*x >= 0.0 && *x <= max)) {
            bail!("{flag} components must be in [0, {max}], got {v:?}");
        }
    }
    let normal = direction("--normal", a.normal)?;
    let to_light = direction("--to-light", a.to_light)?;
    let to_camera = direction("--to-camera", a.to_camera)?;
    let default_up = [0.0, 1.0, 0.0];
    let light_up = direction("--light-up", a.light_up.unwrap_or(default_up))?;
    let camera_up = direction("--camera-up", a.camera_up.unwrap_or(default_up))?;
    let light_frame = Frame::light(to_light, light_up)?;
    let camera_frame = Frame::camera(to_camera, camera_up)?;
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
    let v = json!({
        "diffuse": lobes.diffuse.iter().map(matrix_json).collect::<Vec<_>>(),
        "specular": matrix_json(&lobes.specular),
        "single_scattering": lobes.single_scattering.iter().map(matrix_json).collect::<Vec<_>>(),
        "total": (0..3).map(|c| matrix_json(&lobes.total(c))).collect::<Vec<_>>(),
        "light_frame": frame(&g.light_frame),
        "camera_frame": frame(&g.camera_frame),
        "cos_theta": { "i": g.cos_theta_i, "o": g.cos_theta_o, "h": g.cos_theta_h, "d": g.cos_theta_d },
        "front_facing": g.front_facing,
    });
    check_finite(&v)?;
    Ok(v)
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

/// The docs plot: diffuse DoP (solid, against exit angle θ_o) and specular DoP = R−/R+ for
/// unpolarised light (dashed, against incidence angle θ_d) for η ∈ {1.3, 1.5, 1.7, 2.3}.
pub fn dop_plot() -> LinePlot {
    let angles: Vec<f64> = (0..=360).map(|k| f64::from(k) * 0.25).collect();
    let mut plot = LinePlot::new("DoP vs angle: diffuse (solid) and specular (dashed)")
        .x_label("angle to the normal (°; diffuse: exit angle θo, specular: incidence angle θd)")
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
            format!("diffuse, η = {eta}"),
            diffuse,
            Stroke::solid(color, 3),
        );
        let specular = angles.iter().map(|&t| {
            let f = FresnelTerms::dielectric(t.to_radians().cos(), eta);
            let r = f.r_plus();
            (t, if r > 0.0 { f.r_minus().abs() / r } else { 0.0 })
        });
        plot = plot.series_styled(
            format!("specular, η = {eta}"),
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
        // docs/model.md §8 "Fresnel and diffuse DoP values", η = 1.5, θ = 60°.
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
        // absurd magnitudes: refused with the range, never NaN
        let with = |f: &dyn Fn(&mut MuellerArgs)| {
            let mut a = mueller_args(&[]).unwrap();
            f(&mut a);
            mueller_json(&a)
        };
        let msg = |r: Result<Value>| r.unwrap_err().to_string();
        assert!(msg(with(&|a| a.eta = 1e200)).contains("[1, 5]"));
        assert!(msg(with(&|a| a.rho_s = 1e308)).contains("--rho-s must be in [0, 1000]"));
        assert!(msg(with(&|a| a.rho_ss[1] = 1e308)).contains("--rho-ss"));
        assert!(msg(with(&|a| a.rho_d = [0.1, 2.0, 0.0])).contains("--rho-d"));
        assert!(msg(with(&|a| a.light_up = Some([0.0; 3]))).contains("--light-up"));
        // a huge or tiny but valid direction is a direction
        for n in [[0.0, 0.0, 1e300], [0.0, 0.0, 1e-300], [1e300, 0.0, 1e300]] {
            let v = with(&|a| a.normal = n).unwrap_or_else(|e| panic!("{n:?}: {e}"));
            check_finite(&v).unwrap();
        }
    }

    #[test]
    fn absurd_eta_is_refused_not_nan() {
        for eta in [1e78, 1e155, 5.000_001, f64::INFINITY] {
            assert!(
                dop_json(eta, 30.0)
                    .unwrap_err()
                    .to_string()
                    .contains("[1, 5]")
            );
            assert!(
                fresnel_json(eta, 30.0)
                    .unwrap_err()
                    .to_string()
                    .contains("[1, 5]")
            );
        }
        for theta in [0.0, 30.0, 89.999, 90.0] {
            check_finite(&dop_json(5.0, theta).unwrap()).unwrap();
            check_finite(&fresnel_json(5.0, theta).unwrap()).unwrap();
        }
    }

    #[test]
    fn dop_plot_renders() {
        let c = dop_plot().render().unwrap();
        assert_eq!((c.width(), c.height()), (1100, 720));
    }
}
