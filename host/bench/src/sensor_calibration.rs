//! `ellipso bench sensor`: the sensor calibration loop on simulated captures —
//! render the calibration captures of a real sensor (every fixed-pattern effect at realistic
//! magnitudes), measure them as `ellipso calibrate sensor` does, compare what was recovered
//! with what the simulator put in, and check `ellipso polar` with the calibration against the
//! ideal sensor on a rendered object frame; `ellipso calibrate flash` on a simulated sphere
//! capture against the simulator's flash ([`flash`]). Writes `docs/sensor-calibration.json` and the
//! measured table of `docs/sensor-calibration.md` (between its markers).
//!
//! Contract: the scene is the demo's (its camera, gain, lens) with the effects of
//! [`REAL_SENSOR_EFFECTS`] and cos⁴ vignetting, rendered at [`RESOLUTION`]; everything is seeded,
//! so the report is a pure function of the build. Keys the loop does not reach yet are written
//! as `null` with the reason in `not_measured`.

pub mod eta_shift;
pub mod flash;
mod pixel_truth;

use std::path::{Path, PathBuf};

use crate::table::{self, Align::Left as L};
use ellipso_polar::sensor_calibration::{
    MeasureOptions, SensorCalibration, SensorFigures, measure,
};
use ellipso_polar::{PolarConfig, RawFrame, process, process_with_sensor};
use ellipso_run_error::{Context, RunError, Say, say};
use ellipso_sim::calibration_captures::{self, CapturePlan};
use ellipso_sim::render::{RenderOptions, Renderer};
use ellipso_sim::scene::Scene;
use serde::Serialize;

/// The sensor effects of a real IMX250MYR-class camera, as scene `[effects]` lines (magnitudes
/// and their sources: docs/sensor-calibration.md, "Magnitudes").
pub const REAL_SENSOR_EFFECTS: &str = "black_level = { dn = 64.0, dsnu_dn = 1.5 }\n\
prnu = { sigma_rel = 0.008 }\n\
analyser_errors = { angle_sigma_deg = 1.0, extinction_ratio_rgb = [150.0, 250.0, 80.0], extinction_sigma_rel = 0.1 }\n\
hot_pixels = { fraction = 0.0001, dn = 200.0 }\n\
vignetting = { exponent = 4.0 }\n";

/// The resolution the bench renders at (a quarter of the demo camera's sides).
pub const RESOLUTION: [u32; 2] = [612, 512];

/// Views of the demo's path the end-to-end fits use by default ([`eta_shift`]): enough for
/// every material to be seen from several sides, few enough for three fits on a laptop.
pub const ETA_SHIFT_PHOTOS: usize = 48;

/// What the bench recovered, under the keys.
#[derive(Debug, Clone, Serialize)]
pub struct Recovered {
    /// |K̂ / K − 1|.
    pub gain_rel_err: f64,
    /// |σ̂ / σ − 1| of the read noise in electrons.
    pub read_noise_rel_err: f64,
    /// |black level − truth|, DN (truth: mean offset of the non-hot pixels).
    pub black_level_err_dn: f64,
    /// RMS over the pixels of the per-pixel analyser angle error, degrees.
    pub analyser_angle_rms_deg: f64,
    /// Largest |ÊR / ER − 1| over the colour bands.
    pub extinction_rel_err: f64,
    /// Largest relative error of the vignetting factor over the frame.
    pub vignetting_err: f64,
    /// |flash offset estimated by `calibrate flash` − the simulator's|, mm ([`flash`]).
    pub flash_position_err_mm: Option<f64>,
    /// |flash polariser angle estimated − the simulator's|, degrees ([`flash`]).
    pub flash_polariser_angle_err_deg: Option<f64>,
    /// Largest per-material η change (percentage points of the true η) between the effects
    /// capture fitted with its calibration and the ideal sensor's capture ([`eta_shift`]).
    pub eta_shift_calibrated_points_max: Option<f64>,
    /// The same, the effects capture read as an ideal sensor's (no calibration).
    pub eta_shift_uncalibrated_points_max: Option<f64>,
    /// 95th percentile over the vertices of the change of their refined normals with the
    /// calibration, degrees.
    pub normal_shift_calibrated_deg_p95: Option<f64>,
    /// The largest such change, degrees.
    pub normal_shift_calibrated_deg_max: Option<f64>,
    /// The 95th percentile without the calibration, degrees.
    pub normal_shift_uncalibrated_deg_p95: Option<f64>,
    /// Views per session of those fits.
    pub eta_shift_photos: Option<usize>,
    /// Largest |s − s_ideal| (s0, s1, s2, normalised) over the lit superpixels of an object frame,
    /// calibrated.
    pub stokes_max_err_calibrated: f64,
    /// RMS of the same, calibrated.
    pub stokes_rms_err_calibrated: f64,
    /// RMS of the same through the ideal formulas (black level subtracted, nothing else).
    pub stokes_rms_err_uncalibrated: f64,
}

/// The whole report.
#[derive(Debug, Clone, Serialize)]
pub struct Report {
    /// The keys and the Stokes check.
    pub recovered: Recovered,
    /// Truth and estimate of each figure.
    pub figures: Vec<(String, f64, f64)>,
    /// Why some keys are null.
    pub not_measured: Vec<String>,
    /// The command that measured it.
    pub command: String,
}

/// The demo scene with the real sensor's effects (`extra` appended to `[effects]`); `noise`:
/// keep shot and read noise. The demo's global `polariser_extinction` is dropped: the ideal
/// sensor has ideal analysers, and `analyser_errors` gives every pixel its own extinction.
pub fn demo_with(extra: &str, noise: bool) -> Result<Scene, RunError> {
    let path = ellipso_sim::scene::shipped_scene("demo.toml");
    let text = std::fs::read_to_string(&path).with_context(|| path.display().to_string())?;
    let mut text = text
        .replace("polariser_extinction = { ratio = 300.0 }\n", "")
        .replace("[effects]", &format!("[effects]\n{extra}"));
    if !noise {
        text = text
            .replace("shot_noise = {}\n", "")
            .replace("read_noise = { sigma_e = 2.3 }\n", "");
    }
    Scene::from_toml_str(&text, &path).map_err(|e| RunError::msg(e.to_string()))
}

pub(crate) fn options(resolution: [u32; 2]) -> RenderOptions {
    RenderOptions {
        supersampling: 1,
        resolution_px: Some(resolution),
        ..RenderOptions::default()
    }
}

/// The default capture plan scaled to where `scene`'s camera saturates: the plan's levels are
/// fractions of the full well, and at a gain above 0 dB the ADC's full scale is reached first
/// (the demo's 6 dB: 4095 DN at 0.78 DN/e⁻ is 5 260 e⁻ of a 10 500 e⁻ well), so the brightest
/// flat sits at 70 % and the sheet at 60 % of the signal that clips, whichever clips first.
pub fn capture_plan(scene: &Scene) -> Result<CapturePlan, RunError> {
    let r = Renderer::new(scene, options([4, 4])).map_err(|e| RunError::msg(e.to_string()))?;
    let rad = r.radiometry();
    let clip_e = rad
        .full_well_e()
        .min(rad.full_scale_dn() / rad.dn_per_electron());
    let fraction = clip_e / rad.full_well_e();
    let plan = CapturePlan::default();
    Ok(CapturePlan {
        full_level_rel: plan.full_level_rel * fraction,
        polariser_level_rel: plan.polariser_level_rel * fraction,
        ..plan
    })
}

/// Measures the calibration of `scene`'s sensor from its simulated captures written to `work`.
pub fn calibrate(
    scene: &Scene,
    resolution: [u32; 2],
    work: &Path,
) -> Result<SensorCalibration, RunError> {
    let captures = calibration_captures::render(scene, &capture_plan(scene)?, options(resolution))
        .map_err(|e| RunError::msg(e.to_string()))?;
    calibration_captures::write(&captures, work).map_err(|e| RunError::msg(e.to_string()))?;
    measure(work, &captures.set, MeasureOptions::default())
        .map_err(|e| RunError::msg(e.to_string()))
}

/// Stokes errors of frame 0 of `effects` (calibrated with `cal`, and through the ideal formulas
/// with the black level subtracted) against the same frame of `ideal`: (max, rms) calibrated,
/// rms uncalibrated, over valid superpixels with s0 ≥ 0.1 and a consistency residual below
/// 2e-3 (a uniform block) in the ideal frame. Both are
/// compared in the ideal frame's units: polar normalises by the range above the dark level,
/// which a black level shortens (4031 instead of 4095 DN at 64 DN), so each image is first
/// taken back to DN above dark.
pub fn stokes_check(
    effects: &Scene,
    ideal: &Scene,
    cal: &SensorCalibration,
    resolution: [u32; 2],
) -> Result<(f64, f64, f64), RunError> {
    let frame = |scene: &Scene| -> Result<RawFrame, RunError> {
        let r =
            Renderer::new(scene, options(resolution)).map_err(|e| RunError::msg(e.to_string()))?;
        let f = r
            .render_frame(0)
            .map_err(|e| RunError::msg(e.to_string()))?;
        RawFrame::new(
            f.width,
            f.height,
            scene.rig.camera.bit_depth,
            r.layout(),
            f.raw(),
        )
        .map_err(|e| RunError::msg(e.to_string()))
    };
    let (fe, fi) = (frame(effects)?, frame(ideal)?);
    let truth = process(&fi, &PolarConfig::default()).map_err(|e| RunError::msg(e.to_string()))?;
    let calibrated = process_with_sensor(&fe, &PolarConfig::default(), cal)
        .map_err(|e| RunError::msg(e.to_string()))?;
    let plain = PolarConfig {
        dark_level_dn: cal.header.figures.black_level_dn as f32,
        ..PolarConfig::default()
    };
    let uncalibrated = process(&fe, &plain).map_err(|e| RunError::msg(e.to_string()))?;
    let to_ideal = |img: &ellipso_polar::PolarImage| {
        f64::from(truth.levels.scale_per_dn()) / f64::from(img.levels.scale_per_dn())
    };
    let (kc, ku) = (to_ideal(&calibrated), to_ideal(&uncalibrated));
    let (mut max, mut sum2, mut sum2u, mut n) = (0.0f64, 0.0f64, 0.0f64, 0.0f64);
    for ((t, c), u) in truth
        .bands
        .iter()
        .zip(&calibrated.bands)
        .zip(&uncalibrated.bands)
    {
        for i in 0..t.s0.data().len() {
            // a superpixel whose four raw pixels did not see one Stokes vector (an edge or a
            // steep gradient inside the 2×2 block: ideal-sensor residual above 8 quantisation
            // steps, 8/4095 ≈ 2e-3) has no single right answer: any two estimators disagree there
            let uniform = t.residual.data()[i].abs() < 2e-3;
            if t.s0.data()[i] < 0.1
                || !uniform
                || !t.mask.data()[i].is_valid()
                || !c.mask.data()[i].is_valid()
            {
                continue;
            }
            for (pt, pc, pu) in [
                (&t.s0, &c.s0, &u.s0),
                (&t.s1, &c.s1, &u.s1),
                (&t.s2, &c.s2, &u.s2),
            ] {
                let e = kc * f64::from(pc.data()[i]) - f64::from(pt.data()[i]);
                let eu = ku * f64::from(pu.data()[i]) - f64::from(pt.data()[i]);
                max = max.max(e.abs());
                sum2 += e * e;
                sum2u += eu * eu;
                n += 1.0;
            }
        }
    }
    let n = n.max(1.0);
    Ok((max, (sum2 / n).sqrt(), (sum2u / n).sqrt()))
}

/// Runs the bench; writes `out/sensor-calibration.json` and updates `out/sensor-calibration.md`.
pub fn run(out: &Path, work: &Path, photos: usize, say: &dyn Say) -> Result<Report, RunError> {
    let scene = demo_with(REAL_SENSOR_EFFECTS, true)?;
    let resolution = RESOLUTION;
    say!(
        say,
        "rendering and measuring the calibration captures at {}×{}",
        resolution[0],
        resolution[1]
    );
    let cal = calibrate(&scene, resolution, &work.join("captures"))?;
    let f = &cal.header.figures;
    let truth = pixel_truth::read(&scene, &cal, resolution)?;
    let (k_true, black_true, er_true) = (truth.k_true, truth.black_true, &truth.er_true);
    let sigma_true = 2.3;
    let extinction_rel_err = er_true
        .iter()
        .zip(&f.extinction_ratio)
        .map(|(t, e)| (e / t - 1.0).abs())
        .fold(0.0, f64::max);
    say!(
        say,
        "rendering an object frame with and without the effects"
    );
    let effects_clean = demo_with(REAL_SENSOR_EFFECTS, false)?;
    let ideal = demo_with("vignetting = { exponent = 4.0 }\n", false)?;
    let (smax, srms, srms_u) = stokes_check(&effects_clean, &ideal, &cal, resolution)?;
    let flash = flash::run(&work.join("flash"), say)?;
    say!(
        say,
        "  flash: offset error {:.3} mm (1σ {:.3?} mm), polariser error {:.3}° (1σ {:.3}°) from {} highlights",
        flash.position_err_mm,
        flash.position_std_mm,
        flash.polariser_err_deg,
        flash.polariser_std_deg,
        flash.highlights
    );
    let shift = eta_shift_fits(&cal, resolution, photos, work, say)?;
    let recovered = Recovered {
        gain_rel_err: (f.gain_dn_per_e / k_true - 1.0).abs(),
        read_noise_rel_err: (f.read_noise_e / sigma_true - 1.0).abs(),
        black_level_err_dn: (f.black_level_dn - black_true).abs(),
        analyser_angle_rms_deg: truth.analyser_angle_rms_deg,
        extinction_rel_err,
        vignetting_err: truth.vignetting_err,
        flash_position_err_mm: Some(flash.position_err_mm),
        flash_polariser_angle_err_deg: Some(flash.polariser_err_deg),
        eta_shift_calibrated_points_max: shift.as_ref().map(|s| s.calibrated_points_max),
        eta_shift_uncalibrated_points_max: shift.as_ref().map(|s| s.uncalibrated_points_max),
        normal_shift_calibrated_deg_p95: shift.as_ref().map(|s| s.normals_calibrated.p95_deg),
        normal_shift_calibrated_deg_max: shift.as_ref().map(|s| s.normals_calibrated.max_deg),
        normal_shift_uncalibrated_deg_p95: shift.as_ref().map(|s| s.normals_uncalibrated.p95_deg),
        eta_shift_photos: shift.as_ref().map(|s| s.photos),
        stokes_max_err_calibrated: smax,
        stokes_rms_err_calibrated: srms,
        stokes_rms_err_uncalibrated: srms_u,
    };
    let figures = figures(&truth, f, sigma_true, &flash);
    let report = Report {
        recovered,
        figures,
        not_measured: shift
            .is_none()
            .then(|| {
                "eta_shift_calibrated_points_max: the end-to-end fits were skipped (--photos 0)"
                    .to_string()
            })
            .into_iter()
            .collect(),
        command: "ellipso bench sensor".into(),
    };
    write_report(out, &report)?;
    Ok(report)
}

/// The end-to-end fits of [`eta_shift`] on `photos` views (none when `photos` is 0), each
/// material's η errors said.
fn eta_shift_fits(
    cal: &SensorCalibration,
    resolution: [u32; 2],
    photos: usize,
    work: &Path,
    say: &dyn Say,
) -> Result<Option<eta_shift::EtaShift>, RunError> {
    Ok(if photos > 0 {
        say!(
            say,
            "fitting the demo captured with and without the effects ({photos} views, {}×{})",
            resolution[0],
            resolution[1]
        );
        let s = eta_shift::run(cal, resolution, photos, &work.join("fits"), say)?;
        for (name, ideal, c, u) in &s.materials {
            say!(
                say,
                "  {name}: η error {ideal:+.3} % ideal sensor, {c:+.3} % calibrated, {u:+.3} % uncalibrated"
            );
        }
        Some(s)
    } else {
        None
    })
}

/// Truth and estimate of each figure: the sensor's (`sigma_true`: the true read noise,
/// electrons), the flash's and each colour band's extinction ratio.
fn figures(
    truth: &pixel_truth::PixelTruth,
    f: &SensorFigures,
    sigma_true: f64,
    flash: &flash::FlashRecovered,
) -> Vec<(String, f64, f64)> {
    let (k_true, black_true, er_true) = (truth.k_true, truth.black_true, &truth.er_true);
    let mut figures = vec![
        ("gain_dn_per_e".to_string(), k_true, f.gain_dn_per_e),
        ("read_noise_e".into(), sigma_true, f.read_noise_e),
        ("black_level_dn".into(), black_true, f.black_level_dn),
        ("dsnu_dn".into(), 1.5, f.dsnu_dn),
        ("prnu_rel".into(), 0.008, f.prnu_rel),
        ("vignetting_exponent".into(), 4.0, f.vignetting_exponent),
        (
            "hot_pixels_fraction".into(),
            1e-4,
            f.hot_pixels as f64 / f64::from(truth.pixels),
        ),
    ];
    for (k, axis) in ["x", "y", "z"].iter().enumerate() {
        figures.push((
            format!("flash_offset_{axis}_mm"),
            flash.offset_mm.0[k],
            flash.offset_mm.1[k],
        ));
    }
    figures.push((
        "flash_polariser_deg".into(),
        flash.polariser_deg.0,
        flash.polariser_deg.1,
    ));
    for (b, (t, e)) in er_true.iter().zip(&f.extinction_ratio).enumerate() {
        figures.push((format!("extinction_ratio_{}", ["R", "G", "B"][b]), *t, *e));
    }
    figures
}

fn write_report(out: &Path, report: &Report) -> Result<(), RunError> {
    let json_path = out.join("sensor-calibration.json");
    let mut json =
        serde_json::to_value(&report.recovered).map_err(|e| RunError::msg(e.to_string()))?;
    if let Some(o) = json.as_object_mut() {
        o.insert(
            "figures".into(),
            serde_json::to_value(&report.figures).unwrap_or_default(),
        );
        o.insert(
            "not_measured".into(),
            serde_json::to_value(&report.not_measured).unwrap_or_default(),
        );
        o.insert("command".into(), report.command.clone().into());
    }
    let text = serde_json::to_string_pretty(&json).map_err(|e| RunError::msg(e.to_string()))?;
    ellipso_report::atomic_file::write(&json_path, text + "\n")
        .with_context(|| json_path.display().to_string())?;
    let md_path = out.join("sensor-calibration.md");
    let table = markdown_table(report);
    let md = std::fs::read_to_string(&md_path).unwrap_or_default();
    let (begin, end) = ("<!-- bench:begin -->", "<!-- bench:end -->");
    let md = match (md.find(begin), md.find(end)) {
        (Some(a), Some(b)) if a < b => format!("{}{begin}\n{table}{}", &md[..a], &md[b..]),
        _ => format!("{md}\n## Measured\n\n{begin}\n{table}{end}\n"),
    };
    ellipso_report::atomic_file::write(&md_path, md)
        .with_context(|| md_path.display().to_string())?;
    Ok(())
}

fn markdown_table(report: &Report) -> String {
    use std::fmt::Write;
    let r = &report.recovered;
    let mut s = String::new();
    let _ = writeln!(
        s,
        "Measured by `{}` (demo camera at {}×{}, effects of `REAL_SENSOR_EFFECTS`; the flash \
         from {} photos of the glossy sphere at {}×{}{}).\n",
        report.command,
        RESOLUTION[0],
        RESOLUTION[1],
        flash::PHOTOS,
        flash::RESOLUTION[0],
        flash::RESOLUTION[1],
        r.eta_shift_photos
            .map_or(String::new(), |n| format!("; end-to-end fits on {n} views"))
    );
    let _ = writeln!(
        s,
        "{}",
        table::head(&[("key", L), ("recovered", L), ("target", L)])
    );
    let opt = |v: Option<f64>| v.map_or("not measured".to_string(), |v| format!("{v:.4}"));
    for (k, v, t) in [
        ("gain_rel_err", format!("{:.4}", r.gain_rel_err), "≤ 0.02"),
        (
            "read_noise_rel_err",
            format!("{:.4}", r.read_noise_rel_err),
            "≤ 0.02",
        ),
        (
            "black_level_err_dn",
            format!("{:.4}", r.black_level_err_dn),
            "≤ 0.5",
        ),
        (
            "analyser_angle_rms_deg",
            format!("{:.4}", r.analyser_angle_rms_deg),
            "≤ 0.2",
        ),
        (
            "extinction_rel_err",
            format!("{:.4}", r.extinction_rel_err),
            "≤ 0.10",
        ),
        (
            "vignetting_err",
            format!("{:.4}", r.vignetting_err),
            "≤ 0.01",
        ),
        ("flash_position_err_mm", opt(r.flash_position_err_mm), "≤ 1"),
        (
            "flash_polariser_angle_err_deg",
            opt(r.flash_polariser_angle_err_deg),
            "≤ 0.5",
        ),
        (
            "eta_shift_calibrated_points_max",
            opt(r.eta_shift_calibrated_points_max),
            "≤ 0.1",
        ),
        (
            "eta_shift_uncalibrated_points_max",
            opt(r.eta_shift_uncalibrated_points_max),
            "",
        ),
        (
            "normal_shift_calibrated_deg_p95",
            opt(r.normal_shift_calibrated_deg_p95),
            "≤ 0.1",
        ),
        (
            "normal_shift_calibrated_deg_max",
            opt(r.normal_shift_calibrated_deg_max),
            "",
        ),
        (
            "normal_shift_uncalibrated_deg_p95",
            opt(r.normal_shift_uncalibrated_deg_p95),
            "",
        ),
        (
            "stokes_max_err_calibrated",
            format!("{:.2e}", r.stokes_max_err_calibrated),
            "≤ 1e-3",
        ),
        (
            "stokes_rms_err_calibrated",
            format!("{:.2e}", r.stokes_rms_err_calibrated),
            "",
        ),
        (
            "stokes_rms_err_uncalibrated",
            format!("{:.2e}", r.stokes_rms_err_uncalibrated),
            "",
        ),
    ] {
        let _ = writeln!(s, "| `{k}` | {v} | {t} |");
    }
    let _ = writeln!(
        s,
        "\n{}",
        table::head(&[("figure", L), ("simulator", L), ("calibration", L)])
    );
    for (name, t, e) in &report.figures {
        let _ = writeln!(s, "| {name} | {t:.5} | {e:.5} |");
    }
    for n in &report.not_measured {
        let _ = writeln!(s, "\n- not measured: {n}");
    }
    s
}

/// The default report folder (`docs/` of the repository the binary runs in).
pub fn default_out() -> PathBuf {
    PathBuf::from("docs")
}
