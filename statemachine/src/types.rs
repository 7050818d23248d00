//! Domain types shared by every link: the command the host sends, why a frame was refused, faults and outputs.

use fixed::types::I16F16;

/// A wheel speed in rad/s, Q16.16 fixed point (range ±32768 rad/s, resolution 1.5e-5 rad/s).
///
/// Fixed point keeps NaN and infinity out of the ladder by construction: a float from the wire
/// becomes a `Speed` only after [`crate::validate`] has checked it.
pub type Speed = I16F16;

/// The most axes a ladder drives (seed 001 and seed 004 boards have four motors).
pub const MAX_AXES: usize = 4;

/// A position in rad at the axis (joint angle or wheel angle), Q16.16 (range ±32768 rad).
pub type Position = I16F16;

/// An open-loop PWM duty as a fraction of full scale, Q16.16 in [-1, 1] (sign = direction).
pub type Duty = I16F16;

/// How one axis is driven: the drive modes every seed's link maps onto.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[repr(u8)]
pub enum AxisMode {
    /// No torque: every bridge switch open, the axis runs down freely (seed 004 OFF, seed 001 `pwm = 0`).
    Coast = 0,
    /// Short brake: both low sides on, the motor brakes on its own back-EMF (seed 004 PASSIV_BRAKE).
    Short = 1,
    /// Open-loop duty, target in [-1, 1] of full scale (seed 001 `pwm / 1000`, seed 004 PWM `/ 399`).
    Duty = 2,
    /// Closed-loop speed, target in rad/s (seed 000 speed mode, seed 004 MAV).
    Velocity = 3,
    /// Closed-loop position, target in rad, moved by a trapezoidal profile under a speed cap in rad/s
    /// (seed 003 motor angles, seed 004 MTP).
    Position = 4,
}

impl AxisMode {
    /// Every mode, in code order.
    pub const ALL: [Self; 5] = [
        Self::Coast,
        Self::Short,
        Self::Duty,
        Self::Velocity,
        Self::Position,
    ];

    /// True for the modes that put no drive torque on the axis (coast, short brake).
    pub const fn is_passive(self) -> bool {
        matches!(self, Self::Coast | Self::Short)
    }
}

/// A set of [`AxisMode`]s: the modes a link profile lets its host ask for.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct ModeSet(pub u8);

impl ModeSet {
    /// Velocity only (seed 000: its position and raw-duty modes are refused).
    pub const VELOCITY: Self = Self::of(AxisMode::Velocity);
    /// Every mode.
    pub const ALL: Self = Self(0b1_1111);

    /// The set holding only `m`.
    pub const fn of(m: AxisMode) -> Self {
        Self(1 << m as u8)
    }

    /// This set and `m`.
    pub const fn with(self, m: AxisMode) -> Self {
        Self(self.0 | Self::of(m).0)
    }

    /// True if `m` is in the set.
    pub const fn contains(self, m: AxisMode) -> bool {
        self.0 & Self::of(m).0 != 0
    }
}

/// What the host asks of one axis; floats as they came off the wire, unchecked. `repr(C)`, words
/// first: commands are copied on every received frame (see `validate::AxisSetpoint`).
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[repr(C)]
pub struct AxisCommand {
    /// Duty fraction ([`AxisMode::Duty`]), rad/s ([`AxisMode::Velocity`]) or rad ([`AxisMode::Position`]);
    /// ignored by the passive modes.
    pub target: f32,
    /// Speed cap in rad/s for [`AxisMode::Position`]; ignored by the other modes.
    pub cap: f32,
    /// The drive mode asked for.
    pub mode: AxisMode,
}

impl AxisCommand {
    /// A velocity target in rad/s.
    pub const fn velocity(target: f32) -> Self {
        Self {
            mode: AxisMode::Velocity,
            target,
            cap: 0.0,
        }
    }

    /// A duty target as a fraction of full scale.
    pub const fn duty(target: f32) -> Self {
        Self {
            mode: AxisMode::Duty,
            target,
            cap: 0.0,
        }
    }

    /// A position target in rad, reached at no more than `cap` rad/s.
    pub const fn position(target: f32, cap: f32) -> Self {
        Self {
            mode: AxisMode::Position,
            target,
            cap,
        }
    }

    /// No torque.
    pub const COAST: Self = Self {
        mode: AxisMode::Coast,
        target: 0.0,
        cap: 0.0,
    };

    /// Short brake.
    pub const SHORT: Self = Self {
        mode: AxisMode::Short,
        target: 0.0,
        cap: 0.0,
    };
}

/// What the host asks the `N` axes to do; the shape every wire format decodes into.
///
/// Nothing here has been checked yet: [`crate::validate`] does that.
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[repr(C)]
pub struct Command<const N: usize> {
    /// One request per axis.
    pub axes: [AxisCommand; N],
    /// Sequence number, where the link carries one; used to refuse repeated and stale frames.
    pub seq: Option<u32>,
    /// The frame's own comm-loss threshold in ticks since it arrived (seed 001 `timeout_ms`, see
    /// [`crate::config::brake_age_for_timeout_ms`]), where the link carries one; the profile's
    /// `brake_after` caps it.
    pub timeout: Option<u16>,
    /// Drive enable as sent (0 disabled, anything else enabled).
    pub enable: bool,
}

impl<const N: usize> Command<N> {
    /// Velocity targets for every axis, no timeout of its own.
    pub fn velocity(targets: [f32; N], enable: bool, seq: Option<u32>) -> Self {
        Self {
            axes: targets.map(AxisCommand::velocity),
            enable,
            seq,
            timeout: None,
        }
    }

    /// The same request for every axis.
    pub const fn uniform(axis: AxisCommand, enable: bool, seq: Option<u32>) -> Self {
        Self {
            axes: [axis; N],
            enable,
            seq,
            timeout: None,
        }
    }
}

/// The control modes of seed 000's `MotorCommand.control_mode` (wire values); `protocol::amr` maps
/// them onto [`AxisMode`]s, and the seed 000 profile accepts only velocity.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[repr(u8)]
pub enum ControlMode {
    /// Motors idle: zero speed target, speed loop active.
    Idle = 0,
    /// Closed-loop wheel speed ([`AxisMode::Velocity`]).
    Speed = 1,
    /// Position control ([`AxisMode::Position`]); refused by the seed 000 profile.
    Position = 2,
    /// Raw PWM duty ([`AxisMode::Duty`]); refused by the seed 000 profile (it would bypass the speed loop).
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
    /// A target or cap outside its mode's range (±v_max, ±duty_max, the travel), or a zero timeout.
    OutOfRange = 6,
    /// Control mode value not defined by the protocol.
    UnknownMode = 7,
    /// Drive mode defined but not accepted by the active link profile.
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

/// What one axis's bridge is told to do outside BRAKE.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum AxisDrive {
    /// Every switch open: no torque.
    Coast,
    /// Low sides on: the motor brakes on its own back-EMF.
    Short,
    /// Open-loop duty in [-1, 1] of full scale.
    Duty(Duty),
    /// Speed loop active with this setpoint (rad/s).
    Velocity(Speed),
    /// Position loop active: move toward `target` (rad) at no more than `cap` (rad/s, ≥ 0); with
    /// `cap` = 0 the axis holds where its profile stands.
    Position {
        /// Position target, within the profile's travel.
        target: Position,
        /// Speed cap the profile must respect.
        cap: Speed,
    },
}

impl AxisDrive {
    /// The setpoint as a speed where the axis is velocity-driven, zero otherwise.
    pub const fn speed(&self) -> Speed {
        match self {
            Self::Velocity(v) => *v,
            _ => Speed::ZERO,
        }
    }
}

/// What the bridge is told to do.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Drive<const N: usize> {
    /// Each axis driven as its mode says.
    Run([AxisDrive; N]),
    /// PWM off, low-side switches on: every motor shorted, braking dynamically. The one safe state.
    Brake,
}

impl<const N: usize> Drive<N> {
    /// The velocity setpoints of a running drive (zero for axes not velocity-driven), `None` in BRAKE.
    pub fn speeds(&self) -> Option<[Speed; N]> {
        match self {
            Self::Run(axes) => Some(axes.map(|a| a.speed())),
            Self::Brake => None,
        }
    }
}

/// What the ladder decided after one event: everything the firmware applies and reports.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Output<const N: usize> {
    /// Current rung.
    pub mode: Mode,
    /// Bridge command.
    pub drive: Drive<N>,
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
    use super::{AxisDrive, Drive, Output};

    impl defmt::Format for AxisDrive {
        fn format(&self, f: defmt::Formatter) {
            match self {
                AxisDrive::Coast => defmt::write!(f, "Coast"),
                AxisDrive::Short => defmt::write!(f, "Short"),
                AxisDrive::Duty(d) => defmt::write!(f, "Duty({=i32}/65536)", d.to_bits()),
                AxisDrive::Velocity(v) => defmt::write!(f, "Velocity({=i32}/65536)", v.to_bits()),
                AxisDrive::Position { target, cap } => defmt::write!(
                    f,
                    "Position {{ target: {=i32}/65536, cap: {=i32}/65536 }}",
                    target.to_bits(),
                    cap.to_bits()
                ),
            }
        }
    }

    impl<const N: usize> defmt::Format for Drive<N> {
        fn format(&self, f: defmt::Formatter) {
            match self {
                Drive::Run(axes) => defmt::write!(f, "Run({})", axes),
                Drive::Brake => defmt::write!(f, "Brake"),
            }
        }
    }

    impl<const N: usize> defmt::Format for Output<N> {
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
