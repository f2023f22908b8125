//! The fit's pictures, rendered from the fitted model through the same optics the simulator
//! renders with (`ellipso_model::optics`).
//!
//! Contract (per picture, one PNG each; see docs/fit-outputs.md for how to read them):
//! - parameter maps: η, σs, σss, ρs, η standard error (viridis, robust range, colour bar), ρd and
//!   ρss as RGB (linear albedo × display gain, sRGB), the normal map (camera frame, n·½ + ½);
//! - the 3×3 Mueller grid: per pixel the linear 3×3 block of the full pBRDF (`pbrdf::evaluate`,
//!   mean of the colour channels) for the rig's own camera/flash geometry at that view, M00 in
//!   viridis (log10) and every other element as M_ij/M00 in a diverging map over [−1, 1];
//! - DoLP (viridis) and AoLP of the light the camera receives under the rig's polarised flash,
//!   AoLP as the HSV composite hue = AoLP, saturation = DoLP (`ellipso_report::colour::aolp_dolp`);
//! - relit: s0 under a new unpolarised point light (1/d², foreshortening in P), exposed and
//!   tone-mapped by Reinhard's global operator ([`tone_map`]), sRGB; the novel view: the same
//!   light from another camera pose.
//!
//! Parameters are interpolated over a triangle from its reliable vertices only (barycentric
//! weights renormalised); a vertex is unreliable where the identifiability rule withholds it
//! ([`crate::data::Identifiable`]: `TooFewViews`, `AlbedoAtCap`), and η is grey on triangles
//! with a vertex whose η the rule withholds. Map colour ranges are the fit's shared
//! [`super::colour::MapRanges`] (the view uses the same). Pixels where the mesh is not hit, or nearer unreliable vertices than reliable ones
//! (reliable weight < ½), are grey: one bad vertex is drawn as a small grey patch, never as a
//! fan of its lobe over its neighbours' triangles.

use ellipso_model::optics::Stokes;
use ellipso_model::optics::Vec3;
use ellipso_model::optics::measure::FlashPolariser;
use ellipso_model::optics::pbrdf::{Geometry, PbrdfParams, apply, evaluate};
use ellipso_model::rig::FlashSpec;
use nalgebra::{Point3, Vector3};
use rayon::prelude::*;

use super::colour::{robust_range, srgb};
use super::raster::{Hit, ViewCamera, rasterise};
use crate::data::{VertexFit, ViewGeometry};
use ellipso_model::geometry::TriangleMesh;
use ellipso_report::figure::NO_DATA;
use ellipso_report::{ColourMap, Figure, Key, Picture as Pixels, Rgb};

mod relight;

pub use relight::{radiance, relit, tone_map};

/// Per-vertex arrays interpolated over pixels.
struct Field {
    params: Vec<[f64; 10]>,
    normals: Vec<[f64; 3]>,
    eta_std: Vec<[f64; 1]>,
    reliable: Vec<bool>,
    eta_identifiable: Vec<bool>,
    /// Not [`crate::data::FitFlag::Unobserved`]: some fitted frame saw the vertex lit.
    observed: Vec<bool>,
}

impl Field {
    fn new(fits: &[VertexFit]) -> Self {
        Self {
            params: fits.iter().map(super::ply::params_of).collect(),
            normals: fits.iter().map(|f| f.normal_world).collect(),
            eta_std: fits.iter().map(|f| [f.reported_std_error()[0]]).collect(),
            reliable: fits.iter().map(VertexFit::is_reliable).collect(),
            eta_identifiable: fits.iter().map(|f| f.identifiable().eta).collect(),
            observed: fits
                .iter()
                .map(|f| !f.flags.contains(&crate::data::FitFlag::Unobserved))
                .collect(),
        }
    }

    /// Whether η is reported at a pixel of `hit`: every vertex of its triangle has η
    /// identifiable (the rule, [`crate::data::Identifiable`]).
    fn eta_at(&self, hit: &Hit) -> bool {
        hit.vertices
            .iter()
            .all(|&v| self.eta_identifiable[v as usize])
    }

    /// `hit` with its barycentric weights restricted to the reliable vertices and renormalised;
    /// `None` when they carry less than half the weight (module doc).
    fn reliable_hit(&self, hit: &Hit) -> Option<Hit> {
        let mut h = *hit;
        for (w, &v) in h.barycentric.iter_mut().zip(&hit.vertices) {
            if !self.reliable[v as usize] {
                *w = 0.0;
            }
        }
        let total: f64 = h.barycentric.iter().sum();
        if total.is_nan() || total < 0.5 {
            return None;
        }
        h.barycentric.iter_mut().for_each(|w| *w /= total);
        Some(h)
    }

    /// Parameters and unit normal at a hit, from its reliable vertices (module doc).
    fn at(&self, hit: &Hit) -> Option<(PbrdfParams<f64>, [f64; 3])> {
        let hit = self.reliable_hit(hit)?;
        let p = hit.interpolate(&self.params);
        let n = Vector3::from(hit.interpolate(&self.normals));
        let n = n.try_normalize(1e-12)?;
        // Interpolating valid parameters keeps them valid (a convex combination), except for
        // rounding at σs = σss: restore the order.
        let params = PbrdfParams {
            eta: p[0].max(1.0),
            sigma_s: p[1].clamp(0.0, 1.0),
            sigma_ss: p[2].clamp(p[1].clamp(0.0, 1.0), 1.0),
            rho_s: p[3].max(0.0),
            rho_ss: [p[4].max(0.0), p[5].max(0.0), p[6].max(0.0)],
            rho_d: [p[7].max(0.0), p[8].max(0.0), p[9].max(0.0)],
        };
        Some((params, n.into()))
    }
}

/// One rendered picture.
pub struct Picture {
    /// File stem, e.g. `map-eta`.
    pub name: &'static str,
    /// The framed figure.
    pub figure: Figure,
}

/// Pixels of an RGB field (`None`: no data, drawn grey).
pub fn rgb_pixels(w: u32, h: u32, pixels: impl IntoIterator<Item = Option<Rgb>>) -> Pixels {
    Pixels {
        width: w,
        height: h,
        pixels: pixels.into_iter().map(|p| p.unwrap_or(NO_DATA)).collect(),
    }
}

/// The model's geometry at a surface point for a view (camera + flash as the rig places them).
fn model_geometry(
    view: &ViewGeometry,
    point: &Point3<f64>,
    normal: [f64; 3],
) -> Option<Geometry<f64>> {
    let g = view.geometry_at(point)?;
    g.model::<f64>(Vec3::from_f64(normal)).ok()
}

/// The maps, Mueller grid, DoLP/AoLP and relit pictures of one view, `camera`, from the mesh's
/// rasterisation in it (`hits`, [`rasterise`]).
pub fn pictures(
    hits: &[Option<Hit>],
    fits: &[VertexFit],
    camera: &ViewCamera,
    flash: &FlashSpec,
    light_world: &Point3<f64>,
) -> (Vec<Picture>, Holes) {
    let field = Field::new(fits);
    let (w, h) = (camera.width, camera.height);
    let (at, holes) = models_and_holes(hits, &field, "map-eta");
    let mut out = Vec::new();
    let ranges = super::colour::MapRanges::of_fits(fits);
    let scalar = |name: &'static str,
                  title: &str,
                  label: &str,
                  range: (f64, f64),
                  f: &dyn Fn(&PbrdfParams<f64>) -> f64| {
        let values: Vec<Option<f64>> = at.iter().map(|a| a.as_ref().map(|(p, ..)| f(p))).collect();
        scalar_picture(name, title, label, w, h, &values, range)
    };
    // η where it is identifiable; grey where any vertex of the triangle says it is not.
    let eta: Vec<Option<f64>> = at
        .iter()
        .map(|a| {
            let (p, _, _, hit) = a.as_ref()?;
            field.eta_at(hit).then_some(p.eta)
        })
        .collect();
    out.push(scalar_picture(
        "map-eta",
        "refractive index η (grey: not identifiable)",
        "η",
        w,
        h,
        &eta,
        ranges.params[0],
    ));
    out.push(scalar(
        "map-sigma-s",
        "specular roughness σs (GGX)",
        "σs",
        ranges.params[1],
        &|p| p.sigma_s,
    ));
    out.push(scalar(
        "map-sigma-ss",
        "single-scattering roughness σss",
        "σss",
        ranges.params[2],
        &|p| p.sigma_ss,
    ));
    out.push(scalar(
        "map-rho-s",
        "specular albedo ρs",
        "ρs",
        ranges.params[3],
        &|p| p.rho_s,
    ));
    // η standard error (per vertex, interpolated), grey exactly where map-eta is.
    let eta_std: Vec<Option<f64>> = at
        .iter()
        .map(|a| {
            let hit = &a.as_ref()?.3;
            let s = hit.interpolate(&field.eta_std)[0];
            (field.eta_at(hit) && s.is_finite()).then_some(s)
        })
        .collect();
    out.push(scalar_picture(
        "map-eta-std",
        "standard error of η (grey: not identifiable)",
        "σ(η)",
        w,
        h,
        &eta_std,
        ranges.std_error[0],
    ));
    let rgb = |name: &'static str, title: &str, f: &dyn Fn(&PbrdfParams<f64>) -> [f64; 3]| {
        let values: Vec<Option<[f64; 3]>> =
            at.iter().map(|a| a.as_ref().map(|(p, ..)| f(p))).collect();
        // Display gain from the 95th percentile: a few specular-contaminated vertices must not
        // darken the whole map.
        let mut all: Vec<f64> = values
            .iter()
            .flatten()
            .flatten()
            .copied()
            .filter(|x| x.is_finite())
            .collect();
        let gain = 0.9 / ellipso_report::percentile(&mut all, 0.95).max(1e-9);
        let pixels = rgb_pixels(
            w,
            h,
            values.iter().map(|v| v.map(|c| c.map(|x| srgb(x * gain)))),
        );
        Picture {
            name,
            figure: Figure::new(format!("{title} (×{gain:.2} for display)")).image("", pixels),
        }
    };
    out.push(rgb("map-rho-d", "diffuse albedo ρd (RGB)", &|p| p.rho_d));
    out.push(rgb(
        "map-rho-ss",
        "single-scattering albedo ρss (RGB)",
        &|p| p.rho_ss,
    ));
    let camera_from_world = camera.world_from_camera.inverse();
    let normal_pixels = rgb_pixels(
        w,
        h,
        at.iter().map(|a| {
            a.as_ref().map(|(_, n, ..)| {
                // Camera frame with y up and z toward the viewer (the usual normal-map colours).
                let c = camera_from_world.transform_vector(&Vector3::from(*n));
                let v = [c.x, -c.y, -c.z];
                v.map(|x| ((x * 0.5 + 0.5) * 255.0).clamp(0.0, 255.0) as u8)
            })
        }),
    );
    out.push(Picture {
        name: "map-normal",
        figure: Figure::new(
            "refined normals, camera frame (x → red, y up → green, toward viewer → blue)",
        )
        .image("", normal_pixels),
    });
    let view = ViewGeometry::from_rig(0, &camera.world_from_camera, flash);
    out.push(mueller_grid(&at, w, h, &view));
    out.extend(polarisation(&at, w, h, &view));
    out.push(relit(
        &at,
        w,
        h,
        camera,
        light_world,
        "relit",
        "relit under a key light (unpolarised)",
    ));
    (out, holes)
}

/// What one pixel sees of the fitted model: parameters, unit normal, world point and the hit.
pub type PixelModel = Option<(PbrdfParams<f64>, [f64; 3], Point3<f64>, Hit)>;

/// The linear 3×3 block of the full pBRDF (mean over colour channels) at a surface point seen
/// by `view` with its flash; `None` where the geometry degenerates or nothing is reflected.
pub fn mueller_at(
    view: &ViewGeometry,
    params: &PbrdfParams<f64>,
    normal: [f64; 3],
    point: &Point3<f64>,
) -> Option<[[f64; 3]; 3]> {
    let g = model_geometry(view, point, normal)?;
    let lobes = evaluate(&g, params);
    let mut sum = [[0.0; 3]; 3];
    for c in 0..3 {
        let l = lobes.total(c).linear3();
        for i in 0..3 {
            for j in 0..3 {
                sum[i][j] += l[i][j] / 3.0;
            }
        }
    }
    (sum[0][0] > 0.0 && sum[0][0].is_finite()).then_some(sum)
}

/// The 3×3 Mueller grid (see the module doc).
fn mueller_grid(at: &[PixelModel], w: u32, h: u32, view: &ViewGeometry) -> Picture {
    let m: Vec<Option<[[f64; 3]; 3]>> = at
        .par_iter()
        .map(|a| {
            let (p, n, point, _) = a.as_ref()?;
            mueller_at(view, p, *n, point)
        })
        .collect();
    let m00: Vec<Option<f64>> = m.iter().map(|x| x.map(|x| x[0][0].log10())).collect();
    let (lo, hi) = robust_range(&m00);
    let mut figure =
        Figure::new("Mueller matrix, linear 3×3 block, under the rig's camera and flash")
            .columns(3);
    for i in 0..3 {
        for j in 0..3 {
            figure = if i == 0 && j == 0 {
                figure.image(
                    "log₁₀ M00",
                    Pixels::scalar(w, h, &m00, ColourMap::Viridis, lo, hi),
                )
            } else {
                let v: Vec<Option<f64>> = m.iter().map(|x| x.map(|x| x[i][j] / x[0][0])).collect();
                figure.image(
                    format!("M{i}{j} / M00"),
                    Pixels::scalar(w, h, &v, ColourMap::Diverging, -1.0, 1.0),
                )
            };
        }
    }
    Picture {
        name: "mueller-grid",
        figure: figure
            .key(Key::Bar {
                map: ColourMap::Viridis,
                lo,
                hi,
                label: "log₁₀ M00 (M00: reflectance, sr⁻¹)".into(),
            })
            .key(Key::Bar {
                map: ColourMap::Diverging,
                lo: -1.0,
                hi: 1.0,
                label: "Mij / M00".into(),
            }),
    }
}

/// DoLP and AoLP under the rig's polarised flash.
fn polarisation(at: &[PixelModel], w: u32, h: u32, view: &ViewGeometry) -> Vec<Picture> {
    let stokes: Vec<Option<[f64; 3]>> = at
        .par_iter()
        .map(|a| {
            let (p, n, point, _) = a.as_ref()?;
            let g = model_geometry(view, point, *n)?;
            let s = apply(&g, p, FlashPolariser::default().stokes(1.0));
            let mean = |f: fn(&Stokes<f64>) -> f64| s.iter().map(f).sum::<f64>() / 3.0;
            let s0 = mean(|s| s.s0);
            (s0 > 1e-12).then(|| [s0, mean(|s| s.s1), mean(|s| s.s2)])
        })
        .collect();
    let dolp: Vec<Option<f64>> = stokes
        .iter()
        .map(|s| s.map(|s| s[1].hypot(s[2]) / s[0]))
        .collect();
    let aolp: Vec<Option<f64>> = stokes
        .iter()
        .map(|s| s.map(|s| (0.5 * s[2].atan2(s[1])).rem_euclid(std::f64::consts::PI)))
        .collect();
    let (_, hi) = robust_range(&dolp);
    let hi = hi.max(1e-3);
    let composite = rgb_pixels(
        w,
        h,
        aolp.iter()
            .zip(&dolp)
            .map(|(a, d)| Some(ellipso_report::colour::aolp_dolp((*a)?, (*d)?, 1.0))),
    );
    vec![
        Picture {
            name: "dolp",
            figure: Figure::new("degree of linear polarisation under the rig's flash")
                .image("", Pixels::scalar(w, h, &dolp, ColourMap::Viridis, 0.0, hi))
                .key(Key::Bar {
                    map: ColourMap::Viridis,
                    lo: 0.0,
                    hi,
                    label: "DoLP".into(),
                }),
        },
        Picture {
            name: "aolp",
            figure: Figure::new("AoLP (hue) and DoLP (saturation) under the rig's flash")
                .image("", composite)
                .key(Key::AolpDolp {
                    dolp_as_value: false,
                }),
        },
    ]
}

/// What one picture's view shows of the surface the capture observed, and how much of it the
/// pictures leave grey. A pixel is *observed* when the mesh is hit there and none of its
/// triangle's vertices is [`crate::data::FitFlag::Unobserved`] (the geometry decides: no
/// fitted frame saw it lit); every other mesh pixel may be grey by the contract. Completion
/// (`crate::complete`) gives every observed vertex a full parameter set, so both hole counts
/// are zero unless a vertex the views see was left without one.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize)]
pub struct Holes {
    /// The picture (`map-eta`'s view is the maps' and `relit`'s; `novel-view` its own).
    pub view: &'static str,
    /// Mesh pixels whose triangle every view-seen vertex spans.
    pub observed_px: usize,
    /// Observed pixels drawn without parameters (grey in the maps, relit and novel view).
    pub without_parameters_px: usize,
    /// Observed pixels drawn without η (grey in `map-eta`).
    pub without_eta_px: usize,
}

/// The per-pixel model of a view (for the novel view and tests).
pub fn pixel_models(
    mesh: &TriangleMesh,
    fits: &[VertexFit],
    camera: &ViewCamera,
) -> Vec<PixelModel> {
    pixel_models_of(&rasterise(mesh, camera), fits)
}

/// [`pixel_models`] of a view already rasterised (`hits`, [`rasterise`]).
pub fn pixel_models_of(hits: &[Option<Hit>], fits: &[VertexFit]) -> Vec<PixelModel> {
    models_and_holes(hits, &Field::new(fits), "").0
}

/// [`pixel_models`] with the view's [`Holes`] counted from the same rasterisation.
pub fn pixel_models_and_holes(
    mesh: &TriangleMesh,
    fits: &[VertexFit],
    camera: &ViewCamera,
    view: &'static str,
) -> (Vec<PixelModel>, Holes) {
    models_and_holes(&rasterise(mesh, camera), &Field::new(fits), view)
}

/// `field` interpolated at every hit of one rasterisation, and the [`Holes`] of the observed
/// surface among those hits.
fn models_and_holes(
    hits: &[Option<Hit>],
    field: &Field,
    view: &'static str,
) -> (Vec<PixelModel>, Holes) {
    let mut holes = Holes {
        view,
        ..Holes::default()
    };
    let models = hits
        .iter()
        .map(|hit| {
            let hit = (*hit)?;
            let at = field.at(&hit);
            if hit.vertices.iter().all(|&v| field.observed[v as usize]) {
                holes.observed_px += 1;
                if at.is_none() {
                    holes.without_parameters_px += 1;
                }
                if at.is_none() || !field.eta_at(&hit) {
                    holes.without_eta_px += 1;
                }
            }
            let (p, n) = at?;
            Some((p, n, hit.point_world, hit))
        })
        .collect();
    (models, holes)
}

/// A scalar map (viridis over the fit's shared range, [`super::colour::MapRanges`], with its
/// colour bar); a map with no value to show says so in its title and key instead of drawing a
/// colour bar over a range no pixel has.
fn scalar_picture(
    name: &'static str,
    title: &str,
    label: &str,
    w: u32,
    h: u32,
    values: &[Option<f64>],
    (lo, hi): (f64, f64),
) -> Picture {
    if !values.iter().flatten().any(|v| v.is_finite()) {
        return Picture {
            name,
            figure: Figure::new(format!("{title}: no vertex in view reports it"))
                .image("", Pixels::scalar(w, h, values, ColourMap::Viridis, lo, hi))
                .key(Key::Swatches(vec![(
                    NO_DATA,
                    format!("{label} not reported anywhere in this view (see fit-summary.json)"),
                )])),
        };
    }
    Picture {
        name,
        figure: Figure::new(title)
            .image("", Pixels::scalar(w, h, values, ColourMap::Viridis, lo, hi))
            .key(Key::Bar {
                map: ColourMap::Viridis,
                lo,
                hi,
                label: label.into(),
            }),
    }
}
