//! The hex examples in `docs/protocol.md` are test vectors: each decodes to its canonical message
//! and that message encodes back to the same bytes.

#[path = "common/vectors.rs"]
mod vectors;

use ellipso_protocol::*;
use vectors::{Vector, encode_vector, hex, vectors};

const SPEC: &str = include_str!("../../docs/protocol.md");

/// `(name, bytes)` of every vector row of the example section: `| \`name\` | … | \`hex\` |`.
fn spec_rows() -> Vec<(String, Vec<u8>)> {
    let section = SPEC
        .split("\n## ")
        .find(|s| s.starts_with("Example frames"))
        .expect("docs/protocol.md has an `## Example frames` section");
    section
        .lines()
        .filter(|l| l.starts_with("| `"))
        .filter_map(|l| {
            let cols: Vec<&str> = l.split('|').map(str::trim).collect();
            let name = cols.get(1)?.trim_matches('`').to_string();
            let hexcol = cols.get(3)?.trim_matches('`');
            let bytes = hexcol
                .split_whitespace()
                .map(|h| u8::from_str_radix(h, 16))
                .collect::<Result<Vec<u8>, _>>()
                .ok()?;
            Some((name, bytes))
        })
        .collect()
}

#[test]
fn every_message_has_a_spec_vector_and_it_round_trips() {
    let rows = spec_rows();
    let canonical = vectors();
    assert_eq!(
        rows.len(),
        canonical.len(),
        "one vector per canonical message in docs/protocol.md"
    );
    for (name, expected) in &canonical {
        let (_, bytes) = rows
            .iter()
            .find(|(n, _)| n == name)
            .unwrap_or_else(|| panic!("docs/protocol.md has no vector `{name}`"));
        let mut host = Decoder::<HostMessage>::new();
        let mut board = Decoder::<BoardMessage>::new();
        match expected {
            Vector::Host(m) => {
                assert_eq!(host.feed(bytes).collect::<Vec<_>>(), vec![Ok(*m)], "{name}")
            }
            Vector::Board(m) => {
                assert_eq!(
                    board.feed(bytes).collect::<Vec<_>>(),
                    vec![Ok(m.clone())],
                    "{name}"
                )
            }
        }
        assert_eq!(
            hex(&encode_vector(expected)),
            hex(bytes),
            "`{name}` re-encodes byte for byte (regenerate with the spec_vectors example)"
        );
    }
}
