//! End-to-end tests of the augmentation on synthetic spheres: vertices on a sphere seen from an
//! orbit of near-coaxial polarised-flash views, observations from `measure::observe`.

use ellipso_model::optics::Vec3;
use ellipso_model::optics::measure::observe;
use ellipso_model::optics::pbrdf::PbrdfParams;
use nalgebra::{Point3, Vector3};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, Normal};

use super::labels::confident_group;
use super::lobe_fit::{self, LobeSample};
use super::*;
use crate::data::{FitFlag, GateCounts, Sample, VertexSamples, ViewGeometry};

const SPHERE_RADIUS_M: f64 = 0.05;
const CAMERA_DISTANCE_M: f64 = 0.5;
/// Flash 30 mm below the lens: ~3.4° at 0.5 m.
const FLASH_OFFSET_M: f64 = 0.03;
const GRAZING_COS: f64 = 0.17; // ~80°

/// Three dielectrics that differ in colour, η and lobe.
fn materials() -> [PbrdfParams<f64>; 3] {
    [
        PbrdfParams {
            eta: 1.5,
            sigma_s: 0.1,
            sigma_ss: 0.4,
            rho_s: 0.5,
            rho_ss: [0.8, 0.5, 0.3],
            rho_d: [0.6, 0.6, 0.6],
        },
        PbrdfParams {
            eta: 1.35,
            sigma_s: 0.2,
            sigma_ss: 0.6,
            rho_s: 0.3,
            rho_ss: [0.6, 0.2, 0.1],
            rho_d: [0.7, 0.2, 0.1],
        },
        PbrdfParams {
            eta: 1.8,
            sigma_s: 0.05,
            sigma_ss: 0.25,
            rho_s: 0.8,
            rho_ss: [0.2, 0.3, 0.6],
            rho_d: [0.1, 0.2, 0.5],
        },
    ]
}

/// Cameras on rings around the origin looking at it, flash below the lens, polariser along
/// image rows.
fn orbit_views(azimuths: usize, elevations_deg: &[f64]) -> Vec<ViewGeometry> {
    let mut views = Vec::new();
    for &el in elevations_deg {
        for a in 0..azimuths {
            let az = (360.0 * a as f64 / azimuths as f64 + 7.0 * el).to_radians();
            let el = el.to_radians();
            let position = Vector3::new(el.cos() * az.cos(), el.cos() * az.sin(), el.sin())
                * CAMERA_DISTANCE_M;
            let forward = -position.normalize();
            let right = forward.cross(&Vector3::z()).normalize();
            let up = right.cross(&forward);
            views.push(ViewGeometry {
                frame_id: views.len() as u64,
                camera_position_world: position.into(),
                camera_up_world: up.into(),
                flash_position_world: (position - up * FLASH_OFFSET_M).into(),
                polariser_axis_world: Some(right.into()),
                camera_axis_world: Some(forward.into()),
            });
        }
    }
    views
}

/// `n` points on a Fibonacci sphere: (position, outward unit normal).
fn sphere(n: usize) -> Vec<([f64; 3], [f64; 3])> {
    let golden = std::f64::consts::PI * (3.0 - 5f64.sqrt());
    (0..n)
        .map(|i| {
            let z = 1.0 - 2.0 * (i as f64 + 0.5) / n as f64;
            let r = (1.0 - z * z).sqrt();
            let phi = golden * i as f64;
            let normal = [r * phi.cos(), r * phi.sin(), z];
            (normal.map(|v| v * SPHERE_RADIUS_M), normal)
        })
        .collect()
}

/// Synthetic samples (normaliser 1) of `params[v]` at every view within 80° of the normal,
/// with Gaussian noise of `noise_sd` (model units) on every channel.
fn synthesize(
    views: Vec<ViewGeometry>,
    points: &[([f64; 3], [f64; 3])],
    params: &[PbrdfParams<f64>],
    noise_sd: f64,
    seed: u64,
) -> SampleSet {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let noise = Normal::new(0.0, noise_sd.max(0.0)).unwrap();
    let vertices = points
        .iter()
        .zip(params)
        .enumerate()
        .map(|(v, (&(position, normal), p))| {
            let mut samples = Vec::new();
            for (k, view) in views.iter().enumerate() {
                let Some(sg) = view.geometry_at(&Point3::from(position)) else {
                    continue;
                };
                if Vector3::from(sg.to_camera).dot(&Vector3::from(normal)) < GRAZING_COS {
                    continue;
                }
                let g = sg.model(Vec3::from_f64(normal)).unwrap();
                if !g.front_facing {
                    continue;
                }
                let obs = observe(&g, p, view.flash_polariser());
                let channels = obs.map(|o| {
                    [o.diffuse, o.specular, o.alpha, o.diffuse + o.specular]
                        .map(|x| (x + noise.sample(&mut rng)) as f32)
                });
                samples.push(Sample {
                    view: k as u32,
                    channels,
                    normaliser: 1.0,
                });
            }
            VertexSamples {
                vertex: v as u32,
                position_world: position,
                normal_world: normal,
                samples,
                gates: GateCounts::default(),
            }
        })
        .collect();
    SampleSet {
        views,
        colour: true,
        vertices,
        rings: Vec::new(),
    }
}

/// A joint-solve result with these parameters and normal.
fn fit_of(vertex: usize, params: PbrdfParams<f64>, normal: [f64; 3]) -> VertexFit {
    VertexFit {
        vertex: vertex as u32,
        params,
        normal_world: normal,
        std_error: [0.0; 10],
        normal_std_error_deg: 0.0,
        samples_used: 0,
        cost: 0.0,
        iterations: 0,
        flags: Vec::new(),
        eta_unpooled: None,
        eta_prior_only: false,
        gates: Default::default(),
    }
}

/// A synthetic scene: `n` sphere vertices with material `material_of(v)`, observed with
/// `noise_sd`, and joint-solve results equal to the truth plus feature noise (ρ_d sd
/// `feature_sd`, η sd 2·`feature_sd`).
struct Scene {
    set: SampleSet,
    truth: Vec<PbrdfParams<f64>>,
    fits: Vec<VertexFit>,
}

fn scene(n: usize, material_of: impl Fn(usize) -> usize, noise_sd: f64, feature_sd: f64) -> Scene {
    let points = sphere(n);
    let mats = materials();
    let truth: Vec<PbrdfParams<f64>> = (0..n).map(|v| mats[material_of(v)]).collect();
    let set = synthesize(
        orbit_views(12, &[-45.0, -15.0, 15.0, 45.0, 75.0]),
        &points,
        &truth,
        noise_sd,
        11,
    );
    let mut rng = ChaCha8Rng::seed_from_u64(12);
    let unit = Normal::new(0.0, 1.0).unwrap();
    let fits = truth
        .iter()
        .enumerate()
        .map(|(v, p)| {
            let mut q = *p;
            q.rho_d = q.rho_d.map(|r| r + feature_sd * unit.sample(&mut rng));
            q.eta += 2.0 * feature_sd * unit.sample(&mut rng);
            fit_of(v, q, points[v].1)
        })
        .collect();
    Scene { set, truth, fits }
}

/// The lobe samples of the vertices of one material.
fn lobe_samples(s: &Scene, material: &PbrdfParams<f64>) -> Vec<LobeSample> {
    let mut out = Vec::new();
    for (v, vs) in s.set.vertices.iter().enumerate() {
        if s.truth[v] != *material {
            continue;
        }
        for sample in &vs.samples {
            let (g, flash) = sample_geometry(&s.set, v, sample, &s.fits[v]).unwrap();
            out.push(LobeSample::new(&g, flash, sample, &s.fits[v], material.eta, 1.0).unwrap());
        }
    }
    out
}

#[test]
fn lobe_samples_reproduce_observe() {
    // target + the vertex's diffuse I^s is the observation; model(truth) is observe's I^s
    // minus its diffuse part: the decomposition uses the optics functions consistently.
    let s = scene(60, |v| v % 3, 0.0, 0.0);
    for m in materials() {
        let samples = lobe_samples(&s, &m);
        assert!(samples.len() > 200);
        for x in &samples {
            let model = x.model(m.sigma_s, m.sigma_ss, m.rho_s, m.rho_ss);
            for (m, t) in model.iter().zip(x.target) {
                assert!((m - t).abs() < 2e-6 * (1.0 + t.abs()));
            }
        }
    }
}

#[test]
fn two_lobe_fit_recovers_noiseless_and_degrades_gracefully_with_noise() {
    let clean = scene(240, |v| v % 3, 0.0, 0.0);
    let noisy = scene(240, |v| v % 3, 0.002, 0.0);
    for m in materials() {
        let fit = lobe_fit::fit_lobes(&lobe_samples(&clean, &m), 0.02, 5.0).unwrap();
        let rel = |a: f64, b: f64| (a - b).abs() / b;
        assert!(rel(fit.sigma_s, m.sigma_s) < 1e-3, "{fit:?} vs {m:?}");
        assert!(rel(fit.sigma_ss, m.sigma_ss) < 1e-3, "{fit:?} vs {m:?}");
        assert!(rel(fit.rho_s, m.rho_s) < 1e-3, "{fit:?} vs {m:?}");
        for c in 0..3 {
            assert!(rel(fit.rho_ss[c], m.rho_ss[c]) < 1e-3, "{fit:?} vs {m:?}");
        }
        assert!(fit.rms < 1e-6, "{fit:?}");

        let fit = lobe_fit::fit_lobes(&lobe_samples(&noisy, &m), 0.02, 5.0).unwrap();
        eprintln!("noise 0.002: {fit:?} vs {m:?}");
        assert!(rel(fit.sigma_s, m.sigma_s) < 0.05, "{fit:?} vs {m:?}");
        assert!(rel(fit.sigma_ss, m.sigma_ss) < 0.15, "{fit:?} vs {m:?}");
        assert!(rel(fit.rho_s, m.rho_s) < 0.1, "{fit:?} vs {m:?}");
        // A weak single-scattering channel (B of the second material is ~5e-4 at its peak,
        // a quarter of the noise) is known only to a fraction of the strongest one.
        let rho_ss_max = m.rho_ss.iter().copied().fold(0.0, f64::max);
        for c in 0..3 {
            assert!(
                (fit.rho_ss[c] - m.rho_ss[c]).abs() < 0.2 * rho_ss_max,
                "{fit:?} vs {m:?}"
            );
        }
        // What the virtual samples carry, the coaxial profile, is right to a few % of its
        // peak up to 60°.
        let profile = |p: &PbrdfParams<f64>| {
            virtual_samples::coaxial_profile(p.eta, p.sigma_s, p.sigma_ss, p.rho_s, p.rho_ss, 180)
                .into_iter()
                .map(|q| (q.cos_theta_h, q.specular))
                .collect::<Vec<_>>()
        };
        let fitted = PbrdfParams {
            sigma_s: fit.sigma_s,
            sigma_ss: fit.sigma_ss,
            rho_s: fit.rho_s,
            rho_ss: fit.rho_ss,
            ..m
        };
        let (want, got) = (profile(&m), profile(&fitted));
        for c in 0..3 {
            let peak = want[0].1[c];
            for (w, g) in want.iter().zip(&got).take(121) {
                assert!((w.1[c] - g.1[c]).abs() < 0.05 * peak, "{fit:?} vs {m:?}");
            }
        }
        // The residual is the noise.
        assert!((fit.rms / 0.002 - 1.0).abs() < 0.1, "{fit:?}");
    }
}

#[test]
fn eta_of_a_cluster_from_real_geometry() {
    let s = scene(120, |v| v % 3, 0.0, 0.0);
    for m in materials() {
        let mut dop = Vec::new();
        for (v, vs) in s.set.vertices.iter().enumerate() {
            if s.truth[v] != m {
                continue;
            }
            for sample in &vs.samples {
                let (g, flash) = sample_geometry(&s.set, v, sample, &s.fits[v]).unwrap();
                dop.extend(eta_fit::dop_sample(&g, flash, sample, &s.fits[v]));
            }
        }
        let eta = eta_fit::fit_eta(&dop).unwrap();
        assert!((eta - m.eta).abs() < 1e-4, "{eta} vs {}", m.eta);
    }
}

fn small_config() -> AugmentConfig {
    AugmentConfig {
        max_lobe_samples: 3000,
        ..AugmentConfig::default()
    }
}

fn check_virtual_samples(a: &Augmentation, config: &AugmentConfig) {
    for g in &a.guides {
        let vs = &g.virtual_samples;
        if vs.is_empty() {
            assert_eq!(g.sigma_s_floor, 0.0);
            continue;
        }
        let sum: f64 = vs.iter().map(|s| s.weight).sum();
        assert!((sum - config.lambda_g).abs() < 1e-12, "{sum}");
        for (m, s) in vs.iter().enumerate() {
            // A prefix of the squared grid.
            let want = virtual_samples::grid_deg(m, config.profile_samples)
                .to_radians()
                .cos();
            assert!((s.cos_theta_h - want).abs() < 1e-15);
            assert!(s.weight > 0.0 && s.weight.is_finite());
            assert!(s.specular.iter().all(|v| v.is_finite() && *v >= 0.0));
        }
    }
}

#[test]
fn three_materials_end_to_end() {
    let s = scene(450, |v| (v * 7) % 3, 0.001, 0.01);
    let config = small_config();
    let a = augment(&s.set, &s.fits, &config);
    assert_eq!(a.partition.k, 3, "{:?}", a.partition);
    assert_eq!(a.clusters.len(), 3);
    assert_eq!(a.vertices_with_virtual_samples, 450, "{:?}", a.partition);
    // Each cluster is one material: its η and lobe match that material.
    for (v, &j) in a.assignment.iter().enumerate() {
        let c = &a.clusters[j.unwrap()];
        let m = &s.truth[v];
        assert!((c.eta - m.eta).abs() < 0.01, "{c:?} vs {m:?}");
        assert!(
            (c.sigma_s - m.sigma_s).abs() < 0.1 * m.sigma_s,
            "{c:?} vs {m:?}"
        );
        assert!((a.guides[v].sigma_s_floor - c.sigma_s / 2.0).abs() < 1e-15);
        assert_eq!(
            a.guides[v].lobe_start,
            Some([c.sigma_s, c.sigma_ss, c.rho_s])
        );
    }
    check_virtual_samples(&a, &config);
    // The first virtual sample is the cluster's coaxial peak, unclipped.
    let j = a.assignment[0].unwrap();
    let c = &a.clusters[j];
    let peak = virtual_samples::coaxial_profile(
        c.eta,
        c.sigma_s,
        c.sigma_ss,
        c.rho_s,
        c.rho_ss,
        config.profile_samples,
    )[0]
    .specular;
    assert_eq!(a.guides[0].virtual_samples[0].specular, peak);
    // Summary serialises without the per-vertex vectors.
    let json = serde_json::to_string(&a).unwrap();
    assert!(json.contains("\"clusters\"") && !json.contains("\"virtual_samples\""));
}

#[test]
fn deterministic_for_any_thread_count() {
    let s = scene(150, |v| v % 3, 0.001, 0.01);
    let config = small_config();
    let a = augment(&s.set, &s.fits, &config);
    let b = rayon::ThreadPoolBuilder::new()
        .num_threads(1)
        .build()
        .unwrap()
        .install(|| augment(&s.set, &s.fits, &config));
    assert_eq!(a, b);
}

#[test]
fn far_vertex_gets_no_virtual_samples_and_no_floor() {
    let mut s = scene(300, |v| v % 3, 0.0, 0.01);
    // One vertex whose joint fit says "a different material": far from every centroid.
    s.fits[5].params.rho_d = [3.0, 0.0, 3.0];
    s.fits[5].params.eta = 2.9;
    let a = augment(&s.set, &s.fits, &small_config());
    assert_eq!(a.clusters.len(), 3, "{:?}", a.partition);
    assert!(a.assignment[5].is_some());
    assert!(a.guides[5].virtual_samples.is_empty());
    assert_eq!(a.guides[5].sigma_s_floor, 0.0);
    assert_eq!(a.vertices_with_virtual_samples, 299);
    check_virtual_samples(&a, &small_config());
}

#[test]
fn one_material_still_gets_virtual_samples() {
    // λ₁ of a single material is noise only; the scale floor keeps vertices inside the kernel.
    let s = scene(200, |_| 0, 0.001, 0.01);
    let a = augment(&s.set, &s.fits, &small_config());
    assert!(!a.clusters.is_empty());
    assert_eq!(a.vertices_with_virtual_samples, 200, "{:?}", a.partition);
    for c in &a.clusters {
        assert!(
            (c.eta - 1.5).abs() < 0.01 && (c.sigma_s - 0.1).abs() < 0.01,
            "{c:?}"
        );
    }
}

#[test]
fn degenerate_inputs() {
    let config = small_config();
    // Every vertex flagged: no members, no clusters, nothing assigned.
    let mut s = scene(30, |v| v % 3, 0.0, 0.0);
    for f in &mut s.fits {
        f.flags.push(FitFlag::TooFewViews);
    }
    let a = augment(&s.set, &s.fits, &config);
    assert!(a.clusters.is_empty() && a.partition.members == 0);
    assert!(a.assignment.iter().all(Option::is_none));
    assert!(a.guides.iter().all(|g| g.virtual_samples.is_empty()));
    assert!(a.guides.iter().all(|g| g.sigma_s_floor == 0.0));
    // No fits at all, and fits that point past the mesh or are not finite.
    let mut bad = fit_of(99, materials()[0], [0.0, 0.0, 1.0]);
    bad.vertex = 99;
    let mut nan = fit_of(0, materials()[0], [0.0, 0.0, 1.0]);
    nan.params.eta = f64::NAN;
    let a = augment(&s.set, &[bad, nan], &config);
    assert!(a.clusters.is_empty() && a.assignment.iter().all(Option::is_none));
    // One vertex: one cluster below any useful size — no model, no panic.
    let one = scene(1, |_| 0, 0.0, 0.0);
    let a = augment(&one.set, &one.fits, &config);
    assert_eq!(a.partition.k, 1);
    assert!(a.clusters.len() <= 1);
    check_virtual_samples(&a, &config);
    // Identical features: a single cluster, every vertex at distance 0.
    let same = scene(60, |_| 1, 0.0, 0.0);
    let fixed = AugmentConfig {
        cluster: ClusterConfig {
            k: Some(4),
            ..ClusterConfig::default()
        },
        ..config.clone()
    };
    let a = augment(&same.set, &same.fits, &fixed);
    assert_eq!(a.partition.k, 1);
    assert_eq!(a.clusters.len(), 1);
    assert_eq!(a.vertices_with_virtual_samples, 60);
    check_virtual_samples(&a, &config);
    // An empty sample set.
    let empty = SampleSet {
        views: Vec::new(),
        colour: true,
        vertices: Vec::new(),
        rings: Vec::new(),
    };
    let a = augment(&empty, &[], &config);
    assert!(a.clusters.is_empty() && a.assignment.is_empty());
}

/// Issue 46 item 2: with a recorded noise inflated uniformly (`read_noise_e` 1000), every
/// vertex's data leave η at the default prior's start, yet its σ (scaled by s² = cost/(m − p),
/// which shrinks with the data rows) is small: such members pooled into η = 1.5000 ± 0.0004.
/// A pool most of whose members' data did not move η is no measurement; the same members with
/// data that did move it pool as before.
#[test]
fn a_pool_of_members_whose_data_did_not_move_eta_is_withheld() {
    let pooled = |prior_only: bool| {
        let mut s = scene(200, |_| 0, 0.001, 0.0);
        for (v, f) in s.fits.iter_mut().enumerate() {
            // the start value, with the small σ the inflated noise's s² gives (measured:
            // 0.003 to 0.0034 on a 24-photo sphere capture)
            f.params.eta = 1.5 + 1e-5 * ((v % 7) as f64 - 3.0);
            f.std_error[0] = 0.0032;
            f.eta_prior_only = prior_only;
        }
        let mut a = augment(&s.set, &s.fits, &small_config());
        pool_eta(&mut a, &s.set, &s.fits, [1.5, 0.5], 0.05);
        a.clusters.iter().any(|c| c.eta_pooled.usable)
    };
    assert!(pooled(false), "members whose data moved η pool");
    assert!(!pooled(true), "the start value repeated is no pooled η");
}

#[test]
fn a_vertex_is_labelled_only_where_its_own_eta_decides_its_material() {
    // Two materials of one colour (η 1.59 and 1.85) and one of another colour.
    let centroids: Vec<Feature> = vec![
        [2.0, 0.9, 0.1, 3.18],
        [2.0, 0.9, 0.1, 3.70],
        [0.2, 0.4, 1.8, 3.18],
    ];
    let groups = vec![0, 1, 2];
    let at = |eta: f64| [2.0, 0.9, 0.1, 2.0 * eta];
    // A well-measured η places the vertex.
    assert_eq!(
        confident_group(&at(1.85), 0.01, &centroids, &groups),
        Some(1)
    );
    assert_eq!(
        confident_group(&at(1.60), 0.01, &centroids, &groups),
        Some(0)
    );
    // An η whose interval reaches the midpoint between the two (1.72) does not.
    assert_eq!(confident_group(&at(1.66), 0.05, &centroids, &groups), None);
    // Unidentified η: between the two of its colour it is unlabelled…
    assert_eq!(
        confident_group(&at(1.5), f64::INFINITY, &centroids, &groups),
        None
    );
    // …and its colour alone places it where no other material has that colour.
    let blue = [0.2, 0.4, 1.8, 3.0];
    assert_eq!(
        confident_group(&blue, f64::INFINITY, &centroids, &groups),
        Some(2)
    );
    // Clusters of one group (a split of one material) never make a vertex ambiguous.
    assert_eq!(
        confident_group(&at(1.5), f64::INFINITY, &centroids, &[0, 0, 2]),
        Some(0)
    );
}
