//! Prints the spec vectors of `docs/protocol.md` as markdown table rows:
//! `cargo run -p ellipso-protocol --example spec_vectors`.

#[path = "../tests/common/vectors.rs"]
mod vectors;

fn main() {
    println!("| name | message | frame (hex, delimiter included) |");
    println!("|---|---|---|");
    for (name, v) in vectors::vectors() {
        let debug = match &v {
            vectors::Vector::Host(m) => format!("{m:?}"),
            vectors::Vector::Board(m) => format!("{m:?}"),
        };
        println!(
            "| `{name}` | `{debug}` | `{}` |",
            vectors::hex(&vectors::encode_vector(&v))
        );
    }
}
