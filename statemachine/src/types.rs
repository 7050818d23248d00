//! Domain types shared by every link: the command the host sends, why a frame was refused, faults and outputs.

use fixed::types::I16F16;

/// A wheel speed in rad/s, Q16.16 fixed point (range ±32768 rad/s, resolution 1.5e-5 rad/s).
///
/// Fixed point keeps NaN and infinity out of the ladder by construction: a float from the wire
/// becomes a `Speed` only after [`crate::validate`] has checked it.
pub type Speed = I16F16;

/// What the host asks the wheels to do; the shape every wire format decodes into.
///
/// Floats are kept as they came off the wire; nothing here has been checked yet.
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Command {
    /// Left wheel speed, rad/s at the wheel.
    pub left: f32,
    /// Right wheel speed, rad/s at the wheel.
    pub right: f32,
    /// Raw control mode as sent (seed 000: 0 idle, 1 speed, 2 position, 3 raw duty).
    pub mode: u32,
    /// Drive enable as sent (0 disabled, anything else enabled).
    pub enable: bool,
    /// Sequence number, where the link carries one; used to refuse repeated and stale frames.
    pub seq: Option<u32>,
}

/// The control modes of seed 000's `MotorCommand.control_mode`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[repr(u8)]
pub enum ControlMode {
    /// Motors idle: zero speed target, speed loop active.
    Idle = 0,
    /// Closed-loop wheel speed, the only mode that drives the wheels under the ladder.
    Speed = 1,
    /// Position control; defined by the seed, refused by this firmware (no limit applies to it).
    Position = 2,
    /// Raw PWM duty; defined by the seed, refused by this firmware (it would bypass the speed limits).
    RawDuty = 3,
}

impl ControlMode {
    /// Maps a raw wire value to a mode, `None` for values the seed does not define.
    pub const fn from_raw(raw: u32) -> Option<Self> {
        match raw {
            0 => Some(Self::Idle),
            1 => Some(Self::Speed),
            2 => Some(Self::Position),
            3 => Some(Self::RawDuty),
            _ => None,
        }
    }
}

/// Why a frame was not applied. Wire codes are fixed and never reused.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[repr(u8)]
pub enum RejectReason {
    /// CRC did not match the frame.
    Crc = 1,
    /// Framing broken: bad start of frame, length or delimiter.
    Framing = 2,
    /// Payload did not decode (bad protobuf, missing field, truncated).
    Decode = 3,
    /// Protocol or transfer version differs from ours.
    Version = 4,
    /// A speed was NaN or infinite.
    NonFinite = 5,
    /// A speed exceeded ±v_max.
    OutOfRange = 6,
    /// Control mode value not defined by the protocol.
    UnknownMode = 7,
    /// Control mode defined but not driven by this firmware (position, raw duty).
    UnsupportedMode = 8,
    /// Change from the last valid command faster than the acceleration limit allows.
    Acceleration = 9,
    /// Sequence number repeated or older than the last valid frame.
    Stale = 10,
    /// Parity of the update flags wrong (seed 004).
    Parity = 11,
}

impl RejectReason {
    /// Every reason, in wire-code order (used to size and index counters).
    pub const ALL: [Self; 11] = [
        Self::Crc,
        Self::Framing,
        Self::Decode,
        Self::Version,
        Self::NonFinite,
        Self::OutOfRange,
        Self::UnknownMode,
        Self::UnsupportedMode,
        Self::Acceleration,
        Self::Stale,
        Self::Parity,
    ];

    /// Index of this reason in [`Self::ALL`] and in the reject counters.
    pub const fn index(self) -> usize {
        (self as usize).saturating_sub(1)
    }
}

/// A condition reported by the board (sensors, supervisors) or by the host-side link monitor.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[repr(u8)]
pub enum Condition {
    /// Shunt current above the trip level: PWM off in the same step (BRAKE).
    Overcurrent = 0,
    /// Driver or motor temperature above the trip level (BRAKE).
    Overtemperature = 1,
    /// Speed estimate implausible or encoder signals lost (BRAKE: dynamic braking needs no encoder).
    EncoderFailure = 2,
    /// Bus voltage too low to control the bridge (BRAKE).
    Undervoltage = 3,
    /// Temperature high but below the trip level (REDUCED).
    ThermalWarning = 4,
    /// Host reports the clock sync lost (REDUCED).
    ClockSyncLost = 5,
}

impl Condition {
    /// Every condition.
    pub const ALL: [Self; 6] = [
        Self::Overcurrent,
        Self::Overtemperature,
        Self::EncoderFailure,
        Self::Undervoltage,
        Self::ThermalWarning,
        Self::ClockSyncLost,
    ];

    /// True if the condition latches BRAKE; false if it only degrades to REDUCED.
    pub const fn brakes(self) -> bool {
        matches!(
            self,
            Self::Overcurrent | Self::Overtemperature | Self::EncoderFailure | Self::Undervoltage
        )
    }

    /// The fault flag that reports this condition.
    pub const fn flag(self) -> FaultFlags {
        match self {
            Self::Overcurrent => FaultFlags::OVERCURRENT,
            Self::Overtemperature => FaultFlags::OVERTEMPERATURE,
            Self::EncoderFailure => FaultFlags::ENCODER,
            Self::Undervoltage => FaultFlags::UNDERVOLTAGE,
            Self::ThermalWarning => FaultFlags::THERMAL_WARNING,
            Self::ClockSyncLost => FaultFlags::CLOCK_SYNC_LOST,
        }
    }
}

/// Fault and status bits reported in the feedback frame (`MotorFeedback.fault_flags`).
///
/// Bits 0-2 are the seed's overcurrent, overtemperature and encoder error; the rest extend it.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct FaultFlags(pub u16);

impl FaultFlags {
    /// No flag set.
    pub const NONE: Self = Self(0);
    /// Overcurrent active.
    pub const OVERCURRENT: Self = Self(1 << 0);
    /// Overtemperature active.
    pub const OVERTEMPERATURE: Self = Self(1 << 1);
    /// Encoder failure active.
    pub const ENCODER: Self = Self(1 << 2);
    /// Undervoltage active.
    pub const UNDERVOLTAGE: Self = Self(1 << 3);
    /// The link was lost long enough to brake.
    pub const COMM_LOST: Self = Self(1 << 4);
    /// Emergency stop latched.
    pub const ESTOP: Self = Self(1 << 5);
    /// Host shutdown bit asserted (seed 004).
    pub const SHUTDOWN: Self = Self(1 << 6);
    /// Thermal warning active.
    pub const THERMAL_WARNING: Self = Self(1 << 7);
    /// Clock sync reported lost.
    pub const CLOCK_SYNC_LOST: Self = Self(1 << 8);
    /// BRAKE is latched and waits for an explicit re-arm.
    pub const BRAKE_LATCHED: Self = Self(1 << 9);
    /// Not armed since power-on.
    pub const POWER_ON: Self = Self(1 << 10);
    /// Link quality degraded (rejected frames or a recent HOLD episode).
    pub const LINK_DEGRADED: Self = Self(1 << 11);

    /// True if every bit of `other` is set in `self`.
    pub const fn contains(self, other: Self) -> bool {
        self.0 & other.0 == other.0
    }

    /// True if any bit of `other` is set in `self`.
    pub const fn intersects(self, other: Self) -> bool {
        self.0 & other.0 != 0
    }

    /// Union of the two sets.
    pub const fn union(self, other: Self) -> Self {
        Self(self.0 | other.0)
    }

    /// `self` without the bits of `other`.
    pub const fn without(self, other: Self) -> Self {
        Self(self.0 & !other.0)
    }

    /// True if no bit is set.
    pub const fn is_empty(self) -> bool {
        self.0 == 0
    }
}

/// The rungs of the degradation ladder, from full service to dynamic braking.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[repr(u8)]
pub enum Mode {
    /// Fresh valid commands applied within ±v_max and the acceleration limit.
    Normal = 0,
    /// Link quality degraded or a warning active: commands limited to the reduced speed (≈ IEC 61800-5-2 SLS).
    Reduced = 1,
    /// `hold_after` ticks since the last valid frame: the last direction kept while decelerating gently (≈ SS2 onset).
    Hold = 2,
    /// `stop_after` ticks since the last valid frame, or drive disabled: zero target at the stop deceleration, speed loop active (≈ SS1).
    Stop = 3,
    /// PWM off and low-side short (dynamic brake), no speed loop; latched until an explicit re-arm (≈ STO, stop category 0).
    Brake = 4,
}

/// What the bridge is told to do.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Drive {
    /// Speed loop active with these wheel setpoints (rad/s).
    Run {
        /// Left wheel setpoint.
        left: Speed,
        /// Right wheel setpoint.
        right: Speed,
    },
    /// PWM off, low-side switches on: the motors are shorted and brake dynamically.
    Brake,
}

/// What the ladder decided after one event: everything the firmware applies and reports.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Output {
    /// Current rung.
    pub mode: Mode,
    /// Bridge command.
    pub drive: Drive,
    /// Speed magnitude the current rung allows (rad/s).
    pub limit: Speed,
    /// Fault and status flags for the feedback frame.
    pub faults: FaultFlags,
    /// Watchdog ticks since the last valid frame (saturating).
    pub age: u16,
}

/// defmt renders speeds as raw Q16.16 bits (divide by 65536 for rad/s): `fixed` has no defmt support.
#[cfg(feature = "defmt")]
mod defmt_impls {
    use super::{Drive, Output};

    impl defmt::Format for Drive {
        fn format(&self, f: defmt::Formatter) {
            match self {
                Drive::Run { left, right } => defmt::write!(
                    f,
                    "Run {{ left: {=i32}/65536, right: {=i32}/65536 }}",
                    left.to_bits(),
                    right.to_bits()
                ),
                Drive::Brake => defmt::write!(f, "Brake"),
            }
        }
    }

    impl defmt::Format for Output {
        fn format(&self, f: defmt::Formatter) {
            defmt::write!(
                f,
                "Output {{ mode: {}, drive: {}, limit: {=i32}/65536, faults: {=u16:#x}, age: {=u16} }}",
                self.mode,
                self.drive,
                self.limit.to_bits(),
                self.faults.0,
                self.age
            )
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn fault_flags_are_distinct_single_bits() {
        let all = [
            FaultFlags::OVERCURRENT,
            FaultFlags::OVERTEMPERATURE,
            FaultFlags::ENCODER,
            FaultFlags::UNDERVOLTAGE,
            FaultFlags::COMM_LOST,
            FaultFlags::ESTOP,
            FaultFlags::SHUTDOWN,
            FaultFlags::THERMAL_WARNING,
            FaultFlags::CLOCK_SYNC_LOST,
            FaultFlags::BRAKE_LATCHED,
            FaultFlags::POWER_ON,
            FaultFlags::LINK_DEGRADED,
        ];
        let mut seen = 0u16;
        for f in all {
            assert_eq!(f.0.count_ones(), 1, "{f:?}");
            assert_eq!(seen & f.0, 0, "{f:?} reused");
            seen |= f.0;
        }
        assert_eq!(seen, 0x0FFF, "twelve flags in the low twelve bits");
    }

    #[test]
    fn every_condition_has_its_own_flag_and_severity() {
        let mut seen = FaultFlags::NONE;
        for c in Condition::ALL {
            assert!(!seen.intersects(c.flag()));
            seen = seen.union(c.flag());
        }
        let braking: usize = Condition::ALL.iter().filter(|c| c.brakes()).count();
        assert_eq!(braking, 4);
        assert!(!Condition::ThermalWarning.brakes() && !Condition::ClockSyncLost.brakes());
    }

    #[test]
    fn reject_reasons_index_their_counters() {
        for (i, r) in RejectReason::ALL.iter().enumerate() {
            assert_eq!(r.index(), i);
            assert_eq!(*r as usize, i + 1, "wire codes are 1-based and dense");
        }
        assert_eq!(ControlMode::from_raw(1), Some(ControlMode::Speed));
        assert_eq!(ControlMode::from_raw(4), None);
    }
}
