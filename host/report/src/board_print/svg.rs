//! The board drawing as SVG: the page sized in millimetres, one user unit per millimetre, so
//! any viewer or printer that honours the size prints at exact scale.

use std::fmt::Write as _;

use super::Drawing;

/// Escapes text for an XML text node.
fn xml_escape(s: &str) -> String {
    s.replace('&', "&amp;")
        .replace('<', "&lt;")
        .replace('>', "&gt;")
}

/// The SVG document of `drawing`.
pub fn to_svg(drawing: &Drawing) -> String {
    let [w, h] = drawing.paper_mm;
    let mut s = String::new();
    // writing into a String cannot fail
    let _ = writeln!(
        s,
        r##"<?xml version="1.0" encoding="UTF-8"?>
<svg xmlns="http://www.w3.org/2000/svg" width="{w}mm" height="{h}mm" viewBox="0 0 {w} {h}">
<rect x="0" y="0" width="{w}" height="{h}" fill="#fff"/>"##
    );
    let _ = write!(s, r##"<path fill="#000" d=""##);
    for q in &drawing.quads {
        let [a, b, c, d] = q.0;
        let _ = write!(
            s,
            "M{:.4} {:.4}L{:.4} {:.4}L{:.4} {:.4}L{:.4} {:.4}Z",
            a[0], a[1], b[0], b[1], c[0], c[1], d[0], d[1]
        );
    }
    let _ = writeln!(s, r#""/>"#);
    for t in &drawing.texts {
        let _ = writeln!(
            s,
            r#"<text x="{:.3}" y="{:.3}" font-family="Helvetica, Arial, sans-serif" font-size="{:.3}">{}</text>"#,
            t.x_mm,
            t.baseline_mm,
            t.size_mm,
            xml_escape(&t.text)
        );
    }
    s.push_str("</svg>\n");
    s
}
