//! A flash-energy bracket written as text (`--bracket 1,0.25,0.0625`): 1 to 8 comma-separated
//! relative energies, each in (0, 1], fired in the order given ([`Bracket::from_relative`] holds
//! the range rules and names what breaks them).

use ellipso_protocol::Bracket;

/// Parses `1,0.25,0.0625`: each step a number (spaces around it allowed), then the
/// [`Bracket::from_relative`] rules; an empty bracket is refused.
pub fn parse_bracket(s: &str) -> Result<Bracket, String> {
    let energies = s
        .split(',')
        .map(|v| {
            let v = v.trim();
            v.parse::<f64>()
                .map_err(|e| format!("'{v}' is not a number: {e}"))
        })
        .collect::<Result<Vec<f64>, String>>()?;
    let bracket = Bracket::from_relative(&energies).map_err(|e| e.to_string())?;
    if bracket.is_empty() {
        return Err("a bracket needs at least one step".into());
    }
    Ok(bracket)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn bracket_text_keeps_its_order_and_names_what_is_wrong() {
        let b = parse_bracket("1, 0.25,0.0625").unwrap();
        assert_eq!(b.steps_q15(), [0x8000, 0x2000, 0x0800]);
        let any_order = parse_bracket("0.25,1,0.5").unwrap();
        assert_eq!(any_order.steps_q15(), [0x2000, 0x8000, 0x4000]);
        for (bad, fragment) in [
            ("", "not a number"),
            ("1,,0.5", "not a number"),
            ("1,x", "'x' is not a number"),
            ("1,0", "step 1 is 0"),
            ("1.5", "(0, 1]"),
            ("-0.5", "(0, 1]"),
            ("nan", "(0, 1]"),
            ("1,1,1,1,1,1,1,1,1", "at most 8"),
            ("0.00001", "1/65536"),
        ] {
            let e = parse_bracket(bad).unwrap_err();
            assert!(e.contains(fragment), "{bad:?}: {e}");
        }
    }
}
