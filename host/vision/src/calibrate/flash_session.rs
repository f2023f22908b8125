//! The flash measured from a recorded session's sphere frames, as `ellipso calibrate flash` (and
//! `ellipso calibrate --sphere`) does it: per calibrated view the highlight
//! ([`super::highlight`]) and its polarisation ([`super::flash_polariser`]); over the views the
//! flash position ([`super::flash`]) and then the polariser angle, each view's reading
//! corrected by the model for its highlight's place and the estimated flash; the rig file's
//! `[flash]` table; and that table put into an existing rig file without touching its other
//! tables ([`replace_flash_section`]).

use ellipso_model::camera::{CameraModel, Pose};
use ellipso_polar::frame::RawFrame;

use super::flash::{
    FlashError, FlashEstimate, HighlightObservation, estimate_flash_position, sphere_point,
};
use super::flash_polariser::{
    HighlightStokes, PolariserError, PolariserEstimate, estimate_polariser_angle_corrected,
    highlight_stokes, stokes_config, window_radius_px,
};
use super::highlight::{HighlightConfig, Sphere, find_highlight};

/// One view's highlight: where it is (for the position) and its Stokes sum (for the angle).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ViewHighlight {
    /// The highlight and its view's geometry.
    pub observation: HighlightObservation,
    /// Its summed Stokes vector.
    pub stokes: HighlightStokes,
}

/// The highlight of `sphere` (centre in the world frame) in `raw`, seen from
/// `camera_from_board` with `world_from_board` (the board the view's pose is of), or why the
/// frame gives none, in words.
pub fn view_highlight(
    raw: &RawFrame,
    camera: &CameraModel,
    camera_from_board: &Pose,
    world_from_board: &Pose,
    sphere: &Sphere,
) -> Result<ViewHighlight, String> {
    let camera_from_world = camera_from_board * world_from_board.inverse();
    let h = find_highlight(
        raw,
        camera,
        &camera_from_world,
        sphere,
        &HighlightConfig::default(),
    )
    .map_err(|e| e.to_string())?;
    let image = ellipso_polar::process(raw, &stokes_config()).map_err(|e| e.to_string())?;
    let stokes = highlight_stokes(
        &image,
        raw.width(),
        h.pixel,
        window_radius_px(h.blob_px, raw.layout().tile_px()),
    )
    .map_err(|e| e.to_string())?;
    Ok(ViewHighlight {
        observation: HighlightObservation {
            camera_from_board: *camera_from_board,
            sphere_centre_board_m: world_from_board.inverse() * sphere.centre_m,
            sphere_radius_m: sphere.radius_m,
            highlight_px: h.pixel,
        },
        stokes,
    })
}

/// Why the flash was not measured.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum FlashMeasureError {
    /// The position could not be estimated.
    #[error(transparent)]
    Position(#[from] FlashError),
    /// The polariser angle could not be estimated.
    #[error(transparent)]
    Polariser(#[from] PolariserError),
}

/// The measured flash.
#[derive(Debug, Clone, PartialEq)]
pub struct FlashMeasurement {
    /// Position in the camera frame.
    pub position: FlashEstimate,
    /// Polariser angle.
    pub polariser: PolariserEstimate,
}

/// The flash from the views' highlights: the position, then the polariser angle with each
/// view corrected for its geometry (see the module doc).
pub fn measure_flash(
    camera: &CameraModel,
    views: &[ViewHighlight],
) -> Result<FlashMeasurement, FlashMeasureError> {
    let observations: Vec<_> = views.iter().map(|v| v.observation).collect();
    let position = estimate_flash_position(camera, &observations)?;
    let points = observations
        .iter()
        .enumerate()
        .map(|(i, o)| sphere_point(camera, i, o))
        .collect::<Result<Vec<_>, _>>()?;
    let stokes: Vec<_> = views.iter().map(|v| v.stokes).collect();
    let polariser = estimate_polariser_angle_corrected(&stokes, &points, &position.flash_camera_m)?;
    Ok(FlashMeasurement {
        position,
        polariser,
    })
}

impl FlashMeasurement {
    /// The rig file's `[flash]` table: `offset_m` (camera frame) and `polariser_deg`, their 1σ
    /// in comments; floats in Rust's shortest round-trip form, so reading it back is exact.
    pub fn to_toml_flash_section(&self) -> String {
        let p = &self.polariser;
        format!(
            "{}# polariser: {} views, 1σ {:.3}° (their scatter), min DoLP {:.2}, largest geometric correction {:.3}°\n\
             polariser_deg = {:?}\n",
            self.position.to_toml_flash_section(),
            p.residuals_deg.len(),
            p.std_deg,
            p.min_dolp,
            p.max_correction_deg,
            p.polariser_deg
        )
    }
}

/// Why a rig file cannot take the `[flash]` table.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum RigTextError {
    /// The existing file is not TOML.
    #[error("not a TOML file (the flash is never written into a file this cannot read): {0}")]
    NotToml(String),
    /// The merge made something that is not TOML (an unusual layout, e.g. `flash.offset_m`
    /// written as a dotted key outside a `[flash]` table).
    #[error(
        "its [flash] table cannot be replaced cleanly ({0}); remove the flash keys from it and run again"
    )]
    Merge(String),
}

/// `existing` (a rig file's text) with its `[flash]` table replaced by `section` — from the
/// `[flash]` header line to the next table header — or, when it has none, `section` appended
/// after a blank line. Every other line is kept as it was, comments included. Both the input
/// and the result must parse as TOML.
pub fn replace_flash_section(existing: &str, section: &str) -> Result<String, RigTextError> {
    toml::from_str::<toml::Table>(existing).map_err(|e| RigTextError::NotToml(e.to_string()))?;
    let is_header = |line: &str| line.trim_start().starts_with('[');
    let is_flash = |line: &str| {
        let t = line.trim_start();
        t.starts_with("[flash]") && !t.starts_with("[flash]]")
    };
    let lines: Vec<&str> = existing.lines().collect();
    let mut out = String::new();
    let mut replaced = false;
    let mut k = 0;
    while k < lines.len() {
        if is_flash(lines[k]) && !replaced {
            out.push_str(section);
            k += 1;
            while k < lines.len() && !is_header(lines[k]) {
                k += 1;
            }
            if k < lines.len() {
                out.push('\n');
            }
            replaced = true;
            continue;
        }
        out.push_str(lines[k]);
        out.push('\n');
        k += 1;
    }
    if !replaced {
        if !out.is_empty() && !out.ends_with("\n\n") {
            out.push('\n');
        }
        out.push_str(section);
    }
    toml::from_str::<toml::Table>(&out).map_err(|e| RigTextError::Merge(e.to_string()))?;
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    const SECTION: &str = "[flash]\noffset_m = [0.004, -0.031, 0.002]\npolariser_deg = 1.5\n";

    #[test]
    fn the_flash_table_is_replaced_and_the_rest_kept() {
        let rig = "# my rig\n[sensor]\nbit_depth = 12 # twelve\n\n[flash]\noffset_m = [0.0, -0.03, 0.0]\n\n[[boards]]\nfile = \"a.toml\"\n";
        let out = replace_flash_section(rig, SECTION).unwrap();
        assert_eq!(
            out,
            "# my rig\n[sensor]\nbit_depth = 12 # twelve\n\n[flash]\noffset_m = [0.004, -0.031, 0.002]\npolariser_deg = 1.5\n\n[[boards]]\nfile = \"a.toml\"\n"
        );
        // no [flash] yet: appended; running twice gives one table
        let rig = "[sensor]\nbit_depth = 12\n";
        let once = replace_flash_section(rig, SECTION).unwrap();
        assert_eq!(once, format!("{rig}\n{SECTION}"));
        assert_eq!(replace_flash_section(&once, SECTION).unwrap(), once);
        assert_eq!(replace_flash_section("", SECTION).unwrap(), SECTION);
    }

    #[test]
    fn a_file_that_is_not_toml_or_cannot_be_merged_is_refused() {
        assert!(matches!(
            replace_flash_section("[sensor\nx = 1\n", SECTION),
            Err(RigTextError::NotToml(_))
        ));
        // a dotted flash key outside a [flash] table would define flash twice
        assert!(matches!(
            replace_flash_section("flash.offset_m = [0.0, 0.0, 0.0]\n", SECTION),
            Err(RigTextError::Merge(_))
        ));
    }
}
