//! A link with random bit errors: no corrupted message is ever accepted, and every frame that
//! arrived untouched after an untouched delimiter is decoded. Also garbage: no panic, bounded state.

mod common;

use std::collections::HashMap;

use common::{board_message, frame, host_message};
use ellipso_protocol::*;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

struct Outcome {
    frames: usize,
    corrupted_frames: usize,
    intact_frames: usize,
    intact_decoded: usize,
    accepted_corrupt: usize,
    errors: usize,
}

/// Sends `msgs` over a link that flips each bit with probability `ber`.
fn run<M: Message + PartialEq + core::fmt::Debug>(msgs: &[M], ber: f64, seed: u64) -> Outcome {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let mut stream = Vec::new();
    let mut ends = Vec::with_capacity(msgs.len()); // index of each frame's delimiter
    for m in msgs {
        stream.extend(frame(m));
        ends.push(stream.len() - 1);
    }
    // flip bits: geometric gaps between errors, so the cost is per error, not per bit
    let mut flipped = vec![false; stream.len()];
    let ln_q = (1.0 - ber).ln();
    let mut bit: u64 = 0;
    loop {
        let u: f64 = rng.random::<f64>().max(f64::MIN_POSITIVE);
        bit += (u.ln() / ln_q).floor() as u64;
        let byte = (bit / 8) as usize;
        if byte >= stream.len() {
            break;
        }
        stream[byte] ^= 1 << (bit % 8);
        flipped[byte] = true;
        bit += 1;
    }
    let frame_of_end: HashMap<usize, usize> =
        ends.iter().enumerate().map(|(k, &e)| (e, k)).collect();
    let mut corrupted = vec![false; msgs.len()];
    let mut start = 0;
    for (k, &end) in ends.iter().enumerate() {
        corrupted[k] = flipped[start..=end].iter().any(|&f| f);
        start = end + 1;
    }

    let mut decoder = Decoder::<M>::new();
    let mut decoded = vec![false; msgs.len()];
    let (mut accepted_corrupt, mut errors) = (0, 0);
    for (i, &b) in stream.iter().enumerate() {
        match decoder.push(b) {
            None => {}
            Some(Err(_)) => errors += 1,
            Some(Ok(m)) => match frame_of_end.get(&i) {
                Some(&k) if !corrupted[k] && m == msgs[k] => decoded[k] = true,
                _ => accepted_corrupt += 1,
            },
        }
        assert!(
            decoder.pending() < MAX_FRAME_LEN,
            "decoder state is bounded"
        );
    }
    // intact: the frame's bytes and the delimiter before it arrived untouched
    let intact: Vec<usize> = (0..msgs.len())
        .filter(|&k| !corrupted[k] && (k == 0 || !flipped[ends[k - 1]]))
        .collect();
    Outcome {
        frames: msgs.len(),
        corrupted_frames: corrupted.iter().filter(|&&c| c).count(),
        intact_decoded: intact.iter().filter(|&&k| decoded[k]).count(),
        intact_frames: intact.len(),
        accepted_corrupt,
        errors,
    }
}

fn check(name: &str, o: &Outcome) {
    println!(
        "{name}: {} frames, {} corrupted, {} errors reported, {}/{} intact decoded, {} corrupt accepted",
        o.frames,
        o.corrupted_frames,
        o.errors,
        o.intact_decoded,
        o.intact_frames,
        o.accepted_corrupt
    );
    assert_eq!(
        o.accepted_corrupt, 0,
        "{name}: a corrupted message was accepted"
    );
    assert_eq!(
        o.intact_decoded, o.intact_frames,
        "{name}: an intact frame was lost"
    );
    assert!(
        o.corrupted_frames > 0,
        "{name}: the noise model injected nothing"
    );
}

#[test]
fn board_to_host_at_ber_1e_3() {
    let mut rng = ChaCha8Rng::seed_from_u64(1);
    let msgs: Vec<BoardMessage> = (0..100_000).map(|_| board_message(&mut rng)).collect();
    check("board->host BER 1e-3", &run(&msgs, 1e-3, 11));
}

#[test]
fn host_to_board_at_ber_1e_3() {
    let mut rng = ChaCha8Rng::seed_from_u64(2);
    let msgs: Vec<HostMessage> = (0..100_000).map(|_| host_message(&mut rng)).collect();
    check("host->board BER 1e-3", &run(&msgs, 1e-3, 12));
}

#[test]
fn heavy_noise_still_never_accepts_corruption() {
    let mut rng = ChaCha8Rng::seed_from_u64(3);
    let msgs: Vec<BoardMessage> = (0..20_000).map(|_| board_message(&mut rng)).collect();
    check("board->host BER 1e-2", &run(&msgs, 1e-2, 13));
}

/// Random garbage (with zeros sprinkled in): no panic, bounded state, and a good frame after it
/// still decodes.
#[test]
fn random_garbage_never_panics() {
    let mut rng = ChaCha8Rng::seed_from_u64(4);
    let mut d = Decoder::<BoardMessage>::new();
    for round in 0..200 {
        let len = rng.random_range(0..5000);
        let zero_p = [0.0, 0.01, 0.2][round % 3];
        let junk: Vec<u8> = (0..len)
            .map(|_| {
                if rng.random_bool(zero_p) {
                    0
                } else {
                    rng.random()
                }
            })
            .collect();
        for r in d.feed(&junk) {
            let _ = r; // anything may come out of garbage, including an error of any kind
        }
        assert!(d.pending() < MAX_FRAME_LEN);
        let good = BoardMessage::Pong {
            nonce: round as u32,
            t_device_us: 5,
        };
        let mut tail = vec![0];
        tail.extend(frame(&good));
        assert_eq!(d.feed(&tail).last(), Some(Ok(good)));
    }
}
