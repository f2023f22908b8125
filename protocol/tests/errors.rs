//! Each class of bad frame gives its own typed error, and the next good frame still decodes.

mod common;

use common::frame;
use ellipso_protocol::*;

/// A frame around an arbitrary body, with a correct CRC.
fn raw_frame(body: &[u8]) -> Vec<u8> {
    let mut payload = body.to_vec();
    payload.extend(CRC32C.checksum(body).to_le_bytes());
    let mut out = vec![0u8; cobs::max_encoding_length(payload.len()) + 1];
    let n = cobs::encode(&payload, &mut out);
    out.truncate(n);
    out.push(0);
    out
}

/// Decodes `bad` then a good Ping; returns the error of `bad` and checks the Ping survived.
fn error_of(bad: &[u8]) -> FrameError {
    let good = HostMessage::Ping { nonce: 0xdead_beef };
    let mut stream = bad.to_vec();
    stream.extend(frame(&good));
    let mut d = Decoder::<HostMessage>::new();
    let got: Vec<_> = d.feed(&stream).collect();
    assert_eq!(got.len(), 2, "one error then the good frame: {got:?}");
    assert_eq!(got[1], Ok(good), "decoder resynchronised");
    got[0].unwrap_err()
}

#[test]
fn flipped_crc_byte_is_bad_crc() {
    let mut f = frame(&HostMessage::Ping { nonce: 42 });
    let last = f.len() - 2; // the last CRC byte (COBS keeps it in place when non-zero)
    f[last] ^= 0x01;
    if f[last] == 0 {
        f[last] = 0x55;
    }
    assert_eq!(error_of(&f), FrameError::BadCrc);
}

#[test]
fn unknown_discriminant_is_unknown_message() {
    let f = raw_frame(&[9]); // HostMessage has 9 variants: 0..=8
    assert_eq!(error_of(&f), FrameError::UnknownMessage { discriminant: 9 });
    let f = raw_frame(&[0xff, 0x01]); // varint 255
    assert_eq!(
        error_of(&f),
        FrameError::UnknownMessage { discriminant: 255 }
    );
}

#[test]
fn trailing_bytes_or_truncated_body_is_malformed() {
    let mut buf = [0u8; 16];
    let mut body = postcard::to_slice(&HostMessage::Ping { nonce: 9 }, &mut buf)
        .unwrap()
        .to_vec();
    body.push(1);
    assert_eq!(error_of(&raw_frame(&body)), FrameError::Malformed);
    assert_eq!(
        error_of(&raw_frame(&[6])),
        FrameError::Malformed,
        "Ping without its nonce"
    );
    assert_eq!(
        error_of(&raw_frame(&[0x80, 0x80, 0x80, 0x80, 0x80, 0x01])),
        FrameError::Malformed
    );
}

#[test]
fn too_short_frame() {
    assert_eq!(
        error_of(&[0x03, 0x11, 0x22, 0x00]),
        FrameError::TooShort { len: 2 }
    );
}

#[test]
fn overlong_run_is_overflow() {
    let junk = vec![0x42u8; 3 * MAX_FRAME_LEN];
    let mut bad = junk.clone();
    bad.push(0);
    assert_eq!(
        error_of(&bad),
        FrameError::Overflow {
            max: MAX_FRAME_LEN - 1
        }
    );
}

#[test]
fn broken_cobs_is_bad_cobs() {
    // the code byte claims 16 data bytes but only 2 follow before the delimiter
    assert_eq!(error_of(&[0x11, 0x01, 0x02, 0x00]), FrameError::BadCobs);
}

#[test]
fn errors_map_to_wire_kinds() {
    assert_eq!(FrameError::BadCrc.kind(), BadFrameKind::Crc);
    assert_eq!(FrameError::BadCobs.kind(), BadFrameKind::Cobs);
    assert_eq!(
        FrameError::Overflow { max: 1 }.kind(),
        BadFrameKind::Overflow
    );
    assert_eq!(
        FrameError::UnknownMessage { discriminant: 9 }.kind(),
        BadFrameKind::UnknownMessage
    );
    assert_eq!(FrameError::Malformed.kind(), BadFrameKind::Malformed);
    assert!(FrameError::BadCrc.to_string().contains("CRC"));
}

/// A bracket of more than MAX_BRACKET_STEPS steps is a malformed body, never a truncated bracket.
#[test]
fn overlong_bracket_is_malformed() {
    let config = CaptureConfig {
        exposure_us: 8_000,
        flash_delay_us: 500,
        flash_duration_us: 2_000,
        frame_period_us: 250_000,
        pulses: PulseCount::Count(150),
        trigger: TriggerSource::FreeRun,
        report_edges: false,
        bracket: Bracket::from_q15(&[ENERGY_ONE_Q15; MAX_BRACKET_STEPS]).unwrap(),
    };
    let mut buf = [0u8; MAX_MESSAGE_LEN];
    let mut body = postcard::to_slice(&HostMessage::Configure(config), &mut buf)
        .unwrap()
        .to_vec();
    // The bracket is the body's tail: count 8, then eight 3-byte varints of 0x8000.
    let tail = body.len() - 1 - 3 * MAX_BRACKET_STEPS;
    assert_eq!(body[tail], MAX_BRACKET_STEPS as u8);
    body[tail] = MAX_BRACKET_STEPS as u8 + 1;
    body.extend([0x80, 0x80, 0x02]);
    assert_eq!(error_of(&raw_frame(&body)), FrameError::Malformed);
}
