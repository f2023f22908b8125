//! Host-side cost of the sync core: simulated pulses per second, command bytes per second, and the
//! RAM a board port spends on it.
//!
//! `cargo bench -p ellipso-firmware`. Best of several repetitions (the machine is shared and
//! noisy); the ratios within one run are what to compare. On an MCU the per-edge cost scales
//! roughly with the clock ratio; the sizes are exact for any 64-bit-aligned target.

use std::hint::black_box;
use std::time::{Duration, Instant};

use ellipso_firmware::{Board, BoardConfig, Outputs, Sequencer, TxQueue};
use ellipso_protocol::{
    BoardMessage, Bracket, CaptureConfig, Decoder, HostMessage, MAX_FRAME_LEN, PulseCount,
    TriggerSource, encode,
};

const PULSES: u64 = 200_000;
const PINGS: usize = 100_000;
const REPEATS: usize = 5;

/// Outputs that only count writes (keeps the measured path free of recording).
struct CountingPins(u64);

impl Outputs for CountingPins {
    fn set_camera(&mut self, _high: bool, _t: u64) {
        self.0 += 1;
    }
    fn flash_on(&mut self, _t: u64, _max_on_us: u32) {
        self.0 += 1;
    }
    fn flash_off(&mut self, _t: u64) {
        self.0 += 1;
    }
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

fn free_run(report_edges: bool) -> CaptureConfig {
    CaptureConfig {
        exposure_us: 1_000,
        flash_delay_us: 100,
        flash_duration_us: 500,
        frame_period_us: 50_000,
        pulses: PulseCount::Continuous,
        trigger: TriggerSource::FreeRun,
        report_edges,
        bracket: Bracket::NONE,
    }
}

/// Runs `PULSES` free-run pulses, polling exactly at each deadline; returns messages sent.
fn run_pulses(report_edges: bool) -> u64 {
    let mut board = Board::new(BoardConfig::new("bench", 1_000_000)).expect("valid");
    let mut pins = CountingPins(0);
    let mut sent = 0u64;
    let mut sink = |m: BoardMessage| {
        black_box(&m);
        sent += 1;
    };
    for msg in [
        HostMessage::Configure(free_run(report_edges)),
        HostMessage::Arm,
        HostMessage::Start,
    ] {
        board.handle(msg, 0, &mut pins, &mut sink);
    }
    while board.sequencer().pulses_fired() < PULSES {
        let t = board.next_deadline().expect("continuous");
        board.poll(black_box(t), &mut pins, &mut sink);
    }
    sent
}

fn main() {
    let pulses = best_of(|| {
        black_box(run_pulses(false));
    });
    let pulses_edges = best_of(|| {
        black_box(run_pulses(true));
    });

    let mut stream = Vec::new();
    let mut buf = [0u8; MAX_FRAME_LEN];
    for i in 0..PINGS {
        let n = encode(&HostMessage::Ping { nonce: i as u32 }, &mut buf).expect("fits");
        stream.extend_from_slice(&buf[..n]);
    }
    let bytes = best_of(|| {
        let mut board = Board::new(BoardConfig::new("bench", 1_000_000)).expect("valid");
        let mut pins = CountingPins(0);
        let mut q = TxQueue::<4>::new();
        for &b in black_box(&stream) {
            board.feed_rx_byte(b, 0, &mut pins, &mut q);
            while q.pop().is_some() {}
        }
        assert_eq!(board.faults().bad_frames, 0);
    });

    println!("sync core on the host: {PULSES} free-run pulses (4 edges each), {PINGS} Ping frames");
    println!("| operation | rate | ns each |");
    println!("|---|---|---|");
    let per = |d: Duration, n: f64| (n / d.as_secs_f64(), d.as_secs_f64() * 1e9 / n);
    let (r, ns) = per(pulses, PULSES as f64 * 4.0);
    println!("| edge (poll at deadline) | {r:.2e} edges/s | {ns:.0} |");
    let (r2, ns2) = per(pulses_edges, PULSES as f64 * 4.0);
    println!(
        "| edge with edge reports | {r2:.2e} edges/s | {ns2:.0} ({:.2}x) |",
        ns2 / ns
    );
    let (r3, ns3) = per(bytes, stream.len() as f64);
    println!("| received byte (decode + Pong) | {r3:.2e} bytes/s | {ns3:.0} |");

    println!();
    println!("| RAM of | bytes |");
    println!("|---|---|");
    for (name, size) in [
        ("Board (incl. decoder and BoardInfo)", size_of::<Board>()),
        ("Sequencer", size_of::<Sequencer>()),
        ("Decoder<HostMessage>", size_of::<Decoder<HostMessage>>()),
        ("BoardMessage", size_of::<BoardMessage>()),
        ("TxQueue<16>", size_of::<TxQueue<16>>()),
    ] {
        println!("| {name} | {size} |");
    }
}
