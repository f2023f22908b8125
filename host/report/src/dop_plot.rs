//! The docs' plot of the model's degree of polarisation (`ellipso model plot`, [`dop_plot`]):
//! diffuse DoP against the exit angle and specular DoP against the incidence angle for four
//! refractive indices, from `ellipso_model::optics` (the numbers the simulator and the fit use).

use ellipso_model::optics::FresnelTerms;
use ellipso_model::optics::measure::dop_diffuse_with_d_eta;

use crate::plot::PALETTE;
use crate::{LegendPosition, LinePlot, Stroke};

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

    #[test]
    fn dop_plot_renders() {
        let c = dop_plot().render().unwrap();
        assert_eq!((c.width(), c.height()), (1100, 720));
    }
}
