//! The node's `diagnostic_msgs/DiagnosticStatus`: the MCU's ladder rung and fault flags by name,
//! the bridge's arming state and cmd_vel age, the link counters and the clock-sync state.

use statemachine::Mode;

use super::msg::{level, DiagnosticStatus, KeyValue};
use super::shared::Snapshot;
use crate::bridge::ArmState;

/// The names of the flags set in `bits`, lower case and comma-separated ("none" if none; an
/// undefined bit as `bit<n>`).
pub fn fault_names(bits: u32) -> String {
    let names = crate::names::fault_names(bits);
    if names.is_empty() {
        "none".into()
    } else {
        names.join(",").to_lowercase()
    }
}

pub use crate::names::mode_name;

/// The name of an arming state.
pub fn arm_name(a: Option<ArmState>) -> &'static str {
    match a {
        None => "starting",
        Some(ArmState::Disarmed) => "disarmed",
        Some(ArmState::Arming(_)) => "arming",
        Some(ArmState::Armed) => "armed",
        Some(ArmState::Latched) => "latched",
    }
}

fn kv(key: &str, value: impl ToString) -> KeyValue {
    KeyValue {
        key: key.into(),
        value: value.to_string(),
    }
}

/// The status of the motor link from a snapshot; `recent` names the bridge diagnostics raised
/// since the last status.
pub fn status(s: &Snapshot, hardware_id: &str, recent: &[&str]) -> DiagnosticStatus {
    let fb = s.feedback;
    let mode = fb.map(|f| f.mode);
    let faults = fb.map_or(0, |f| f.fault_flags);
    let stale = s
        .cmd_vel_age_us
        .is_none_or(|a| a > crate::bridge::BridgeConfig::DEFAULT.cmd_vel_timeout_us);
    let (lvl, message) = if s.silent {
        (
            level::ERROR,
            "ESTOP: exchanges stopped, the MCU brakes on comm loss".to_string(),
        )
    } else if s.ended {
        (level::ERROR, "bridge ended".to_string())
    } else {
        match mode {
            None => (level::STALE, "no feedback from the MCU".to_string()),
            Some(m) => {
                let rung = mode_name(m);
                let lvl = if m == u32::from(Mode::Brake as u8) {
                    level::ERROR
                } else if m == u32::from(Mode::Normal as u8) && !stale {
                    level::OK
                } else {
                    level::WARN
                };
                (lvl, format!("{rung}, {}", arm_name(s.arm)))
            }
        }
    };
    let mut values = vec![
        kv("mode", mode.map_or("unknown", mode_name)),
        kv("arm_state", arm_name(s.arm)),
        kv(
            "cmd_vel_age_ms",
            s.cmd_vel_age_us
                .map_or_else(|| "never".to_string(), |a| format!("{:.1}", a as f64 / 1e3)),
        ),
        kv("cmd_vel_stale", stale),
        kv("faults", fault_names(faults)),
        kv("fault_flags", format!("{faults:#06x}")),
        kv("exchanges", if s.silent { "stopped" } else { "running" }),
        kv("cycles", s.cycles),
        kv("commands", s.stats.commands),
        kv("feedback_ok", s.stats.feedback_ok),
        kv("feedback_rejected", s.stats.feedback_rejected),
        kv("not_accepted", s.stats.not_accepted),
        kv("transport_errors", s.transport_errors),
        kv("period_misses", s.period_misses),
        kv("skipped_deadlines", s.skipped_deadlines),
        kv(
            "clock_sync",
            if s.clock_synced {
                "synced"
            } else {
                "not synced"
            },
        ),
        kv(
            "clock_offset_us",
            s.clock_offset_us
                .map_or_else(|| "unknown".to_string(), |o| format!("{o:.0}")),
        ),
        kv(
            "wheel_cmd_rad_s",
            format!("{:.3},{:.3}", s.output[0], s.output[1]),
        ),
        kv(
            "recent",
            if recent.is_empty() {
                "none".to_string()
            } else {
                recent.join(",")
            },
        ),
    ];
    if let Some(f) = fb {
        values.push(kv("mcu_time_us", f.timestamp_us));
        values.push(kv("mcu_seq", f.seq));
    }
    if let Some(i) = s.mcu_info {
        let (ma, mi, pa) = i.fw_version_parts();
        values.push(kv("firmware", format!("{ma}.{mi}.{pa}")));
        values.push(kv("reset_cause", format!("{:?}", i.reset_cause)));
        values.push(kv("reset_count", i.reset_count));
    }
    if let Some(e) = &s.last_error {
        values.push(kv("last_transport_error", e));
    }
    DiagnosticStatus {
        level: lvl,
        name: "motorlink: motor link".into(),
        message,
        hardware_id: hardware_id.into(),
        values,
    }
}

#[cfg(test)]
#[allow(clippy::unwrap_used, clippy::indexing_slicing)]
mod tests {
    use super::*;
    use protocol::amr::MotorFeedback;
    use statemachine::FaultFlags;

    #[test]
    fn flags_are_named_by_bit() {
        assert_eq!(fault_names(0), "none");
        // Bit 4 comm lost, bit 9 brake latched (statemachine::FaultFlags).
        assert_eq!(fault_names((1 << 4) | (1 << 9)), "comm_lost,brake_latched");
        assert_eq!(fault_names(1 << 15), "bit15");
    }

    #[test]
    fn a_braked_mcu_is_an_error_with_its_faults() {
        let s = Snapshot {
            feedback: Some(MotorFeedback {
                mode: 4,
                fault_flags: u32::from((FaultFlags::COMM_LOST.0) | FaultFlags::BRAKE_LATCHED.0),
                ..MotorFeedback::default()
            }),
            arm: Some(ArmState::Latched),
            ..Snapshot::default()
        };
        let st = status(&s, "sim", &["brake_latched"]);
        assert_eq!(st.level, level::ERROR);
        let get = |k: &str| st.values.iter().find(|v| v.key == k).unwrap().value.clone();
        assert_eq!(get("mode"), "BRAKE");
        assert_eq!(get("faults"), "comm_lost,brake_latched");
        assert_eq!(get("arm_state"), "latched");
        assert_eq!(get("recent"), "brake_latched");
    }

    #[test]
    fn normal_with_a_fresh_command_is_ok_and_stale_is_a_warning() {
        let mut s = Snapshot {
            feedback: Some(MotorFeedback::default()),
            arm: Some(ArmState::Armed),
            cmd_vel_age_us: Some(20_000),
            ..Snapshot::default()
        };
        assert_eq!(status(&s, "", &[]).level, level::OK);
        s.cmd_vel_age_us = Some(250_000);
        assert_eq!(status(&s, "", &[]).level, level::WARN);
        s.silent = true;
        assert_eq!(status(&s, "", &[]).level, level::ERROR);
    }
}
