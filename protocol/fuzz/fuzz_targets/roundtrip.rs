//! Arbitrary bytes as a postcard body: whatever postcard accepts as a message must survive a
//! full frame round trip unchanged.
#![no_main]

use ellipso_protocol::*;
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    if let Ok((m, [])) = postcard::take_from_bytes::<BoardMessage>(data) {
        let mut buf = [0u8; MAX_FRAME_LEN];
        if let Ok(n) = encode(&m, &mut buf) {
            let mut d = Decoder::<BoardMessage>::new();
            assert_eq!(d.feed(&buf[..n]).next(), Some(Ok(m)));
        }
    }
});
