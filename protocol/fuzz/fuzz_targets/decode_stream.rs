//! Arbitrary bytes into both decoders, in arbitrary chunking: never panics, state stays bounded,
//! and anything accepted re-encodes to a frame that decodes to the same message.
#![no_main]

use ellipso_protocol::*;
use libfuzzer_sys::fuzz_target;

fn check<M: Message + PartialEq + core::fmt::Debug>(data: &[u8]) {
    let mut d = Decoder::<M>::new();
    for r in d.feed(data) {
        if let Ok(m) = r {
            let mut buf = [0u8; MAX_FRAME_LEN];
            let n = encode(&m, &mut buf).expect("an accepted message re-encodes");
            let mut again = Decoder::<M>::new();
            assert_eq!(again.feed(&buf[..n]).next(), Some(Ok(m)));
        }
        assert!(d.pending() < MAX_FRAME_LEN);
    }
}

fuzz_target!(|data: &[u8]| {
    check::<HostMessage>(data);
    check::<BoardMessage>(data);
});
