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

/// The current loop's own state: both PIs and the shunt scaling.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct CurrentLoop {
    pis: [CurrentPi; 2],
    offsets: [u16; 2],
    amps_per_count: Q,
    trip: Amps,
}

impl CurrentLoop {
    /// Controllers at rest with the zero-current readings `offsets` (calibrated at boot).
    pub const fn new(t: &Tuning, offsets: [u16; 2]) -> Self {
        Self {
            pis: [CurrentPi::new(t.current), CurrentPi::new(t.current)],
            offsets,
            amps_per_count: t.amps_per_count,
            trip: t.trip_amps,
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
        let tripped = soft || bridge.break_tripped();
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

    /// The duty integrators, for tests and proofs.
    pub fn pis(&self) -> &[CurrentPi; 2] {
        &self.pis
    }
}
