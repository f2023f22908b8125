//! Encode and decode throughput of a realistic link stream (pulse events with growing times).
//!
//! `cargo bench -p ellipso-protocol`. Prints frames/s and MB/s; best of several repetitions, so
//! figures from one run are comparable with each other (the machine is shared and noisy).

use std::hint::black_box;
use std::time::{Duration, Instant};

use ellipso_protocol::*;

const FRAMES: usize = 200_000;
const REPEATS: usize = 7;

fn pulse(i: u64) -> BoardMessage {
    let t0 = 1_000_000 + i * 250_000;
    BoardMessage::Pulse(PulseEvent {
        seq: i,
        t_trigger_us: t0,
        t_flash_on_us: t0 + 500,
        t_flash_off_us: t0 + 2_500,
        flags: 0,
        bracket_step: (i % 3) as u8,
        flash_on_us: 2_000,
    })
}

fn best_of(mut f: impl FnMut()) -> Duration {
    (0..REPEATS)
        .map(|_| {
            let t = Instant::now();
            f();
            t.elapsed()
        })
        .min()
        .unwrap_or_default()
}

fn main() {
    let msgs: Vec<BoardMessage> = (0..FRAMES as u64).map(pulse).collect();
    let mut stream = Vec::with_capacity(FRAMES * 24);
    let mut buf = [0u8; MAX_FRAME_LEN];
    for m in &msgs {
        let n = encode(m, &mut buf).expect("fits");
        stream.extend_from_slice(&buf[..n]);
    }
    let mb = stream.len() as f64 / 1e6;

    let enc = best_of(|| {
        let mut total = 0usize;
        for m in &msgs {
            total += encode(black_box(m), &mut buf).expect("fits");
        }
        black_box(total);
    });
    let dec = best_of(|| {
        let mut d = Decoder::<BoardMessage>::new();
        let ok = d.feed(black_box(&stream)).filter(|r| r.is_ok()).count();
        assert_eq!(ok, FRAMES);
    });
    let copy = best_of(|| {
        black_box(black_box(&stream).clone());
    });

    println!(
        "protocol throughput: {FRAMES} pulse-event frames, {:.1} bytes/frame",
        stream.len() as f64 / FRAMES as f64
    );
    println!("| operation | frames/s | MB/s | time vs memcpy |");
    println!("|---|---|---|---|");
    for (name, d) in [
        ("encode", enc),
        ("decode", dec),
        ("memcpy (reference)", copy),
    ] {
        let s = d.as_secs_f64();
        println!(
            "| {name} | {:.2e} | {:.0} | {:.1}x |",
            FRAMES as f64 / s,
            mb / s,
            s / copy.as_secs_f64()
        );
    }
}
