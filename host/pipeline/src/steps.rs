//! Where a run's long steps (carving the mesh, the fit) are shown: the caller's [`Steps`] (the
//! binary draws a spinner per step; the demo and the benches theirs).

/// Where a run's long steps are shown: the binary draws a spinner per step. A step begun and
/// not ended (an error, a step that gave up) is dropped silently when the next one begins or the
/// run ends.
pub trait Steps: Send {
    /// A step (`mesh`, `fit`) begins.
    fn begin(&mut self, label: &str);
    /// The running step's current stage.
    fn stage(&mut self, name: &str);
    /// The running step ends, with its one summary line.
    fn end(&mut self, summary: &str);
}
