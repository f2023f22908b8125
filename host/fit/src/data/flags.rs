//! The flags of a vertex's fit and the identifiability rule over them: [`FitFlag`] (with the
//! bit order every output's `flags` bitmask uses) and [`Identifiable`], which says from the
//! flags alone whether the outputs report the vertex's parameters and its η as measurements.

/// Why a vertex's result should not be trusted as is. A flagged vertex still carries finite
/// parameters inside their bounds.
#[derive(
    Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord, serde::Serialize, serde::Deserialize,
)]
#[serde(rename_all = "snake_case")]
pub enum FitFlag {
    /// Fewer samples than the minimum view count: parameters are the prior / cluster values.
    TooFewViews,
    /// Fewer samples than unknowns: the fit is under-determined.
    UnderDetermined,
    /// Every sample is dark: albedos are upper bounds, other parameters unidentified.
    Dark,
    /// Samples were saturated and dropped; what is left may bias the specular lobe.
    Saturated,
    /// All views near normal incidence: η is not identifiable (∂DoP/∂η ≈ 0).
    EtaUnidentifiable,
    /// All views grazing: normal and η poorly conditioned.
    GrazingOnly,
    /// A parameter sits at a bound (η at its floor, σ at its floor or 1).
    AtBound,
    /// The solver stopped at its iteration limit without converging.
    NotConverged,
    /// An albedo ended at the solver's cap: the data fixed only a product like ρ·σ², not the
    /// lobe, so no parameter of the vertex is reported as a measurement.
    AlbedoAtCap,
    /// The normal's standard error would exceed 180° (or is infinite): the data do not
    /// constrain the normal; outputs report 180°.
    NormalUnconstrained,
    /// η was fitted with the material's pooled η as a prior (the vertex's own estimate is kept
    /// in [`VertexFit::eta_unpooled`](super::VertexFit::eta_unpooled)).
    EtaPooled,
    /// No fitted frame saw the vertex lit: in every frame it was out of view, occluded or in the
    /// flash's shadow ([`GateCounts::seen_lit`](super::GateCounts::seen_lit) is 0) — what no
    /// view sees: the underside, the contact with the board. Its parameters are the prior's and
    /// its position follows its observed neighbours (docs/fit-shape.md "Surface update"). A
    /// vertex the views see but whose every sample a gate removed (mixed materials, grazing,
    /// dark, saturated) is only [`FitFlag::TooFewViews`].
    Unobserved,
    /// The views see the vertex, but its own samples do not identify every parameter: those
    /// they do not identify are its material's (the pooled η and its cluster's lobe; ρd its own
    /// where it has samples), with the material's spread as their standard error
    /// (`crate::complete`). Reported as values, never withheld: a vertex the views see always
    /// has a full parameter set.
    FromMaterial,
    /// The vertex's material has no identified η (its pool was weak — its standard error, the
    /// default prior's possible pull included, above the solver's limit — or it formed none):
    /// η is withheld, whatever [`FitFlag::FromMaterial`] completed of the rest is reported.
    MaterialEtaUnidentified,
}

/// The largest angular standard error an output reports, degrees: an angle's uncertainty cannot
/// exceed a half-turn; a larger value is reported as this with [`FitFlag::NormalUnconstrained`].
pub const MAX_REPORTED_ANGLE_STD_DEG: f64 = 180.0;

impl FitFlag {
    /// Every flag in the bit order of the `flags` bitmask every output writes (`fit.ply`'s
    /// `flags`, `maps.exr`'s `flags` channel, the view): bit k = `ALL[k]`. A new flag is one
    /// entry at the end (and one line in [`FitFlag::withholds_vertex`] or
    /// [`FitFlag::withholds_eta`] when it withholds values).
    pub const ALL: [FitFlag; 14] = [
        FitFlag::TooFewViews,
        FitFlag::UnderDetermined,
        FitFlag::Dark,
        FitFlag::Saturated,
        FitFlag::EtaUnidentifiable,
        FitFlag::GrazingOnly,
        FitFlag::AtBound,
        FitFlag::NotConverged,
        FitFlag::AlbedoAtCap,
        FitFlag::NormalUnconstrained,
        FitFlag::EtaPooled,
        FitFlag::Unobserved,
        FitFlag::FromMaterial,
        FitFlag::MaterialEtaUnidentified,
    ];

    /// This flag's bit in the bitmask ([`FitFlag::ALL`] order).
    pub fn bit(self) -> u32 {
        let k = Self::ALL.iter().position(|f| *f == self).unwrap_or(0);
        1 << k
    }

    /// The bitmask of `flags`.
    pub fn mask(flags: &[FitFlag]) -> u32 {
        flags.iter().fold(0, |m, f| m | f.bit())
    }

    /// The flags set in `mask` (unknown bits ignored).
    pub fn from_mask(mask: u32) -> Vec<FitFlag> {
        Self::ALL
            .iter()
            .copied()
            .filter(|f| mask & f.bit() != 0)
            .collect()
    }

    /// Whether this flag withholds every parameter of the vertex: no output reports them as a
    /// measurement (standard errors +inf, grey in every picture and in the view).
    pub fn withholds_vertex(self) -> bool {
        matches!(
            self,
            FitFlag::TooFewViews | FitFlag::AlbedoAtCap | FitFlag::Unobserved
        )
    }

    /// Whether this flag withholds η (standard error +inf, grey η maps), beyond
    /// [`FitFlag::withholds_vertex`].
    pub fn withholds_eta(self) -> bool {
        self.withholds_vertex()
            || matches!(
                self,
                FitFlag::EtaUnidentifiable | FitFlag::MaterialEtaUnidentified
            )
    }
}

/// The identifiability rule: what the outputs report of a vertex, from its flags alone
/// (`fit.ply`, `maps.exr`, the pictures and the view all call [`Identifiable::of_mask`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Identifiable {
    /// The vertex's parameters are measurements (drawn; finite standard errors where the
    /// covariance has them).
    pub vertex: bool,
    /// η is a measurement.
    pub eta: bool,
}

impl Identifiable {
    /// The rule over a flags bitmask ([`FitFlag::ALL`] bit order). [`FitFlag::FromMaterial`]
    /// lifts every withholding but [`FitFlag::Unobserved`]'s (and η's where the material has
    /// none, [`FitFlag::MaterialEtaUnidentified`]): what the vertex's data left open is its
    /// material's value, reported as such.
    pub fn of_mask(mask: u32) -> Self {
        let flags = FitFlag::from_mask(mask);
        if flags.contains(&FitFlag::FromMaterial) {
            let seen = !flags.contains(&FitFlag::Unobserved);
            return Self {
                vertex: seen,
                eta: seen && !flags.contains(&FitFlag::MaterialEtaUnidentified),
            };
        }
        Self {
            vertex: !flags.iter().any(|f| f.withholds_vertex()),
            eta: !flags.iter().any(|f| f.withholds_eta()),
        }
    }

    /// Standard errors as every output reports them: +inf for each parameter the rule
    /// withholds (η: index 0), the covariance's value otherwise.
    pub fn std_error(self, std_error: &[f64; 10]) -> [f64; 10] {
        std::array::from_fn(|k| {
            let withheld = !self.vertex || (k == 0 && !self.eta);
            if withheld {
                f64::INFINITY
            } else {
                std_error[k]
            }
        })
    }
}
