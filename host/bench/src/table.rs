//! Markdown tables of the bench reports: a table's head, its column names and the rule that
//! aligns each column, written from one list, so the two lines cannot disagree in count or
//! order (each report used to write both by hand).

/// How a column's cells sit.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Align {
    /// Text: `---`.
    Left,
    /// Numbers: `---:`.
    Right,
}

/// The head of a Markdown table: `| a | b |` and, on the next line, its rule `|---|---:|`
/// (`---:` for a [`Align::Right`] column); no newline at the end. A name is written as it is:
/// a `|` in it must come escaped (`\|`).
pub fn head<S: AsRef<str>>(columns: &[(S, Align)]) -> String {
    let mut names = String::from("|");
    let mut rule = String::from("|");
    for (name, align) in columns {
        names.push(' ');
        names.push_str(name.as_ref());
        names.push_str(" |");
        rule.push_str(match align {
            Align::Left => "---|",
            Align::Right => "---:|",
        });
    }
    format!("{names}\n{rule}")
}

#[cfg(test)]
mod tests {
    use super::Align::{Left as L, Right as R};
    use super::*;

    #[test]
    fn a_head_names_every_column_and_aligns_each_as_told() {
        assert_eq!(
            head(&[("scene", L), ("η (%)", R), ("largest \\|Δη\\|", R)]),
            "| scene | η (%) | largest \\|Δη\\| |\n|---|---:|---:|"
        );
        assert_eq!(head::<&str>(&[]), "|\n|");
    }
}
