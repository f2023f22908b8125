//! A full parameter set for every vertex the views see: where a vertex's own samples do not
//! identify a parameter, it takes its material's value, flagged [`FitFlag::FromMaterial`], with
//! the material's spread as its standard error (docs/fit-augment.md "Every observed vertex").
//!
//! Why. The per-vertex solve needs `min_views` usable samples; a vertex the views see only
//! near a silhouette, behind a highlight or at a material boundary has fewer, and η needs
//! oblique views besides. Left withheld, those vertices are holes in every map and picture — a
//! quarter to a half of what the camera saw. Their material, though, is known from what the
//! rest of the object says about it, and their colour from their own samples.
//!
//! Contract:
//! - **Which vertices.** Every vertex the views see lit (not [`FitFlag::Unobserved`]) whose
//!   flags withhold its parameters ([`FitFlag::TooFewViews`], [`FitFlag::AlbedoAtCap`]) is
//!   *completed*; one whose flags withhold only η ([`FitFlag::EtaUnidentifiable`]) gets its
//!   material's η and keeps the rest. Vertices the fit identified are never touched. An
//!   unobserved vertex stays withheld.
//! - **Its material** ([`assign`], module `assign`): of the clusters its colour allows (every
//!   cluster when it has no sample), the one whose own-fit members are nearest along the mesh.
//!   So a vertex takes the material of its surroundings that its colour allows: two materials
//!   of one colour and different η stay where they lie, and a small patch of another colour
//!   keeps it. Where several materials of different η remain possible, its η's σ adds their
//!   spread about the chosen one ([`membership_sd`]): nearness is no evidence of η.
//! - **The material's values** ([`MaterialValues`], from the cluster's own-fit members): η the
//!   pooled one (`Pooled::mean`) with the predictive spread of a member √(se² + τ²), or, where
//!   no pool formed, the members' median η and robust spread — none where that spread exceeds
//!   the solver's per-vertex limit `max_eta_std_error`, the weak pool's rule (several materials
//!   the clustering joined have no one η); σs, σss, ρs, ρss the cluster's
//!   two-lobe model with the members' robust spread (1.4826·MAD) of their own values; ρd the
//!   members' median and robust spread, used only where the vertex has no sample.
//! - **Its own ρd** ([`own_rho_d`]): per colour channel the weighted least-squares albedo of its
//!   samples' observation channels with every other parameter the material's, at the surface's
//!   normal (weights N: the samples' inverse variance at a given model intensity); its standard
//!   error from the residuals (at least one sample gives three channels per colour). Clamped
//!   to [0, cap].
//! - **Its surroundings' own η** (module `local_eta`): the completed vertices of its material
//!   within two rings pool their kept samples into one η estimate (ρd refitted per vertex,
//!   the material's lobes, the normal profiled over its σ). Where that estimate is identified
//!   (σ within the per-vertex limit) and contradicts the material's η beyond
//!   `pool::AGREE_SIGMAS` combined standard deviations, the vertex reports it, with a σ that
//!   adds the gap between the two in quadrature (which of them is right, nothing here proves;
//!   counted in [`Completion::eta_local`]). A material without an identified η stays
//!   withheld: one estimate alone, this one, is not trusted at its own σ (measured on the
//!   development scenes: a median error of 4–5 times it).
//! - **Its normal** is the surface's (the refined mesh's), with `normal_std_deg` as its σ.
//! - A vertex without a material (no cluster: step B did not run or found none) completes
//!   nothing; it stays withheld and [`Completion::unassigned`] counts it. A material without an
//!   identified η (its pool weak or absent, `Pooled::weak`) completes everything but η, which
//!   stays withheld ([`FitFlag::MaterialEtaUnidentified`], counted in
//!   [`Completion::eta_withheld`]): the reason is the material's, named in the report.
//! - Deterministic: a function of its inputs, no randomness (the local curves run in parallel,
//!   one vertex each; everything else is serial over vertices).

mod assign;
mod diffuse;
mod local_eta;
mod report;
mod sigma;

pub use assign::{Assigned, assign, colour_within_reach, membership_sd};

pub use sigma::{MESH_NORMAL_MIN_VERTICES, mesh_normal_std_deg};

use ellipso_model::geometry::TriangleMesh;

use crate::augment::Augmentation;
use crate::data::{FitFlag, SampleSet, VertexFit};

/// What [`complete`] did, and what the fit covers of the surface the views see.
#[derive(Clone, Debug, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Completion {
    /// Vertices given their material's parameters (all but ρd where they had samples).
    pub completed: usize,
    /// Of those, with their own ρd from their samples.
    pub own_rho_d: usize,
    /// Vertices given only their material's η.
    pub eta_from_material: usize,
    /// Vertices that needed completing but had no material to take it from.
    pub unassigned: usize,
    /// Vertices that needed their material's η where the material has none identified
    /// ([`FitFlag::MaterialEtaUnidentified`]: the pool is weak or absent): η withheld, the
    /// rest completed.
    #[serde(default)]
    pub eta_withheld: usize,
    /// Of the vertices given their material's η, those whose colour allows more than one
    /// material of different η (or who have no sample to show a colour): their η's σ holds the
    /// spread over those materials ([`membership_sd`]).
    #[serde(default)]
    pub material_open: usize,
    /// Of the vertices that needed their material's η, those whose surroundings' own samples
    /// identify another η than the material's: η from those samples, its σ spanning both
    /// (`local_eta`, docs/fit-augment.md "Every vertex the views see").
    #[serde(default)]
    pub eta_local: usize,
    /// Vertices the views see (not [`FitFlag::Unobserved`]: in view, unoccluded and lit in at
    /// least one fitted frame, decided from the poses and the mesh, never from the gates).
    pub observed: usize,
    /// Of those, with a full parameter set (every parameter and η reported).
    pub full_set: usize,
    /// `full_set / observed` (NaN without an observed vertex).
    pub coverage: f64,
    /// Per material (cluster of step B, in the augmentation's order).
    pub materials: Vec<MaterialCoverage>,
    /// Each vertex's material (cluster index): its own cluster where the fit identified it,
    /// the one it was completed from otherwise (`None`: no material).
    #[serde(skip)]
    pub labels: Vec<Option<usize>>,
}

/// One material's share of the surface the views see (`Completion::materials`).
#[derive(Clone, Debug, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct MaterialCoverage {
    /// Cluster index.
    pub cluster: usize,
    /// The material's η (pooled), `null` where it has none (no pool, or a weak one).
    pub eta: Option<f64>,
    /// A from-material vertex's η standard error: `Pooled::se_reported` ⊕ the between-vertex τ.
    pub eta_se: Option<f64>,
    /// Where the material's η is withheld although its vertices pooled (`Pooled::weak`): the
    /// pool's standard error and, within it, the default prior's possible pull
    /// (`Pooled::prior_pull`) — the reason it is withheld.
    #[serde(default)]
    pub eta_withheld_se: Option<[f64; 2]>,
    /// Observed vertices of this material.
    pub observed: usize,
    /// Of those, fitted from their own samples.
    pub own: usize,
    /// Of those, with their material's values ([`FitFlag::FromMaterial`]).
    pub from_material: usize,
    /// Of those, without a full parameter set.
    pub withheld: usize,
    /// `(own + from_material) / observed`.
    pub coverage: f64,
}

/// One material's values and spreads, from its cluster's own-fit members.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct MaterialValues {
    /// η and its spread (`None`: no η for this material).
    pub eta: Option<[f64; 2]>,
    /// A weak pool's standard error and the prior's possible pull in it (η withheld).
    pub eta_withheld_se: Option<[f64; 2]>,
    /// σs, σss, ρs, ρss RGB (the cluster's lobe model).
    pub lobe: [f64; 6],
    /// Their spreads.
    pub lobe_spread: [f64; 6],
    /// Median ρd RGB of the members.
    pub rho_d: [f64; 3],
    /// Its spread.
    pub rho_d_spread: [f64; 3],
}

impl MaterialValues {
    /// `base` with this material's lobe model and η `eta` (ρd left as it is).
    pub fn params(
        &self,
        base: ellipso_model::optics::pbrdf::PbrdfParams<f64>,
        eta: f64,
    ) -> ellipso_model::optics::pbrdf::PbrdfParams<f64> {
        let mut params = base;
        params.eta = eta;
        params.sigma_s = self.lobe[0];
        params.sigma_ss = self.lobe[1].max(self.lobe[0]);
        params.rho_s = self.lobe[2];
        params.rho_ss = [self.lobe[3], self.lobe[4], self.lobe[5]];
        params
    }
}

/// Vertex `v`'s normal on the refined surface (`mesh`), or its fit's where the mesh has none.
fn surface_normal(mesh: &TriangleMesh, v: usize, f: &VertexFit) -> [f64; 3] {
    mesh.normals()
        .get(v)
        .map_or(f.normal_world, |n| n.into_inner().into())
}

/// 1.4826·MAD: the robust standard deviation (NaN below two values).
fn robust_sd(values: &mut [f64]) -> f64 {
    if values.len() < 2 {
        return f64::NAN;
    }
    ellipso_model::stats::robust_sigma(values)
}

fn median(values: &mut [f64]) -> f64 {
    ellipso_model::stats::median(values)
}

impl MaterialValues {
    /// The values of cluster `j` of `a` from its own-fit members' `fits`; a material η whose
    /// spread exceeds `max_eta_std_error` (the solver's per-vertex limit) is withheld.
    fn of_cluster(
        a: &Augmentation,
        j: usize,
        members: &[&VertexFit],
        max_eta_std_error: f64,
    ) -> Self {
        let c = &a.clusters[j];
        let column = |f: &dyn Fn(&VertexFit) -> f64| -> Vec<f64> {
            members
                .iter()
                .map(|m| f(m))
                .filter(|v| v.is_finite())
                .collect()
        };
        let spread = |f: &dyn Fn(&VertexFit) -> f64| robust_sd(&mut column(f));
        let mut members_sd = f64::NAN;
        let eta = if c.eta_pooled.usable {
            // A vertex that takes its material's η is a new member of the pool: its η is the
            // material's, uncertain by the pooled value's own standard error and the
            // members' between-vertex spread τ (0 on one homogeneous material; the spread of
            // what the pool mixed where it is not).
            let p = c.eta_pooled;
            Some([p.mean, p.tau.hypot(p.se_reported())])
        } else if c.eta_pooled.member_se_median.is_finite() && c.eta_pooled.vertices > 0 {
            // A pool that formed but is no measurement (weak, `Pooled::weak`): no η.
            None
        } else {
            let mut etas = column(&|m| {
                if m.eta_identified() {
                    m.params.eta
                } else {
                    f64::NAN
                }
            });
            let centre = median(&mut etas);
            let sd = robust_sd(&mut etas);
            members_sd = sd;
            // The rule of a weak pool (`Pooled::weak`): members that spread wider than what a
            // vertex may report are no measurement of one material's η — they are several
            // materials the clustering joined (measured on a generated scene at 612×512: seven
            // materials of η 1.33–2.37 in one cluster, spread 0.20, gave every completed vertex
            // η 2.26).
            (centre.is_finite() && sd.is_finite() && sd <= max_eta_std_error)
                .then_some([centre, sd])
        };
        let rho_d: [f64; 3] = std::array::from_fn(|k| median(&mut column(&|m| m.params.rho_d[k])));
        let p = c.eta_pooled;
        let eta_withheld_se = if eta.is_none() && p.vertices > 0 && p.se.is_finite() && p.se > 0.0 {
            Some([p.se_reported(), p.prior_pull])
        } else if eta.is_none() && members_sd.is_finite() {
            // No pool formed; the members' own spread withheld it (above).
            Some([members_sd, 0.0])
        } else {
            None
        };
        Self {
            eta,
            eta_withheld_se,
            lobe: [
                c.sigma_s,
                c.sigma_ss,
                c.rho_s,
                c.rho_ss[0],
                c.rho_ss[1],
                c.rho_ss[2],
            ],
            lobe_spread: [
                spread(&|m| m.params.sigma_s),
                spread(&|m| m.params.sigma_ss),
                spread(&|m| m.params.rho_s),
                spread(&|m| m.params.rho_ss[0]),
                spread(&|m| m.params.rho_ss[1]),
                spread(&|m| m.params.rho_ss[2]),
            ],
            rho_d,
            rho_d_spread: std::array::from_fn(|k| spread(&|m| m.params.rho_d[k])),
        }
    }
}

/// Whether the fit reports `f`'s parameters as its own (the identifiability rule before any
/// completion).
pub(crate) fn own_vertex(f: &VertexFit) -> bool {
    f.identifiable().vertex && !f.flags.contains(&FitFlag::FromMaterial)
}

/// The η a completed vertex `v` of material `j` takes: the material's `[η, σ]`, unless the
/// material's own identified vertices within two rings of it (`identified`: material, η, σ)
/// say otherwise — their inverse-variance weighted η disagrees with the material's beyond
/// [`crate::augment::pool::AGREE_SIGMAS`] combined standard deviations — as they do in a patch
/// of another η too small to be a cluster of its own: then theirs. Fewer than
/// [`crate::augment::pool::MIN_VERTICES`] such neighbours say nothing.
fn local_or(
    material: [f64; 2],
    rings: &[Vec<u32>],
    identified: &[Option<(usize, f64, f64)>],
    v: usize,
    j: usize,
) -> [f64; 2] {
    let (mut sw, mut swe, mut n) = (0.0, 0.0, 0usize);
    for u in crate::neighbours::within(rings, v, crate::augment::LOCAL_RINGS) {
        if let Some((k, eta, se)) = identified.get(u).copied().flatten()
            && k == j
            && se > 0.0
        {
            let w = 1.0 / (se * se);
            sw += w;
            swe += w * eta;
            n += 1;
        }
    }
    if n < crate::augment::pool::MIN_VERTICES || sw <= 0.0 {
        return material;
    }
    let (local, local_se) = (swe / sw, sw.sqrt().recip());
    let spread = (local_se * local_se + material[1] * material[1]).sqrt();
    if (local - material[0]).abs() > crate::augment::pool::AGREE_SIGMAS * spread {
        [local, local_se]
    } else {
        material
    }
}

/// The vertex's own ρd per colour channel and its standard error, with every other parameter
/// `params`'s at `normal` (module doc); `None` without a usable sample.
pub fn own_rho_d(
    set: &SampleSet,
    v: usize,
    params: &ellipso_model::optics::pbrdf::PbrdfParams<f64>,
    normal: [f64; 3],
    normal_std_deg: f64,
    albedo_cap: f64,
) -> Option<([f64; 3], [f64; 3])> {
    let vertex = set.vertices.get(v)?;
    let (rho, se) = rho_d_of(set, vertex, &vertex.samples, params, normal, albedo_cap)?;
    let tilt =
        sigma::normal_tilt_rho_d_se(set, vertex, params, normal, normal_std_deg, albedo_cap, rho);
    Some((rho, std::array::from_fn(|c| se[c].hypot(tilt[c]))))
}

/// [`own_rho_d`] from `samples` of `vertex`: the albedo and its standard error of
/// [`diffuse::fit`].
pub(crate) fn rho_d_of(
    set: &SampleSet,
    vertex: &crate::data::VertexSamples,
    samples: &[crate::data::Sample],
    params: &ellipso_model::optics::pbrdf::PbrdfParams<f64>,
    normal: [f64; 3],
    albedo_cap: f64,
) -> Option<([f64; 3], [f64; 3])> {
    diffuse::fit(set, vertex, samples, params, normal, albedo_cap).map(|d| (d.rho, d.se))
}

/// Completes `fits` (one per vertex of `set`, in order) from the materials of `a` (module doc).
/// `mesh` is the surface the fit ends on (its normals are the completed vertices' normals);
/// `normal_std_deg` is that surface's normal σ; `albedo_cap` and `max_eta_std_error` the
/// solver's.
pub fn complete(
    set: &SampleSet,
    fits: &mut [VertexFit],
    a: &Augmentation,
    mesh: &TriangleMesh,
    normal_std_deg: f64,
    albedo_cap: f64,
    max_eta_std_error: f64,
) -> Completion {
    let k = a.clusters.len();
    let mut report = Completion::default();
    let needs_all: Vec<bool> = fits
        .iter()
        .map(|f| !f.flags.contains(&FitFlag::Unobserved) && !own_vertex(f))
        .collect();
    let needs_eta: Vec<bool> = fits
        .iter()
        .map(|f| own_vertex(f) && !f.identifiable().eta)
        .collect();
    let needs: Vec<bool> = needs_all
        .iter()
        .zip(&needs_eta)
        .map(|(a, b)| *a || *b)
        .collect();
    let materials: Vec<MaterialValues> = (0..k)
        .map(|j| {
            let members: Vec<&VertexFit> = fits
                .iter()
                .enumerate()
                .filter(|(v, f)| a.assignment.get(*v) == Some(&Some(j)) && own_vertex(f))
                .map(|(_, f)| f)
                .collect();
            MaterialValues::of_cluster(a, j, &members, max_eta_std_error)
        })
        .collect();
    let own_colour = |v: usize, j: usize| {
        let m = &materials[j];
        let f = &fits[v];
        let params = m.params(f.params, m.eta.map_or(f.params.eta, |e| e[0]));
        let normal = surface_normal(mesh, v, f);
        own_rho_d(set, v, &params, normal, normal_std_deg, albedo_cap)
    };
    let labels = assign(fits, a, mesh, &needs, own_colour);
    let rings = crate::neighbours::rings(mesh);
    // What the fit identified of η, and its material, before any completion.
    let identified = identified_eta(fits, a);
    // What the completed vertices' own samples say of η around each of them (`local_eta`).
    let curves = local_eta::Curves::new(set, albedo_cap, |v| {
        if !needs.get(v).copied().unwrap_or(false) {
            return None;
        }
        let j = labels.get(v)?.as_ref()?.material;
        // A material without η takes none from its surroundings (`eta_or_local`).
        materials[j].eta?;
        let f = &fits[v];
        if needs_eta[v] {
            Some((f.params, f.normal_world, f.normal_std_error_deg))
        } else {
            Some((
                materials[j].params(f.params, f.params.eta),
                surface_normal(mesh, v, f),
                normal_std_deg,
            ))
        }
    });
    let material_of = |u: usize| labels.get(u).and_then(|l| l.as_ref().map(|a| a.material));
    for v in 0..fits.len() {
        if !needs[v] {
            continue;
        }
        let Some(Assigned {
            material: j,
            candidates,
        }) = &labels[v]
        else {
            report.unassigned += 1;
            continue;
        };
        let j = *j;
        let m = &materials[j];
        // Its surroundings' own samples, where they identify η (`local_eta`).
        let local = curves
            .local(&rings, v, j, material_of)
            .filter(|l| l[1] <= max_eta_std_error);
        let material_eta = m.eta.map(|material| {
            let [eta, sd] = local_or(material, &rings, &identified, v, j);
            // Which of its candidate materials the vertex is of, its data do not say: η's σ
            // carries that (`assign` module doc, "How sure").
            let open = membership_sd(eta, candidates, &materials);
            [eta, sd, open]
        });
        let material_eta = eta_or_local(material_eta, local, &mut report);
        let f = &mut fits[v];
        // A material without an identified η completes the rest; η stays withheld, flagged.
        let [eta, eta_sd] = material_eta.unwrap_or([f.params.eta, f64::INFINITY]);
        if material_eta.is_none() {
            report.eta_withheld += 1;
            if needs_eta[v] {
                // Its own data identified everything else: only η is missing, and stays so.
                continue;
            }
            f.flags.push(FitFlag::MaterialEtaUnidentified);
        }
        if needs_eta[v] {
            f.params.eta = eta;
            f.std_error[0] = eta_sd;
            f.flags.push(FitFlag::FromMaterial);
            report.eta_from_material += 1;
            continue;
        }
        let normal = surface_normal(mesh, v, f);
        let mut params = m.params(f.params, eta);
        let (rho_d, rho_d_se) = match own_rho_d(set, v, &params, normal, normal_std_deg, albedo_cap)
        {
            Some(own) => {
                report.own_rho_d += 1;
                own
            }
            None => (m.rho_d, m.rho_d_spread),
        };
        params.rho_d = rho_d;
        f.params = params;
        f.normal_world = normal;
        f.normal_std_error_deg = normal_std_deg;
        f.std_error = [
            eta_sd,
            m.lobe_spread[0],
            m.lobe_spread[1],
            m.lobe_spread[2],
            m.lobe_spread[3],
            m.lobe_spread[4],
            m.lobe_spread[5],
            rho_d_se[0],
            rho_d_se[1],
            rho_d_se[2],
        ];
        f.flags.push(FitFlag::FromMaterial);
        f.flags.sort();
        f.flags.dedup();
        report.completed += 1;
    }
    let labels = labels.into_iter().map(|l| l.map(|l| l.material)).collect();
    tally(&mut report, fits, a, labels, &materials);
    report
}

/// Per vertex, its material (cluster) and η with its σ where the fit identified η from its
/// own samples, before any completion.
fn identified_eta(fits: &[VertexFit], a: &Augmentation) -> Vec<Option<(usize, f64, f64)>> {
    fits.iter()
        .enumerate()
        .map(|(v, f)| {
            let j = a.assignment.get(v).copied().flatten()?;
            (own_vertex(f) && f.identifiable().eta && f.std_error[0].is_finite()).then_some((
                j,
                f.params.eta,
                f.std_error[0],
            ))
        })
        .collect()
}

/// The η a completed vertex reports: its material's `[η, σ, membership spread]` (the spread
/// widening σ, counted in `material_open`), unless its surroundings' own estimate `local`
/// contradicts it beyond [`crate::augment::pool::AGREE_SIGMAS`] combined standard deviations
/// — then that estimate, with a σ that spans the gap between the two (which of them is
/// right, nothing here proves; `local_eta` module doc), counted in `eta_local`. `None` where
/// the material has no η: one estimate alone is not trusted at its own σ.
fn eta_or_local(
    material: Option<[f64; 3]>,
    local: Option<[f64; 2]>,
    report: &mut Completion,
) -> Option<[f64; 2]> {
    let [eta, sd, open] = material?;
    if let Some([l, l_se]) = local
        && (l - eta).abs() > crate::augment::pool::AGREE_SIGMAS * sd.hypot(l_se)
    {
        report.eta_local += 1;
        let gap = (l - eta).abs().max(open);
        return Some([l, l_se.hypot(gap)]);
    }
    if open > 0.0 {
        report.material_open += 1;
    }
    Some([eta, sd.hypot(open)])
}

/// The coverage figures of `report` (module doc of [`Completion`]) after completion.
fn tally(
    report: &mut Completion,
    fits: &[VertexFit],
    a: &Augmentation,
    completed_from: Vec<Option<usize>>,
    materials: &[MaterialValues],
) {
    let k = a.clusters.len();
    report.materials = (0..k)
        .map(|j| MaterialCoverage {
            cluster: j,
            eta: materials[j].eta.map(|e| e[0]),
            eta_se: materials[j].eta.map(|e| e[1]),
            eta_withheld_se: materials[j].eta_withheld_se,
            ..Default::default()
        })
        .collect();
    report.labels = fits
        .iter()
        .enumerate()
        .map(|(v, f)| {
            if f.flags.contains(&FitFlag::FromMaterial) {
                completed_from[v]
            } else {
                a.assignment.get(v).copied().flatten()
            }
        })
        .collect();
    for (f, label) in fits.iter().zip(&report.labels) {
        if f.flags.contains(&FitFlag::Unobserved) {
            continue;
        }
        report.observed += 1;
        let full = f.identifiable().vertex && f.identifiable().eta;
        report.full_set += usize::from(full);
        if let Some(m) = label.and_then(|j| report.materials.get_mut(j)) {
            m.observed += 1;
            if !full {
                m.withheld += 1;
            } else if f.flags.contains(&FitFlag::FromMaterial) {
                m.from_material += 1;
            } else {
                m.own += 1;
            }
        }
    }
    let ratio = |a: usize, b: usize| {
        if b == 0 {
            f64::NAN
        } else {
            a as f64 / b as f64
        }
    };
    report.coverage = ratio(report.full_set, report.observed);
    for m in &mut report.materials {
        m.coverage = ratio(m.own + m.from_material, m.observed);
    }
}
