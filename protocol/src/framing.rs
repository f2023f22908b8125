//! Framing: `COBS(postcard(message) ++ crc32c_le) ++ 0x00`, and a streaming decoder that resyncs.
//!
//! Contract:
//! - [`encode`] writes one complete frame, delimiter included, of at most [`MAX_FRAME_LEN`] bytes.
//! - [`Decoder::push`] takes one byte at a time from any byte stream (UART ISR, pty, socket) and
//!   returns `Some` exactly when a `0x00` delimiter ends a non-empty frame: the message, or a typed
//!   [`FrameError`]. Every delimiter resets the decoder, so after any corruption the next frame
//!   that arrives intact after a delimiter decodes. It never panics, never allocates, and its memory
//!   is a fixed `MAX_FRAME_LEN` bytes whatever arrives.
//! - A frame is accepted only if its COBS structure is valid, its CRC-32C (Castagnoli,
//!   `crc::CRC_32_ISCSI`, over the postcard bytes, appended little-endian) matches, its first
//!   varint names a known variant and postcard consumes the body exactly (no trailing bytes).
//!
//! ```
//! use ellipso_protocol::{encode, Decoder, HostMessage, MAX_FRAME_LEN};
//! let mut frame = [0u8; MAX_FRAME_LEN];
//! let n = encode(&HostMessage::Ping { nonce: 7 }, &mut frame).unwrap();
//! let mut decoder = Decoder::<HostMessage>::new();
//! let got: Vec<_> = frame[..n].iter().filter_map(|&b| decoder.push(b)).collect();
//! assert_eq!(got, [Ok(HostMessage::Ping { nonce: 7 })]);
//! ```

use core::fmt;
use core::marker::PhantomData;

use crc::{CRC_32_ISCSI, Crc};
use serde::Serialize;
use serde::de::DeserializeOwned;

use crate::messages::{BadFrameKind, BoardMessage, HostMessage};

/// CRC-32C (Castagnoli), as used by iSCSI: strong Hamming distance at our frame lengths.
pub const CRC32C: Crc<u32> = Crc::<u32>::new(&CRC_32_ISCSI);
/// Bytes of CRC appended to the postcard body.
pub const CRC_LEN: usize = 4;
/// Largest postcard body of any message; a test encodes the worst case of every variant.
pub const MAX_MESSAGE_LEN: usize = 96;
/// Largest frame on the wire, delimiter included: COBS of body + CRC, plus the `0x00`.
pub const MAX_FRAME_LEN: usize = cobs::max_encoding_length(MAX_MESSAGE_LEN + CRC_LEN) + 1;

mod sealed {
    pub trait Sealed {}
    impl Sealed for crate::HostMessage {}
    impl Sealed for crate::BoardMessage {}
}

/// A top-level message type of one link direction.
pub trait Message: Serialize + DeserializeOwned + sealed::Sealed {
    /// Number of variants; a discriminant at or above it is an unknown message.
    const VARIANT_COUNT: u32;
}

impl Message for HostMessage {
    const VARIANT_COUNT: u32 = 9;
}

impl Message for BoardMessage {
    const VARIANT_COUNT: u32 = 8;
}

/// Why a message could not be encoded.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum EncodeError {
    /// The postcard body exceeds [`MAX_MESSAGE_LEN`] (a protocol bug: the size test guards it).
    MessageTooLong,
    /// The output buffer is shorter than the frame.
    BufferTooSmall {
        /// Bytes the frame needs at most.
        needed: usize,
    },
}

impl fmt::Display for EncodeError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::MessageTooLong => {
                write!(
                    f,
                    "message body exceeds {MAX_MESSAGE_LEN} bytes of postcard"
                )
            }
            Self::BufferTooSmall { needed } => {
                write!(
                    f,
                    "output buffer too small: a frame needs up to {needed} bytes"
                )
            }
        }
    }
}

impl core::error::Error for EncodeError {}

/// Encodes `msg` as one frame into `out`; returns the frame length, delimiter included.
pub fn encode<M: Message>(msg: &M, out: &mut [u8]) -> Result<usize, EncodeError> {
    let mut body = [0u8; MAX_MESSAGE_LEN + CRC_LEN];
    let n = postcard::to_slice(msg, &mut body[..MAX_MESSAGE_LEN])
        .map_err(|_| EncodeError::MessageTooLong)?
        .len();
    let crc = CRC32C.checksum(&body[..n]).to_le_bytes();
    body[n..n + CRC_LEN].copy_from_slice(&crc);
    let needed = cobs::max_encoding_length(n + CRC_LEN) + 1;
    if out.len() < needed {
        return Err(EncodeError::BufferTooSmall { needed });
    }
    let k = cobs::try_encode(&body[..n + CRC_LEN], out)
        .map_err(|_| EncodeError::BufferTooSmall { needed })?;
    out[k] = 0;
    Ok(k + 1)
}

/// Why one frame was dropped. The decoder has already resynchronised when this is returned.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum FrameError {
    /// More than `max` bytes arrived without a delimiter; they were discarded.
    Overflow {
        /// The decoder's frame capacity, bytes.
        max: usize,
    },
    /// The COBS structure is broken (a code byte points past the frame end).
    BadCobs,
    /// Shorter than the CRC plus one byte of message.
    TooShort {
        /// Decoded length, bytes.
        len: usize,
    },
    /// The CRC-32C does not match the body.
    BadCrc,
    /// The CRC matched but the discriminant names no message of this direction.
    UnknownMessage {
        /// The discriminant received.
        discriminant: u32,
    },
    /// A known message whose body does not decode (or has trailing bytes).
    Malformed,
}

impl FrameError {
    /// The wire-level class of this error, as reported in [`crate::Fault::BadFrame`].
    pub fn kind(&self) -> BadFrameKind {
        match self {
            Self::Overflow { .. } => BadFrameKind::Overflow,
            Self::BadCobs => BadFrameKind::Cobs,
            Self::TooShort { .. } | Self::BadCrc => BadFrameKind::Crc,
            Self::UnknownMessage { .. } => BadFrameKind::UnknownMessage,
            Self::Malformed => BadFrameKind::Malformed,
        }
    }
}

impl fmt::Display for FrameError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::Overflow { max } => {
                write!(f, "frame longer than {max} bytes without a delimiter")
            }
            Self::BadCobs => write!(f, "broken COBS encoding"),
            Self::TooShort { len } => {
                write!(
                    f,
                    "frame of {len} bytes is shorter than a CRC plus a message"
                )
            }
            Self::BadCrc => write!(f, "CRC-32C mismatch"),
            Self::UnknownMessage { discriminant } => {
                write!(f, "unknown message discriminant {discriminant}")
            }
            Self::Malformed => write!(f, "malformed message body"),
        }
    }
}

impl core::error::Error for FrameError {}

/// Frame capacity of the decoder: the longest encoded frame without its delimiter.
const CAPACITY: usize = MAX_FRAME_LEN - 1;

/// Streaming frame decoder for messages of type `M` (a COBS accumulator with CRC and resync).
#[derive(Clone)]
pub struct Decoder<M> {
    buf: [u8; CAPACITY],
    len: usize,
    overflowed: bool,
    _message: PhantomData<fn() -> M>,
}

impl<M: Message> Default for Decoder<M> {
    fn default() -> Self {
        Self::new()
    }
}

impl<M: Message> Decoder<M> {
    /// An empty decoder.
    pub const fn new() -> Self {
        Self {
            buf: [0; CAPACITY],
            len: 0,
            overflowed: false,
            _message: PhantomData,
        }
    }

    /// Bytes of the current (unfinished) frame held so far.
    pub fn pending(&self) -> usize {
        self.len
    }

    /// Drops any partial frame (e.g. after a reconnect).
    pub fn reset(&mut self) {
        self.len = 0;
        self.overflowed = false;
    }

    /// Feeds one byte; returns `Some` when a delimiter ends a non-empty frame.
    pub fn push(&mut self, byte: u8) -> Option<Result<M, FrameError>> {
        if byte != 0 {
            match self.buf.get_mut(self.len) {
                Some(slot) => {
                    *slot = byte;
                    self.len += 1;
                }
                None => self.overflowed = true,
            }
            return None;
        }
        let len = core::mem::take(&mut self.len);
        if core::mem::take(&mut self.overflowed) {
            return Some(Err(FrameError::Overflow { max: CAPACITY }));
        }
        if len == 0 {
            return None; // back-to-back delimiters: a resync byte, not a frame
        }
        Some(decode_frame(&mut self.buf[..len]))
    }

    /// Feeds a chunk; yields one result per completed frame, in order.
    pub fn feed<'a>(&'a mut self, bytes: &'a [u8]) -> Feed<'a, M> {
        Feed {
            decoder: self,
            bytes,
        }
    }
}

/// Iterator returned by [`Decoder::feed`].
pub struct Feed<'a, M> {
    decoder: &'a mut Decoder<M>,
    bytes: &'a [u8],
}

impl<M: Message> Iterator for Feed<'_, M> {
    type Item = Result<M, FrameError>;

    fn next(&mut self) -> Option<Self::Item> {
        while let Some((&b, rest)) = self.bytes.split_first() {
            self.bytes = rest;
            if let Some(r) = self.decoder.push(b) {
                return Some(r);
            }
        }
        None
    }
}

/// Decodes one COBS frame (delimiter stripped) in place.
fn decode_frame<M: Message>(frame: &mut [u8]) -> Result<M, FrameError> {
    let n = cobs::decode_in_place(frame).map_err(|_| FrameError::BadCobs)?;
    let decoded = frame.get(..n).ok_or(FrameError::BadCobs)?;
    if n <= CRC_LEN {
        return Err(FrameError::TooShort { len: n });
    }
    let (body, crc) = decoded.split_at(n - CRC_LEN);
    let mut crc_le = [0u8; CRC_LEN];
    crc_le.copy_from_slice(crc);
    if CRC32C.checksum(body) != u32::from_le_bytes(crc_le) {
        return Err(FrameError::BadCrc);
    }
    let discriminant = leading_varint(body).ok_or(FrameError::Malformed)?;
    if discriminant >= M::VARIANT_COUNT {
        return Err(FrameError::UnknownMessage { discriminant });
    }
    match postcard::take_from_bytes::<M>(body) {
        Ok((msg, [])) => Ok(msg),
        _ => Err(FrameError::Malformed),
    }
}

/// Reads postcard's leading varint (the enum discriminant) as a `u32`; `None` if malformed.
fn leading_varint(bytes: &[u8]) -> Option<u32> {
    let mut value: u32 = 0;
    for (i, &b) in bytes.iter().take(5).enumerate() {
        value |= u32::from(b & 0x7f).checked_shl(7 * i as u32)?;
        if b & 0x80 == 0 {
            return Some(value);
        }
    }
    None
}
