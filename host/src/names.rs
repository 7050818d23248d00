//! The names of the MCU's ladder rungs and fault flags as the host shows them: one table for the
//! operator's verbs, the recorder and the ROS 2 node's diagnostics.

use statemachine::{FaultFlags, Mode};

/// Every fault flag of the feedback's `fault_flags` with its name, in bit order.
pub const FAULT_NAMES: [(FaultFlags, &str); 12] = [
    (FaultFlags::OVERCURRENT, "OVERCURRENT"),
    (FaultFlags::OVERTEMPERATURE, "OVERTEMPERATURE"),
    (FaultFlags::ENCODER, "ENCODER"),
    (FaultFlags::UNDERVOLTAGE, "UNDERVOLTAGE"),
    (FaultFlags::COMM_LOST, "COMM_LOST"),
    (FaultFlags::ESTOP, "ESTOP"),
    (FaultFlags::SHUTDOWN, "SHUTDOWN"),
    (FaultFlags::THERMAL_WARNING, "THERMAL_WARNING"),
    (FaultFlags::CLOCK_SYNC_LOST, "CLOCK_SYNC_LOST"),
    (FaultFlags::BRAKE_LATCHED, "BRAKE_LATCHED"),
    (FaultFlags::POWER_ON, "POWER_ON"),
    (FaultFlags::LINK_DEGRADED, "LINK_DEGRADED"),
];

/// The names of the flags set in `bits`, in bit order; a bit no flag defines as `BIT<n>`.
pub fn fault_names(bits: u32) -> Vec<String> {
    let mut names = Vec::new();
    for n in 0..32u32 {
        let Some(mask) = 1u32.checked_shl(n) else {
            continue;
        };
        if bits & mask == 0 {
            continue;
        }
        let known = FAULT_NAMES
            .iter()
            .find(|(f, _)| u32::from(f.0) == mask)
            .map(|(_, name)| (*name).to_string());
        names.push(known.unwrap_or_else(|| format!("BIT{n}")));
    }
    names
}

/// The name of ladder rung `mode` (the feedback's `mode`, `Mode as u8`); `UNKNOWN` for a number no
/// rung has.
pub fn mode_name(mode: u32) -> &'static str {
    const RUNGS: [(Mode, &str); 5] = [
        (Mode::Normal, "NORMAL"),
        (Mode::Reduced, "REDUCED"),
        (Mode::Hold, "HOLD"),
        (Mode::Stop, "STOP"),
        (Mode::Brake, "BRAKE"),
    ];
    RUNGS
        .iter()
        .find(|(m, _)| u32::from(*m as u8) == mode)
        .map_or("UNKNOWN", |(_, n)| n)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn each_named_flag_is_one_distinct_bit_and_names_follow_the_bits() {
        let mut all = 0u16;
        for (f, _) in FAULT_NAMES {
            assert_eq!(f.0.count_ones(), 1, "one bit per flag");
            assert_eq!(all & f.0, 0, "no two flags share a bit");
            all |= f.0;
        }
        // Bit 4 is COMM_LOST and bit 9 BRAKE_LATCHED in statemachine::FaultFlags.
        assert_eq!(
            fault_names((1 << 4) | (1 << 9)),
            ["COMM_LOST", "BRAKE_LATCHED"]
        );
        assert_eq!(fault_names(1 << 20), ["BIT20"]);
        assert!(fault_names(0).is_empty());
    }

    #[test]
    fn rungs_are_named_in_ladder_order() {
        let names: Vec<&str> = (0..6).map(mode_name).collect();
        assert_eq!(
            names,
            ["NORMAL", "REDUCED", "HOLD", "STOP", "BRAKE", "UNKNOWN"]
        );
    }
}
