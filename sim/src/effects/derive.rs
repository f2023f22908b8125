//! Deriving a scene's [`EffectPlan`] (rules in the [`crate::effects`] module doc): the content
//! stages from what the scene holds, then the sensor and fault stages from what its `[effects]`
//! lists. Stages are pushed in pipeline order; every stage left out gets its reason.

use super::{EffectPlan, LightTransport, OmittedStage, Origin, PlannedStage, Stage, StageParams};
use crate::scene::{EffectsSpec, MaterialBinding, ObjectGeometry, Scene};

/// What the scene content contains, as far as planning cares.
#[derive(Clone, Copy, Debug, Default)]
struct Content {
    diffuse_object: bool,
    specular: bool,
    single_scattering: bool,
    surfaces: usize,
    has_mesh: bool,
}

fn content_of(scene: &Scene) -> Content {
    let mut c = Content {
        surfaces: scene.objects.len() + scene.boards.len(),
        ..Content::default()
    };
    for o in &scene.objects {
        c.has_mesh |= matches!(o.geometry, ObjectGeometry::Mesh(_));
        let ids: Vec<usize> = match &o.material {
            MaterialBinding::Uniform(id) => vec![*id],
            MaterialBinding::Regions { by_region, .. } => by_region.clone(),
        };
        for id in ids {
            let Some(m) = scene.materials.get(id) else {
                continue;
            };
            let p = &m.params;
            c.diffuse_object |= p.rho_d.iter().any(|&r| r > 0.0);
            c.specular |= p.rho_s > 0.0;
            c.single_scattering |= p.rho_ss.iter().any(|&r| r > 0.0);
        }
    }
    c
}

/// A content stage's decision: whether it is in, the reason if in, the reason if out.
type Decision = (bool, String, String);

/// The decision on each content stage, in pipeline order, from the scene content, the number of
/// boards, whether the camera has analysers and whether the flash is polarised.
fn content_decisions(
    c: &Content,
    boards: usize,
    analysers: bool,
    polarised_flash: bool,
) -> [(Stage, Decision); 7] {
    let content = |on: bool, why_in: String, why_out: &str| (on, why_in, why_out.to_string());
    [
        (
            Stage::Diffuse,
            content(
                c.diffuse_object || boards > 0,
                match (c.diffuse_object, boards) {
                    (true, 0) => "an object material has rho_d > 0".into(),
                    (true, _) => format!(
                        "an object material has rho_d > 0; {boards} board(s) of matte paper"
                    ),
                    _ => format!("{boards} board(s) of matte paper"),
                },
                "no material with rho_d > 0 and no boards",
            ),
        ),
        (
            Stage::DiffusePolarisation,
            content(
                analysers && c.diffuse_object,
                "the camera has analysers and an object material has rho_d > 0".into(),
                if analysers {
                    "no object material with rho_d > 0 (boards are depolarising paper)"
                } else {
                    "S0-only camera (rig.camera.analysers = false): polarisation is not observed"
                },
            ),
        ),
        (
            Stage::Specular,
            content(
                c.specular,
                "an object material has rho_s > 0".into(),
                "every object material has rho_s = 0",
            ),
        ),
        (
            Stage::SingleScattering,
            content(
                c.single_scattering,
                "an object material has rho_ss > 0".into(),
                "every object material has rho_ss = 0",
            ),
        ),
        (
            Stage::Polarisation,
            content(
                analysers,
                if polarised_flash {
                    "the camera has analysers; polarised flash (Stokes transport, per-pixel analyser)".into()
                } else {
                    "the camera has analysers; unpolarised flash, but surfaces polarise (Stokes transport)".into()
                },
                if polarised_flash {
                    "S0-only camera: only row 0 of P is evaluated (no Mueller work)"
                } else {
                    "S0-only camera and unpolarised flash: scalar BRDF only (no Mueller work)"
                },
            ),
        ),
        (
            Stage::Shadows,
            content(
                c.surfaces >= 2 || c.has_mesh,
                if c.has_mesh {
                    "a mesh object can shadow itself and others".into()
                } else {
                    format!("{} surfaces can shadow one another", c.surfaces)
                },
                "a single convex analytic surface cannot shadow itself",
            ),
        ),
        (
            Stage::FlashFalloff,
            content(true, "point flash: 1/d² and its angular profile".into(), ""),
        ),
    ]
}

/// The parameters `[effects]` gives a listed stage ([`StageParams::None`] for a stage without
/// parameters).
fn listed_params(e: &EffectsSpec, stage: Stage) -> StageParams {
    match stage {
        Stage::ReadNoise => e.read_noise.map(StageParams::ReadNoise),
        Stage::Vignetting => e.vignetting.map(StageParams::Vignetting),
        Stage::PolariserExtinction => e.polariser_extinction.map(StageParams::PolariserExtinction),
        Stage::AnalyserErrors => e.analyser_errors.map(StageParams::AnalyserErrors),
        Stage::Prnu => e.prnu.map(StageParams::Prnu),
        Stage::BlackLevel => e.black_level.map(StageParams::BlackLevel),
        Stage::HotPixels => e.hot_pixels.map(StageParams::HotPixels),
        Stage::FlashPolariserError => e
            .flash_polariser_error
            .map(StageParams::FlashPolariserError),
        Stage::FlashProfileError => e.flash_profile_error.map(StageParams::FlashProfileError),
        Stage::MotionBlur => e.motion_blur.map(StageParams::MotionBlur),
        Stage::TriggerJitter => e.trigger_jitter.map(StageParams::TriggerJitter),
        Stage::FrameDrops => e.frame_drops.map(StageParams::FrameDrops),
        Stage::LinkCorruption => e.link_corruption.map(StageParams::LinkCorruption),
        Stage::LinkDisconnect => e.link_disconnect.map(StageParams::LinkDisconnect),
        _ => None,
    }
    .unwrap_or(StageParams::None)
}

impl EffectPlan {
    /// Derives the plan of `scene` (rules in the [`crate::effects`] module doc).
    pub fn from_scene(scene: &Scene) -> EffectPlan {
        let c = content_of(scene);
        let camera = &scene.rig.camera;
        let analysers = camera.analysers;
        let polarised_flash = scene.rig.flash.polarised;
        let transport = match (analysers, polarised_flash) {
            (true, _) => LightTransport::Stokes,
            (false, false) => LightTransport::Scalar,
            (false, true) => LightTransport::IntensityOfPolarised,
        };
        let mut plan = EffectPlan {
            scene: scene.name.clone().unwrap_or_else(|| {
                scene
                    .source
                    .file_stem()
                    .map(|s| s.to_string_lossy().into_owned())
                    .unwrap_or_default()
            }),
            transport,
            stages: Vec::new(),
            omitted: Vec::new(),
        };
        let boards = scene.boards.len();
        plan.push_content(content_decisions(&c, boards, analysers, polarised_flash));
        plan.push_listed(&scene.effects);
        plan
    }

    /// Puts each content stage in the plan or among the omitted, as its decision says.
    fn push_content(&mut self, derived: [(Stage, Decision); 7]) {
        for (stage, (on, why_in, why_out)) in derived {
            if on {
                self.stages.push(PlannedStage {
                    stage,
                    executor: stage.executor(),
                    origin: Origin::Content,
                    reason: why_in,
                    params: StageParams::None,
                });
            } else {
                self.omitted.push(OmittedStage {
                    stage,
                    reason: why_out,
                });
            }
        }
    }

    /// Puts each listable stage (from vignetting on, in pipeline order) in the plan when `e`
    /// lists it — except motion blur with both speeds zero — and among the omitted otherwise.
    fn push_listed(&mut self, e: &EffectsSpec) {
        let listed = e.listed();
        for stage in &Stage::ALL[Stage::Vignetting.index()..] {
            if !listed.iter().any(|k| Stage::from_effect(*k) == *stage) {
                self.omitted.push(OmittedStage {
                    stage: *stage,
                    reason: format!("not listed in [effects] ({} absent)", stage.name()),
                });
                continue;
            }
            let params = listed_params(e, *stage);
            if let StageParams::MotionBlur(m) = params
                && !(m.linear_speed_m_per_s > 0.0 || m.angular_speed_deg_per_s > 0.0)
            {
                self.omitted.push(OmittedStage {
                    stage: *stage,
                    reason: "listed, but both speeds are zero: a static rig has no motion blur"
                        .into(),
                });
                continue;
            }
            self.stages.push(PlannedStage {
                stage: *stage,
                executor: stage.executor(),
                origin: Origin::Listed,
                reason: format!("listed in [effects] ({})", stage.name()),
                params,
            });
        }
    }
}
