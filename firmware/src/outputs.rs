//! The two board outputs, behind the [`Outputs`] trait the sequencer drives.
//!
//! Contract for implementors:
//! - Each call sets the output *now* and must not block; the sequencer calls it from inside
//!   [`Sequencer::poll`](crate::Sequencer::poll) (on an MCU typically a timer ISR).
//! - `t_device_us` is the device time the sequencer executes the edge at (the `now_us` of the
//!   poll); hardware ports may ignore it, simulators and recorders log it.
//! - [`Outputs::flash_on`] receives the flash's hard cap `max_on_us`. **Safety rule 5:** a port
//!   with a one-pulse timer should arm it to cut the flash after `max_on_us` whatever the CPU does:
//!   the sequencer turns the flash off at the first poll after its deadline, which bounds the
//!   on-time only as tightly as the loop keeps time; the hardware one-pulse is the silicon-level
//!   guarantee against a stuck loop. Ports without one get the software bound only.
//! - Calls may repeat a level (e.g. `flash_off` on `Stop` while already off); that must be
//!   harmless.
//!
//! Provided implementations: [`PinOutputs`] over two embedded-hal 1.0 [`OutputPin`]s, and
//! [`RecordingOutputs`], which logs a timeline of edges (tests, simulator, emulator).

use ellipso_protocol::Output;
use embedded_hal::digital::OutputPin;

/// The camera trigger and flash outputs.
pub trait Outputs {
    /// Sets the camera trigger (high = exposing).
    fn set_camera(&mut self, high: bool, t_device_us: u64);
    /// Lights the flash; a port with a one-pulse timer cuts it after `max_on_us` in hardware.
    fn flash_on(&mut self, t_device_us: u64, max_on_us: u32);
    /// Turns the flash off.
    fn flash_off(&mut self, t_device_us: u64);
}

/// [`Outputs`] over two embedded-hal 1.0 output pins, both active high.
///
/// Pin errors cannot stop the sequencer (it has to carry on forcing the flash off); they are
/// counted in [`PinOutputs::write_errors`] and a failed flash-off write is retried once. On MCUs
/// the pins' error type is usually `Infallible`. `max_on_us` is ignored: GPIO has no one-pulse.
#[derive(Debug)]
pub struct PinOutputs<C, F> {
    camera: C,
    flash: F,
    write_errors: u32,
}

impl<C: OutputPin, F: OutputPin> PinOutputs<C, F> {
    /// Wraps the pins; does not touch them (the board drives both low when armed or stopped).
    pub fn new(camera: C, flash: F) -> Self {
        Self {
            camera,
            flash,
            write_errors: 0,
        }
    }

    /// Pin writes that returned an error since construction.
    pub fn write_errors(&self) -> u32 {
        self.write_errors
    }

    /// Gives the pins back.
    pub fn release(self) -> (C, F) {
        (self.camera, self.flash)
    }

    fn count(&mut self, ok: bool) -> bool {
        if !ok {
            self.write_errors = self.write_errors.saturating_add(1);
        }
        ok
    }
}

impl<C: OutputPin, F: OutputPin> Outputs for PinOutputs<C, F> {
    fn set_camera(&mut self, high: bool, _t_device_us: u64) {
        let ok = if high {
            self.camera.set_high()
        } else {
            self.camera.set_low()
        }
        .is_ok();
        self.count(ok);
    }

    fn flash_on(&mut self, _t_device_us: u64, _max_on_us: u32) {
        let ok = self.flash.set_high().is_ok();
        self.count(ok);
    }

    fn flash_off(&mut self, _t_device_us: u64) {
        let ok = self.flash.set_low().is_ok();
        if !self.count(ok) {
            let retry = self.flash.set_low().is_ok();
            self.count(retry);
        }
    }
}

/// One recorded output transition.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct OutputEdge {
    /// Which output.
    pub output: Output,
    /// New level.
    pub high: bool,
    /// When it was set, device µs.
    pub t_device_us: u64,
}

/// [`Outputs`] that records the last `N` level *changes* with their times (repeated levels are
/// not edges and are not recorded) and tracks the current levels.
///
/// When more than `N` edges arrive the oldest are dropped and counted in
/// [`RecordingOutputs::dropped`]; the current levels stay exact.
#[derive(Debug, Clone)]
pub struct RecordingOutputs<const N: usize> {
    edges: heapless::Deque<OutputEdge, N>,
    camera_high: bool,
    flash_high: bool,
    dropped: u32,
}

impl<const N: usize> Default for RecordingOutputs<N> {
    fn default() -> Self {
        Self::new()
    }
}

impl<const N: usize> RecordingOutputs<N> {
    /// Both outputs low, no edges.
    pub const fn new() -> Self {
        Self {
            edges: heapless::Deque::new(),
            camera_high: false,
            flash_high: false,
            dropped: 0,
        }
    }

    /// Current camera trigger level.
    pub fn camera_high(&self) -> bool {
        self.camera_high
    }

    /// Current flash level.
    pub fn flash_high(&self) -> bool {
        self.flash_high
    }

    /// Recorded edges, oldest first.
    pub fn edges(&self) -> impl Iterator<Item = &OutputEdge> {
        self.edges.iter()
    }

    /// Removes and returns the oldest recorded edge.
    pub fn pop_edge(&mut self) -> Option<OutputEdge> {
        self.edges.pop_front()
    }

    /// Edges dropped because more than `N` were held.
    pub fn dropped(&self) -> u32 {
        self.dropped
    }

    fn record(&mut self, output: Output, high: bool, t_device_us: u64) {
        let level = match output {
            Output::CameraTrigger => &mut self.camera_high,
            Output::Flash => &mut self.flash_high,
        };
        if *level == high {
            return;
        }
        *level = high;
        let edge = OutputEdge {
            output,
            high,
            t_device_us,
        };
        if self.edges.is_full() {
            self.edges.pop_front();
            self.dropped = self.dropped.saturating_add(1);
        }
        // Fails only for N = 0, which holds nothing; that edge was counted as dropped above.
        let _ = self.edges.push_back(edge);
    }
}

impl<const N: usize> Outputs for RecordingOutputs<N> {
    fn set_camera(&mut self, high: bool, t_device_us: u64) {
        self.record(Output::CameraTrigger, high, t_device_us);
    }

    fn flash_on(&mut self, t_device_us: u64, _max_on_us: u32) {
        self.record(Output::Flash, true, t_device_us);
    }

    fn flash_off(&mut self, t_device_us: u64) {
        self.record(Output::Flash, false, t_device_us);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use embedded_hal_mock::eh1::MockError;
    use embedded_hal_mock::eh1::digital::{Mock as PinMock, State, Transaction as T};

    #[test]
    fn pin_outputs_write_the_pins_in_call_order() {
        let camera = PinMock::new(&[T::set(State::High), T::set(State::Low)]);
        let flash = PinMock::new(&[T::set(State::High), T::set(State::Low)]);
        let mut out = PinOutputs::new(camera, flash);
        out.set_camera(true, 0);
        out.flash_on(1, 5_000);
        out.flash_off(2);
        out.set_camera(false, 3);
        assert_eq!(out.write_errors(), 0);
        let (mut camera, mut flash) = out.release();
        camera.done();
        flash.done();
    }

    #[test]
    fn a_failed_flash_off_is_counted_and_retried() {
        let err = MockError::Io(std::io::ErrorKind::Other);
        let camera = PinMock::new(&[]);
        let flash = PinMock::new(&[T::set(State::Low).with_error(err), T::set(State::Low)]);
        let mut out = PinOutputs::new(camera, flash);
        out.flash_off(7);
        assert_eq!(out.write_errors(), 1);
        let (mut camera, mut flash) = out.release();
        camera.done();
        flash.done();
    }

    #[test]
    fn recorder_logs_changes_only_and_keeps_the_newest() {
        let mut rec = RecordingOutputs::<2>::new();
        rec.set_camera(true, 10);
        rec.set_camera(true, 11); // same level: no edge
        rec.flash_on(12, 100);
        rec.flash_off(13);
        assert!(rec.camera_high());
        assert!(!rec.flash_high());
        assert_eq!(rec.dropped(), 1);
        let got: Vec<_> = rec.edges().copied().collect();
        assert_eq!(
            got,
            [
                OutputEdge {
                    output: Output::Flash,
                    high: true,
                    t_device_us: 12
                },
                OutputEdge {
                    output: Output::Flash,
                    high: false,
                    t_device_us: 13
                },
            ]
        );
        assert_eq!(rec.pop_edge().map(|e| e.t_device_us), Some(12));
    }
}
