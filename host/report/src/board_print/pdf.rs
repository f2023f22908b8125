//! The board drawing as a one-page PDF (through `pdf-writer`): the media box is the paper in
//! points (72 per inch), so printing at 100 % gives exact scale. Text uses the viewer's built-in
//! Helvetica (one of the 14 standard fonts: nothing embedded).

use pdf_writer::{Content, Finish, Name, Pdf, Rect, Ref, Str};

use super::Drawing;

/// Points per millimetre.
const PT_PER_MM: f64 = 72.0 / 25.4;

/// The PDF file of `drawing`.
pub fn to_pdf(drawing: &Drawing) -> Vec<u8> {
    let [w_mm, h_mm] = drawing.paper_mm;
    // sheet mm (y down) to PDF points (y up)
    let pt = |p: [f64; 2]| {
        (
            (p[0] * PT_PER_MM) as f32,
            ((h_mm - p[1]) * PT_PER_MM) as f32,
        )
    };
    let (catalog_id, tree_id, page_id, font_id, content_id) = (
        Ref::new(1),
        Ref::new(2),
        Ref::new(3),
        Ref::new(4),
        Ref::new(5),
    );
    let font = Name(b"F1");
    let mut pdf = Pdf::new();
    pdf.catalog(catalog_id).pages(tree_id);
    pdf.pages(tree_id).kids([page_id]).count(1);
    let mut page = pdf.page(page_id);
    page.media_box(Rect::new(
        0.0,
        0.0,
        (w_mm * PT_PER_MM) as f32,
        (h_mm * PT_PER_MM) as f32,
    ));
    page.parent(tree_id);
    page.contents(content_id);
    page.resources().fonts().pair(font, font_id);
    page.finish();
    pdf.type1_font(font_id).base_font(Name(b"Helvetica"));
    let mut content = Content::new();
    content.set_fill_gray(0.0);
    for q in &drawing.quads {
        let [a, b, c, d] = q.0.map(pt);
        content.move_to(a.0, a.1);
        content.line_to(b.0, b.1);
        content.line_to(c.0, c.1);
        content.line_to(d.0, d.1);
        content.close_path();
    }
    content.fill_nonzero();
    for t in &drawing.texts {
        let (x, y) = pt([t.x_mm, t.baseline_mm]);
        content.begin_text();
        content.set_font(font, (t.size_mm * PT_PER_MM) as f32);
        content.next_line(x, y);
        content.show(Str(t.text.as_bytes()));
        content.end_text();
    }
    pdf.stream(content_id, &content.finish());
    pdf.finish()
}
