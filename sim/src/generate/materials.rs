//! The table of real materials the scene generator draws from: each row a material whose
//! refractive index was measured, with the measurement it comes from.
//!
//! Contract: [`TABLE`] holds rows with η in [`ETA_RANGE`] (the range issue 42 asks the bench to
//! span), each with a citation of the measurement (the refractiveindex.info page that tabulates
//! it, and the paper or catalogue behind it). η is the value at the sodium D line (589 nm) or
//! the nearest tabulated wavelength, to three decimals; birefringent crystals give the ordinary
//! index. Only η comes from the table: the surface finish (roughness, albedo, colour) of a
//! generated material is drawn by the generator, since the same substance can be polished or
//! matte, clear-coated over any pigment.

/// One measured material.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TableMaterial {
    /// Short name (a scene's material key: lower case, underscores).
    pub name: &'static str,
    /// Refractive index at ≈ 589 nm.
    pub eta: f64,
    /// Where the value was measured (refractiveindex.info page and its primary source).
    pub source: &'static str,
}

/// The η range the table spans, inclusive (issue 42: 1.3–2.4; diamond, 2.417, is the classic
/// high-index dielectric the brief names and is kept at its measured value).
pub const ETA_RANGE: [f64; 2] = [1.30, 2.42];

/// The measured materials (module doc).
pub const TABLE: &[TableMaterial] = &[
    TableMaterial {
        name: "water_film",
        eta: 1.333,
        source: "refractiveindex.info H2O (water): Hale & Querry 1973, Appl. Opt. 12, 555",
    },
    TableMaterial {
        name: "magnesium_fluoride",
        eta: 1.378,
        source: "refractiveindex.info MgF2 (ordinary): Dodge 1984, Appl. Opt. 23, 1980",
    },
    TableMaterial {
        name: "calcium_fluoride",
        eta: 1.434,
        source: "refractiveindex.info CaF2: Malitson 1963, Appl. Opt. 2, 1103",
    },
    TableMaterial {
        name: "fused_silica",
        eta: 1.458,
        source: "refractiveindex.info SiO2 (fused silica): Malitson 1965, JOSA 55, 1205",
    },
    TableMaterial {
        name: "pmma",
        eta: 1.491,
        source: "refractiveindex.info PMMA: Sultanova et al. 2009, Acta Phys. Pol. A 116, 585",
    },
    TableMaterial {
        name: "acrylic_paint",
        eta: 1.491,
        source: "TiO2-pigmented acrylic paint, specular from its PMMA binder: refractiveindex.info \
                 PMMA, Sultanova et al. 2009, Acta Phys. Pol. A 116, 585",
    },
    TableMaterial {
        name: "bk7_glass",
        eta: 1.517,
        source: "refractiveindex.info SCHOTT N-BK7: SCHOTT optical glass data sheets (n_d 1.5168)",
    },
    TableMaterial {
        name: "soda_lime_glaze",
        eta: 1.524,
        source: "ceramic glaze as soda-lime glass: refractiveindex.info soda-lime glass, Rubin \
                 1985, Sol. Energy Mater. 12, 275",
    },
    TableMaterial {
        name: "polycarbonate",
        eta: 1.585,
        source: "refractiveindex.info PC: Sultanova et al. 2009, Acta Phys. Pol. A 116, 585",
    },
    TableMaterial {
        name: "polystyrene",
        eta: 1.590,
        source: "refractiveindex.info PS: Sultanova et al. 2009, Acta Phys. Pol. A 116, 585",
    },
    TableMaterial {
        name: "sapphire",
        eta: 1.768,
        source: "refractiveindex.info Al2O3 (ordinary): Malitson & Dodge 1972, JOSA 62, 1405",
    },
    TableMaterial {
        name: "sf11_glass",
        eta: 1.785,
        source: "refractiveindex.info SCHOTT N-SF11: SCHOTT optical glass data sheets (n_d 1.7847)",
    },
    TableMaterial {
        name: "yag",
        eta: 1.831,
        source: "refractiveindex.info Y3Al5O12: Zelmon et al. 1998, Appl. Opt. 37, 4933",
    },
    TableMaterial {
        name: "lasf9_glass",
        eta: 1.850,
        source: "refractiveindex.info SCHOTT N-LASF9: SCHOTT optical glass data sheets (n_d 1.8503)",
    },
    TableMaterial {
        name: "silicon_nitride",
        eta: 2.022,
        source: "refractiveindex.info Si3N4: Luke et al. 2015, Opt. Lett. 40, 4823",
    },
    TableMaterial {
        name: "cubic_zirconia",
        eta: 2.159,
        source: "refractiveindex.info ZrO2 (Y2O3-stabilised): Wood & Nassau 1982, Appl. Opt. 21, \
                 2978",
    },
    TableMaterial {
        name: "lithium_niobate",
        eta: 2.300,
        source: "refractiveindex.info LiNbO3 (ordinary): Zelmon et al. 1997, JOSA B 14, 3319",
    },
    TableMaterial {
        name: "zinc_sulfide",
        eta: 2.368,
        source: "refractiveindex.info ZnS (cubic): Debenham 1984, Appl. Opt. 23, 2238",
    },
    TableMaterial {
        name: "diamond",
        eta: 2.417,
        source: "refractiveindex.info C (diamond): Phillip & Taft 1964, Phys. Rev. 136, A1445",
    },
];

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_row_is_in_range_cited_and_unique() {
        assert!(TABLE.len() >= 8, "a scene draws up to 8 distinct rows");
        for (i, m) in TABLE.iter().enumerate() {
            assert!(
                (ETA_RANGE[0]..=ETA_RANGE[1]).contains(&m.eta),
                "{} η {}",
                m.name,
                m.eta
            );
            assert!(m.source.len() > 20, "{} cites its source", m.name);
            assert!(
                TABLE[..i].iter().all(|o| o.name != m.name),
                "{} listed twice",
                m.name
            );
        }
        let etas: Vec<f64> = TABLE.iter().map(|m| m.eta).collect();
        assert!(etas.iter().any(|&e| e < 1.4) && etas.iter().any(|&e| e > 2.3));
    }
}
