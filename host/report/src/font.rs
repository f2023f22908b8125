//! The one font every picture uses: DejaVu Sans (a subset: Latin, Greek, arrows, super- and
//! subscripts, mathematical operators), compiled into the binary and registered with plotters'
//! `ab_glyph` text renderer, so no picture depends on the fonts of the machine it is drawn on.
//!
//! Contract: [`ensure_registered`] is cheap and idempotent; every drawing entry point of this
//! crate calls it before drawing text. Text is drawn through [`FAMILY`]. The font's licence is
//! `host/report/fonts/LICENSE-DejaVu.txt`.

use std::sync::OnceLock;

use plotters::style::FontStyle;

/// The font family name text styles use.
pub const FAMILY: &str = "sans-serif";

static FONT_TTF: &[u8] = include_bytes!("../fonts/DejaVuSans-subset.ttf");

/// Registers the bundled font with plotters (once per process).
///
/// # Panics
/// Never for the bundled file (a unit test parses it); a corrupt build would panic here.
pub fn ensure_registered() {
    static DONE: OnceLock<()> = OnceLock::new();
    DONE.get_or_init(|| {
        if plotters::style::register_font(FAMILY, FontStyle::Normal, FONT_TTF).is_err() {
            panic!("the bundled font host/report/fonts/DejaVuSans-subset.ttf does not parse");
        }
    });
}

#[cfg(test)]
mod tests {
    use plotters::style::{FontDesc, FontFamily};

    #[test]
    fn bundled_font_has_the_symbols_our_labels_use() {
        super::ensure_registered();
        let font = FontDesc::new(
            FontFamily::Name(super::FAMILY),
            20.0,
            super::FontStyle::Normal,
        );
        let w = |s: &str| font.box_size(s).expect("layout").0;
        // A glyph the subset lacks has no advance: each of these must take space.
        for s in ["η", "σ", "ρ", "°", "±", "×", "≤", "√", "²", "→", "−"] {
            assert!(w(s) > 3, "{s} has no glyph");
        }
        assert!(w("ηηηη") > 3 * w("η"));
    }
}
