//! The plots' font: DejaVu Sans from the `dejavu` crate, registered once with `plotters`
//! for every family it is asked for (no system fonts, fontconfig or freetype needed).

use std::sync::Once;

use plotters::style::{register_font, FontStyle};

static FONTS: Once = Once::new();

/// Registers the embedded font (once per process).
pub(crate) fn register_fonts() {
    FONTS.call_once(|| {
        for family in ["sans-serif", "serif", "monospace"] {
            // The font is a valid TTF shipped by the crate; failure would only lose text.
            let _ = register_font(family, FontStyle::Normal, dejavu::sans::regular());
        }
    });
}
