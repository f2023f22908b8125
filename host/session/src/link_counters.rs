//! The trigger link's counters as a session records them: bytes moved and frames dropped by
//! reason. The link (`ellipso-rig`) fills them; the session log keeps them.

/// A snapshot of the trigger link's counters (`ellipso_rig::link::LinkStats`), as the session's
/// `link_stats` event records it.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Serialize, serde::Deserialize)]
pub struct LinkCounters {
    /// Bytes received.
    pub bytes_rx: u64,
    /// Bytes sent.
    pub bytes_tx: u64,
    /// Frames decoded.
    pub frames_ok: u64,
    /// Frames with broken COBS.
    pub bad_cobs: u64,
    /// Frames with a CRC mismatch.
    pub bad_crc: u64,
    /// Frames too short to hold a CRC.
    pub too_short: u64,
    /// Byte runs longer than a frame.
    pub overflow: u64,
    /// Frames naming an unknown message.
    pub unknown_message: u64,
    /// Frames with a malformed body.
    pub malformed: u64,
}

impl LinkCounters {
    /// All dropped frames, whatever the reason.
    pub fn bad_frames(&self) -> u64 {
        self.bad_cobs
            + self.bad_crc
            + self.too_short
            + self.overflow
            + self.unknown_message
            + self.malformed
    }
}
