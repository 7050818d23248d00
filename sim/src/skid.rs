//! The plant of the seed 001 board: a small four-wheel skid-steer robot, each wheel on its own
//! brushed gearmotor behind one channel of two TB6612 drivers.
//!
//! ```text
//!        front
//!   m1 ┌───────┐ m2        m1, m3: left side     (TB1_A, TB2_A)
//!      │   ↑ x │           m2, m4: right side    (TB1_B, TB2_B)
//!   m3 └───────┘ m4        track = wheelbase_m of the parameters
//! ```
//!
//! Each motor is the DC motor of [`crate::plant`] (the same winding equation, integrated exactly
//! per step); both wheels of a side turn together (skid steer, no slip along the track), so the
//! body is the differential-drive body of [`Plant`] with four rotors reflected into its mass and
//! inertia. The driver's three states per motor (TB6612, IN1/IN2 and PWM):
//!
//! | IN1 IN2 | what the motor sees                                                      |
//! |---------|--------------------------------------------------------------------------|
//! | 1 0 / 0 1 | the supply for the PWM's on time, shorted for the rest (slow decay): `u = duty · V` on average |
//! | 1 1     | short brake: `u = 0`                                                     |
//! | 0 0     | outputs open: the winding current dies out through the body diodes (taken as at once), no torque |

use mcu::cdc::{MotorOutput, MOTORS};

use crate::plant::{Plant, PlantParams};

/// Which side each motor drives: 0 left, 1 right.
pub const SIDE: [usize; MOTORS] = [0, 1, 0, 1];

/// Standard gravity, m/s².
pub const G: f64 = 9.806_65;

/// A 2.5 kg robot on 65 mm wheels, 12 V, 1:30 gearmotors (about 35 rad/s at the wheel without
/// load, 2.4 A stall per motor: within the TB6612's 3.2 A peak).
pub const SMALL_4WD: PlantParams = PlantParams {
    v_bus: 12.0,
    r_ohm: 5.0,
    l_h: 1.5e-3,
    kt: 0.0114,
    gear: 30.0,
    j_rotor: 2.0e-7,
    mass_kg: 2.5,
    yaw_inertia: 0.017,
    wheel_radius_m: 0.0325,
    wheelbase_m: 0.18,
    drag_v: 0.5,
    drag_w: 0.3,
    rolling_n: 1.0,
    counts_per_rev: 1320,
};

/// How one motor is switched, as the plant sees it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum MotorDrive {
    /// Average duty in [-1, 1].
    Pwm(f64),
    /// Both low sides on.
    Short,
    /// Outputs open.
    Coast,
}

impl MotorDrive {
    /// The plant's view of one TB6612 channel's inputs (`arr`: the timer's auto-reload).
    pub fn of(m: &MotorOutput, arr: u16) -> Self {
        match (m.in1, m.in2) {
            (true, true) => Self::Short,
            (false, false) => Self::Coast,
            _ => Self::Pwm(f64::from(m.duty(arr))),
        }
    }
}

/// The robot: four motor currents, the body.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Skid {
    /// The body (its two wheel speeds and angles are the sides').
    pub body: Plant,
    /// Motor currents, A.
    pub current: [f64; MOTORS],
    /// Forward acceleration over the last step, m/s².
    pub accel: f64,
}

impl Default for Skid {
    fn default() -> Self {
        Self::new(SMALL_4WD)
    }
}

impl Skid {
    /// At rest.
    pub fn new(p: PlantParams) -> Self {
        Self {
            body: Plant::new(p),
            current: [0.0; MOTORS],
            accel: 0.0,
        }
    }

    /// Wheel speeds of the four motors' wheels, rad/s.
    pub fn wheel_speeds(&self) -> [f64; MOTORS] {
        let s = self.body.wheel_speeds();
        SIDE.map(|k| s[k])
    }

    /// Advances by `dt` seconds.
    pub fn step(&mut self, dt: f64, drive: [MotorDrive; MOTORS]) {
        let p = self.body.p;
        let ws = self.wheel_speeds();
        let a = (-dt * p.r_ohm / p.l_h).exp();
        let mut force = [0.0; 2];
        for k in 0..MOTORS {
            let i = match drive[k] {
                MotorDrive::Coast => 0.0,
                MotorDrive::Short => p.winding_current(self.current[k], 0.0, ws[k], a),
                MotorDrive::Pwm(d) => {
                    p.winding_current(self.current[k], d.clamp(-1.0, 1.0) * p.v_bus, ws[k], a)
                }
            };
            self.current[k] = i;
            force[SIDE[k]] += p.wheel_force(i);
        }
        let v0 = self.body.v;
        let n = MOTORS as f64;
        self.body
            .move_body(dt, force, p.m_eff_with(n), p.j_eff_with(n));
        self.accel = (self.body.v - v0) / dt;
    }

    /// What an IMU fixed to the body reads: specific force (x forward, y left, z up), m/s², and
    /// angular rate, rad/s. Level ground: gravity on z, the centripetal v·ω on y.
    pub fn imu_truth(&self) -> ([f64; 3], [f64; 3]) {
        let b = &self.body;
        ([self.accel, b.v * b.w, G], [0.0, 0.0, b.w])
    }

    /// The MPU6050's registers for the body's motion at full scales ±2 g and ±250 dps (16 384
    /// LSB/g, 131 LSB/dps), rounded and limited to the 16-bit range as the sensor's ADC does;
    /// the die temperature register for 25 °C.
    pub fn mpu6050_raw(&self) -> ([i16; 3], i16, [i16; 3]) {
        let (acc, rate) = self.imu_truth();
        let count = |x: f64| x.round().clamp(f64::from(i16::MIN), f64::from(i16::MAX)) as i16;
        let accel = acc.map(|a| count(a / G * 16_384.0));
        let gyro = rate.map(|w| count(w.to_degrees() * 131.0));
        // T = raw / 340 + 36.53 °C.
        let temp = count((25.0 - 36.53) * 340.0);
        (accel, temp, gyro)
    }
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;

    #[test]
    fn full_duty_settles_near_the_no_load_speed_and_shorting_stops_fast() {
        let mut s = Skid::default();
        for _ in 0..30_000 {
            s.step(100e-6, [MotorDrive::Pwm(1.0); MOTORS]);
        }
        // No load: 12 V / (Kt · N) = 12 / 0.342 = 35.1 rad/s; drag and rolling take a little.
        let w = s.wheel_speeds();
        assert!(w.iter().all(|x| (30.0..35.1).contains(x)), "{w:?}");
        assert!(s.body.w.abs() < 1e-9);
        let v0 = s.body.v;
        let tau = s.body.p.m_eff_with(4.0) / (2.0 * s.body.p.short_brake_damping());
        let mut t = 0.0;
        while t < 5.0 * tau {
            s.step(100e-6, [MotorDrive::Short; MOTORS]);
            t += 100e-6;
        }
        // Four shorted motors: e^-5 of the speed left after five of their time constants.
        assert!(s.body.v < v0 * 0.01, "{} of {v0}", s.body.v);
    }

    #[test]
    fn opposite_sides_turn_in_place_and_the_imu_sees_it() {
        let mut s = Skid::default();
        let l = MotorDrive::Pwm(-0.3);
        let r = MotorDrive::Pwm(0.3);
        for _ in 0..20_000 {
            s.step(100e-6, [l, r, l, r]);
        }
        assert!(s.body.v.abs() < 1e-6 && s.body.w > 0.5, "{:?}", s.body);
        let (acc, _, gyro) = s.mpu6050_raw();
        assert_eq!(acc[2], 16_384, "1 g on z");
        let dps = f64::from(gyro[2]) / 131.0;
        assert!((dps - s.body.w.to_degrees()).abs() < 0.01, "{dps}");
    }
}
