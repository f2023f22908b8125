//! The capture timing sent to the trigger board as the session records it: the wire's
//! [`CaptureConfig`] turned into the session's own [`BoardConfig`] (the session crate does not
//! link the protocol crate, so the fit reads sessions without it).
//!
//! Contract: field for field, in the same JSON form the log held when it recorded the wire type
//! itself (tested), so logs written before and after read alike.

use ellipso_protocol::{CaptureConfig, PulseCount, TriggerSource};
use ellipso_session::events::{BoardConfig, BoardPulses, BoardTrigger};

/// The session's record of `config`.
pub fn board_config_record(config: &CaptureConfig) -> BoardConfig {
    BoardConfig {
        bracket: config.bracket.steps_q15().to_vec(),
        exposure_us: config.exposure_us,
        flash_delay_us: config.flash_delay_us,
        flash_duration_us: config.flash_duration_us,
        frame_period_us: config.frame_period_us,
        pulses: match config.pulses {
            PulseCount::Continuous => BoardPulses::Continuous,
            PulseCount::Count(n) => BoardPulses::Count(n),
        },
        report_edges: config.report_edges,
        trigger: match config.trigger {
            TriggerSource::HostCommand => BoardTrigger::HostCommand,
            TriggerSource::GripButton => BoardTrigger::GripButton,
            TriggerSource::FreeRun => BoardTrigger::FreeRun,
        },
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use ellipso_protocol::Bracket;

    #[test]
    fn the_record_is_the_wire_config_in_the_same_json() {
        let bracket = Bracket::from_relative(&[1.0, 0.25, 0.0625]).unwrap();
        for (pulses, trigger, bracket) in [
            (
                PulseCount::Count(150),
                TriggerSource::FreeRun,
                Bracket::NONE,
            ),
            (PulseCount::Continuous, TriggerSource::GripButton, bracket),
            (PulseCount::Count(1), TriggerSource::HostCommand, bracket),
        ] {
            let config = CaptureConfig {
                exposure_us: 6000,
                flash_delay_us: 100,
                flash_duration_us: 5000,
                frame_period_us: 500_000,
                pulses,
                trigger,
                report_edges: true,
                bracket,
            };
            let record = board_config_record(&config);
            let wire = serde_json::to_value(config).unwrap();
            assert_eq!(serde_json::to_value(&record).unwrap(), wire);
            // a log line written with the wire type reads back as the record
            let back: BoardConfig = serde_json::from_value(wire).unwrap();
            assert_eq!(back, record);
        }
        // before the bracket existed the log had no `bracket`
        let old = serde_json::json!({"exposure_us":6000,"flash_delay_us":100,
            "flash_duration_us":5000,"frame_period_us":500000,"pulses":{"Count":3},
            "report_edges":false,"trigger":"FreeRun"});
        let back: BoardConfig = serde_json::from_value(old).unwrap();
        assert!(back.bracket.is_empty());
    }
}
