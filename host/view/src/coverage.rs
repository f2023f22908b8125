//! The coverage measure: how well each region of the object is constrained by the posed views so
//! far, and plain-language hints on where to take the next photos.
//!
//! Contract:
//! - Elements are the mesh's vertices (when a mesh is given) or a coarse proxy: points on a small
//!   sphere around the object's centre, upper hemisphere and a 10° band below the equator, with
//!   outward normals ([`CoverageModel::proxy`]).
//! - A posed view sees an element when the view direction is within 80° of its normal (the fit's
//!   grazing cut-off, `GateConfig::grazing_cutoff_deg`), the element projects inside the image,
//!   and, for a mesh, no triangle lies between them (a ray cast).
//! - Per element it keeps: the number of views; the number of oblique views (θ_o ≥
//!   [`OBLIQUE_DEG`], where the diffuse degree of polarisation carries η: for η = 1.5 it is 0.05
//!   at 40° against 0.01 at 20°); the smallest half-vector angle θ_h between the normal and the
//!   bisector of flash and camera (a near-mirror, specular view has θ_h ≤ [`MIRROR_DEG`]; the flash
//!   sits ~3.5° from the camera, so this is a view nearly along the normal); and which of eight
//!   azimuth sectors around the normal the off-normal views (θ_o ≥ 15°) come from.
//! - Its [`Category`] is the first unmet need, in this order: seen at all, at least
//!   [`MIN_VIEWS`] views (the fit's `min_views`), an oblique view, a near-mirror view, views from
//!   at least 3 azimuth sectors; otherwise good.
//! - [`hints`] groups the weak elements by the direction their normal faces (eight azimuth sectors
//!   in the world/board frame × side, shoulder, top) and names the dominant need of each group with
//!   where to stand; it adds hints from the camera path itself (a side with no views, no views
//!   below 40° elevation on a side). Directions: azimuth counter-clockwise from the board's +x
//!   axis seen from above, elevation above the board plane.

use ellipso_model::camera::CameraModel;
use ellipso_model::geometry::{Intersect, Ray, TriangleMesh};
use nalgebra::{Isometry3, Point3, Unit, Vector3};

/// Views needed for a vertex to be fitted (the fit's `GateConfig::min_views`).
pub const MIN_VIEWS: u32 = 12;
/// A view at least this far from the normal is oblique (carries η), degrees.
pub const OBLIQUE_DEG: f64 = 40.0;
/// A view whose half vector is within this of the normal is near-mirror (specular), degrees.
pub const MIRROR_DEG: f64 = 8.0;
/// Views beyond this angle from the normal are not counted (the fit's grazing cut-off), degrees.
pub const GRAZING_DEG: f64 = 80.0;

/// The first unmet need of an element (what its colour shows).
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, serde::Serialize)]
#[serde(rename_all = "snake_case")]
#[repr(u8)]
pub enum Category {
    /// No posed view sees it.
    Unseen = 0,
    /// Fewer than [`MIN_VIEWS`] views.
    FewViews = 1,
    /// No oblique view: η is not identifiable.
    NoOblique = 2,
    /// No near-mirror view: the specular lobe (σ_s, ρ_s) is unconstrained.
    NoMirror = 3,
    /// Views from fewer than 3 azimuth sectors.
    Narrow = 4,
    /// All needs met.
    Good = 5,
}

impl Category {
    /// Every category, in order.
    pub const ALL: [Category; 6] = [
        Category::Unseen,
        Category::FewViews,
        Category::NoOblique,
        Category::NoMirror,
        Category::Narrow,
        Category::Good,
    ];
    /// What it means, for the legend.
    pub fn label(self) -> &'static str {
        match self {
            Category::Unseen => "not seen",
            Category::FewViews => "fewer than 12 views",
            Category::NoOblique => "no view ≥ 40° off the surface (η)",
            Category::NoMirror => "no near-mirror view (specular)",
            Category::Narrow => "views from one side only",
            Category::Good => "well constrained",
        }
    }
}

#[derive(Clone, Copy, Debug, Default)]
struct Acc {
    views: u32,
    oblique: u32,
    min_theta_h_deg: f64,
    sectors: u8,
}

/// One posed view as coverage needs it.
#[derive(Clone, Copy, Debug)]
pub struct PosedView {
    /// Camera → world.
    pub world_from_camera: Isometry3<f64>,
}

/// Coverage of one object (mesh or proxy) by posed views.
pub struct CoverageModel {
    positions: Vec<Point3<f64>>,
    normals: Vec<Unit<Vector3<f64>>>,
    occluder: Option<TriangleMesh>,
    acc: Vec<Acc>,
    camera: CameraModel,
    /// Flash position in the camera frame (OpenCV axes), metres.
    flash_offset_m: Vector3<f64>,
    centre: Point3<f64>,
    proxy: bool,
    views: Vec<PosedView>,
}

impl CoverageModel {
    /// Coverage on a mesh's vertices (occlusion by the mesh itself).
    pub fn on_mesh(mesh: TriangleMesh, camera: CameraModel, flash_offset_m: Vector3<f64>) -> Self {
        let positions = mesh.positions().to_vec();
        let normals = mesh.normals().to_vec();
        let centre = ellipso_model::geometry::Aabb::from_points(&positions).centre();
        Self {
            acc: vec![Acc::default(); positions.len()],
            positions,
            normals,
            occluder: Some(mesh),
            camera,
            flash_offset_m,
            centre,
            proxy: false,
            views: Vec::new(),
        }
    }

    /// Coverage on a proxy sphere of `radius_m` around `centre` (~`count` points).
    pub fn proxy(
        centre: Point3<f64>,
        radius_m: f64,
        count: usize,
        camera: CameraModel,
        flash_offset_m: Vector3<f64>,
    ) -> Self {
        let normals = proxy_normals(count);
        let positions = normals
            .iter()
            .map(|n| centre + n.into_inner() * radius_m)
            .collect();
        Self {
            acc: vec![Acc::default(); normals.len()],
            positions,
            normals,
            occluder: None,
            camera,
            flash_offset_m,
            centre,
            proxy: true,
            views: Vec::new(),
        }
    }

    /// Whether this is the proxy sphere.
    pub fn is_proxy(&self) -> bool {
        self.proxy
    }
    /// The object's centre.
    pub fn centre(&self) -> Point3<f64> {
        self.centre
    }
    /// Element normals (proxy: the directions drawn on the dome).
    pub fn normals(&self) -> &[Unit<Vector3<f64>>] {
        &self.normals
    }
    /// Views added so far.
    pub fn view_count(&self) -> usize {
        self.views.len()
    }

    /// Accounts one more posed view.
    pub fn add_view(&mut self, view: PosedView) {
        let camera_from_world = view.world_from_camera.inverse();
        let eye = view.world_from_camera.translation.vector;
        let flash = view.world_from_camera * Point3::from(self.flash_offset_m);
        let cos_grazing = GRAZING_DEG.to_radians().cos();
        let scale = self.occluder.as_ref().map_or(1.0, |m| {
            ellipso_model::geometry::Aabb::from_points(m.positions())
                .extent()
                .norm()
        });
        let elements = self
            .positions
            .iter()
            .zip(&self.normals)
            .zip(self.acc.iter_mut());
        for ((&p, n), a) in elements {
            let n = n.into_inner();
            let to_eye = eye - p.coords;
            let dist = to_eye.norm();
            if dist <= 0.0 {
                continue;
            }
            let wo = to_eye / dist;
            let cos_o = n.dot(&wo);
            if cos_o < cos_grazing {
                continue;
            }
            let in_image = self
                .camera
                .project(&(camera_from_world * p))
                .is_some_and(|px| self.camera.contains_pixel(px));
            if !in_image {
                continue;
            }
            if let Some(mesh) = &self.occluder {
                let origin = p + n * (1e-4 * scale);
                if mesh.occluded(&Ray::new(origin, wo), 0.0, dist) {
                    continue;
                }
            }
            let wi = (flash - p).normalize();
            let h = (wi + wo).normalize();
            let theta_h = n.dot(&h).clamp(-1.0, 1.0).acos().to_degrees();
            let theta_o = cos_o.clamp(-1.0, 1.0).acos().to_degrees();
            if a.views == 0 || theta_h < a.min_theta_h_deg {
                a.min_theta_h_deg = theta_h;
            }
            a.views += 1;
            if theta_o >= OBLIQUE_DEG {
                a.oblique += 1;
            }
            if theta_o >= 15.0 {
                let (t1, t2) = tangent_frame(&n);
                let az = wo.dot(&t2).atan2(wo.dot(&t1));
                let sector = ((az / std::f64::consts::TAU * 8.0).floor() as i64).rem_euclid(8);
                a.sectors |= 1 << sector;
            }
        }
        self.views.push(view);
    }

    /// The category of element `i`.
    pub fn category(&self, i: usize) -> Category {
        let a = &self.acc[i];
        if a.views == 0 {
            Category::Unseen
        } else if a.views < MIN_VIEWS {
            Category::FewViews
        } else if a.oblique == 0 {
            Category::NoOblique
        } else if a.min_theta_h_deg > MIRROR_DEG {
            Category::NoMirror
        } else if a.sectors.count_ones() < 3 {
            Category::Narrow
        } else {
            Category::Good
        }
    }

    /// Views of element `i`.
    #[cfg(test)]
    pub fn views_of(&self, i: usize) -> u32 {
        self.acc[i].views
    }

    /// One byte per element: its category.
    pub fn categories(&self) -> Vec<u8> {
        (0..self.acc.len())
            .map(|i| self.category(i) as u8)
            .collect()
    }

    /// Elements per category, in [`Category::ALL`] order.
    pub fn counts(&self) -> [usize; 6] {
        let mut c = [0; 6];
        for i in 0..self.acc.len() {
            c[self.category(i) as usize] += 1;
        }
        c
    }

    /// Azimuth and elevation (degrees) of a world point seen from the centre.
    pub fn dome_angles(&self, p: &Point3<f64>) -> (f64, f64) {
        dome_angles(&(p - self.centre))
    }

    /// Hints, most important first.
    pub fn hints(&self) -> Vec<String> {
        hints(self)
    }
}

/// Azimuth (from +x toward +y) and elevation of a direction, degrees.
pub fn dome_angles(d: &Vector3<f64>) -> (f64, f64) {
    let r = d.norm().max(1e-12);
    let az = d.y.atan2(d.x).to_degrees().rem_euclid(360.0);
    let el = (d.z / r).clamp(-1.0, 1.0).asin().to_degrees();
    (az, el)
}

fn tangent_frame(n: &Vector3<f64>) -> (Vector3<f64>, Vector3<f64>) {
    let a = if n.x.abs() < 0.9 {
        Vector3::x()
    } else {
        Vector3::y()
    };
    let t1 = n.cross(&a).normalize();
    (t1, n.cross(&t1))
}

/// Fibonacci-sphere directions with elevation ≥ −10°.
fn proxy_normals(count: usize) -> Vec<Unit<Vector3<f64>>> {
    let golden = std::f64::consts::PI * (3.0 - 5f64.sqrt());
    // sample the sphere densely enough that `count` points land in the kept band
    let total = (count as f64 / 0.59).ceil() as usize;
    (0..total)
        .filter_map(|k| {
            let z = 1.0 - 2.0 * (k as f64 + 0.5) / total as f64;
            let r = (1.0 - z * z).sqrt();
            let phi = golden * k as f64;
            (z >= -(10f64.to_radians().sin()))
                .then(|| Unit::new_normalize(Vector3::new(r * phi.cos(), r * phi.sin(), z)))
        })
        .collect()
}

const SECTOR_NAMES: [&str; 8] = ["+x", "+x+y", "+y", "−x+y", "−x", "−x−y", "−y", "+x−y"];

fn sector_of(az_deg: f64) -> usize {
    (((az_deg + 22.5) / 45.0).floor() as i64).rem_euclid(8) as usize
}

fn hints(model: &CoverageModel) -> Vec<String> {
    let mut out = Vec::new();
    if model.views.is_empty() {
        out.push("no posed views yet: keep the AprilTag board in the frame".to_string());
        return out;
    }
    // camera-path hints per quadrant
    let angles: Vec<(f64, f64)> = model
        .views
        .iter()
        .map(|v| dome_angles(&(v.world_from_camera.translation.vector - model.centre.coords)))
        .collect();
    for q in 0..4 {
        let centre = 90.0 * q as f64;
        let in_q: Vec<f64> = angles
            .iter()
            .filter(|(az, _)| {
                let d = (az - centre + 540.0).rem_euclid(360.0) - 180.0;
                d.abs() < 45.0
            })
            .map(|(_, el)| *el)
            .collect();
        let name = SECTOR_NAMES[q * 2];
        if in_q.is_empty() {
            out.push(format!(
                "{name} side (azimuth {:.0}°±45°): no views yet — walk round to it",
                centre
            ));
        } else if in_q.iter().cloned().fold(f64::INFINITY, f64::min) > 40.0 {
            out.push(format!(
                "{name} side: no views below 40° elevation — crouch for lower photos there"
            ));
        }
    }
    if angles.iter().all(|(_, el)| *el < 60.0) {
        out.push("no views above 60° elevation: top surfaces lack near-mirror views — take a few from above".into());
    }
    // element groups by normal direction
    let mut groups: std::collections::BTreeMap<(usize, usize), [usize; 6]> = Default::default();
    let mut totals: std::collections::BTreeMap<(usize, usize), usize> = Default::default();
    for (i, n) in model.normals.iter().enumerate() {
        let (az, el) = dome_angles(&n.into_inner());
        let band = if el < 30.0 {
            0
        } else if el < 60.0 {
            1
        } else {
            2
        };
        let key = (if band == 2 { 0 } else { sector_of(az) }, band);
        groups.entry(key).or_insert([0; 6])[model.category(i) as usize] += 1;
        *totals.entry(key).or_insert(0) += 1;
    }
    let mut weak: Vec<(usize, String)> = Vec::new();
    for ((sector, band), counts) in &groups {
        let total = totals[&(*sector, *band)];
        let bad: usize = counts[..5].iter().sum();
        if bad * 4 < total || bad < 2 {
            continue;
        }
        let worst = (0..5).max_by_key(|&c| (counts[c], 5 - c)).unwrap_or(0);
        let az = 45.0 * *sector as f64;
        let (region, el) = match band {
            0 => (format!("{} side", SECTOR_NAMES[*sector]), 15.0),
            1 => (format!("{} shoulder", SECTOR_NAMES[*sector]), 45.0),
            _ => ("top".to_string(), 80.0),
        };
        let stand = if *band == 2 {
            "from above".to_string()
        } else {
            format!("at azimuth {az:.0}°")
        };
        let need = match Category::ALL[worst] {
            Category::Unseen => format!("not seen — photograph it {stand}, elevation ≈{el:.0}°"),
            Category::FewViews => {
                format!("fewer than {MIN_VIEWS} views — add photos {stand}, elevation ≈{el:.0}°")
            }
            Category::NoOblique => format!(
                "no view ≥{OBLIQUE_DEG:.0}° off the surface (η unknown) — add photos from {}",
                if *band == 2 {
                    "low elevation (≤45°)".to_string()
                } else {
                    format!("azimuth {:.0}° or {:.0}°", az - 60.0, az + 60.0)
                }
            ),
            Category::NoMirror => format!(
                "no near-mirror view (specular unknown) — point the camera straight at it {stand}, elevation ≈{el:.0}°"
            ),
            Category::Narrow => format!(
                "all views from one direction — add photos from azimuth {:.0}°",
                (az + 90.0).rem_euclid(360.0)
            ),
            Category::Good => continue,
        };
        weak.push((bad, format!("{region}: {need}")));
    }
    weak.sort_by_key(|w| std::cmp::Reverse(w.0));
    out.extend(weak.into_iter().map(|(_, h)| h));
    if out.is_empty() {
        out.push("every region is well constrained".into());
    }
    out.truncate(8);
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use ellipso_model::camera::{CameraModel, Intrinsics};
    use nalgebra::{Translation3, UnitQuaternion};

    fn camera() -> CameraModel {
        CameraModel::pinhole(
            640,
            512,
            Intrinsics {
                fx: 900.0,
                fy: 900.0,
                cx: 319.5,
                cy: 255.5,
            },
        )
    }

    /// A camera at azimuth/elevation (deg) and distance 0.5 m looking at the origin.
    fn view(az: f64, el: f64) -> PosedView {
        let (a, e) = (az.to_radians(), el.to_radians());
        let eye = Vector3::new(e.cos() * a.cos(), e.cos() * a.sin(), e.sin()) * 0.5;
        let forward = -eye.normalize();
        // OpenCV camera: z forward, y down (world -z projected)
        let down = (-Vector3::z() + forward * forward.z).normalize();
        let down = if down.norm().is_finite() {
            down
        } else {
            Vector3::y()
        };
        let right = down.cross(&forward);
        let rot = nalgebra::Rotation3::from_basis_unchecked(&[right, down, forward]);
        PosedView {
            world_from_camera: Isometry3::from_parts(
                Translation3::from(eye),
                UnitQuaternion::from_rotation_matrix(&rot),
            ),
        }
    }

    fn model() -> CoverageModel {
        CoverageModel::proxy(
            Point3::origin(),
            0.03,
            300,
            camera(),
            Vector3::new(0.0, -0.03, 0.0),
        )
    }

    #[test]
    fn one_sided_capture_leaves_the_far_side_unseen_and_says_so() {
        // 20 photos from the +x side, all from 50° elevation
        let mut m = model();
        for k in 0..20 {
            m.add_view(view(-30.0 + 3.0 * k as f64, 50.0));
        }
        let facing = |az: f64| {
            (0..m.normals.len())
                .filter(|&i| {
                    let (a, e) = dome_angles(&m.normals[i].into_inner());
                    e < 20.0 && ((a - az + 540.0).rem_euclid(360.0) - 180.0).abs() < 20.0
                })
                .collect::<Vec<_>>()
        };
        assert!(
            facing(180.0)
                .iter()
                .all(|&i| m.category(i) == Category::Unseen)
        );
        assert!(facing(0.0).iter().all(|&i| m.views_of(i) >= 15));
        let hints = m.hints().join("\n");
        assert!(
            hints.contains("−x side (azimuth 180°±45°): no views yet"),
            "{hints}"
        );
        assert!(
            hints.contains("+x side: no views below 40° elevation"),
            "{hints}"
        );
    }

    #[test]
    fn a_dense_all_round_capture_is_mostly_good() {
        // every 6° of azimuth and elevation: each direction has a view within the mirror cone
        let mut m = model();
        for ring in (0..15).map(|k| 6.0 * k as f64) {
            for k in 0..60 {
                m.add_view(view(6.0 * k as f64, ring));
            }
        }
        let c = m.counts();
        let total: usize = c.iter().sum();
        assert!(c[Category::Good as usize] * 10 > total * 8, "{c:?}");
        assert_eq!(c[Category::Unseen as usize], 0, "{c:?}");
    }

    #[test]
    fn rings_25_degrees_apart_leave_the_normals_between_them_without_a_mirror_view() {
        // 4 rings of 24 photos: every element is seen often, from many sides and obliquely, but
        // a normal halfway between two rings is ~12° from the nearest view (> MIRROR_DEG)
        let mut m = model();
        for ring in [15.0, 40.0, 65.0, 88.0] {
            for k in 0..24 {
                m.add_view(view(15.0 * k as f64, ring));
            }
        }
        let c = m.counts();
        for cat in [
            Category::Unseen,
            Category::FewViews,
            Category::NoOblique,
            Category::Narrow,
        ] {
            assert_eq!(c[cat as usize], 0, "{cat:?}: {c:?}");
        }
        assert!(c[Category::NoMirror as usize] > 0, "{c:?}");
        assert!(c[Category::Good as usize] > 0, "{c:?}");
        let between = (0..m.normals.len())
            .filter(|&i| {
                let el = dome_angles(&m.normals[i].into_inner()).1;
                (25.0..30.0).contains(&el)
            })
            .collect::<Vec<_>>();
        assert!(!between.is_empty());
        assert!(between.iter().all(|&i| m.category(i) == Category::NoMirror));
        assert!(
            m.hints().iter().any(|h| h.contains("no near-mirror view")),
            "{:?}",
            m.hints()
        );
    }

    #[test]
    fn a_mesh_occludes_its_own_far_side() {
        let (dirs, faces) = ellipso_model::geometry::procedural::icosphere(2);
        let pos = dirs
            .iter()
            .map(|d| Point3::from(d.into_inner() * 0.03))
            .collect();
        let mesh = TriangleMesh::new(pos, None, None, faces).unwrap();
        let mut m = CoverageModel::on_mesh(mesh, camera(), Vector3::new(0.0, -0.03, 0.0));
        m.add_view(view(0.0, 0.0));
        let seen = (0..m.normals.len()).filter(|&i| m.views_of(i) > 0).count();
        assert!(seen > 0 && seen * 2 < m.normals.len() + 10, "seen {seen}");
        // the vertex facing straight at the camera has a near-mirror view (the flash 3 cm above
        // the lens at 0.47 m puts the half-vector ~1.8° off its normal)
        let i = (0..m.normals.len())
            .max_by(|&a, &b| m.normals[a].x.total_cmp(&m.normals[b].x))
            .unwrap();
        assert!(m.normals[i].x > 0.999);
        let theta_h = m.acc[i].min_theta_h_deg;
        assert!((1.0..3.0).contains(&theta_h), "{theta_h}");
        // and one 10° further up sees it outside the mirror cone
        m.add_view(view(0.0, 10.0));
        assert!(m.acc[i].min_theta_h_deg == theta_h);
        let mut up = CoverageModel::on_mesh(
            m.occluder.clone().unwrap(),
            camera(),
            Vector3::new(0.0, -0.03, 0.0),
        );
        up.add_view(view(0.0, 10.0));
        assert!(
            up.acc[i].min_theta_h_deg > MIRROR_DEG,
            "{}",
            up.acc[i].min_theta_h_deg
        );
    }
}
