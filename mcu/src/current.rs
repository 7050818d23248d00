//! `current_loop` (priority 4, 20 kHz, ADC end of conversion triggered once per PWM period):
//! shunt counts → amperes → overcurrent check → PI → compare values.

use crate::hw::Bridge;
use crate::tuning::Tuning;
use control::bridge::bridge_compare;
use control::sense::{adc_to_amps, overcurrent};
use control::{Amps, BridgeState, CurrentPi, Q};

/// What one current-loop run measured.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct CurrentSample {
    /// Motor currents, A [left, right], signed.
    pub amps: [Amps; 2],
    /// The software trip or the hardware break fired in this run; the bridge is braked.
    pub tripped: bool,
}

/// Readings averaged at boot for the zero-current calibration (3.2 ms at 20 kHz).
pub const CALIBRATION_SAMPLES: u32 = 64;

/// Why the boot calibration refused a shunt (its reading with no current flowing).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum CalibrationError {
    /// Fewer readings than [`CALIBRATION_SAMPLES`] arrived (the ADC trigger did not run).
    TooFewSamples,
    /// A shunt's mean reading was further from the nominal zero than the tuning allows:
    /// the amplifier or its reference is faulty. `[left, right]` means.
    Implausible([u16; 2]),
}

/// Sums readings taken with the bridge braked, for [`Calibration::offsets`].
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Calibration {
    sums: [u32; 2],
    n: u32,
}

impl Calibration {
    /// No reading yet.
    pub const fn new() -> Self {
        Self { sums: [0; 2], n: 0 }
    }

    /// Adds one pair of readings (12-bit; higher bits ignored).
    pub fn add(&mut self, raw: [u16; 2]) {
        for (s, r) in self.sums.iter_mut().zip(raw) {
            *s = s.saturating_add(u32::from(r & 0x0FFF));
        }
        self.n = self.n.saturating_add(1);
    }

    /// Readings so far.
    pub const fn count(&self) -> u32 {
        self.n
    }

    /// The zero-current readings to use, or why not: each mean must lie within the tuning's
    /// tolerance of the nominal zero ([`Tuning::calibrated_offset`]).
    pub fn offsets(&self, t: &Tuning) -> Result<[u16; 2], CalibrationError> {
        if self.n < CALIBRATION_SAMPLES {
            return Err(CalibrationError::TooFewSamples);
        }
        // Rounded mean; n ≥ 1 and a mean of 12-bit readings fits u16.
        let mean = self.sums.map(|s| {
            let m = s
                .saturating_add(self.n / 2)
                .checked_div(self.n)
                .unwrap_or(0);
            u16::try_from(m).unwrap_or(u16::MAX)
        });
        let [ml, mr] = mean;
        match (t.calibrated_offset(ml), t.calibrated_offset(mr)) {
            (Some(l), Some(r)) => Ok([l, r]),
            _ => Err(CalibrationError::Implausible(mean)),
        }
    }
}

/// The current loop's own state: both PIs and the shunt scaling.
///
/// Built from a failed calibration ([`CurrentLoop::calibrated`] with an error) it trips on every
/// run: without a believable zero the current cannot be bounded, so the bridge stays braked and
/// the overcurrent condition keeps BRAKE latched (the feedback reports it as an overcurrent).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct CurrentLoop {
    pis: [CurrentPi; 2],
    offsets: [u16; 2],
    amps_per_count: Q,
    trip: Amps,
    sensor_failed: bool,
}

impl CurrentLoop {
    /// Controllers at rest with the zero-current readings `offsets` (calibrated at boot).
    pub const fn new(t: &Tuning, offsets: [u16; 2]) -> Self {
        Self {
            pis: [CurrentPi::new(t.current), CurrentPi::new(t.current)],
            offsets,
            amps_per_count: t.amps_per_count,
            trip: t.trip_amps,
            sensor_failed: false,
        }
    }

    /// Controllers at rest with the offsets of the boot calibration; a refused calibration gives
    /// a loop that keeps the bridge braked (see the type's docs).
    pub fn calibrated(t: &Tuning, calibration: Result<[u16; 2], CalibrationError>) -> Self {
        match calibration {
            Ok(offsets) => Self::new(t, offsets),
            Err(_) => Self {
                sensor_failed: true,
                ..Self::new(t, [t.adc_zero; 2])
            },
        }
    }

    /// One run: scales the two raw 12-bit readings, brakes the bridge at once on a software trip
    /// or a hardware break, and while the bridge runs, steps the PIs toward `refs` and writes the
    /// compares. While braked the PIs are held reset at the measured current.
    pub fn run(
        &mut self,
        bridge: &mut impl Bridge,
        raw: [u16; 2],
        refs: [Amps; 2],
    ) -> CurrentSample {
        let [rl, rr] = raw;
        let [ol, or] = self.offsets;
        let amps = [
            adc_to_amps(rl, ol, self.amps_per_count),
            adc_to_amps(rr, or, self.amps_per_count),
        ];
        let soft = amps.iter().any(|i| overcurrent(*i, self.trip));
        let tripped = soft || self.sensor_failed || bridge.break_tripped();
        if tripped {
            // Software backstop of the hardware break: PWM off in this very period.
            bridge.apply(BridgeState::Brake);
        }
        let [pl, pr] = &mut self.pis;
        let [al, ar] = amps;
        if bridge.state() == BridgeState::Run {
            let [il, ir] = refs;
            let arr = bridge.pwm_arr();
            bridge.set([
                bridge_compare(pl.step(il, al), arr),
                bridge_compare(pr.step(ir, ar), arr),
            ]);
        } else {
            pl.reset(al);
            pr.reset(ar);
        }
        CurrentSample { amps, tripped }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::hw::RecordingBridge;
    use crate::tuning::AMR;

    fn calibrate(readings: [u16; 2], n: u32) -> Result<[u16; 2], CalibrationError> {
        let mut c = Calibration::new();
        for _ in 0..n {
            c.add(readings);
        }
        c.offsets(&AMR)
    }

    #[test]
    fn calibration_by_hand() {
        assert_eq!(calibrate([2060, 2030], 64), Ok([2060, 2030]));
        assert_eq!(
            calibrate([2060, 2030], 63),
            Err(CalibrationError::TooFewSamples)
        );
        // 2200 is 152 counts (1.2 A) off the nominal 2048: beyond the 100-count tolerance.
        assert_eq!(
            calibrate([2048, 2200], 64),
            Err(CalibrationError::Implausible([2048, 2200]))
        );
        // A mean, rounded: half the readings 2050, half 2051 → 2050.5 → 2051.
        let mut c = Calibration::new();
        assert_eq!(c.count(), 0);
        for k in 0..64 {
            c.add([2050 + (k % 2), 2048]);
        }
        assert_eq!(c.count(), 64);
        assert_eq!(c.offsets(&AMR), Ok([2051, 2048]));
    }

    #[test]
    fn a_failed_calibration_keeps_the_bridge_braked() {
        let mut l = CurrentLoop::calibrated(&AMR, Err(CalibrationError::TooFewSamples));
        let mut b = RecordingBridge::new(4200);
        b.apply(BridgeState::Run);
        let s = l.run(&mut b, [2048, 2048], [Q::ZERO; 2]);
        assert!(s.tripped);
        assert_eq!(b.state, BridgeState::Brake);
        // A calibrated offset is what zero current reads as.
        let mut l = CurrentLoop::calibrated(&AMR, Ok([2100, 2000]));
        let s = l.run(&mut b, [2100, 2000], [Q::ZERO; 2]);
        assert_eq!(s.amps, [Q::ZERO; 2]);
        assert!(!s.tripped);
    }
}
